#!/usr/bin/env bash
# Opens the browser viewer for a user: installs what is missing, builds
# dynsolid-server, starts it (sessions kept in out/viewer/data, so a
# restart recovers them), starts the gateway (clients/web) with a session on
# a built-in scene, and prints the URL to open. Ctrl+C stops both.
#
#   SCENE=block3 LEVELS= VIEWER_LISTEN=127.0.0.1:8080 bash scripts/run_viewer.sh
#
# One instance per OUT: a second one on the same OUT (its sessions) is
# refused and told how to run another; each run logs into its own
# $OUT/runs/<time>-<pid>/, so no run touches another's files. A taken port
# is named, and a free one is used instead.
#
# VIEWER_LISTEN=0.0.0.0:8080 serves other machines: the gateway then needs
# an access token (made here, carried by the printed URL); pages served
# under a host name need VIEWER_ALLOW_ORIGIN=http://NAME:8080 (the
# gateway's --allow_origin). VIEWER_TLS_CERT and VIEWER_TLS_KEY (PEM files)
# serve the page over HTTPS (the gateway's --tls_cert/--tls_key; docs/
# viewer.md "Serving beyond this machine").
#
# NO_SETUP=1 uses what is there (no build, no npm ci); DYNSOLID_SERVER
# names the server binary (default build/$PRESET/server/dynsolid-server).
set -euo pipefail
cd "$(dirname "$0")/.."
PRESET="${PRESET:-release}"
SCENE="${SCENE:-block3}"
LEVELS="${LEVELS:-}"
VIEWER_LISTEN="${VIEWER_LISTEN:-127.0.0.1:8080}"
VIEWER_ALLOW_ORIGIN="${VIEWER_ALLOW_ORIGIN:-}"
OUT="${OUT:-out/viewer}"
SERVER="${DYNSOLID_SERVER:-build/$PRESET/server/dynsolid-server}"

if [ "${NO_SETUP:-0}" != 1 ]; then
  bash scripts/build.sh dynsolid-server
  bash scripts/setup_web.sh
fi
mkdir -p "$OUT/data" "$OUT/runs"

# The lock is held by this script and inherited by the server and the
# gateway: OUT stays taken while any of them runs. Opened for append, so
# taking it never changes the file.
exec 9>>"$OUT/lock"
if ! flock -n 9; then
  echo "run_viewer: another run_viewer.sh is running on OUT=$OUT (its sessions are in $OUT/data);" \
       "stop it, or run a second one with OUT=${OUT}2 VIEWER_LISTEN=127.0.0.1:0" >&2
  exit 1
fi
RUN="$OUT/runs/$(date +%Y%m%d-%H%M%S)-$$"
mkdir -p "$RUN"

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

# shellcheck source=scripts/start_server.sh
. scripts/start_server.sh
start_server "$RUN/server.out" "$RUN/server.log" --listen 127.0.0.1:0 --data_dir "$OUT/data"
echo "run_viewer: dynsolid-server at $ADDR (logs: $RUN)" >&2

host="${VIEWER_LISTEN%:*}"
args=(--server "$ADDR" --create "$SCENE")
if [ -n "$LEVELS" ]; then args+=(--levels "$LEVELS"); fi
if [ -n "$VIEWER_ALLOW_ORIGIN" ]; then args+=(--allow_origin "$VIEWER_ALLOW_ORIGIN"); fi
if [ -n "${VIEWER_TLS_CERT:-}" ] || [ -n "${VIEWER_TLS_KEY:-}" ]; then
  args+=(--tls_cert "${VIEWER_TLS_CERT:-}" --tls_key "${VIEWER_TLS_KEY:-}")
fi
case "$host" in
  127.*|localhost|"[::1]") ;;
  *)
    # Beyond loopback: an access token, readable by this user only.
    (umask 077 && od -An -N16 -tx1 /dev/urandom | tr -d ' \n' > "$RUN/access_token")
    args+=(--access_token_file "$RUN/access_token")
    ;;
esac

# Starts the gateway on $1 (HOST:PORT) and waits for its session's URL;
# returns 1 when it exits first (its log says why).
start_gateway() {
  node clients/web/gateway/main.js "${args[@]}" --listen "$1" > "$RUN/gateway.out" 2>> "$RUN/gateway.log" &
  GATEWAY_PID=$!
  URL=""
  for _ in $(seq 6000); do
    URL=$(sed -n 's/^session [^ ]* ([^)]*): //p' "$RUN/gateway.out" 2>/dev/null || true)
    if [ -n "$URL" ]; then return 0; fi
    if ! kill -0 "$GATEWAY_PID" 2>/dev/null; then return 1; fi
    sleep 0.1
  done
  return 1
}

if ! start_gateway "$VIEWER_LISTEN"; then
  if grep -q "the port is taken" "$RUN/gateway.log"; then
    echo "run_viewer: $VIEWER_LISTEN is taken (another program listens there); using a free port on $host" >&2
    start_gateway "$host:0" || true
  fi
fi
if [ -z "$URL" ]; then
  echo "run_viewer: the gateway did not open a $SCENE session (see $RUN/gateway.log)" >&2
  cat "$RUN/gateway.log" >&2
  exit 1
fi
echo "run_viewer: open $URL"
echo "run_viewer: Ctrl+C stops the viewer and the server" >&2
wait "$GATEWAY_PID"
