"""Static int8 quantization of the fused model with onnxruntime (QDQ, per-channel weights).

The output heads stay in float by default: the last learnt convolution of each head and
everything after it (upsampling, sigmoid, the depth's clamp and exp). Probabilities near the threshold
and metres at range are where 8 bits would cost the most. The input's preparation (cast,
layout, resize, normalisation) is left out of the quantizer: as quantized element-wise ops on
whole frames it costs more than it saves. Where it is one fixed convolution of the uint8 frame
(no resize in between), ``export.integer_input`` then runs it as an exact integer convolution on
the frame itself, and the float frame is never made.
"""

from __future__ import annotations

import tempfile
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import onnx
import onnx.numpy_helper
from onnxruntime.quantization import CalibrationDataReader, CalibrationMethod, QuantFormat, QuantType, quantize_static
from onnxruntime.quantization.shape_inference import quant_pre_process

from bsn_edge.card import SEVEN_BIT_WEIGHTS
from bsn_edge.export.fused import NORMALISE
from bsn_edge.export.integer_input import INTEGER_INPUT, integer_input
from bsn_edge.export.seal import read_card, seal
from bsn_edge.modelfile.quant_names import METHOD_NAMES, TYPE_NAMES

METHODS = {"minmax": CalibrationMethod.MinMax, "entropy": CalibrationMethod.Entropy,
           "percentile": CalibrationMethod.Percentile}
TYPES = {"uint8": QuantType.QUInt8, "int8": QuantType.QInt8}
assert set(METHODS) == set(METHOD_NAMES) and set(TYPES) == set(TYPE_NAMES), "quant_names.py lists every choice"


@dataclass(frozen=True)
class QuantConfig:
    """How to quantize. Unsigned activations with signed weights are the fast pair on x86 with
    VNNI (the benchmark measures the alternative); per-channel weights keep ResNet accurate."""

    method: str = "minmax"
    activations: str = "uint8"
    weights: str = "int8"
    per_channel: bool = True
    keep_heads_float: bool = True
    # 7-bit weights ([-64, 63]): x86 CPUs without VNNI then run uint8 x int8 without saturating,
    # at full speed, where 8-bit weights fall back to slower uint8 x uint8 (the runtime's session);
    # the default, as the shipped model is made (benchmarks/results/int8_cpu.md)
    reduce_range: bool = True
    # the frame's normalisation as an exact integer convolution on the uint8 frame, where it applies
    integer_input: bool = True

    def __post_init__(self) -> None:
        if self.method not in METHODS:
            raise ValueError(f"unknown calibration method {self.method!r}; valid: {', '.join(METHODS)}")
        for k in (self.activations, self.weights):
            if k not in TYPES:
                raise ValueError(f"unknown quantized type {k!r}; valid: {', '.join(TYPES)}")

    def scheme(self) -> str:
        """The card's words for this scheme (``quantize`` writes them with the weights' granularity
        read from the graph it made)."""
        return (f"static QDQ, activations {self.activations}, weights {self.weights}"
                f"{' ' + SEVEN_BIT_WEIGHTS if self.reduce_range else ''}{' per-channel' if self.per_channel else ''}, "
                f"{self.method} calibration")


def conv_weight_scales(model: onnx.ModelProto) -> dict[str, tuple[int, np.ndarray]]:
    """Each quantized convolution weight of a QDQ graph: ``{conv name: (output channels, scale)}``,
    the scale as its ``DequantizeLinear`` holds it (one value per tensor, or one per output channel)."""
    inits = {i.name: i for i in model.graph.initializer}
    producer = {o: n for n in model.graph.node for o in n.output}
    out: dict[str, tuple[int, np.ndarray]] = {}
    for n in model.graph.node:
        dq = producer.get(n.input[1]) if n.op_type == "Conv" and len(n.input) > 1 else None
        if dq is None or dq.op_type != "DequantizeLinear" or dq.input[0] not in inits:
            continue
        out[n.name] = (int(inits[dq.input[0]].dims[0]), onnx.numpy_helper.to_array(inits[dq.input[1]]))
    return out


def weights_per_channel(model: onnx.ModelProto) -> bool:
    """True when every quantized convolution weight has one scale per output channel."""
    scales = conv_weight_scales(model)
    return bool(scales) and all(s.ndim == 1 and s.shape[0] == c for c, s in scales.values())


class FrameReader(CalibrationDataReader):
    """Feeds calibration frames (``[N, H, W, 3]`` uint8) to the ``frame`` input one at a time."""

    def __init__(self, frames: np.ndarray) -> None:
        self.frames = frames
        self.i = 0

    def get_next(self) -> dict[str, np.ndarray] | None:
        if self.i >= len(self.frames):
            return None
        self.i += 1
        return {"frame": self.frames[self.i - 1][None]}

    def rewind(self) -> None:
        self.i = 0


def head_nodes(model: onnx.ModelProto) -> dict[str, str]:
    """Nodes from each output back to and including the first learnt convolution: ``{name: reason}``.

    A convolution feeding ``DepthToSpace`` is bilinear upsampling (``export.upsample``), part of
    the head, so the walk goes on through it.
    """
    producer = {o: n for n in model.graph.node for o in n.output}
    shuffled = {i for n in model.graph.node if n.op_type == "DepthToSpace" for i in n.input}
    keep: dict[str, str] = {}
    for out in model.graph.output:
        frontier = [out.name]
        while frontier:
            t = frontier.pop()
            n = producer.get(t)
            if n is None or n.name in keep:
                continue
            upsampling = n.op_type == "Conv" and n.output[0] in shuffled
            keep[n.name] = f"{'upsampling ' if upsampling else ''}{n.op_type} in the '{out.name}' head"
            if n.op_type != "Conv" or upsampling:
                frontier.extend(i for i in n.input if i in producer)
    return keep


def input_nodes(model: onnx.ModelProto) -> dict[str, str]:
    """Nodes from the graph input forward up to (not including) the first learnt convolutions:
    the cast, layout change, resize and normalisation (a fixed 1x1 convolution) of the uint8
    frame, cheap in float and slow as quantized ops."""
    consumers: dict[str, list] = {}
    for n in model.graph.node:
        for i in n.input:
            consumers.setdefault(i, []).append(n)
    keep: dict[str, str] = {}
    frontier = [i.name for i in model.graph.input]
    while frontier:
        for n in consumers.get(frontier.pop(), []):
            if n.name in keep or (n.op_type == "Conv" and f"/{NORMALISE}/" not in n.name):
                continue
            keep[n.name] = f"{n.op_type} preparing the input"
            frontier.extend(n.output)
    return keep


def quantize(fp32: str | Path, out: str | Path, frames: np.ndarray, cfg: QuantConfig | None = None
             ) -> dict[str, Any]:
    """Quantize ``fp32`` into ``out`` calibrated on ``frames``; returns what stayed float and why."""
    cfg = cfg or QuantConfig()
    fp32, out = Path(fp32), Path(out)
    card = read_card(fp32)
    with tempfile.TemporaryDirectory() as tmp:
        pre = Path(tmp) / "pre.onnx"
        quant_pre_process(str(fp32), str(pre), skip_symbolic_shape=True)
        model = onnx.load(str(pre))
        excluded = {**input_nodes(model), **(head_nodes(model) if cfg.keep_heads_float else {})}
        quantize_static(str(pre), str(out), FrameReader(frames), quant_format=QuantFormat.QDQ,
                        per_channel=cfg.per_channel, reduce_range=cfg.reduce_range,
                        activation_type=TYPES[cfg.activations],
                        weight_type=TYPES[cfg.weights], calibrate_method=METHODS[cfg.method],
                        nodes_to_exclude=list(excluded),
                        extra_options={"ActivationSymmetric": cfg.activations == "int8"})
        rewritten = None
        if cfg.integer_input:
            q = onnx.load(str(out))
            rewritten = integer_input(q)
            if rewritten is not None:
                onnx.checker.check_model(q)
                onnx.save(q, str(out))
                for name in rewritten.replaced:
                    excluded.pop(name, None)
    # the card says what the graph holds, whatever was asked
    made = replace(cfg, per_channel=weights_per_channel(onnx.load(str(out))))
    scheme = made.scheme() + (f", {INTEGER_INPUT}" if rewritten is not None else "")
    sealed = seal(out, card.replace(quantization=scheme))
    return {"config": asdict(cfg), "scheme": scheme, "float_nodes": excluded,
            "integer_input": asdict(rewritten) if rewritten is not None else None,
            "calibration_frames": len(frames), "card": sealed}
