"""What every encoder is: a module that publishes its features' channels and strides, so that decoders and
heads are built from them (segmentation_models_pytorch's ``out_channels``)."""

from __future__ import annotations

from torch import nn


class Encoder(nn.Module):
    """Features at strides 4, 8, 16 and the encoder's output stride: ``out_channels[i]`` channels at
    ``strides[i]``. A subclass sets both in its ``__init__``."""

    out_channels: tuple[int, ...]
    strides: tuple[int, ...]
