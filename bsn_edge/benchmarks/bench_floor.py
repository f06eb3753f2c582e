"""The shipped model's latency as a multiple of this machine's int8 floor.

    python -m bsn_edge.benchmarks.bench_floor [--model MODEL.onnx] [--baseline OLD.onnx] --out benchmarks/results

The floor is how fast the model could run if every multiply-accumulate went at the best int8
rate onnxruntime reaches on this machine on the kernels the runtime gives this model: a stack of
dense 3x3 convolutions (with ReLU), quantized as the model's card says it was (static QDQ, 7-bit
weights when the model has them), at the feature sizes of the model's encoder stages, in the
session the runtime would open for the model (the exact uint8 x uint8 kernels for 8-bit weights,
the fast uint8 x int8 ones for 7-bit weights). Which kernels those are depends on the CPU: VNNI
dot products, or without VNNI the 7-bit fast path or the exact kernels; the report names it. The rate is their MACs
over their median latency; the fastest stack is then timed again, one run at a time in alternation
with the model, and its rate there is the machine's int8 peak. Then:

    floor   = the model's GMACs / peak rate
    multiple = the model's median latency / floor      (1 / multiple = share of peak)

The alternation is repeated in fresh sessions (``--repeats``) and the multiple is the median of
the repeats, with their range: on a shared cloud machine one alternation can differ from the next
by a tenth. ``--baseline`` times another model of the same family in the same rounds (before and
after an export change). Everything with 2 intra-op threads, in one run of this script, so the
multiple compares like with like on whatever machine runs it. An onnxruntime profile of the model
says where the rest goes, by operator.
"""

from __future__ import annotations

import argparse
import re
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
import onnx
import torch
from onnxruntime.quantization import QuantFormat, quantize_static
from onnxruntime.quantization.shape_inference import quant_pre_process

from bsn_edge.cli.common import CHECKOUT
from bsn_edge.default_model import DEFAULT_MODEL
from bsn_edge.export.quantize import METHODS, TYPES, FrameReader, QuantConfig
from bsn_edge.export.seal import read_card
from bsn_edge.modelfile.read import session
from bsn_edge.networks import create_model

from .arch_speed import count_gmacs
from .bench_quant import kernel_times, latency
from .common import class_name, machine
from .runner import Report, run

# (channels, stride below the input) of dense 3x3 stacks: ResNet stages at 1/4 to 1/32
STACKS = ((64, 4), (128, 8), (256, 16), (512, 32))
DEPTH = 6          # convolutions per stack
GOAL_MULTIPLE = 1.5


class ConvStack(torch.nn.Module):
    """``DEPTH`` dense 3x3 convolutions with ReLU, ``channels`` in and out."""

    def __init__(self, channels: int) -> None:
        super().__init__()
        self.body = torch.nn.Sequential(*[m for _ in range(DEPTH) for m in
                                          (torch.nn.Conv2d(channels, channels, 3, padding=1), torch.nn.ReLU())])

    def forward(self, frame: torch.Tensor) -> torch.Tensor:
        return self.body(frame)


def kernel_class(isa: list[str], seven_bit: bool) -> str:
    """The int8 kernels a model runs on, on a CPU with instruction sets ``isa`` (``machine()``)."""
    if "VNNI" in isa or "AVX-VNNI" in isa:
        return "VNNI dot products (uint8 x int8)"
    if seven_bit:
        return "uint8 x int8 without VNNI, exact with 7-bit weights"
    return "exact uint8 x uint8 (no VNNI, 8-bit weights)"


def stack_rate(channels: int, hw: tuple[int, int], cfg: QuantConfig, runs: int, tmp: Path) -> dict:
    """int8 multiply-accumulates per second of one dense stack at feature size ``hw``."""
    torch.manual_seed(0)
    net = ConvStack(channels).eval()
    x = torch.randn(1, channels, *hw).relu()
    fp32, pre, q = (tmp / f"stack{channels}_{n}.onnx" for n in ("fp32", "pre", "int8"))
    torch.onnx.export(net, (x,), str(fp32), input_names=["frame"], output_names=["out"], dynamo=False)
    quant_pre_process(str(fp32), str(pre), skip_symbolic_shape=True)
    calib = np.stack([torch.randn(channels, *hw).relu().numpy() for _ in range(8)])
    quantize_static(str(pre), str(q), FrameReader(calib), quant_format=QuantFormat.QDQ, per_channel=cfg.per_channel,
                    activation_type=TYPES[cfg.activations], weight_type=TYPES[cfg.weights],
                    calibrate_method=METHODS[cfg.method],
                    reduce_range=cfg.reduce_range, extra_options={"ActivationSymmetric": cfg.activations == "int8"})
    macs = DEPTH * channels * channels * 9 * hw[0] * hw[1]
    t = latency(q, x.numpy(), runs, exact_x64=not cfg.reduce_range)
    return {"channels": channels, "size": list(hw), "gmacs": macs / 1e9, "median_ms": 1e3 * t,
            "tmacs_per_s": macs / t / 1e12, "path": q, "input": x.numpy()}


def alternation(models: list[tuple[Path, np.ndarray]], runs: int, exact_x64: bool = True) -> list[float]:
    """Median seconds per run of each model, one run of each per round, in fresh sessions."""
    # no spinning: an idle session's spinning threads would take the cores from the running one
    sessions = [session(m[0], threads=2, spinning=False, exact_x64=exact_x64) for m in models]
    times: list[list[float]] = [[] for _ in models]
    for _ in range(5):
        for s, (_, x) in zip(sessions, models, strict=True):
            s.run(None, {"frame": x})
    for _ in range(runs):
        for s, (_, x), t in zip(sessions, models, times, strict=True):
            t0 = time.perf_counter()
            s.run(None, {"frame": x})
            t.append(time.perf_counter() - t0)
    return [float(np.median(t)) for t in times]


def conv_kinds(path: Path) -> dict[str, tuple[str, float]]:
    """Every convolution of the model by name: its kind (dense kxk, 1x1, depthwise) and its MACs,
    from the graph's weights and inferred shapes."""
    model = onnx.shape_inference.infer_shapes(onnx.load(str(path)))
    init = {t.name: tuple(t.dims) for t in model.graph.initializer}
    producer = {o: n for n in model.graph.node for o in n.output}
    shapes = {v.name: [d.dim_value for d in v.type.tensor_type.shape.dim]
              for v in (*model.graph.value_info, *model.graph.output)}
    out: dict[str, tuple[str, float]] = {}
    for n in model.graph.node:
        if n.op_type != "Conv":
            continue
        w = n.input[1]
        while w not in init and w in producer:      # through DequantizeLinear to the stored weight
            w = producer[w].input[0]
        if w not in init or n.output[0] not in shapes:
            continue
        c_out, c_in_g, kh, kw = init[w]
        group = next((a.i for a in n.attribute if a.name == "group"), 1)
        _, _, ho, wo = shapes[n.output[0]]
        kind = "depthwise" if group > 1 and c_in_g == 1 else ("1x1" if kh == kw == 1 else f"dense {kh}x{kw}")
        out[n.name] = (kind, float(c_out * c_in_g * kh * kw * ho * wo))
    return out


def op_shares(path: Path, frame: np.ndarray, runs: int) -> tuple[dict[str, float], dict[str, dict[str, float]]]:
    """Milliseconds per run in each onnxruntime operator type, and per kind of convolution its
    milliseconds, GMACs and rate (the profiler adds overhead: read shares and ratios, not sums)."""
    kinds = conv_kinds(path)
    ms: dict[str, float] = {}
    conv: dict[str, dict[str, float]] = {}
    seen: set[str] = set()
    for entry, op, t in kernel_times(path, frame, runs):
        ms[op] = ms.get(op, 0.0) + t
        name = re.sub(r"(_token_\d+)?_kernel_time$", "", entry)
        if name in kinds:
            kind, macs = kinds[name]
            c = conv.setdefault(kind, {"ms": 0.0, "gmacs": 0.0})
            c["ms"] += t
            if name not in seen:
                seen.add(name)
                c["gmacs"] += macs / 1e9
    for c in conv.values():
        c["tmacs_per_s"] = c["gmacs"] / c["ms"] if c["ms"] else 0.0
    return dict(sorted(ms.items(), key=lambda kv: -kv[1])), dict(sorted(conv.items(), key=lambda kv: -kv[1]["ms"]))


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--model", default=str(DEFAULT_MODEL), help="an int8 model exported by bsn-export")
    p.add_argument("--out", default="benchmarks/results")
    p.add_argument("--runs", type=int, default=60)
    p.add_argument("--repeats", type=int, default=5, help="alternations in fresh sessions (default 5); "
                   "the multiple is their median")
    p.add_argument("--baseline", help="another int8 model of the same variant and size, timed in the same rounds")
    p.add_argument("--name", help="the report's name in --out (default: floor with VNNI, floor_avx2 without)")
    return p


def _rounds(args: argparse.Namespace, cfg: QuantConfig, frame: np.ndarray, h: int, w: int):
    """The dense stacks' rates, the fastest of them, and the rounds that time the model (and the baseline)
    in alternation with it: ``(stacks, best, timed, rounds)``."""
    with tempfile.TemporaryDirectory() as tmp:
        stacks = [stack_rate(c, (h // s, w // s), cfg, args.runs, Path(tmp)) for c, s in STACKS]
        best = max(stacks, key=lambda r: r["tmacs_per_s"])
        # the model (and the baseline) and the fastest stack again, alternating: the multiple is a
        # ratio of these, taken in each repeat
        timed = [(Path(args.model), frame)] + ([(Path(args.baseline), frame)] if args.baseline else [])
        rounds = [alternation([*timed, (best["path"], best["input"])], 3 * args.runs, exact_x64=not cfg.reduce_range)
                  for _ in range(max(1, args.repeats))]
        for r in stacks:
            del r["path"], r["input"]
    return stacks, best, timed, rounds


def _markdown(args: argparse.Namespace, card, cfg: QuantConfig, kernels: str, result: dict[str, Any],
              best: dict[str, Any], rounds: list, multiples: list) -> list[str]:
    h, w = card.input_size
    stacks, peak, gmacs = result["stacks"], result["peak_tmacs_per_s"], result["model_gmacs"]
    t_model, floor_s, multiple = result["model_median_ms"] / 1e3, result["floor_ms"] / 1e3, result["multiple"]
    ops, convs = result["op_ms"], result["conv_kinds"]
    total = sum(ops.values())
    lines = ["# The shipped model against this machine's int8 floor", "",
             f"Kernels on this CPU for this model: **{kernels}**.", "",
             f"Dense 3x3 stacks ({DEPTH} convolutions + ReLU each), quantized as the model was "
             f"({cfg.scheme()}), onnxruntime with 2 intra-op threads, in the session the runtime opens for it:", "",
             "| channels | feature size | GMACs | median ms | TMAC/s |", "|---|---|---|---|---|"]
    lines += [f"| {r['channels']} | {r['size'][0]}x{r['size'][1]} | {r['gmacs']:.2f} | {r['median_ms']:.2f} | "
              f"{r['tmacs_per_s']:.3f} |" for r in stacks]
    lines += ["", f"Peak int8 rate here: **{peak:.3f} TMAC/s** (the fastest stack, {best['channels']} channels, "
              f"timed again in alternation with the model, {3 * args.runs} runs each, in the repeat with the "
              f"median multiple).", "",
              f"`{card.variant}` at {h}x{w}: {gmacs:.2f} GMACs, median {1e3 * t_model:.2f} ms; floor "
              f"{1e3 * floor_s:.2f} ms. **Latency = {multiple:.2f}x its int8 floor ({100 / multiple:.0f} % of "
              f"peak)**; goal <= {GOAL_MULTIPLE:g}x ({'met' if multiple <= GOAL_MULTIPLE else 'not met'}). "
              f"Median of {len(rounds)} alternations in fresh sessions; their multiples range "
              f"{min(multiples[0]):.2f}x-{max(multiples[0]):.2f}x.", ""]
    if args.baseline:
        b = sorted(multiples[1])[len(rounds) // 2]
        lines += [f"Baseline `{Path(args.baseline).name}`, timed in the same rounds: **{b:.2f}x** (range "
                  f"{min(multiples[1]):.2f}x-{max(multiples[1]):.2f}x); the model took "
                  f"{np.median([r[0] / r[1] for r in rounds]):.2f} of its time (median of the repeats).", ""]
    lines += ["Where the model's time goes (onnxruntime profile, 20 runs; shares of the profiled kernel time):", "",
              "| operator | ms per run | share |", "|---|---|---|"]
    lines += [f"| {op} | {v:.2f} | {100 * v / total:.0f} % |" for op, v in list(ops.items())[:10]]
    lines += ["", "The convolutions by kind (profiled time, their MACs, the rate they reach against the peak "
              "above, which was measured without the profiler):", "",
              "| kind | ms per run | GMACs | TMAC/s | share of peak |", "|---|---|---|---|---|"]
    lines += [f"| {k} | {c['ms']:.2f} | {c['gmacs']:.3f} | {c['tmacs_per_s']:.3f} | "
              f"{100 * c['tmacs_per_s'] / peak:.0f} % |" for k, c in convs.items()]
    return lines


def measure(args: argparse.Namespace, p: argparse.ArgumentParser) -> Report:
    card = read_card(args.model)
    h, w = card.input_size
    if args.baseline:
        other = read_card(args.baseline)
        if (other.variant, tuple(other.input_size)) != (card.variant, (h, w)):
            p.error(f"--baseline {args.baseline} is {other.variant} at {other.input_size[0]}x{other.input_size[1]}; "
                    f"the model is {card.variant} at {h}x{w}: the floor is the same only for the same network")
    cfg = QuantConfig(reduce_range=card.seven_bit_weights)
    kernels = kernel_class(machine()["isa"], card.seven_bit_weights)
    torch.manual_seed(0)
    gmacs = count_gmacs(create_model(card.variant).eval(), (h, w))
    frame = np.random.default_rng(0).integers(0, 256, (1, h, w, 3), dtype=np.uint8)
    stacks, best, timed, rounds = _rounds(args, cfg, frame, h, w)
    peaks = [best["gmacs"] * 1e9 / r[-1] / 1e12 for r in rounds]
    multiples = [[r[i] * peak * 1e12 / (gmacs * 1e9) for r, peak in zip(rounds, peaks, strict=True)]
                 for i in range(len(timed))]
    pick = int(np.argsort(multiples[0])[len(rounds) // 2])        # the repeat with the median multiple
    peak, t_model = peaks[pick], rounds[pick][0]
    floor_s = gmacs * 1e9 / (peak * 1e12)
    multiple = multiples[0][pick]
    ops, convs = op_shares(Path(args.model), frame, 20)
    model = Path(args.model).resolve()
    shown = model.relative_to(CHECKOUT) if model.is_relative_to(CHECKOUT) else model.name
    result = {"model": str(shown), "variant": card.variant, "size": [h, w], "scheme": cfg.scheme(), "kernels": kernels,
              "stacks": stacks, "peak_tmacs_per_s": peak, "model_gmacs": gmacs, "model_median_ms": 1e3 * t_model,
              "floor_ms": 1e3 * floor_s, "multiple": multiple, "share_of_peak": 1 / multiple,
              "goal_multiple": GOAL_MULTIPLE, "repeats": len(rounds), "multiples": multiples[0],
              "op_ms": ops, "conv_kinds": convs}
    if args.baseline:
        result["baseline"] = {"model": Path(args.baseline).name, "multiples": multiples[1],
                              "median_ms": [1e3 * r[1] for r in rounds]}
    lines = _markdown(args, card, cfg, kernels, result, best, rounds, multiples)
    return Report(result, lines, lines, name=args.name or class_name("floor"))


def main(argv: list[str] | None = None) -> int:
    return run(measure, parser(), argv)


if __name__ == "__main__":
    raise SystemExit(main())
