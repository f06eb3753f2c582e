"""bsn-bench from a checkout: one benchmark and the report."""

import json

from bsn_edge.cli import bench
from bsn_edge.synth import STYLES


def test_bench_runs_a_benchmark_and_writes_the_report(tmp_path):
    assert bench.main(["--only", "synth", "--out", str(tmp_path), "--synth-frames", "4"]) == 0
    res = json.loads((tmp_path / "synth.json").read_text())
    assert {r["style"] for r in res["rows"]} == set(STYLES) and res["machine"]["cores"]
    report = (tmp_path / "REPORT.md").read_text()
    assert "Measured on" in report and "Synthetic world" in report


def test_quant_profile_blocks_follow_node_names():
    from bsn_edge.benchmarks.bench_quant import block_of

    assert block_of("/depth_net/net/encoder/stem/stem.0/Conv_token_42_kernel_time") == "stem"
    assert block_of("/blindspot/encoder/stages.3/stages.3.0/conv2/Conv_output_0_nchwc_kernel_time") == "encoder"
    assert block_of("/blindspot/decoder/fuse/fuse.0/fuse.0.3/Relu_kernel_time") == "decoder"
    assert block_of("/depth_net/net/head/up/DepthToSpace_kernel_time") == "heads and upsampling"
    assert block_of("/upsample/Conv_kernel_time") == "heads and upsampling"
    assert block_of("/to_frame_1/DepthToSpace_kernel_time") == "heads and upsampling"
    assert block_of("/depth_net/Exp_kernel_time") == "heads and upsampling"
    assert block_of("/normalise/Conv_kernel_time") == "input and layout"
    assert block_of("ReorderOutput_token_36_kernel_time") == "input and layout"


def test_floor_counts_each_kind_of_convolution_from_the_graph(tmp_path):
    import torch

    from bsn_edge.benchmarks.bench_floor import conv_kinds

    net = torch.nn.Sequential(torch.nn.Conv2d(3, 16, 7, stride=2, padding=3),       # 16x32 out
                              torch.nn.Conv2d(16, 16, 3, padding=1, groups=16),     # depthwise
                              torch.nn.Conv2d(16, 32, 1),
                              torch.nn.Conv2d(32, 32, 3, padding=1)).eval()
    path = tmp_path / "net.onnx"
    torch.onnx.export(net, (torch.zeros(1, 3, 32, 64),), str(path), dynamo=False)
    got = sorted(conv_kinds(path).values())
    px = 16 * 32
    assert got == sorted([("dense 7x7", 16 * 3 * 49 * px), ("depthwise", 16 * 9 * px), ("1x1", 32 * 16 * px),
                          ("dense 3x3", 32 * 32 * 9 * px)])


def test_every_benchmark_module_imports():
    """A benchmark no test runs still has to load: a helper renamed in the package must not break it."""
    import importlib
    import pkgutil

    from bsn_edge import benchmarks

    names = [m.name for m in pkgutil.iter_modules(benchmarks.__path__) if m.name.startswith("bench_")]
    assert "bench_train_step" in names
    for name in names:
        importlib.import_module(f"bsn_edge.benchmarks.{name}")


def test_camvid_counts_road_users_and_open_road_by_the_stated_rule():
    """A hand-made 360x480 label: a car of 50x40 px reaching row 300 (near), a car of 50x40 px ending at
    row 150 (not near: above the lower 40 %), a pedestrian of 15x20 px (all, not near), a speck of 10 px
    (neither), pavement along the left; open road is the road of rows 216-359 at least 25 px from the
    cars and from everything but road or pavement (the kerb of pavement does not count)."""
    import numpy as np

    from bsn_edge.benchmarks.bench_camvid import open_road, road_users
    lab = np.full((360, 480), 3, np.uint8)        # road
    lab[:100] = 0                                  # sky
    lab[:, :60] = 4                                # pavement
    lab[261:301, 200:250] = 8                      # near car: 2,000 px, bottom row 300
    lab[111:151, 300:350] = 8                      # far car: 2,000 px, bottom row 150
    lab[250:270, 400:415] = 9                      # pedestrian: 300 px
    lab[330:332, 100:105] = 10                     # a speck of a cyclist: 10 px
    users = sorted(road_users(lab), key=lambda u: (u["group"], -u["near"]))
    assert [(u["group"], u["area"], u["near"]) for u in users] == [
        ("people", 300, False), ("vehicles", 2000, True), ("vehicles", 2000, False)]
    clear = open_road(lab)
    assert not clear[:216].any() and clear[216:, 60:].any()
    assert not clear[237:325, 200:250].any() and not clear[261:301, 176:274].any(), "within 25 px of the near car"
    assert clear[350, 65], "the pavement is not an obstacle"
    assert not clear[330:332, 100:105].any()



def test_camvid_says_where_the_flagged_pixels_fall_and_finds_the_threshold_of_a_like_area():
    """Where flagged pixels fall, counted by hand on a two-class label; the like-area threshold flags the
    share asked for, whatever the distribution (uniform ramp: the share's complement), and nothing for 0."""
    import numpy as np

    from bsn_edge.benchmarks.bench_camvid import like_area_threshold, score_masks
    lab = np.zeros((100, 200), np.uint8)           # sky
    lab[50:] = 1                                   # building below
    prob = np.zeros((100, 200), np.float16)
    prob[40:60, :100] = 0.9                        # 1,000 px on sky, 1,000 on the building
    prob[60:70, :100] = 0.9                        # 1,000 more on the building
    r = score_masks([prob], [lab], 0.5)
    assert r["flagged"] == 0.15 and r["falls"]["sky"] == round(1 / 3, 4)
    assert r["falls"]["buildings and trees"] == round(2 / 3, 4) and r["falls"]["road users"] == 0
    ramp = [np.linspace(0, 1, 10_000, dtype=np.float32).reshape(100, 100)]
    for share in (0.05, 0.25, 0.5):
        t = like_area_threshold(ramp, share)
        assert abs(float((ramp[0] >= t).mean()) - share) < 1e-3
    assert not (ramp[0] >= like_area_threshold(ramp, 0.0)).any()
