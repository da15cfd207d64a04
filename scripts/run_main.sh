#!/usr/bin/env bash
# The main job: builds dynsolid, starts dynsolid-server on a free port with a
# temporary --data_dir, runs the scripted sculpting session of
# clients/scripts/sculpt_block3.txt on the default scene (block3) with
# dynsolid-client (pull, inflate, paint, pin; extrude, merge, drag, curve,
# subdivide, delete, mass paint, undo/redo; pause/resume/step, save),
# recording frames, then stops the server with SIGTERM and checks that it
# exits 0. Writes under out/main/ (OUT=...):
#   session/report.json     the client's report (commands, latency, frames, stats)
#   session/frames/         snapshots (pulled, inflated, pinned, after_realtime,
#                           final) and every RECORD_EVERY-th frame, .obj + .vtu
#   session/client.txt      the client's summary lines
#   session/server.log      the server's log
#   offline/<scene>/        dynsolid-sim of every built-in scene for STEPS (20)
#                           steps: the Table-1 style table (OFFLINE=0: skip;
#                           about a minute on two cores)
#   sculpt.png              the block before and after sculpting (four frames)
#   keep/                   the sculpted block baked and exported (scene file,
#                           OBJ, STL, glb), the session created again from the
#                           scene file (recreated.obj), and the session's
#                           animation replayed from its journal (animation/:
#                           sculpt.pvd and a VTU per frame); keep.png
#   haptic/                 the haptic segment (HAPTIC=0: skip): traces, loop
#                           metrics, force_depth.png (docs/haptic.md)
#   summary.md              the session summary, the Table-1 style table and
#                           the haptic segment
set -euo pipefail
cd "$(dirname "$0")/.."
PRESET="${PRESET:-release}"
OUT=${OUT:-out/main}
OFFLINE=${OFFLINE:-1}
STEPS=${STEPS:-20}
RECORD_EVERY=${RECORD_EVERY:-10}
TARGETS="dynsolid-server dynsolid-client dynsolid-replay"
if [ "$OFFLINE" != 0 ]; then TARGETS="$TARGETS dynsolid-sim"; fi
# shellcheck disable=SC2086
bash scripts/build.sh $TARGETS
BIN=build/$PRESET
SERVER=$BIN/server/dynsolid-server
CLIENT=$BIN/clients/cli/dynsolid-client

S="$OUT/session"
rm -rf "$S"
mkdir -p "$S/frames"
DATA=$(mktemp -d "${TMPDIR:-/tmp}/dynsolid_main_XXXXXX")
SERVER_PID=""
cleanup() {
  if [ -n "$SERVER_PID" ] && kill -0 "$SERVER_PID" 2>/dev/null; then
    kill -TERM "$SERVER_PID" 2>/dev/null || true
    wait "$SERVER_PID" 2>/dev/null || true
  fi
  rm -rf "$DATA"
}
trap cleanup EXIT

# shellcheck source=scripts/start_server.sh
. scripts/start_server.sh
start_server "$S/server.out" "$S/server.log" --listen 127.0.0.1:0 --data_dir "$DATA"
echo "run_main: dynsolid-server listening on $ADDR" >&2

# The session is created first (its id and token are kept: the design is
# exported from it afterwards).
"$CLIENT" --server "$ADDR" create --scene block3 --start_paused > "$S/session.json"
SID=$(/usr/bin/python3 -c 'import json,sys; print(json.load(open(sys.argv[1]))["id"])' "$S/session.json")
STOKEN=$(/usr/bin/python3 -c 'import json,sys; print(json.load(open(sys.argv[1]))["token"])' "$S/session.json")
REF=(--id "$SID" --token "$STOKEN")
"$CLIENT" --server "$ADDR" run --script clients/scripts/sculpt_block3.txt "${REF[@]}" --noclose \
  --frames_dir "$S/frames" --format obj,vtu --record_every "$RECORD_EVERY" \
  --fields displacement,strain,stiffness \
  --json "$S/report.json" | tee "$S/client.txt"

# Keeping the work (docs/export.md): the sculpted block is baked (its shape
# now is its rest shape), exported as a scene file, OBJ, STL and glTF, and
# created again from the scene file; the re-created session's surface is
# exported beside the original's. Then the session's animation is replayed
# from its journal (.pvd + one VTU per frame).
K="$OUT/keep"
rm -rf "$K"
mkdir -p "$K"
printf 'bake\nwait 0\n' > "$K/bake.txt"
"$CLIENT" --server "$ADDR" run --script "$K/bake.txt" "${REF[@]}" --noclose --nowatch > /dev/null
for f in scene:textproto obj:obj stl:stl glb:glb; do
  "$CLIENT" --server "$ADDR" export "${REF[@]}" --format "${f%%:*}" --out "$K/sculpted.${f##*:}" \
    > "$K/export_${f%%:*}.json"
done
"$CLIENT" --server "$ADDR" create --scene_file "$K/sculpted.textproto" --start_paused > "$K/recreated.json"
RID=$(/usr/bin/python3 -c 'import json,sys; print(json.load(open(sys.argv[1]))["id"])' "$K/recreated.json")
RTOKEN=$(/usr/bin/python3 -c 'import json,sys; print(json.load(open(sys.argv[1]))["token"])' "$K/recreated.json")
"$CLIENT" --server "$ADDR" export --id "$RID" --token "$RTOKEN" --format obj --out "$K/recreated.obj" > /dev/null

# The design segment (docs/sculpt.md "Designs that stay"): the clay block
# pulled by a drag and released keeps its new shape, then is baked.
D="$OUT/design"
rm -rf "$D"
mkdir -p "$D/frames"
"$CLIENT" --server "$ADDR" run --script clients/scripts/clay_design.txt \
  --scene clay --start_paused \
  --frames_dir "$D/frames" --format obj --record_every 0 \
  --json "$D/report.json" > "$D/client.txt"

kill -TERM "$SERVER_PID"
SERVER_EXIT=0
wait "$SERVER_PID" || SERVER_EXIT=$?
SERVER_PID=""
if [ "$SERVER_EXIT" != 0 ]; then
  echo "run_main: dynsolid-server exited $SERVER_EXIT after SIGTERM (see $S/server.log)" >&2
  exit 1
fi
echo "run_main: dynsolid-server stopped cleanly (exit 0)" >&2

# The animation of the sculpting session, replayed from its journal.
"$BIN/server/dynsolid-replay" --session "$DATA/sessions/$SID" --out "$K/animation" --fps 20 \
  --name sculpt > "$K/replay.json"
/usr/bin/python3 scripts/render_frames.py "$OUT/keep.png" \
  "$K/sculpted.obj:the sculpted block, baked" "$K/recreated.obj:created again from sculpted.textproto" >&2
KEEP_LINES=$(/usr/bin/python3 scripts/keep_summary.py "$K")

# The sculpting, before and after (scripts/render_frames.py).
F="$S/frames"
/usr/bin/python3 scripts/render_frames.py "$OUT/sculpt.png" \
  "$F/pinned.obj:before sculpting" "$F/dragged.obj:extruded, joined, dragged" \
  "$F/bent.obj:bent by a curve" "$F/sculpted.obj:refined, cut, painted" >&2

/usr/bin/python3 scripts/render_frames.py "$OUT/clay.png" --floor=0 \
  "$D/frames/before.obj:clay at rest" "$D/frames/during.obj:pulled by a drag" \
  "$D/frames/after.obj:released: the shape stays" "$D/frames/baked.obj:baked, 0.5 s on" >&2
SET_LINE=$(/usr/bin/python3 scripts/shape_change.py "$D/frames/before.obj" "$D/frames/after.obj" \
  "permanent set after the drag was released")
BAKED_LINE=$(/usr/bin/python3 scripts/shape_change.py "$D/frames/after.obj" "$D/frames/baked.obj" \
  "moved in the 0.5 s after the bake (gravity sagging the new rest shape)")

# The drop: a rubber block released 2 m above a floor comes to rest on it
# (frames every 0.3 s; the first after 0.3 s of falling).
DROP="$OUT/drop"
rm -rf "$DROP"
"$BIN/solver/tools/dynsolid-sim" --scene clients/scripts/drop_block.textproto --steps 3000 \
  --frames 300 --out "$DROP" > /dev/null
/usr/bin/python3 scripts/render_frames.py "$OUT/drop.png" --floor=0 \
  "$DROP/frames/frame_000300.obj:0.3 s: falling" "$DROP/frames/frame_000600.obj:0.6 s" \
  "$DROP/frames/frame_000900.obj:0.9 s" "$DROP/frames/frame_003000.obj:3 s: at rest" >&2
DROP_LINE=$(/usr/bin/python3 - "$DROP/frames/frame_003000.obj" "$DROP/trace.csv" <<'PY'
import csv, sys
zs = [float(l.split()[3]) for l in open(sys.argv[1]) if l.startswith("v ")]
rows = list(csv.reader(open(sys.argv[2])))
lowest = min(float(r[-1]) for r in rows[1:])
print(f"lowest surface point at rest {1e3 * min(zs):.2f} mm relative to the floor; "
      f"the bottom centre's lowest over the run {1e3 * lowest:.2f} mm")
PY
)

SCENES="block3 block4 chair bridge nozzle torus mixed beam clay"
if [ "$OFFLINE" != 0 ]; then
  SIM=$BIN/solver/tools/dynsolid-sim
  mkdir -p "$OUT/offline"
  for s in $SCENES; do
    rm -rf "${OUT:?}/offline/$s"
    if ! "$SIM" --scene "$s" --steps "$STEPS" --out "$OUT/offline/$s" 2> "$OUT/offline/$s.err"; then
      if grep -q "not available in this build" "$OUT/offline/$s.err"; then
        echo "$s: $(cat "$OUT/offline/$s.err") -- exporting without stepping" >&2
        "$SIM" --scene "$s" --out "$OUT/offline/$s"
      else
        cat "$OUT/offline/$s.err" >&2
        exit 1
      fi
    fi
    rm -f "$OUT/offline/$s.err"
  done
fi

{
  /usr/bin/python3 scripts/summarize_session.py "$S/report.json" --server-exit "$SERVER_EXIT"
  echo
  echo "Before and after sculpting: ![sculpt](sculpt.png) (\`sculpt.png\`)"
  echo
  echo "## Designs that stay: clay, bake and the floor"
  echo
  echo "The built-in scene \`clay\` (a 40 x 40 x 30 cm block of clay on a floor), pulled by"
  echo "a drag and released, then baked (\`clients/scripts/clay_design.txt\`):"
  echo "- $SET_LINE"
  echo "- $BAKED_LINE"
  echo
  echo "![clay](clay.png) (\`clay.png\`)"
  echo
  echo "A 1 m rubber block dropped from 2 m onto the floor (\`clients/scripts/drop_block.textproto\`):"
  echo "- $DROP_LINE"
  echo
  echo "![drop](drop.png) (\`drop.png\`)"
  echo
  echo "## Keeping the work: save as, export, animation (docs/export.md)"
  echo
  echo "$KEEP_LINES"
  echo
  echo "![keep](keep.png) (\`keep.png\`)"
  if [ "$OFFLINE" != 0 ]; then
    echo
    echo "## Offline: every built-in scene, $STEPS steps with dynsolid-sim (Table-1 style)"
    echo
    # shellcheck disable=SC2086
    /usr/bin/python3 scripts/summarize.py "$OUT/offline" $SCENES
  fi
} > "$OUT/summary.md"

# The haptic segment (docs/haptic.md; HAPTIC=0 skips it, about 40 s): the
# bridge with a virtual hand probes the soft and the painted half of a
# block3 session on a server of its own, then the server is frozen, killed
# and restarted under it; the summary gains the force-depth curves
# (haptic/force_depth.png) and the loop metrics.
if [ "${HAPTIC:-1}" != 0 ]; then
  bash scripts/build.sh dynsolid-haptic-bridge
  rm -rf "$OUT/haptic"
  mkdir -p "$OUT/haptic"
  /usr/bin/python3 tests/haptic/haptic_loopback_test.py --server "$SERVER" --client "$CLIENT" \
    --bridge "$BIN/clients/haptic/dynsolid-haptic-bridge" --out "$OUT/haptic" \
    > "$OUT/haptic/run.txt" 2>&1 || { cat "$OUT/haptic/run.txt" >&2; exit 1; }
  { echo; /usr/bin/python3 scripts/haptic_report.py "$OUT/haptic"; } >> "$OUT/summary.md"
fi
cat "$OUT/summary.md"
