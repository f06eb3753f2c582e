"""A trained run -> the sealed ONNX file the runtime reads (fp32 or int8), with its summary beside it.

One function for ``bsn-export`` and for anything else that ships a run (``bsn-adapt --export``),
and one that brings an int8 file exported before the integer input (``export.integer_input``) up
to date without re-exporting it.
"""

from __future__ import annotations

import dataclasses
import json
import sys
import tempfile
from pathlib import Path
from typing import Any, TextIO

import numpy as np
import onnx

from bsn_edge.card import ModelCard
from bsn_edge.export.calib_frames import load_frames
from bsn_edge.export.fused import check_parity, export_fused
from bsn_edge.export.integer_input import INTEGER_INPUT, integer_input
from bsn_edge.export.quantize import QuantConfig, quantize
from bsn_edge.export.seal import seal
from bsn_edge.modelfile import selftest
from bsn_edge.modelfile.read import ModelFile, session
from bsn_edge.networks import ORACLE_DEPTH_NOTE
from bsn_edge.sequence.images import atomic_write_bytes
from bsn_edge.train.run import Run


def export_run(checkpoint: str | Path, out: str | Path, size: tuple[int, int] | None = None, int8: bool = False,
               calib: str | Path | None = None, calib_frames: int = 64, qcfg: QuantConfig | None = None,
               log: TextIO | None = None, prune_dead: bool = True) -> dict[str, Any]:
    """Export the run ``checkpoint`` to ``out`` (and ``out`` with ``.json``: the summary, returned).

    fp32 parity with torch is checked (``ValueError`` past the tolerance); with ``int8`` the graph
    is statically quantized on ``calib_frames`` frames of ``calib`` and compared with fp32. Raises
    ``FileNotFoundError`` / ``ValueError`` for a missing or unfinished run or unreadable frames;
    ``out`` is replaced only when everything succeeded. Progress goes to ``log``: standard error as it
    is when called (not when this module was imported: a stream replaced since may be closed). With
    ``prune_dead`` the convolution channels nothing reads are taken out of the graph first
    (``export.prune``), recorded in the summary's ``pruned``."""
    log = log if log is not None else sys.stderr
    out = Path(out)
    if int8 and not calib:
        raise ValueError("int8 export needs calibration frames (a folder of images or a video)")
    if calib_frames < 1:
        raise ValueError(f"calibration frames must be >= 1, got {calib_frames}")
    qcfg = qcfg or QuantConfig()
    model, card = Run(checkpoint).load_model()
    if model.oracle_depth:
        raise ValueError(f"{checkpoint}: a {card.variant!r} run cannot be exported: {ORACLE_DEPTH_NOTE}")
    if card.threshold is None:
        raise ValueError(f"{checkpoint}: the run has no decision threshold yet (training did not finish)")
    h, w = size or card.input_size
    card = card.at_size(h, w)
    frames = load_frames(calib, (h, w), calib_frames, card=card) if calib else None
    out.parent.mkdir(parents=True, exist_ok=True)
    check_frames = list(frames[:4]) if frames is not None else \
        [np.random.default_rng(i).integers(0, 256, (h, w, 3), dtype=np.uint8) for i in range(2)]
    summary: dict[str, Any] = {"checkpoint": str(checkpoint), "size": [h, w]}
    with tempfile.TemporaryDirectory(dir=out.parent) as tmp:
        fp32 = Path(tmp) / "fp32.onnx"
        print(f"exporting {card.variant} at {h}x{w} ...", file=log)
        exported = export_fused(model, fp32, card, prune_dead)
        sealed = exported.card
        if exported.pruned is not None:
            print(exported.pruned.line(), file=log)
            summary["pruned"] = exported.pruned.to_dict()
        summary["parity_fp32"] = check_parity(model, fp32, check_frames)
        summary["fp32_bytes"] = fp32.stat().st_size
        final = fp32
        if int8:
            assert frames is not None           # int8 without calibration frames was refused above
            print(f"quantizing on {len(frames)} calibration frames ({qcfg.scheme()}) ...", file=log)
            q = Path(tmp) / "int8.onnx"
            info = quantize(fp32, q, frames, qcfg)
            sealed = info.pop("card")
            summary.update(int8_bytes=q.stat().st_size, quantization=info,
                           int8_vs_fp32=compare(fp32, q, frames, sealed.threshold))
            final = q
        final.replace(out)
    write_summary(out, summary, sealed)
    return summary


def write_summary(out: Path, summary: dict[str, Any], sealed: ModelCard) -> None:
    """``summary`` with ``sealed``'s card (its self-test answer elided) as ``out`` with ``.json``."""
    card_record = sealed.to_dict()
    assert sealed.self_test is not None         # a sealed card has its answer
    card_record["self_test"] = dataclasses.asdict(sealed.self_test) | {"prob": "...", "depth": "..."}
    summary["card"] = card_record
    atomic_write_bytes(Path(out).with_suffix(".json"), (json.dumps(summary, indent=1) + "\n").encode())


def compare(fp32: Path, int8: Path, frames: np.ndarray, threshold: float) -> dict[str, float]:
    """How far the second model (``int8``) strays from the first (``fp32``) on ``frames``: the largest
    probability difference, the masks' agreement at ``threshold``, and depth's relative difference (the
    median of each frame's median, and the largest)."""
    a, b = session(fp32), session(int8)
    dp, agree, rel, worst = 0.0, [], [], 0.0
    for f in frames:
        pa, da = a.run(None, {"frame": f[None]})
        pb, db = b.run(None, {"frame": f[None]})
        dp = max(dp, float(np.abs(pa - pb).max()))
        agree.append(float(((pa >= threshold) == (pb >= threshold)).mean()))
        r = np.abs(da - db) / np.maximum(da, 1e-3)
        rel.append(float(np.median(r)))
        worst = max(worst, float(r.max()))
    return {"frames": len(frames), "max_abs_prob": dp, "mask_agreement": float(np.mean(agree)),
            "depth_median_rel": float(np.median(rel)), "depth_max_rel": worst}


def upgrade_integer_input(src: str | Path, out: str | Path, frames: int = 4) -> dict[str, Any]:
    """Give the sealed int8 model ``src``, exported before the integer input, its integer input:
    written resealed to ``out`` only when its outputs equal ``src``'s to the bit on the self-test
    frame and ``frames`` random frames; the summary beside ``src`` (if any) is carried to ``out``'s
    with the new card and what was replaced, and returned. ``ValueError`` for a damaged seal, a model
    without the float input chain, or any output that differs."""
    mf = ModelFile.read(src)
    card = ModelCard.from_metadata(mf.metadata, str(src))
    if card.graph_sha256 != mf.graph_sha256:
        raise ValueError(f"{src}: the graph does not match its seal (damaged or edited); re-export it instead")
    model = onnx.load(str(src))
    done = integer_input(model)
    if done is None:
        raise ValueError(f"{src}: no float input chain to make integer (already done, fp32, or a model that "
                         "resizes the frame before normalising it)")
    onnx.checker.check_model(model)
    del model.metadata_props[:]
    data = model.SerializeToString()
    before, after = session(src), session(data)
    h, w = card.input_size
    rng = np.random.default_rng(0)
    for f in [selftest.test_frame(h, w), *(rng.integers(0, 256, (h, w, 3), dtype=np.uint8) for _ in range(frames))]:
        for name, a, b in zip(("blindspot", "depth"), before.run(None, {"frame": f[None]}),
                              after.run(None, {"frame": f[None]}), strict=True):
            if not np.array_equal(a, b):
                raise ValueError(f"{src}: with the integer input its {name} differs by up to "
                                 f"{float(np.abs(a - b).max()):.3g}; left as it is")
    Path(out).parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=Path(out).parent) as tmp:
        path = Path(tmp) / "integer.onnx"
        path.write_bytes(data)
        sealed = seal(path, card.replace(quantization=f"{card.quantization}, {INTEGER_INPUT}", graph_sha256="",
                                         self_test=None), out)
    old = Path(src).with_suffix(".json")
    summary = json.loads(old.read_text()) if old.is_file() else {}
    quant = summary.setdefault("quantization", {})
    for name in done.replaced:
        quant.get("float_nodes", {}).pop(name, None)
    quant.update(scheme=sealed.quantization, integer_input=dataclasses.asdict(done))
    summary["upgraded_from"] = str(src)
    write_summary(Path(out), summary, sealed)
    return summary
