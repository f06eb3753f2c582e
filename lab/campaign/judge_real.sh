#!/usr/bin/env bash
# Judge a leg of the lite-light campaign beside the shipped default (and beside another leg, when
# given), in one sitting and as the issue of the real-street default asks: exported as the default is
# (int8, 7-bit weights, calibrated on calib/); the real boxes (near and all occluders marked, by class,
# open road flagged), once more on the frames that have a camera file with it withheld; CamVid's held-out
# drive by its pixel labels (bench_camvid); held-out IoU
# per style (bystyle/STYLE); the real cameras' depth; the real footage side by side for the eye. No
# timing is taken. Run from the campaign folder (calib/, bystyle/).
#   usage: judge_real.sh CHECKOUT RUN LABEL OUT [OTHER_LABEL=OTHER_MODEL.onnx]
set -euo pipefail
REPO=$(cd "${1:?the bsn-edge checkout}" && pwd)
RUN=${2:?a bsn-train run folder}
LABEL=${3:?the name the leg gets in the reports}
OUT=$(realpath -m "${4:?a folder for the results}")
OTHER=${5:-}
B=$REPO/.venv/bin
HERE=$PWD
for d in calib bystyle/highway bystyle/suburb bystyle/town bystyle/urban; do
  [ -d "$d" ] || { echo "judge_real.sh: no $d in $HERE: run it from the campaign folder" >&2; exit 2; }
done
[ -f "$RUN/checkpoint.json" ] || { echo "judge_real.sh: $RUN has no checkpoint.json: not a bsn-train run" >&2; exit 2; }
if ! "$B/python" -c "import sys; from bsn_edge.train.run import Run; sys.exit(not Run(sys.argv[1]).finished())" "$RUN"; then
  echo "judge_real.sh: $RUN has not chosen its threshold yet (its training or final sweep is still running)" >&2; exit 2
fi
if [ -e "$OUT" ] && [ -z "${FORCE:-}" ]; then
  echo "judge_real.sh: $OUT exists; FORCE=1 writes into it" >&2; exit 2
fi
mkdir -p "$OUT"
MODEL=$OUT/model_int8.onnx
SHIPPED=$("$B/python" -c "from bsn_edge.default_model import DEFAULT_MODEL; print(DEFAULT_MODEL)")
[ -f "$MODEL" ] || "$B/bsn-export" --checkpoint "$RUN" --out "$MODEL" --int8 --reduce-range --int8-frames calib
models=(--model "default=$SHIPPED" --model "$LABEL=$MODEL")
[ -n "$OTHER" ] && models+=(--model "$OTHER")
cd "$REPO"
"$B/python" -m bsn_edge.benchmarks.bench_realboxes --out "$OUT/realboxes" "${models[@]}"
"$B/python" -m bsn_edge.benchmarks.bench_realboxes --out "$OUT/withheld" --name withheld --withhold-camera "${models[@]}"
"$B/python" -m bsn_edge.benchmarks.bench_camvid --out "$OUT/camvid" --like-area "${models[@]}"
sets=()
for s in highway suburb town urban; do sets+=(--set "$s=$HERE/bystyle/$s"); done
"$B/python" -m bsn_edge.benchmarks.bench_cameras --out "$OUT/cameras" "${sets[@]}" "${models[@]}"
"$B/python" -m bsn_edge.benchmarks.bench_realcam --out "$OUT/realcam" "${models[@]}"
"$B/python" -m bsn_edge.benchmarks.bench_realview --out "$OUT/realview" "${models[@]}"
echo "judged $RUN: $OUT (realboxes/, withheld/, camvid/, cameras/, realcam/, realview/)"
