"""Power cut: every acknowledged command survives losing what was not fsynced.

kill -9 alone cannot test the journal's fdatasync: the kernel still writes
the dead process's page cache to disk. Here the server's --data_dir is on
powercut_fs (powercut_fs.c beside this file, a FUSE passthrough built with
cc against libfuse3) which, when "the power goes", reverts every file to
what was last fsynced/fdatasynced and drops the rest (metadata operations
count as durable at once; the C file's header says exactly what it models).

1. Controls of the filesystem itself, so nothing below passes vacuously:
   - a file written and closed without fsync is empty after a cut, an
     fsynced file keeps exactly its fsynced bytes (an append and an
     overwrite after the fsync are undone), and the mount showed the newer
     bytes before the cut (a page cache);
   - the torn mode keeps exactly half of an un-fsynced append;
   - without a cut (a plain unmount) un-fsynced data stays: the loss comes
     from the cut, not from the passthrough.
2. The server under power cuts: dynsolid-load (4 clients, a shared session,
   a seeded command mix) against dynsolid-server --data_dir MOUNT/data
   (snapshots every 300 steps, fsyncs made 2 ms slower so un-fsynced data
   is often in flight):
   - cut 1, "instant": SIGSTOP the server (the machine freezes), cut the
     filesystem's power (every un-fsynced write dropped), SIGKILL the
     server;
   - cut 2, "torn": the power goes inside the server's next fdatasync of a
     journal holding data not durable yet, and half of that data survives
     (a torn record); then SIGKILL the server;
   after each: mount again, restart the server on the same port and data
   dir; it must come back (first line "listening on ..."), say what it
   recovered, and after cut 2 drop the torn tail. The load's clients
   reconnect and resend; at the end dynsolid-load checks every client's
   acknowledged commands against the session's GetCommandLog (the journal):
   none lost, duplicated or reordered, statuses equal. The server stops
   with exit 0 on SIGTERM.

Exit 77 (a ctest skip) only when /dev/fuse does not exist; any other
reason FUSE does not work (no libfuse3-dev, a mount refused) fails.

--lying_journal (by hand, not in ctest) makes the filesystem answer the
journal's fdatasyncs without making anything durable: that run must fail
with acknowledged commands lost, which shows the check can fail.

Usage: powercut_test.py --server PATH --load PATH [--cc cc] [--figures FILE]
                        [--keep] [--lying_journal]
"""

import argparse
import json
import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "..", "testing"))
from loopback import expect, expect_equal, fail, first_line  # noqa: E402

SKIP = 77
STARTUP_SECONDS = 60
MOUNT_SECONDS = 10
CUT_SECONDS = 20
LOAD_SECONDS = 18


def log(message):
    print("powercut_test: " + message, flush=True)


# ---- The journal's framing (server/journal.h), read independently -------

def _crc_table():
    table = []
    for i in range(256):
        c = i
        for _ in range(8):
            c = (c >> 1) ^ 0x82F63B78 if c & 1 else c >> 1
        table.append(c)
    return table


CRC_TABLE = _crc_table()


def crc32c(data):
    c = 0xFFFFFFFF
    for b in data:
        c = CRC_TABLE[(c ^ b) & 0xFF] ^ (c >> 8)
    return c ^ 0xFFFFFFFF


def read_journal(path):
    """(whole valid records, byte offset after them, file size)."""
    data = open(path, "rb").read()
    at, records = 0, 0
    while len(data) - at >= 8:
        n = int.from_bytes(data[at:at + 4], "little")
        crc = int.from_bytes(data[at + 4:at + 8], "little")
        if len(data) - at - 8 < n or crc32c(data[at + 8:at + 8 + n]) != crc:
            break
        records += 1
        at += 8 + n
    return records, at, len(data)


def journals(backing):
    found = []
    root = os.path.join(backing, "data", "sessions")
    if os.path.isdir(root):
        for sid in sorted(os.listdir(root)):
            path = os.path.join(root, sid, "journal")
            if os.path.isfile(path):
                found.append(path)
    return found


def journal_bytes(backing):
    return sum(os.path.getsize(p) for p in journals(backing))


# ---- The filesystem ------------------------------------------------------

def is_mounted(path):
    path = os.path.realpath(path)
    with open("/proc/self/mounts") as f:
        return any(line.split()[1] == path for line in f)


class PowercutFs:
    """One mount of powercut_fs: BACKING mirrored at MOUNT."""

    def __init__(self, binary, backing, mount, extra=()):
        self.mount = mount
        self.err_path = os.path.join(os.path.dirname(mount), "powercut_fs.log")
        self.err = open(self.err_path, "a")
        self.err_start = self.err.tell()
        self.process = subprocess.Popen([binary] + list(extra) + [backing, mount],
                                        stdout=subprocess.PIPE, stderr=self.err, text=True)
        self.lines = []
        self.reader = threading.Thread(target=self._read, daemon=True)
        self.reader.start()
        deadline = time.time() + MOUNT_SECONDS
        while not is_mounted(mount):
            if self.process.poll() is not None or time.time() > deadline:
                self.process.kill()
                self.process.wait()
                self.err.close()
                fail("powercut_fs did not mount %s (exit %s): %s" %
                     (mount, self.process.returncode, open(self.err_path).read()[-2000:]))
            time.sleep(0.02)

    def _read(self):
        for line in self.process.stdout:
            self.lines.append(line.rstrip("\n"))

    def report(self, timeout):
        """Its "powercut: ..." line as a dict, None if none within timeout."""
        deadline = time.time() + timeout
        while time.time() < deadline:
            for line in self.lines:
                if line.startswith("powercut: "):
                    return dict(kv.split("=", 1) for kv in line.split()[1:] if "=" in kv)
            time.sleep(0.01)
        return None

    def reverted(self):
        """Its stderr lines about the files a cut reverted."""
        with open(self.err_path) as f:
            f.seek(self.err_start)
            return [line.rstrip("\n") for line in f if " bytes -> " in line]

    def cut(self, sig):
        self.process.send_signal(sig)

    def wait(self, timeout=CUT_SECONDS):
        try:
            code = self.process.wait(timeout)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait()
            fail("powercut_fs did not exit within %d s" % timeout)
        self.reader.join(5)
        self.err.close()
        if is_mounted(self.mount):
            subprocess.run(["umount", "-l", self.mount], check=False)
        return code

    def unmount(self):
        """A normal end, no cut."""
        self.process.send_signal(signal.SIGTERM)
        return self.wait()

    def kill(self):
        if self.process.poll() is None:
            self.process.kill()
            self.process.wait()
        if is_mounted(self.mount):
            subprocess.run(["umount", "-l", self.mount], check=False)


def build_fs(cc, out_dir):
    pc = subprocess.run(["pkg-config", "--cflags", "--libs", "fuse3"], capture_output=True,
                        text=True)
    if pc.returncode != 0:
        fail("pkg-config fuse3 failed (install libfuse3-dev fuse3: scripts/setup.sh): " +
             pc.stderr.strip())
    binary = os.path.join(out_dir, "powercut_fs")
    build = subprocess.run([cc, "-std=c11", "-Wall", "-Wextra", "-Werror", "-O2", "-o", binary,
                            os.path.join(HERE, "powercut_fs.c")] + pc.stdout.split(),
                           capture_output=True, text=True)
    if build.returncode != 0:
        fail("cannot build powercut_fs.c:\n" + build.stdout + build.stderr)
    return binary


# ---- 1. Controls ---------------------------------------------------------

def write_file(path, data, fsync):
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
    os.write(fd, data)
    if fsync:
        os.fsync(fd)
    os.close(fd)


def controls(fs_binary, work, figures):
    backing, mount = os.path.join(work, "control_backing"), os.path.join(work, "control_mnt")
    os.makedirs(backing)
    os.makedirs(mount)
    rnd = os.urandom(256 * 1024)
    synced, appended, patch = rnd[:64 * 1024], os.urandom(16 * 1024), b"P" * 100

    # Drop mode.
    fs = PowercutFs(fs_binary, backing, mount)
    write_file(os.path.join(mount, "unsynced"), rnd, fsync=False)
    write_file(os.path.join(mount, "synced"), synced, fsync=True)
    fd = os.open(os.path.join(mount, "synced"), os.O_RDWR)
    os.pwrite(fd, appended, len(synced))
    os.pwrite(fd, patch, 1000)
    os.close(fd)
    newest = bytearray(synced + appended)
    newest[1000:1100] = patch
    expect_equal("control: the mount's view of 'synced' before the cut",
                 open(os.path.join(mount, "synced"), "rb").read() == bytes(newest), True)
    expect_equal("control: the mount's view of 'unsynced' before the cut",
                 open(os.path.join(mount, "unsynced"), "rb").read() == rnd, True)
    fs.cut(signal.SIGUSR1)
    report = fs.report(CUT_SECONDS)
    expect(report is not None, "control: powercut_fs printed no report after SIGUSR1")
    expect_equal("control: powercut_fs exit code after a cut", fs.wait(), 0)
    log("control cut: %s" % report)
    expect_equal("control: size_bytes_dropped", int(report["size_bytes_dropped"]),
                 len(rnd) + len(appended))
    expect_equal("control: restored_bytes", int(report["restored_bytes"]), len(patch))
    fs = PowercutFs(fs_binary, backing, mount)
    got_unsynced = open(os.path.join(mount, "unsynced"), "rb").read()
    got_synced = open(os.path.join(mount, "synced"), "rb").read()
    expect_equal("control: bytes of 'unsynced' (256 KiB written, never fsynced) after the cut",
                 len(got_unsynced), 0)
    expect_equal("control: 'synced' after the cut is exactly its fsynced 64 KiB",
                 got_synced == synced, True)
    figures["control_unsynced_written"] = len(rnd)
    figures["control_unsynced_after"] = len(got_unsynced)
    figures["control_dropped_bytes"] = int(report["size_bytes_dropped"])
    figures["control_restored_bytes"] = int(report["restored_bytes"])

    # Torn mode: half of an un-fsynced append survives.
    head, tail = os.urandom(1000), os.urandom(1000)
    write_file(os.path.join(mount, "torn"), head, fsync=True)
    fd = os.open(os.path.join(mount, "torn"), os.O_WRONLY | os.O_APPEND)
    os.write(fd, tail)
    os.close(fd)
    fs.cut(signal.SIGUSR2)
    report = fs.report(CUT_SECONDS)
    expect(report is not None, "control: powercut_fs printed no report after SIGUSR2")
    fs.wait()
    log("control torn cut: %s" % report)
    expect_equal("control: torn file after the torn cut",
                 open(os.path.join(backing, "torn"), "rb").read() == head + tail[:500], True)

    # No cut: a plain unmount keeps un-fsynced data.
    fs = PowercutFs(fs_binary, backing, mount)
    write_file(os.path.join(mount, "kept"), rnd, fsync=False)
    fs.unmount()
    expect_equal("control: un-fsynced file after an unmount without a cut",
                 open(os.path.join(backing, "kept"), "rb").read() == rnd, True)
    log("controls passed: un-fsynced data is dropped by a cut and only by a cut")


# ---- 2. The server -------------------------------------------------------

class Server:
    def __init__(self, binary, data_dir, log_path, listen):
        self.log_path = log_path
        self.log = open(log_path, "a")
        self.log.write("==== start %s\n" % time.strftime("%H:%M:%S"))
        self.log.flush()
        self.process = subprocess.Popen(
            [binary, "--listen", listen, "--data_dir", data_dir, "--snapshot_every_steps", "300"],
            stdout=subprocess.PIPE, stderr=self.log, text=True)
        first = first_line(self.process, STARTUP_SECONDS)
        match = re.fullmatch(r"listening on (127\.0\.0\.1:(\d+))", first)
        if not match:
            self.process.kill()
            self.process.wait()
            fail("server's first line: expected 'listening on 127.0.0.1:PORT', got %r "
                 "(exit %s; log %s):\n%s" % (first, self.process.poll(), log_path,
                                              open(log_path).read()[-3000:]))
        self.address = match.group(1)

    def log_since_start(self):
        text = open(self.log_path).read()
        return text[text.rfind("==== start"):]

    def kill(self):
        if self.process.poll() is None:
            self.process.kill()
        self.process.wait()
        self.log.close()


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def wait_for(what, predicate, timeout):
    deadline = time.time() + timeout
    while not predicate():
        if time.time() > deadline:
            fail("timed out after %d s waiting for %s" % (timeout, what))
        time.sleep(0.05)


def describe_journals(backing):
    out = []
    for path in journals(backing):
        records, valid_end, size = read_journal(path)
        out.append({"records": records, "valid_end": valid_end, "bytes": size})
    return out


def server_under_cuts(args, fs_binary, work, figures):
    backing, mount = os.path.join(work, "backing"), os.path.join(work, "mnt")
    os.makedirs(backing)
    os.makedirs(mount)
    data_dir = os.path.join(mount, "data")
    server_log = os.path.join(work, "server.log")
    fs_flags = ["--fsync_delay_ms", "2"]
    if args.lying_journal:
        fs_flags += ["--lying_fsync_of", "journal"]
    started = []  # everything to clean up

    try:
        fs = PowercutFs(fs_binary, backing, mount, fs_flags)
        started.append(fs)
        server = Server(args.server, data_dir, server_log, "127.0.0.1:%d" % free_port())
        started.append(server)
        address = server.address
        log("server on %s, data dir %s (backing %s)" % (address, data_dir, backing))
        load_json = os.path.join(work, "load.json")
        load_log = open(os.path.join(work, "load.log"), "w")
        load = subprocess.Popen(
            [args.load, "--server", address, "--clients", "4", "--rate", "25", "--seconds",
             str(LOAD_SECONDS), "--seed", "3", "--watch_hz", "10", "--json", load_json],
            stdout=load_log, stderr=subprocess.STDOUT)
        started.append(load)

        # Cut 1: instant, drop everything not durable.
        # (A wait, not a figure: a CI run on a loaded machine, load 6 on two
        # cores, took more than 30 s to create the load's sessions.)
        wait_for("the load's commands in the journal", lambda: journal_bytes(backing) > 0, 180)
        time.sleep(2.5)
        server.process.send_signal(signal.SIGSTOP)
        fs.cut(signal.SIGUSR1)
        report1 = fs.report(CUT_SECONDS)
        server.kill()
        expect(report1 is not None, "cut 1: powercut_fs printed no report")
        expect_equal("cut 1: powercut_fs exit code", fs.wait(), 0)
        after1 = describe_journals(backing)
        log("cut 1 (instant, drop): %s; journals after: %s" % (report1, after1))
        reverted1 = fs.reverted()
        for line in reverted1:
            log("  " + line)
        expect(after1, "cut 1: no journal survived at all")

        fs = PowercutFs(fs_binary, backing, mount, fs_flags + ["--cut_in_fsync_of", "journal"])
        started.append(fs)
        server = Server(args.server, data_dir, server_log, address)
        started.append(server)
        recovered1 = re.findall(r"recovered: (.*)", server.log_since_start())
        log("restart 1: %s" % recovered1)
        expect(recovered1, "restart 1: the server recovered no session")

        # Cut 2: inside the next fdatasync of a journal with data not yet
        # durable; half of that data survives (a torn record).
        size_before = journal_bytes(backing)
        wait_for("more commands after restart 1",
                 lambda: journal_bytes(backing) > size_before + 2000, 30)
        fs.cut(signal.SIGUSR2)
        report2 = fs.report(CUT_SECONDS)
        # The server's journal thread is blocked in the cut fdatasync: kill
        # it, then end the filesystem (which fails that fdatasync to a
        # process that is gone), then reap the server.
        server.process.kill()
        fs_code = fs.unmount()
        server.kill()
        expect(report2 is not None,
               "cut 2: no fdatasync of a journal with un-fsynced data came within %d s" %
               CUT_SECONDS)
        expect_equal("cut 2: powercut_fs exit code", fs_code, 0)
        after2 = describe_journals(backing)
        log("cut 2 (in fdatasync, torn): %s; journals after: %s" % (report2, after2))
        reverted2 = fs.reverted()
        for line in reverted2:
            log("  " + line)
        expect(int(report2["kept_torn_bytes"]) > 0 and int(report2["size_bytes_dropped"]) > 0,
               "cut 2: expected a torn tail (bytes kept and dropped), got %s" % report2)
        expect(any(j["valid_end"] < j["bytes"] for j in after2),
               "cut 2: no journal has a torn tail after the torn cut: %s" % after2)

        fs = PowercutFs(fs_binary, backing, mount, fs_flags)
        started.append(fs)
        server = Server(args.server, data_dir, server_log, address)
        started.append(server)
        recovered2 = re.findall(r"recovered: (.*)", server.log_since_start())
        log("restart 2: %s" % recovered2)
        expect(any("unacknowledged tail" in r for r in recovered2),
               "restart 2: the server did not report dropping the torn tail: %s" % recovered2)

        # The load ends by checking every acknowledged command against the
        # restarted session's GetCommandLog.
        try:
            load_code = load.wait(LOAD_SECONDS + 90)
        except subprocess.TimeoutExpired:
            fail("dynsolid-load did not finish (log %s)" % load_log.name)
        load_log.close()
        load_text = open(load_log.name).read()
        if not os.path.exists(load_json):
            fail("dynsolid-load wrote no report (exit %d):\n%s" % (load_code, load_text[-3000:]))
        rep = json.load(open(load_json))
        log("load: sent %d, acknowledged %d (applied %d, refused %d), resends %d, "
            "reconnects %d, verified %s, problems %s" %
            (rep["sent"], rep["acknowledged"], rep["applied"], rep["rejected"], rep["resends"],
             rep["reconnects"], rep["verified"], rep["problems"][:10]))
        expect(rep["verified"], "dynsolid-load did not check the journal")
        expect(not rep["problems"], "acknowledged commands lost or wrong after the power cuts: %s"
               % rep["problems"][:20])
        expect_equal("dynsolid-load exit code", load_code, 0)
        expect(rep["acknowledged"] >= 100, "too few commands acknowledged (%d) to mean anything"
               % rep["acknowledged"])
        expect(rep["reconnects"] > 0, "the clients never reconnected: did the cuts happen?")
        expect(server.process.poll() is None,
               "the restarted server died (exit %s)" % server.process.poll())
        server.process.send_signal(signal.SIGTERM)
        code = server.process.wait(30)
        server.log.close()
        expect_equal("the restarted server's exit code after SIGTERM", code, 0)
        fs.unmount()

        figures.update({
            "cut1": report1, "reverted1": reverted1, "journals_after_cut1": after1,
            "recovered1": recovered1,
            "cut2": report2, "reverted2": reverted2, "journals_after_cut2": after2,
            "recovered2": recovered2,
            "load": {k: rep[k] for k in ("sent", "acknowledged", "applied", "rejected",
                                         "resends", "reconnects", "verified", "problems")},
        })
    finally:
        for thing in reversed(started):
            if isinstance(thing, PowercutFs):
                thing.kill()
            elif isinstance(thing, Server):
                if thing.process.poll() is None:
                    thing.process.kill()
                    thing.process.wait()
            elif thing.poll() is None:
                thing.kill()
                thing.wait()


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--server", required=True)
    parser.add_argument("--load", required=True)
    parser.add_argument("--cc", default="cc")
    parser.add_argument("--figures", help="write the measured figures here (JSON)")
    parser.add_argument("--keep", action="store_true", help="keep the work directory")
    parser.add_argument("--lying_journal", action="store_true",
                        help="a mutation check, by hand: the journal's fdatasyncs succeed "
                             "without making anything durable; the run must FAIL")
    args = parser.parse_args()

    if not os.path.exists("/dev/fuse"):
        print("SKIP: /dev/fuse does not exist here: FUSE cannot be mounted, so the power cut "
              "cannot be simulated", flush=True)
        sys.exit(SKIP)
    expect(os.geteuid() == 0 or shutil.which("fusermount3"),
           "not root and no fusermount3 (install fuse3: scripts/setup.sh)")
    work = tempfile.mkdtemp(prefix="dynsolid_powercut_")
    figures = {}
    try:
        fs_binary = build_fs(args.cc, work)
        controls(fs_binary, work, figures)
        server_under_cuts(args, fs_binary, work, figures)
    finally:
        for sub in ("control_mnt", "mnt"):
            mount = os.path.join(work, sub)
            if is_mounted(mount):
                subprocess.run(["umount", "-l", mount], check=False)
        if args.figures:
            with open(args.figures, "w") as f:
                json.dump(figures, f, indent=1)
        if args.keep:
            log("work directory kept: " + work)
        else:
            shutil.rmtree(work, ignore_errors=True)
    print("PASS: every acknowledged command survived two power cuts", flush=True)


if __name__ == "__main__":
    main()
