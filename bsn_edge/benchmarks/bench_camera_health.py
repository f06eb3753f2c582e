"""The camera-health check on real footage: false faults on every real clip, and each failure injected.

    python -m bsn_edge.benchmarks.bench_camera_health --out benchmarks/results

Every real clip in ``../shared/data/real`` (the videos whole, the parking-garage frames, CamVid's drives) runs
through :class:`~bsn_edge.runtime.visibility.CameraHealth` as ``bsn-run`` runs it (each frame and what the
shipped model sees of it: the model camera's warp of a camera with no camera file, on the frames' own clock):

- **false faults**: frames with a reason raised on the clean clip, and the longest such stretch;
- **detection**: each failure of :mod:`bsn_edge.benchmarks.corruptions` injected at every severity into the clips at
  least :data:`MIN_S` long: clean for :data:`CLEAN_S` (the running baselines learn), failed for
  :data:`FAILED_S`, clean again for :data:`AFTER_S` (a clip shorter than that plays on from its start). Caught:
  a reason raised within :data:`ONSET_BAR_S` of the failure (1 s; for fog, blur, contrast and brightness, which are
  judged against the camera's own baseline and must hold ``visibility.blur_hold_s`` first, 1 s after that: 4 s);
  recovered: CLEAR within :data:`CLEAR_BAR_S` of its end. A cover must also mark the sector it covers. A standing
  car (one real frame with a real sensor's noise for 10 s) must raise nothing;
- **cost**: the check's milliseconds per frame beside the shipped int8 model's, in the same run.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from bsn_edge.alerts.blindness import Blindness
from bsn_edge.alerts.sectors import SECTORS, SectorGeometry
from bsn_edge.runtime.camera_state import CameraState
from bsn_edge.runtime.engine import Engine
from bsn_edge.runtime.visibility import CameraHealth, VisibilityConfig
from bsn_edge.sequence.images import read_image
from bsn_edge.sequence.media import read_video

from .corruptions import CORRUPTIONS, ONE_SEVERITY, SEVERITIES, sensor_noise
from .real_samples import REAL
from .runner import Report, run

MIN_S = 4.0          # clips at least this long take injected failures
CLEAN_S, FAILED_S, AFTER_S = 2.0, 5.0, 2.5
ONSET_BAR_S, CLEAR_BAR_S = 1.0, 2.0
SLOW = ("fog", "blur", "contrast", "brightness")   # judged against the camera's baseline: raised after blur_hold_s
STANDING_S = 10.0
GARAGE_FPS = 25.0    # the garage drive's frames store no rate (about 20-30 frames/s)
SIDE_SECTOR = {"left": "LEFT", "centre": "CENTRE", "right": "RIGHT"}


@dataclass(frozen=True)
class Clip:
    name: str
    frames: list[np.ndarray]
    fps: float

    @property
    def seconds(self) -> float:
        return len(self.frames) / self.fps


def _rate(path: Path) -> float:
    cap = cv2.VideoCapture(str(path))
    fps = cap.get(cv2.CAP_PROP_FPS) or 25.0
    cap.release()
    return float(fps)


def real_clips(root: Path = REAL) -> list[Clip]:
    """Every real clip there, whole (videos, the garage drive's frames, CamVid's drives at their rates)."""
    out = []
    for name in ("dashcam_highway.mp4", "mountain_highway.mp4", "udacity_test_video.mp4",
                 "udacity_challenge_352x288.avi"):
        frames, fps = read_video(root / name), _rate(root / name)
        if frames:
            out.append(Clip(name, frames, fps))
    garage = root / "garage_drive"
    if garage.is_dir():
        pics = sorted(garage.glob("*.jpg"), key=lambda p: int(p.stem) if p.stem.isdigit() else -1)
        out.append(Clip("garage_drive", [read_image(p) for p in pics], GARAGE_FPS))
    if (root / "camvid").is_dir():
        from bsn_edge.labels import camvid

        for d in camvid.drives(root / "camvid"):
            out.append(Clip(f"camvid {d.name} {d.split}", [f.rgb() for f in d.frames], 1.0 / d.step_s))
    return out


class Watcher:
    """The check as the runtime runs it on one clip: the model camera's warp of an unknown camera."""

    def __init__(self, engine: Engine, cfg: VisibilityConfig) -> None:
        self.engine, self.cfg = engine, cfg
        self.columns = SectorGeometry(engine.card.camera).column_sector

    def run(self, frames: Iterator[np.ndarray], fps: float, engine_every: int = 0) -> tuple[list, dict[str, float]]:
        """Each frame's :class:`Visibility`, and the milliseconds per frame of the check (and of the model, on
        every ``engine_every``-th frame)."""
        state = CameraState(self.engine.card, None, background=False)
        health = CameraHealth(self.cfg, self.columns, len(SECTORS))
        out, look_s, model_s, models = [], 0.0, 0.0, 0
        for k, frame in enumerate(frames):
            mf = state.frame_for(frame)
            buf = mf.to_model(frame)
            t0 = time.perf_counter()
            out.append(health.look(k / fps, frame, buf))
            look_s += time.perf_counter() - t0
            if engine_every and k % engine_every == 0:
                t0 = time.perf_counter()
                self.engine.infer(buf[None])
                model_s += time.perf_counter() - t0
                models += 1
        state.close()
        return out, {"check_ms": 1e3 * look_s / max(len(out), 1), "model_ms": 1e3 * model_s / max(models, 1)}


def stretches(raised: list[bool], fps: float) -> float:
    """The longest run of raised frames, in seconds."""
    best = cur = 0
    for r in raised:
        cur = cur + 1 if r else 0
        best = max(best, cur)
    return best / fps


def scenario(clip: Clip, name: str, severity: int, rng: np.random.Generator) -> tuple[Iterator[np.ndarray], int, int]:
    """The clip clean, failed, clean again (played on from its start when short); the failure's first and
    last frame indices."""
    n0, n1, n2 = (round(s * clip.fps) for s in (CLEAN_S, FAILED_S, AFTER_S))
    fail = CORRUPTIONS.get(name)
    held = clip.frames[n0 % len(clip.frames)]

    def frames() -> Iterator[np.ndarray]:
        for k in range(n0 + n1 + n2):
            f = clip.frames[k % len(clip.frames)]
            if n0 <= k < n0 + n1:
                f = held if name == "frozen" else fail(f, severity, rng)  # type: ignore[misc]
            yield f

    return frames(), n0, n0 + n1


def _clean(watch: Watcher, clips: list[Clip], result: dict[str, Any]) -> tuple[list[str], list[dict[str, float]]]:
    """False faults on the clean clips: the table's rows, and the check's and the model's cost on each clip."""
    rows = ["| clip | frames | seconds | frames flagged | share | longest stretch | reasons |",
            "|---|---|---|---|---|---|---|"]
    costs = []
    for clip in clips:
        vis, cost = watch.run(iter(clip.frames), clip.fps, engine_every=5)
        costs.append(cost)
        flagged = [v.reason is not Blindness.CLEAR for v in vis]
        reasons = sorted({v.reason.name for v in vis if v.reason is not Blindness.CLEAR})
        r: dict[str, Any] = {"frames": len(vis), "flagged": int(sum(flagged)),
                             "share": round(sum(flagged) / len(vis), 4),
                             "longest_s": round(stretches(flagged, clip.fps), 2), "reasons": reasons}
        result["clean"][clip.name] = r
        rows.append(f"| {clip.name} | {len(vis)} | {clip.seconds:.1f} | {r['flagged']} | "
                    f"{100 * r['share']:.1f} % | {r['longest_s']:.2f} s | {', '.join(reasons) or '-'} |")
    return rows, costs


def _detection(watch: Watcher, long_clips: list[Clip], rng: np.random.Generator, result: dict[str, Any]) -> list[str]:
    """Each failure injected into the long clips at each severity: caught within its bar, recovered, the reason
    raised and, for a cover, the sector marked; the table's rows."""
    rows = ["| failure | severity | caught within its bar | median onset | recovered within 2 s | reason raised | "
            "right sector |", "|---|---|---|---|---|---|---|"]
    for name in [*CORRUPTIONS, "frozen"]:
        for severity in (5,) if name in (*ONE_SEVERITY, "frozen") else SEVERITIES:
            onsets: list[float] = []
            reasons: set[str] = set()
            recovered, caught, sector_ok = 0, 0, 0
            for clip in long_clips:
                frames, start, end = scenario(clip, name, severity, rng)
                vis, _ = watch.run(frames, clip.fps)
                raised = [k for k in range(start, len(vis)) if vis[k].reason is not Blindness.CLEAR]
                onset = (raised[0] - start) / clip.fps if raised else None
                bar = ONSET_BAR_S + (watch.cfg.blur_hold_s if name in SLOW else 0.0)
                if onset is not None and onset <= bar and raised[0] < end:
                    caught += 1
                    onsets.append(onset)
                    reasons.add(vis[raised[0]].reason.name)
                    if name.startswith("cover_"):
                        want = SECTORS.index(SIDE_SECTOR[name.removeprefix("cover_")])
                        sector_ok += any(vis[k].unseen[want] for k in range(start, end))
                clear = [k for k in range(end, len(vis)) if vis[k].reason is Blindness.CLEAR]
                recovered += bool(clear) and (clear[0] - end) / clip.fps <= CLEAR_BAR_S
            n = len(long_clips)
            result["detection"][f"{name}:{severity}"] = {
                "clips": n, "caught": caught, "median_onset_s": float(np.median(onsets)) if onsets else None,
                "recovered": recovered, "reasons": sorted(reasons), "right_sector": sector_ok}
            med = f"{np.median(onsets):.2f} s" if onsets else "-"
            side = f"{sector_ok} of {caught}" if name.startswith("cover_") else ""
            rows.append(f"| {name} | {severity} | {caught} of {n} | {med} | {recovered} of {n} | "
                        f"{', '.join(sorted(reasons)) or '-'} | {side} |")
    return rows


def _standing(watch: Watcher, long_clips: list[Clip], rng: np.random.Generator, result: dict[str, Any]) -> list[str]:
    """A standing car: one real frame with a real sensor's noise for ``STANDING_S``; the table's rows."""
    rows = ["| clip | seconds | frames flagged | reasons |", "|---|---|---|---|"]
    for clip in long_clips:
        frame = clip.frames[len(clip.frames) // 2]
        n = round(STANDING_S * clip.fps)
        vis, _ = watch.run((sensor_noise(frame, rng) for _ in range(n)), clip.fps)
        flagged = [v for v in vis if v.reason is not Blindness.CLEAR]
        result["standing"][clip.name] = {"frames": n, "flagged": len(flagged),
                                         "reasons": sorted({v.reason.name for v in flagged})}
        rows.append(f"| {clip.name} | {STANDING_S:g} | {len(flagged)} of {n} | "
                    f"{', '.join(sorted({v.reason.name for v in flagged})) or '-'} |")
    return rows


def measure(args: argparse.Namespace, p: argparse.ArgumentParser) -> Report | None:
    from bsn_edge.default_model import DEFAULT_MODEL

    clips = real_clips()
    if not clips:
        print(f"no real clips at {REAL}: nothing to measure")
        return None
    watch = Watcher(Engine(DEFAULT_MODEL, threads=2), VisibilityConfig())
    rng = np.random.default_rng(0)
    result: dict[str, Any] = {"clean": {}, "detection": {}, "standing": {}, "cost": {}}
    clean_rows, costs = _clean(watch, clips, result)
    long_clips = [c for c in clips if c.seconds >= MIN_S]
    det_rows = _detection(watch, long_clips, rng, result)
    stand_rows = _standing(watch, long_clips, rng, result)
    check = float(np.mean([c["check_ms"] for c in costs]))
    model = float(np.mean([c["model_ms"] for c in costs]))
    result["cost"] = {"check_ms": round(check, 3), "model_ms": round(model, 3), "share": round(check / model, 3)}
    md = ["# The camera-health check on real footage", "", __doc__.split("\n\n", 2)[2].strip(), "",
          "## False faults on the clean clips", "", *clean_rows, "",
          f"## Detection: each failure injected into {len(long_clips)} clips "
          f"({', '.join(c.name for c in long_clips)})", "", *det_rows, "",
          "## A standing car: one real frame with a real sensor's noise (2 grey levels), 10 s", "", *stand_rows, "",
          "## Cost per frame", "",
          f"The check {check:.2f} ms per frame, the shipped int8 model {model:.2f} ms (2 threads), on the same "
          f"frames in one run: {100 * check / model:.1f} % of the model's time.",
          "", "Clips: `../shared/data/real` (their sources and licences in its README)."]
    return Report(result, md, [f"false faults: {sum(r['flagged'] for r in result['clean'].values())} frames; "
                               f"cost {check:.2f} ms against the model's {model:.2f} ms"])


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", default="benchmarks/results")
    p.add_argument("--name", default="camera_health", help="the report's name in --out")
    return p


def main(argv: list[str] | None = None) -> int:
    return run(measure, parser(), argv)


if __name__ == "__main__":
    raise SystemExit(main())
