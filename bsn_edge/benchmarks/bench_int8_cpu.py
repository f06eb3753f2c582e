"""int8 on this CPU: is it exact, and what do 8-bit and 7-bit weights cost, side by side.

    python -m bsn_edge.benchmarks.bench_int8_cpu --out benchmarks/results [--model MODEL.onnx]

x86 CPUs without VNNI (AVX2, AVX-512F) multiply uint8 activations by int8 weights in pairs summed
into int16, which saturates for weights outside [-64, 63]. The runtime's session asks onnxruntime
for uint8 x uint8 there (exact, slower); 7-bit weights (``bsn-export --reduce-range``) never
saturate and keep the fast kernels. In one run, alternating rounds, 2 intra-op threads:

- the shipped model through a plain session and through the runtime's: the largest deviation
  from the self-test answer stored at export (a model exported on a VNNI CPU), and frames/s;
- the shipped architecture at the shipped size, exported fp32, int8 with 8-bit weights and int8
  with 7-bit weights (untrained weights: speed does not depend on their values; the accuracy of
  7-bit weights is a trained model's question, see the quant benchmark), frames/s.
"""

from __future__ import annotations

import argparse
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from bsn_edge.card import ModelCard
from bsn_edge.default_model import DEFAULT_MODEL
from bsn_edge.export import quantize, to_onnx
from bsn_edge.export.quantize import QuantConfig
from bsn_edge.modelfile import selftest
from bsn_edge.modelfile.read import ModelFile, session
from bsn_edge.networks import create_model

from . import runner
from .common import summary, time_calls
from .runner import Report

SHIPPED = DEFAULT_MODEL
ROUNDS, CALLS = 6, 20


def plain_session(path: Path):
    """A session without the runtime's precision setting: what onnxruntime does by default."""
    import onnxruntime as ort

    so = ort.SessionOptions()
    so.intra_op_num_threads, so.inter_op_num_threads = 2, 1
    return ort.InferenceSession(str(path), so, providers=["CPUExecutionProvider"])


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--model", default=str(SHIPPED), help="an exported int8 model (default: the shipped one)")
    p.add_argument("--out", default="benchmarks/results")
    p.add_argument("--name", default="int8_cpu", help="the report's name in --out")
    return p


def measure(args: argparse.Namespace, p: argparse.ArgumentParser) -> Report | None:
    import torch

    model_path = Path(args.model)
    card = ModelCard.from_metadata(ModelFile.read(model_path).metadata, str(model_path))
    frame = selftest.test_frame(*card.input_size)[None]
    with tempfile.TemporaryDirectory() as tmp:
        fp32 = Path(tmp) / "fp32.onnx"
        torch.manual_seed(0)
        to_onnx(create_model(card.variant).eval(), fp32, card)
        rng = np.random.default_rng(0)
        calib = rng.integers(0, 256, (8, *card.input_size, 3), dtype=np.uint8)
        calib[:4] = frame[0]
        for bits, reduce in ((8, False), (7, True)):
            quantize(fp32, Path(tmp) / f"w{bits}.onnx", calib, QuantConfig(reduce_range=reduce))
        sessions = {
            f"{model_path.name}, plain session": plain_session(model_path),
            f"{model_path.name}, runtime session": session(model_path),
            f"{card.variant} fp32": session(fp32),
            f"{card.variant} int8, 8-bit weights": session(Path(tmp) / "w8.onnx"),
            f"{card.variant} int8, 7-bit weights (--reduce-range)": session(Path(tmp) / "w7.onnx"),
        }
        times: dict[str, list[float]] = {k: [] for k in sessions}
        def once(s: Any) -> Callable[[int], Any]:
            return lambda _: s.run(None, {"frame": frame})

        for _ in range(ROUNDS):
            for k, s in sessions.items():
                times[k] += time_calls(once(s), CALLS)
    rates = {k: summary(v) for k, v in times.items()}
    known = card.self_test
    if known is None:
        raise RuntimeError(f"{model_path}: the model is not sealed (no self-test answer to hold the sessions to)")

    def answer(s: Any) -> Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]:
        def run(f: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            prob, depth = s.run(None, {"frame": f[None]})
            return prob[0, 0], depth[0, 0]
        return run

    exact = {k: selftest.deviation(answer(sessions[k]), card.input_size, known) for k in list(sessions)[:2]}
    result: dict[str, Any] = {"model": model_path.name, "input_size": card.input_size, "rates": rates,
                              "self_test_deviation": exact, "allowed": {"prob_abs": known.prob_atol,
                                                                        "depth_rel": known.depth_rtol}}
    rows = [f"| {k} | {r['per_second']:.1f} | {r['median_ms']:.1f} | "
            + (f"{exact[k]['max_abs_prob']:.4f} / {100 * exact[k]['max_rel_depth']:.1f} %" if k in exact else "") + " |"
            for k, r in rates.items()]
    md = "\n".join([
        "# int8 on this CPU: exactness and speed of 8-bit and 7-bit weights", "",
        f"Model-only, 2 intra-op threads, alternating rounds ({ROUNDS} x {CALLS} calls each), "
        f"{card.input_size[0]}x{card.input_size[1]}. Deviation: largest difference from the self-test answer "
        f"stored at export (probability, depth), allowed {known.prob_atol} / "
        f"{100 * known.depth_rtol:.0f} %.", "",
        "| session | frames/s | median ms | self-test deviation |", "|---|---|---|---|", *rows])
    return Report(result, [md], [md])


def main(argv: list[str] | None = None) -> int:
    return runner.run(measure, parser(), argv)


if __name__ == "__main__":
    raise SystemExit(main())
