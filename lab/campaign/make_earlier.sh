#!/usr/bin/env bash
# The earlier, plainer world: release 6a40ea8's bsn-synth (the world before the street-like one),
# installed in a virtual environment of its own; 16 training clips and the held-out set, labelled
# with this checkout's bsn-label.   usage: make_earlier.sh CHECKOUT [DATA]
set -euo pipefail
REPO=$(cd "${1:?the bsn-edge checkout}" && pwd)
D=${2:-data}
OLD=${OLD:-$PWD/release-6a40ea8}
[ -d "$OLD" ] || git -C "$REPO" worktree add --detach "$OLD" 6a40ea8
[ -x "$OLD/.venv/bin/bsn-synth" ] || (python3 -m venv "$OLD/.venv" && "$OLD/.venv/bin/pip" install -q -e "$OLD")
old() { [ -f "$1/meta.json" ] || "$OLD/.venv/bin/bsn-synth" "$@" --no-video >/dev/null; }
for s in $(seq 0 7); do
  old $D/earlier_town_$s   --frames 200 --style town   --seed $s
  old $D/earlier_suburb_$s --frames 200 --style suburb --seed $s
done
for s in 50 51; do
  old heldout/earlier/town_$s   --frames 100 --style town   --seed $s --camera fixed
  old heldout/earlier/suburb_$s --frames 100 --style suburb --seed $s --camera fixed
done
"$REPO/.venv/bin/bsn-label" $D/earlier_* heldout/earlier/* --jobs 2 >/dev/null
