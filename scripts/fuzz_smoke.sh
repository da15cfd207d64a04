#!/usr/bin/env bash
# The fuzz smoke test: builds the libFuzzer targets (tests/fuzz, the "fuzz"
# preset: clang-14, ASan, UBSan, in build/fuzz) and runs each one for a
# bounded time on a copy of its seed corpus (tests/fuzz/corpus/<name>, left
# as committed), after running its regression inputs
# (tests/fuzz/regressions/<name>, crashes found and fixed) once each.
#   scripts/fuzz_smoke.sh [SECONDS_PER_TARGET]   (default 20)
# Environment: FUZZ_TARGETS="scene journal" runs only those; FUZZ_JOBS
# (default 2) build jobs; FUZZ_NICE (default 0) niceness of builds and runs;
# FUZZ_NO_BUILD=1 runs the targets as last built; FUZZ_SEED (default 1)
# libFuzzer's -seed, so that a CI run explores the same inputs each time and
# a red run is a finding, not luck (FUZZ_SEED=0: a new random seed per run,
# for longer campaigns).
# Prints per target: executions, coverage (libFuzzer's final cov:), and
# crashes. Exits non-zero on any crash, leak, timeout or out-of-memory, and
# prints the reproducer's path (build/fuzz/artifacts/<name>/...), which
# `build/fuzz/tests/fuzz/<name>_fuzz <path>` runs again.
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$(pwd)
SECONDS_PER_TARGET="${1:-20}"
JOBS="${FUZZ_JOBS:-2}"
NICE=(nice -n "${FUZZ_NICE:-0}")
ALL_TARGETS=(scene mesh_reader journal solid_state surface_decoder command script)
read -r -a TARGETS <<< "${FUZZ_TARGETS:-${ALL_TARGETS[*]}}"

bash scripts/setup.sh

BUILD="$ROOT/build/fuzz"
if [ "${FUZZ_NO_BUILD:-0}" != 1 ]; then
  start=$(date +%s)
  cmake --preset fuzz >/dev/null
  "${NICE[@]}" cmake --build "$BUILD" -j"$JOBS" --target fuzz_all
  echo "fuzz_smoke: fuzz tree built in $(( $(date +%s) - start )) s"
fi

WORK=$(mktemp -d "${TMPDIR:-/tmp}/dynsolid_fuzz_smoke.XXXXXX")
trap 'rm -rf "$WORK"' EXIT

# Crashes stop the run; UBSan's reports are crashes (the build also says
# -fno-sanitize-recover); leaks are reported at the end of a run.
export ASAN_OPTIONS="${ASAN_OPTIONS:-abort_on_error=1:detect_leaks=1:allocator_may_return_null=1}"
export UBSAN_OPTIONS="${UBSAN_OPTIONS:-halt_on_error=1:print_stacktrace=1}"

failed=0
summary=()
for name in "${TARGETS[@]}"; do
  bin="$BUILD/tests/fuzz/${name}_fuzz"
  artifacts="$BUILD/artifacts/$name"
  mkdir -p "$artifacts"
  log="$WORK/$name.log"

  # Regression inputs: each runs once.
  regressions=()
  if [ -d "tests/fuzz/regressions/$name" ]; then
    while IFS= read -r -d '' f; do regressions+=("$f"); done \
      < <(find "tests/fuzz/regressions/$name" -type f ! -name '*.md' -print0 | sort -z)
  fi
  if [ "${#regressions[@]}" -gt 0 ]; then
    if ! "${NICE[@]}" "$bin" -rss_limit_mb=2048 -timeout=10 \
         -artifact_prefix="$artifacts/" "${regressions[@]}" >"$WORK/$name.reg.log" 2>&1; then
      tail -n 40 "$WORK/$name.reg.log"
      echo "fuzz_smoke: $name: a regression input fails again (inputs: tests/fuzz/regressions/$name)"
      summary+=("$(printf '%-16s regressions FAILED' "$name")")
      failed=1
      continue
    fi
  fi

  # A copy of the corpus: what the run finds stays out of the source tree.
  corpus="$WORK/corpus_$name"
  mkdir -p "$corpus"
  if [ -d "tests/fuzz/corpus/$name" ]; then
    cp -r "tests/fuzz/corpus/$name/." "$corpus/"
  else
    # No committed seeds yet: the target writes its own (fuzz_util.h).
    DYNSOLID_FUZZ_WRITE_SEEDS="$corpus" "$bin" >/dev/null 2>&1 || true
  fi
  rc=0
  "${NICE[@]}" "$bin" -max_total_time="$SECONDS_PER_TARGET" -rss_limit_mb=2048 -timeout=10 \
    -seed="${FUZZ_SEED:-1}" -print_final_stats=1 -artifact_prefix="$artifacts/" "$corpus" >"$log" 2>&1 || rc=$?
  execs=$(grep -o 'stat::number_of_executed_units: *[0-9]*' "$log" | grep -o '[0-9]*$' | tail -n 1 || true)
  cov=$(grep -o 'cov: [0-9]*' "$log" | tail -n 1 | grep -o '[0-9]*' || true)
  reproducer=$(grep -o "Test unit written to .*" "$log" | tail -n 1 | sed 's/Test unit written to //' || true)
  crashes=0
  if [ "$rc" -ne 0 ] || [ -n "$reproducer" ]; then
    crashes=1
    failed=1
    grep -E "ERROR: |SUMMARY: |FUZZ_CHECK|runtime error|==[0-9]+==" "$log" | head -n 20 || true
    tail -n 30 "$log"
    echo "fuzz_smoke: $name: FAILED (exit $rc); reproducer: ${reproducer:-none written}"
    echo "fuzz_smoke: rerun it with: $bin ${reproducer:-<input>}"
  fi
  summary+=("$(printf '%-16s executions %9s  cov %6s  corpus %4s seeds, %3s regressions  crashes %s' \
    "$name" "${execs:-?}" "${cov:-?}" "$(ls "tests/fuzz/corpus/$name" 2>/dev/null | wc -l)" \
    "${#regressions[@]}" "$crashes")")
done

echo "fuzz_smoke: ${SECONDS_PER_TARGET} s per target"
printf '%s\n' "${summary[@]}"
if [ "$failed" -ne 0 ]; then
  echo "fuzz_smoke: FAILED"
  exit 1
fi
echo "fuzz_smoke: OK"
