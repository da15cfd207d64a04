#!/usr/bin/env bash
# Redraws docs/architecture.png from the build's CMake targets
# (scripts/draw_architecture.py: CMake's file API, Graphviz's dot).
#   scripts/architecture.sh
set -euo pipefail
cd "$(dirname "$0")/.."
if ! command -v dot >/dev/null; then
  SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  $SUDO apt-get update -qq && $SUDO apt-get install -y -qq graphviz >/dev/null
fi
BUILD=build/release
mkdir -p "$BUILD/.cmake/api/v1/query"
touch "$BUILD/.cmake/api/v1/query/codemodel-v2"
cmake --preset release >/dev/null
/usr/bin/python3 scripts/draw_architecture.py "$BUILD" "$BUILD/architecture.dot"
dot -Tpng -Gdpi=80 "$BUILD/architecture.dot" -o docs/architecture.png
echo "architecture: docs/architecture.png"
