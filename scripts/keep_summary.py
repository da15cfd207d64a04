#!/usr/bin/python3
"""The main job's "keeping the work" lines (scripts/run_main.sh).

    keep_summary.py KEEP_DIR

KEEP_DIR holds the sculpted block's exports (sculpted.textproto, .obj,
.stl, .glb), the surface of the session created again from the scene file
(recreated.obj), replay.json and animation/ (dynsolid-replay's output).
Prints markdown lines: each file with its size, how far the re-created
surface is from the original (the largest vertex distance; 0 when the
design came back bit for bit), and the animation's frames.
"""
import json
import os
import sys


def size(n):
    return "%.1f MiB" % (n / 2**20) if n >= 2**20 else "%.1f KiB" % (n / 1024)


def vertices(path):
    with open(path) as f:
        return [tuple(float(x) for x in line.split()[1:4]) for line in f if line.startswith("v ")]


def main():
    k = sys.argv[1]
    lines = ["Files (`keep/`):", ""]
    for name in ("sculpted.textproto", "sculpted.obj", "sculpted.stl", "sculpted.glb"):
        path = os.path.join(k, name)
        what = {"textproto": "the design as a scene file (save as)", "obj": "surface, polygons",
                "stl": "surface, triangles", "glb": "glTF 2.0 binary"}[name.split(".")[1]]
        lines.append("- `%s`: %s, %s" % (name, size(os.path.getsize(path)), what))
    a, b = vertices(os.path.join(k, "sculpted.obj")), vertices(os.path.join(k, "recreated.obj"))
    if len(a) != len(b):
        gap = "a different surface (%d and %d vertices)" % (len(a), len(b))
    else:
        d = max(max(abs(x - y) for x, y in zip(p, q)) for p, q in zip(a, b))
        gap = "its surface is %s the original's (largest vertex difference %.3g m)" % (
            "identical to" if d == 0 else "close to", d)
    lines.append("")
    lines.append("The session created again from `sculpted.textproto`: %s." % gap)
    with open(os.path.join(k, "replay.json")) as f:
        r = json.load(f)
    anim = os.path.join(k, "animation")
    total = sum(os.path.getsize(os.path.join(anim, x)) for x in os.listdir(anim))
    lines.append("The session's animation, replayed from its journal (%d records, steps 0-%d): "
                 "%d frames at 20 per second of session time, `animation/sculpt.pvd` and a VTU "
                 "per frame (%s), made in %.1f s." % (r["journal_records"], r["end_step"],
                                                      r["frames"], size(total),
                                                      r["milliseconds"] / 1000))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
