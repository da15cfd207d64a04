#!/usr/bin/env bash
# dynsolid against VegaFEM on the same block, side by side in one run.
# See bench/vega/README.md.
#
#   bench/vega/compare.sh [--vega-src=DIR] [--build-dir=DIR] [--sizes="8 12 16"]
#                         [--steps=40] [--raw=FILE] [--plot=FILE.png]
#
# VEGA_SRC (or --vega-src): a VegaFEM checkout. Default: exported from the
# local mirror /work/.mirror/dyollb+VegaFEM/repo if it exists; otherwise run
#   git clone https://github.com/dyollb/VegaFEM /tmp/VegaFEM
# and pass --vega-src=/tmp/VegaFEM. Vega and our driver are built under the
# build dir (default /tmp/vega-build), never inside the repository; dynsolid
# is not rebuilt: its already built build/release/bench/scaling_bench is run.
set -euo pipefail

HERE="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
REPO="$(cd "$HERE/../.." && pwd)"
VEGA_SRC="${VEGA_SRC:-}"
BUILD_DIR="${BUILD_DIR:-/tmp/vega-build}"
SIZES="${SIZES:-8 12 16}"
STEPS="${STEPS:-40}"
RAW=""
PLOT=""
MIRROR=/work/.mirror/dyollb+VegaFEM/repo
for arg in "$@"; do
  case "$arg" in
    --vega-src=*) VEGA_SRC="${arg#*=}" ;;
    --build-dir=*) BUILD_DIR="${arg#*=}" ;;
    --sizes=*) SIZES="${arg#*=}"; SIZES="${SIZES//,/ }" ;;
    --steps=*) STEPS="${arg#*=}" ;;
    --raw=*) RAW="${arg#*=}" ;;
    --plot=*) PLOT="${arg#*=}" ;;
    -h|--help) sed -n 2,13p "$0"; exit 0 ;;
    *) echo "unknown argument: $arg" >&2; exit 2 ;;
  esac
done
NICE=(nice -n 5)
WARMUP=5

# --- dynsolid: already built, never built here ----------------------------
DYN_BUILD="$REPO/build/release"
SCALING="$DYN_BUILD/bench/scaling_bench"
if [[ ! -x "$SCALING" ]]; then
  echo "error: $SCALING is missing; build the repository's release tree first" \
       "(this script does not build it)." >&2
  exit 1
fi
case "$BUILD_DIR" in
  "$REPO"|"$REPO"/*) echo "error: the build dir must be outside the repository" >&2; exit 2 ;;
esac
mkdir -p "$BUILD_DIR"

# --- tools -------------------------------------------------------------------
need_apt=()
command -v cmake >/dev/null || need_apt+=(cmake)
command -v g++ >/dev/null || need_apt+=(g++)
# Vega's mesh/boundingBox.cpp includes GL/gl.h and its render() calls OpenGL.
[[ -f /usr/include/GL/gl.h ]] || need_apt+=(libgl-dev)
ls /usr/lib/*/libGL.so >/dev/null 2>&1 || need_apt+=(libgl-dev)
if ((${#need_apt[@]})); then
  echo "installing with apt-get: ${need_apt[*]}" >&2
  SUDO=""; [[ $(id -u) -ne 0 ]] && SUDO=sudo
  $SUDO apt-get update -qq && $SUDO apt-get install -y -qq "${need_apt[@]}"
fi

# --- VegaFEM sources -----------------------------------------------------------
if [[ -z "$VEGA_SRC" ]]; then
  if [[ -d "$MIRROR" ]]; then
    VEGA_SRC="$BUILD_DIR/vega-src"
    if [[ ! -f "$VEGA_SRC/libraries/corotationalLinearFEM/corotationalLinearFEM.cpp" ]]; then
      echo "exporting VegaFEM from $MIRROR to $VEGA_SRC" >&2
      mkdir -p "$VEGA_SRC"
      # The mirror lacks some large binaries (the manual PDF), so git archive
      # stops with an error after the libraries; keep what it wrote.
      git --git-dir="$MIRROR" archive --format=tar HEAD libraries \
        > "$BUILD_DIR/vega-libraries.tar" 2>"$BUILD_DIR/vega-archive.log" || true
      tar -xf "$BUILD_DIR/vega-libraries.tar" -C "$VEGA_SRC" 2>/dev/null || true
      git --git-dir="$MIRROR" rev-parse HEAD > "$VEGA_SRC/VEGA_COMMIT" || true
    fi
  else
    echo "error: no VegaFEM checkout. Run" >&2
    echo "  git clone https://github.com/dyollb/VegaFEM /tmp/VegaFEM" >&2
    echo "and pass --vega-src=/tmp/VegaFEM (or VEGA_SRC=/tmp/VegaFEM)." >&2
    exit 1
  fi
fi
if [[ ! -f "$VEGA_SRC/libraries/corotationalLinearFEM/corotationalLinearFEM.cpp" ]]; then
  echo "error: $VEGA_SRC does not look like a VegaFEM checkout (no libraries/)" >&2
  exit 1
fi
VEGA_COMMIT="$(cat "$VEGA_SRC/VEGA_COMMIT" 2>/dev/null || git -C "$VEGA_SRC" rev-parse HEAD 2>/dev/null || echo unknown)"

# --- build Vega's subset and our driver (outside the repository) -----------------
echo "building VegaFEM subset + vega_block in $BUILD_DIR/vega" >&2
"${NICE[@]}" cmake -S "$HERE" -B "$BUILD_DIR/vega" -DVEGA_SRC="$VEGA_SRC" \
  -DCMAKE_BUILD_TYPE=Release >"$BUILD_DIR/vega-cmake.log" 2>&1 \
  || { cat "$BUILD_DIR/vega-cmake.log" >&2; exit 1; }
"${NICE[@]}" cmake --build "$BUILD_DIR/vega" -j 2 >"$BUILD_DIR/vega-build.log" 2>&1 \
  || { tail -40 "$BUILD_DIR/vega-build.log" >&2; exit 1; }
VEGA="$BUILD_DIR/vega/vega_block"

# --- runs, interleaved per size ------------------------------------------------
RAW="${RAW:-$BUILD_DIR/compare_raw.txt}"
: > "$RAW"
echo "# vega_commit=$VEGA_COMMIT dynsolid_commit=$(git -C "$REPO" rev-parse --short HEAD) steps=$STEPS warmup=$WARMUP cpu=$(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ *//')" >> "$RAW"
for n in $SIZES; do
  echo "n=$n" >&2
  "${NICE[@]}" "$VEGA" --n="$n" --integrator=central --steps="$STEPS" --warmup=$WARMUP \
    | grep '^vega ' >> "$RAW" || echo "vega n=$n integrator=central failed=1" >> "$RAW"
  # One process per solver so that each peak RSS (VmHWM) is that solver's own.
  for solver in factored cg; do
    "${NICE[@]}" "$SCALING" --sizes="$n" --solvers="$solver" --steps="$STEPS" \
      | grep '^| [0-9]' | sed 's/^/dynsolid_row /' >> "$RAW" || true
  done
  "${NICE[@]}" "$VEGA" --n="$n" --integrator=backward_euler --steps="$STEPS" --warmup=$WARMUP \
    | grep '^vega ' >> "$RAW" || echo "vega n=$n integrator=backward_euler failed=1" >> "$RAW"
  "${NICE[@]}" "$SCALING" --sizes="$n" --solvers=backward_euler --steps="$STEPS" \
    | grep '^| [0-9]' | sed 's/^/dynsolid_row /' >> "$RAW" || true
done

# --- table -------------------------------------------------------------------------
/usr/bin/python3 "$HERE/compare_table.py" "$RAW" ${PLOT:+--plot="$PLOT"}
