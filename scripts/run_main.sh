#!/usr/bin/env bash
# The main job: builds dynsolid, subdivides the built-in default scene
# (block3) and every other built-in scene, and writes the results to
# out/main/<scene>/ (stats.json, boundary.obj, boundary.ply, volume.vtu)
# plus out/main/summary.md, a Table-1 style summary.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/build.sh dynsolid-sim
SIM=build/${PRESET:-release}/solver/tools/dynsolid-sim
OUT=${OUT:-out/main}
mkdir -p "$OUT"
SCENES="block3 block4 chair bridge nozzle torus mixed beam"
for s in $SCENES; do
  "$SIM" --scene "$s" --out "$OUT/$s"
done
/usr/bin/python3 scripts/summarize.py "$OUT" $SCENES > "$OUT/summary.md"
cat "$OUT/summary.md"
