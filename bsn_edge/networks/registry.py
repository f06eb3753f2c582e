"""The model registry: names -> specs -> modules."""

from __future__ import annotations

import hashlib
import io
from dataclasses import asdict, dataclass, replace
from enum import StrEnum
from typing import Any, cast

import torch
from torch import nn

from bsn_edge.camera import Intrinsics
from bsn_edge.card import ModelCard
from bsn_edge.networks.bsn import MAX_DEPTH_M, MIN_DEPTH_M, BlindSpotNet, DepthNet
from bsn_edge.networks.deeplab import EncoderDecoder
from bsn_edge.networks.encoder_base import Encoder
from bsn_edge.networks.encoders import ENCODERS, encoder_info, make_encoder
from bsn_edge.networks.resnet import DEPTHS as RESNET_DEPTHS
from bsn_edge.networks.resnet import ResNetEncoder
from bsn_edge.networks.shared import SharedEncoderBSN
from bsn_edge.networks.unet import UNet
from bsn_edge.semantics import NUM_CLASSES


@dataclass(frozen=True)
class ModelSpec:
    """What a registry name stands for.

    arch: ``deeplab`` (ResNet + ASPP + DeepLabV3+ decoder) or ``unet``.
    encoder_depth: ResNet depth of B. decoder_width / separable: B's decoder (256 dense is the
    paper's; 64 separable is the light one). use_depth: B sees D's depth. distill: trained with
    the teacher's pairwise-similarity loss (lambda = 1) or without (lambda = 0). shared_encoder:
    D and B read one encoder (:class:`~bsn_edge.networks.shared.SharedEncoderBSN`) instead of one
    ResNet each. encoder: that shared encoder, a name of :data:`~bsn_edge.networks.encoders.ENCODERS`
    (``resnet``: ResNet-18; ``efficientnet-lite0``). pretrained: ``imagenet`` when training starts
    from the encoder's ImageNet weights (the card then names the encoder), else ``''``.
    oracle_depth: B reads the ground-truth depth given with the frame instead of D's,
    a research arm that says how much better depth would help B (no camera has that depth, so
    such a model is not exported or adapted).
    """

    arch: str = "deeplab"
    encoder_depth: int = 18
    decoder_width: int = 256
    separable: bool = False
    use_depth: bool = True
    distill: bool = True
    depth_width: int = 64       # D's light decoder
    output_stride: int = 16     # of both encoders
    input_scale: float = 1.0    # both networks run on the frame resized by this
    shared_encoder: bool = False
    oracle_depth: bool = False
    encoder: str = "resnet"
    pretrained: str = ""

    def __post_init__(self) -> None:
        if self.arch not in ("deeplab", "unet"):
            raise ValueError(f"unknown arch {self.arch!r}; valid: deeplab, unet")
        if self.shared_encoder and (self.arch != "deeplab" or self.encoder_depth != 18):
            raise ValueError("a shared encoder is D's ResNet-18: it needs arch 'deeplab' and encoder_depth 18")
        info = encoder_info(self.encoder)
        if self.encoder != "resnet" and not self.shared_encoder:
            raise ValueError(f"encoder {self.encoder!r} is built as the one encoder D and B share (shared_encoder)")
        if self.output_stride not in info.output_strides:
            raise ValueError(f"encoder {self.encoder!r} runs at output stride "
                             f"{' or '.join(map(str, info.output_strides))}, not {self.output_stride}")
        if self.pretrained not in ("", "imagenet") or (self.pretrained and info.load_pretrained is None):
            raise ValueError(f"pretrained must be '' or 'imagenet' for an encoder that has ImageNet weights; got "
                             f"{self.pretrained!r} for {self.encoder!r}")

    def to_dict(self) -> dict:
        return asdict(self)


# The light variant is what a 2-core CPU runs in real time: a light decoder, encoders at output
# stride 32, and both networks on the frame at half size (outputs come back at full size).
_LIGHT: dict[str, Any] = {"decoder_width": 64, "separable": True, "output_stride": 32, "input_scale": 0.5,
                          "depth_width": 32}
MODELS: dict[str, ModelSpec] = {
    "small": ModelSpec(),
    "small-light": ModelSpec(**_LIGHT),
    "medium": ModelSpec(encoder_depth=50),
    "large": ModelSpec(encoder_depth=101),
    "unet": ModelSpec(arch="unet"),
    "small-d": ModelSpec(use_depth=False),
    "small-kd": ModelSpec(distill=False),
    "small-light-d": ModelSpec(use_depth=False, **_LIGHT),
    "small-light-kd": ModelSpec(distill=False, **_LIGHT),
    "small-light-oracle": ModelSpec(oracle_depth=True, **_LIGHT),
    "shared-light": ModelSpec(shared_encoder=True, **_LIGHT),
    "shared-light-d": ModelSpec(shared_encoder=True, use_depth=False, **_LIGHT),
    "shared-light-kd": ModelSpec(shared_encoder=True, distill=False, **_LIGHT),
    "shared-light-oracle": ModelSpec(shared_encoder=True, oracle_depth=True, **_LIGHT),
    # D and B on one EfficientNet-Lite0 that starts from ImageNet: features learnt on real photographs
    "lite-light": ModelSpec(shared_encoder=True, encoder="efficientnet-lite0", pretrained="imagenet", **_LIGHT),
    # lite-light's network on the model frame at its full size, not halved
    "lite-full": ModelSpec(shared_encoder=True, encoder="efficientnet-lite0", pretrained="imagenet",
                           **{**_LIGHT, "input_scale": 1.0}),
}


def get_spec(name: str) -> ModelSpec:
    try:
        return MODELS[name]
    except KeyError:
        raise ValueError(f"unknown model {name!r}; valid: {', '.join(MODELS)}") from None


def build(spec: ModelSpec, pretrained: bool = False) -> BlindSpotNet:
    """The network ``spec`` describes, initialised at random, or with ``pretrained`` its encoder's
    ImageNet weights where ``spec.pretrained`` says it starts from them (training does; a model whose
    trained weights are loaded next does not need them)."""
    if spec.shared_encoder:
        enc = make_encoder(spec.encoder, 3, spec.output_stride, pretrained=pretrained and bool(spec.pretrained))
        return SharedEncoderBSN(spec.encoder_depth, spec.output_stride, spec.decoder_width, spec.depth_width,
                                spec.separable, spec.use_depth, spec.input_scale, spec.oracle_depth, encoder=enc)
    in_ch = 4 if spec.use_depth else 3
    if spec.arch == "unet":
        b: nn.Module = UNet(in_ch, 1)
    else:
        enc = ResNetEncoder(spec.encoder_depth, in_ch, spec.output_stride)
        b = EncoderDecoder(enc, 1, spec.decoder_width, spec.separable)
    d = DepthNet(18, spec.depth_width, output_stride=spec.output_stride)
    return BlindSpotNet(b, d, spec.use_depth, spec.input_scale, spec.oracle_depth)


def create_model(name: str, pretrained: bool = False) -> BlindSpotNet:
    """A fresh BlindSpotNet for a registry name (``small``, ``small-light``, ``lite-light``, ...);
    ``pretrained``: its encoder's ImageNet weights loaded, for a variant that starts from them."""
    return build(get_spec(name), pretrained)


class Carried(StrEnum):
    """What a model takes from the run it starts from (``train.init``)."""

    ALL = "all"     # every weight: the same network
    D = "D"         # D alone: B's decoder starts fresh


def carried_over(name: str, source_name: str) -> Carried:
    """What a ``name`` model takes from a ``source_name`` run to train on from: all its weights
    when the two are one network (the same variant, or variants that differ only in
    ``input_scale``: the same modules, run on another size of the frame), D alone for a
    shared-encoder model from a two-network run with the same D (its encoder, decoder and head carry
    over whole; B's decoder, which read another encoder's features, starts fresh). ValueError for
    any other pair."""
    spec, src = get_spec(name), get_spec(source_name)
    if replace(src, input_scale=spec.input_scale) == spec:
        return Carried.ALL
    same_d = (spec.depth_width, spec.output_stride, spec.input_scale) == (src.depth_width, src.output_stride,
                                                                          src.input_scale)
    if spec.shared_encoder and not src.shared_encoder and src.arch == "deeplab" and same_d:
        return Carried.D
    raise ValueError(f"a {name!r} model starts from a run of its own network (at any input scale), or from a "
                     f"two-network run with the same D when it shares its encoder; got a {source_name!r} run")


def start_from(model: BlindSpotNet, name: str, source: BlindSpotNet, source_name: str) -> Carried:
    """Load into ``model`` (a ``name`` network) what :func:`carried_over` says it takes from
    ``source`` (a ``source_name`` network), and say which."""
    what = carried_over(name, source_name)
    if what is Carried.ALL:
        model.load_state_dict(source.state_dict())
    else:
        model.depth_net.load_state_dict(cast(nn.Module, source.depth_net.net).state_dict())
    return what


#: the encoders a segmentation teacher can be built on: ResNets at output stride 16, and the
#: encoders of :data:`~bsn_edge.networks.encoders.ENCODERS` that publish pretrained weights
TEACHER_ENCODERS: tuple[str, ...] = (*(f"resnet{d}" for d in RESNET_DEPTHS),
                                     *(n for n, i in ENCODERS.items() if i.load_pretrained is not None))


def teacher_encoder(name: str | int, pretrained: bool = False) -> str:
    """``name`` as a teacher encoder's name (a whole number N, as runs written before names record
    it, is ``resnetN``); ValueError naming the valid ones for any other, or for ``pretrained`` on an
    encoder without published weights."""
    canon = f"resnet{name}" if isinstance(name, int) and not isinstance(name, bool) else name
    if canon not in TEACHER_ENCODERS:
        raise ValueError(f"unknown teacher encoder {name!r}; valid: {', '.join(TEACHER_ENCODERS)}")
    if pretrained and canon.startswith("resnet"):
        pretrained_ones = [n for n in TEACHER_ENCODERS if not n.startswith("resnet")]
        raise ValueError(f"teacher encoder {canon!r} has no pretrained weights; those with: "
                         f"{', '.join(pretrained_ones)}")
    return canon


def create_teacher(encoder: str | int = "resnet18", width: int = 128, pretrained: bool = False) -> EncoderDecoder:
    """The DeepLabV3+ segmentation teacher (Cityscapes trainIds) on ``encoder`` (one of
    :data:`TEACHER_ENCODERS`); its decoder output is the distillation target. ``pretrained``: the
    encoder starts from its published weights (ImageNet), for a teacher about to be trained."""
    name = teacher_encoder(encoder, pretrained)
    if name.startswith("resnet"):
        enc: Encoder = ResNetEncoder(int(name.removeprefix("resnet")), 3)
    else:
        enc = make_encoder(name, 3, max(encoder_info(name).output_strides), pretrained=pretrained)
    return EncoderDecoder(enc, NUM_CLASSES, width)


def describe(name: str, model: nn.Module, camera: Intrinsics, threshold: float | None = None,
             config_digest: str = "") -> ModelCard:
    """The card of ``model`` (a ``name`` network, trained or not) run with the model camera
    ``camera`` (its size is the input size); the weights' sha256 is taken from ``model``."""
    return ModelCard(variant=name, spec=get_spec(name).to_dict(), input_size=(camera.height, camera.width),
                     threshold=threshold, camera=camera, depth_range=(MIN_DEPTH_M, MAX_DEPTH_M),
                     weights_sha256=hashlib.sha256(weights_bytes(model)).hexdigest(), config_digest=config_digest)


def weights_bytes(model: nn.Module) -> bytes:
    """The serialized state dict of ``model`` (what ``model.pt`` holds; its sha256 is the card's
    ``weights_sha256``)."""
    buf = io.BytesIO()
    torch.save({k: v.detach().cpu().contiguous() for k, v in model.state_dict().items()}, buf)
    return buf.getvalue()
