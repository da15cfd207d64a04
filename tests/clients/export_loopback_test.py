"""dynsolid-client export against a real dynsolid-server.

On a block3 session that has been pulled out of shape:
1. OBJ at the session's own level: the vertices and faces the session
   reports for its boundary; the first chunk names the file, the step and
   the level.
2. Binary STL two levels finer: 84 + 50 n bytes, every normal a unit
   vector, the enclosed volume near the block's 27 m^3 (subdivision
   shrinks it a little) and above zero (faces outward).
3. glb with the displacement as colours: the glTF magic and length, and
   the Khronos validator's verdict when tests/io/gltf's packages are there.
4. VTU three levels deep: several chunks (progress lines with --verbose),
   reassembled into XML with the cell count the first chunk gave.
5. Bad requests: a level out of range and an unknown colour field get
   INVALID_ARGUMENT naming the field (exit 2), an unknown format is a usage
   error (exit 1), a wrong token is refused; nothing is written.

Usage: export_loopback_test.py --server PATH --client PATH
"""

import json
import math
import os
import struct
import subprocess
import sys
import xml.etree.ElementTree as ET

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
sys.path.insert(0, os.path.join(HERE, "..", "testing"))
from client_loopback_test import Server, run_client  # noqa: E402
from loopback import binary_args, expect, expect_equal, run_in_temp_dir  # noqa: E402

SOURCE = os.path.abspath(os.path.join(HERE, "..", ".."))


def export(args, server, ref, *flags):
    return run_client(args.client, server.address, "export", "--id", ref["id"], "--token",
                      ref["token"], *flags)


def stl_volume(data):
    (n,) = struct.unpack_from("<I", data, 80)
    expect_equal("STL size", len(data), 84 + 50 * n)
    volume = 0.0
    for t in range(n):
        vals = struct.unpack_from("<12f", data, 84 + 50 * t)
        normal = vals[0:3]
        a, b, c = vals[3:6], vals[6:9], vals[9:12]
        expect(abs(math.sqrt(sum(x * x for x in normal)) - 1) < 1e-4,
               "STL triangle %d: normal %r is not a unit vector" % (t, normal))
        volume += (a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0]) +
                   a[2] * (b[0] * c[1] - b[1] * c[0])) / 6.0
    return n, volume


def main():
    run_in_temp_dir(run, binary_args("server", "client"), "dynsolid_export_test_")


def run(args, tmp):
    server = Server(args.server, os.path.join(tmp, "data"), os.path.join(tmp, "server.log"))
    try:
        r = run_client(args.client, server.address, "create", "--scene", "block3", "--levels", "1")
        expect(r.returncode == 0, "create: %s" % r.stderr)
        session = json.loads(r.stdout)
        ref = {"id": session["id"], "token": session["token"]}
        script = os.path.join(tmp, "pull.txt")
        with open(script, "w") as f:
            f.write("force at=1.5,1.5,3 f=2e4,0,0 name=pull\nstep 50\nwait\n")
        r = run_client(args.client, server.address, "run", "--script", script, "--id", ref["id"],
                       "--token", ref["token"], "--noclose", "--nowatch")
        expect(r.returncode == 0, "pull: %s" % r.stderr)
        os.chdir(tmp)

        # 1. OBJ at the session's level, named by the server.
        r = export(args, server, ref, "--format", "obj")
        expect(r.returncode == 0, "export obj: %s" % r.stderr)
        first = json.loads(r.stdout)
        expect(first["file_name"].endswith("-level1.obj") and os.path.exists(first["file_name"]),
               "obj file %r" % first["file_name"])
        expect(int(first["step"]) >= 50, "taken at step %s" % first["step"])
        with open(first["file_name"]) as f:
            lines = f.read().splitlines()
        vertices = sum(1 for x in lines if x.startswith("v "))
        faces = sum(1 for x in lines if x.startswith("f "))
        solid = session["stats"]
        expect_equal("OBJ vertices", vertices, solid["boundary_vertices"])
        expect_equal("OBJ faces", faces, solid["boundary_faces"])
        expect_equal("first chunk's surface_faces", int(first["surface_faces"]), faces)

        # 2. STL two levels finer.
        r = export(args, server, ref, "--format", "stl", "--level", "3", "--out", "fine.stl")
        expect(r.returncode == 0, "export stl: %s" % r.stderr)
        with open("fine.stl", "rb") as f:
            n, volume = stl_volume(f.read())
        print("stl level 3: %d triangles, enclosed volume %.4f m^3" % (n, volume))
        expect(24 < volume < 27.5, "enclosed volume %.4f m^3 (block3 is 27 m^3)" % volume)

        # 3. glb with colours, validated.
        r = export(args, server, ref, "--format", "glb", "--level", "2", "--color_field",
                   "displacement", "--out", "design.glb")
        expect(r.returncode == 0, "export glb: %s" % r.stderr)
        with open("design.glb", "rb") as f:
            glb = f.read()
        magic, version, length = struct.unpack_from("<4sII", glb, 0)
        expect(magic == b"glTF" and version == 2 and length == len(glb),
               "glb header %r %d %d (file %d bytes)" % (magic, version, length, len(glb)))
        expect(b"COLOR_0" in glb, "no COLOR_0 in the glb")
        validator = os.path.join(SOURCE, "tests", "io", "gltf")
        if os.path.isdir(os.path.join(validator, "node_modules")):
            v = subprocess.run(["node", os.path.join(validator, "validate.mjs"), "design.glb"],
                               capture_output=True, text=True, timeout=120)
            expect(v.returncode == 0, "glTF validator: %s%s" % (v.stdout, v.stderr))
        else:
            expect(False, "tests/io/gltf/node_modules is missing: run scripts/setup_web.sh")

        # 4. VTU three levels deep: several chunks.
        r = export(args, server, ref, "--format", "vtu", "--level", "3", "--out", "volume.vtu",
                   "--verbose")
        expect(r.returncode == 0, "export vtu: %s" % r.stderr)
        progress = [x for x in r.stderr.splitlines() if x.startswith("export: ")]
        expect(len(progress) >= 2 and progress[-1].endswith("(100 %)"),
               "progress lines %r" % progress[-3:])
        first = json.loads(r.stdout)
        piece = ET.parse("volume.vtu").getroot().find("UnstructuredGrid/Piece")
        expect_equal("VTU cells", int(piece.get("NumberOfCells")), int(first["cells"]))
        names = {a.get("Name") for a in piece.iter("DataArray")}
        expect({"displacement", "element_kind", "control_cell"} <= names, "VTU arrays %r" % names)
        print("vtu level 3: %s cells, %s bytes in %d chunks" % (first["cells"], first["total_bytes"],
                                                                len(progress)))

        # 5. Bad requests.
        r = export(args, server, ref, "--format", "obj", "--level", "7", "--out", "bad.obj")
        expect(r.returncode == 2 and "INVALID_ARGUMENT" in r.stderr and
               "request.level: 7 is not in [0, 6]" in r.stderr, "level 7: %d %s" % (r.returncode, r.stderr))
        # Six levels of block3 are 27 * 8^6 = 7.1 million cells: more than
        # a session may have (the server's --max_cells, 1 million).
        r = export(args, server, ref, "--format", "stl", "--level", "6", "--out", "huge.stl")
        expect(r.returncode == 2 and "more than the export limit of 1000000" in r.stderr,
               "level 6: %d %s" % (r.returncode, r.stderr))
        expect(not os.path.exists("huge.stl"), "a refused export wrote a file")
        r = export(args, server, ref, "--format", "glb", "--color_field", "strain", "--out", "bad.glb")
        expect(r.returncode == 2 and "request.color_field" in r.stderr,
               "colour field: %d %s" % (r.returncode, r.stderr))
        r = export(args, server, ref, "--format", "dwg", "--out", "bad.dwg")
        expect(r.returncode == 1 and "--format dwg" in r.stderr, "format dwg: %d %s" % (r.returncode, r.stderr))
        r = run_client(args.client, server.address, "export", "--id", ref["id"], "--token",
                       "not-the-token", "--format", "obj", "--out", "bad2.obj")
        expect(r.returncode == 2, "wrong token: %d %s" % (r.returncode, r.stderr))
        expect(not any(os.path.exists(p) for p in ("bad.obj", "bad.glb", "bad.dwg", "bad2.obj")),
               "a refused export wrote a file")
    finally:
        server.stop()


if __name__ == "__main__":
    main()
