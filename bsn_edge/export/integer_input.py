"""The frame's normalisation as one integer convolution on the uint8 frame, in a quantized graph.

After static quantization the fused model reads its frame as ``Cast`` to float -> the fixed
normalising convolution (``export.fused``, ``export.space_to_depth``) -> optional zero ``Pad`` ->
``QuantizeLinear`` into the first learnt convolution. The frame's values are integers 0..255, so
``x_scale = 1, x_zero_point = 0`` represents them exactly, and every output channel of the fixed
convolution has one weight value (a box average of one colour channel) and one bias: per-channel
scales make the weights exact integers, chosen at most 63 so that x86 CPUs without VNNI multiply
them without saturating. The bias is exact where some integer weight ``k <= 63`` makes
``bias * k / weight`` an integer (the largest such ``k`` is taken; for the ImageNet constants 60
for red and 50 for green and blue); otherwise it is off by at most half the accumulator's step,
far below the output's step. So ``QLinearConv`` computes the same uint8 values as the float chain
it replaces, without the float frame, and a ``Pad`` with the output's zero point stands for the
float zero padding.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import onnx
from onnx import TensorProto, helper, numpy_helper

from bsn_edge.export.fused import NORMALISE

INTEGER_INPUT = "integer input"     # how a quantization scheme says the frame is normalised in integers
MAX_WEIGHT = 63     # 7-bit: exact on every x86 int8 kernel path
EXACT = 1e-5        # slack for "an integer multiple" of a step
FLOAT32 = 2.4e-7    # relative rounding of a float32 constant (2 ulp)


@dataclass(frozen=True)
class IntegerInput:
    """What the rewrite did: the nodes it replaced and the largest bias rounding, in units of the
    output's quantization step."""

    replaced: tuple[str, ...]
    bias_error_steps: float


def _integer_weights(w: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
    """Per output channel: int8 weights, their scale and the int32 bias (input scale 1), and the
    bias's rounding in the convolution's output units; None when a channel's weights are all zero
    or not all integer multiples of one step with at most ``MAX_WEIGHT`` steps."""
    q = np.zeros(w.shape, np.int8)
    scale = np.zeros(w.shape[0], np.float32)
    bias = np.zeros(w.shape[0], np.int32)
    error = np.zeros(w.shape[0], np.float64)
    for o in range(w.shape[0]):
        wo = w[o].astype(np.float64)
        top = float(np.abs(wo).max())
        if top == 0.0:     # a constant channel: not the fixed normalisation this is for
            return None
        best = None     # (off, step): the most steps per weight with an exact bias, else the nearest bias
        for k in range(MAX_WEIGHT, 0, -1):
            step = top / k
            steps = wo / step
            if np.abs(steps - np.rint(steps)).max() > EXACT * k:
                continue
            ratio = float(b[o]) / step
            off = abs(ratio - np.rint(ratio))
            if off <= EXACT + FLOAT32 * abs(ratio):
                best = (off, step)
                break
            if best is None or off < best[0]:
                best = (off, step)
        if best is None:
            return None
        off, step = best
        scale[o] = step
        q[o] = np.rint(wo / step).astype(np.int8)
        bias[o] = int(np.rint(float(b[o]) / step))
        error[o] = off * step
    return q, scale, bias, error


def _from_uint8_input(g: onnx.GraphProto, tensor: str) -> bool:
    """Whether ``tensor`` is a uint8 graph input, directly or through layout changes."""
    producer = {o: n for n in g.node for o in n.output}
    while tensor in producer and producer[tensor].op_type in ("Transpose", "Reshape", "Identity"):
        tensor = producer[tensor].input[0]
    return any(i.name == tensor and i.type.tensor_type.elem_type == TensorProto.UINT8 for i in g.input)


def _input_chain(g: onnx.GraphProto, init: dict[str, onnx.TensorProto]):
    """The float input chain this rewrite applies to: (Cast to float of the uint8 frame, the
    normalising Conv, an optional zero Pad, the QuantizeLinear after it); None when the graph has another."""
    consumers: dict[str, list[onnx.NodeProto]] = {}
    for n in g.node:
        for i in n.input:
            consumers.setdefault(i, []).append(n)

    def only(tensor: str, op: str) -> onnx.NodeProto | None:
        c = consumers.get(tensor, [])
        return c[0] if len(c) == 1 and c[0].op_type == op else None

    def to(n: onnx.NodeProto) -> int | None:
        return next((helper.get_attribute_value(a) for a in n.attribute if a.name == "to"), None)

    cast = next((n for n in g.node if n.op_type == "Cast" and to(n) == TensorProto.FLOAT
                 and any(c.op_type == "Conv" and f"/{NORMALISE}/" in c.name for c in consumers.get(n.output[0], []))),
                None)
    if cast is None or not _from_uint8_input(g, cast.input[0]):
        return None
    conv = only(cast.output[0], "Conv")
    if conv is None or len(conv.input) < 3 or conv.input[1] not in init or conv.input[2] not in init:
        return None
    if any(a.name in ("group", "auto_pad") and helper.get_attribute_value(a) not in (1, b"NOTSET")
           for a in conv.attribute):
        return None
    tail = conv.output[0]
    pad = only(tail, "Pad")
    if pad is not None:
        mode = next((helper.get_attribute_value(a) for a in pad.attribute if a.name == "mode"), b"constant")
        value = pad.input[2] if len(pad.input) > 2 else ""
        if mode != b"constant" or (value and (value not in init or float(numpy_helper.to_array(init[value])) != 0.0)) \
                or (len(pad.input) > 3 and pad.input[3]):
            return None
        tail = pad.output[0]
    quant = only(tail, "QuantizeLinear")
    if quant is None or quant.input[1] not in init or quant.input[2] not in init:
        return None
    y_zero = numpy_helper.to_array(init[quant.input[2]])
    if y_zero.dtype != np.uint8 or y_zero.size != 1:
        return None
    return cast, conv, pad, quant


def integer_input(model: onnx.ModelProto) -> IntegerInput | None:
    """Rewrite ``model`` (quantized, QDQ) in place so its normalisation runs as ``QLinearConv``
    straight on the uint8 frame; None (and ``model`` untouched) when the graph does not have the
    float input chain this applies to, or its weights are not exact in 7 bits."""
    g = model.graph
    init = {t.name: t for t in g.initializer}
    chain = _input_chain(g, init)
    if chain is None:
        return None
    cast, conv, pad, quant = chain
    y_zero = numpy_helper.to_array(init[quant.input[2]])
    found = _integer_weights(numpy_helper.to_array(init[conv.input[1]]), numpy_helper.to_array(init[conv.input[2]]))
    if found is None:
        return None
    q, scale, bias, error = found
    y_scale = float(numpy_helper.to_array(init[quant.input[1]]))

    name = f"/{NORMALISE}/integer"
    out_conv = f"{name}/conv_output" if pad is not None else quant.output[0]
    new_init = [
        numpy_helper.from_array(np.array(1.0, np.float32), f"{name}/x_scale"),
        numpy_helper.from_array(np.array(0, np.uint8), f"{name}/x_zero_point"),
        numpy_helper.from_array(q, f"{name}/w"),
        numpy_helper.from_array(scale, f"{name}/w_scale"),
        numpy_helper.from_array(np.zeros(len(scale), np.int8), f"{name}/w_zero_point"),
        numpy_helper.from_array(bias, f"{name}/bias"),
    ]
    qconv = helper.make_node(
        "QLinearConv",
        [cast.input[0], f"{name}/x_scale", f"{name}/x_zero_point", f"{name}/w", f"{name}/w_scale",
         f"{name}/w_zero_point", quant.input[1], quant.input[2], f"{name}/bias"],
        [out_conv], name=f"{name}/QLinearConv",
        **{a.name: helper.get_attribute_value(a) for a in conv.attribute})
    new_nodes = [qconv]
    if pad is not None:
        new_init.append(numpy_helper.from_array(y_zero.reshape(()), f"{name}/pad_value"))
        new_nodes.append(helper.make_node("Pad", [out_conv, pad.input[1], f"{name}/pad_value"], [quant.output[0]],
                                          name=f"{name}/Pad", mode="constant"))
    replaced = [n for n in (cast, conv, pad, quant) if n is not None]
    at = min(i for i, n in enumerate(g.node) if any(n is r for r in replaced))
    kept = [n for n in g.node if not any(n is r for r in replaced)]
    del g.node[:]
    g.node.extend(kept[:at] + new_nodes + kept[at:])
    used = {i for n in g.node for i in n.input}
    dead = [t for t in g.initializer if t.name not in used]
    for t in dead:
        g.initializer.remove(t)
    g.initializer.extend(new_init)
    return IntegerInput(tuple(n.name for n in replaced), float(error.max()) / y_scale)

