#!/usr/bin/env bash
# Bench smoke: runs every benchmark binary built in bench/ with
# tiny arguments, so none can break silently. Checks only that each runs to
# its end (exit 0, no "failed" row); never times anything. CTest runs it
# as `bench_smoke` (label bench_smoke): bench/CMakeLists.txt.
#   bench/smoke.sh BENCH_BINARY_DIR
# A binary in BENCH_BINARY_DIR without a line below fails the smoke: a new
# benchmark gets its tiny arguments here.
set -uo pipefail
dir="${1:?usage: bench/smoke.sh BENCH_BINARY_DIR}"
cd "$(dirname "$0")/.."

declare -A args=(
  [subdivide_bench]="2 1 1"
  [table1_bench]="2 0"
  [accuracy_bench]="--max_levels=0 --statics_only --newton_max_level=-1"
  [stability_bench]="cases 0.005 3 50"
  [paint_bench]="block3"
  [implicit_bench]="--steps=3 --warmup=1 --cases=static,pull"
  [measure_bench]="2000"
  [sculpt_bench]="block3 0 delete 1"
  [quadrature_bench]="0"
  [gram_bench]=""
  [scaling_bench]="--sizes=2 --steps=3"
  [watch_bench]="--seconds=0.5 --rounds=1 --watchers=2 --hz=10"
  [haptic_bench]="--seconds=0.5 --watchers=0 --rt_priority=0"
)

failed=0
ran=0
for bin in "$dir"/*; do
  [ -f "$bin" ] && [ -x "$bin" ] || continue
  name="$(basename "$bin")"
  if [ -z "${args[$name]+set}" ]; then
    echo "bench_smoke: $name has no tiny arguments in bench/smoke.sh" >&2
    failed=$((failed + 1))
    continue
  fi
  out="$(mktemp)"
  start=$SECONDS
  # shellcheck disable=SC2086  # the arguments are words
  if timeout 120 "$bin" ${args[$name]} >"$out" 2>&1 && ! grep -q "| failed" "$out"; then
    echo "bench_smoke: $name ok ($((SECONDS - start)) s)"
  else
    echo "bench_smoke: $name FAILED ($((SECONDS - start)) s); its output:" >&2
    tail -n 30 "$out" >&2
    failed=$((failed + 1))
  fi
  ran=$((ran + 1))
  rm -f "$out"
done
echo "bench_smoke: $ran benchmarks ran, $failed failed"
[ "$ran" -gt 0 ] && [ "$failed" -eq 0 ]
