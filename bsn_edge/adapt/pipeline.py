"""``bsn-adapt``'s stages: import the user's clips, label them with the run's own depth, teacher and
visual odometry, fine-tune B on the labels, choose the threshold on held-out clips, write the run."""

from __future__ import annotations

import dataclasses
import hashlib
import json
import shutil
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

from bsn_edge.adapt.clips import Imported, UnusableClipError, clip_name, import_clip, moving_seconds
from bsn_edge.adapt.config import AdaptConfig
from bsn_edge.adapt.finetune import agreement, at_threshold, finetune_b
from bsn_edge.adapt.labeller import load_teacher, prepare_labeller, road_share
from bsn_edge.adapt.workspace import AdaptFolder
from bsn_edge.adapt.written import export_adapted, write_adapted
from bsn_edge.calibration.camera_file import Calibration
from bsn_edge.data.dataset import BlindSpotDataset, Clip
from bsn_edge.labels import Sources
from bsn_edge.labels.batch import label_many
from bsn_edge.labels.generator import made_with
from bsn_edge.labels.sources.base import ClipData
from bsn_edge.labels.sources.registry import make_seg
from bsn_edge.networks import ORACLE_DEPTH_NOTE
from bsn_edge.progress import progress_bar
from bsn_edge.sequence.folder import SequenceFolder
from bsn_edge.sequence.meta import SequenceMeta
from bsn_edge.train.run import Run

EXPORT_NAME = "model_int8.onnx"
MIN_ROAD_SHARE = 0.02     # of the lower half of a clip's frames, by the teacher: less is "no road found"
MIN_BLIND_SPOT_SHARE = 1e-3   # of V over a clip's labels: less teaches B that nothing is ever hidden


class AdaptError(ValueError):
    """An adaptation that cannot be done as asked (the message says what and where)."""


def _prepare_out(src: Run, out: Path, settings: dict[str, Any], resume: bool, force: bool) -> AdaptFolder:
    folder = AdaptFolder(out)
    if out.resolve() == src.path.resolve():
        raise AdaptError(f"--out {out} is the run being adapted; give the adapted run its own folder")
    if resume and force:
        raise AdaptError("--resume and --force contradict each other")
    taken = Run(out).exists() or folder.exists()
    if taken and not (resume or force):
        raise AdaptError(f"{out} already holds a run or an adaptation; pass --resume to continue it or --force to "
                         "start again")
    if taken and resume:
        old = folder.read_config() if folder.exists() else {}
        if old.get("labelling") != settings:
            raise AdaptError(f"{out} was labelled from other inputs or label settings; --force starts again")
    if force:
        for p in (Run(out).model_path, Run(out).checkpoint_path, Run(out).state_path, Run(out).config_path):
            p.unlink(missing_ok=True)
        shutil.rmtree(Run(out).teacher_path.parent, ignore_errors=True)
        shutil.rmtree(folder.root, ignore_errors=True)
    return folder


def _split(clips: list[Clip], fraction: float, horizon_frames: int, seed: int) -> tuple[list[Clip], list[Clip]]:
    """Held-out part of the labelled frames: whole clips when there are several, else the end of
    the one clip (after a gap of ``horizon_frames`` label frames when the clip affords it)."""
    if len(clips) >= 2:
        order = sorted(clips, key=lambda c: hashlib.sha256(f"{seed}:{c.path.name}".encode()).hexdigest())
        k = min(max(1, round(fraction * len(clips))), len(clips) - 1)
        return order[k:], order[:k]
    c = clips[0]
    n = len(c.frames)
    cut = round(n * (1 - fraction))
    # a gap of T keeps the training labels from looking into the held-out frames, when the clip
    # is long enough to afford it
    gap = horizon_frames if cut - horizon_frames >= max(4, n // 4) else 0
    train, held = c.frames[:cut - gap], c.frames[cut:]
    if not held or not train:
        raise AdaptError(f"{c.path}: {n} labelled frames are too few to hold some out; record longer or add a clip")
    return [dataclasses.replace(c, frames=train)], [dataclasses.replace(c, frames=held)]


def _coverage(seq: Path, label: str) -> dict[str, Any]:
    rep = json.loads(SequenceFolder(seq).labels(label).report_path.read_text())
    pf = rep.get("per_frame", [])
    vis = sum(f["visible_px"] for f in pf)
    return {"label_frames": len(pf), "blind_spot_share_of_v": round(sum(f["blindspot_in_v_px"] for f in pf)
                                                                     / max(vis, 1), 4),
            "v_share_of_frame": round(vis / max(len(pf) * rep["size"][0] * rep["size"][1], 1), 4),
            "depth": rep.get("sources_detail", {}).get("depth", {}).get("correlation")}


def _labelling_settings(run_dir: str | Path, weights: str, videos: list[str | Path], calib: str | Path | None,
                        fps: float | None, cfg: AdaptConfig, teacher: Run | None = None) -> dict[str, Any]:
    """What the imported clips and their labels depend on (a resumed adaptation must match it;
    fine-tuning settings may change between resumes)."""
    c = cfg.to_dict()
    return {"run": str(Path(run_dir).resolve()), "weights_sha256": weights,
            "videos": [str(Path(v).resolve()) for v in videos], "calib": str(calib or ""), "fps": fps,
            "teacher": str(teacher.path.resolve()) if teacher else "",
            **{k: c[k] for k in ("labels", "label_depth", "max_fps", "min_moving_s")}}


def label_clips(src: Run, videos: list[str | Path], folder: AdaptFolder, cfg: AdaptConfig,
                calib: Calibration | None, fps: float | None, report: dict[str, Any],
                progress: bool = True, teacher: Run | None = None) -> list[Clip]:
    """Import ``videos`` into ``folder`` and label them with ``src``'s depth, ``teacher``'s segmentation
    (``src``'s own teacher by default) and the built-in VO; clips that cannot be used go to
    ``report["rejected"]`` with the reason. Both steps resume: a finished import and finished label
    frames are kept."""
    card = src.card()
    hfov = float(np.degrees(2 * np.arctan(card.camera.width / (2 * card.camera.fx))))
    with _stage(report, "import"):
        usable = _import_all(videos, folder, cfg, calib, hfov, fps, report, progress)
    with _stage(report, "label models"):
        specs = prepare_labeller(src, folder.depth_model, folder.teacher_model, teacher)
    with _stage(report, "label"):
        road_ok = _with_road(usable, specs["seg"], report)
        depth_of = {imp.name: _first_depth(cfg.label_depth, imp.path, cfg.label_config().name, specs["depth"])
                    for imp in road_ok}
        results = _label_all(road_ok, depth_of, specs["seg"], cfg, report, progress)
    return _kept(road_ok, results, depth_of, cfg, report)


@contextmanager
def _stage(report: dict[str, Any], name: str) -> Iterator[None]:
    """Time one stage into ``report["stages_s"]`` (a resumed stage counts what it did this time)."""
    t0 = time.perf_counter()
    try:
        yield
    finally:
        report.setdefault("stages_s", {})[name] = round(time.perf_counter() - t0, 1)


def _import_all(videos: list[str | Path], folder: AdaptFolder, cfg: AdaptConfig, calib: Calibration | None,
                hfov: float, fps: float | None, report: dict[str, Any], progress: bool) -> list[Imported]:
    """The videos imported as clips long enough and moving enough to label; the others rejected."""
    names: set[str] = set()
    usable = []
    with progress_bar(desc="import", unit="frame", enabled=progress) as bar:
        for v in videos:
            name = clip_name(Path(v), names)
            names.add(name)
            try:
                imp = import_clip(v, folder.clip(name), calib, hfov, fps, cfg.max_fps, progress=bar.update)
                need = cfg.labels.horizon_s + 1.0 / cfg.labels.rate
                if imp.frames / imp.fps < need:
                    raise UnusableClipError(f"too short: {imp.frames / imp.fps:.1f} s, a label needs {need:.1f} s "
                                            f"(T = {cfg.labels.horizon_s:g} s)")
                moving = moving_seconds(imp.path, imp.fps)
                if moving < cfg.min_moving_s:
                    raise UnusableClipError(f"standing still: the image moves in {moving:.1f} s of "
                                            f"{imp.frames / imp.fps:.1f} s, at least {cfg.min_moving_s:g} s needed")
            except UnusableClipError as e:
                report["rejected"][name] = str(e)
                continue
            report["clips"][name] = {"source": imp.source, "frames": imp.frames, "fps": imp.fps,
                                     "camera": imp.camera, "moving_s": round(moving, 1)}
            usable.append(imp)
    return usable


def _with_road(usable: list[Imported], seg: str, report: dict[str, Any]) -> list[Imported]:
    """The clips whose road the teacher finds; the others rejected."""
    road_ok = []
    for imp in usable:
        share = road_share(make_seg(seg, ClipData(imp.path, SequenceMeta.read(imp.path), imp.frames)), imp.frames)
        report["clips"][imp.name]["road_share"] = round(share, 3)
        if share < MIN_ROAD_SHARE:
            report["rejected"][imp.name] = (f"no road found: the teacher sees road in {100 * share:.1f} % of the lower "
                                            f"half of the frames (at least {100 * MIN_ROAD_SHARE:g} % needed)")
            del report["clips"][imp.name]
        else:
            road_ok.append(imp)
    return road_ok


def _label_all(road_ok: list[Imported], depth_of: dict[str, str], seg: str, cfg: AdaptConfig,
               report: dict[str, Any], progress: bool) -> dict[str, Any]:
    """Label every clip with its depth source (``depth_of``, updated where it falls back); the results."""
    results: dict[str, Any] = {}
    with progress_bar(total=0, desc="label", unit="frame", enabled=progress) as bar:
        def on_total(n: int) -> None:
            bar.total = (bar.total or 0) + n
            bar.refresh()

        def label(group: list[Imported], force: bool = False) -> None:
            for depth in sorted({depth_of[imp.name] for imp in group}):
                part = [imp for imp in group if depth_of[imp.name] == depth]
                sources = Sources(depth=depth, seg=seg, poses="vo")
                done = label_many([i.path for i in part], cfg.label_config(depth), sources, jobs=1, progress=bar.update,
                                  on_total=on_total, force=force)
                results.update({imp.name: r for imp, r in zip(part, done, strict=True)})

        label(road_ok)
        # auto: a clip the depth head does not fit is labelled from the road plane: the camera file's
        # mounting, else the plane square to the direction the car travels at the assumed height
        fallback = [imp for imp in road_ok if cfg.label_depth == "auto" and depth_of[imp.name] != "ground"
                    and results[imp.name].status == "rejected"]
        for imp in fallback:
            report["clips"][imp.name]["model_depth_rejected"] = results[imp.name].message
            depth_of[imp.name] = "ground"
        label(fallback, force=True)
    return results


def _kept(road_ok: list[Imported], results: dict[str, Any], depth_of: dict[str, str], cfg: AdaptConfig,
          report: dict[str, Any]) -> list[Clip]:
    """The labelled clips with blind spots in their labels; the others rejected with the reason."""
    lcfg = cfg.label_config()
    labelled = []
    for imp in road_ok:
        r = results[imp.name]
        report["clips"][imp.name]["label_depth"] = "ground" if depth_of[imp.name] == "ground" else "model"
        if depth_of[imp.name] == "ground":
            report["clips"][imp.name]["road_plane_from"] = _plane_from(imp.path, cfg)
        frames = tuple(SequenceFolder(imp.path).labels(lcfg.name).frames()) if r.status == "ok" else ()
        if not frames:
            report["rejected"][imp.name] = f"labels {r.status}: {r.message or 'no label frame'}"
            report["clips"].pop(imp.name, None)
            continue
        cov = _coverage(imp.path, lcfg.name)
        if cov["blind_spot_share_of_v"] < MIN_BLIND_SPOT_SHARE:
            report["rejected"][imp.name] = (
                f"no blind spot in its labels ({100 * cov['blind_spot_share_of_v']:.2f} % of V over "
                f"{cov['label_frames']} frames, at least {100 * MIN_BLIND_SPOT_SHARE:g} % needed): nothing within "
                f"{lcfg.vis_range:g} m hid road that came into view; fine-tuning on it would teach that nothing is "
                "ever hidden. Record streets with parked cars, traffic or bends nearby")
            report["clips"].pop(imp.name, None)
            continue
        report["clips"][imp.name].update(cov)
        labelled.append(Clip(imp.path, "user", frames))
    return labelled


def _plane_from(clip: Path, cfg: AdaptConfig) -> str:
    """Where a clip's road plane comes from when it is labelled from it (said in the report)."""
    if Calibration.read(SequenceFolder(clip).calibration_path).mounting is not None:
        return "the camera file's mounting"
    height = cfg.label_config("ground").camera_height
    return (f"pitch and yaw from the direction of travel, the camera {height:g} m above the road "
            f"({'--camera-height' if cfg.labels.camera_height else 'assumed: --camera-height states it'})")


def _first_depth(choice: str, clip: Path, label: str, model_spec: str) -> str:
    """The depth source spec a clip is first labelled with (``AdaptConfig.label_depth``): ``auto``
    tries the depth head first, unless the clip's labels were already made from the road plane (a
    resumed adaptation keeps them)."""
    if choice == "ground":
        return "ground"
    if choice == "auto" and made_with(SequenceFolder(clip).labels(label)).get("sources", {}).get("depth") == "ground":
        return "ground"
    return model_spec


def tune(src: Run, labelled: list[Clip], out: str | Path, cfg: AdaptConfig, report: dict[str, Any],
         export: bool = False, progress: bool = True) -> dict[str, Any]:
    """Fine-tune ``src``'s B on the labelled clips, choose the threshold on the held-out part by
    agreement with its labels, write the adapted run to ``out`` (and, with ``export``, its int8
    model); fills and returns ``report``."""
    import torch

    model, card = src.load_model()
    teacher, _, teacher_scale = load_teacher(src)
    lcfg = cfg.label_config()
    train, held = _split(labelled, cfg.holdout_fraction, lcfg.horizon_frames, cfg.seed)
    size = card.input_size
    train_ds = BlindSpotDataset(train, size, augment=True, label_name=lcfg.name, seed=cfg.seed,
                                camera=card.camera, mounting=card.mounting)
    held_ds = BlindSpotDataset(held, size, label_name=lcfg.name, camera=card.camera, mounting=card.mounting)
    torch.set_num_threads(cfg.threads)
    before = agreement(model, held_ds)
    if before.counts[0].tp + before.counts[0].fn == 0:
        raise AdaptError(f"the held-out frames ({', '.join(c.path.name for c in held)}) hold no blind spot: agreement "
                         "cannot be measured nor a threshold chosen; add clips or hold out more (--holdout)")
    grid = tuple(src.config().get("train", {}).get("distill_grid", (8, 16)))
    use_teacher = bool(card.spec.get("distill", True))
    with _stage(report, "fine-tune"):
        losses = finetune_b(model, train_ds, cfg, teacher if use_teacher else None, teacher_scale, grid, progress)
        after = agreement(model, held_ds)
    threshold, best = after.best()
    b_th, b_best = before.best()
    source_threshold = card.threshold
    if source_threshold is None:
        raise ValueError("the source model's card has no threshold: nothing to compare the adapted one with")
    as_trained = at_threshold(before, source_threshold)
    if best["iou"] < as_trained["iou"] or best["iou"] <= b_best["iou"]:
        # never hand out a model that the user's own held-out labels score below the one it came from,
        # nor one that only beats it by a threshold: both are measured at their best threshold, and a
        # gain a threshold alone gives is the labels' bias (their own threshold is chosen on them), not
        # what B learnt; the source keeps the threshold it was trained to
        report["kept_source"] = (f"fine-tuning reached {best['iou']:.3f} agreement with the held-out labels; the "
                                 f"source model reaches {as_trained['iou']:.3f} at its threshold and "
                                 f"{b_best['iou']:.3f} at the labels' best ({b_th:.2f}): the adapted run is the "
                                 "source model as it was (more or longer clips may help)")
        report["fine_tuned_agreement"] = {"threshold": threshold, **best}
        model, _ = src.load_model()
        threshold, best = source_threshold, as_trained
    report["split"] = {"train_frames": len(train_ds), "held_out_frames": len(held_ds),
                       "train": [f"{c.path.name}[{c.frames[0]}..{c.frames[-1]}]" for c in train],
                       "held_out": [f"{c.path.name}[{c.frames[0]}..{c.frames[-1]}]" for c in held]}
    report["agreement"] = {
        "measure": "IoU inside V against the held-out T-frame labels of the user's clips",
        "before": at_threshold(before, source_threshold), "before_at_its_best_threshold": {"threshold": b_th, **b_best},
        "after": {"threshold": threshold, **best}}
    report["fine_tune"] = {"steps": cfg.steps, "seed": cfg.seed, "loss_first_last": [losses[0], losses[-1]],
                           "trained": "B (D frozen)"}

    report["weights_sha256"] = write_adapted(src, Path(out), model, card, threshold, best, lcfg.name, train, held)
    if export:
        path = Path(out) / EXPORT_NAME
        with _stage(report, "export"):
            kept = card.weights_sha256 if "kept_source" in report else None
            report["export"] = export_adapted(out, path, labelled, kept)
    return report


def adapt(run_dir: str | Path, videos: list[str | Path], out: str | Path, cfg: AdaptConfig | None = None,
          calib: str | Path | None = None, fps: float | None = None, export: bool = False,
          resume: bool = False, force: bool = False, progress: bool = True,
          teacher: str | Path | None = None) -> dict[str, Any]:
    """Adapt the run ``run_dir`` to the recordings ``videos`` (videos, image folders or sequence
    folders; only their frames and camera are read) and write the adapted run to ``out``; returns
    the report (also ``out/adapt/report.json``). ``teacher``: a run whose segmentation teacher labels
    the road and road users (by default ``run_dir``'s own). Clips that cannot be used are reported
    with the reason; ``AdaptError`` when none can, or when ``out`` is taken (see ``resume`` /
    ``force``)."""
    cfg = cfg or AdaptConfig()
    t0 = time.perf_counter()
    src = Run(run_dir)
    try:
        card = src.card()
        model, _ = src.load_model()
        if model.oracle_depth:
            raise AdaptError(f"{run_dir}: a {card.variant!r} run cannot be adapted: {ORACLE_DEPTH_NOTE}")
        load_teacher(src)
        labeller = Run.of_teacher(teacher) if teacher else None
        if labeller is not None:
            load_teacher(labeller, src)
    except (FileNotFoundError, ValueError) as e:
        raise AdaptError(str(e)) from None
    if card.threshold is None:
        raise AdaptError(f"{run_dir}: the run has no decision threshold (training did not finish)")
    cal = Calibration.read(calib) if calib else None
    out = Path(out)
    labelling = _labelling_settings(run_dir, card.weights_sha256, videos, calib, fps, cfg, labeller)
    folder = _prepare_out(src, out, labelling, resume, force)
    folder.write_json(folder.config_path, {"labelling": labelling, "config": cfg.to_dict()})
    report: dict[str, Any] = {"run": str(run_dir), "out": str(out), "config": cfg.to_dict(), "clips": {},
                              "rejected": {}}
    labelled = label_clips(src, videos, folder, cfg, cal, fps, report, progress, labeller)
    if not labelled:
        folder.write_json(folder.report_path, {**report, "status": "failed"})
        why = "; ".join(f"{k}: {v}" for k, v in report["rejected"].items()) or "no clip given"
        raise AdaptError(f"no clip could be labelled ({why})")
    try:
        tune(src, labelled, out, cfg, report, export, progress)
    except AdaptError:
        folder.write_json(folder.report_path, {**report, "status": "failed"})
        raise
    report["seconds"] = round(time.perf_counter() - t0, 1)
    report["status"] = "ok"
    folder.write_json(folder.report_path, report)
    return report
