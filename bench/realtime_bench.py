"""realtime_bench: does each built-in scene keep up with the clock?

For every built-in scene, with the scene's own model, integrator, time
step and loads:

- offline: `dynsolid-sim --scene S --steps N` (2 threads by default, the
  machine's cores): median ms per step, real-time factor (h / ms per step),
  sub-steps, CG iterations, phase times, and microseconds per element per
  pass ((measure + stiffness) / sub-steps / elements);
- live: a `dynsolid-server` on 127.0.0.1 (its default threads) steps a
  session of the scene in real time for --seconds while one
  `dynsolid-client run` watches it at 60 Hz; from the server's stats at the
  end: steps taken and dropped, the live real-time factor (taken / (taken +
  dropped)), the median step time.

Each figure is also printed as a ratio to block3's in the same run. Prints
a markdown table; asserts nothing.

    /usr/bin/python3 bench/realtime_bench.py [--build build/release]
        [--scenes block3,chair,...] [--steps 60] [--seconds 5]
"""

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "tests", "testing"))
from loopback import fail, first_line  # noqa: E402

SCENES = ["block3", "beam", "chair", "torus", "bridge", "nozzle", "block4", "mixed", "clay"]
# Scenes whose contact (a floor) and plasticity (clay) are measured against
# the same scene without them (the clay and floor budget: at most 25 % of
# the step), and block3 given a floor under it and a clay top.
SHARE_SCENES = ["chair", "clay", "block3+floor+clay"]


def offline(build, scene, steps, out):
    sim = os.path.join(build, "solver", "tools", "dynsolid-sim")
    run = subprocess.run([sim, "--scene", scene, "--steps", str(steps), "--out", out],
                         stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    if run.returncode != 0:
        fail("dynsolid-sim --scene %s: %s" % (scene, run.stdout[-2000:]))
    with open(os.path.join(out, "stats.json")) as f:
        stats = json.load(f)
    dyn = stats["dynamics"]
    phases = stats["phases_ms"]
    elements = sum(stats["elements"][k] for k in ("cubic", "linear", "pyramid"))
    substeps = dyn.get("substeps", 1) or 1
    passes = phases.get("measure", 0) + phases.get("stiffness", 0)
    return {
        "elements": elements,
        "model": "%s, %s" % (dyn.get("model", "?"), dyn.get("integrator", "?")),
        "h_ms": 1e3 * dyn["time_step"],
        "substeps": substeps,
        "cg": stats["cg_iterations"]["mean_per_step"],
        "ms": stats["ms_per_step"],
        "rtf": 1e3 * dyn["time_step"] / stats["ms_per_step"],
        "us_per_element_pass": 1e3 * passes / substeps / elements,
        "phases": phases,
    }


def scene_text(name):
    """A built-in scene's text; `block3+floor+clay` is block3 standing on a
    floor (its pins kept) with its top layer of cells painted clay."""
    base = name.split("+")[0]
    with open(os.path.join(HERE, "..", "scenes", base + ".textproto")) as f:
        text = f.read()
    if name == "block3+floor+clay":
        text = text.replace('name: "block3"', 'name: "block3_floor_clay"')
        base = "  base { young_modulus: 1e5 poisson_ratio: 0.3 density: 1000 damping: 3000 }\n"
        if base not in text:
            fail("scenes/block3.textproto: no %r to add the clay region after" % base)
        text = text.replace(base, base + (
            "  regions { region { box { min { x: -1 y: -1 z: 2 } max { x: 4 y: 4 z: 4 } } }\n"
            "    material { preset: CLAY young_modulus: 1e5 density: 1000 damping: 3000 } }\n"))
        text += "environment { floor { normal { z: 1 } } friction: 0.8 }\n"
    return text


def without_contact_and_clay(text):
    """The same scene with no environment and no material that yields (the
    same moduli: the clay preset's stiffness written out)."""
    out = []
    for line in text.splitlines():
        if line.strip().startswith("environment"):
            continue
        out.append(line.replace("preset: CLAY young_modulus", "young_modulus")
                   .replace("preset: CLAY", "young_modulus: 1e6 poisson_ratio: 0.4"))
    return "\n".join(out) + "\n"


def share(build, name, steps, work):
    """ms per step with and without the floor and the clay, offline."""
    runs = {}
    for label, text in (("with", scene_text(name)), ("without", without_contact_and_clay(scene_text(name)))):
        path = os.path.join(work, "%s-%s.textproto" % (name.replace("+", "_"), label))
        with open(path, "w") as f:
            f.write(text)
        runs[label] = offline(build, path, steps, os.path.join(work, "%s-%s" % (name.replace("+", "_"), label)))
    return runs


def live(build, scene, seconds, work):
    server = os.path.join(build, "server", "dynsolid-server")
    client = os.path.join(build, "clients", "cli", "dynsolid-client")
    log = open(os.path.join(work, "server-%s.log" % scene), "w")
    process = subprocess.Popen([server, "--listen", "127.0.0.1:0", "--max_sessions", "2"],
                               stdout=subprocess.PIPE, stderr=log, text=True)
    try:
        line = first_line(process, 30)
        if not line.startswith("listening on "):
            fail("dynsolid-server's first line: %r" % line)
        address = line[len("listening on "):]
        script = os.path.join(work, "watch.txt")
        with open(script, "w") as f:
            f.write("# watch the session stepping in real time\nsleep %g\n" % seconds)
        report = os.path.join(work, "live-%s.json" % scene)
        run = subprocess.run([client, "--server", address, "run", "--script", script, "--scene",
                              scene, "--json", report], stdout=subprocess.PIPE,
                             stderr=subprocess.STDOUT, text=True, timeout=600)
        if run.returncode != 0:
            fail("dynsolid-client run --scene %s: %s" % (scene, run.stdout[-2000:]))
        with open(report) as f:
            stats = json.load(f)["server_stats"]
    finally:
        process.terminate()
        process.wait(30)
        log.close()
    taken = int(stats["step"])
    dropped = int(stats.get("steps_dropped", 0))
    # A session whose step failed pauses (the stability guard): say so.
    error = stats.get("last_error", "")
    return {
        "taken": taken,
        "dropped": dropped,
        "rtf": taken / max(1, taken + dropped),
        "step_ms": stats.get("step_ms_median", 0.0),
        "note": ("paused at step %d: %s" % (taken, error[:80])) if error else "",
    }


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--build", default=os.path.join(HERE, "..", "build", "release"))
    parser.add_argument("--scenes", default=",".join(SCENES))
    parser.add_argument("--steps", type=int, default=60)
    parser.add_argument("--seconds", type=float, default=5)
    parser.add_argument("--share_steps", type=int, default=300)
    args = parser.parse_args()
    work = tempfile.mkdtemp(prefix="realtime_bench.")
    rows = {}
    shares = {}
    try:
        for scene in args.scenes.split(","):
            print("realtime_bench: %s" % scene, file=sys.stderr)
            rows[scene] = (offline(args.build, scene, args.steps, os.path.join(work, scene)),
                           live(args.build, scene, args.seconds, work))
        for name in SHARE_SCENES:
            print("realtime_bench: contact and clay in %s" % name, file=sys.stderr)
            shares[name] = share(args.build, name, args.share_steps, work)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    base = rows.get("block3")
    cpu = ""
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    print("# Real time per scene (bench/realtime_bench.py)\n")
    print("Machine: %d CPUs (%s). Offline: dynsolid-sim, %d steps; live: a session stepping in "
          "real time for %g s with one watcher at 60 Hz. Ratios are to block3 in this run.\n"
          % (os.cpu_count(), cpu, args.steps, args.seconds))
    print("| scene | elements | model, integrator | h (ms) | sub-steps | CG its / step | ms / step "
          "| real-time factor offline | µs / element / pass (x block3) | live: steps taken "
          "| dropped | real-time factor live | live step ms | live note |")
    print("| --- | ---: | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | --- |")
    for scene, (off, on) in rows.items():
        ratio = ""
        if base is not None:
            ratio = " (%.2f)" % (off["us_per_element_pass"] / base[0]["us_per_element_pass"])
        print("| %s | %d | %s | %g | %d | %.1f | %.2f | %.2f | %.2f%s | %d | %d | %.2f | %.2f | %s |"
              % (scene, off["elements"], off["model"], off["h_ms"], off["substeps"], off["cg"],
                 off["ms"], off["rtf"], off["us_per_element_pass"], ratio, on["taken"],
                 on["dropped"], on["rtf"], on["step_ms"], on["note"]))
    print("\nPhases offline (ms per step):\n")
    names = []
    for off, _ in rows.values():
        for name in off["phases"]:
            if name not in names:
                names.append(name)
    print("| scene | " + " | ".join(names) + " |")
    print("| --- |" + " ---: |" * len(names))
    for scene, (off, _) in rows.items():
        print("| %s | " % scene + " | ".join("%.3f" % off["phases"].get(n, 0) for n in names) + " |")
    print("\nContact (the floor) and plasticity (clay): the step with them against the same "
          "scene without them (the clay's moduli kept), offline, %d steps. The contact's cost "
          "includes the sub-steps its stiffness asks for; plasticity runs inside the stiffness "
          "pass; `loads` holds the contact forces.\n" % args.share_steps)
    print("| scene | ms / step with | sub-steps | loads ms | ms / step without | sub-steps "
          "| share of the step |")
    print("| --- | ---: | ---: | ---: | ---: | ---: | ---: |")
    for name, runs in shares.items():
        w, wo = runs["with"], runs["without"]
        print("| %s | %.3f | %d | %.3f | %.3f | %d | %.0f %% |"
              % (name, w["ms"], w["substeps"], w["phases"].get("loads", 0), wo["ms"],
                 wo["substeps"], 100.0 * (1 - wo["ms"] / w["ms"])))


if __name__ == "__main__":
    main()
