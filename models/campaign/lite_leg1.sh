#!/usr/bin/env bash
# lite-light, leg 1: D and B on one EfficientNet-Lite0 that starts from its ImageNet weights, on the
# campaign's data (make_data.sh, seeds 0-31 per style: leg 3's 160 clips), the default's teacher, the
# encoder at a tenth of the learning rate. Resumable: run it again and it goes on from its last state.
#   cd ~/.cache/bsn-edge/campaign && REPO=/path/to/bsn-edge /path/to/bsn-edge/models/campaign/lite_leg1.sh
set -euo pipefail
REPO=${REPO:?set REPO to the checkout}
BIN=$REPO/.venv/bin
if [ ! -f data/.made ]; then
  BIN=$BIN "$REPO/models/campaign/make_data.sh" data
  BIN=$BIN FIRST=16 "$REPO/models/campaign/make_data.sh" data
  touch data/.made
fi
resume=()                       # go on from the last state; a run that never reached one starts again
if [ -f lite1/state.pt ]; then resume=(--resume); elif [ -d lite1 ]; then resume=(--force); fi
"$BIN/bsn-train" --config "$REPO/configs/campaign.toml" --data data --out lite1 "${resume[@]}" \
  --set 'model.name="lite-light"' --set "teacher.checkpoint=\"$REPO/models/default\"" \
  --set train.encoder_lr=0.1 --set train.seed=5
