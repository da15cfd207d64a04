#!/usr/bin/env bash
# The accuracy and stability reports, one command: builds the bench targets
# (Release) if needed, runs them and writes bench/reports/:
#   accuracy.csv, accuracy_<problem>.png, accuracy.md   (error against run time)
#   stability.csv, stable_step.csv, stable_step.png, stability.md
# About 15-25 minutes on 2 cores (the accuracy sweep is most of it).
#
#   bash bench/make_reports.sh [--quick]   # --quick: levels 0-1 only (a few minutes)
#
# Timings depend on the machine and its load: the markdown records both.
set -euo pipefail
cd "$(dirname "$0")/.."

quick=0
if [ "${1:-}" = "--quick" ]; then quick=1; fi

bash scripts/setup.sh
if [ ! -f build/release/build.ninja ]; then
  cmake --preset release -S . >/dev/null
fi
cmake --build build/release -j2 --target accuracy_bench stability_bench

out=bench/reports
mkdir -p "$out"
load="$(cut -d' ' -f1-3 /proc/loadavg)"
commit="$(git rev-parse --short HEAD)$(git diff --quiet HEAD -- solver bench || echo '+changes')"
note="${REPORT_NOTE:-}"

echo "make_reports: stability cases" >&2
build/release/bench/stability_bench cases > "$out/stability.csv.tmp"
mv "$out/stability.csv.tmp" "$out/stability.csv"
echo "make_reports: largest stable step" >&2
build/release/bench/stability_bench stable_step > "$out/stable_step.csv.tmp"
mv "$out/stable_step.csv.tmp" "$out/stable_step.csv"

echo "make_reports: error against run time" >&2
levels=3
if [ "$quick" = 1 ]; then levels=1; fi
build/release/bench/accuracy_bench --max_levels="$levels" > "$out/accuracy.csv.tmp"
mv "$out/accuracy.csv.tmp" "$out/accuracy.csv"

/usr/bin/python3 bench/plot_reports.py --dir "$out" --commit "$commit" --load "$load" --note "$note"
echo "make_reports: wrote $out" >&2
