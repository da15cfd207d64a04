#!/usr/bin/env bash
# Instructions a benchmark executes, by valgrind's callgrind: within about
# 0.6 % from run to run (the worker threads' spin-waits are counted too;
# a function's own count within 0.1 %), where wall time on a shared 2-core
# VM moves by a third within minutes (docs/benchmarks.md, "Sculpting").
# For changes of a few percent: run it on two builds (BIN=... of each)
# and compare the functions that moved.
#   bench/count_instructions.sh [benchmark and its arguments]
#   default: sculpt_bench chair 2 subdivide 2 (the chair's build and two
#   local subdivisions; about five minutes)
# Prints the total and the TOP (25) functions by their own instructions;
# the callgrind file stays in OUT (/tmp/dynsolid-callgrind.out).
# Under valgrind the CPU reports no AVX-512, so the dispatched kernels run
# their AVX2 paths: counts compare builds, not instruction sets.
set -euo pipefail
cd "$(dirname "$0")/.."
PRESET="${PRESET:-release}"
TOP="${TOP:-25}"
OUT="${OUT:-/tmp/dynsolid-callgrind.out}"
if ! command -v valgrind > /dev/null; then
  echo "count_instructions: valgrind is not installed (Debian: apt-get install valgrind)" >&2
  exit 1
fi
if [ $# -eq 0 ]; then set -- sculpt_bench chair 2 subdivide 2; fi
name="$1"
shift
if [ -z "${BIN:-}" ]; then
  bash scripts/build.sh "$name" > /dev/null
  BIN="build/$PRESET/bench/$name"
fi
valgrind --tool=callgrind --callgrind-out-file="$OUT" "$BIN" "$@" > /dev/null 2> "$OUT.log"
echo "count_instructions: $BIN $*"
callgrind_annotate --inclusive=no "$OUT" 2> /dev/null |
  grep -E "^ *[0-9,]+ " | head -n $((TOP + 1)) | cut -c1-160
