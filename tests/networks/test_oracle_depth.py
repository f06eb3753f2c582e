"""The ground-truth depth oracle (a research arm): B reads the depth it is given in place of D's,
and nothing that would put such a model in a car (export, adaptation) accepts it."""

import pytest
import torch

from bsn_edge.adapt import AdaptError, adapt
from bsn_edge.cli import export as export_cli
from bsn_edge.networks import MAX_DEPTH_M, create_model, depth_feature
from bsn_edge.networks.bsn import given_depth_feature
from bsn_edge.train import Run
from bsn_edge.train.validation import given_depth
from tests.cards import card_for

PAIRS = [("small-light", "small-light-oracle"), ("shared-light", "shared-light-oracle")]


def _pair(plain_name: str, oracle_name: str):
    torch.manual_seed(0)
    plain = create_model(plain_name).eval()
    oracle = create_model(oracle_name).eval()
    oracle.load_state_dict(plain.state_dict())      # the same parameters: only what B reads differs
    return plain, oracle


def _ds_depth(model, x: torch.Tensor) -> torch.Tensor:
    """D's depth at the size B reads it, for ``x`` already at the networks' input scale."""
    if hasattr(model, "predict_coarse"):
        return model.predict_coarse(x)[1].exp()
    return model.depth_net(x)


@pytest.mark.parametrize("plain_name, oracle_name", PAIRS)
def test_given_ds_own_depth_the_oracle_is_the_plain_model(plain_name, oracle_name):
    plain, oracle = _pair(plain_name, oracle_name)
    x = torch.randn(2, 3, 64, 128)
    with torch.no_grad():
        truth = _ds_depth(plain, x)
        want = plain.predict(x)
        got = oracle.predict(x, truth)
    for a, b in zip(want, got, strict=True):
        torch.testing.assert_close(a, b, rtol=1e-5, atol=1e-5)


@pytest.mark.parametrize("plain_name, oracle_name", PAIRS)
def test_the_oracle_reads_the_given_depth_and_d_still_predicts(plain_name, oracle_name):
    plain, oracle = _pair(plain_name, oracle_name)
    x = torch.randn(1, 3, 64, 128)
    near, far = torch.full((1, 1, 64, 128), 2.0), torch.full((1, 1, 64, 128), 60.0)
    with torch.no_grad():
        a_logits, a_depth, _ = oracle(x, near)
        b_logits, b_depth, _ = oracle(x, far)
        _, plain_depth, _ = plain(x)
    assert not torch.allclose(a_logits, b_logits)
    torch.testing.assert_close(a_depth, b_depth)
    torch.testing.assert_close(a_depth, plain_depth)


def test_missing_ground_truth_reads_as_the_far_end():
    depth = torch.tensor([[[[0.0, 5.0], [0.1, 500.0]]]])
    got = given_depth_feature(depth, (2, 2))
    # 0 is "no depth" (sky): the far end; values outside D's range are held to it
    want = depth_feature(torch.tensor([[[[MAX_DEPTH_M, 5.0], [0.5, MAX_DEPTH_M]]]]))
    torch.testing.assert_close(got, want)
    # a smaller size averages the feature over each block
    torch.testing.assert_close(given_depth_feature(depth, (1, 1)), want.mean().reshape(1, 1, 1, 1))
    assert abs(float(depth_feature(torch.tensor(10.0))) - 0.5) < 1e-7    # 10 / (10 + 10)


def test_each_model_takes_only_the_depth_it_reads():
    plain, oracle = _pair("shared-light", "shared-light-oracle")
    x = torch.randn(1, 3, 64, 128)
    with pytest.raises(ValueError, match="ground-truth depth"):
        oracle(x)
    with pytest.raises(ValueError, match="only an oracle_depth model"):
        plain(x, torch.ones(1, 1, 64, 128))
    with pytest.raises(ValueError, match="needs use_depth"):
        type(plain)(use_depth=False, oracle_depth=True)


def test_the_trainer_hands_the_batchs_depth_to_the_oracle_only():
    plain, oracle = _pair("shared-light", "shared-light-oracle")
    batch = {"depth": torch.ones(1, 1, 8, 8)}
    assert given_depth(plain, batch) is None
    assert given_depth(oracle, batch) is batch["depth"]
    wrapped = torch.nn.Module()
    wrapped.module = oracle                          # as DistributedDataParallel holds it
    assert given_depth(wrapped, batch) is batch["depth"]


@pytest.fixture
def oracle_run(tmp_path):
    """An (untrained) oracle run folder as bsn-train writes it."""
    torch.manual_seed(0)
    card = card_for((64, 128), variant="shared-light-oracle", threshold=0.4)
    fields = {k: getattr(card, k) for k in ("variant", "spec", "input_size", "threshold", "camera", "depth_range",
                                            "config_digest")}
    Run(tmp_path / "run").save(create_model("shared-light-oracle"), fields, {"step": 0})
    return tmp_path / "run"


def test_an_oracle_run_is_not_exported(oracle_run, tmp_path, capsys):
    out = tmp_path / "model.onnx"
    assert export_cli.main(["--checkpoint", str(oracle_run), "--out", str(out)]) != 0
    assert "ground-truth depth" in capsys.readouterr().err
    assert not out.exists()


def test_an_oracle_run_is_not_adapted(oracle_run, tmp_path):
    with pytest.raises(AdaptError, match="cannot be adapted: its B reads ground-truth depth"):
        adapt(oracle_run, [tmp_path / "any.mp4"], tmp_path / "adapted")
    assert not (tmp_path / "adapted").exists()
