#!/usr/bin/env bash
# The living student (#102): shared-light from the shipped default's weights with its dead channels re-drawn
# (train.revive), trained under AdamW (decoupled decay, none on norm scales and biases) on both worlds: the
# campaign's rendered clips and CamVid's drives with their T-frame labels (every drive but the held-out 0006R0),
# a quarter of each batch real, distilled from the real teacher (lab/campaign/teacher_real, 99.4 % alive),
# the positive pixels of people and cyclists weighted PEOPLE (bench_label_classes: 3-7 % of the positives).
# 6,000 steps at 2.5e-4, seed 7. Resumable: run it again and it goes on from its last state (every 500 steps).
#   cd ~/.cache/bsn-edge/campaign && REPO=/path/to/bsn-edge /path/to/bsn-edge/lab/campaign/living_leg.sh
set -euo pipefail
REPO=${REPO:?set REPO to the checkout}
RUN=${RUN:-living2}
REAL=${REAL:-0.25}
PEOPLE=${PEOPLE:-4.0}
STEPS=${STEPS:-6000}
BIN=$REPO/.venv/bin
[ -f data/.made ] || { echo "no data/.made here: make the campaign's data first (make_data.sh)" >&2; exit 1; }
grep -q '"frames"' data/camvid_0016E5_train/labels/T5s/report.json 2>/dev/null \
  || { echo "no CamVid T-frame labels in data/: run FORCE=1 make_camvid.sh" >&2; exit 1; }
resume=()
if [ -f "$RUN/state.pt" ]; then resume=(--resume); elif [ -d "$RUN" ]; then resume=(--force); fi
"$BIN/bsn-train" --config "$REPO/configs/campaign.toml" --data data --out "$RUN" "${resume[@]}" \
  --set 'model.name="shared-light"' --set "train.init=\"$REPO/models/default\"" --set train.revive=true \
  --set "teacher.checkpoint=\"$REPO/lab/campaign/teacher_real\"" --set "train.lr=${LR:-0.00025}" \
  --set train.seed=7 --set "train.steps=$STEPS" --set train.eval_every=1000 --set "data.real_share=$REAL" \
  --set "train.people_weight=$PEOPLE"
