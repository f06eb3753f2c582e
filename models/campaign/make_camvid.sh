#!/usr/bin/env bash
# usage (in the campaign folder): make_camvid.sh [DATA]; REPO points at the checkout.
# CamVid's labelled drives as sequence folders in DATA (labels.camvid.write_sequence), every drive but the
# held-out one (0006R0, bsn-bench --only camvid's): pictures, labels as trainIds, an empty V until T-frame
# labels are made for them. Finished drives are skipped.
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
    if (out / "meta.json").is_file():
        continue
    camvid.write_sequence(d, out)
    print(f"{out}: {len(d.frames)} frames, {1 / d.step_s:g} frames/s")
PY
