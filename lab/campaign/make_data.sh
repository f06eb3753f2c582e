#!/usr/bin/env bash
# usage (from an empty folder): make_data.sh [DATA]; BIN points at the checkout's .venv/bin
# Campaign data: training clips (all four styles, varied cameras, sensor effects, platoon and slow
# traffic) and the held-out sets, rendered and labelled once. More clips for a later leg: FIRST=16
# make_data.sh data (seeds FIRST..FIRST+15 per style, slow traffic FIRST/8..FIRST/8+1; the held-out
# seeds, 960-967, stay apart from every training seed); finished clips and frames are skipped.
set -euo pipefail
BIN=${BIN:-.venv/bin}
D=${1:-data}
FIRST=${FIRST:-0}
mkdir -p "$D" heldout
synth() { [ -f "$1/meta.json" ] || "$BIN/bsn-synth" "$@" --no-video >/dev/null; }
for s in $(seq "$FIRST" $((FIRST + 15))); do
  synth $D/town_$s    --frames 200 --style town    --seed $s
  synth $D/suburb_$s  --frames 200 --style suburb  --seed $((s + 100))
  synth $D/highway_$s --frames 200 --style highway --seed $((s + 200))
  synth $D/urban_$s   --frames 200 --style urban   --seed $((s + 300))
done
for s in $((FIRST / 8)) $((FIRST / 8 + 1)); do
  for st in town suburb highway urban; do
    synth $D/queue_${st}_$s --frames 200 --style $st --seed $((s + 500)) --queue 1
  done
done
# held-out: seeds 960-967, two per style; without a platoon, with one, in slow traffic
i=960
for st in highway suburb town urban; do
  for k in 0 1; do
    synth heldout/plain/${st}_$k   --frames 120 --style $st --seed $i --lead 0
    synth heldout/platoon/${st}_$k --frames 120 --style $st --seed $i --lead 1
    synth heldout/queue/${st}_$k   --frames 120 --style $st --seed $i --queue 1
    i=$((i + 1))
  done
done
"$BIN/bsn-label" $D/* heldout/*/* --jobs 2 >/dev/null
echo done
