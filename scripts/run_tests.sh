#!/usr/bin/env bash
# The test command: installs what is missing, builds everything, runs every
# test (CTest over GoogleTest and the loopback/tool tests).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/build.sh
bash scripts/setup_web.sh
PRESET="${PRESET:-release}"
ctest --preset "$PRESET" -j2 --timeout 600 -LE fuzz
# The fuzz smoke (bench/reports/fuzz.md): builds the clang-14 ASan/UBSan
# tree of the libFuzzer targets (build/fuzz; 20-25 min from scratch on 2
# idle cores, then only what changed), runs each target's regression
# inputs, then each target for 20 s from its committed corpus with a fixed
# seed. After the tests, so that its build does not slow the
# timing-sensitive ones.
start=$(date +%s)
bash scripts/fuzz_smoke.sh 20
echo "run_tests: fuzz smoke took $(( $(date +%s) - start )) s"
