# Sourced by the scripts that start dynsolid-server in the background:
#   start_server OUT_FILE LOG_FILE SERVER_ARGS...
# starts "$SERVER" with SERVER_ARGS (stdout to OUT_FILE, stderr to LOG_FILE),
# waits up to a minute for its "listening on ADDR" line and sets SERVER_PID
# and ADDR; returns 1 (having printed the log) when it does not start.
start_server() {
  local out=$1 log=$2
  shift 2
  "$SERVER" "$@" > "$out" 2> "$log" &
  SERVER_PID=$!
  ADDR=""
  for _ in $(seq 600); do
    if [ -s "$out" ]; then
      ADDR=$(sed -n '1s/^listening on //p' "$out")
      if [ -n "$ADDR" ]; then return 0; fi
    fi
    if ! kill -0 "$SERVER_PID" 2>/dev/null; then break; fi
    sleep 0.1
  done
  echo "dynsolid-server did not start (see $log)" >&2
  cat "$log" >&2
  return 1
}
