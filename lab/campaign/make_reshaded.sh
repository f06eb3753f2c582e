#!/usr/bin/env bash
# usage (from the campaign folder): make_reshaded.sh DATA OUT; BIN points at the checkout's .venv/bin
# The same clips as DATA rendered again by the shader of the checkout BIN belongs to. A street-world clip
# is hard-linked whole from DATA, then the images of its labelled frames (the only ones training reads)
# are rendered again from its own synth_config.json: same seed, so the same scene, which is checked
# (depth and blind spots equal DATA's on every re-rendered frame); its labels are made from depth,
# semantics and poses only, so they stay. Clips of other renderers (the earlier world) are hard-linked
# whole. Finished clips are skipped.
set -euo pipefail
BIN=${BIN:-.venv/bin}
SRC=${1:?the data folder to re-render}
OUT=${2:?a folder for the re-rendered clips}
mkdir -p "$OUT"
# -c, not stdin: the renderer's worker processes re-import the main module
RENDER=$(cat <<'EOF'
import json
import sys
from pathlib import Path

import numpy as np

from bsn_edge.sequence import read_mask, write_image
from bsn_edge.sequence.folder import SequenceFolder
from bsn_edge.sequence.images import DEPTH_SCALE, depth_to_png16, read_depth
from bsn_edge.synth import SynthConfig, make_clip, render_frames

src, tmp = SequenceFolder(sys.argv[1]), SequenceFolder(sys.argv[2])
cfg = SynthConfig(**json.loads(src.synth_config_path.read_text())["config"])
labelled = sorted({i for d in (src / "labels").iterdir() for i in src.labels(d.name).frames()})
for i, fr in zip(labelled, render_frames(make_clip(cfg), workers=2, indices=labelled), strict=True):
    if not (np.array_equal(read_depth(src.depth(i)), depth_to_png16(fr.depth) / np.float32(DEPTH_SCALE)) and
            np.array_equal(read_mask(src.bsgt(i)), fr.bsgt)):
        raise SystemExit(f"frame {i} of {src.path} renders another scene; {tmp.path} left as it is")
    tmp.rgb(i).unlink()          # a hard link into DATA: replaced, never written through
    write_image(tmp.rgb(i), fr.rgb)
EOF
)
for clip in "$SRC"/*/; do
  name=$(basename "$clip")
  dst=$OUT/$name
  [ -f "$dst/meta.json" ] && continue
  if [[ $name == earlier_* ]]; then
    cp -al "$clip" "$dst"
    continue
  fi
  rm -rf "$dst.part"
  cp -al "$clip" "$dst.part"
  rm -f "$dst.part/meta.json"   # written last: a clip without it is unfinished
  "$BIN/python" -c "$RENDER" "$clip" "$dst.part"
  cp -p "$clip/meta.json" "$dst.part/meta.json"
  mv "$dst.part" "$dst"
  echo "$name"
done
echo done
