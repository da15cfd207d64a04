#!/usr/bin/python3
"""Summarises a dynsolid-client run report (run --json) as markdown.

usage: summarize_session.py REPORT.json [--server-exit CODE]
"""
import argparse
import json
import os


def num(v):
    """proto3 JSON writes int64 as strings."""
    return int(v) if isinstance(v, str) else v


def fmt(v, digits=4):
    return "%.*g" % (digits, v) if isinstance(v, float) else str(v)


def vec(v, form="%.4f"):
    return "(" + ", ".join(form % x for x in v) + ")"


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("report")
    parser.add_argument("--server-exit", type=int, default=None)
    args = parser.parse_args()
    with open(args.report) as f:
        r = json.load(f)
    st = r["server_stats"]
    solid = r["session"]["solid"]
    c = r["commands"]
    w = r["watch"]
    s = r["surface"]
    out = []
    p = out.append

    p("# dynsolid main job: a scripted sculpting session")
    p("")
    p("`dynsolid-client run --script %s --scene %s --start_paused` against a live "
      "`dynsolid-server` (loopback, `--data_dir` in a temporary directory); status: **%s**."
      % (r["script"]["file"], r["session"]["scene_name"], r["status"]))
    if args.server_exit is not None:
        p("The server was stopped with SIGTERM and exited with code %d." % args.server_exit)
    p("")
    p("## Solid")
    p("")
    p("| scene | control cells | levels | cells | nodes | cubic / linear / pyramid elements "
      "| surface vertices | surface quads | h (s) |")
    p("| --- | ---: | ---: | ---: | ---: | --- | ---: | ---: | ---: |")
    p("| %s | %d | %d | %d | %d | %d / %d / %d | %d | %d | %g |" % (
        r["session"]["scene_name"], solid["control_cells"], solid["levels"], solid["cells"],
        solid["nodes"], solid["cubic_elements"], solid["linear_elements"],
        solid["pyramid_elements"], solid["boundary_vertices"], solid["boundary_faces"],
        r["session"]["time_step"]))
    p("")
    p("## Steps (server GetStats at the end)")
    p("")
    p("| steps | simulated time (s) | step time median (ms) | p99 (ms) | steps measured "
      "| overruns | steps dropped | rollbacks | journal records | snapshots |")
    p("| ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |")
    p("| %d | %.3f | %.3f | %.3f | %d | %d | %d | %d | %d | %d |" % (
        num(st["step"]), st["time"], st["step_ms_median"], st["step_ms_p99"],
        num(st["steps_measured"]), num(st["overruns"]), num(st["steps_dropped"]),
        num(st["rollbacks"]), num(st["journal_records"]), num(st["snapshots"])))
    phases = st.get("phases", [])
    if phases:
        p("")
        p("Per-phase median (ms): " + ", ".join(
            "%s %.3f" % (ph["name"], ph["median_ms"]) for ph in phases) + ".")
    p("")
    p("## Commands")
    p("")
    lat = c["latency_ms"]
    p("%d sent, %d answered, %d ok, %d rejected; %d resent, %d duplicate answers, %d "
      "reconnects; answers to already answered commands: %d. Latency (first write to answer): "
      "median **%.3f ms**, p99 **%.3f ms**, max %.3f ms. Server: %d applied, %d rejected, "
      "%d duplicates." % (
          c["sent"], c["answered"], c["ok"], c["rejected"], c["resends"],
          c["duplicate_answers"], c["reconnects"], c["extra_answers"], lat["median"], lat["p99"],
          lat["max"], num(st["commands_applied"]), num(st["commands_rejected"]),
          num(st["commands_duplicate"])))
    p("")
    p("| seq | line | command | applied at step | latency (ms) | held the loop (ms) | result |")
    p("| ---: | --- | --- | ---: | ---: | ---: | --- |")
    for e in c["log"]:
        result = "ok" if e["code"] == 0 else "code %d: %s" % (e["code"], e["message"])
        for key in ("load_id", "constraint_id"):
            if key in e:
                result += ", %s %d" % (key, e[key])
        if "edit" in e:
            result += (": %s (%d -> %d control cells, %d elements; new solid built in %.0f ms "
                       "while the old one went on)" % (
                           e["edit"]["summary"], e["edit"]["cells_before"],
                           e["edit"]["cells_after"], e["edit"]["elements_after"],
                           e["edit"].get("build_ms", 0.0)))
        if "history" in e:
            result += ": %s (undo %d, redo %d)" % (
                e["history"]["what"], e["history"]["undo_depth"], e["history"]["redo_depth"])
        if "saved_step" in e:
            result += ", snapshot at step %d (%d bytes)" % (e["saved_step"], e["saved_bytes"])
        p("| %d | %s | %s | %d | %.3f | %.2f | %s |" % (
            e["seq"], e["where"], e["kind"], e["applied_step"], e["latency_ms"],
            e.get("hold_ms", 0.0), result))
    p("")
    p("## Frames (one watcher, keyframe + 16-bit deltas)")
    p("")
    raw = w["raw_float32_bytes"]
    fields = w.get("field_bytes", 0)
    p("| received | keyframes | deltas | skipped | frames/s | bytes | of them fields "
      "| without fields, of raw float32 positions | steps | written |")
    p("| ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | --- | ---: |")
    p("| %d | %d | %d | %d | %.1f | %d | %d | %s | %d..%d | %d |" % (
        w["frames"], w["keyframes"], w["deltas"], w["skipped"], w["frames_per_second"],
        w["bytes"], fields, "%.1f %%" % (100.0 * (w["bytes"] - fields) / raw) if raw else "-",
        w["first_step"], w["last_step"], w["frames_written"]))
    p("")
    p("Server: %d frames published, %d sent, %d skipped, %d keyframes, %d bytes." % (
        num(st["frames_published"]), num(st["frames_sent"]), num(st["frames_skipped"]),
        num(st["keyframes_sent"]), num(st["bytes_sent"])))
    p("")
    p("Snapshots: " + ", ".join(
        "%s (step %d: %s)" % (sn["name"], sn["step"],
                              ", ".join(os.path.basename(f) for f in sn["files"]))
        for sn in r["snapshots"]) + ".")
    p("")
    p("## Final surface")
    p("")
    p("At step %d: %d vertices, %d quads; bounding box %s .. %s m." % (
        s["step"], s["vertices"], s["quads"], vec(s["bbox_min"]), vec(s["bbox_max"])))
    if "max_moved_since_first" in s:
        p("Largest vertex motion since the first frame (step %d): %.4f m." % (
            s["first_step"], s["max_moved_since_first"]))
    if "max_displacement" in s:
        p("Largest displacement from rest (server field): %.4f m." % s["max_displacement"])
    if "stiffness_min" in s:
        p("Young's modulus on the surface: %s .. %s Pa (after painting)." % (
            fmt(s["stiffness_min"]), fmt(s["stiffness_max"])))
    ch = r["check"]
    if ch["done"]:
        p("Watched surface against the server's exact positions at step %d: largest error %s m "
          "per axis, quantization bound %s m: %s." % (
              ch["step"], vec(ch["max_error"], "%.3g"), vec(s["error_bound"], "%.3g"),
              "within the bound" if ch["within_bound"] else "**outside the bound**"))
    print("\n".join(out))


if __name__ == "__main__":
    main()
