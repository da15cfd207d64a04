#!/bin/bash
B=/work/wt/server/build/release/bench/watch_bench
run() { name=$1; shift; echo "=== $name $(date +%T) load $(cat /proc/loadavg)"; $B --watchers 64 --hz 60 --seconds 2 --rounds 5 "$@" 2>&1 | grep -v "^| ---" | tail -24; }
run old-L2-b0 --server_binary=/tmp/dynsolid-server-old
run new-L2-b0
run old-L2-b19 --server_binary=/tmp/dynsolid-server-old --bench_nice=19
run new-L2-b19 --bench_nice=19
run old-L1-b0 --levels 1 --server_binary=/tmp/dynsolid-server-old
run new-L1-b0 --levels 1
echo "=== done $(date +%T) load $(cat /proc/loadavg)"
