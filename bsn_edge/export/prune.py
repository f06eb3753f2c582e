"""Structured pruning at export: channels nothing reads are taken out of the ONNX graph.

A convolution's output channel whose every reader multiplies it by exactly zero changes no output, yet
an int8 graph computes it at full price. Such channels are found on the exported fp32 graph, where the
batch norms are already folded, and removed: the producing convolution loses that output row, each
reading convolution the matching input column. Nothing is approximated: only weights that are exactly
zero are dropped, so the pruned graph computes the same numbers (to float summation order).

Channels are followed through the ops that keep them in place (activations, pooling, resizing,
residual sums, depthwise convolutions: a *tied* set of tensors shares one channel selection) and
through concatenation along channels. Any other reader of a tensor keeps all its channels, as do the
graph's inputs and outputs, so a graph this module does not understand is left as it is.
"""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass

import numpy as np
import onnx
from onnx import numpy_helper

from bsn_edge.modelfile.read import session

# ops whose output channel c depends on input channel c only (other operands broadcast over channels)
CHANNEL_WISE = frozenset({"Relu", "Clip", "Sigmoid", "Exp", "Tanh", "LeakyRelu", "HardSigmoid", "HardSwish",
                          "MaxPool", "AveragePool", "GlobalAveragePool", "Resize", "Add", "Sub", "Mul", "Div",
                          "Reciprocal", "Expand", "Identity"})
# ops that read a tensor's shape, not its values
SHAPE_ONLY = frozenset({"Shape"})


@dataclass(frozen=True)
class Pruned:
    """What pruning removed: convolution output channels and multiply-accumulates, before and after."""

    channels_before: int
    channels_after: int
    macs_before: int
    macs_after: int
    convolutions_changed: int

    def line(self) -> str:
        return (f"pruned {self.channels_before - self.channels_after:,} of {self.channels_before:,} convolution "
                f"channels nothing reads; {self.macs_before / 1e9:.2f} -> {self.macs_after / 1e9:.2f} GMACs")

    def to_dict(self) -> dict[str, int]:
        return {"channels_before": self.channels_before, "channels_after": self.channels_after,
                "macs_before": self.macs_before, "macs_after": self.macs_after,
                "convolutions_changed": self.convolutions_changed}


class _Tied:
    """Union-find over tensor names: tensors whose channels must be selected alike."""

    def __init__(self) -> None:
        self.parent: dict[str, str] = {}

    def find(self, t: str) -> str:
        self.parent.setdefault(t, t)
        while self.parent[t] != t:
            self.parent[t] = self.parent[self.parent[t]]
            t = self.parent[t]
        return t

    def tie(self, a: str, b: str) -> None:
        self.parent[self.find(a)] = self.find(b)


def _attr(node: onnx.NodeProto, name: str, default: int) -> int:
    for a in node.attribute:
        if a.name == name:
            return int(a.i)
    return default


def _broadcasts(operand: np.ndarray, c: int | None) -> bool:
    """Whether a constant operand of a channel-wise op is the same for every channel, or is laid out
    ``[1, C, ...]`` so that it can be sliced with the channels."""
    if operand.ndim < 3:
        return True
    if operand.ndim == 3:
        return operand.shape[0] == 1
    return operand.ndim == 4 and operand.shape[1] in (1, c)


def _shapes(model: onnx.ModelProto) -> dict[str, list[int]]:
    """Every tensor's shape, read off one run of ``model`` on zeros (shape inference stops at the
    first shape computed from data, such as the frame's padding)."""
    probe = onnx.ModelProto()
    probe.CopyFrom(model)
    have = {o.name for o in probe.graph.output}
    probe.graph.output.extend(onnx.ValueInfoProto(name=t) for n in probe.graph.node for t in n.output
                              if t and t not in have)
    feeds = {}
    for i in probe.graph.input:
        tt = i.type.tensor_type
        feeds[i.name] = np.zeros([d.dim_value for d in tt.shape.dim],
                                 onnx.helper.tensor_dtype_to_np_dtype(tt.elem_type))
    names = [o.name for o in probe.graph.output]
    arrays = session(probe.SerializeToString()).run(names, feeds)
    return {t: list(np.shape(a)) for t, a in zip(names, arrays, strict=True)}


def _macs(model: onnx.ModelProto, shapes: dict[str, list[int]], weights: dict[str, np.ndarray]) -> int:
    total = 0
    for n in model.graph.node:
        if n.op_type == "Conv" and n.output[0] in shapes and n.input[1] in weights:
            o = shapes[n.output[0]]
            total += int(np.prod(o[2:])) * int(weights[n.input[1]].size)
    return total


def prune(model: onnx.ModelProto) -> Pruned:
    """Remove from ``model`` (an fp32 graph, edited in place) every convolution output channel that
    nothing reads; returns what was removed. Shapes must be known to ONNX shape inference."""
    graph = model.graph
    weights = {i.name: numpy_helper.to_array(i) for i in graph.initializer}
    shapes = _shapes(model)
    macs_before = _macs(model, shapes, weights)

    def channels(t: str) -> int | None:
        s = shapes.get(t)
        return s[1] if s is not None and len(s) == 4 and t not in weights else None

    tied = _Tied()
    convs = [n for n in graph.node if n.op_type == "Conv" and n.input[1] in weights]
    depthwise = {id(n) for n in convs if _attr(n, "group", 1) > 1
                 and _attr(n, "group", 1) == channels(n.input[0]) == channels(n.output[0])
                 and weights[n.input[1]].shape[1] == 1}
    readers: dict[str, list[onnx.NodeProto]] = defaultdict(list)
    for n in graph.node:
        for t in n.input:
            if t:
                readers[t].append(n)
    for n in graph.node:
        if n.op_type in CHANNEL_WISE and channels(n.output[0]) is not None:
            for t in n.input:
                if t and channels(t) == channels(n.output[0]):
                    tied.tie(t, n.output[0])
        elif id(n) in depthwise:
            tied.tie(n.input[0], n.output[0])

    tensors = [t for t in shapes if channels(t) is not None]
    kept: dict[str, set[int]] = defaultdict(set)
    width = {tied.find(t): channels(t) for t in tensors}

    def keep_all(t: str) -> None:
        c = channels(t)
        if c is not None:
            kept[tied.find(t)] |= set(range(c))

    # a tensor is sliceable only when every writer and reader of its tied set is understood
    for t in [*(i.name for i in graph.input), *(o.name for o in graph.output)]:
        keep_all(t)
    producer = {o: n for n in graph.node for o in n.output}
    for t in tensors:
        p = producer.get(t)
        if p is None or not (p.op_type in ("Conv", "Concat") or p.op_type in CHANNEL_WISE) \
                or (p.op_type == "Conv" and p.input[1] not in weights) \
                or (p.op_type == "Conv" and _attr(p, "group", 1) > 1 and id(p) not in depthwise) \
                or (p.op_type == "Concat" and _attr(p, "axis", 0) not in (1, -3)):
            keep_all(t)
        for r in readers.get(t, []):
            understood = r.op_type in SHAPE_ONLY or r.op_type in CHANNEL_WISE or id(r) in depthwise \
                or (r.op_type == "Conv" and _attr(r, "group", 1) == 1 and r.input[1] in weights
                    and r.input[0] == t) \
                or (r.op_type == "Concat" and _attr(r, "axis", 0) in (1, -3))
            if r.op_type in CHANNEL_WISE:
                # a broadcast operand of another rank, or one not tied, cannot be followed
                understood = all(not x or x in weights or channels(x) is None or channels(x) == 1
                                 or tied.find(x) == tied.find(t) for x in r.input)
                understood &= all(x not in weights or _broadcasts(weights[x], channels(t)) for x in r.input if x)
            if not understood:
                keep_all(t)

    changed = True
    while changed:
        changed = False
        for n in convs:
            if id(n) in depthwise or _attr(n, "group", 1) != 1:
                continue
            out_kept = sorted(kept[tied.find(n.output[0])])
            w = weights[n.input[1]]
            need = set(np.flatnonzero(np.any(w[out_kept] != 0, axis=(0, 2, 3))).tolist()) if out_kept else set()
            g = tied.find(n.input[0])
            if not need <= kept[g]:
                kept[g] |= need
                changed = True
        for n in graph.node:
            if n.op_type != "Concat" or channels(n.output[0]) is None:
                continue
            g_out, off = tied.find(n.output[0]), 0
            for t in n.input:
                c = channels(t)
                if c is None:
                    break
                g_in = tied.find(t)
                down = {k - off for k in kept[g_out] if off <= k < off + c}
                up = {k + off for k in kept[g_in]}
                if not down <= kept[g_in] or not up <= kept[g_out]:
                    kept[g_in] |= down
                    kept[g_out] |= up
                    changed = True
                off += c

    selection: dict[str, list[int]] = {}
    for g, c in width.items():
        if c is None:
            continue
        sel = sorted(kept[g]) or [0]   # a tensor keeps at least one channel
        if len(sel) < c:
            selection[g] = sel
    names = {i.name for i in graph.initializer}
    changed_convs = 0

    def replace(node: onnx.NodeProto, slot: int, array: np.ndarray) -> None:
        name = f"{node.input[slot]}.pruned"
        while name in names:
            name += "_"
        names.add(name)
        graph.initializer.append(numpy_helper.from_array(array.astype(weights[node.input[slot]].dtype), name))
        node.input[slot] = name

    for n in graph.node:
        if n.op_type == "Conv" and n.input[1] in weights:
            sel_out = selection.get(tied.find(n.output[0]))
            sel_in = selection.get(tied.find(n.input[0]))
            if sel_out is None and sel_in is None:
                continue
            w = weights[n.input[1]]
            b = weights.get(n.input[2]) if len(n.input) > 2 and n.input[2] else None
            if id(n) in depthwise:
                both = sel_out if sel_out is not None else sel_in
                assert both is not None
                w = w[both]
                b = b[both] if b is not None else None
                for a in n.attribute:
                    if a.name == "group":
                        a.i = len(both)
            else:
                if sel_out is not None:
                    w = w[sel_out]
                    b = b[sel_out] if b is not None else None
                if sel_in is not None:
                    w = w[:, sel_in]
            replace(n, 1, w)
            if b is not None:
                replace(n, 2, b)
            changed_convs += 1
        elif n.op_type in CHANNEL_WISE and (kept_here := selection.get(tied.find(n.output[0]))) is not None:
            for slot, x in enumerate(n.input):
                if x in weights and weights[x].ndim == 4 and weights[x].shape[1] > 1:
                    replace(n, slot, weights[x][:, kept_here])
    used = {t for n in graph.node for t in n.input}
    for init in [i for i in graph.initializer if i.name not in used]:
        graph.initializer.remove(init)
    del graph.value_info[:]
    onnx.checker.check_model(model)
    weights = {i.name: numpy_helper.to_array(i) for i in graph.initializer}
    shapes_after = _shapes(model)
    out_channels = [(n.input[1], n.output[0]) for n in graph.node if n.op_type == "Conv" and n.input[1] in weights]
    before = sum(int(np.asarray(shapes[o])[1]) for _, o in out_channels if o in shapes)
    after = sum(int(weights[w].shape[0]) for w, _ in out_channels)
    return Pruned(before, after, macs_before, _macs(model, shapes_after, weights), changed_convs)
