#!/usr/bin/env bash
# shared-light, legs G1 to G3: the shipped default with a share of guessed cameras. From the default's
# weights (models/default, so no earlier leg's cache is needed), on leg 1's 88 clips (make_data.sh and
# make_earlier.sh), 2,500 steps at 2.5e-4, seed 6: leg S5's control, whose figures are recorded, with
# 30 % of the training samples warped with the camera a user without a camera file gets
# (data.guessed_camera). What those samples teach D (data.guessed_depth): G1 their metric depth (the
# default), G2 its shape only (DEPTH=scale-free RUN=guess2), G3 nothing (DEPTH=none RUN=guess3); the
# control shows no guessed camera (SHARE=0 RUN=guess0). Resumable: run it again and it goes on.
#   cd ~/.cache/bsn-edge/campaign && REPO=/path/to/bsn-edge /path/to/bsn-edge/models/campaign/shared_guess.sh
#   ... && RUN=guess2 DEPTH=scale-free REPO=/path/to/bsn-edge /path/to/bsn-edge/models/campaign/shared_guess.sh
set -euo pipefail
REPO=${REPO:?set REPO to the checkout}
RUN=${RUN:-guess1}
DEPTH=${DEPTH:-metric}
SHARE=${SHARE:-0.3}
BIN=$REPO/.venv/bin
[ -d data ] || { echo "shared_guess.sh: no data/ here: run make_data.sh and make_earlier.sh first" >&2; exit 2; }
resume=()                       # go on from the last state; a run that never reached one starts again
if [ -f "$RUN/state.pt" ]; then resume=(--resume); elif [ -d "$RUN" ]; then resume=(--force); fi
"$BIN/bsn-train" --config "$REPO/configs/campaign.toml" --data data --out "$RUN" "${resume[@]}" \
  --set 'model.name="shared-light"' --set "train.init=\"$REPO/models/default\"" \
  --set "teacher.checkpoint=\"$REPO/models/default\"" --set train.lr=0.00025 --set train.seed=6 \
  --set train.steps=2500 --set train.eval_every=500 --set data.guessed_camera=$SHARE \
  --set "data.guessed_depth=\"$DEPTH\""
