#!/usr/bin/python3
"""--help and address checks of the five binaries (bench/reports/reliability.md,
sections 1 and 2).

  cmdline_test.py server=PATH client=PATH sim=PATH haptic=PATH load=PATH

1. `BINARY --help` exits 0 and lists the binary's own flags, each with its
   default (several known flags and defaults are checked per binary).
2. A listen or server address with a port outside 1-65535 (0 is allowed for
   listeners: "pick a free port") or a malformed HOST:PORT is refused at
   once: non-zero exit and a message naming the flag and the value.

Every run has a timeout: a binary that accepted a bad address and went on
serving or connecting fails the test instead of hanging it.
"""
import subprocess
import sys

BINARIES = dict(arg.split("=", 1) for arg in sys.argv[1:])
FAILURES = []


def run(name, args, timeout=30):
    try:
        p = subprocess.run([BINARIES[name]] + args, capture_output=True, text=True,
                           timeout=timeout, stdin=subprocess.DEVNULL)
        return p.returncode, p.stdout, p.stderr
    except subprocess.TimeoutExpired:  # the process is killed
        return None, "", "timed out"


def check(ok, what):
    print(("ok   " if ok else "FAIL ") + what)
    if not ok:
        FAILURES.append(what)


# Flags and the default each must show under --help.
HELP = {
    "server": [("--listen", '"127.0.0.1:50051"'), ("--max_sessions", "16"),
               ("--max_cells", "1000000"), ("--data_dir", '""'), ("--watch_hz", "60"),
               ("--stream_idle", "true"), ("--shutdown_grace_seconds", "5")],
    "client": [("--server", '"127.0.0.1:50051"'), ("--timeout_seconds", "120"),
               ("--levels", "-1"), ("--watch", "true"), ("--format", '"obj"')],
    "sim": [("--scene", '"block3"'), ("--levels", "-1"), ("--steps", "0"), ("--out", '""')],
    "haptic": [("--server", '"127.0.0.1:50051"'), ("--period_ms", "1"),
               ("--max_force", "40"), ("--device", '"virtual_hand"'), ("--rt_priority", "80")],
    "load": [("--clients", "8"), ("--seconds", "5"), ("--rate", "10"), ("--scene", '"block3"'),
             ("--shared", "true")],
}

for name, flags in HELP.items():
    rc, out, err = run(name, ["--help"])
    check(rc == 0, f"{name} --help exits 0 (got {rc}; stderr {err.strip()[:200]!r})")
    check("No flags matched" not in out + err, f"{name} --help lists flags")
    for flag, default in flags:
        lines = [line for line in out.splitlines() if line.strip().startswith(flag + " ")]
        check(len(lines) == 1 and f"(default: {default}" in lines[0],
              f"{name} --help: {flag} with default {default} (got {lines})")
    # Each listed flag is followed by its help text (a non-empty line).
    out_lines = out.splitlines()
    flag_lines = [i for i, line in enumerate(out_lines) if line.startswith("  --")]
    check(len(flag_lines) >= len(flags) and
          all(i + 1 < len(out_lines) and out_lines[i + 1].strip() for i in flag_lines),
          f"{name} --help: every flag has a help line")

# Bad addresses: (binary, args, flag named, value named).
BAD = [
    ("server", ["--listen", "127.0.0.1:99999"], "--listen", "127.0.0.1:99999"),
    ("server", ["--listen", "127.0.0.1:-1"], "--listen", "127.0.0.1:-1"),
    ("server", ["--listen", "127.0.0.1"], "--listen", "127.0.0.1"),
    ("server", ["--listen", "127.0.0.1:50x"], "--listen", "127.0.0.1:50x"),
    ("server", ["--listen", ":50051"], "--listen", ":50051"),
    ("server", ["--listen", "127.0.0.1:0", "--health_listen", "127.0.0.1:65536"],
     "--health_listen", "127.0.0.1:65536"),
    ("server", ["--listen", "127.0.0.1:0", "--advertise", "127.0.0.1:0"],
     "--advertise", "127.0.0.1:0"),
    ("client", ["--server", "127.0.0.1:99999", "--timeout_seconds", "3", "list"],
     "--server", "127.0.0.1:99999"),
    ("client", ["--server", "127.0.0.1:0", "--timeout_seconds", "3", "list"],
     "--server", "127.0.0.1:0"),
    ("client", ["--server", "localhost", "--timeout_seconds", "3", "list"],
     "--server", "localhost"),
    ("haptic", ["--server", "127.0.0.1:70000", "--scene", "block3", "--seconds", "1",
                "--rt_priority", "0"], "--server", "127.0.0.1:70000"),
    ("load", ["--server", "127.0.0.1:123456", "--seconds", "1", "--clients", "1"],
     "--server", "127.0.0.1:123456"),
]
for name, args, flag, value in BAD:
    rc, out, err = run(name, args)
    check(rc is not None and rc != 0, f"{name} {' '.join(args)}: exits non-zero (got {rc})")
    check(flag in err and value in err,
          f"{name} {' '.join(args)}: message names {flag} and {value} (stderr {err.strip()[:300]!r})")

# A good listen address with port 0 still starts (and is stopped here).
server = subprocess.Popen([BINARIES["server"], "--listen", "127.0.0.1:0"], stdout=subprocess.PIPE,
                          stderr=subprocess.DEVNULL, text=True)
first = server.stdout.readline()
server.terminate()
server.wait(timeout=30)
check(first.startswith("listening on 127.0.0.1:"), f"server --listen 127.0.0.1:0 serves ({first!r})")

if FAILURES:
    print(f"{len(FAILURES)} failures")
    sys.exit(1)
print("all passed")
