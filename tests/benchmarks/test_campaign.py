"""The campaign report's verdict on whether a curve has flattened."""

from bsn_edge.benchmarks.bench_campaign import flattened


def recs(values):
    return [{"step": 1000 * (i + 1), "val_iou": v} for i, v in enumerate(values)]


def test_a_curve_still_rising_in_its_last_fifth_is_not_flat():
    f = flattened(recs([0.2, 0.3, 0.4, 0.45, 0.48, 0.50, 0.52, 0.53, 0.545, 0.56]))
    # last fifth of 10,000 steps: 8,000 < step <= 10,000; best after 0.56, best before 0.53
    assert f["from_step"] == 8000 and abs(f["gain"] - 0.03) < 1e-9 and not f["flat"]


def test_a_curve_that_gains_under_a_hundredth_is_flat_and_a_dip_is_not_a_gain():
    f = flattened(recs([0.2, 0.4, 0.5, 0.55, 0.56, 0.565, 0.567, 0.569, 0.560, 0.572]))
    assert f["flat"] and abs(f["gain"] - 0.003) < 1e-9
    assert flattened(recs([0.3, 0.4])) is None


def test_a_leg_without_teacher_records_draws_no_empty_teacher_panel(tmp_path):
    import cv2

    from bsn_edge.benchmarks.bench_campaign import plot

    student = [{"samples": 8000 * i, "val_iou": 0.4 + 0.01 * i, "val_abs_rel": 0.1, "loss": 0.2, "bce": 0.03,
                "kd": 0.005, "depth": 0.15} for i in range(1, 4)]
    teacher = [{"samples": 8000 * i, "val_road": 0.9, "val_sidewalk": 0.5, "val_vehicle": 0.7, "val_person": 0.3,
                "val_miou": 0.6} for i in range(1, 4)]
    plot([], student, tmp_path / "leg.png", "leg")
    plot(teacher, student, tmp_path / "whole.png", "whole")
    # 5 inches a panel at 90 dpi: two panels for a leg, three with the teacher's curve
    assert cv2.imread(str(tmp_path / "leg.png")).shape[1] == 2 * 5 * 90
    assert cv2.imread(str(tmp_path / "whole.png")).shape[1] == 3 * 5 * 90


def test_a_runs_curve_names_every_arithmetic_its_pieces_trained_in(tmp_path):
    import json

    from bsn_edge.benchmarks.bench_campaign import run_curve

    # a run begun where records did not name their arithmetic, resumed in bf16, then in fp32; step 0
    # (the start's own score) is no training; a teacher record and a loss-only record are not B's curve
    lines = [{"phase": "teacher", "step": 5, "seconds": 1.0, "val_miou": 0.5, "precision": "fp32"},
             {"phase": "train", "step": 0, "seconds": 0.0, "val_iou": 0.1, "precision": "fp32"},
             {"phase": "train", "step": 10, "seconds": 4.0, "val_iou": 0.2},
             {"phase": "train", "step": 20, "seconds": 7.0, "val_iou": 0.3, "precision": "bf16"},
             {"phase": "train", "step": 25, "seconds": 8.0, "loss": 0.4, "precision": "fp32"},
             {"phase": "train", "step": 30, "seconds": 9.6, "val_iou": 0.35, "precision": "fp32"}]
    (tmp_path / "history.jsonl").write_text("".join(json.dumps(r) + "\n" for r in lines))
    c = run_curve(tmp_path)
    assert c["steps"] == [0, 10, 20, 30] and c["val_iou"] == [0.1, 0.2, 0.3, 0.35]
    assert c["precision"] == ["bf16", "fp32", "unrecorded"] and c["seconds"] == 10
    t = run_curve(tmp_path, "teacher", "val_miou")
    assert t["steps"] == [5] and t["val_miou"] == [0.5] and t["precision"] == ["fp32"] and t["flattened"] is None
