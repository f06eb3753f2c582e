"""Bilinear upsampling rewritten as convolution + depth-to-space: same numbers, exported cleanly."""

import numpy as np
import onnx
import pytest
import torch
import torch.nn.functional as F

from bsn_edge.export.upsample import ShuffleUpsample, bilinear_taps, chained_taps, with_shuffle_upsampling
from bsn_edge.networks import create_model
from bsn_edge.networks.upsample import Upsample


@pytest.mark.parametrize("factor", [2, 4, 8])
@pytest.mark.parametrize("shape", [(1, 1, 8, 16), (2, 3, 5, 7), (1, 1, 1, 2)])
def test_matches_bilinear_interpolation_edges_included(factor, shape):
    x = torch.randn(*shape)
    ref = F.interpolate(x, scale_factor=factor, mode="bilinear", align_corners=False)
    torch.testing.assert_close(ShuffleUpsample(factor)(x), ref, atol=1e-5, rtol=0)


def test_taps_are_a_partition_of_unity():
    for f in (2, 3, 4, 8):
        t = bilinear_taps(f)
        assert t.shape == (f, 3) and abs(t.sum(1) - 1).max() < 1e-12 and (t >= 0).all()


def test_factor_validation():
    with pytest.raises(ValueError, match="positive integer"):
        Upsample(1.5)
    with pytest.raises(ValueError, match=">= 2"):
        ShuffleUpsample(1)
    with pytest.raises(ValueError, match=">= 2"):
        ShuffleUpsample()


def test_model_copy_swaps_every_upsampler_and_keeps_outputs():
    torch.manual_seed(0)
    model = create_model("small-light").eval()
    swapped = with_shuffle_upsampling(model)
    assert not any(isinstance(m, Upsample) for m in swapped.modules())
    assert sum(isinstance(m, Upsample) for m in model.modules()) == 3, "the original is untouched"
    x = torch.randn(1, 3, 64, 128)
    with torch.no_grad():
        for a, b in zip(model(x)[:2], swapped(x)[:2], strict=True):
            torch.testing.assert_close(a, b, atol=1e-5, rtol=1e-5)


def test_exported_graph_upsamples_without_resize(small_light_onnx):
    g = onnx.load(str(small_light_onnx((64, 128))))
    ops = [n.op_type for n in g.graph.node]
    assert ops.count("DepthToSpace") == 4, "two per head: the head's x4 and the frame's x2"
    assert "Pad" not in ops and "ConstantOfShape" not in [n.op_type for n in g.graph.node if "up" in n.name]
    resized = [n.name for n in g.graph.node if n.op_type == "Resize" and "/decoder/" not in n.name]
    assert resized == ["/Resize"], f"only the frame is resized, got {resized}"


@pytest.mark.parametrize("factors", [(4, 2), (2, 2), (2, 4), (2, 2, 2), (3, 2)])
@pytest.mark.parametrize("shape", [(1, 1, 8, 16), (2, 3, 5, 7), (1, 1, 1, 2)])
def test_chained_upsampling_is_one_shuffle_edges_included(factors, shape):
    x = torch.randn(*shape)
    ref = x
    for f in factors:
        ref = F.interpolate(ref, scale_factor=f, mode="bilinear", align_corners=False)
    up = ShuffleUpsample(*factors)
    assert up.factor == int(np.prod(factors))
    torch.testing.assert_close(up(x), ref, atol=1e-5, rtol=0)


def test_a_chain_of_one_is_the_plain_taps():
    for f in (2, 3, 4, 8):
        np.testing.assert_array_equal(chained_taps(f), bilinear_taps(f))
