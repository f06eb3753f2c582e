"""The campaign report's verdict on whether a curve has flattened."""

from benchmarks.bench_campaign import flattened


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

    from benchmarks.bench_campaign import plot

    student = [{"samples": 8000 * i, "val_iou": 0.4 + 0.01 * i, "val_abs_rel": 0.1, "loss": 0.2, "bce": 0.03,
                "kd": 0.005, "depth": 0.15} for i in range(1, 4)]
    teacher = [{"samples": 8000 * i, "val_road": 0.9, "val_sidewalk": 0.5, "val_vehicle": 0.7, "val_person": 0.3,
                "val_miou": 0.6} for i in range(1, 4)]
    plot([], student, tmp_path / "leg.png", "leg")
    plot(teacher, student, tmp_path / "whole.png", "whole")
    # 5 inches a panel at 90 dpi: two panels for a leg, three with the teacher's curve
    assert cv2.imread(str(tmp_path / "leg.png")).shape[1] == 2 * 5 * 90
    assert cv2.imread(str(tmp_path / "whole.png")).shape[1] == 3 * 5 * 90
