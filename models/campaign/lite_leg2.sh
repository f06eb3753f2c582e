#!/usr/bin/env bash
# lite-light, leg 2: on from a finished leg 1's weights (its validation curve was still rising at 9,000
# steps) with a warm restart at half the learning rate, the same data and teacher, another seed.
# Resumable: run it again and it goes on from its last state.
#   cd ~/.cache/bsn-edge/campaign && REPO=/path/to/bsn-edge /path/to/bsn-edge/models/campaign/lite_leg2.sh
# Leg LF1, L1T's network on the model frame at its full size (lite-full), on from L1T's weights with L1T's
# randomisation, a 2,500-step schedule at a quarter of leg 1's rate, shipped (fp16) when it ends:
#   FROM=lite1t RUN=litef1 MODEL=lite-full LR=0.00025 STEPS=2500 OBJECTS=0.5 LOOK=0.5 \
#     SHIP=/path/to/bsn-edge/models/campaign/litef1 REPO=... .../lite_leg2.sh
set -euo pipefail
REPO=${REPO:?set REPO to the checkout}
FROM=${FROM:-lite1}             # the finished run it starts from (train.init)
RUN=${RUN:-lite2}               # the run's folder here
MODEL=${MODEL:-lite-light}      # model.name: lite-light, or lite-full (the same network at full size)
LR=${LR:-0.0005}                # train.lr: the warm restart's peak
OBJECTS=${OBJECTS:-0}           # data.object_repaint and data.object_see_through: shares of samples
LOOK=${LOOK:-0}                 # data.camera_look: share of samples
STEPS=${STEPS:-9000}            # train.steps: the whole schedule
SHIP=${SHIP:-}                  # where the finished run is shipped (fp16), if anywhere
BIN=$REPO/.venv/bin
[ -f "$FROM/checkpoint.json" ] || { echo "lite_leg2.sh: no run $FROM/ here: run lite_leg1.sh first" >&2; exit 2; }
if ! "$BIN/python" -c "import sys; from bsn_edge.train.run import Run; sys.exit(not Run(sys.argv[1]).finished())" "$FROM"; then
  echo "lite_leg2.sh: $FROM has not ended yet (no threshold chosen): let its leg finish first" >&2; exit 2
fi
resume=()                       # go on from the last state; a run that never reached one starts again
if [ -f "$RUN/state.pt" ]; then resume=(--resume); elif [ -d "$RUN" ]; then resume=(--force); fi
"$BIN/bsn-train" --config "$REPO/configs/campaign.toml" --data data --out "$RUN" "${resume[@]}" \
  --set "model.name=\"$MODEL\"" --set "teacher.checkpoint=\"$REPO/models/default\"" \
  --set "train.init=\"$FROM\"" --set train.lr=$LR --set train.encoder_lr=0.1 --set train.seed=6 \
  --set "train.steps=$STEPS" \
  --set "data.object_repaint=$OBJECTS" --set "data.object_see_through=$OBJECTS" --set "data.camera_look=$LOOK"
if [ -n "$SHIP" ] && [ ! -e "$SHIP" ]; then
  "$BIN/python" -c "import sys; from bsn_edge.train.run import Run; from bsn_edge.train.ship import ship_run; ship_run(Run(sys.argv[1]), sys.argv[2])" "$RUN" "$SHIP"
  echo "shipped $RUN to $SHIP"
fi
