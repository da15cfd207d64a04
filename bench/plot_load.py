#!/usr/bin/python3
"""The load report's table and plots from dynsolid-load's JSON files.

    plot_load.py DIR SCENE [SCENE ...]

Reads DIR/<scene>_<clients>.json, writes DIR/README.md (the table, with
the machine it ran on) and DIR/load.png: latency against clients, the
step rate loaded against unloaded, and the server's CPU and memory over
the largest run of each scene.
"""
import glob
import json
import os
import platform
import re
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def load(directory, scene):
    runs = []
    for path in glob.glob(os.path.join(directory, "%s_*.json" % scene)):
        m = re.search(r"_(\d+)\.json$", path)
        if not m:
            continue
        with open(path) as f:
            runs.append(json.load(f))
    return sorted(runs, key=lambda r: r["clients"])


def cpu_model():
    try:
        with open("/proc/cpuinfo") as f:
            text = f.read()
        name = re.search(r"model name\s*:\s*(.*)", text).group(1)
        flags = re.search(r"flags\s*:\s*(.*)", text).group(1).split()
        return "%s, %d cores, %s" % (name, os.cpu_count(),
                                     "AVX-512" if "avx512f" in flags else "AVX2 only")
    except (OSError, AttributeError):
        return platform.processor()


def main():
    directory, scenes = sys.argv[1], sys.argv[2:]
    data = {s: load(directory, s) for s in scenes}
    lines = ["# Load: scripted clients against one dynsolid-server", "",
             "Made by `bash bench/load_report.sh` (dynsolid-load, docs/load.md): each client on "
             "its own channel, one shared session, 10 commands/s each, a watcher each at 30 "
             "frames/s, no faults; the server started by the tool with its own `--data_dir`, "
             "every acknowledged command checked against the journal. Machine: %s. The clients "
             "run on the same machine as the server." % cpu_model(), ""]
    header = None
    for s in scenes:
        for r in data[s]:
            with open(os.path.join(directory, "%s_%d.md" % (s, r["clients"]))) as f:
                rows = f.read().strip().split("\n")
            if header is None:
                header = rows[:2]
                lines += header
            lines += rows[2:]
    lines += ["", "![latency, step rate, CPU and memory](load.png)", "",
              "What ran out, and why: [ANALYSIS.md](ANALYSIS.md) (written by hand after the run).", "",
              "## Where the stepping thread went", "",
              "Each command holds the session's loop while it applies (`CommandReply.hold_ms`); "
              "summed over a run and divided by its length, that is the share of the simulation "
              "thread's time that commands took from steps. The server process's CPU is the "
              "`server CPU %` column (100 % = one core: the stepping thread's core; the "
              "streaming and gRPC threads run at lowered priority on the other, shared with "
              "the clients).", "",
              "| scene | clients | commands held the loop (ms per s) | the most holding kinds (total ms, count, max ms) |",
              "| --- | ---: | ---: | --- |"]
    for s in scenes:
        for r in data[s]:
            hold = r.get("hold", {})
            total = sum(h["total_ms"] for h in hold.values())
            top = sorted(hold.items(), key=lambda kv: -kv[1]["total_ms"])[:3]
            lines.append("| %s | %d | %.0f | %s |" % (
                s, r["clients"], total / max(r["seconds"], 1e-9),
                ", ".join("%s %.0f ms (%d, max %.0f)" % (k, h["total_ms"], h["count"], h["max_ms"])
                          for k, h in top)))
    kinds = sorted({k for s in scenes for r in data[s] for k in r.get("visible_by_kind_ms", {})})
    if kinds:
        lines += ["", "## Command-to-visible by command kind", "",
                  "p50 / p99 in ms (count). A paint, an edit, an unfix, an undo and a redo may "
                  "build a solid off the loop; their own command is visible only after that "
                  "build. Loads and drags of other clients do not wait for it.", "",
                  "| scene | clients | " + " | ".join(kinds) + " |",
                  "| --- | ---: | " + " | ".join("---" for _ in kinds) + " |"]
        for s in scenes:
            for r in data[s]:
                by = r.get("visible_by_kind_ms", {})
                lines.append("| %s | %d | %s |" % (s, r["clients"], " | ".join(
                    "%.1f / %.1f (%d)" % (by[k]["p50"], by[k]["p99"], by[k]["count"]) if k in by
                    else "" for k in kinds)))
    lines.append("")
    with open(os.path.join(directory, "README.md"), "w") as f:
        f.write("\n".join(lines))

    fig, axes = plt.subplots(1, 3, figsize=(15, 4.2), dpi=100)
    for s in scenes:
        runs = data[s]
        if not runs:
            continue
        n = [r["clients"] for r in runs]
        axes[0].plot(n, [r["ack_ms"]["p99"] for r in runs], "o-", label="%s ack p99" % s)
        axes[0].plot(n, [r["visible_ms"]["p99"] for r in runs], "s--", label="%s visible p99" % s)
        axes[0].plot(n, [r["visible_ms"]["p50"] for r in runs], "^:", label="%s visible p50" % s)
        if all("visible_no_build_ms" in r for r in runs):
            axes[0].plot(n, [r["visible_no_build_ms"]["p99"] for r in runs], "x-.",
                         label="%s visible p99, commands that build nothing" % s)
        axes[1].plot(n, [r["loaded_steps_per_second"] / max(r["unloaded_steps_per_second"], 1e-9)
                         for r in runs], "o-", label=s)
        big = runs[-1]
        t = [x[0] for x in big["server_samples"]]
        axes[2].plot(t, [x[1] for x in big["server_samples"]], label="%s CPU %% (%d clients)" % (s, big["clients"]))
        ax2 = axes[2].twinx() if s == scenes[0] else ax2
        ax2.plot(t, [x[2] / 1024 for x in big["server_samples"]], ":",
                 label="%s RSS MB (%d clients)" % (s, big["clients"]))
    axes[0].set_xscale("log", base=2)
    axes[0].set_yscale("log")
    axes[0].set_xlabel("clients")
    axes[0].set_ylabel("ms")
    axes[0].set_title("command latency")
    axes[0].legend(fontsize=7)
    axes[1].set_xscale("log", base=2)
    axes[1].axhline(0.95, color="grey", lw=0.8, ls="--")
    axes[1].set_xlabel("clients")
    axes[1].set_ylabel("loaded / unloaded steps per second")
    axes[1].set_title("the simulation under load (target >= 0.95)")
    axes[1].legend(fontsize=7)
    axes[2].set_xlabel("seconds")
    axes[2].set_ylabel("server CPU % of one core")
    ax2.set_ylabel("server RSS (MB)")
    axes[2].set_title("server over the largest run")
    axes[2].legend(fontsize=7, loc="upper left")
    ax2.legend(fontsize=7, loc="lower right")
    fig.tight_layout()
    fig.savefig(os.path.join(directory, "load.png"))
    print("wrote %s/README.md and load.png" % directory)


if __name__ == "__main__":
    main()
