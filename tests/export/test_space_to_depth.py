"""The stem on 2 x 2 blocks: the same numbers as the strided convolution and the frame's
resize and normalisation it replaces."""

import numpy as np
import pytest
import torch
import torch.nn.functional as F
from torch import nn

from bsn_edge.data.dataset import IMAGENET_MEAN, IMAGENET_STD
from bsn_edge.export.fused import normalisation
from bsn_edge.export.space_to_depth import SpaceToDepthInput, block_conv, block_padding, fits


@pytest.mark.parametrize("kernel", [3, 5, 7])
@pytest.mark.parametrize("size", [(8, 12), (32, 64)])
def test_the_block_convolution_is_the_strided_one(kernel, size):
    torch.manual_seed(kernel)
    conv = nn.Conv2d(3, 16, kernel, 2, kernel // 2, bias=False)
    x = torch.randn(2, 3, *size)
    before, after = block_padding(kernel)
    blocks = F.pad(F.pixel_unshuffle(x, 2), (before, after, before, after))
    with torch.no_grad():
        torch.testing.assert_close(block_conv(conv)(blocks), conv(x), atol=1e-5, rtol=1e-5)


def test_only_stride_two_odd_stems_fit():
    assert fits(nn.Conv2d(3, 64, 7, 2, 3, bias=False))
    for conv in (nn.Conv2d(3, 64, 7, 1, 3, bias=False), nn.Conv2d(3, 64, 4, 2, 1, bias=False),
                 nn.Conv2d(3, 64, 7, 2, 2, bias=False), nn.Conv2d(3, 64, 7, 2, 3, bias=True),
                 nn.Conv2d(4, 64, 7, 2, 3, bias=False, groups=2), nn.MaxPool2d(3)):
        assert not fits(conv), conv
    with pytest.raises(ValueError, match="not a stride-2"):
        block_conv(nn.Conv2d(3, 64, 3, 1, 1, bias=False))


@pytest.mark.parametrize("shrink", [1, 2])
def test_the_input_convolution_is_resize_flip_normalise_and_blocks(shrink):
    frame = torch.from_numpy(np.random.default_rng(shrink).integers(0, 256, (1, 3, 16, 24)).astype(np.float32))
    x = frame if shrink == 1 else F.interpolate(frame, scale_factor=1 / shrink, mode="bilinear", align_corners=False)
    rgb = x[:, [2, 1, 0]] / 255.0
    mean = torch.tensor(IMAGENET_MEAN, dtype=torch.float32)[:, None, None]
    std = torch.tensor(IMAGENET_STD, dtype=torch.float32)[:, None, None]
    want = F.pad(F.pixel_unshuffle((rgb - mean) / std, 2), (2, 1, 2, 1))
    with torch.no_grad():
        got = SpaceToDepthInput(normalisation(IMAGENET_MEAN, IMAGENET_STD), shrink, 7)(frame)
    torch.testing.assert_close(got, want, atol=1e-5, rtol=1e-5)
    with pytest.raises(ValueError, match="positive integer"):
        SpaceToDepthInput(normalisation(IMAGENET_MEAN, IMAGENET_STD), 1.5, 7)
