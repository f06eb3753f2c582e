"""The architecture table keeps one arithmetic: a sitting that would train its runs in another is
refused before it trains, and says why."""

import json

import pytest

import bsn_edge.train.device as train_device
from bsn_edge.benchmarks import bench_arch
from bsn_edge.benchmarks.bench_arch import arithmetic_clash, trained_in
from bsn_edge.benchmarks.ledger import Ledger
from bsn_edge.card import UNRECORDED

EXPERIMENT = {"steps": 12000, "batch_size": 8, "size": [128, 256], "clips": [], "teacher": "T"}


def record(*precision: str) -> dict:
    return {"iou": 0.4, "curve": {"precision": list(precision)} if precision else {}}


def ledger_with(tmp_path, runs: dict) -> Ledger:
    ledger = Ledger(tmp_path / "r_ledger.json", EXPERIMENT)
    for key, rec in runs.items():
        ledger.put(key, rec)
    return ledger


def test_a_clash_only_where_every_recorded_run_was_trained_in_another_arithmetic(tmp_path):
    bf16 = ledger_with(tmp_path / "a", {"unet/seed0": record("bf16"), "small/seed0": record()})
    assert trained_in(bf16.runs.values()) == sorted(["bf16", UNRECORDED])
    why = arithmetic_clash(bf16, "fp32")
    assert why is not None and "trains in fp32" in why and "trained in bf16" in why and "--mixed-arithmetic" in why
    assert arithmetic_clash(bf16, "bf16") is None
    mixed = ledger_with(tmp_path / "b", {"unet/seed0": record("bf16", "fp32")})
    assert arithmetic_clash(mixed, "fp32") is None
    assert arithmetic_clash(ledger_with(tmp_path / "c", {"unet/seed0": record()}), "fp32") is None
    assert arithmetic_clash(ledger_with(tmp_path / "d", {}), "fp32") is None


class WouldTrainError(Exception):
    pass


def refuse_to_train(*_args, **_kwargs):
    raise WouldTrainError


@pytest.fixture
def fp32_cpu(monkeypatch):
    monkeypatch.setattr(train_device, "cpu_has_native_bf16", lambda: False)
    monkeypatch.setattr(bench_arch, "train_seeds", refuse_to_train)


def argv(tmp_path, *extra: str) -> list[str]:
    (tmp_path / "clips").mkdir(exist_ok=True)
    return ["--out", str(tmp_path), "--report", "r", "--data", str(tmp_path / "clips"), "--train-steps", "12000",
            "--teacher", "T", "--only", "medium", "--seeds", "2", "--work", str(tmp_path / "work"), *extra]


def test_a_sitting_that_would_mix_arithmetic_is_refused_before_it_trains(tmp_path, fp32_cpu, capsys):
    ledger = ledger_with(tmp_path, {"medium/seed0": record("bf16"), "medium/seed1": record("bf16")})
    before = ledger.path.read_bytes()
    assert bench_arch.main(argv(tmp_path)) == 2
    out = capsys.readouterr().out
    assert "trains in fp32" in out and "medium/seed2 left to train" in out
    assert ledger.path.read_bytes() == before and not (tmp_path / "work").exists()
    with pytest.raises(WouldTrainError):
        bench_arch.main(argv(tmp_path, "--mixed-arithmetic"))


def test_a_sitting_with_nothing_left_to_train_is_not_refused(tmp_path, fp32_cpu):
    ledger_with(tmp_path, {"medium/seed2": record("bf16")})
    with pytest.raises(WouldTrainError):                       # it goes on to the report (training nothing)
        bench_arch.main(argv(tmp_path))
    assert json.loads((tmp_path / "r_ledger.json").read_text())["runs"]["medium/seed2"]["iou"] == 0.4
