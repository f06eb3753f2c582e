"""Structured pruning at export: exactly the channels nothing reads leave the graph, and the outputs stay.

The truth is built in by hand: small networks with chosen channels zeroed on both sides (their
producer's row and every reader's column), so the pruned weight shapes are known in advance, and
channels that look dead but are still read (a constant channel through its bias) must stay.
"""

from pathlib import Path

import numpy as np
import onnx
import pytest
import torch
from onnx import numpy_helper
from torch import nn

from bsn_edge.export.fused import export_fused
from bsn_edge.export.prune import prune
from bsn_edge.modelfile.read import session
from bsn_edge.train.run import Run
from tests.cards import card_for

DEFAULT_RUN = Path(__file__).resolve().parents[2] / "models" / "default"


class Net(nn.Module):
    """conv a (3->8) -> relu -> depthwise -> conv b (8->6); a residual sum with conv r; a channel concat
    with conv c (3->4); conv d reads the concat; the output is d's and a's first channel."""

    def __init__(self) -> None:
        super().__init__()
        self.a = nn.Conv2d(3, 8, 3, padding=1)
        self.dw = nn.Conv2d(8, 8, 3, padding=1, groups=8)
        self.b = nn.Conv2d(8, 6, 1)
        self.r = nn.Conv2d(3, 6, 3, padding=1)
        self.c = nn.Conv2d(3, 4, 1)
        self.d = nn.Conv2d(10, 2, 3, padding=1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        h = torch.relu(self.dw(torch.relu(self.a(x))))
        s = torch.relu(self.b(h) + self.r(x))
        cat = torch.cat([s, torch.relu(self.c(x))], dim=1)
        return self.d(cat)


def _dead(net: Net) -> Net:
    """Zero, on both sides: a's channels 2 and 5 (nothing reads them past the depthwise); the residual
    stream's channel 1 (b, r and d's column 1); c's channel 3 (d's column 6 + 3). a's channel 4 gets zero
    weights but a bias, and b reads it: a constant channel still read, which must stay."""
    with torch.no_grad():
        for c in (2, 5):
            net.a.weight[c] = 0
            net.a.bias[c] = 0
            net.b.weight[:, c] = 0
        net.a.weight[4] = 0
        net.a.bias[4] = 0.7
        net.b.weight[0, 4] = 0.5
        for conv in (net.b, net.r):
            conv.weight[1] = 0
            conv.bias[1] = 0
        net.d.weight[:, 1] = 0
        net.d.weight[:, 6 + 3] = 0
        net.c.weight[3] = 0
        net.c.bias[3] = 0
    return net


def _onnx(net: nn.Module, path: Path) -> onnx.ModelProto:
    torch.onnx.export(net.eval(), (torch.zeros(1, 3, 16, 16),), str(path), input_names=["x"], output_names=["y"],
                      opset_version=17, dynamo=False)
    return onnx.load(str(path))


def _weights(model: onnx.ModelProto) -> dict[str, tuple[int, ...]]:
    """Each convolution's weight shape, by the torch module it came from."""
    init = {i.name: numpy_helper.to_array(i).shape for i in model.graph.initializer}
    return {n.name.strip("/").split("/")[0]: init[n.input[1]] for n in model.graph.node if n.op_type == "Conv"}


def _run(model: onnx.ModelProto, x: np.ndarray) -> np.ndarray:
    return session(model.SerializeToString()).run(None, {"x": x})[0]


def test_exactly_the_unread_channels_leave_and_the_outputs_stay(tmp_path):
    torch.manual_seed(0)
    model = _onnx(_dead(Net()), tmp_path / "net.onnx")
    x = np.random.default_rng(0).normal(size=(1, 3, 16, 16)).astype(np.float32)
    before = _run(model, x)
    report = prune(model)
    shapes = _weights(model)
    assert shapes["a"] == (6, 3, 3, 3)        # 2 and 5 gone, the constant channel 4 kept
    assert shapes["dw"] == (6, 1, 3, 3)
    assert shapes["b"] == (5, 6, 1, 1)        # the residual stream's channel 1 gone
    assert shapes["r"] == (5, 3, 3, 3)
    assert shapes["c"] == (3, 3, 1, 1)
    assert shapes["d"] == (2, 8, 3, 3)        # 10 - the stream's 1 - c's 1
    assert (report.channels_before, report.channels_after) == (8 + 8 + 6 + 6 + 4 + 2, 6 + 6 + 5 + 5 + 3 + 2)
    assert report.macs_after < report.macs_before
    np.testing.assert_allclose(_run(model, x), before, rtol=1e-5, atol=1e-5)


def test_a_channel_read_by_an_op_it_cannot_follow_stays(tmp_path):
    class Flat(nn.Module):
        def __init__(self) -> None:
            super().__init__()
            self.a = nn.Conv2d(3, 4, 1)
            self.b = nn.Conv2d(4, 2, 1)

        def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
            h = self.a(x)
            return self.b(h), h.flatten(1).sum(1)

    net = Flat()
    with torch.no_grad():
        net.a.weight[1] = 0
        net.b.weight[:, 1] = 0
    path = tmp_path / "flat.onnx"
    torch.onnx.export(net.eval(), (torch.zeros(1, 3, 8, 8),), str(path), input_names=["x"],
                      output_names=["y", "z"], opset_version=17, dynamo=False)
    model = onnx.load(str(path))
    report = prune(model)
    assert _weights(model)["a"] == (4, 3, 1, 1)
    assert report.channels_after == report.channels_before


@pytest.mark.skipif(not (DEFAULT_RUN / "model.pt").is_file(), reason="the default run's weights are not here")
def test_the_default_run_pruned_computes_what_it_computed(tmp_path):
    model, card = Run(DEFAULT_RUN).load_model()
    card = card_for((64, 128), card.variant)
    pruned = export_fused(model, tmp_path / "p.onnx", card)
    export_fused(model, tmp_path / "u.onnx", card, prune_dead=False)
    assert pruned.pruned is not None and pruned.pruned.channels_after < 0.3 * pruned.pruned.channels_before
    a, b = session(tmp_path / "p.onnx"), session(tmp_path / "u.onnx")
    rng = np.random.default_rng(1)
    for _ in range(3):
        f = rng.integers(0, 256, (1, 64, 128, 3), dtype=np.uint8)
        for x, y in zip(a.run(None, {"frame": f}), b.run(None, {"frame": f}), strict=True):
            np.testing.assert_allclose(x, y, rtol=1e-4, atol=1e-5)
