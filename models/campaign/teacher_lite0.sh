#!/usr/bin/env bash
# The segmentation teacher on EfficientNet-Lite0 from its ImageNet weights (the encoder at a tenth of
# the learning rate), trained alone on the campaign's data (make_data.sh: leg 3's 160 clips), for
# legs to distil from with --set teacher.checkpoint=$PWD/teacher_lite0. Resumable: run it again and
# it goes on from its last state (every 500 steps).
#   cd ~/.cache/bsn-edge/campaign && REPO=/path/to/bsn-edge /path/to/bsn-edge/models/campaign/teacher_lite0.sh
# The same with domain randomisation in its batches (objects repainted and seen through, cameras of
# their own), so it finds cars by shape rather than by the renderer's paint:
#   RUN=teacher_lite0_dr OBJECTS=0.5 LOOK=0.5 REPO=... .../teacher_lite0.sh
# And beside CamVid's labelled real drives (make_camvid.sh writes them into data/, the held-out drive left out),
# a quarter of each batch from them:
#   RUN=teacher_real REAL=0.25 REPO=... .../teacher_lite0.sh
set -euo pipefail
REPO=${REPO:?set REPO to the checkout}
RUN=${RUN:-teacher_lite0}       # the run's folder here
STEPS=${STEPS:-3000}            # teacher.steps: the schedule (an ImageNet start needs fewer than the ResNet teacher's 10,000)
OBJECTS=${OBJECTS:-0}           # data.object_repaint and data.object_see_through: shares of samples
LOOK=${LOOK:-0}                 # data.camera_look: share of samples
REAL=${REAL:-0}                 # data.real_share: share of each batch from real pictures (CamVid drives in data/)
BIN=$REPO/.venv/bin
[ -f data/.made ] || { echo "no data/.made here: make the campaign's data first (lite_leg1.sh does)" >&2; exit 1; }
resume=()                       # go on from the last state; a run that never reached one starts again
if [ -f "$RUN/teacher/state.pt" ] || [ -f "$RUN/teacher/teacher.pt" ]; then resume=(--resume)
elif [ -d "$RUN" ]; then resume=(--force); fi
"$BIN/bsn-train" --config "$REPO/configs/campaign.toml" --data data --out "$RUN" "${resume[@]}" --teacher-only \
  --set 'teacher.encoder="efficientnet-lite0"' --set teacher.pretrained=true --set teacher.encoder_lr=0.1 \
  --set "teacher.steps=$STEPS" --set "data.object_repaint=$OBJECTS" --set "data.object_see_through=$OBJECTS" \
  --set "data.camera_look=$LOOK" --set "data.real_share=$REAL"
