"""The encoders a model can be built on: names -> how to build them and where their weights come from.

Every encoder publishes ``out_channels`` and ``strides`` (features at strides 4, 8, 16 and its output
stride), so decoders and heads are built from them. :data:`ENCODERS` is the one list of names; an
unknown name is refused with the valid ones.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from bsn_edge.networks.efficientnet_lite import WEIGHTS_LICENCE, WEIGHTS_ORIGIN, WEIGHTS_PACKAGE, EfficientNetLite0
from bsn_edge.networks.efficientnet_lite import load_imagenet as _load_lite0
from bsn_edge.networks.encoder_base import Encoder
from bsn_edge.networks.resnet import ResNetEncoder


@dataclass(frozen=True)
class EncoderInfo:
    """One encoder: how to build it (``in_channels``, ``output_stride``), the output strides it
    supports, and its pretrained weights (``None`` when it has none): where they come from, their
    licence, the package that ships them and the function that loads them into a built encoder."""

    build: Callable[[int, int], Encoder]
    output_strides: tuple[int, ...]
    weights_origin: str = ""
    weights_licence: str = ""
    weights_package: str = ""
    load_pretrained: Callable[[Any], object] | None = None


ENCODERS: dict[str, EncoderInfo] = {
    "resnet": EncoderInfo(lambda cin, os_: ResNetEncoder(18, cin, os_), (16, 32)),
    "efficientnet-lite0": EncoderInfo(lambda cin, os_: EfficientNetLite0(cin), (32,), WEIGHTS_ORIGIN, WEIGHTS_LICENCE,
                                      WEIGHTS_PACKAGE, _load_lite0),
}


def encoder_info(name: str) -> EncoderInfo:
    try:
        return ENCODERS[name]
    except KeyError:
        raise ValueError(f"unknown encoder {name!r}; valid: {', '.join(ENCODERS)}") from None


def make_encoder(name: str, in_channels: int = 3, output_stride: int = 32, pretrained: bool = False) -> Encoder:
    """A ``name`` encoder; with ``pretrained``, its published weights loaded (ValueError for an
    encoder that has none)."""
    info = encoder_info(name)
    if output_stride not in info.output_strides:
        raise ValueError(f"encoder {name!r} runs at output stride {' or '.join(map(str, info.output_strides))}, "
                         f"not {output_stride}")
    enc = info.build(in_channels, output_stride)
    if pretrained:
        if info.load_pretrained is None:
            raise ValueError(f"encoder {name!r} has no pretrained weights")
        info.load_pretrained(enc)
    return enc
