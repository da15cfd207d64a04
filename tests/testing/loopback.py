"""What the loopback tests (Python scripts driving the real binaries) share:
failing with a message, and reading a started process's first line."""

import sys
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
