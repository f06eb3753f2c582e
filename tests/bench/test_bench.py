"""bsn-bench from a checkout: one benchmark and the report."""

import json

from bsn_edge.cli import bench
from bsn_edge.synth import STYLES


def test_bench_runs_a_benchmark_and_writes_the_report(tmp_path):
    assert bench.main(["--only", "synth", "--out", str(tmp_path), "--synth-frames", "20"]) == 0
    res = json.loads((tmp_path / "synth.json").read_text())
    assert {r["style"] for r in res["rows"]} == set(STYLES) and res["machine"]["cores"]
    report = (tmp_path / "REPORT.md").read_text()
    assert "Measured on" in report and "Synthetic world" in report


def test_quant_profile_blocks_follow_node_names():
    from benchmarks.bench_quant import block_of

    assert block_of("/depth_net/net/encoder/stem/stem.0/Conv_token_42_kernel_time") == "stem"
    assert block_of("/blindspot/encoder/stages.3/stages.3.0/conv2/Conv_output_0_nchwc_kernel_time") == "encoder"
    assert block_of("/blindspot/decoder/fuse/fuse.0/fuse.0.3/Relu_kernel_time") == "decoder"
    assert block_of("/depth_net/net/head/up/DepthToSpace_kernel_time") == "heads and upsampling"
    assert block_of("/upsample/Conv_kernel_time") == "heads and upsampling"
    assert block_of("/depth_net/Exp_kernel_time") == "heads and upsampling"
    assert block_of("/normalise/Conv_kernel_time") == "input and layout"
    assert block_of("ReorderOutput_token_36_kernel_time") == "input and layout"
