#!/usr/bin/python3
"""A session too big for the machine is refused before it is built.

  memory_budget_test.py --server PATH --client PATH

The real dynsolid-server (default limits: --max_cells 1000000 and
--max_session_bytes a quarter of physical memory) is asked for a
100 x 100 x 100 block at level 0: exactly --max_cells, which used to pass
8 GiB while building. It must be refused with RESOURCE_EXHAUSTED naming the
memory estimate and the limit, and the server's peak RSS (VmHWM in
/proc/PID/status) must grow by less than 50 MB. A small scene is still
accepted. Then a server allowed 1 % of each estimate (--build_memory_factor
0.01) must stop block3's level-3 build between its phases and refuse it,
leaving no session. Every client call has a timeout: a server that starts building
fails the test instead of filling the machine (it is killed).
"""
import os
import re
import subprocess
import sys
import tempfile

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "testing"))
from loopback import binary_args, fail, first_line  # noqa: E402

HUGE = """
name: "huge"
mesh { block { nx: 100 ny: 100 nz: 100 } }
subdivision { levels: 0 }
"""


def vm_hwm_bytes(pid):
    with open("/proc/%d/status" % pid) as f:
        for line in f:
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) * 1024
    fail("no VmHWM in /proc/%d/status" % pid)


def start_server(args, *flags):
    """A dynsolid-server on a free loopback port, and a function that runs
    dynsolid-client against it (every call with a timeout: a server that
    starts building fails the test instead of filling the machine)."""
    server = subprocess.Popen([args.server, "--listen", "127.0.0.1:0"] + list(flags),
                              stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    first = first_line(server, 60)
    match = re.fullmatch(r"listening on (127\.0\.0\.1:\d+)", first or "")
    if not match:
        server.kill()
        fail("the server (%s) did not start: %r" % (" ".join(flags) or "default flags", first))
    address = match.group(1)

    def client(*command):
        try:
            return subprocess.run([args.client, "--server", address, "--timeout_seconds", "60"]
                                  + list(command), capture_output=True, text=True, timeout=90)
        except subprocess.TimeoutExpired:
            fail("dynsolid-client %s did not return within 90 s (the server is building?)"
                 % " ".join(command))

    return server, client


def main():
    args = binary_args("server", "client")
    server, client = start_server(args)
    try:
        # Warm the server's gRPC paths first, so that the measured growth is
        # the refused request's own.
        small = client("create", "--scene", "block3", "--levels", "1")
        if small.returncode != 0:
            fail("block3 at level 1 was refused: %s" % small.stderr.strip())
        with tempfile.TemporaryDirectory() as tmp:
            scene = os.path.join(tmp, "huge.textproto")
            with open(scene, "w") as f:
                f.write(HUGE)
            before = vm_hwm_bytes(server.pid)
            huge = client("create", "--scene_file", scene)
            after = vm_hwm_bytes(server.pid)
        growth = after - before
        print("refused: exit %d: %s" % (huge.returncode, huge.stderr.strip()))
        print("server VmHWM %.1f MB -> %.1f MB (+%.2f MB)" % (before / 1e6, after / 1e6, growth / 1e6))
        if huge.returncode == 0:
            fail("the 100^3 block was accepted")
        for want in ("RESOURCE_EXHAUSTED", "1000000 cells", "MiB of memory",
                     "--max_session_bytes"):
            if want not in huge.stderr:
                fail("the refusal does not say %r: %s" % (want, huge.stderr.strip()))
        if re.search(r"about \d+ MiB of memory", huge.stderr) is None or \
                re.search(r"limit of \d+ MiB", huge.stderr) is None:
            fail("the refusal names no estimate or no limit: %s" % huge.stderr.strip())
        if growth >= 50e6:
            fail("the server's peak RSS grew by %.1f MB refusing it (at most 50 MB)" % (growth / 1e6))
        # Still serving.
        again = client("create", "--scene", "block3", "--levels", "1")
        if again.returncode != 0:
            fail("block3 refused after the huge request: %s" % again.stderr.strip())
    finally:
        server.kill()
        server.wait()
    stopped_build(args)
    print("PASS")


def stopped_build(args):
    """A build that grows past its estimate is stopped between its phases.

    The estimate errs high, so a real scene never passes it at the default
    --build_memory_factor of 1.5; a server told to allow 1 % of the estimate
    stands in for a scene the estimate gets badly wrong: block3 at level 3
    (13824 cells, estimated 124 MiB, measured about 90 MB) must be stopped,
    refused with RESOURCE_EXHAUSTED naming the phase, and leave no session."""
    server, client = start_server(args, "--build_memory_factor", "0.01")
    try:
        big = client("create", "--scene", "block3", "--levels", "3")
        print("stopped: exit %d: %s" % (big.returncode, big.stderr.strip()))
        if big.returncode == 0:
            fail("block3 at level 3 was built within 1 %% of its estimate: %s" % big.stdout)
        for want in ("RESOURCE_EXHAUSTED", "the build was stopped after its", "phase",
                     "--build_memory_factor", "nothing of it was kept"):
            if want not in big.stderr:
                fail("the stopped build's refusal does not say %r: %s" % (want, big.stderr.strip()))
        listed = client("list")
        if listed.returncode != 0:
            fail("list failed after the stopped build: %s" % listed.stderr.strip())
        if "block3" in listed.stdout:
            fail("the stopped build left a session: %s" % listed.stdout.strip())
        if server.poll() is not None:
            fail("the server exited")
    finally:
        server.kill()
        server.wait()


if __name__ == "__main__":
    main()
