#!/usr/bin/env bash
# Judge a campaign leg against the shipped default, as legs 1-5 and S1 were: export it as the default is
# exported (int8, 7-bit weights, calibrated on calib/), held-out IoU and depth beside the models already in
# benchmarks/results/cameras.json, the real cameras' depth, the real footage side by side for the eye, and
# held-out IoU against model-only frames/s. Run from the campaign folder (data/, heldout/, calib/); no
# timing is taken until the last step, which needs the machine to itself (stop any training first).
#   usage: judge.sh CHECKOUT RUN "LABEL" OUT        (OUT must not exist yet: FORCE=1 to write into it)
set -euo pipefail
REPO=$(cd "${1:?the bsn-edge checkout}" && pwd)
RUN=${2:?a bsn-train run folder}
LABEL=${3:?the name the leg gets in the reports}
OUT=$(realpath -m "${4:?a folder for the results}")
B=$REPO/.venv/bin
HERE=$PWD
for d in heldout/plain heldout/platoon heldout/queue heldout/earlier calib; do
  [ -d "$d" ] || { echo "judge.sh: no $d in $HERE: run it from the campaign folder" >&2; exit 2; }
done
[ -f "$RUN/checkpoint.json" ] || { echo "judge.sh: $RUN has no checkpoint.json: not a bsn-train run" >&2; exit 2; }
if [ -e "$OUT" ] && [ -z "${FORCE:-}" ]; then
  echo "judge.sh: $OUT exists; FORCE=1 writes into it" >&2; exit 2
fi
mkdir -p "$OUT"
MODEL=$OUT/model_int8.onnx
SHIPPED=$("$B/python" -c "from bsn_edge.default_model import DEFAULT_MODEL; print(DEFAULT_MODEL)")
"$B/bsn-export" --checkpoint "$RUN" --out "$MODEL" --int8 --reduce-range --int8-frames calib
cp "$REPO/benchmarks/results/cameras.json" "$OUT/"
cd "$REPO"
"$B/python" -m bsn_edge.benchmarks.bench_cameras --keep --out "$OUT" \
  --set "no platoon=$HERE/heldout/plain" --set "platoon=$HERE/heldout/platoon" \
  --set "slow traffic=$HERE/heldout/queue" --set "earlier world=$HERE/heldout/earlier" \
  --model "$LABEL=$MODEL"
"$B/python" -m bsn_edge.benchmarks.bench_realcam --out "$OUT/realcam" --model "$MODEL"
"$B/python" -m bsn_edge.benchmarks.bench_realview --out "$OUT/realview" --model "default=$SHIPPED" \
  --model "$LABEL=$MODEL"
DEFAULT_LABEL=${DEFAULT_LABEL:-"shared-light S3 (shipped)"}   # the default's name in cameras.md
"$B/python" -m bsn_edge.benchmarks.bench_tradeoff --cameras "$OUT/cameras.json" --out "$OUT" \
  --model "$DEFAULT_LABEL=$SHIPPED" --model "$LABEL=$MODEL"
echo "judged $RUN: $OUT (cameras.md, realcam/, realview/, tradeoff*.md)"
