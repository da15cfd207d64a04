#!/usr/bin/python3
"""The main job's haptic segment: plot and markdown from a haptic loopback run.

Reads DIR/results.json, DIR/{soft,stiff,safety}.csv and .json (written by
tests/haptic/haptic_loopback_test.py --out DIR); writes DIR/force_depth.png
(force against the device's depth and against the solid's dent, soft and
painted region, with the held points and the fitted slopes) and prints the
markdown section for out/main/summary.md.

    /usr/bin/python3 scripts/haptic_report.py DIR [--png-link PATH]

Needs Debian's python3-matplotlib.
"""
import argparse
import csv
import json
import os

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

COLORS = {"soft": "tab:blue", "stiff": "tab:red"}
LABELS = {"soft": "soft half (E = 100 kPa)", "stiff": "painted half (E = 1 MPa)"}


def read_trace(path):
    with open(path) as f:
        return [{k: float(v) for k, v in r.items()} for r in csv.DictReader(f)]


def plot(out_dir, results):
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.4))
    for name in ("soft", "stiff"):
        rows = read_trace(os.path.join(out_dir, name + ".csv"))
        # The pressing phase only (before the hand lets go): up to the last hold.
        last = results[name]["holds"][-1]
        contact = [r for r in rows if r["f_normal"] > 0 and r["model_step"] >= 0]
        color = COLORS[name]
        for ax, key, slope_key in ((axes[0], "depth", "slope_depth"),
                                   (axes[1], "dent", "slope_dent")):
            ax.plot([1e3 * r[key] for r in contact], [r["f_normal"] for r in contact], ".",
                    ms=1.0, color=color, alpha=0.25,
                    label="%s: every tick in contact (loading, holds, release)" % name)
            holds = results[name]["holds"]
            ax.plot([1e3 * h[key] for h in holds], [h["force"] for h in holds], "o",
                    color=color, label="%s: held points" % LABELS[name])
            slope = results[name][slope_key]
            xmax = 1e3 * max(h[key] for h in holds) * 1.15
            ax.plot([0, xmax], [0, slope * xmax * 1e-3], "-", color=color, lw=1,
                    label="%s: slope %.0f N/m" % (name, slope))
            if key == "dent":
                ks = results[name]["k_static"]
                ax.plot([0, xmax], [0, ks * xmax * 1e-3], ":", color=color, lw=1,
                        label="%s: k_static of the contact model %.0f N/m" % (name, ks))
        del last
    axes[0].set_xlabel("depth of the device below the rest surface (mm)")
    axes[0].set_ylabel("force rendered on the device (N)")
    axes[0].set_title("What the hand feels (coupling in series)")
    axes[1].set_xlabel("dent of the solid's surface at the contact point (mm)")
    axes[1].set_ylabel("force (N)")
    axes[1].set_title("The solid's own response")
    for ax in axes:
        ax.grid(True, alpha=0.3)
        ax.set_xlim(left=0)
        ax.set_ylim(bottom=0)
        ax.legend(fontsize=7, loc="upper left")
    fig.suptitle("Haptic probe on block3 (1 level, light and damped variant), virtual hand, "
                 "dynsolid-haptic-bridge at 1 kHz", fontsize=10)
    fig.tight_layout()
    path = os.path.join(out_dir, "force_depth.png")
    fig.savefig(path, dpi=110)
    return path


def metrics_rows(results):
    rows = []
    for name in ("soft", "stiff", "safety"):
        m = results[name]["metrics"]
        rows.append(
            "| %s | %.1f / %.1f / %.1f / %.1f | %.1f / %.1f | %d | %.0f | %.2f / %.2f | %.2f / %.2f"
            " | %.2f / %.2f | %.2f (%.0f) | %d |" %
            (name, m["period_p50_us"], m["period_p99_us"], m["period_p999_us"],
             m["period_max_us"], m["period_error_p99_us"], m["period_error_p999_us"],
             m["deadline_misses"], m["model_refresh_hz"], m["model_age_p50_ms"],
             m["model_age_p99_ms"], m["round_trip_p50_ms"], m["round_trip_p99_ms"],
             m["compute_p50_us"], m["compute_p99_us"], m["largest_force_step_n"],
             m["force_step_bound_n"], m["safety_ramps"]))
    return rows


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("dir")
    parser.add_argument("--png-link", default="haptic/force_depth.png",
                        help="the PNG's path as summary.md links it")
    args = parser.parse_args()
    results = json.load(open(os.path.join(args.dir, "results.json")))
    plot(args.dir, results)
    r = results["ratios"]
    out = []
    out.append("## Haptic: the bridge with a virtual hand probes the painted block")
    out.append("")
    out.append("`dynsolid-haptic-bridge` (1 kHz, virtual coupling) with a virtual hand "
               "(0.5 kg on a 500 N/m spring to a scripted target) against a live session of "
               "block3 at 1 level, its half x > 1.5 painted ten times stiffer (E 100 kPa -> 1 "
               "MPa), in a light, damped variant (density 100 kg/m^3, damping 1100 kg/(m^3 s)) "
               "so held pushes settle (tests/haptic/haptic_loopback_test.py; docs/haptic.md). "
               "The hand pushes 1, 3 and 5 cm below the top face at (0.75, 1.5) and at "
               "(2.25, 1.5), holding each for 2 s; the points are the last 0.25 s of each hold.")
    out.append("")
    out.append("![force-depth curves](%s)" % args.png_link)
    out.append("")
    out.append("| region | held force (N) | device depth (mm) | dent (mm) | force/depth felt "
               "(N/m) | force/dent (N/m) | k_static of the model (N/m) | k over 30 ms (N/m) |")
    out.append("| --- | --- | --- | --- | ---: | ---: | ---: | ---: |")
    for name in ("soft", "stiff"):
        x = results[name]
        h = x["holds"]
        out.append("| %s | %s | %s | %s | %.0f | %.0f | %.0f | %.3g |" %
                   (name, " / ".join("%.2f" % p["force"] for p in h),
                    " / ".join("%.2f" % (1e3 * p["depth"]) for p in h),
                    " / ".join("%.3f" % (1e3 * p["dent"]) for p in h),
                    x["slope_depth"], x["slope_dent"], x["k_static"], x["k"]))
    out.append("")
    out.append("Stiff / soft: force-dent slope ratio **%.2f** against the ratio of the solid's "
               "own static stiffness from its contact models **%.2f**; at the device (the "
               "coupling spring of 28.8 kN/m in series) **%.2f**." %
               (r["force_dent"], r["k_static"], r["force_depth"]))
    out.append("")
    s = results["safety"]
    out.append("Safety: the server frozen (SIGSTOP) at t = %.2f s of the third run: the force "
               "ramped to zero within 10 ms and stayed there until models came again; killed "
               "(SIGKILL) at t = %.2f s: the same; restarted on its data directory, the bridge "
               "reconnected by itself at t = %.2f s and pushed again (%d reconnect)." %
               (s["silent_t"], s["broken_t"], s["reconnected_t"],
                s["metrics"]["reconnects"]))
    out.append("")
    out.append("Loop metrics (us unless noted; compute = force computation per tick):")
    out.append("")
    out.append("| run | period p50 / p99 / p99.9 / max | period error p99 / p99.9 | deadline "
               "misses | model refresh (Hz) | model age p50 / p99 (ms) | pose -> model round "
               "trip p50 / p99 (ms) | compute p50 / p99 | largest force step (bound), N | "
               "safety ramps |")
    out.append("| --- | --- | --- | ---: | ---: | --- | --- | --- | --- | ---: |")
    out.extend(metrics_rows(results))
    out.append("")
    out.append("(The session steps block3 at 1 level in real time, 1000 steps/s: the model "
               "refresh is the step rate less the replies merged while a write was in flight. "
               "The safety run's ramps are the freeze and the kill; its period maxima include "
               "them.)")
    print("\n".join(out))


if __name__ == "__main__":
    main()
