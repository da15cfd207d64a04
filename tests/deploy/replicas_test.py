"""Three dynsolid-server replicas on this machine, as a StatefulSet runs them.

Each replica listens on its own loopback address (127.0.0.1, .2, .3, one
port), has its own data directory, and knows the other two (--replica,
--peers). Shown:

1. Sessions created through one replica spread over the three (placement
   by load; ties go to the replica asked, then to the peers in order), and
   each id names its owner ("rK.HEX"), whose address the reply carries.
2. The CLI asked at a replica that does not own a session follows the
   redirect (get, stats, loads, run); a wrong token there still fails with
   PERMISSION_DENIED, and an id naming an unknown replica gets NOT_FOUND
   naming it. The haptic bridge given a replica that does not own its
   session probes it where it lives.
3. The load tester pointed at one replica spreads its sessions over the
   three and loses nothing.
4. One replica drained with SIGTERM exits 0 at once and, restarted, has
   every session, none behind.
5. One replica killed with SIGKILL while clients work on the other two:
   a session created meanwhile is placed on a live replica; the killed one,
   restarted on its data directory, has all its sessions, with every
   acknowledged command (the step count, the loads); the clients of the
   other replicas finish their scripts without a single reconnect.

Usage: replicas_test.py --server PATH --client PATH --load PATH --bridge PATH
"""

import argparse
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "testing"))
from loopback import expect, fail, first_line  # noqa: E402

STARTUP_SECONDS = 60
CALL_SECONDS = 120
HOSTS = ["127.0.0.1", "127.0.0.2", "127.0.0.3"]


def free_port():
    """A port free on all three loopback addresses."""
    for _ in range(50):
        probe = socket.socket()
        probe.bind((HOSTS[0], 0))
        port = probe.getsockname()[1]
        probe.close()
        ok = True
        for host in HOSTS:
            s = socket.socket()
            try:
                s.bind((host, port))
            except OSError:
                ok = False
            finally:
                s.close()
        if ok:
            return port
    fail("no port is free on %s" % ", ".join(HOSTS))


class Replica:
    def __init__(self, binary, index, port, root):
        self.binary = binary
        self.name = "r%d" % index
        self.address = "%s:%d" % (HOSTS[index], port)
        self.data_dir = os.path.join(root, self.name)
        self.log_path = os.path.join(root, self.name + ".log")
        os.makedirs(self.data_dir, exist_ok=True)
        self.peers = ",".join("r%d=%s:%d" % (i, h, port) for i, h in enumerate(HOSTS))
        self.process = None

    def start(self):
        log = open(self.log_path, "a")
        self.process = subprocess.Popen(
            [self.binary, "--listen", self.address, "--replica", self.name, "--peers", self.peers,
             "--data_dir", self.data_dir, "--max_sessions", "8", "--sim_threads", "1",
             "--snapshot_every_steps", "2000",
             # The RPC threads at normal priority: ctest runs other tests
             # beside this one, and under SCHED_IDLE (the default) they got
             # no core while those ran (a 2 s load run outlasted 300 s).
             "--stream_idle=false"],
            stdout=subprocess.PIPE, stderr=log, text=True)
        log.close()
        first = first_line(self.process, STARTUP_SECONDS)
        if first != "listening on " + self.address:
            self.process.kill()
            fail("%s's first line: expected 'listening on %s', got %r (log %s)"
                 % (self.name, self.address, first, self.log_path))

    def stop(self, sig=signal.SIGTERM):
        if self.process is None or self.process.poll() is not None:
            return
        self.process.send_signal(sig)
        try:
            self.process.wait(30)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait()
            fail("%s did not exit within 30 s of signal %d" % (self.name, sig))


class Cli:
    def __init__(self, binary):
        self.binary = binary

    def call(self, address, *args, timeout=CALL_SECONDS):
        return subprocess.run([self.binary, "--server", address] + list(args),
                              capture_output=True, text=True, timeout=timeout)

    def json(self, address, *args):
        r = self.call(address, *args)
        expect(r.returncode == 0, "dynsolid-client %s at %s: exit %d: %s"
               % (" ".join(args), address, r.returncode, r.stderr.strip()))
        return json.loads(r.stdout)


def ref(session):
    return ["--id", session["id"], "--token", session["token"]]


def write(path, text):
    with open(path, "w") as f:
        f.write(text)


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--server", required=True)
    parser.add_argument("--client", required=True)
    parser.add_argument("--load", required=True)
    parser.add_argument("--bridge", required=True)
    args = parser.parse_args()
    cli = Cli(args.client)
    root = tempfile.mkdtemp(prefix="dynsolid-replicas-")
    port = free_port()
    replicas = [Replica(args.server, i, port, root) for i in range(3)]
    by_name = {r.name: r for r in replicas}
    try:
        for r in replicas:
            r.start()

        # 1. Placement: six sessions through r0 go round the set.
        sessions = []
        for k in range(6):
            create = ["create", "--scene", "block3", "--levels", "1"]
            if k < 3:
                create.append("--start_paused")  # steps only by command: exact counts
            sessions.append(cli.json(replicas[0].address, *create))
        owners = [s["replica"] for s in sessions]
        expect(owners == ["r0", "r1", "r2", "r0", "r1", "r2"],
               "six sessions created through r0 should go r0, r1, r2, r0, r1, r2; got %r" % owners)
        for s in sessions:
            expect(s["id"].startswith(s["replica"] + "."), "id %s does not name its owner %s"
                   % (s["id"], s["replica"]))
            expect(s["address"] == by_name[s["replica"]].address,
                   "session %s: address %s, owner %s at %s"
                   % (s["id"], s["address"], s["replica"], by_name[s["replica"]].address))
        for r in replicas:
            info = cli.json(r.address, "info")
            expect(info["replica"] == r.name and info["address"] == r.address
                   and info["sessions"] == 2,
                   "%s: info %r (expected 2 sessions)" % (r.name, info))
            listed = cli.json(r.address, "list").get("sessions", [])
            expect(sorted(e["id"] for e in listed)
                   == sorted(s["id"] for s in sessions if s["replica"] == r.name),
                   "%s lists %r" % (r.name, listed))
        print("placement: %s" % ", ".join("%s on %s" % (s["id"], s["replica"]) for s in sessions))

        # 2. Redirects followed by the CLI: every session through every
        #    replica that does not own it.
        for s in sessions:
            for r in replicas:
                if r.name == s["replica"]:
                    continue
                got = cli.json(r.address, "get", *ref(s))
                expect(got["id"] == s["id"] and got["address"] == s["address"],
                       "get %s through %s: %r" % (s["id"], r.name, got))
                cli.json(r.address, "stats", *ref(s))
        s1 = sessions[1]  # on r1, paused
        wrong = cli.call(replicas[0].address, "stats", "--id", s1["id"], "--token", "0" * 32)
        expect(wrong.returncode != 0 and "PERMISSION_DENIED" in wrong.stderr,
               "a wrong token through a non-owner: %r" % wrong.stderr)
        unknown = cli.call(replicas[0].address, "stats", "--id", "r9.0123456789abcdef",
                           "--token", s1["token"])
        expect(unknown.returncode != 0 and "NOT_FOUND" in unknown.stderr
               and '"r9"' in unknown.stderr,
               "an id naming an unknown replica: %r" % unknown.stderr)
        script = os.path.join(root, "push.txt")
        write(script, "force at=1.5,1.5,3 f=2e3,0,0 name=push\nstep 50\nwait\n")
        report_path = os.path.join(root, "push.json")
        run = cli.call(replicas[2].address, "run", "--script", script, "--nowatch", "--noclose",
                       "--json", report_path, *ref(s1))
        expect(run.returncode == 0, "run on %s through r2: exit %d: %s"
               % (s1["id"], run.returncode, run.stderr.strip()))
        with open(report_path) as f:
            report = json.load(f)
        expect(report["commands"]["sent"] == 2 and report["commands"]["answered"] == 2,
               "run through r2: commands %r" % report["commands"])
        before = cli.json(replicas[0].address, "stats", *ref(s1))
        expect(int(before["step"]) == 50, "%s after the script: step %s, expected 50"
               % (s1["id"], before["step"]))
        print("redirects: every session through both other replicas; a script on %s run "
              "through r2" % s1["id"])

        # 2b. The haptic bridge, given r2's address and a session on r0:
        #     the probe stream follows the redirect and contact models come.
        hand = os.path.join(root, "hand.txt")
        write(hand, "0 1.5 1.5 3.05\n0.3 1.5 1.5 3.05\n1.0 1.5 1.5 2.98\n2.0 1.5 1.5 2.98\n")
        metrics_path = os.path.join(root, "bridge.json")
        s0 = sessions[3]
        bridge = subprocess.run(
            [args.bridge, "--server", replicas[2].address, "--id", s0["id"], "--token",
             s0["token"], "--device", "virtual_hand", "--script", hand, "--hand_stiffness", "500",
             "--rt_priority", "0", "--json", metrics_path, "--verbose"],
            capture_output=True, text=True, timeout=CALL_SECONDS)
        expect(bridge.returncode == 0, "dynsolid-haptic-bridge through r2 on %s: exit %d: %s"
               % (s0["id"], bridge.returncode, bridge.stderr.strip()[-2000:]))
        with open(metrics_path) as f:
            metrics = json.load(f)
        expect(metrics["models_received"] > 100,
               "the bridge through r2 on %s received %d contact models in 2 s"
               % (s0["id"], metrics["models_received"]))
        expect("lives on replica r0" in bridge.stderr,
               "the bridge's log does not show the redirect it followed: %r" % bridge.stderr[-500:])
        print("haptic bridge: through r2 to %s, %d contact models"
              % (s0["id"], metrics["models_received"]))

        # 3. The load tester through one replica.
        load_json = os.path.join(root, "load.json")
        load = subprocess.run(
            [args.load, "--server", replicas[1].address, "--clients", "3", "--shared=false",
             "--levels", "1", "--seconds", "2", "--rate", "5", "--json", load_json],
            capture_output=True, text=True, timeout=300)
        expect(load.returncode == 0, "dynsolid-load: exit %d: %s"
               % (load.returncode, load.stderr.strip()[-2000:]))
        with open(load_json) as f:
            lr = json.load(f)
        expect(lr["problems"] == [] and lr["acknowledged"] == lr["sent"] and lr["sent"] > 0,
               "dynsolid-load: sent %s, acknowledged %s, problems %r"
               % (lr["sent"], lr["acknowledged"], lr["problems"]))
        expect(len(lr["sessions_per_replica"]) == 3,
               "dynsolid-load's three sessions through r1 went to %r"
               % lr["sessions_per_replica"])
        print("load tester: sessions %r, %d commands, nothing lost"
              % (lr["sessions_per_replica"], lr["sent"]))

        # 4. SIGKILL r1 while clients work on r0 and r2 (their running
        #    sessions), each through the other live replica.
        watchers = []
        for s, via in ((sessions[3], replicas[2]), (sessions[5], replicas[0])):
            path = os.path.join(root, "watch-%s.txt" % s["replica"])
            write(path, "force at=1.5,1.5,3 f=1e3,0,0 name=f\nsleep 5\nremove f\nsleep 1\n")
            out = os.path.join(root, "watch-%s.json" % s["replica"])
            proc = subprocess.Popen(
                [args.client, "--server", via.address, "run", "--script", path, "--noclose",
                 "--json", out] + ref(s), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                text=True)
            watchers.append((s, proc, out))
        time.sleep(1.5)
        replicas[1].stop(signal.SIGKILL)
        during = cli.json(replicas[0].address, "create", "--scene", "block3", "--levels", "1")
        expect(during["replica"] in ("r0", "r2"),
               "created while r1 is dead: placed on %s" % during["replica"])
        time.sleep(1.0)
        replicas[1].start()
        for s, proc, out in watchers:
            stdout, stderr = proc.communicate(timeout=CALL_SECONDS)
            expect(proc.returncode == 0, "the client of %s: exit %d: %s"
                   % (s["id"], proc.returncode, stderr.strip()))
            with open(out) as f:
                rep = json.load(f)
            expect(rep["commands"]["reconnects"] == 0 and rep["watch"]["reconnects"] == 0,
                   "the client of %s (on %s) noticed r1's death: commands %r, watch %r"
                   % (s["id"], s["replica"], rep["commands"], rep["watch"]))
            expect(rep["watch"]["frames"] >= 60,
                   "the watcher of %s got %d frames in 6 s" % (s["id"], rep["watch"]["frames"]))
        after = cli.json(replicas[2].address, "stats", *ref(s1))
        expect(int(after["step"]) == 50, "%s after r1's restart: step %s, expected 50"
               % (s1["id"], after["step"]))
        loads = cli.json(replicas[0].address, "loads", *ref(s1))
        names = [l.get("kind", "") for l in loads.get("loads", [])]
        expect(len(loads.get("loads", [])) == 1,
               "%s after r1's restart: loads %r (expected the one point force)" % (s1["id"], names))
        for s in sessions:
            if s["replica"] == "r1":
                cli.json(replicas[0].address, "get", *ref(s))
        info = cli.json(replicas[1].address, "info")
        expect(info["sessions"] >= 2, "r1 after restart holds %d sessions" % info["sessions"])
        write(script, "step 10\nwait\n")
        run = cli.call(replicas[0].address, "run", "--script", script, "--nowatch", "--noclose",
                       *ref(s1))
        expect(run.returncode == 0, "run on %s after the restart: %s" % (s1["id"], run.stderr))
        final = cli.json(replicas[1].address, "stats", *ref(s1))
        expect(int(final["step"]) == 60, "%s: step %s, expected 60" % (s1["id"], final["step"]))
        # 5. Draining: SIGTERM on r2 exits 0 within its grace period (5 s)
        #    after a last snapshot of each session; restarted, r2 has every
        #    session, none behind the step it had reached.
        r2_sessions = [x for x in sessions if x["replica"] == "r2"]
        steps_before = {x["id"]: int(cli.json(replicas[2].address, "stats", *ref(x))["step"])
                        for x in r2_sessions}
        t0 = time.monotonic()
        replicas[2].process.send_signal(signal.SIGTERM)
        code = replicas[2].process.wait(30)
        drained = time.monotonic() - t0
        expect(code == 0 and drained < 10,
               "r2 after SIGTERM: exit %s after %.1f s (expected 0 within the 5 s grace)"
               % (code, drained))
        replicas[2].start()
        for x in r2_sessions:
            step = int(cli.json(replicas[0].address, "stats", *ref(x))["step"])
            expect(step >= steps_before[x["id"]],
                   "%s after r2's drain and restart: step %d < %d before"
                   % (x["id"], step, steps_before[x["id"]]))
        print("SIGTERM of r2: drained in %.1f s (exit 0); its %d sessions back, none behind"
              % (drained, len(r2_sessions)))

        print("SIGKILL of r1: its sessions back at their steps with their loads; clients of r0 "
              "and r2 saw no reconnect; a session created meanwhile went to %s"
              % during["replica"])
    finally:
        for r in replicas:
            r.stop()
        if os.environ.get("KEEP_TEST_DIR") is None:
            shutil.rmtree(root, ignore_errors=True)
    print("PASS")


if __name__ == "__main__":
    main()
