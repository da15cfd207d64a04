"""dynsolid-client against a real dynsolid-server, as a user runs them.

1. A scripted session (block3 at one level, paused, every command kind):
   exit 0; each command answered exactly once although the command stream
   is dropped after every 3rd command (--break_every 3); the server applied
   each once (its counters); the final step is what the script's steps add
   up to; the watched surface equals the server's within the quantization
   bound; snapshots and recorded frames exist and parse (OBJ by hand, .vtu
   as XML) with the surface's vertex and quad counts; the summary numbers
   are sane.
2. kill -9 of the server while the client sleeps in the middle of a script,
   restart on the same port and data directory: the client reconnects,
   resends, and finishes; the step commands were applied once each.
3. A command the server rejects stops the run with exit code 3 and the
   script's file:line; a bad script is refused before anything is sent.
4. SIGTERM stops the server with exit code 0.
5. Over TLS (a self-signed certificate made with openssl): --tls_ca runs a
   script; without it the client cannot connect.

Usage: client_loopback_test.py --server PATH --client PATH
"""

import json
import os
import re
import signal
import subprocess
import sys
import time
import xml.etree.ElementTree as ET

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "testing"))
from loopback import (binary_args, expect, expect_equal, fail, first_line,  # noqa: E402
                      run_in_temp_dir)

STARTUP_SECONDS = 60
RUN_SECONDS = 120


class Server:
    def __init__(self, binary, data_dir, log, listen="127.0.0.1:0", extra=()):
        self.log = open(log, "a")
        self.process = subprocess.Popen(
            [binary, "--listen", listen, "--data_dir", data_dir] + list(extra),
            stdout=subprocess.PIPE, stderr=self.log, text=True)
        first = first_line(self.process, STARTUP_SECONDS)
        match = re.fullmatch(r"listening on (127\.0\.0\.1:(\d+))", first)
        if not match or int(match.group(2)) == 0:
            self.process.kill()
            fail("server's first line: expected 'listening on 127.0.0.1:PORT', got %r (log %s)"
                 % (first, log))
        self.address = match.group(1)

    def stop(self, sig=signal.SIGTERM):
        self.process.send_signal(sig)
        try:
            return self.process.wait(30)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait()
            fail("the server did not exit within 30 s of signal %d" % sig)
        finally:
            self.log.close()


def run_client(client, address, *args, timeout=RUN_SECONDS):
    return subprocess.run([client, "--server", address] + list(args), capture_output=True,
                          text=True, timeout=timeout)


def read_obj(path):
    vertices, faces = [], []
    with open(path) as f:
        for line in f:
            parts = line.split()
            if not parts or parts[0] == "#":
                continue
            if parts[0] == "v":
                vertices.append(tuple(float(x) for x in parts[1:4]))
            elif parts[0] == "f":
                faces.append(tuple(int(x) for x in parts[1:]))
    for f in faces:
        expect(len(f) == 4 and all(1 <= i <= len(vertices) for i in f),
               "%s: face %r is not a quad of existing vertices" % (path, f))
    return vertices, faces


def read_vtu(path):
    root = ET.parse(path).getroot()
    piece = root.find("UnstructuredGrid/Piece")
    n_points = int(piece.get("NumberOfPoints"))
    n_cells = int(piece.get("NumberOfCells"))
    arrays = {}
    for a in piece.iter("DataArray"):
        arrays[a.get("Name") or "points"] = [float(x) for x in a.text.split()]
    expect_equal("%s: point coordinates" % path, len(arrays["points"]), 3 * n_points)
    expect_equal("%s: connectivity" % path, len(arrays["connectivity"]), 4 * n_cells)
    expect(all(t == 9 for t in arrays["types"]), "%s: cells are not all VTK_QUAD" % path)
    return n_points, n_cells, arrays


SCRIPT = """# every command kind of service.proto
force at=1.5,1.5,3 f=5e3,0,0 name=pull
step 20
wait
snapshot pulled
pressure box=0,0,2.99,3,3,3.01 pa=2000 name=puff
fix box=2.99,0,0,3.01,3,3 name=pin
paint sphere=1.5,1.5,2.5,1 E=3e5 strength=0.8
gravity 0,0,-9.81
step 15
wait
remove pull
unfix pin
remove puff
save
pause
resume
pause
wait 0
step 5
wait
snapshot final
"""


def check_report(report, n_commands):
    expect_equal("report status", report["status"], "OK")
    log = report["commands"]["log"]
    expect_equal("commands in the log", len(log), n_commands)
    expect_equal("seqs", [c["seq"] for c in log], list(range(1, n_commands + 1)))
    for c in log:
        expect(c["answered"] and c["answers"] == 1,
               "command %s (%s) answered %d times" % (c["seq"], c["where"], c["answers"]))
        expect_equal("command %s (%s) code" % (c["seq"], c["where"]), c["code"], 0)
        expect(c["applied_step"] >= 0, "command %s applied_step %d" % (c["seq"], c["applied_step"]))
        expect(c["latency_ms"] > 0, "command %s latency %r" % (c["seq"], c["latency_ms"]))
    expect_equal("extra answers", report["commands"]["extra_answers"], 0)
    lat = report["commands"]["latency_ms"]
    expect(0 < lat["median"] <= lat["p99"] <= lat["max"], "latency figures %r" % lat)
    return log


def check_final_step(report, step):
    expect_equal("surface step", report["surface"]["step"], step)
    expect_equal("server step", int(report["server_stats"]["step"]), step)


def main():
    run_in_temp_dir(run, binary_args("server", "client"), "dynsolid_client_test_")


def run(args, tmp):
    log = os.path.join(tmp, "server.log")
    server = Server(args.server, os.path.join(tmp, "data"), log)
    try:
        # ---- 1. The scripted session ----
        script = os.path.join(tmp, "s.txt")
        with open(script, "w") as f:
            f.write(SCRIPT)
        frames = os.path.join(tmp, "frames")
        report_path = os.path.join(tmp, "report.json")
        r = run_client(args.client, server.address, "run", "--script", script, "--scene", "block3",
                       "--levels", "1", "--start_paused", "--frames_dir", frames,
                       "--format", "obj,vtu", "--record_every", "4",
                       "--fields", "displacement,stiffness", "--json", report_path,
                       "--break_every", "3", "--client_id", "loopback-test")
        expect(r.returncode == 0, "run exited %d: %s" % (r.returncode, r.stderr))
        with open(report_path) as f:
            report = json.load(f)
        n = 15  # command lines in SCRIPT
        log_ = check_report(report, n)
        # Paused, the steps come from the script alone, up to the resume;
        # the second pause lands whenever it arrives, then 5 more steps.
        steps = [c["applied_step"] for c in log_]
        expect_equal("applied steps of the paused part", steps[:12],
                     [0, 0, 20, 20, 20, 20, 20, 35, 35, 35, 35, 35])
        expect(35 <= steps[12] <= steps[13] == steps[14],
               "applied steps of resume, pause, step: %r" % steps[12:])
        final = steps[14] + 5
        check_final_step(report, final)
        # A drop may hit a stream that is already broken, so fewer reconnects
        # than drops are possible; but some commands were written twice.
        expect(report["commands"]["resends"] >= 1 and report["commands"]["reconnects"] >= 1,
               "--break_every 3: resends %d, reconnects %d"
               % (report["commands"]["resends"], report["commands"]["reconnects"]))
        stats = report["server_stats"]
        duplicates = sum(1 for c in log_ if c["duplicate"])
        expect_equal("server commands_applied (each command once)",
                     int(stats["commands_applied"]), n)
        expect_equal("server commands_duplicate = duplicate answers the client got",
                     int(stats.get("commands_duplicate", "0")), duplicates)
        expect_equal("server commands_rejected", int(stats.get("commands_rejected", "0")), 0)
        steps = [c["applied_step"] for c in log_]
        expect(report["check"]["done"] and report["check"]["within_bound"],
               "watched surface vs server positions: %r" % report["check"])
        bound = report["surface"]["error_bound"]
        for a in range(3):
            # Half a grid step, up to the rounding of origin + code * step.
            expect(report["check"]["max_error"][a] <= bound[a] * (1 + 1e-9),
                   "axis %d: error %g > bound %g" % (a, report["check"]["max_error"][a], bound[a]))
        solid = report["session"]["solid"]
        surface = report["surface"]
        expect_equal("surface vertices", surface["vertices"], solid["boundary_vertices"])
        expect_equal("surface quads", surface["quads"], solid["boundary_faces"])
        expect(surface["max_moved_since_first"] > 1e-4,
               "the pulled block did not move: %r" % surface["max_moved_since_first"])
        expect(surface["stiffness_max"] > surface["stiffness_min"] > 0,
               "painted stiffness range %r..%r" % (surface["stiffness_min"],
                                                    surface["stiffness_max"]))
        watch = report["watch"]
        expect(watch["frames"] >= 2 and watch["keyframes"] >= 1, "watch %r" % watch)
        expect(watch["bytes"] < watch["raw_float32_bytes"], "frames larger than raw: %r" % watch)
        expect(watch["frames_written"] >= 1, "no frame recorded: %r" % watch)
        expect_equal("last watched step", watch["last_step"], final)
        snaps = {s["name"]: s for s in report["snapshots"]}
        expect_equal("snapshots", sorted(snaps), ["final", "pulled"])
        expect(snaps["pulled"]["step"] >= 20, "pulled at step %d" % snaps["pulled"]["step"])
        expect_equal("final snapshot step", snaps["final"]["step"], final)
        for name in ("pulled", "final"):
            v, f = read_obj(os.path.join(frames, name + ".obj"))
            expect_equal("%s.obj vertices" % name, len(v), surface["vertices"])
            expect_equal("%s.obj quads" % name, len(f), surface["quads"])
            nv, nc, arrays = read_vtu(os.path.join(frames, name + ".vtu"))
            expect_equal("%s.vtu points" % name, nv, surface["vertices"])
            expect_equal("%s.vtu cells" % name, nc, surface["quads"])
            for field in ("displacement", "stiffness", "node"):
                expect_equal("%s.vtu %s values" % (name, field), len(arrays.get(field, [])), nv)
            # OBJ and .vtu carry the same positions.
            for i in range(nv):
                for a in range(3):
                    expect(abs(v[i][a] - arrays["points"][3 * i + a]) <= 1e-12,
                           "%s: obj and vtu differ at vertex %d" % (name, i))
        # The final snapshot's bounding box is the report's.
        v, _ = read_obj(os.path.join(frames, "final.obj"))
        for a in range(3):
            expect(abs(min(p[a] for p in v) - surface["bbox_min"][a]) < 1e-12, "bbox_min")
            expect(abs(max(p[a] for p in v) - surface["bbox_max"][a]) < 1e-12, "bbox_max")
        recorded = [f for f in os.listdir(frames) if re.fullmatch(r"frame_\d{8}\.(obj|vtu)", f)]
        expect_equal("recorded frame files", len(recorded), 2 * watch["frames_written"])
        # frames.pvd indexes the recorded VTU frames, in order, by time.
        sets = ET.parse(os.path.join(frames, "frames.pvd")).getroot().findall("Collection/DataSet")
        listed = [x.get("file") for x in sets]
        expect_equal("frames.pvd files", listed,
                     sorted(f for f in recorded if f.endswith(".vtu")))
        times = [float(x.get("timestep")) for x in sets]
        expect(times == sorted(times) and len(set(times)) == len(times),
               "frames.pvd times %r" % times)
        for out in ("median", "p99", "frames/s"):
            expect(out in r.stdout, "stdout lacks %r: %r" % (out, r.stdout))
        expect(report["session"]["closed"], "the session was not closed")

        # ---- 2. kill -9 while the client sleeps; restart on the same port ----
        created = run_client(args.client, server.address, "create", "--scene", "block3",
                             "--levels", "1", "--start_paused")
        expect(created.returncode == 0, "create: %s" % created.stderr)
        session = json.loads(created.stdout)
        sid, token = session["id"], session["token"]
        with open(script, "w") as f:
            f.write("step 10\nwait\nsleep 3\nstep 10\nforce at=1.5,1.5,3 f=1e3,0,0\n"
                    "step 10\nwait\n")
        report2 = os.path.join(tmp, "report2.json")
        client = subprocess.Popen(
            [args.client, "--server", server.address, "run", "--script", script, "--id", sid,
             "--token", token, "--close", "--json", report2, "--client_id", "survivor"],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        deadline = time.time() + 60
        while True:
            st = run_client(args.client, server.address, "stats", "--id", sid, "--token", token)
            if st.returncode == 0 and int(json.loads(st.stdout).get("step", "0")) >= 10:
                break
            expect(time.time() < deadline, "the session never reached step 10")
            time.sleep(0.05)
        port = server.address
        server.stop(signal.SIGKILL)
        time.sleep(0.3)
        server = Server(args.server, os.path.join(tmp, "data"), log, listen=port)
        out, err = client.communicate(timeout=RUN_SECONDS)
        expect(client.returncode == 0, "client across the restart exited %d: %s"
               % (client.returncode, err))
        with open(report2) as f:
            rep = json.load(f)
        check_report(rep, 4)
        # Step counts add up: 10, then 10 + 10 at step 10. Had a resent step
        # been applied twice, the session would be further.
        check_final_step(rep, 30)
        expect(rep["commands"]["reconnects"] >= 1 and rep["watch"]["reconnects"] >= 1,
               "no reconnect seen: commands %d, watch %d"
               % (rep["commands"]["reconnects"], rep["watch"]["reconnects"]))

        # ---- 3. Rejected command; bad script ----
        with open(script, "w") as f:
            f.write("step 1\nfix box=10,10,10,11,11,11\nstep 1\n")
        r = run_client(args.client, server.address, "run", "--script", script, "--scene",
                       "block3", "--levels", "1", "--start_paused", "--nowatch")
        expect_equal("exit code of a run with a rejected command", r.returncode, 3)
        expect(re.search(re.escape(script) + r":2: fix: rejected: INVALID_ARGUMENT: \S",
                         r.stderr), "stderr of the rejected run: %r" % r.stderr)
        with open(script, "w") as f:
            f.write("step 1\nforce at=1,2 f=0,0,1\n")
        r = run_client(args.client, server.address, "run", "--script", script, "--scene",
                       "block3")
        expect_equal("exit code of a bad script", r.returncode, 1)
        expect_equal("stderr of a bad script", r.stderr,
                     script + ":2: force: \"at=1,2\" needs 3 numbers, got 2\n")
        listed = json.loads(run_client(args.client, server.address, "list").stdout)
        expect_equal("sessions left open", listed.get("sessions", []), [])
    finally:
        code = server.stop()
    expect_equal("server exit code after SIGTERM", code, 0)

    # ---- 5. TLS ----
    cert, key = os.path.join(tmp, "cert.pem"), os.path.join(tmp, "key.pem")
    made = subprocess.run(["openssl", "req", "-x509", "-newkey", "rsa:2048", "-nodes",
                           "-keyout", key, "-out", cert, "-days", "1", "-subj", "/CN=localhost",
                           "-addext", "subjectAltName=IP:127.0.0.1,DNS:localhost"],
                          capture_output=True, text=True)
    expect(made.returncode == 0, "openssl could not make a certificate: %s" % made.stderr)
    server = Server(args.server, os.path.join(tmp, "tls_data"), log,
                    extra=["--tls_cert", cert, "--tls_key", key])
    try:
        with open(script, "w") as f:
            f.write("step 3\nwait\n")
        report_path = os.path.join(tmp, "tls.json")
        r = run_client(args.client, server.address, "--tls_ca", cert, "run", "--script", script,
                       "--scene", "block3", "--levels", "1", "--start_paused",
                       "--json", report_path)
        expect(r.returncode == 0, "run over TLS exited %d: %s" % (r.returncode, r.stderr))
        with open(report_path) as f:
            check_final_step(json.load(f), 3)
        r = run_client(args.client, server.address, "--timeout_seconds", "5", "list")
        expect(r.returncode == 2 and "UNAVAILABLE" in r.stderr,
               "plaintext client against the TLS server: exit %d, %r" % (r.returncode, r.stderr))
    finally:
        code = server.stop()
    expect_equal("TLS server exit code after SIGTERM", code, 0)


if __name__ == "__main__":
    main()
