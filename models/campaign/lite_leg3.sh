#!/usr/bin/env bash
# lite-light, leg 3: leg 2 with a share of guessed cameras. The same start (leg L1's weights), learning
# rate, data, teacher and seed as leg 2, and 30 % of the training samples warped with the camera a user
# without a camera file gets (data.guessed_camera): leg 2 against leg 3 is the measure of that share alone.
# Resumable: run it again and it goes on from its last state.
#   cd ~/.cache/bsn-edge/campaign && REPO=/path/to/bsn-edge /path/to/bsn-edge/models/campaign/lite_leg3.sh
set -euo pipefail
REPO=${REPO:?set REPO to the checkout}
BIN=$REPO/.venv/bin
[ -f lite1/model.pt ] || { echo "lite_leg3.sh: no lite1/ here: run lite_leg1.sh first" >&2; exit 2; }
resume=()                       # go on from the last state; a run that never reached one starts again
if [ -f lite3/state.pt ]; then resume=(--resume); elif [ -d lite3 ]; then resume=(--force); fi
"$BIN/bsn-train" --config "$REPO/configs/campaign.toml" --data data --out lite3 "${resume[@]}" \
  --set 'model.name="lite-light"' --set "teacher.checkpoint=\"$REPO/models/default\"" \
  --set train.init=\"lite1\" --set train.lr=0.0005 --set train.encoder_lr=0.1 --set train.seed=6 \
  --set data.guessed_camera=0.3
