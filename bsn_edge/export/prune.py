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


class _Channels:
    """One graph's channel bookkeeping: which tensors are tied, which channels each tied set must keep."""

    def __init__(self, model: onnx.ModelProto) -> None:
        self.model, self.graph = model, model.graph
        self.weights = {i.name: numpy_helper.to_array(i) for i in self.graph.initializer}
        self.shapes = _shapes(model)
        self.tied = _Tied()
        self.convs = [n for n in self.graph.node if n.op_type == "Conv" and n.input[1] in self.weights]
        self.depthwise = {id(n) for n in self.convs if _attr(n, "group", 1) > 1
                          and _attr(n, "group", 1) == self.channels(n.input[0]) == self.channels(n.output[0])
                          and self.weights[n.input[1]].shape[1] == 1}
        self.readers: dict[str, list[onnx.NodeProto]] = defaultdict(list)
        for n in self.graph.node:
            for t in n.input:
                if t:
                    self.readers[t].append(n)
        for n in self.graph.node:
            if n.op_type in CHANNEL_WISE and self.channels(n.output[0]) is not None:
                for t in n.input:
                    if t and self.channels(t) == self.channels(n.output[0]):
                        self.tied.tie(t, n.output[0])
            elif id(n) in self.depthwise:
                self.tied.tie(n.input[0], n.output[0])
        self.kept: dict[str, set[int]] = defaultdict(set)

    def channels(self, t: str) -> int | None:
        s = self.shapes.get(t)
        return s[1] if s is not None and len(s) == 4 and t not in self.weights else None

    def keep_all(self, t: str) -> None:
        c = self.channels(t)
        if c is not None:
            self.kept[self.tied.find(t)] |= set(range(c))

    def _writer_understood(self, p: onnx.NodeProto | None) -> bool:
        if p is None or not (p.op_type in ("Conv", "Concat") or p.op_type in CHANNEL_WISE):
            return False
        if p.op_type == "Conv":
            return p.input[1] in self.weights and (_attr(p, "group", 1) == 1 or id(p) in self.depthwise)
        return p.op_type != "Concat" or _attr(p, "axis", 0) in (1, -3)

    def _reader_understood(self, r: onnx.NodeProto, t: str) -> bool:
        if r.op_type in CHANNEL_WISE:
            # a broadcast operand of another rank, or one not tied, cannot be followed
            return all(not x or x in self.weights or self.channels(x) in (None, 1)
                       or self.tied.find(x) == self.tied.find(t) for x in r.input) \
                and all(x not in self.weights or _broadcasts(self.weights[x], self.channels(t)) for x in r.input if x)
        return r.op_type in SHAPE_ONLY or id(r) in self.depthwise \
            or (r.op_type == "Conv" and _attr(r, "group", 1) == 1 and r.input[1] in self.weights and r.input[0] == t) \
            or (r.op_type == "Concat" and _attr(r, "axis", 0) in (1, -3))

    def pin(self) -> None:
        """Every channel of a tied set that the graph's inputs or outputs hold, or that a writer or reader this
        module does not follow touches, is kept."""
        for t in [*(i.name for i in self.graph.input), *(o.name for o in self.graph.output)]:
            self.keep_all(t)
        producer = {o: n for n in self.graph.node for o in n.output}
        for t in [t for t in self.shapes if self.channels(t) is not None]:
            if not self._writer_understood(producer.get(t)) \
                    or not all(self._reader_understood(r, t) for r in self.readers.get(t, [])):
                self.keep_all(t)

    def _grow(self, g: str, more: set[int]) -> bool:
        if more <= self.kept[g]:
            return False
        self.kept[g] |= more
        return True

    def propagate(self) -> None:
        """Until nothing changes: a convolution's input keeps the columns any kept output row reads
        (a weight not exactly zero); a concatenation's parts keep what the whole keeps, and back."""
        changed = True
        while changed:
            changed = False
            for n in self.convs:
                if id(n) in self.depthwise or _attr(n, "group", 1) != 1:
                    continue
                rows = sorted(self.kept[self.tied.find(n.output[0])])
                w = self.weights[n.input[1]]
                need = set(np.flatnonzero(np.any(w[rows] != 0, axis=(0, 2, 3))).tolist()) if rows else set()
                changed |= self._grow(self.tied.find(n.input[0]), need)
            for n in self.graph.node:
                if n.op_type == "Concat" and self.channels(n.output[0]) is not None:
                    changed |= self._concat(n)

    def _concat(self, n: onnx.NodeProto) -> bool:
        g_out, off, changed = self.tied.find(n.output[0]), 0, False
        for t in n.input:
            c = self.channels(t)
            if c is None:
                break
            g_in = self.tied.find(t)
            changed |= self._grow(g_in, {k - off for k in self.kept[g_out] if off <= k < off + c})
            changed |= self._grow(g_out, {k + off for k in self.kept[g_in]})
            off += c
        return changed

    def selection(self) -> dict[str, list[int]]:
        """The channels each tied set keeps, for those that lose any (each keeps at least one)."""
        out = {}
        for t in self.shapes:
            c = self.channels(t)
            if c is not None:
                sel = sorted(self.kept[self.tied.find(t)]) or [0]
                if len(sel) < c:
                    out[self.tied.find(t)] = sel
        return out

    def rewrite(self, selection: dict[str, list[int]]) -> int:
        """Slice every convolution (and channel-wise constant) by ``selection``; returns the convolutions
        changed. Unused weights are dropped and shapes left to be inferred again."""
        names = {i.name for i in self.graph.initializer}
        changed = 0

        def replace(node: onnx.NodeProto, slot: int, array: np.ndarray) -> None:
            name = f"{node.input[slot]}.pruned"
            while name in names:
                name += "_"
            names.add(name)
            self.graph.initializer.append(
                numpy_helper.from_array(array.astype(self.weights[node.input[slot]].dtype), name))
            node.input[slot] = name

        for n in self.graph.node:
            if n.op_type == "Conv" and n.input[1] in self.weights:
                sel_out = selection.get(self.tied.find(n.output[0]))
                sel_in = selection.get(self.tied.find(n.input[0]))
                if sel_out is None and sel_in is None:
                    continue
                w, b = self._sliced(n, sel_out, sel_in)
                replace(n, 1, w)
                if b is not None:
                    replace(n, 2, b)
                changed += 1
            elif n.op_type in CHANNEL_WISE and (kept := selection.get(self.tied.find(n.output[0]))) is not None:
                for slot, x in enumerate(n.input):
                    if x in self.weights and self.weights[x].ndim == 4 and self.weights[x].shape[1] > 1:
                        replace(n, slot, self.weights[x][:, kept])
        used = {t for n in self.graph.node for t in n.input}
        for init in [i for i in self.graph.initializer if i.name not in used]:
            self.graph.initializer.remove(init)
        del self.graph.value_info[:]
        return changed

    def _sliced(self, n: onnx.NodeProto, sel_out: list[int] | None,
                sel_in: list[int] | None) -> tuple[np.ndarray, np.ndarray | None]:
        w = self.weights[n.input[1]]
        b = self.weights.get(n.input[2]) if len(n.input) > 2 and n.input[2] else None
        if id(n) in self.depthwise:          # one channel in, one out: the group shrinks with them
            both = sel_out if sel_out is not None else sel_in
            assert both is not None
            for a in n.attribute:
                if a.name == "group":
                    a.i = len(both)
            return w[both], (b[both] if b is not None else None)
        if sel_out is not None:
            w, b = w[sel_out], (b[sel_out] if b is not None else None)
        if sel_in is not None:
            w = w[:, sel_in]
        return w, b


def prune(model: onnx.ModelProto) -> Pruned:
    """Remove from ``model`` (an fp32 graph, edited in place) every convolution output channel that
    nothing reads; returns what was removed."""
    ch = _Channels(model)
    macs_before = _macs(model, ch.shapes, ch.weights)
    ch.pin()
    ch.propagate()
    changed = ch.rewrite(ch.selection())
    onnx.checker.check_model(model)
    weights = {i.name: numpy_helper.to_array(i) for i in model.graph.initializer}
    out_channels = [(n.input[1], n.output[0]) for n in model.graph.node
                    if n.op_type == "Conv" and n.input[1] in weights]
    before = sum(int(ch.shapes[o][1]) for _, o in out_channels if o in ch.shapes)
    after = sum(int(weights[w].shape[0]) for w, _ in out_channels)
    return Pruned(before, after, macs_before, _macs(model, _shapes(model), weights), changed)
