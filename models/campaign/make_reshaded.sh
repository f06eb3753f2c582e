#!/usr/bin/env bash
# usage (from the campaign folder): make_reshaded.sh DATA OUT; BIN points at the checkout's .venv/bin
# The same clips as DATA rendered again by today's shader: every street-world clip re-rendered from its own
# synth_config.json (same seed, so the same depth, semantics, poses and blind spots, which are checked
# against DATA's), its labels hard-linked from DATA (they are made from depth, semantics and poses only);
# clips of other renderers (the earlier world) hard-linked whole. Finished clips are skipped.
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

from bsn_edge.synth import SynthConfig, write_clip

src, dst = Path(sys.argv[1]), Path(sys.argv[2])
cfg = SynthConfig(**json.loads((src / "synth_config.json").read_text())["config"])
tmp = dst.with_name(dst.name + ".part")
write_clip(cfg, tmp, force=True, video=False, workers=2)
for sub in ("depth", "semantic", "bsgt"):
    for f in sorted((src / sub).iterdir()):
        if f.read_bytes() != (tmp / sub / f.name).read_bytes():
            raise SystemExit(f"{tmp / sub / f.name} differs from {f}: not the same scene; left in {tmp}")
tmp.rename(dst)
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
  "$BIN/python" -c "$RENDER" "$clip" "$dst"
  cp -al "$clip/labels" "$dst/labels"
  echo "$name"
done
echo done
