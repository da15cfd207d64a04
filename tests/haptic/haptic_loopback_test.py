"""dynsolid-haptic-bridge with a virtual hand against a real dynsolid-server.

Over loopback, as a user runs them (docs/haptic.md "What is shown"):
  1. a session of block3 (one level, damped to settle quickly: see SCENE)
     with the half x > 1.5 painted ten times stiffer; before any probe its
     stats have no "contact" phase;
  2. the virtual hand pushes into the soft half, then into the stiff half,
     in three held steps each: forces oppose penetration and grow with
     depth; the solid dents (a Pick at the contact point mid-push finds
     the surface pushed in; GetStats shows the probe and the contact
     phase); the force-dent slope ratio stiff / soft is printed and
     checked against the ratio of the solid's own static stiffness that
     the contact models report;
  3. the hand holds a push while the server is frozen (SIGSTOP: silent,
     the stream stays open) and later killed (SIGKILL: the stream breaks):
     each time the force ramps to zero within 10 ms and stays there; the
     server is restarted on its data directory and the bridge reconnects
     and pushes again by itself.
Every run's largest force step must stay within the bound.

Usage: haptic_loopback_test.py --server PATH --client PATH --bridge PATH
           [--out DIR] (keeps traces, metrics and results.json there)
"""

import argparse
import csv
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "testing"))
from loopback import fail  # noqa: E402

CALL_SECONDS = 60
SOFT = (0.75, 1.5)
STIFF = (2.25, 1.5)
# Held steps of the hand's target below the surface (m) and their length.
STEPS = [0.01, 0.03, 0.05]
HOLD = 2.0
RAMP_MS = 10.0
# The probe's replies go out on gRPC's threads, which the server runs under
# SCHED_IDLE by default (server/README.md "Priorities"): on a machine whose
# cores are busy they starve, the models come in bursts with gaps above the
# bridge's 10 ms timeout, and the bridge ramps its force down again and
# again. A haptic server runs its streaming threads at normal priority
# (docs/haptic.md "Server").
SERVER_FLAGS = ["--stream_idle=false", "--stream_nice=0"]
BRIDGE_FLAGS = []


def check(ok, message):
    if not ok:
        fail(message)
    print("ok: " + message)


def free_port():
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return port


class ServerProcess:
    def __init__(self, binary, port, data_dir, log_path):
        self.binary, self.port, self.data_dir, self.log_path = binary, port, data_dir, log_path
        self.process = None

    def start(self):
        log = open(self.log_path, "a")
        self.process = subprocess.Popen(
            [self.binary, "--listen", "127.0.0.1:%d" % self.port, "--data_dir", self.data_dir] +
            SERVER_FLAGS,
            stdout=subprocess.PIPE, stderr=log, text=True)
        line = []
        reader = threading.Thread(target=lambda: line.append(self.process.stdout.readline()))
        reader.daemon = True
        reader.start()
        reader.join(30)
        if not line or "listening on" not in line[0]:
            fail("the server did not start: %r" % line)

    def signal(self, sig):
        self.process.send_signal(sig)

    def kill(self):
        self.process.kill()
        self.process.wait()

    def stop(self):
        if self.process and self.process.poll() is None:
            self.process.send_signal(signal.SIGTERM)
            try:
                self.process.wait(20)
            except subprocess.TimeoutExpired:
                self.process.kill()


def client_json(args, server, *command):
    r = subprocess.run([args.client, "--server", server] + list(command), capture_output=True,
                       text=True, timeout=CALL_SECONDS)
    if r.returncode != 0:
        fail("dynsolid-client %s exited %d: %s" % (" ".join(command), r.returncode,
                                                   r.stderr.strip()))
    return json.loads(r.stdout)


def scene_text(source_dir):
    """block3 at a tenth of its density (100 kg/m^3, a foam-like block of
    2.7 t instead of 27 t) and damped about critically for its slowest
    way of yielding under a push (1100 kg/(m^3 s): 11 per second per unit
    mass; that way has about 5 rad/s at this density), so a held push
    settles within its two seconds and the force-dent slopes are static
    ones. At block3's own density a push on the soft half creeps for
    seconds (about 1.7 rad/s, damped at 2 per second). The paper's
    local-frame model, for which the damping and the pushes (dents of a few
    millimetres) were tuned: block3 itself now steps the corotational model
    per control cell, about 70 times stiffer in bending. Otherwise the scene
    itself."""
    text = open(os.path.join(source_dir, "scenes", "block3.textproto")).read()
    for old, new in (("density: 1000 damping: 3000", "density: 100 damping: 1100"),
                     ("model: COROTATIONAL\n  corotation: CONTROL_CELL\n", "model: LOCAL_FRAME\n")):
        if old not in text:
            fail("scenes/block3.textproto: no \"%s\" to change" % old)
        text = text.replace(old, new)
    return text.replace('name: "block3"', 'name: "block3_haptic"')


def hand_script(path, x, y, steps, hold, tail=True):
    """The virtual hand's target: above the point, then down in held steps."""
    lines = ["0 %g %g 3.05" % (x, y), "0.3 %g %g 3.05" % (x, y)]
    t = 0.3
    for i, s in enumerate(steps):
        t += 0.7 if i == 0 else 0.3
        lines.append("%g %g %g %g" % (t, x, y, 3.0 - s))
        t += hold
        lines.append("%g %g %g %g" % (t, x, y, 3.0 - s))
    if tail:
        t += 0.5
        lines.append("%g %g %g 3.05" % (t, x, y))
        t += 0.3
        lines.append("%g %g %g 3.05" % (t, x, y))
    open(path, "w").write("\n".join(lines) + "\n")
    return t


def hold_ends(steps, hold):
    """(start, end) of the last 0.25 s of each hold."""
    out = []
    t = 0.3
    for i, _ in enumerate(steps):
        t += 0.7 if i == 0 else 0.3
        t += hold
        out.append((t - 0.25, t))
    return out


def read_trace(path):
    rows = []
    with open(path) as f:
        for r in csv.DictReader(f):
            rows.append({k: float(v) for k, v in r.items()})
    return rows


def mean(values):
    return sum(values) / len(values) if values else float("nan")


def bridge_cmd(args, server, session, script, tag, extra=()):
    return [args.bridge, "--server", server, "--id", session["id"], "--token", session["token"],
            "--device", "virtual_hand", "--script", script, "--hand_stiffness", "500",
            "--json", os.path.join(args.out, tag + ".json"),
            "--trace", os.path.join(args.out, tag + ".csv"), "--verbose"] + BRIDGE_FLAGS + list(extra)


def probe_region(args, server, session, name, point):
    script = os.path.join(args.out, name + "_hand.txt")
    duration = hand_script(script, point[0], point[1], STEPS, HOLD)
    log = open(os.path.join(args.out, name + "_bridge.log"), "w")
    bridge = subprocess.Popen(bridge_cmd(args, server, session, script, name), stdout=log,
                              stderr=subprocess.STDOUT, text=True)
    # Mid-push of the deepest hold: the solid's own state, from the server.
    windows = hold_ends(STEPS, HOLD)
    time.sleep(windows[-1][0] - 0.1)
    pick = client_json(args, server, "pick", "--id", session["id"], "--token", session["token"],
                       "--origin", "%g,%g,4" % point, "--direction", "0,0,-1")
    stats = client_json(args, server, "stats", "--id", session["id"], "--token",
                        session["token"])
    if bridge.wait(duration + 60) != 0:
        fail("the %s bridge exited %d (log %s)" % (name, bridge.returncode, log.name))
    rows = read_trace(os.path.join(args.out, name + ".csv"))
    metrics = json.load(open(os.path.join(args.out, name + ".json")))
    holds = []
    for (a, b) in windows:
        sel = [r for r in rows if a <= r["t"] <= b and r["model_step"] >= 0]
        holds.append({"force": mean([r["f_normal"] for r in sel]),
                      "depth": mean([r["depth"] for r in sel]),
                      "dent": mean([r["dent"] for r in sel]),
                      "k_static": mean([r["k_static"] for r in sel]),
                      "k": mean([r["k"] for r in sel])})
    return {"rows": rows, "metrics": metrics, "holds": holds, "pick": pick, "stats": stats}


def slope_through_origin(xs, ys):
    return sum(x * y for x, y in zip(xs, ys)) / sum(x * x for x in xs)


def check_region(name, r):
    rows, m = r["rows"], r["metrics"]
    contact = [x for x in rows if x["f_normal"] > 0]
    # (A share of the ticks, not a count: on a loaded machine the 1 kHz
    # loop runs fewer ticks; here about 80 % of them push.)
    check(len(contact) > 100 and len(contact) > 0.3 * len(rows),
          "%s: the hand was in contact for %d of %d ticks" % (name, len(contact), len(rows)))
    # The force opposes penetration: along the outward normal, only with
    # the device below the (rest) surface.
    # A fresh model (at most 2 ms old) pushes only while the device is below
    # the surface. (An older one extrapolates the surface and carries the
    # server's last force, so on a busy machine, as the hand leaves, a late
    # model can push for a tick or two from just above the rest surface;
    # after it leaves, a blend or a safety ramp may also finish for a few ms.)
    # "Below" within 2 % of the deepest dent: as the hand leaves, the
    # surface springs back and overshoots its rest place by a few microns,
    # and a model that saw it there pushes from just above the rest surface
    # (a CI run on a loaded machine: -5.0 um against a 0.37 mm dent).
    fresh = [x for x in rows if x["in_contact"] and x["model_age"] <= 0.002]
    overshoot = 0.02 * max([x["dent"] for x in rows] or [0])
    check(len(fresh) > 100 and all(x["depth"] > -overshoot for x in fresh),
          "%s: a fresh model pushes only while the device is below the surface, within "
          "%.1f um (%d fresh ticks in contact, least depth %.1f um)" %
          (name, 1e6 * overshoot, len(fresh), 1e6 * min([x["depth"] for x in fresh] or [0])))
    # Out of contact the force fades: below 10 mN (less than a device
    # renders) once a fresh model (at most 2 ms old) has come more than 15
    # ticks after the hand left, below 1 mN after 30. Only fresh models
    # count: on a loaded machine the last models of a contact come late
    # (a CI run on a loaded machine saw 64 mN 16 ticks out), and a blend
    # or a safety ramp then finishes later; that is timing, not physics.
    tail = 0
    for x in rows:
        tail = 0 if x["in_contact"] else tail + 1
        if x["model_age"] > 0.002:
            continue
        if (tail > 15 and x["f_normal"] > 1e-2) or (tail > 30 and x["f_normal"] > 1e-3):
            fail("%s: force %.3f N at t = %.3f, %d ticks out of contact with a model %.1f ms "
                 "old" % (name, x["f_normal"], x["t"], tail, 1e3 * x["model_age"]))
    ramps = sum(1 for i in range(1, len(rows)) if rows[i]["ramping"] and
                not rows[i - 1]["ramping"])
    print("%s: %d safety ramps (silences of the server above 10 ms)" % (name, ramps))
    check(all(x["fz"] >= 0.99 * (x["fx"] ** 2 + x["fy"] ** 2 + x["fz"] ** 2) ** 0.5
              for x in rows),
          "%s: the force points out of the top face (+z, within 8 degrees)" % name)
    holds = r["holds"]
    for i in range(1, len(holds)):
        check(holds[i]["depth"] > holds[i - 1]["depth"] and
              holds[i]["force"] > holds[i - 1]["force"] and
              holds[i]["dent"] > holds[i - 1]["dent"],
              "%s: deeper hold %d: force %.2f > %.2f N at depth %.2f > %.2f mm, dent %.3f mm" %
              (name, i, holds[i]["force"], holds[i - 1]["force"], 1e3 * holds[i]["depth"],
               1e3 * holds[i - 1]["depth"], 1e3 * holds[i]["dent"]))
    pick = r["pick"]
    z = pick.get("point", {}).get("z", 3.0)
    check(pick.get("hit") and z < 3.0 - 2e-4,
          "%s: Pick mid-push finds the surface pushed in to z = %.5f" % (name, z))
    phases = [p["name"] for p in r["stats"].get("phases", [])]
    check("contact" in phases and r["stats"].get("probes") == 1,
          "%s: GetStats mid-push: 1 probe, phases %s" % (name, phases))
    check(m["largest_force_step_n"] <= m["force_step_bound_n"] + 1e-9,
          "%s: largest force step %.3f N within the bound %.1f N" %
          (name, m["largest_force_step_n"], m["force_step_bound_n"]))


def check_ramp(rows, start, label, until):
    """From tick `start` (the first silent or broken one) the force reaches
    zero within RAMP_MS and stays zero up to time `until`."""
    t0 = rows[start]["t"]
    f0 = rows[start - 1]["f_normal"]
    zero_at = None
    for r in rows[start:]:
        if r["t"] > until:
            break
        if zero_at is None and r["f_normal"] == 0:
            zero_at = r["t"]
        if zero_at is not None and r["f_normal"] != 0:
            fail("%s: the force came back at t = %.4f before %.4f" % (label, r["t"], until))
    check(f0 > 1.0 and zero_at is not None and (zero_at - t0) * 1e3 <= RAMP_MS + 0.5,
          "%s: force %.2f N ramped to zero in %.1f ms and stayed zero" %
          (label, f0, (zero_at - t0) * 1e3 if zero_at else float("nan")))


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--server", required=True)
    parser.add_argument("--client", required=True)
    parser.add_argument("--bridge", required=True)
    parser.add_argument("--out", default="")
    args = parser.parse_args()
    source_dir = os.environ.get("DYNSOLID_SOURCE_DIR",
                                os.path.dirname(os.path.dirname(os.path.dirname(
                                    os.path.abspath(__file__)))))
    keep = bool(args.out)
    if not keep:
        args.out = tempfile.mkdtemp(prefix="haptic_loopback_")
    os.makedirs(args.out, exist_ok=True)
    data_dir = tempfile.mkdtemp(prefix="haptic_data_")
    port = free_port()
    server_addr = "127.0.0.1:%d" % port
    srv = ServerProcess(args.server, port, data_dir, os.path.join(args.out, "server.log"))
    srv.start()
    try:
        scene_path = os.path.join(args.out, "block3_haptic.textproto")
        open(scene_path, "w").write(scene_text(source_dir))
        session = client_json(args, server_addr, "create", "--scene_file", scene_path,
                              "--levels", "1")
        stats = client_json(args, server_addr, "stats", "--id", session["id"], "--token",
                            session["token"])
        phases = [p["name"] for p in stats.get("phases", [])]
        check("contact" not in phases and stats.get("probes", 0) == 0,
              "no probe: no contact phase (phases %s)" % phases)
        paint = os.path.join(args.out, "paint.txt")
        open(paint, "w").write("paint box=1.5,-1,-1,4,4,4 E=1e6 strength=1\n")
        r = subprocess.run([args.client, "--server", server_addr, "run", "--script", paint,
                            "--id", session["id"], "--token", session["token"]],
                           capture_output=True, text=True, timeout=CALL_SECONDS)
        if r.returncode != 0:
            fail("paint: %s" % r.stderr)

        soft = probe_region(args, server_addr, session, "soft", SOFT)
        stiff = probe_region(args, server_addr, session, "stiff", STIFF)
        check_region("soft", soft)
        check_region("stiff", stiff)
        # Slopes: force against the solid's dent (its own response) and
        # against the device's depth (what the hand feels, through the
        # coupling spring in series).
        results = {}
        for name, reg in (("soft", soft), ("stiff", stiff)):
            h = reg["holds"]
            results[name] = {
                "holds": h,
                "slope_dent": slope_through_origin([x["dent"] for x in h],
                                                   [x["force"] for x in h]),
                "slope_depth": slope_through_origin([x["depth"] for x in h],
                                                    [x["force"] for x in h]),
                "k_static": mean([x["k_static"] for x in h]),
                "k": mean([x["k"] for x in h]),
                "metrics": reg["metrics"],
            }
        measured = results["stiff"]["slope_dent"] / results["soft"]["slope_dent"]
        predicted = results["stiff"]["k_static"] / results["soft"]["k_static"]
        felt = results["stiff"]["slope_depth"] / results["soft"]["slope_depth"]
        print("force-dent slope: soft %.0f N/m, stiff %.0f N/m, ratio %.2f; the solid's own "
              "static stiffness (contact models): soft %.0f, stiff %.0f N/m, ratio %.2f; "
              "force-depth slope felt at the device: soft %.0f, stiff %.0f N/m, ratio %.2f" %
              (results["soft"]["slope_dent"], results["stiff"]["slope_dent"], measured,
               results["soft"]["k_static"], results["stiff"]["k_static"], predicted,
               results["soft"]["slope_depth"], results["stiff"]["slope_depth"], felt))
        check(felt > 1.3, "the stiff region gives a larger force at equal depth (x%.2f)" % felt)
        check(abs(measured / predicted - 1) < 0.2,
              "force-dent slope ratio %.2f within 20 %% of the solid's own %.2f" %
              (measured, predicted))
        # Each region's own slope against its static stiffness: within 30 %.
        # (The holds end on the wall clock; a server behind real time on a
        # loaded machine has dented less by then: 22 % high with 84 safety
        # ramps at load 6 on two cores. The ratio above cancels that.)
        for name in ("soft", "stiff"):
            k_s, slope = results[name]["k_static"], results[name]["slope_dent"]
            check(abs(slope / k_s - 1) < 0.3,
                  "%s: force-dent slope %.0f N/m within 30 %% of k_static %.0f N/m" %
                  (name, slope, k_s))

        # Safety: a long push; freeze the server, thaw it, kill it, restart it.
        script = os.path.join(args.out, "safety_hand.txt")
        open(script, "w").write("0 0.75 1.5 3.05\n0.3 0.75 1.5 3.05\n1.0 0.75 1.5 2.97\n"
                                "9.0 0.75 1.5 2.97\n")
        log = open(os.path.join(args.out, "safety_bridge.log"), "w")
        t_start = time.monotonic()
        bridge = subprocess.Popen(bridge_cmd(args, server_addr, session, script, "safety"),
                                  stdout=log, stderr=subprocess.STDOUT, text=True)
        time.sleep(2.5)
        t_stop = time.monotonic() - t_start
        srv.signal(signal.SIGSTOP)
        time.sleep(0.4)
        srv.signal(signal.SIGCONT)
        time.sleep(1.6)
        t_kill = time.monotonic() - t_start
        srv.kill()
        time.sleep(1.0)
        srv.start()  # same port, same data directory: the session is recovered
        if bridge.wait(60) != 0:
            fail("the safety bridge exited %d" % bridge.returncode)
        rows = read_trace(os.path.join(args.out, "safety.csv"))
        metrics = json.load(open(os.path.join(args.out, "safety.json")))
        # The freeze: the longest ramp with the stream open after contact was
        # established. (On a loaded machine the server can also fall silent
        # for more than 10 ms on its own, a short ramp that ends when its
        # models come again; the freeze lasts 0.4 s.)
        first_contact = next(i for i, r in enumerate(rows) if r["f_normal"] > 1.0)
        episodes = []
        i = first_contact
        while i < len(rows):
            if rows[i]["ramping"] == 1 and rows[i]["link_up"] == 1:
                j = i
                while j < len(rows) and rows[j]["ramping"] == 1 and rows[j]["link_up"] == 1:
                    j += 1
                if j < len(rows) and rows[j]["ramping"] == 0:
                    episodes.append((rows[j]["t"] - rows[i]["t"], i, j))
                i = j
            else:
                i += 1
        if not episodes:
            fail("freeze: no ramp with the stream open after contact")
        _, silent, resumed = max(episodes)
        check(rows[silent]["link_up"] == 1, "freeze: the stream stayed open (silent server)")
        check_ramp(rows, silent, "silent server (SIGSTOP)", rows[resumed]["t"])
        check(rows[resumed]["t"] < t_kill, "after SIGCONT models came again at t = %.2f s" %
              rows[resumed]["t"])
        broken = next(i for i in range(resumed, len(rows)) if rows[i]["link_up"] == 0)
        back = next((i for i in range(broken, len(rows)) if rows[i]["link_up"] == 1), None)
        check_ramp(rows, broken, "broken stream (SIGKILL)",
                   rows[back]["t"] if back is not None else rows[-1]["t"])
        check(back is not None, "the bridge reconnected to the restarted server by itself")
        pushed_again = [r for r in rows[back:] if r["f_normal"] > 1.0]
        check(len(pushed_again) > 500, "and pushed again (%d ticks with force after "
                                       "reconnecting; %d reconnects)" %
              (len(pushed_again), metrics["reconnects"]))
        check(metrics["largest_force_step_n"] <= metrics["force_step_bound_n"] + 1e-9,
              "safety run: largest force step %.3f N within the bound" %
              metrics["largest_force_step_n"])
        print("silent at t = %.3f s (SIGSTOP sent at %.2f s), broken at t = %.3f s (SIGKILL at "
              "%.2f s), reconnected at t = %.3f s" %
              (rows[silent]["t"], t_stop, rows[broken]["t"], t_kill, rows[back]["t"]))
        results["safety"] = {"metrics": metrics, "silent_t": rows[silent]["t"],
                             "broken_t": rows[broken]["t"], "reconnected_t": rows[back]["t"]}
        results["ratios"] = {"force_dent": measured, "k_static": predicted,
                             "force_depth": felt}
        json.dump(results, open(os.path.join(args.out, "results.json"), "w"), indent=1)
    finally:
        srv.stop()
        shutil.rmtree(data_dir, ignore_errors=True)
        if not keep:
            shutil.rmtree(args.out, ignore_errors=True)
    print("PASS")


if __name__ == "__main__":
    main()
