#!/bin/bash
B=/work/wt/server/build/release/bench/watch_bench
run() { name=$1; shift; echo "=== $name $(date +%T) load $(cat /proc/loadavg)"; $B --watchers 64 --hz 60 --seconds 2 --rounds 5 "$@" 2>&1 | grep -v "^| ---" | tail -24; }
while pgrep -f "set5.sh|set6.sh" >/dev/null; do sleep 2; done
run old-L2-b19 --server_binary=/tmp/dynsolid-server-old --bench_nice=19
run new10-L2-b19 --bench_nice=19
run idle-L2-b19 --bench_nice=19 --server_flags=--stream_idle
run new19-L2-b19 --bench_nice=19 --server_flags=--stream_nice=19
echo "=== done $(date +%T) load $(cat /proc/loadavg)"
