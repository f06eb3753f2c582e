"""The seeded benchmarks' ledger: runs survive a stop, another experiment is refused, and the
table's statistics match values worked out by hand."""

import json

import pytest

from bsn_edge.benchmarks.bench_bsn_accuracy import markdown, table
from bsn_edge.benchmarks.ledger import Ledger, exceeds_spread, fmt, mean_std

EXPERIMENT = {"steps": 3000, "size": [128, 256],
              "models": {"BSN": "small-light", "BSN-D": "small-light-d", "BSN-KD": "small-light-kd"}}


def test_a_run_put_is_on_disk_at_once_and_read_back_by_the_next_sitting(tmp_path):
    path = tmp_path / "results" / "t_ledger.json"
    a = Ledger(path, EXPERIMENT)
    a.put("BSN/town/seed0", {"test": {"town": {"iou": 0.41}}})
    on_disk = json.loads(path.read_text())
    assert on_disk["runs"]["BSN/town/seed0"]["test"]["town"]["iou"] == 0.41
    b = Ledger(path, dict(EXPERIMENT))
    assert "BSN/town/seed0" in b and "BSN/town/seed1" not in b
    assert b.get("BSN/town/seed0") == {"test": {"town": {"iou": 0.41}}}


def test_another_experiment_is_refused_naming_what_differs_and_fresh_starts_over(tmp_path):
    path = tmp_path / "t_ledger.json"
    Ledger(path, EXPERIMENT).put("k", {"x": 1})
    with pytest.raises(ValueError, match=r"differs in steps.*--fresh"):
        Ledger(path, {**EXPERIMENT, "steps": 2000})
    assert json.loads(path.read_text())["runs"] == {"k": {"x": 1}}      # nothing lost by the refusal
    fresh = Ledger(path, {**EXPERIMENT, "steps": 2000}, fresh=True)
    assert "k" not in fresh


def test_a_damaged_ledger_is_an_error_not_an_empty_table(tmp_path):
    path = tmp_path / "t_ledger.json"
    path.write_text('{"runs": ')
    with pytest.raises(ValueError, match="not a ledger"):
        Ledger(path, EXPERIMENT)


def test_mean_std_and_spread_against_hand_values():
    m, s, n = mean_std([0.40, 0.44, 0.48])
    assert (round(m, 6), round(s, 6), n) == (0.44, 0.04, 3)      # sample std: sqrt(0.0032 / 2)
    # means 0.44 and 0.38, stds 0.04 and 0.01: 0.06 > 0.05, beyond the spread
    assert exceeds_spread([0.40, 0.44, 0.48], [0.37, 0.38, 0.39]) is True
    # means 0.44 and 0.41, stds 0.04 and 0.01: 0.03 < 0.05, within it
    assert exceeds_spread([0.40, 0.44, 0.48], [0.40, 0.41, 0.42]) is False
    assert exceeds_spread([0.4], [0.3, 0.2]) is None
    assert fmt([0.40, 0.44, 0.48]) == "0.440 +- 0.040" and fmt([0.5]) == "0.500 (1 seed)" and fmt([]) == "-"


def test_table_takes_each_cell_from_its_own_seeds(tmp_path):
    led = Ledger(tmp_path / "l.json", EXPERIMENT)
    for seed, (same, cross, ft) in enumerate([(0.50, 0.20, 0.30), (0.54, 0.22, 0.34)]):
        led.put(f"BSN/town/seed{seed}", {"curve": {}, "test": {"town": {"iou": same}, "suburb": {"iou": cross}},
                                         "finetuned": {"suburb": {"iou": ft}}})
    led.put("BSN-D/town/seed0", {"curve": {}, "test": {"town": {"iou": 0.45}, "suburb": {"iou": 0.25}},
                                 "finetuned": {"suburb": {"iou": 0.31}}})
    led.put("baselines/town", {"Traversable": {"iou": 0.1}})
    tab = table(led)
    assert tab["rows"]["BSN"]["town->town"] == [0.50, 0.54]
    assert tab["rows"]["BSN"]["town->suburb"] == [0.20, 0.22]
    assert tab["rows"]["BSN"]["town->suburb ft"] == [0.30, 0.34]
    assert tab["rows"]["BSN"]["suburb->suburb"] == []
    assert tab["rows"]["Traversable"]["suburb->town"] == [0.1]
    d = tab["ablations"]["BSN-D"]["town->town"]
    assert d["bsn_minus"] == pytest.approx(0.07) and d["beyond_spread"] is None   # one seed of BSN-D


def test_the_report_names_the_runs_that_distil_from_a_retrained_teacher(tmp_path):
    led = Ledger(tmp_path / "l.json", {**EXPERIMENT, "test_clips_per_style": 2, "batch_size": 8,
                                       "finetune_steps": 600, "finetune_lr": 1e-4, "teacher_steps": 3000})
    led.put("teacher", {"val_miou": [0.5, 0.59], "flattened": {"gain": 0.008}, "retrained": [[0.585]]})
    rec = {"curve": {}, "test": {"town": {"iou": 0.2}}, "finetuned": {}}
    led.put("BSN/town/seed0", {**rec, "teacher": 0})
    led.put("BSN/suburb/seed0", {**rec, "teacher": 1})
    text = markdown(led, table(led), "f.png")
    assert "validation mIoU 0.590" in text
    line = next(x for x in text.splitlines() if "trained again" in x)
    assert "0.585" in line and line.endswith(": BSN/suburb/seed0")


def test_the_architecture_plot_draws_a_seeded_table_and_the_earlier_single_figure_one(tmp_path):
    from bsn_edge.benchmarks.report import plot_arch
    seeded = {"rows": [{"model": "small-light", "gmacs": 2.45, "fps": 76.3, "iou": "0.420 +- 0.010",
                        "iou_seeds": [0.41, 0.42, 0.43]},
                       {"model": "shared-light", "gmacs": 1.24, "fps": 120.0, "iou": "-", "iou_seeds": []}]}
    earlier = {"rows": [{"model": "unet", "gmacs": 29.47, "fps": 7.89, "iou": 0.2661}]}
    for name, res in (("seeded", seeded), ("earlier", earlier)):
        out = plot_arch(res, tmp_path / f"{name}.png")
        assert out.is_file() and out.stat().st_size > 0


def test_read_opens_any_experiment_and_trained_keys_skip_the_shared_records(tmp_path):
    from bsn_edge.benchmarks.bench_bsn_accuracy import trained_keys
    path = tmp_path / "l.json"
    led = Ledger(path, EXPERIMENT)
    for key in ("teacher", "baselines/town", "BSN-KD/suburb/seed2", "BSN/town/seed0"):
        led.put(key, {})
    again = Ledger.read(path)
    assert again.experiment == EXPERIMENT
    assert trained_keys(again) == [("BSN-KD/suburb/seed2", "BSN-KD", "suburb", 2), ("BSN/town/seed0", "BSN", "town", 0)]
    with pytest.raises(FileNotFoundError, match="no ledger"):
        Ledger.read(tmp_path / "none.json")


def test_the_architecture_table_draws_every_seeds_curve_of_the_architectures_asked(tmp_path):
    from bsn_edge.benchmarks.bench_arch import plot_curves
    led = Ledger(tmp_path / "l.json", {"steps": 6000})
    curve = {"steps": [600, 1200, 1800], "val_iou": [0.2, 0.3, 0.31]}
    for key in ("small-light/seed0", "small-light/seed1", "shared-light/seed0"):
        led.put(key, {"iou": 0.3, "curve": curve})
    assert plot_curves(led, ["small-light", "shared-light"], tmp_path / "c.png")
    assert (tmp_path / "c.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert not plot_curves(led, ["unet"], tmp_path / "none.png") and not (tmp_path / "none.png").exists()


def test_an_architecture_table_trained_one_run_per_sitting_reports_every_row_its_ledger_holds(tmp_path, monkeypatch):
    import bsn_edge.benchmarks.bench_arch as arch
    data, out = tmp_path / "clips", tmp_path / "results"
    for clip in ("town_0", "urban_0"):
        (data / clip).mkdir(parents=True)
        (data / clip / "meta.json").write_text("{}")
    experiment = {"steps": 12000, "batch_size": 8, "size": [128, 256], "clips": ["town_0", "urban_0"],
                  "teacher": "teacher"}
    led = Ledger(out / "heavy_ledger.json", experiment)
    curve = {"steps": [1200, 2400, 12000], "val_iou": [0.2, 0.3, 0.305], "flattened": {"gain": 0.005}}
    led.put("small/seed0", {"iou": 0.41, "curve": {**curve, "precision": ["bf16"]}})
    led.put("small/seed2", {"iou": 0.43, "curve": {**curve, "precision": ["fp32"]}})
    led.put("unet/seed1", {"iou": 0.30, "curve": {**curve, "precision": ["bf16"]}})
    measured = []
    monkeypatch.setattr(arch, "measure_arch", lambda name, *a: measured.append(name) or {
        "model": name, "params_m": 1.0, "gmacs": 2.0, "median_ms": 10.0, "fps": 100.0, "repeats": 1})
    rc = arch.main(["--out", str(out), "--data", str(data), "--train-steps", "12000", "--teacher", "teacher",
                    "--only", "small", "--seeds", "0", "--report", "heavy"])
    assert rc == 0 and measured == ["unet", "small"]          # the ledger's rows too, in the table's order
    res = json.loads((out / "heavy.json").read_text())
    assert res["iou_training"]["seeds"] == [0, 1, 2]
    small = next(r for r in res["rows"] if r["model"] == "small")
    assert small["seeds"] == ["seed0", "seed2"] and small["precision"] == ["bf16", "fp32"]
    md = (out / "heavy.md").read_text()
    assert "| small | 1.0 | 2.0 | 10.0 | 100.0 | 0.420 +- 0.014 (0.410, 0.430) | 2 of 2 |" in md
    assert "| unet | 1.0 | 2.0 | 10.0 | 100.0 | 0.300 (1 seed) | 1 of 1 |" in md
    assert "- `small` - `unet`: +0.120, a side has one seed: not told apart yet" in md


def test_a_run_trained_here_names_the_machine_that_finished_it_and_older_runs_say_not_recorded(tmp_path, monkeypatch):
    import bsn_edge.benchmarks.bench_arch as arch
    data, out = tmp_path / "clips", tmp_path / "results"
    (data / "town_0").mkdir(parents=True)
    (data / "town_0" / "meta.json").write_text("{}")
    experiment = {"steps": 12000, "batch_size": 8, "size": [128, 256], "clips": ["town_0"], "teacher": "teacher"}
    curve = {"steps": [1200, 2400, 12000], "val_iou": [0.2, 0.3, 0.305], "flattened": {"gain": 0.005}}
    Ledger(out / "heavy_ledger.json", experiment).put("small/seed0", {"iou": 0.41, "curve": curve})
    here = {"cpu": "Some Xeon", "isa": ["AVX-512", "AMX"], "cores": 2, "python": "3.11", "platform": "x"}
    trained = []
    monkeypatch.setattr(arch, "machine", lambda: here)
    monkeypatch.setattr(arch, "train_uniform", lambda name, *a: trained.append(name) or tmp_path / name)
    monkeypatch.setattr(arch, "held_out_iou", lambda run, data, report: 0.45)
    monkeypatch.setattr(arch, "run_curve", lambda run: curve)
    monkeypatch.setattr(arch, "measure_arch", lambda name, *a: {
        "model": name, "params_m": 1.0, "gmacs": 2.0, "median_ms": 10.0, "fps": 100.0, "repeats": 1})
    rc = arch.main(["--out", str(out), "--data", str(data), "--train-steps", "12000", "--teacher", "teacher",
                    "--only", "unet", "--seeds", "1", "--report", "heavy"])
    assert rc == 0 and trained == ["unet"]
    assert Ledger.read(out / "heavy_ledger.json").runs["unet/seed1"]["finished_on"] == {
        "cpu": "Some Xeon", "isa": ["AVX-512", "AMX"]}      # what the run needs of the record, not the whole of it
    md = (out / "heavy.md").read_text()
    assert "- Some Xeon (AVX-512, AMX): `unet` seed 1\n- not recorded: `small` seed 0\n" in md


def test_a_sitting_of_known_length_ends_inside_a_run_with_its_state_saved_and_the_next_goes_on(
        tmp_path, monkeypatch, capsys):
    from types import SimpleNamespace

    import bsn_edge.benchmarks.bench_arch as arch
    data, out = tmp_path / "clips", tmp_path / "results"
    (data / "town_0").mkdir(parents=True)
    (data / "town_0" / "meta.json").write_text("{}")
    clock = [0.0]
    calls = []

    def train_run(data, folder, sets, stop_after=None):
        # each call trains 10 minutes; it ends the run only when it was given at least that long
        calls.append((folder.name, stop_after))
        clock[0] += 600.0
        if stop_after is None or stop_after >= 10:
            folder.mkdir(parents=True, exist_ok=True)
            (folder / "checkpoint.json").write_text(json.dumps({"card": {"threshold": 0.3}}))
        return folder

    monkeypatch.setattr(arch, "time", SimpleNamespace(monotonic=lambda: clock[0]))
    monkeypatch.setattr(arch, "train_run", train_run)
    monkeypatch.setattr(arch, "held_out_iou", lambda run, data, report: 0.4)
    monkeypatch.setattr(arch, "run_curve", lambda run: {"steps": [10], "val_iou": [0.4]})
    monkeypatch.setattr(arch, "measure_arch", lambda name, *a: {
        "model": name, "params_m": 1.0, "gmacs": 2.0, "median_ms": 10.0, "fps": 100.0, "repeats": 1})
    argv = ["--out", str(out), "--data", str(data), "--train-steps", "100", "--teacher", "teacher",
            "--only", "small", "unet", "--seeds", "0", "--report", "r", "--work", str(tmp_path / "work")]
    assert arch.main([*argv, "--stop-after", "15"]) == 0
    assert calls == [("small", 15.0), ("unet", 5.0)]       # the second run gets what is left of the sitting
    assert sorted(Ledger.read(out / "r_ledger.json").runs) == ["small/seed0"]
    said = capsys.readouterr().out
    assert f"{tmp_path / 'work' / 'unet'} unfinished" in said
    assert "| small | 1.0 | 2.0 | 10.0 | 100.0 | 0.400 (1 seed) |" in (out / "r.md").read_text()

    calls.clear()
    assert arch.main([*argv, "--stop-after", "15"]) == 0
    assert calls == [("unet", 15.0)]
    assert sorted(Ledger.read(out / "r_ledger.json").runs) == ["small/seed0", "unet/seed0"]
    assert "--stop-after" not in capsys.readouterr().out

    calls.clear()
    argv[argv.index("0")] = "1"
    assert arch.main([*argv, "--stop-after", "10"]) == 0
    assert calls == [("small", 10.0)]                      # the sitting is used up: unet seed 1 is not begun
    assert "small/seed1" in Ledger.read(out / "r_ledger.json").runs
    assert f"{tmp_path / 'work' / 'seed1' / 'unet'} unfinished" in capsys.readouterr().out
    with pytest.raises(SystemExit):
        arch.main([*argv, "--stop-after", "0"])
    assert "--stop-after needs --train-steps and a positive number of minutes, got 0" in capsys.readouterr().err


def test_the_architecture_table_says_which_differences_exceed_the_seeds_spread():
    from bsn_edge.benchmarks.bench_arch import differences
    rows = [{"model": "a", "iou_seeds": [0.40, 0.44, 0.48]}, {"model": "b", "iou_seeds": [0.37, 0.38, 0.39]},
            {"model": "c", "iou_seeds": [0.40, 0.41, 0.42]}, {"model": "d", "iou_seeds": [0.50]},
            {"model": "untrained"}]
    got = {(d["higher"], d["lower"]): (d["difference"], d["beyond_spread"]) for d in differences(rows)}
    # a - b: 0.06 against stds 0.04 + 0.01; a - c: 0.03 against 0.04 + 0.01; c - b: 0.03 against 0.01 + 0.01
    assert got == {("a", "b"): (0.06, True), ("a", "c"): (0.03, False), ("d", "a"): (0.06, None),
                   ("c", "b"): (0.03, True), ("d", "b"): (0.12, None), ("d", "c"): (0.09, None)}


def test_an_architecture_report_refreshed_while_the_machine_trains_takes_its_times_from_an_earlier_one(
        tmp_path, monkeypatch, capsys):
    import torch

    import bsn_edge.benchmarks.bench_arch as arch
    data, out = tmp_path / "clips", tmp_path / "results"
    (data / "town_0").mkdir(parents=True)
    (data / "town_0" / "meta.json").write_text("{}")
    out.mkdir()
    led = Ledger(out / "light_ledger.json", {"steps": 6000, "batch_size": 8, "size": [128, 256], "clips": ["town_0"],
                                             "teacher": "teacher"})
    for seed, iou in ((0, 0.30), (1, 0.32), (2, 0.34)):
        led.put(f"shared-light/seed{seed}", {"iou": iou, "curve": {"steps": [600], "val_iou": [0.3]}})
    machine = {"cpu": "Other CPU", "isa": ["AVX2"], "cores": 2, "python": "3.11", "platform": "x"}
    earlier = {"benchmark": "light", "measured_at": "2026-11-01T10:00:00+0000", "machine": machine, "size": [256, 512],
               "threads": 2, "rows": [{"model": "shared-light", "params_m": 9.0, "gmacs": 9.0, "median_ms": 7.5,
                                       "fps": 133.33, "repeats": 30}]}
    (out / "light.json").write_text(json.dumps(earlier))
    from bsn_edge.benchmarks import arch_speed

    monkeypatch.setattr(arch_speed, "time_calls", lambda *a, **k: pytest.fail("timed while told not to"))
    monkeypatch.setattr(arch_speed, "create_model", lambda name: torch.nn.Linear(1000, 1000))   # 1,001,000 parameters
    monkeypatch.setattr(arch_speed, "count_gmacs", lambda m, size: 1.5)
    argv = ["--out", str(out), "--data", str(data), "--train-steps", "6000", "--teacher", "teacher",
            "--only", "shared-light", "--seeds", "0", "--report", "light", "--timing-from", str(out / "light.json")]
    assert arch.main(argv) == 0
    res = json.loads((out / "light.json").read_text())
    assert res["timing_from"] == {"report": "light", "measured_at": "2026-11-01T10:00:00+0000", "machine": machine}
    md = (out / "light.md").read_text()
    assert "| shared-light | 1.0 | 1.5 | 7.5 | 133.33 | 0.320 +- 0.020 (0.300, 0.320, 0.340) |" in md
    assert "taken from `light` (measured 2026-11-01T10:00:00+0000 on Other CPU (AVX2)), not timed again" in md
    assert arch.main(argv) == 0     # refreshed again: the times still name where they were measured
    assert json.loads((out / "light.json").read_text())["timing_from"]["machine"] == machine

    led.put("small/seed0", {"iou": 0.4, "curve": {"steps": [600], "val_iou": [0.4]}})
    before = (out / "light.md").read_text()
    capsys.readouterr()
    assert arch.main(argv) == 2     # a row the earlier report never timed
    assert "has no timed row for small" in capsys.readouterr().out
    assert (out / "light.md").read_text() == before
    (out / "bad.json").write_text(json.dumps({**earlier, "size": [128, 256]}))
    assert arch.main([*argv[:-1], str(out / "bad.json")]) == 2
    assert "timed at [128, 256] with 2 threads, not [256, 512]" in capsys.readouterr().out
