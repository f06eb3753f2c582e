"""The frame's normalisation as an integer convolution on the uint8 frame: the same uint8 values
as the float chain it replaces, on every kernel path."""

import json

import numpy as np
import onnx
import pytest
import torch
from onnx import numpy_helper

from bsn_edge.cli.export import main as export_main
from bsn_edge.data.dataset import IMAGENET_MEAN, IMAGENET_STD
from bsn_edge.export import quantize, read_card, to_onnx
from bsn_edge.export.calib_frames import load_frames
from bsn_edge.export.fused import normalisation
from bsn_edge.export.integer_input import MAX_WEIGHT, _integer_weights, integer_input
from bsn_edge.export.quantize import QuantConfig
from bsn_edge.export.space_to_depth import SpaceToDepthInput
from bsn_edge.modelfile.read import ModelFile, session
from bsn_edge.networks import create_model
from bsn_edge.synth import SynthConfig, write_clip
from tests.cards import card_for

SIZE = (64, 128)


@pytest.fixture(scope="module")
def quantized(tmp_path_factory):
    """``shared-light`` (it reads the frame in blocks) quantized with 7-bit weights twice from one
    fp32 file, with and without the rewrite, and frames of a style the calibration never saw."""
    root = tmp_path_factory.mktemp("integer_input")
    torch.manual_seed(0)
    model = create_model("shared-light").eval()
    fp32 = root / "m.onnx"
    to_onnx(model, fp32, card_for(SIZE, "shared-light"))
    write_clip(SynthConfig(frames=6, height=64, width=128, seed=1), root / "calib")
    write_clip(SynthConfig(frames=4, height=64, width=128, seed=5, style="suburb"), root / "unseen")
    frames = load_frames(root / "calib", SIZE, 6)
    out = {}
    for on in (False, True):
        q = root / f"q{int(on)}.onnx"
        out[on] = (q, quantize(fp32, q, frames, QuantConfig(reduce_range=True, integer_input=on)))
    return out, load_frames(root / "unseen", SIZE, 4)


def test_the_float_frame_is_gone(quantized):
    out, _ = quantized
    (path, info) = out[True]
    g = onnx.load(str(path)).graph
    ops = [n.op_type for n in g.node]
    assert "Cast" not in ops and info["integer_input"]["replaced"][0] == "/Cast"
    qconv = next(n for n in g.node if n.op_type == "QLinearConv")
    producer = {o: n for n in g.node for o in n.output}
    assert producer[qconv.input[0]].op_type == "Transpose" and producer[qconv.input[0]].input[0] == "frame"
    init = {t.name: numpy_helper.to_array(t) for t in g.initializer}
    assert init[qconv.input[1]] == 1.0 and init[qconv.input[2]] == 0
    assert np.abs(init[qconv.input[3]]).max() <= MAX_WEIGHT
    assert "integer input" in info["scheme"] and info["card"].quantization == info["scheme"]
    assert not any("preparing the input" in why and name in info["integer_input"]["replaced"]
                   for name, why in info["float_nodes"].items())
    assert "integer input" not in out[False][1]["scheme"]


@pytest.mark.parametrize("exact_x64", [True, False])
def test_same_outputs_as_the_float_chain_on_each_kernel_path(quantized, exact_x64):
    """The float chain (cast, float convolution, quantize) and the integer convolution are two
    computations of one uint8 tensor: the models agree to the bit, on onnxruntime's exact
    uint8 x uint8 kernels and on its uint8 x int8 ones."""
    out, unseen = quantized
    before = session(out[False][0], exact_x64=exact_x64)
    after = session(out[True][0], exact_x64=exact_x64)
    for f in unseen:
        for a, b in zip(before.run(None, {"frame": f[None]}), after.run(None, {"frame": f[None]}), strict=True):
            np.testing.assert_array_equal(a, b)


def test_imagenet_normalisation_is_exact_in_integers():
    """The block input's channels read one colour over a 2 x 2 box (the frame's halving) with
    weight 1 / (255 std 4) and bias -mean / std, so at k steps per weight the bias is
    -mean * 1020 k steps: an integer for red (0.485) at k = 60 and for green (0.456) and blue
    (0.406) at k = 50, the largest such k <= 63."""
    conv = SpaceToDepthInput(normalisation(IMAGENET_MEAN, IMAGENET_STD), 2, 7).conv
    q, _, bias, error = _integer_weights(conv.weight.numpy(), conv.bias.numpy())
    k = np.asarray([60, 50, 50])
    assert [int(q[c * 4:(c + 1) * 4].max()) for c in range(3)] == list(k) and q.min() == 0
    np.testing.assert_array_equal(bias[::4], -np.asarray([0.485, 0.456, 0.406]) * 1020 * k)
    assert error.max() < 1e-6


def test_weights_that_are_not_one_step_apart_leave_the_graph_alone():
    w = np.array([[[[1.0]], [[0.37]], [[0.0]]]], np.float32)   # 0.37 is no k / 63 of 1.0
    assert _integer_weights(w, np.zeros(1, np.float32)) is None
    assert _integer_weights(np.zeros((1, 3, 1, 1), np.float32), np.full(1, 0.3, np.float32)) is None


def test_a_graph_without_the_chain_is_untouched(quantized):
    out, _ = quantized
    m = onnx.load(str(out[True][0]))
    before = m.SerializeToString()
    assert integer_input(m) is None and m.SerializeToString() == before


def test_bsn_export_upgrades_a_model_exported_before(quantized, tmp_path, capsys):
    """``bsn-export --integer-input``: the rewrite of a sealed int8 file, the same outputs as the
    float chain's, resealed; refused for a file that has it already or whose seal is broken."""
    out, unseen = quantized
    new = tmp_path / "up.onnx"
    assert export_main(["--integer-input", str(out[False][0]), "--out", str(new)]) == 0
    card = read_card(new)
    assert card.quantization.endswith(", integer input") and card.sealed
    summary = json.loads(new.with_suffix(".json").read_text())
    assert summary["card"]["quantization"] == card.quantization == summary["quantization"]["scheme"]
    assert summary["quantization"]["integer_input"]["replaced"][0] == "/Cast"
    assert card.graph_sha256 == ModelFile.read(new).graph_sha256 != read_card(out[False][0]).graph_sha256
    a, b = session(out[False][0]), session(new)
    for x, y in zip(a.run(None, {"frame": unseen[0][None]}), b.run(None, {"frame": unseen[0][None]}), strict=True):
        np.testing.assert_array_equal(x, y)
    assert export_main(["--integer-input", str(out[False][0]), "--out", str(new)]) == 2
    assert "pass --force" in capsys.readouterr().err
    assert export_main(["--integer-input", str(out[True][0]), "--out", str(tmp_path / "again.onnx")]) == 2
    assert "no float input chain" in capsys.readouterr().err and not (tmp_path / "again.onnx").exists()
    m = onnx.load(str(out[False][0]))
    w = next(t for t in m.graph.initializer if t.data_type == onnx.TensorProto.INT8 and len(t.dims) == 4)
    w.raw_data = bytes(reversed(w.raw_data))
    onnx.save(m, str(tmp_path / "damaged.onnx"))
    assert export_main(["--integer-input", str(tmp_path / "damaged.onnx"), "--out", str(tmp_path / "d.onnx")]) == 2
    assert "does not match its seal" in capsys.readouterr().err and not (tmp_path / "d.onnx").exists()
