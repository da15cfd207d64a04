#!/usr/bin/python3
"""End-to-end checks of dynsolid-sim (run by CTest with the binary's path)."""
import json
import os
import subprocess
import sys
import tempfile

import meshio

SIM = sys.argv[1]
failures = []
passed = 0


def check(cond, what):
    global passed
    if cond:
        passed += 1
    else:
        failures.append(what)
        print("FAIL:", what)


def run(*args):
    return subprocess.run([SIM, *args], capture_output=True, text=True)


with tempfile.TemporaryDirectory() as tmp:
    # block3 at 2 levels: the paper's Table 1 numbers for the cube.
    out = os.path.join(tmp, "block3")
    r = run("--scene", "block3", "--out", out)
    check(r.returncode == 0, f"block3 exit code 0, got {r.returncode}: {r.stderr}")
    stats = json.load(open(os.path.join(out, "stats.json")))
    check(stats["control_cells"] == 27, f"control_cells 27, got {stats['control_cells']}")
    check(stats["control_vertices"] == 64, f"control_vertices 64, got {stats['control_vertices']}")
    check(stats["levels"] == 2, f"levels 2, got {stats['levels']}")
    check(stats["cells"] == 1728, f"cells 1728, got {stats['cells']}")
    check(stats["nodes"] == 2197, f"nodes 2197, got {stats['nodes']}")
    check(stats["elements"] == {"cubic": 1000, "linear": 728, "pyramid": 0, "pyramid_cells": 0},
          f"elements, got {stats['elements']}")
    check(abs(stats["fractions_percent"]["cubic"] - 57.87) < 0.01,
          f"cubic fraction 57.9 %, got {stats['fractions_percent']['cubic']}")

    # The volume .vtu and boundary .ply read back by meshio.
    vol = meshio.read(os.path.join(out, "volume.vtu"))
    hexes = sum(len(b.data) for b in vol.cells if b.type == "hexahedron")
    check(hexes == 1728, f"volume.vtu has 1728 hexahedra, got {hexes}")
    kinds = [int(k) for block in vol.cell_data["element_kind"] for k in block]
    check(kinds.count(0) == 1000 and kinds.count(1) == 728,
          f"element_kind cell data: 1000 cubic and 728 linear, got {kinds.count(0)}/{kinds.count(1)}")
    levels = {int(k) for block in vol.cell_data["level"] for k in block}
    check(levels == {2}, f"level cell data is 2, got {levels}")
    ply = meshio.read(os.path.join(out, "boundary.ply"))
    quads = sum(len(b.data) for b in ply.cells if b.type == "quad")
    check(quads == 6 * 144, f"boundary.ply has 864 quads, got {quads}")

    # --levels overrides the scene; a mesh file on its own gets defaults.
    out1 = os.path.join(tmp, "mixed1")
    r = run("--scene", "scenes/meshes/mixed.vtk", "--levels", "1", "--out", out1)
    check(r.returncode == 0, f"mixed.vtk exit code 0, got {r.returncode}: {r.stderr}")
    if r.returncode == 0:
        s = json.load(open(os.path.join(out1, "stats.json")))
        check(s["levels"] == 1 and s["control_cells"] == 4,
              f"mixed.vtk: 4 control cells, 1 level, got {s['control_cells']}, {s['levels']}")
        check(s["elements"]["pyramid"] > 0, "mixed mesh has pyramid elements after one level")
        vol = meshio.read(os.path.join(out1, "volume.vtu"))
        pyr = sum(len(b.data) for b in vol.cells if b.type == "pyramid")
        check(pyr == s["elements"]["pyramid"], f"volume.vtu pyramids {pyr}")

    # Dynamics: the beam moves, trace.csv and frames are written.
    outb = os.path.join(tmp, "beam")
    r = run("--scene", "beam", "--steps", "40", "--frames", "20", "--out", outb)
    check(r.returncode == 0, f"beam --steps 40 exit 0, got {r.returncode}: {r.stderr}")
    if r.returncode == 0:
        s = json.load(open(os.path.join(outb, "stats.json")))
        check(s["steps"] == 40, f"steps 40, got {s['steps']}")
        check(s["ms_per_step"] > 0 and s["steps_per_second"] > 0, "step timings present")
        check("stiffness" in s["phases_ms"] and "solve" in s["phases_ms"], f"phases {s['phases_ms']}")
        check("damping" not in s["phases_ms"], "no separate damping phase")
        # Central differences solve with the factor made at set-up: no CG.
        check(s["cg_iterations"]["max_single_solve"] == 0,
              f"the factored explicit solve iterates not: {s['cg_iterations']}")
        check(s["energy_j"]["kinetic"] > 0, f"the loaded beam moves: {s['energy_j']}")
        check(s["dynamics"]["fixed_control_points"] > 0, "the beam's root is fixed")
        lines = open(os.path.join(outb, "trace.csv")).read().strip().split("\n")
        check(len(lines) == 42, f"trace.csv: header + 41 rows, got {len(lines)}")
        check(lines[0].startswith("step,time,tip_x"), f"trace header {lines[0]!r}")
        last = [float(x) for x in lines[-1].split(",")]
        check(last[4] < 0, f"the tip moves down under its load: z = {last[4]}")
        for k in (20, 40):
            f = os.path.join(outb, "frames", f"frame_{k:06d}.vtu")
            check(os.path.exists(f), f"{f} written")
        m = meshio.read(os.path.join(outb, "frames", "frame_000040.vtu"))
        check(len(m.points) > 0, "frame .vtu readable")

    # Bad input: exit 2, a message that says what and where, nothing written.
    bad = os.path.join(tmp, "bad.textproto")
    with open(bad, "w") as f:
        f.write('name: "bad"\nmesh { block { nx: 0 ny: 2 nz: 2 } }\n')
    out2 = os.path.join(tmp, "bad_out")
    r = run("--scene", bad, "--out", out2)
    check(r.returncode == 2, f"bad scene exit code 2, got {r.returncode}")
    check("nx" in r.stderr, f"bad scene message names the field: {r.stderr!r}")
    check(not os.path.exists(out2), "bad scene writes nothing")

    broken = os.path.join(tmp, "open.vtk")
    with open(broken, "w") as f:
        # A hexahedron listed with a repeated vertex.
        f.write("# vtk DataFile Version 4.2\nbroken\nASCII\nDATASET UNSTRUCTURED_GRID\n"
                "POINTS 8 double\n0 0 0 1 0 0 1 1 0 0 1 0 0 0 1 1 0 1 1 1 1 0 1 1\n"
                "CELLS 1 9\n8 0 1 2 3 4 5 6 6\nCELL_TYPES 1\n12\n")
    out3 = os.path.join(tmp, "broken_out")
    r = run("--scene", broken, "--out", out3)
    check(r.returncode == 2, f"broken mesh exit code 2, got {r.returncode}")
    check("open.vtk" in r.stderr and "cell 0" in r.stderr,
          f"broken mesh message names file and cell: {r.stderr!r}")
    check(not os.path.exists(out3), "broken mesh writes nothing")

    r = run("--scene", "no_such_scene", "--out", os.path.join(tmp, "x"))
    check(r.returncode == 2 and "block3" in r.stderr,
          f"unknown scene: exit 2 and the known names listed: {r.returncode} {r.stderr!r}")

print(f"{passed} passed, {len(failures)} failed")
sys.exit(1 if failures else 0)
