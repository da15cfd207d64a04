#!/usr/bin/env bash
# The load report: dynsolid-load with 1, 8, 32, 64 and 128
# clients on block3 and on the chair, each client on its own channel in
# one shared session, 10 commands/s each for SECONDS (10) seconds, no
# faults; then the table and the plots. Writes bench/reports/load/
# (OUT=...): <scene>_<clients>.json and .md, README.md, load.png.
# Takes about four minutes on two cores.
set -euo pipefail
cd "$(dirname "$0")/.."
PRESET="${PRESET:-release}"
OUT=${OUT:-bench/reports/load}
SECONDS_EACH=${SECONDS_EACH:-10}
CLIENTS=${CLIENTS:-"1 8 32 64 128"}
SCENES=${SCENES:-"block3 chair"}
bash scripts/build.sh dynsolid-server dynsolid-load
BIN=build/$PRESET
mkdir -p "$OUT"
for scene in $SCENES; do
  for n in $CLIENTS; do
    echo "load_report: $scene, $n clients" >&2
    "$BIN/clients/load/dynsolid-load" --server_binary "$BIN/server/dynsolid-server" \
      --server_args "--max_watchers_per_session 256" \
      --scene "$scene" --clients "$n" --seconds "$SECONDS_EACH" --rate 10 \
      --json "$OUT/${scene}_${n}.json" --markdown "$OUT/${scene}_${n}.md" > /dev/null || true
  done
done
/usr/bin/python3 bench/plot_load.py "$OUT" $SCENES
