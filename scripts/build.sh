#!/usr/bin/env bash
# Configures and builds dynsolid (Release unless PRESET says otherwise).
#   scripts/build.sh [target...]
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
PRESET="${PRESET:-release}"
cmake --preset "$PRESET" >/dev/null
if [ "$#" -gt 0 ]; then
  cmake --build --preset "$PRESET" -j2 --target "$@"
else
  cmake --build --preset "$PRESET" -j2
fi
