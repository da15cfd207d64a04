"""dynsolid-server and dynsolid-client over loopback, as a user runs them.

Starts the real server on 127.0.0.1:0, reads the bound port from the first
line of its stdout, drives dynsolid-client (create, get, list, close and a
denied get), then stops the server with SIGTERM and checks that it exits 0.

Usage: cli_loopback_test.py --server PATH --client PATH
"""

import json
import os
import re
import signal
import subprocess
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "testing"))
from loopback import binary_args, expect_equal, fail, first_line  # noqa: E402

STARTUP_SECONDS = 30
CALL_SECONDS = 60
SHUTDOWN_SECONDS = 20


def read_first_line(process, timeout):
    line = first_line(process, timeout)
    if not line:
        fail("the server printed no line within %d s" % timeout)
    return line


def client(args, server, *command):
    return subprocess.run([args.client, "--server", server] + list(command),
                          capture_output=True, text=True, timeout=CALL_SECONDS)


def client_json(args, server, *command):
    result = client(args, server, *command)
    if result.returncode != 0:
        fail("dynsolid-client %s exited %d: %s" % (" ".join(command), result.returncode,
                                                   result.stderr.strip()))
    try:
        return json.loads(result.stdout)
    except ValueError as e:
        fail("dynsolid-client %s printed no JSON (%s): %r" % (" ".join(command), e, result.stdout))


def main():
    args = binary_args("server", "client")

    server = subprocess.Popen([args.server, "--listen", "127.0.0.1:0", "--max_sessions", "4"],
                              stdout=subprocess.PIPE, text=True)
    try:
        first = read_first_line(server, STARTUP_SECONDS)
        match = re.fullmatch(r"listening on 127\.0\.0\.1:(\d+)", first)
        if not match or int(match.group(1)) == 0:
            fail("first line of the server's stdout: expected 'listening on 127.0.0.1:PORT', "
                 "got %r" % first)
        address = "127.0.0.1:" + match.group(1)

        session = client_json(args, address, "create", "--scene", "block3", "--levels", "2")
        if not re.fullmatch(r"[0-9a-f]{32}", session.get("token", "")):
            fail("create: token is not 32 hex digits: %r" % session.get("token"))
        stats = session["stats"]
        expect_equal("create block3 --levels 2: stats.cells", stats["cells"], 1728)
        expect_equal("create block3 --levels 2: stats.nodes", stats["nodes"], 2197)
        expect_equal("create block3 --levels 2: stats.cubic_elements",
                     stats["cubic_elements"], 1000)
        expect_equal("create: scene_name", session["scene_name"], "block3")

        got = client_json(args, address, "get", "--id", session["id"],
                          "--token", session["token"])
        expect_equal("get: stats", got["stats"]["cells"], 1728)

        denied = client(args, address, "get", "--id", session["id"], "--token", "0" * 32)
        expect_equal("get with a wrong token: exit code", denied.returncode, 2)
        if "PERMISSION_DENIED" not in denied.stderr:
            fail("get with a wrong token: stderr lacks PERMISSION_DENIED: %r" % denied.stderr)

        bad = client(args, address, "create", "--scene", "no_such_scene")
        expect_equal("create of an unknown scene: exit code", bad.returncode, 2)

        listed = client_json(args, address, "list")
        expect_equal("list: ids", [s["id"] for s in listed["sessions"]], [session["id"]])
        if "token" in json.dumps(listed):
            fail("list shows a token: %r" % listed)

        client_json(args, address, "close", "--id", session["id"], "--token", session["token"])
        expect_equal("list after close", client_json(args, address, "list")["sessions"], [])

        server.send_signal(signal.SIGTERM)
        try:
            code = server.wait(SHUTDOWN_SECONDS)
        except subprocess.TimeoutExpired:
            fail("the server did not exit within %d s of SIGTERM" % SHUTDOWN_SECONDS)
        expect_equal("server exit code after SIGTERM", code, 0)
    finally:
        if server.poll() is None:
            server.kill()
            server.wait()
    print("PASS")


if __name__ == "__main__":
    main()
