"""bench_depth_role across machines: a lost work folder is refused or trained again by the table's
recipe, the report says whether its arms stand on the table's own runs, and seeds scored earlier
are kept."""

import json

import pytest

from benchmarks.archive import bench_depth_role as role
from benchmarks.ledger import Ledger
from bsn_edge.train import Run

EXPERIMENT = {"steps": 3000, "finetune_steps": 600, "finetune_lr": 0.0001, "teacher_steps": 3000, "batch_size": 8,
              "size": [128, 256], "train_clips_per_style": 8, "test_clips_per_style": 2, "frames_per_clip": 200,
              "models": {"BSN": "shared-light", "BSN-D": "shared-light-d", "BSN-KD": "shared-light-kd"}}
REPORT = "bsn_accuracy_shared-light_depth_role"


def arm_scores(iou: float) -> dict:
    part = {"iou": iou, "ap": iou + 0.1, "clips": {"town_8": {"iou": iou, "ap": iou + 0.1}}}
    return {a: {"table": part, "more": part} for a in role.ARMS}


@pytest.fixture
def table(tmp_path):
    """A results folder with the table's ledger (BSN and BSN-D town seed 2 recorded) and an empty work folder."""
    out, work = tmp_path / "results", tmp_path / "work"
    led = Ledger(out / "bsn_accuracy_shared-light_ledger.json", EXPERIMENT)
    led.put("teacher", {"val_miou": [0.4567, 0.5901]})
    led.put("BSN/town/seed2", {"test": {"town": {"iou": 0.2357}}})
    led.put("BSN-D/town/seed2", {"test": {"town": {"iou": 0.2149}}})
    for d in ("test", "test_more"):
        (work / d).mkdir(parents=True)
    return out, work


def keep_run(work, seed, name):
    run = work / "runs" / f"seed{seed}" / f"{name}_town"
    run.mkdir(parents=True)
    Run(run).model_path.write_bytes(b"weights")


def test_lost_runs_are_refused_without_retrain_naming_them_and_nothing_is_written(table, capsys):
    out, work = table
    (out / f"{REPORT}.json").write_text("{}")
    assert role.main(["--family", "shared-light", "--out", str(out), "--work", str(work), "--seeds", "2"]) == 2
    said = capsys.readouterr().out
    assert "seed2/shared-light_town" in said and "seed2/shared-light-d_town" in said and "--retrain" in said
    assert (out / f"{REPORT}.json").read_text() == "{}"


def test_retrain_trains_each_lost_run_by_the_tables_recipe_and_seed(table, monkeypatch):
    out, work = table
    keep_run(work, 2, "shared-light")                    # BSN kept, BSN-D lost
    trained, prepared = [], []
    monkeypatch.setattr(role, "prepare", lambda w, ex: prepared.append(w) or (w / "train", w / "test", None))
    monkeypatch.setattr(role, "train_run", lambda data, run, sets: trained.append((data, run, sets)))
    monkeypatch.setattr(role, "seed_arms", lambda ex, w, sd, style, tests, oracle: (arm_scores(0.2), {}))
    assert role.main(["--family", "shared-light", "--out", str(out), "--work", str(work), "--seeds", "2",
                      "--retrain"]) == 0
    assert prepared == [work]
    [(data, run, sets)] = trained
    assert data == work / "train" and run == work / "runs" / "seed2" / "shared-light-d_town"
    assert 'model.name="shared-light-d"' in sets and "train.seed=2" in sets and "train.steps=3000" in sets
    assert 'data.train_styles=["town"]' in sets
    assert any(s.startswith("teacher.checkpoint=") and "runs/teacher/teacher" in s for s in sets)


def test_the_report_says_whether_the_arms_stand_on_the_tables_own_runs():
    led = Ledger.__new__(Ledger)
    led.runs = {"BSN/town/seed2": {"test": {"town": {"iou": 0.2357}}},
                "BSN-D/town/seed2": {"test": {"town": {"iou": 0.2149}}}}
    scores = {"BSN": {"table": {"iou": 0.23571}}, "BSN-D": {"table": {"iou": 0.2601}}}
    check = role.source_check(led, scores, 2, "town")
    assert check["BSN"] == {"table": 0.2357, "here": 0.2357, "same_run": True}
    assert check["BSN-D"] == {"table": 0.2149, "here": 0.2601, "same_run": False}
    assert role.source_check(led, scores, 3, "town")["BSN"]["same_run"] is None     # the table has no such run


def test_seeds_scored_earlier_are_kept_and_a_seed_asked_again_is_replaced(table, monkeypatch):
    out, work = table
    keep_run(work, 2, "shared-light")
    keep_run(work, 2, "shared-light-d")
    old = {"family": "shared-light", "style": "town", "seeds": [1, 2], "tests": ["table", "more"],
           "measured_at": "2026-11-20T10:00:00+0000",
           "scores": {"1": arm_scores(0.30), "2": arm_scores(0.99)}, "val_iou": {"1": {"BSN oracle": [0.4]}}}
    (out / f"{REPORT}.json").write_text(json.dumps(old))
    monkeypatch.setattr(role, "seed_arms", lambda ex, w, sd, style, tests, oracle: (arm_scores(0.20), {}))
    assert role.main(["--family", "shared-light", "--out", str(out), "--work", str(work), "--seeds", "2"]) == 0
    new = json.loads((out / f"{REPORT}.json").read_text())
    assert new["seeds"] == [1, 2]
    assert new["scores"]["1"]["BSN"]["table"]["iou"] == 0.30 and new["scores"]["2"]["BSN"]["table"]["iou"] == 0.20
    assert new["val_iou"]["1"] == {"BSN oracle": [0.4]} and new["scored"]["1"] == "2026-11-20T10:00:00+0000"
    # both source runs scored 0.20 on the table's clips, which recorded 0.2357 and 0.2149: trained again
    assert new["source_runs"]["2"]["BSN"]["same_run"] is False
    md = (out / f"{REPORT}.md").read_text()
    assert "seeds 1, 2" in md and "| BSN | 0.250 +- 0.071 | 0.350 +- 0.071 |" in md
    assert "BSN 0.2 / 0.2357 (trained again by the table's recipe)" in md
    assert new["teacher"]["2"] == {"table": 0.5901, "here": None}      # no teacher in this work folder


def test_an_earlier_report_of_another_style_is_not_mixed_in(table, monkeypatch):
    out, work = table
    for name in ("shared-light", "shared-light-d"):
        keep_run(work, 2, name)
    other = {"family": "shared-light", "style": "suburb", "tests": ["table", "more"], "scores": {"1": arm_scores(0.3)}}
    (out / f"{REPORT}.json").write_text(json.dumps(other))
    monkeypatch.setattr(role, "seed_arms", lambda ex, w, sd, style, tests, oracle: (arm_scores(0.2), {}))
    assert role.main(["--family", "shared-light", "--out", str(out), "--work", str(work), "--seeds", "2"]) == 0
    assert json.loads((out / f"{REPORT}.json").read_text())["seeds"] == [2]
