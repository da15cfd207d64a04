#!/usr/bin/env bash
# The test command: installs what is missing, builds everything, runs every
# test (CTest over GoogleTest and the loopback/tool tests).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/build.sh
bash scripts/setup_web.sh
PRESET="${PRESET:-release}"
ctest --preset "$PRESET" -j2 --timeout 600
