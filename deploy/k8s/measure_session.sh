#!/bin/bash
# CPU and resident memory of dynsolid-server holding N sessions of a scene,
# idle (no client): deploy/k8s/RESOURCES.md.
#   bash deploy/k8s/measure_session.sh SCENE [N]   (from the source tree, after a build)
scene=$1; n=${2:-1}
B=build/release
D=$(mktemp -d)
$B/server/dynsolid-server --listen 127.0.0.1:0 --data_dir $D --sim_threads 1 > $D/out 2> $D/log &
P=$!
for i in $(seq 100); do [ -s $D/out ] && break; sleep 0.1; done
A=$(sed -n '1s/^listening on //p' $D/out)
rss0=$(grep VmRSS /proc/$P/status | awk '{print $2}')
for k in $(seq $n); do $B/clients/cli/dynsolid-client --server $A create --scene $scene > /dev/null; done
sleep 3
t0=$(awk '{print $14+$15}' /proc/$P/stat); sleep 5; t1=$(awk '{print $14+$15}' /proc/$P/stat)
rss=$(grep VmRSS /proc/$P/status | awk '{print $2}')
echo "$scene x$n: cpu $(( (t1-t0) * 100 / 5 / $(getconf CLK_TCK) ))% of a core, RSS ${rss} kB (empty server ${rss0} kB)"
kill -TERM $P; wait $P; rm -rf $D
