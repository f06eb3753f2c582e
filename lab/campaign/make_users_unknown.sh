#!/usr/bin/env bash
# The campaign's data with road users unknown where no road was seen behind them, the rendered clips too
# (bsn-label --users-unknown): data_uu/ beside data/, each rendered clip linked to its frames, depth,
# semantics and poses with labels of its own; CamVid's drives (labelled so already) linked whole. The
# held-out sets keep the paper's V, which every judged IoU is read in.
#   cd ~/.cache/bsn-edge/campaign && REPO=/path/to/bsn-edge /path/to/bsn-edge/lab/campaign/make_users_unknown.sh
set -euo pipefail
REPO=${REPO:?set REPO to the checkout}
[ -f data/.made ] || { echo "no data/.made here: make the campaign's data first (make_data.sh)" >&2; exit 1; }
mkdir -p data_uu
for clip in data/*/; do
  name=$(basename "$clip")
  case "$name" in
    camvid_*) ln -sfn "$PWD/data/$name" "data_uu/$name" ;;
    *) mkdir -p "data_uu/$name"
       for entry in "$clip"*; do
         [ "$(basename "$entry")" = labels ] || ln -sfn "$PWD/$entry" "data_uu/$name/$(basename "$entry")"
       done ;;
  esac
done
rendered=$(ls -d data_uu/*/ | grep -v '/camvid_')
"$REPO/.venv/bin/bsn-label" --rate 5 --T 5 --users-unknown --jobs 2 $rendered
touch data_uu/.made
