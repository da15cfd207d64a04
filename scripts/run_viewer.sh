#!/usr/bin/env bash
# Opens the browser viewer for a user: installs what is missing, builds
# dynsolid-server, starts it (sessions kept in out/viewer/data, so a
# restart recovers them), starts the gateway (clients/web) with a session on
# a built-in scene, and prints the URL to open. Ctrl+C stops both.
#
#   SCENE=block3 LEVELS= VIEWER_LISTEN=127.0.0.1:8080 bash scripts/run_viewer.sh
#
# VIEWER_LISTEN=0.0.0.0:8080 serves other machines (the gateway has no
# TLS or login of its own: put it behind one; docs/viewer.md "Access").
set -euo pipefail
cd "$(dirname "$0")/.."
PRESET="${PRESET:-release}"
SCENE="${SCENE:-block3}"
LEVELS="${LEVELS:-}"
VIEWER_LISTEN="${VIEWER_LISTEN:-127.0.0.1:8080}"
OUT="${OUT:-out/viewer}"

bash scripts/build.sh dynsolid-server
bash scripts/setup_web.sh
mkdir -p "$OUT/data"

SERVER_PID=""
GATEWAY_PID=""
cleanup() {
  for pid in $GATEWAY_PID $SERVER_PID; do
    if kill -0 "$pid" 2>/dev/null; then
      kill -TERM "$pid" 2>/dev/null || true
      wait "$pid" 2>/dev/null || true
    fi
  done
}
trap cleanup EXIT INT TERM

SERVER="build/$PRESET/server/dynsolid-server"
# shellcheck source=scripts/start_server.sh
. scripts/start_server.sh
start_server "$OUT/server.out" "$OUT/server.log" --listen 127.0.0.1:0 --data_dir "$OUT/data"
echo "run_viewer: dynsolid-server at $ADDR (log: $OUT/server.log)" >&2

args=(--server "$ADDR" --listen "$VIEWER_LISTEN" --create "$SCENE")
if [ -n "$LEVELS" ]; then args+=(--levels "$LEVELS"); fi
node clients/web/gateway/main.js "${args[@]}" > "$OUT/gateway.out" 2> "$OUT/gateway.log" &
GATEWAY_PID=$!
URL=""
for _ in $(seq 6000); do
  URL=$(sed -n 's/^session [0-9a-f]* ([^)]*): //p' "$OUT/gateway.out" 2>/dev/null || true)
  if [ -n "$URL" ]; then break; fi
  if ! kill -0 "$GATEWAY_PID" 2>/dev/null; then break; fi
  sleep 0.1
done
if [ -z "$URL" ]; then
  echo "run_viewer: the gateway did not open a $SCENE session (see $OUT/gateway.log)" >&2
  cat "$OUT/gateway.log" >&2
  exit 1
fi
echo "run_viewer: open $URL"
echo "run_viewer: Ctrl+C stops the viewer and the server" >&2
wait "$GATEWAY_PID"
