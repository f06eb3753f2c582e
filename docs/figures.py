"""The README's pictures of the synthetic world.

    python docs/figures.py --data DIR --out docs/img

``styles.png``: ``bsn-sheet``'s contact sheet of one clip per style under ``DIR`` (RGB, depth,
semantics, true blind spots). ``sensor.png``: one frame rendered twice from the same seed, without
and with the sensor effects, side by side at full size.
"""

from __future__ import annotations

import argparse
import dataclasses
from itertools import islice
from pathlib import Path

import cv2
import numpy as np

from bsn_edge.cli import sheet
from bsn_edge.sequence import write_image
from bsn_edge.synth import STYLES, SynthConfig, make_clip
from bsn_edge.synth.clip import render_frames

SENSOR_FRAME = 30


def _frame(cfg: SynthConfig, i: int) -> np.ndarray:
    return next(islice(render_frames(make_clip(cfg)), i, None)).rgb


def sensor_figure(cfg: SynthConfig) -> np.ndarray:
    """The frame ``SENSOR_FRAME`` of ``cfg`` without (left) and with (right) the sensor effects."""
    plain = _frame(dataclasses.replace(cfg, sensor_effects=False), SENSOR_FRAME)
    real = _frame(cfg, SENSOR_FRAME)
    gap = np.full((plain.shape[0], 8, 3), 255, np.uint8)
    img = np.concatenate([plain, gap, real], axis=1)
    for text, x in (("rendered", 8), ("sensor effects", plain.shape[1] + 16)):
        cv2.putText(img, text, (x, 22), cv2.FONT_HERSHEY_SIMPLEX, 0.6, (255, 255, 255), 2, cv2.LINE_AA)
    return img


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--data", required=True, help="folder with one clip per style named STYLE_0")
    p.add_argument("--out", default="docs/img")
    p.add_argument("--seed", type=int, default=3, help="seed of the sensor-effects frame (town)")
    args = p.parse_args(argv)
    out = Path(args.out)
    seqs = [str(Path(args.data) / f"{s}_0") for s in sorted(STYLES)]
    rc = sheet.main([*seqs, "--out", str(out / "styles.png"), "--rows", "2"])
    if rc == 0:   # half size: the README's page is narrower than the sheet
        img = cv2.imread(str(out / "styles.png"))
        write_image(out / "styles.png", cv2.resize(img, None, fx=0.5, fy=0.5, interpolation=cv2.INTER_AREA))
    cfg = SynthConfig(frames=SENSOR_FRAME + 1, style="town", seed=args.seed)
    write_image(out / "sensor.png", sensor_figure(cfg))
    print(f"wrote {out / 'sensor.png'}")
    return rc


if __name__ == "__main__":
    raise SystemExit(main())
