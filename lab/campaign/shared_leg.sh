#!/usr/bin/env bash
# A short leg of shared-light from the shipped default's weights (models/default, so no earlier leg's
# cache is needed): 2,500 steps at 2.5e-4, seed 6, on leg 1's 88 clips (make_data.sh and
# make_earlier.sh; linked into data88/ when data/ holds more), the default's teacher. Each leg changes
# one thing against the control (RUN=guess0 SHARE=0), whose figures are recorded:
#   G1-G3  30 % of the training samples warped with the camera a user without a camera file gets
#          (data.guessed_camera); what they teach D (data.guessed_depth): G1 their metric depth,
#          G2 its shape only (DEPTH=scale-free RUN=guess2), G3 nothing (DEPTH=none RUN=guess3);
#   F1     B taught beyond the labels' V, out to 40 m of exact depth (train.bce_range_m):
#          RUN=far40 SHARE=0 RANGE=40.
# Resumable: run it again and it goes on.
#   cd ~/.cache/bsn-edge/campaign && REPO=/path/to/bsn-edge /path/to/bsn-edge/lab/campaign/shared_leg.sh
#   ... && RUN=far40 SHARE=0 RANGE=40 REPO=/path/to/bsn-edge /path/to/bsn-edge/lab/campaign/shared_leg.sh
set -euo pipefail
REPO=${REPO:?set REPO to the checkout}
RUN=${RUN:-guess1}
DEPTH=${DEPTH:-metric}
SHARE=${SHARE:-0.3}
RANGE=${RANGE:-0}
BIN=$REPO/.venv/bin
[ -d data ] || { echo "shared_leg.sh: no data/ here: run make_data.sh and make_earlier.sh first" >&2; exit 2; }
if [ ! -d data88 ]; then        # leg 1's clips: seeds under 16, the first two slow-traffic clips, the earlier world
  mkdir -p data88.tmp
  for c in data/*/; do
    c=$(basename "$c"); n=${c##*_}
    case $c in earlier_*) ;; queue_*) [ "$n" -lt 2 ] || continue ;; *) [ "$n" -lt 16 ] || continue ;; esac
    ln -sfn "../data/$c" "data88.tmp/$c"
  done
  mv data88.tmp data88
fi
resume=()                       # go on from the last state; a run that never reached one starts again
if [ -f "$RUN/state.pt" ]; then resume=(--resume); elif [ -d "$RUN" ]; then resume=(--force); fi
"$BIN/bsn-train" --config "$REPO/configs/campaign.toml" --data data88 --out "$RUN" "${resume[@]}" \
  --set 'model.name="shared-light"' --set "train.init=\"$REPO/models/default\"" \
  --set "teacher.checkpoint=\"$REPO/models/default\"" --set train.lr=0.00025 --set train.seed=6 \
  --set train.steps=2500 --set train.eval_every=500 --set data.guessed_camera=$SHARE \
  --set "data.guessed_depth=\"$DEPTH\"" --set "train.bce_range_m=$RANGE"
