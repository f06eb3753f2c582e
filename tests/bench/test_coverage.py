"""The coverage check's report: every arm per clip, in clip order, and pooled per test set."""

from benchmarks.archive.bench_coverage import ARMS, markdown


def test_report_has_every_arm_per_clip_in_clip_order():
    def part(iou: float) -> dict:
        return {"iou": iou, "ap": iou + 0.1,
                "clips": {"suburb_10": {"iou": iou, "ap": 0.5}, "suburb_9": {"iou": iou / 2, "ap": 0.2}}}
    result = {"key": "BSN/suburb/seed1", "steps": 600, "lr": 1e-4,
              "added": {"nothing": None, "day": "sun, 90 deg", "night": "night, 95 deg"},
              "scores": {arm: {"more": part(0.1 * (i + 1))} for i, arm in enumerate(["before", *ARMS])}}
    text = markdown(result, {"suburb_9": "night, 89 deg"})
    rows = [x for x in text.splitlines() if x.startswith("| suburb_")]
    assert rows[0] == "| suburb_9 | night, 89 deg | 0.050 / 0.200 | 0.100 / 0.200 | 0.150 / 0.200 | 0.200 / 0.200 |"
    assert rows[1].startswith("| suburb_10 | - | 0.100 / 0.500 |")
    assert "+ wide night (night, 95 deg)" in text
    assert "- `more`: before 0.100 / 0.200; + nothing 0.200 / 0.300; + wide day 0.300 / 0.400; " \
           "+ wide night 0.400 / 0.500" in text
