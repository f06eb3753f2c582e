#!/usr/bin/env bash
# usage (in the campaign folder): make_camvid.sh [DATA]; REPO points at the checkout.
# CamVid's labelled drives as sequence folders in DATA (labels.camvid.write_sequence), every drive but the
# held-out one (0006R0, bsn-bench --only camvid's): pictures, labels as trainIds, a camera file of what is
# assumed; then their T-frame labels (T = 5 s at their 1 frame/s: 5 steps), from the road plane and
# odometry on matched features (bsn-label --depth ground --poses vo), road users the drive never showed road
# behind left out of V (--users-unknown: a second apart, few later frames look behind them). Finished drives
# and frames are skipped; FORCE=1 relabels.
set -euo pipefail
REPO=${REPO:?set REPO to the checkout}
D=${1:-data}
"$REPO/.venv/bin/python" - "$REPO/../shared/data/real/camvid" "$D" <<'PY'
import sys
from pathlib import Path

from bsn_edge.labels import camvid

root, data = Path(sys.argv[1]), Path(sys.argv[2])
for d in camvid.drives(root):
    if d.name == camvid.HELD_OUT:
        continue
    out = data / f"camvid_{d.name}_{d.split}"
    if (out / "calibration.json").is_file():
        continue
    camvid.write_sequence(d, out, force=out.exists())
    print(f"{out}: {len(d.frames)} frames, {1 / d.step_s:g} frames/s")
PY
"$REPO/.venv/bin/bsn-label" "$D"/camvid_*_* --rate 1 --T 5 --depth ground --seg files --poses vo --users-unknown \
  ${FORCE:+--force}
