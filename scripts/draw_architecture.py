#!/usr/bin/python3
"""Draws the project's rooms from its build: docs/architecture.png.

  scripts/draw_architecture.py BUILD_DIR OUT.dot

Reads CMake's file API (codemodel-v2) from a configured BUILD_DIR: every
library and executable of the product (tests, benchmarks and fuzz targets
left out), the folder its CMakeLists.txt lives in, and what it links. The
arrows are the transitive reduction of "links" (a -> c is drawn only when
no a -> b -> c says it already), grouped in boxes by top-level folder
(proto/, solver/, server/, clients/, cmdline/). Writes Graphviz dot;
scripts/architecture.sh renders it. Nothing is hand-drawn: the picture
changes when the CMake targets do.
"""
import glob
import json
import os
import sys

LEFT_OUT = ("tests", "bench")
FOLDERS = ["proto", "cmdline", "solver", "server", "clients"]
COLOURS = {"proto": "#fff4d6", "cmdline": "#eeeeee", "solver": "#dcebff",
           "server": "#ffe0e0", "clients": "#e2f5e0"}


def load(build):
    reply = os.path.join(build, ".cmake", "api", "v1", "reply")
    indexes = sorted(glob.glob(os.path.join(reply, "index-*.json")))
    if not indexes:
        sys.exit("draw_architecture: no CMake file API reply in %s (configure it with a "
                 "codemodel-v2 query first: scripts/architecture.sh does)" % build)
    index = json.load(open(indexes[-1]))
    model = [o for o in index["objects"] if o["kind"] == "codemodel"][0]
    codemodel = json.load(open(os.path.join(reply, model["jsonFile"])))
    targets = {}
    for ref in codemodel["configurations"][0]["targets"]:
        t = json.load(open(os.path.join(reply, ref["jsonFile"])))
        targets[t["id"]] = t
    return targets


def main():
    build, out = sys.argv[1], sys.argv[2]
    targets = load(build)
    keep = {}
    for tid, t in targets.items():
        source = t["paths"]["source"]
        top = source.split("/")[0]
        if top in LEFT_OUT or "fuzz" in t["name"]:
            continue
        if t["type"] not in ("STATIC_LIBRARY", "SHARED_LIBRARY", "EXECUTABLE",
                             "INTERFACE_LIBRARY", "OBJECT_LIBRARY"):
            continue
        if top not in FOLDERS:
            continue
        keep[tid] = t
    deps = {tid: {d["id"] for d in t.get("dependencies", []) if d["id"] in keep}
            for tid, t in keep.items()}

    # Everything reachable from each target.
    reach = {}

    def reachable(tid):
        if tid not in reach:
            reach[tid] = set()
            for d in deps[tid]:
                reach[tid] |= {d} | reachable(d)
        return reach[tid]

    for tid in keep:
        reachable(tid)
    # Transitive reduction.
    edges = []
    for a in keep:
        for c in sorted(deps[a]):
            if not any(c in reach[b] for b in deps[a] if b != c):
                edges.append((a, c))

    def node(tid):
        return '"%s"' % keep[tid]["name"]

    lines = ["digraph dynsolid {",
             '  graph [rankdir=BT, fontname="Helvetica", fontsize=20, nodesep=0.25, '
             'ranksep=0.55, label="dynsolid: CMake targets by folder; an arrow: links '
             '(transitive reduction)", labelloc=t];',
             '  node [fontname="Helvetica", fontsize=12, style="rounded,filled", shape=box, '
             'fillcolor=white];',
             '  edge [color="#555555", arrowsize=0.6];']
    for folder in FOLDERS:
        members = sorted((t["name"], tid) for tid, t in keep.items()
                         if t["paths"]["source"].split("/")[0] == folder)
        if not members:
            continue
        lines.append('  subgraph "cluster_%s" {' % folder)
        lines.append('    label="%s/"; style="filled,rounded"; fillcolor="%s"; color="#999999";'
                     % (folder, COLOURS[folder]))
        for name, tid in members:
            shape = "ellipse" if keep[tid]["type"] == "EXECUTABLE" else "box"
            sub = keep[tid]["paths"]["source"]
            label = name if sub == folder else "%s\\n(%s)" % (name, sub)
            lines.append('    %s [shape=%s, label="%s"];' % (node(tid), shape, label))
        lines.append("  }")
    for a, c in edges:
        lines.append("  %s -> %s;" % (node(a), node(c)))
    lines.append("}")
    with open(out, "w") as f:
        f.write("\n".join(lines) + "\n")
    print("draw_architecture: %d targets, %d arrows (of %d links) -> %s"
          % (len(keep), len(edges), sum(len(d) for d in deps.values()), out))


if __name__ == "__main__":
    main()
