#!/usr/bin/env bash
# The student on both worlds: shared-light from the shipped default's weights, on the campaign's clips
# (make_data.sh, FIRST=16 make_data.sh, make_earlier.sh) and CamVid's drives with their T-frame labels
# (make_camvid.sh; every drive but the held-out 0006R0), a quarter of each batch real, distilled from the
# real teacher (lab/campaign/teacher_real). 2,000 steps at 2.5e-4, seed 6. Resumable: run it again and it
# goes on from its last state (every 500 steps).
#   cd ~/.cache/bsn-edge/campaign && REPO=/path/to/bsn-edge /path/to/bsn-edge/lab/campaign/real_leg.sh
# Its control, the same leg without real pictures: RUN=real0 REAL=0 .../real_leg.sh
# R3, the same with the default's synthetic-only teacher: RUN=real3 TEACHER=default .../real_leg.sh
# R4, R2 at 1e-4 (a leg that moves less from the default): RUN=real4 LR=0.0001 .../real_leg.sh
# R5, R2 with the rendered clips' road users unknown too: RUN=real5 DATA=data_uu .../real_leg.sh
set -euo pipefail
REPO=${REPO:?set REPO to the checkout}
RUN=${RUN:-real1}
REAL=${REAL:-0.25}
DATA=${DATA:-data}       # data_uu: the rendered clips with road users unknown too (make_users_unknown.sh)
STEPS=${STEPS:-2000}
TEACHER=${TEACHER:-campaign/teacher_real}   # under models/: the teacher distilled from
BIN=$REPO/.venv/bin
[ -f "$DATA/.made" ] || { echo "no $DATA/.made here: make the campaign's data first (make_data.sh)" >&2; exit 1; }
[ -f "$DATA/camvid_0016E5_train/labels/T5s/report.json" ] || { echo "no CamVid labels in data/: run make_camvid.sh" >&2; exit 1; }
resume=()
if [ -f "$RUN/state.pt" ]; then resume=(--resume); elif [ -d "$RUN" ]; then resume=(--force); fi
"$BIN/bsn-train" --config "$REPO/configs/campaign.toml" --data "$DATA" --out "$RUN" "${resume[@]}" \
  --set 'model.name="shared-light"' --set "train.init=\"$REPO/models/default\"" \
  --set "teacher.checkpoint=\"$REPO/models/$TEACHER\"" --set "train.lr=${LR:-0.00025}" --set train.seed=6 \
  --set "train.steps=$STEPS" --set train.eval_every=500 --set "data.real_share=$REAL"
