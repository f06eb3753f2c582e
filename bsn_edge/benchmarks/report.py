"""The benchmark report: every result's Markdown in one page, with PNG plots.

    python -m bsn_edge.benchmarks.report --results benchmarks/results
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # headless: before pyplot is imported
import matplotlib.pyplot as plt
from matplotlib.ticker import NullFormatter, ScalarFormatter

from .common import machine
from .ledger import mean_std

ORDER = ("synth", "labels", "train_step", "train_step_avx2_research", "train_step_avx2_shared",
         "train_step_avx512_research", "train_step_archs", "train_step_archs_avx2", "checkpoint_state_avx2",
         "bsn_accuracy", "bsn_accuracy_shared-light", "bsn_accuracy_shared-light_rescore",
         "bsn_accuracy_shared-light_coverage", "bsn_accuracy_shared-light_depth_role", "bsn_arch", "bsn_arch_light",
         "bsn_arch_light_6k", "bsn_arch_light_12k", "bsn_arch_light_24k", "bsn_arch_heavy_12k",
         "quant", "floor", "floor_avx2", "int8_cpu",
         "runtime", "runtime_s3", "runtime_avx2", "runtime_avx2_decode", "runtime_avx2_flight", "runtime_avx2_shared",
         "runtime_avx2_s3", "runtime_avx2_s3fast", "runtime_avx2_s3warp", "runtime_avx2_s3flight",
         "runtime_avx2_budget", "tradeoff", "tradeoff_avx2",
         "calibration", "calibration_avx2", "install", "footprint", "realcam", "realview", "cameras", "remap",
         "remap_mirror", "warp", "overlay_behind")


def _load(results: Path, name: str) -> dict | None:
    p = results / f"{name}.json"
    return json.loads(p.read_text()) if p.is_file() else None


def _save(fig, out: Path) -> Path:
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out


def plot_stages(res: dict, out: Path) -> Path:
    rows = res.get("rows") or [{**res, "clip": "", "model_file": "", "camera_file": True}]
    stages = list(rows[0]["stage_ms"])
    labels = [f"{r['clip']}, {'file' if r['camera_file'] else 'calibrating'}"
              + (f", {r['loop']}" if r.get("loop") else "") for r in rows]
    fig, ax = plt.subplots(figsize=(8, 0.5 + 0.45 * len(rows)))
    left = [0.0] * len(rows)
    for s in stages:
        widths = [r["stage_ms"].get(s, 0.0) for r in rows]
        ax.barh(labels, widths, left=left, label=s)
        left = [a + b for a, b in zip(left, widths, strict=True)]
    ax.set_xlabel("ms per frame (overlapped rows: work on two threads)")
    ax.set_title(f"bsn-run stages per frame, {rows[0]['model_file']}" if rows[0].get("model_file") else
                 "bsn-run stages per frame")
    ax.legend(fontsize=7, ncol=3, loc="lower center", bbox_to_anchor=(0.5, 1.08))
    ax.invert_yaxis()
    return _save(fig, out)


def plot_arch(res: dict, out: Path) -> Path:
    # a seeded table carries each seed's IoU (drawn as mean +- std); the earlier one IoU per row
    with_iou = [(r, r["iou_seeds"] if r.get("iou_seeds") else [r["iou"]]) for r in res["rows"]
                if r.get("iou_seeds") or isinstance(r.get("iou"), float)]
    fig, axes = plt.subplots(1, 2 if with_iou else 1, figsize=(10 if with_iou else 5, 3.4), squeeze=False)
    ax = axes[0, 0]
    if with_iou:
        a2 = axes[0, 1]
        for r, ious in with_iou:
            m, s, _ = mean_std(ious)
            a2.errorbar(r["fps"], m, yerr=s, fmt="o", capsize=3)
            a2.annotate(r["model"], (r["fps"], m), textcoords="offset points", xytext=(4, 4), fontsize=8)
        a2.set_xscale("log")
        a2.set_xticks([2, 5, 10, 20, 50, 100, 200])
        a2.set_xlabel("frames/s (fp32, 2 threads)")
        a2.set_ylabel("IoU inside V (same training budget)")
        a2.xaxis.set_major_formatter(ScalarFormatter())
        a2.xaxis.set_minor_formatter(NullFormatter())
        a2.grid(alpha=0.3)
    for r in res["rows"]:
        ax.scatter(r["gmacs"], r["fps"], s=30)
        ax.annotate(r["model"], (r["gmacs"], r["fps"]), textcoords="offset points", xytext=(4, 4), fontsize=8)
    ax.set_xlabel("GMACs at 256x512 (D + B)")
    ax.set_ylabel("frames/s (fp32, 2 threads)")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xticks([1, 2, 5, 10, 20, 50, 100])
    ax.set_yticks([2, 5, 10, 20, 50, 100, 200])
    for axis in (ax.xaxis, ax.yaxis):
        axis.set_major_formatter(ScalarFormatter())
        axis.set_minor_formatter(NullFormatter())
    ax.grid(alpha=0.3)
    return _save(fig, out)


def plot_quant(res: dict, out: Path) -> Path:
    fig, ax = plt.subplots(figsize=(5, 3))
    keys = ("iou", "recall", "precision")
    x = range(len(keys))
    ax.bar([i - 0.2 for i in x], [res["fp32"][k] for k in keys], 0.4, label="fp32")
    ax.bar([i + 0.2 for i in x], [res["int8"][k] for k in keys], 0.4, label="int8")
    ax.set_xticks(list(x), keys)
    ax.set_ylim(0, 1)
    ax.legend()
    ax.set_title(f"int8 vs fp32 (agreement {100 * res['pixel_agreement']:.1f} %)")
    return _save(fig, out)


def build(results: Path) -> Path:
    m = machine()
    parts = ["# bsn-edge benchmark report", "",
             f"Measured on {m['cpu']}, {m['cores']} cores, Python {m['python']} ({m['platform']}).",
             "Each section is one benchmark's own report, measured on the machine its last line names (a "
             "`_avx2` section on a CPU without VNNI); the JSON beside it has every number.", ""]
    plots = {"runtime": ("stages.png", plot_stages), "runtime_avx2": ("stages_avx2.png", plot_stages),
             "bsn_arch": ("arch.png", plot_arch), "bsn_arch_light": ("arch_light.png", plot_arch),
             "bsn_arch_light_6k": ("arch_light_6k.png", plot_arch),
             "bsn_arch_light_12k": ("arch_light_12k.png", plot_arch),
             "bsn_arch_light_24k": ("arch_light_24k.png", plot_arch),
             "bsn_arch_heavy_12k": ("arch_heavy_12k.png", plot_arch),
             "quant": ("quant.png", plot_quant)}
    for name in ORDER:
        md = results / f"{name}.md"
        if not md.is_file():
            continue
        parts += [md.read_text().replace("# ", "## ", 1).rstrip(), ""]
        res = _load(results, name)
        if name in plots and res is not None:
            fname, fn = plots[name]
            fn(res, results / fname)
            parts += [f"![{name}]({fname})", ""]
    out = results / "REPORT.md"
    out.write_text("\n".join(parts))
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--results", default="benchmarks/results")
    args = p.parse_args(argv)
    print(f"wrote {build(Path(args.results))}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
