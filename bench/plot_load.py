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
                # The first table (the second says where the CPU went).
                rows = f.read().strip().split("\n\n")[0].split("\n")
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
    roles = ["sim", "encode", "gRPC and other", "journal"]
    lines += ["", "## Where the CPU went", "",
              "Per second of the run, from /proc (`schedstat` of each thread): ms on a CPU / ms "
              "ready to run but waiting for a core, and the mean wait each time the thread was "
              "woken. A thread that waits long had work and no core. `busy cores` is the "
              "machine's (of its %d): the server, the load tool's clients and anything else. "
              "The builds (paints, edits, unfixes, undos and redos across them) are timed by the "
              "server itself (SessionStats.build_*): ms the build thread was busy, of which on "
              "a CPU / waiting for one, and builds a second." % os.cpu_count(), "",
              "| scene | clients | busy cores | dynsolid-load (clients) | server builds: busy (CPU / "
              "wait), builds/s | " + " | ".join("server %s" % k for k in roles) + " |",
              "| --- | ---: | ---: | --- | --- | " + " | ".join("---" for _ in roles) + " |"]

    def use(u):
        if not u:
            return ""
        mean_us = 1e3 * u["wait_ms_per_s"] / u["runs_per_s"] if u.get("runs_per_s") else 0
        return "%.0f / %.0f, %.0f us" % (u["cpu_ms_per_s"], u["wait_ms_per_s"], mean_us)

    for s in scenes:
        for r in data[s]:
            if "busy_cores" not in r:
                continue
            b = r["builds"]
            lines.append("| %s | %d | %.2f | %s | %.0f (%.0f / %.0f), %.1f | %s |" % (
                s, r["clients"], r["busy_cores"], use(r["load_tool"]), r["build_busy_ms_per_s"],
                b["cpu_ms_per_s"], b["wait_ms_per_s"], b["runs_per_s"],
                " | ".join(use(r["server_threads"].get(k)) for k in roles)))
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

    fig, grid = plt.subplots(2, 2, figsize=(14, 9), dpi=100)
    axes = [grid[0][0], grid[0][1], grid[1][0], grid[1][1]]
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
    # Where the CPU went: stacked CPU ms per second by thread role, one bar
    # per scene at each client count, and the simulation thread's wait.
    parts = [("sim", lambda r: r["server_threads"].get("sim", {}).get("cpu_ms_per_s", 0)),
             ("builds", lambda r: r["builds"]["cpu_ms_per_s"]),
             ("encode", lambda r: r["server_threads"].get("encode", {}).get("cpu_ms_per_s", 0)),
             ("gRPC and other", lambda r: r["server_threads"].get("gRPC and other", {}).get("cpu_ms_per_s", 0)
              + r["server_threads"].get("journal", {}).get("cpu_ms_per_s", 0)),
             ("dynsolid-load (clients)", lambda r: r["load_tool"]["cpu_ms_per_s"])]
    colours = ["tab:blue", "tab:orange", "tab:green", "tab:grey", "tab:purple"]
    width = 0.38
    counts = sorted({r["clients"] for s in scenes for r in data[s]})
    ax = axes[3]
    for si, s in enumerate(scenes):
        runs = [r for r in data[s] if "busy_cores" in r]
        for r in runs:
            x = counts.index(r["clients"]) + (si - 0.5) * width
            bottom = 0
            for (name, get), colour in zip(parts, colours):
                v = get(r)
                ax.bar(x, v, width * 0.95, bottom=bottom, color=colour,
                       label=name if (si == 0 and r is runs[0]) else None,
                       hatch="//" if si else None, edgecolor="white")
                bottom += v
            wait = r["server_threads"].get("sim", {}).get("wait_ms_per_s", 0)
            ax.plot([x], [wait], "kv", label="sim thread waiting for a core" if (si == 0 and r is runs[0]) else None)
    ax.axhline(1000 * os.cpu_count(), color="grey", lw=0.8, ls="--")
    ax.set_xticks(range(len(counts)))
    ax.set_xticklabels([str(c) for c in counts])
    ax.set_xlabel("clients (left bar %s, right bar %s, hatched)" % (scenes[0], scenes[-1]))
    ax.set_ylabel("CPU ms per second (dashed: all cores)")
    ax.set_title("where the CPU went")
    ax.legend(fontsize=7, loc="upper left")
    fig.tight_layout()
    fig.savefig(os.path.join(directory, "load.png"))
    print("wrote %s/README.md and load.png" % directory)


if __name__ == "__main__":
    main()
