#!/bin/bash
B=/work/wt/server/build/release/bench/watch_bench
run() { name=$1; shift; echo "=== $name $(date +%T) load $(cat /proc/loadavg)"; $B --watchers 64 --hz 60 --seconds 2 --rounds 5 "$@" 2>&1 | grep -v "^| ---" | tail -24; }
while pgrep -f "set5.sh|set6.sh|set7.sh" >/dev/null; do sleep 2; done
run old-L1-b0 --levels 1 --server_binary=/tmp/dynsolid-server-old
run new10-L1-b0 --levels 1
run idle-L1-b0 --levels 1 --server_flags=--stream_idle
run new10-L2-b0
echo "=== done $(date +%T) load $(cat /proc/loadavg)"
