#!/usr/bin/python3
"""Renders surface frames (dynsolid OBJ: quads) side by side into one PNG.

    render_frames.py OUT.png [--floor=Z] FRAME.obj[:TITLE] [FRAME.obj[:TITLE] ...]

--floor=Z draws the floor (the plane z = Z) as a grey square under the
solid, so that a picture shows where the solid stands.

Flat-shaded quads (a headlight and a key light), one panel per frame, the
same view and the same axes limits in every panel so that shapes compare.
Uses Debian's python3-matplotlib (run with /usr/bin/python3).
"""
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from mpl_toolkits.mplot3d.art3d import Poly3DCollection  # noqa: E402


def read_obj(path):
    verts, faces, title = [], [], ""
    with open(path) as f:
        for line in f:
            if line.startswith("v "):
                verts.append([float(x) for x in line.split()[1:4]])
            elif line.startswith("f "):
                faces.append([int(t.split("/")[0]) - 1 for t in line.split()[1:]])
            elif line.startswith("#") and not title:
                title = line[1:].strip()
    return np.array(verts), faces, title


def shade(verts, faces, light):
    out = []
    for f in faces:
        p = verts[f]
        n = np.cross(p[2] - p[0], p[-1] - p[1]) if len(f) == 4 else np.cross(p[1] - p[0], p[2] - p[0])
        ln = np.linalg.norm(n)
        out.append(0.0 if ln == 0 else max(0.0, float(np.dot(n / ln, light))))
    return np.array(out)


def main():
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    out = sys.argv[1]
    frames = []
    floor = None
    for arg in sys.argv[2:]:
        if arg.startswith("--floor="):
            floor = float(arg[len("--floor="):])
            continue
        path, _, title = arg.partition(":")
        v, f, header = read_obj(path)
        frames.append((v, f, title or os.path.basename(path), header))
    allv = np.vstack([v for v, _, _, _ in frames])
    lo, hi = allv.min(axis=0), allv.max(axis=0)
    if floor is not None:
        lo[2] = min(lo[2], floor)
    centre, half = (lo + hi) / 2, (hi - lo).max() / 2 * 1.05
    light = np.array([0.4, -0.6, 0.7])
    light /= np.linalg.norm(light)
    fig = plt.figure(figsize=(2.8 * len(frames), 3.0), dpi=110)
    for k, (v, f, title, header) in enumerate(frames):
        # (computed_zorder off: the floor is drawn first, the solid over it.)
        ax = fig.add_subplot(1, len(frames), k + 1, projection="3d", computed_zorder=False)
        s = shade(v, f, light)
        colours = plt.cm.Blues(0.35 + 0.6 * s)
        poly = Poly3DCollection([v[face] for face in f], facecolors=colours, edgecolors=(0, 0, 0, 0.15),
                                linewidths=0.2)
        if floor is not None:
            # The floor first (drawn behind): a square around the solids.
            r = (hi - lo)[:2].max() * 0.75
            cx, cy = (lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2
            square = [[cx - r, cy - r, floor], [cx + r, cy - r, floor], [cx + r, cy + r, floor],
                      [cx - r, cy + r, floor]]
            ax.add_collection3d(Poly3DCollection([square], facecolors=(0.6, 0.6, 0.6, 0.5),
                                                 edgecolors=(0.3, 0.3, 0.3, 0.6), linewidths=0.5,
                                                 zorder=0))
        poly.set_zorder(1)
        ax.add_collection3d(poly)
        for a, set_lim in enumerate((ax.set_xlim, ax.set_ylim, ax.set_zlim)):
            set_lim(centre[a] - half, centre[a] + half)
        ax.set_box_aspect((1, 1, 1))
        ax.view_init(elev=22, azim=-60)
        ax.set_axis_off()
        step = next((p.strip() for p in header.split(",") if p.strip().startswith("step")), "")
        ax.set_title("%s\n%s" % (title, step), fontsize=9, pad=0)
    fig.subplots_adjust(left=0, right=1, bottom=0, top=0.9, wspace=0)
    fig.savefig(out)
    print("wrote %s" % out)


if __name__ == "__main__":
    main()
