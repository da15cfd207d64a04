#!/usr/bin/python3
"""How far a surface moved between two frames of one topology (dynsolid OBJ).

    shape_change.py BEFORE.obj AFTER.obj [LABEL]

Prints one line: the largest vertex displacement (mm), the mean one, and
where the largest is (metres). Uses numpy from Debian's python3-numpy.
"""
import sys

import numpy as np


def read_vertices(path):
    with open(path) as f:
        return np.array([[float(x) for x in line.split()[1:4]] for line in f if line.startswith("v ")])


def main():
    before, after = read_vertices(sys.argv[1]), read_vertices(sys.argv[2])
    if before.shape != after.shape:
        sys.exit(f"shape_change: {sys.argv[1]} has {len(before)} vertices, {sys.argv[2]} {len(after)}")
    d = np.linalg.norm(after - before, axis=1)
    k = int(np.argmax(d))
    label = sys.argv[3] if len(sys.argv) > 3 else "moved"
    x = after[k]
    print(f"{label}: up to {1e3 * d[k]:.1f} mm (mean {1e3 * d.mean():.1f} mm), "
          f"largest at ({x[0]:.3f}, {x[1]:.3f}, {x[2]:.3f}) m")


if __name__ == "__main__":
    main()
