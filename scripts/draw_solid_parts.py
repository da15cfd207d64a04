"""Draws the solid's parts from the code: which files of solver/solid use
which part of Solid::Impl, and which of Impl's own members more than one
file touches.

Usage: draw_solid_parts.py OUT.dot OUT.md

It reads the sources as text (no compiler): the data members of
`struct Solid::Impl` in solver/solid/solid_impl.h, then, in every .cc of
solver/solid, the uses of each member: written through an Impl reference
(`im.x`, `impl_->x`, `old.x`, `ip->x`, `impl.x`) anywhere, or bare (`x`)
inside a function of Impl's own (`Solid::Impl::...`). A member whose type
is a class of its own file (a part: LoadSet, SurfacePressure, ...) is
drawn as that part; the others are the members Impl still shares. The
counts are textual: a local variable named like a member inside an Impl
function counts as a use.
"""
import collections
import pathlib
import re
import sys

ROOT = pathlib.Path(__file__).resolve().parent.parent
SOLID = ROOT / "solver" / "solid"

# Members that are parts with their own state and file (the type's header).
PARTS = {
    "loads": ("LoadSet", "load_set.h"),
    "pressure": ("SurfacePressure", "surface_pressure.h"),
    "probe": ("ProbeLoads", "probe_loads.h"),
    "environment": ("contact::ObstacleContact", "contact/obstacle_contact.h"),
    "plasticity": ("material::Plasticity", "material/plasticity.h"),
    "ledger": ("EnergyLedger", "energy_ledger.h"),
}


def impl_members(text):
    """Data member names of struct Solid::Impl (top level of its body)."""
    start = text.index("struct Solid::Impl {")
    i = text.index("{", start) + 1
    depth, line, members = 1, "", []
    body = []
    while depth > 0:
        c = text[i]
        if c == "{":
            depth += 1
        elif c == "}":
            depth -= 1
        if depth == 1 and c not in "{}":
            body.append(c)
        elif depth == 1 and c == "}":
            body.append(";")  # a nested body ends a declaration
        i += 1
    for stmt in "".join(body).split(";"):
        stmt = re.sub(r"//[^\n]*", "", stmt).strip()
        if not stmt or "(" in stmt.split("=")[0] or stmt.startswith(("using", "struct", "static",
                                                                       "friend", "class")):
            continue
        stmt = stmt.split("=")[0].strip()
        # "Points a, b, c" or "std::vector<int> x": the names after the type.
        m = re.match(r"^(?:mutable\s+)?(.+?)\s+([A-Za-z_]\w*(?:\s*,\s*[A-Za-z_]\w*)*)$",
                     re.sub(r"\s+", " ", stmt))
        if not m:
            continue
        for name in m.group(2).split(","):
            members.append(name.strip())
    return members


def functions(text):
    """(name, body) of the function definitions of a file: from a line that
    starts at column 0 and names the function to the next `}` at column 0
    (the project's layout)."""
    out = []
    for m in re.finditer(r"^[^\s#/}][^\n;]*?\b((?:\w+::)+~?\w+)\s*\(", text, re.M):
        end = text.find("\n}", m.start())
        if end < 0:
            continue
        body = text[m.start():end]
        if "{" in body:
            out.append((m.group(1), body))
    return out


def uses(files, members):
    """member -> set of files using it."""
    used = collections.defaultdict(set)
    for f in files:
        text = f.read_text()
        text_nc = re.sub(r"//[^\n]*", "", text)
        for mem in members:
            if re.search(r"(?:\bim|\bimpl_|\bold|\bip|\bimpl|\bs\.impl_|\bout->impl_)"
                         r"(?:\.|->)" + re.escape(mem) + r"\b", text_nc):
                used[mem].add(f.name)
        for fname, body in functions(text_nc):
            if not fname.startswith("Solid::Impl::"):
                continue
            for mem in members:
                if re.search(r"(?<![\.\w>])" + re.escape(mem) + r"\b", body):
                    used[mem].add(f.name)
    return used


def main():
    dot_path, md_path = sys.argv[1], sys.argv[2]
    header = (SOLID / "solid_impl.h").read_text()
    members = impl_members(header)
    files = sorted(SOLID.glob("*.cc"))
    used = uses(files, members)
    shared = [m for m in members if m not in PARTS and len(used[m]) > 1]
    own = [m for m in members if m not in PARTS and len(used[m]) <= 1]

    lines = ["digraph parts {", "  rankdir=LR; nodesep=0.15; ranksep=1.2;",
             '  node [fontname="Helvetica", fontsize=11];']
    sees = [f for f in files if '"solver/solid/solid_impl.h"' in f.read_text()]
    lines.append('  subgraph cluster_files { label="files that include solid_impl.h"; color=gray70;')
    for f in sees:
        lines.append(f'    "{f.name}" [shape=note];')
    lines.append("  }")
    lines.append('  subgraph cluster_apart { label="files that do not"; color=gray70;')
    for f in files:
        if f not in sees:
            lines.append(f'    "{f.name}" [shape=note, color=gray50, fontcolor=gray30];')
    lines.append("  }")
    lines.append('  subgraph cluster_parts { label="parts with their own state"; color=gray40;')
    for mem, (typ, hdr) in PARTS.items():
        if mem in members:
            lines.append(f'    "{mem}" [shape=box, style=filled, fillcolor="#d8ecd8", '
                         f'label="{typ}\\n({hdr})"];')
    lines.append("  }")
    lines.append(f'  "impl" [shape=box, style=filled, fillcolor="#f4e0c8", '
                 f'label="Solid::Impl\\n{len(shared)} members shared by files\\n'
                 f'{len(own)} used by one file or none"];')
    edges = collections.Counter()
    for mem in members:
        for f in used[mem]:
            if mem in PARTS:
                lines.append(f'  "{f}" -> "{mem}";')
            elif mem in shared:
                edges[f] += 1
    for f, n in sorted(edges.items()):
        lines.append(f'  "{f}" -> "impl" [label="{n}", color=gray50, fontsize=9];')
    lines.append("}")
    pathlib.Path(dot_path).write_text("\n".join(lines) + "\n")

    md = ["# Solid::Impl's members and the files that use them", "",
          "Written by `scripts/draw_solid_parts.py` (run by `bash scripts/architecture.sh`) from "
          "the sources, read as text; do not edit by hand. The parts are drawn in "
          "[architecture.md](architecture.md#the-solids-parts).", "",
          "| member | files that use it |", "| --- | --- |"]
    for mem in members:
        label = f"`{mem}` ({PARTS[mem][0]})" if mem in PARTS else f"`{mem}`"
        md.append(f"| {label} | {', '.join(sorted(used[mem])) or '(the header only)'} |")
    md.append("")
    md.append(f"{len(members)} data members: {len([m for m in members if m in PARTS])} parts, "
              f"{len(shared)} other members used by more than one file, {len(own)} by one or none.")
    pathlib.Path(md_path).write_text("\n".join(md) + "\n")
    print(f"solid parts: {len(members)} members, {len(shared)} shared; {dot_path}, {md_path}")


if __name__ == "__main__":
    main()
