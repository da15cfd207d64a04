"""Keeping the work against a real dynsolid-server: "save as"
and animations from the journal.

A `clay` session (started paused, so its steps come from the scripts) is
painted, pulled until it yields, released, baked, pinned and pulled again.
1. Save as: `export --format scene` gives a scene file; a session created
   from it, exported again, gives the same file (rest shape, samples as
   painted, clay state, sharp tags, pins, floor: every number to the bit),
   except its description and header. Another level is refused.
2. Replay: `dynsolid-replay` on the session's directory gives, at the steps
   the live session was exported at (VTU, full precision), the very same
   bytes: the replay reaches the live positions bit for bit.
3. The animation: a .pvd index and one VTU per frame, which meshio reads,
   with the frame count and times asked for; an OBJ per frame; one glb
   with a morph target per frame, which Khronos' glTF validator passes.
4. A range outside the journal is refused (exit 2), and nothing is written.

Usage: keep_loopback_test.py --server PATH --client PATH --replay PATH
"""

import json
import os
import struct
import subprocess
import sys
import xml.etree.ElementTree as ET

HERE = os.path.dirname(os.path.abspath(__file__))
SOURCE = os.path.abspath(os.path.join(HERE, "..", ".."))
sys.path.insert(0, HERE)
sys.path.insert(0, os.path.join(HERE, "..", "testing"))
from client_loopback_test import Server, run_client  # noqa: E402
from loopback import binary_args, expect, expect_equal, run_in_temp_dir  # noqa: E402

PARTS = [
    # Step 0-300: a stiffer patch with a soft edge, a pull past yield, let
    # go (at step 300: a release moves nothing there).
    "paint sphere=0.2,0.2,0.3,0.15 E=3e6 yield=0.02 strength=1 falloff=0.5\n"
    "drag at=0.2,0.02,0.28 to=0.2,-0.12,0.4 k=1e4 name=pull\n"
    "step 300\nwait\nrelease pull\n",
    # 300-600: the clay keeps its set; bake it, settle.
    "step 200\nwait\nbake\nstep 100\nwait\n",
    # 600-750: a pin on a corner and a second pull.
    "fix sphere=0.4,0.4,0.3,0.06 name=corner\n"
    "drag at=0.2,0.38,0.28 to=0.2,0.5,0.35 k=1e4 name=pull2\n"
    "step 150\nwait\n",
]


def body(path):
    """A scene file without its comments and description."""
    with open(path) as f:
        return [x for x in f.read().splitlines()
                if not x.startswith("#") and not x.startswith("description:")]


def main():
    run_in_temp_dir(run, binary_args("server", "client", "replay"), "dynsolid_keep_test_",
                    keep=bool(os.environ.get("KEEP_TMP")))


def run(args, tmp):
    data = os.path.join(tmp, "data")
    server = Server(args.server, data, os.path.join(tmp, "server.log"))
    os.chdir(tmp)
    try:
        r = run_client(args.client, server.address, "create", "--scene", "clay", "--start_paused")
        expect(r.returncode == 0, "create: %s" % r.stderr)
        session = json.loads(r.stdout)
        ref = ["--id", session["id"], "--token", session["token"]]

        def export(fmt, out, *flags, at=ref):
            r = run_client(args.client, server.address, "export", *at, "--format", fmt, "--out",
                           out, *flags)
            expect(r.returncode == 0, "export %s: %s" % (fmt, r.stderr))
            return json.loads(r.stdout)

        live = {}
        for i, part in enumerate(PARTS):
            script = os.path.join(tmp, "part%d.txt" % i)
            with open(script, "w") as f:
                f.write(part)
            r = run_client(args.client, server.address, "run", "--script", script, *ref,
                           "--noclose", "--nowatch")
            expect(r.returncode == 0, "part %d: %s" % (i, r.stderr))
            first = export("vtu", "live%d.vtu" % i)
            live[int(first["step"])] = "live%d.vtu" % i
        print("live exports at steps %s" % sorted(live))
        expect_equal("steps exported", sorted(live), [300, 600, 750])

        # 1. Save as, and back.
        first = export("scene", "design.textproto")
        expect(first["file_name"].endswith(".textproto"), "file name %r" % first["file_name"])
        with open("design.textproto") as f:
            text = f.read()
        expect(text.startswith("# dynsolid scene: a design saved by Export SCENE"), text[:200])
        for part in ("design {", "inline_mesh {", "control_points:", "floor {", "flow_laws {",
                     "plastic_offsets:"):
            expect(part in text, "the scene file has no %r" % part)
        print("scene file: %d bytes" % len(text))
        r = run_client(args.client, server.address, "create", "--scene_file", "design.textproto",
                       "--start_paused")
        expect(r.returncode == 0, "create from the saved design: %s" % r.stderr)
        again = json.loads(r.stdout)
        export("scene", "again.textproto", at=["--id", again["id"], "--token", again["token"]])
        a, b = body("design.textproto"), body("again.textproto")
        diff = [(i, x, y) for i, (x, y) in enumerate(zip(a, b)) if x != y]
        expect(len(a) == len(b) and not diff,
               "the design saved again differs: %d and %d lines, first differences %r"
               % (len(a), len(b), diff[:3]))
        r = run_client(args.client, server.address, "export", *ref, "--format", "scene",
                       "--level", "3", "--out", "bad.textproto")
        expect(r.returncode == 2 and "request.level: a scene file is saved at the session's level 2"
               in r.stderr, "scene at level 3: %d %s" % (r.returncode, r.stderr))
        expect(not os.path.exists("bad.textproto"), "a refused export wrote a file")
    finally:
        server.stop()

    # 2. The replay reaches the live positions bit for bit.
    session_dir = os.path.join(data, "sessions", session["id"])
    for step, path in sorted(live.items()):
        t = "%.17g" % (step * 1e-3)
        r = subprocess.run([args.replay, "--session", session_dir, "--out", "one%d" % step,
                            "--from", t, "--to", t, "--name", "f"],
                           capture_output=True, text=True, timeout=600)
        expect(r.returncode == 0, "replay at step %d: %s" % (step, r.stderr))
        report = json.loads(r.stdout)
        expect_equal("replayed frame steps", report["steps"], [step])
        with open(path, "rb") as f, open(os.path.join("one%d" % step, "f_0000.vtu"), "rb") as g:
            expect(f.read() == g.read(), "step %d: the replayed VTU differs from the live export"
                   % step)
    print("replayed frames at steps %s equal the live exports byte for byte" % sorted(live))

    # 3. An animation, 20 frames per second over 0.2-0.7 s, read by meshio.
    r = subprocess.run([args.replay, "--session", session_dir, "--out", "anim", "--from", "0.2",
                        "--to", "0.7", "--fps", "20", "--format", "pvd,obj,glb"],
                       capture_output=True, text=True, timeout=600)
    expect(r.returncode == 0, "replay: %s" % r.stderr)
    report = json.loads(r.stdout)
    print("animation: %d frames in %.0f ms" % (report["frames"], report["milliseconds"]))
    expect_equal("frames", report["frames"], 11)
    expect_equal("end step", report["end_step"], 750)
    pvd = [x for x in os.listdir("anim") if x.endswith(".pvd")]
    expect(len(pvd) == 1, "pvd files %r" % pvd)
    sets = ET.parse(os.path.join("anim", pvd[0])).getroot().findall("Collection/DataSet")
    expect_equal("pvd data sets", len(sets), 11)
    objs = [x for x in os.listdir("anim") if x.endswith(".obj")]
    expect_equal("obj frames", len(objs), 11)
    check = (
        "import meshio, sys, json\n"
        "out = []\n"
        "for path in sys.argv[1:]:\n"
        "    m = meshio.read(path)\n"
        "    cd = lambda name: max(float(a.max()) for a in m.cell_data[name])\n"
        "    out.append([len(m.points), sum(len(c.data) for c in m.cells),\n"
        "                float(abs(m.point_data['displacement']).max()),\n"
        "                cd('plastic_strain'), cd('young_modulus'), cd('strain')])\n"
        "print(json.dumps(out))\n")
    files = [os.path.join("anim", s.get("file")) for s in sets]
    m = subprocess.run(["/usr/bin/python3", "-c", check] + files, capture_output=True, text=True,
                       timeout=300)
    expect(m.returncode == 0, "meshio: %s" % m.stderr)
    read = json.loads(m.stdout)
    for k, (s, (points, cells, disp, plastic, young, strain)) in enumerate(zip(sets, read)):
        expect(abs(float(s.get("timestep")) - (0.2 + k / 20)) < 1e-9,
               "frame %d's time %s, asked for %g" % (k, s.get("timestep"), 0.2 + k / 20))
        expect(points > 0 and cells > 0, "frame %d: %d points, %d cells" % (k, points, cells))
    print("meshio read %d frames: %d points, %d cells each; largest displacement %.4f m, "
          "plastic strain %.4f, Young's modulus %.3g Pa, cell strain %.4f"
          % (len(read), read[0][0], read[0][1], max(x[2] for x in read), max(x[3] for x in read),
             max(x[4] for x in read), max(x[5] for x in read)))
    # The clay yielded under the pull (its plastic strain is in the cells),
    # and the painted patch (3 MPa on the 1 MPa clay) shows in the moduli.
    expect(max(x[3] for x in read) > 0, "no plastic strain in any frame")
    expect(2.5e6 < max(x[4] for x in read) <= 3e6 * (1 + 1e-9),
           "the painted modulus: %r" % max(x[4] for x in read))

    # The glTF animation: one file, a morph target per later frame, its
    # key times the frames', valid for Khronos' validator.
    glbs = [x for x in os.listdir("anim") if x.endswith(".glb")]
    expect(len(glbs) == 1, "glb files %r" % glbs)
    with open(os.path.join("anim", glbs[0]), "rb") as f:
        glb = f.read()
    magic, version, length = struct.unpack_from("<4sII", glb, 0)
    expect(magic == b"glTF" and version == 2 and length == len(glb), "glb header")
    (json_length,) = struct.unpack_from("<I", glb, 12)
    gltf = json.loads(glb[20:20 + json_length])
    targets = gltf["meshes"][0]["primitives"][0]["targets"]
    expect_equal("morph targets", len(targets), 10)
    sampler = gltf["animations"][0]["samplers"][0]
    times = gltf["accessors"][sampler["input"]]
    expect_equal("animation key times", times["count"], 11)
    expect(abs(times["min"][0] - 0.2) < 1e-6 and abs(times["max"][0] - 0.7) < 1e-6,
           "key times %r-%r" % (times["min"], times["max"]))
    expect_equal("weights", gltf["accessors"][sampler["output"]]["count"], 11 * 10)
    validator = os.path.join(SOURCE, "tests", "io", "gltf")
    expect(os.path.isdir(os.path.join(validator, "node_modules")),
           "tests/io/gltf/node_modules is missing: run scripts/setup_web.sh")
    v = subprocess.run(["node", os.path.join(validator, "validate.mjs"),
                        os.path.join("anim", glbs[0])], capture_output=True, text=True, timeout=120)
    expect(v.returncode == 0, "glTF validator: %s%s" % (v.stdout, v.stderr))
    print("glb animation: %d bytes, %d morph targets; the glTF validator: %s"
          % (len(glb), len(targets), v.stdout.strip().splitlines()[-1] if v.stdout.strip() else "ok"))

    # 4. Outside the journal: refused, nothing written.
    r = subprocess.run([args.replay, "--session", session_dir, "--out", "late", "--from", "0.5",
                        "--to", "2"], capture_output=True, text=True, timeout=600)
    expect(r.returncode == 2 and "the journal covers [0, 0.75] s" in r.stderr,
           "a range past the end: %d %s" % (r.returncode, r.stderr))
    expect(not os.path.isdir("late") or not os.listdir("late"), "a refused replay wrote files")


if __name__ == "__main__":
    main()
