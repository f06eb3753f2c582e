"""int8 convolutions through the runtime's session are exact on every x86 CPU.

Without VNNI (AVX2, AVX-512F), onnxruntime's uint8 x int8 kernels add products in pairs into
int16, which saturates when the weights reach past [-64, 63]; the shipped model's depth came out
up to 55 % off on such a machine. The answer here is computed by numpy in integers, not by
onnxruntime, so the test fails on a CPU where the runtime's session would saturate.
"""

import numpy as np
import pytest

onnx = pytest.importorskip("onnx")
from onnx import TensorProto, helper, numpy_helper  # noqa: E402

from bsn_edge.modelfile.read import session  # noqa: E402

C_IN, C_OUT, SIZE = 64, 8, 6
X_SCALE, W_SCALE, Y_SCALE = 1 / 255, 1 / 127, 1.5


def _qdq_conv(weights: np.ndarray) -> bytes:
    """uint8 frame -> DQ -> Conv 3x3 (int8 weights, DQ) -> Q -> DQ: onnxruntime fuses it into one
    uint8 x int8 convolution, as in the exported models."""
    init = [numpy_helper.from_array(weights, "w"),
            numpy_helper.from_array(np.array(X_SCALE, np.float32), "xs"),
            numpy_helper.from_array(np.array(0, np.uint8), "xz"),
            numpy_helper.from_array(np.array(W_SCALE, np.float32), "ws"),
            numpy_helper.from_array(np.array(0, np.int8), "wz"),
            numpy_helper.from_array(np.array(Y_SCALE, np.float32), "ys"),
            numpy_helper.from_array(np.array(0, np.uint8), "yz")]
    nodes = [helper.make_node("DequantizeLinear", ["x", "xs", "xz"], ["xf"]),
             helper.make_node("DequantizeLinear", ["w", "ws", "wz"], ["wf"]),
             helper.make_node("Conv", ["xf", "wf"], ["yf"], pads=[1, 1, 1, 1]),
             helper.make_node("QuantizeLinear", ["yf", "ys", "yz"], ["yq"]),
             helper.make_node("DequantizeLinear", ["yq", "ys", "yz"], ["y"])]
    graph = helper.make_graph(nodes, "qdq_conv",
                              [helper.make_tensor_value_info("x", TensorProto.UINT8, [1, C_IN, SIZE, SIZE])],
                              [helper.make_tensor_value_info("y", TensorProto.FLOAT, [1, C_OUT, SIZE, SIZE])], init)
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = 8
    return model.SerializeToString()


def _reference(x: np.ndarray, w: np.ndarray) -> np.ndarray:
    """The same convolution in int64, requantized with round-half-to-even and saturation."""
    xp = np.pad(x[0].astype(np.int64), ((0, 0), (1, 1), (1, 1)))
    acc = np.zeros((C_OUT, SIZE, SIZE), np.int64)
    for dy in range(3):
        for dx in range(3):
            acc += np.einsum("oc,chw->ohw", w[:, :, dy, dx].astype(np.int64), xp[:, dy:dy + SIZE, dx:dx + SIZE])
    q = np.clip(np.rint(acc * (X_SCALE * W_SCALE / Y_SCALE)), 0, 255)
    return (q * Y_SCALE)[None].astype(np.float32)


def test_uint8_by_int8_convolution_does_not_saturate():
    rng = np.random.default_rng(0)
    # bright pixels and full-range weights, positive on average so that the sums stay in the
    # output's range: the products that saturate int16 pairs
    x = rng.integers(200, 256, (1, C_IN, SIZE, SIZE), dtype=np.uint8)
    w = rng.integers(-60, 128, (C_OUT, C_IN, 3, 3)).astype(np.int8)
    w[:, :, 1, 1] = 127
    want = _reference(x, w)
    assert 0 < want.max() < 255 * Y_SCALE, "the test's sums must stay inside the output's range"
    got = session(_qdq_conv(w), threads=1).run(None, {"x": x})[0]
    np.testing.assert_allclose(got, want, atol=Y_SCALE * 1.01)


def test_seven_bit_weights_are_exact_on_the_fast_kernels():
    """Weights in [-64, 63] are why a 7-bit model may skip the exact kernels: pairs of uint8 x int8
    products then stay inside int16 (2 x 255 x 64 < 32768) on every x86 CPU."""
    rng = np.random.default_rng(1)
    x = rng.integers(200, 256, (1, C_IN, SIZE, SIZE), dtype=np.uint8)
    w = rng.integers(-30, 64, (C_OUT, C_IN, 3, 3)).astype(np.int8)
    w[:, :, 1, 1] = 63
    want = _reference(x, w)
    assert 0 < want.max() < 255 * Y_SCALE
    got = session(_qdq_conv(w), threads=1, exact_x64=False).run(None, {"x": x})[0]
    np.testing.assert_allclose(got, want, atol=Y_SCALE * 1.01)


def test_the_engine_asks_for_exact_kernels_only_for_8_bit_weights(small_light_onnx, tmp_path):
    """The card of a 7-bit model lets the runtime use the fast kernels; any other int8 model gets
    the exact ones (and the self-test checks the answer either way)."""
    from bsn_edge.runtime import Engine

    path = small_light_onnx((64, 128))
    fp32 = Engine(path)
    assert not fp32.card.seven_bit_weights
    assert fp32.sess.get_session_options().get_session_config_entry("session.x64quantprecision") == "1"
    from bsn_edge.export.quantize import QuantConfig
    from bsn_edge.export.seal import read_card, seal

    seven = tmp_path / "m7.onnx"
    seal(path, read_card(path).replace(quantization=QuantConfig(reduce_range=True).scheme()), out=seven)
    engine = Engine(seven)
    assert engine.card.seven_bit_weights
    with pytest.raises(Exception, match="x64quantprecision"):
        engine.sess.get_session_options().get_session_config_entry("session.x64quantprecision")
