#!/usr/bin/env bash
# lite-light, leg 1: D and B on one EfficientNet-Lite0 that starts from its ImageNet weights, on the
# campaign's data (make_data.sh, seeds 0-31 per style: leg 3's 160 clips), the default's teacher, the
# encoder at a tenth of the learning rate. Resumable: run it again and it goes on from its last state.
#   cd ~/.cache/bsn-edge/campaign && REPO=/path/to/bsn-edge /path/to/bsn-edge/models/campaign/lite_leg1.sh
# Leg L1F, the same with the encoder's batch-norm statistics frozen at ImageNet's, shipped (fp16) into
# the checkout when it ends:
#   RUN=lite1f BN=frozen SHIP=/path/to/bsn-edge/models/campaign/lite1f REPO=... .../lite_leg1.sh
# Leg L1T, L1 with domain randomisation: half the samples' vehicles and people repainted and shown
# see-through (as leg S5) and half the samples through a camera of their own (data.camera_look):
#   RUN=lite1t OBJECTS=0.5 LOOK=0.5 SHIP=/path/to/bsn-edge/models/campaign/lite1t REPO=... .../lite_leg1.sh
# Leg L1S, L1T with the encoder at a hundredth of the learning rate (how much of ImageNet it keeps):
#   RUN=lite1s ENCODER_LR=0.01 OBJECTS=0.5 LOOK=0.5 SHIP=/path/to/bsn-edge/models/campaign/lite1s REPO=... .../lite_leg1.sh
# TEACHER=$PWD/teacher_lite0 distils from the teacher on Lite0 (teacher_lite0.sh) instead of the default's.
set -euo pipefail
REPO=${REPO:?set REPO to the checkout}
RUN=${RUN:-lite1}               # the run's folder here
BN=${BN:-batch}                 # train.encoder_bn: batch or frozen
TEACHER=${TEACHER:-$REPO/models/default}   # teacher.checkpoint: the run whose teacher B distils from
OBJECTS=${OBJECTS:-0}           # data.object_repaint and data.object_see_through: shares of samples
LOOK=${LOOK:-0}                 # data.camera_look: share of samples
SEED=${SEED:-5}                 # train.seed
ENCODER_LR=${ENCODER_LR:-0.1}   # train.encoder_lr: the encoder's share of the learning rate
SHIP=${SHIP:-}                  # where the finished run is shipped (fp16), if anywhere
BIN=$REPO/.venv/bin
if [ ! -f data/.made ]; then
  BIN=$BIN "$REPO/models/campaign/make_data.sh" data
  BIN=$BIN FIRST=16 "$REPO/models/campaign/make_data.sh" data
  touch data/.made
fi
resume=()                       # go on from the last state; a run that never reached one starts again
if [ -f "$RUN/state.pt" ]; then resume=(--resume); elif [ -d "$RUN" ]; then resume=(--force); fi
"$BIN/bsn-train" --config "$REPO/configs/campaign.toml" --data data --out "$RUN" "${resume[@]}" \
  --set 'model.name="lite-light"' --set "teacher.checkpoint=\"$TEACHER\"" \
  --set "train.encoder_lr=$ENCODER_LR" --set "train.encoder_bn=\"$BN\"" --set "train.seed=$SEED" \
  --set "data.object_repaint=$OBJECTS" --set "data.object_see_through=$OBJECTS" --set "data.camera_look=$LOOK"
if [ -n "$SHIP" ] && [ ! -e "$SHIP" ]; then
  "$BIN/python" -c "import sys; from bsn_edge.train.run import Run; from bsn_edge.train.ship import ship_run; ship_run(Run(sys.argv[1]), sys.argv[2])" "$RUN" "$SHIP"
  echo "shipped $RUN to $SHIP"
fi
