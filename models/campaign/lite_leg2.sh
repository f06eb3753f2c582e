#!/usr/bin/env bash
# lite-light, leg 2: on from leg L1's weights (its validation curve was still rising at 9,000 steps) with
# a warm restart at half the learning rate, the same data and teacher, another seed. Resumable: run it
# again and it goes on from its last state.
#   cd ~/.cache/bsn-edge/campaign && REPO=/path/to/bsn-edge /path/to/bsn-edge/models/campaign/lite_leg2.sh
set -euo pipefail
REPO=${REPO:?set REPO to the checkout}
BIN=$REPO/.venv/bin
[ -f lite1/model.pt ] || { echo "lite_leg2.sh: no lite1/ here: run lite_leg1.sh first" >&2; exit 2; }
resume=()                       # go on from the last state; a run that never reached one starts again
if [ -f lite2/state.pt ]; then resume=(--resume); elif [ -d lite2 ]; then resume=(--force); fi
"$BIN/bsn-train" --config "$REPO/configs/campaign.toml" --data data --out lite2 "${resume[@]}" \
  --set 'model.name="lite-light"' --set "teacher.checkpoint=\"$REPO/models/default\"" \
  --set train.init=\"lite1\" --set train.lr=0.0005 --set train.encoder_lr=0.1 --set train.seed=6
