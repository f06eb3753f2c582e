#!/usr/bin/env bash
# lite-light, leg L1F: leg L1 with the encoder's batch-norm statistics frozen at ImageNet's
# (train.encoder_bn = "frozen"; scale and shift still learn). Everything else is L1's (data, teacher,
# learning rates, seed), so L1 against L1F measures frozen statistics alone. When it ends, its run is
# shipped (fp16) to models/campaign/lite1f in the checkout, so no cache has to survive for its
# judgement or the next leg. Resumable: run it again and it goes on from its last state.
#   cd ~/.cache/bsn-edge/campaign && REPO=/path/to/bsn-edge /path/to/bsn-edge/models/campaign/lite_leg1f.sh
set -euo pipefail
REPO=${REPO:?set REPO to the checkout}
BIN=$REPO/.venv/bin
if [ ! -f data/.made ]; then
  BIN=$BIN "$REPO/models/campaign/make_data.sh" data
  BIN=$BIN FIRST=16 "$REPO/models/campaign/make_data.sh" data
  touch data/.made
fi
resume=()                       # go on from the last state; a run that never reached one starts again
if [ -f lite1f/state.pt ]; then resume=(--resume); elif [ -d lite1f ]; then resume=(--force); fi
"$BIN/bsn-train" --config "$REPO/configs/campaign.toml" --data data --out lite1f "${resume[@]}" \
  --set 'model.name="lite-light"' --set "teacher.checkpoint=\"$REPO/models/default\"" \
  --set train.encoder_lr=0.1 --set 'train.encoder_bn="frozen"' --set train.seed=5
SHIP=$REPO/models/campaign/lite1f
if [ ! -e "$SHIP" ]; then
  "$BIN/python" -c "import sys; from bsn_edge.train.run import Run; Run(sys.argv[1]).ship(sys.argv[2])" lite1f "$SHIP"
  echo "shipped lite1f to $SHIP"
fi
