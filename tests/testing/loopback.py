"""What the loopback tests (Python scripts driving the real binaries) share:
failing with a message, reading a started process's first line, the
binaries' paths from the command line and a temporary directory to run in."""

import argparse
import shutil
import sys
import tempfile
import threading


def fail(message):
    print("FAIL: " + message, file=sys.stderr)
    sys.exit(1)


def expect(condition, message):
    if not condition:
        fail(message)


def expect_equal(what, got, want):
    if got != want:
        fail("%s: expected %r, got %r" % (what, want, got))


def first_line(process, seconds):
    """The first line `process` writes to its stdout pipe, without the
    newline; "" if none comes within `seconds`."""
    line = []
    reader = threading.Thread(target=lambda: line.append(process.stdout.readline()))
    reader.daemon = True
    reader.start()
    reader.join(seconds)
    return line[0].rstrip("\n") if line else ""


def binary_args(*names):
    """The command line's paths of the binaries a test drives: a required
    --NAME PATH for each of `names`."""
    parser = argparse.ArgumentParser()
    for name in names:
        parser.add_argument("--" + name, required=True)
    return parser.parse_args()


def run_in_temp_dir(run, args, prefix, keep=False):
    """run(args, tmp) in a fresh temporary directory named from `prefix`,
    removed afterwards unless `keep`; then prints PASS."""
    tmp = tempfile.mkdtemp(prefix=prefix)
    try:
        run(args, tmp)
    finally:
        if not keep:
            shutil.rmtree(tmp, ignore_errors=True)
    print("PASS")
