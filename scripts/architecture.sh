#!/usr/bin/env bash
# Redraws docs/architecture.png from the build's CMake targets
# (scripts/draw_architecture.py: CMake's file API, Graphviz's dot), and
# docs/solid-parts.png with its table docs/solid-parts.md from the solid's
# sources (scripts/draw_solid_parts.py).
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
/usr/bin/python3 scripts/draw_solid_parts.py "$BUILD/solid_parts.dot" docs/solid-parts.md
dot -Tpng -Gdpi=70 "$BUILD/solid_parts.dot" -o docs/solid-parts.png
echo "architecture: docs/architecture.png, docs/solid-parts.png"
