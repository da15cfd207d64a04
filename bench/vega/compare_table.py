#!/usr/bin/python3
"""The VegaFEM comparison (bench/reports/scaling.md): turns compare.sh's raw
lines into markdown tables (and a plot).

  compare_table.py RAW [--plot=FILE.png]

RAW lines (written by compare.sh):
  vega n=12 integrator=central dofs=.. free_dofs=.. ms_per_step=.. build_s=.. peak_mb=.. top_dx=..
  dynsolid_row | 12^3 | 6591 | factored | build s | ms/step | solve | ms/sim s | us/DOF | substeps | MB | top dx mm |
(scaling_bench's table rows; top dx: the top face's mean x displacement after the run)
"""
import sys

DYN = ["factored", "cg", "backward_euler"]
VEGA = ["central", "backward_euler"]
# Which Vega integrator each dynsolid solver is set against.
PAIR = {"factored": "central", "cg": "central", "backward_euler": "backward_euler"}


def kv(line):
    return dict(tok.split("=", 1) for tok in line.split()[1:] if "=" in tok)


def parse(path):
    vega, dyn, dyn_dx, header = {}, {}, {}, ""
    for line in open(path):
        line = line.strip()
        if line.startswith("#"):
            header = line[1:].strip()
        elif line.startswith("vega "):
            d = kv(line)
            vega[(int(d["n"]), d["integrator"])] = d
        elif line.startswith("dynsolid_row "):
            c = [x.strip() for x in line[len("dynsolid_row "):].strip("|").split("|")]
            if len(c) < 10:
                continue
            n = int(c[0].split("^")[0])
            dyn[(n, c[2])] = {"dofs": c[1], "build_s": float(c[3]), "ms": float(c[4]),
                              "solve_ms": float(c[5]), "substeps": c[8], "peak_mb": float(c[9])}
            if len(c) >= 11 and c[10]:
                dyn_dx[(n, c[2])] = float(c[10]) / 1000.0  # mm -> m, as Vega's
    return vega, dyn, dyn_dx, header


def f(x, fmt="%.3f"):
    return "-" if x is None else fmt % x


def main():
    args = [a for a in sys.argv[1:] if not a.startswith("--plot=")]
    plot = next((a[7:] for a in sys.argv[1:] if a.startswith("--plot=")), None)
    vega, dyn, dyn_dx, header = parse(args[0])
    sizes = sorted({k[0] for k in vega} | {k[0] for k in dyn})

    def v(n, integ, key):
        d = vega.get((n, integ))
        return float(d[key]) if d and key in d else None

    def dy(n, solver, key):
        d = dyn.get((n, solver))
        return d[key] if d else None

    def ratio(a, b):
        return None if a is None or b is None or b == 0 else a / b

    def dofs(n):
        d = vega.get((n, "central")) or vega.get((n, "backward_euler"))
        if d:
            return "%s (%s free)" % (d["dofs"], d["free_dofs"])
        return dy(n, "factored", "dofs") or "-"

    out = []
    if header:
        out.append("Run: " + header + "\n")
    out.append("Time per step (median ms; ratio = Vega / dynsolid, > 1 means dynsolid is faster)\n")
    out.append("| n | DOFs | dynsolid factored | dynsolid cg | dynsolid BE | Vega central | Vega BE "
               "| Vega central / factored | Vega central / cg | Vega BE / dynsolid BE |")
    out.append("| ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |")
    for n in sizes:
        row = [dy(n, s, "ms") for s in DYN] + [v(n, i, "ms_per_step") for i in VEGA]
        out.append("| %d^3 | %s | %s | %s | %s | %s | %s | %s | %s | %s |" % (
            n, dofs(n), *[f(x) for x in row],
            f(ratio(row[3], row[0]), "%.2f"), f(ratio(row[3], row[1]), "%.2f"),
            f(ratio(row[4], row[2]), "%.2f")))

    out.append("\nBuild time (s) and peak resident memory (VmHWM, MB), one process per solver "
               "or integrator; ratio = dynsolid / Vega of the paired integrator "
               "(factored and cg against central, BE against BE; target <= 2)\n")
    out.append("| n | build dynsolid factored / cg / BE | build Vega central / BE | build ratio "
               "factored / cg / BE | peak MB dynsolid factored / cg / BE | peak MB Vega central / BE "
               "| memory ratio factored / cg / BE |")
    out.append("| ---: | ---: | ---: | ---: | ---: | ---: | ---: |")
    for n in sizes:
        bd = [dy(n, s, "build_s") for s in DYN]
        bv = {i: v(n, i, "build_s") for i in VEGA}
        md = [dy(n, s, "peak_mb") for s in DYN]
        mv = {i: v(n, i, "peak_mb") for i in VEGA}
        out.append("| %d^3 | %s | %s | %s | %s | %s | %s |" % (
            n, " / ".join(f(x, "%.2f") for x in bd),
            " / ".join(f(bv[i], "%.2f") for i in VEGA),
            " / ".join(f(ratio(bd[k], bv[PAIR[s]]), "%.1f") for k, s in enumerate(DYN)),
            " / ".join(f(x, "%.0f") for x in md),
            " / ".join(f(mv[i], "%.0f") for i in VEGA),
            " / ".join(f(ratio(md[k], mv[PAIR[s]]), "%.1f") for k, s in enumerate(DYN))))

    out.append("\nTop face's mean x displacement (mm) after warm-up + measured steps; "
               "difference = dynsolid / Vega - 1 of the paired integrator\n")
    out.append("| n | dynsolid factored | dynsolid cg | Vega central | diff factored | dynsolid BE "
               "| Vega BE | diff BE |")
    out.append("| ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |")
    for n in sizes:
        dx = {s: dyn_dx.get((n, s)) for s in DYN}
        vx = {i: v(n, i, "top_dx") for i in VEGA}
        mm = lambda x: None if x is None else 1000 * x
        diff = lambda a, b: None if a is None or b is None or b == 0 else 100 * (a / b - 1)
        out.append("| %d^3 | %s | %s | %s | %s | %s | %s | %s |" % (
            n, f(mm(dx["factored"]), "%.4f"), f(mm(dx["cg"]), "%.4f"),
            f(mm(vx["central"]), "%.4f"), f(diff(dx["factored"], vx["central"]), "%+.2f %%"),
            f(mm(dx["backward_euler"]), "%.4f"), f(mm(vx["backward_euler"]), "%.4f"),
            f(diff(dx["backward_euler"], vx["backward_euler"]), "%+.2f %%")))
    print("\n".join(out))

    if plot:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 4.2))
        xs = {n: int(dofs(n).split()[0]) for n in sizes}
        series = [("dynsolid factored (CD)", lambda n: dy(n, "factored", "ms"),
                   lambda n: dy(n, "factored", "peak_mb"), "C0", "o-"),
                  ("dynsolid cg (CD)", lambda n: dy(n, "cg", "ms"),
                   lambda n: dy(n, "cg", "peak_mb"), "C1", "o-"),
                  ("dynsolid backward Euler", lambda n: dy(n, "backward_euler", "ms"),
                   lambda n: dy(n, "backward_euler", "peak_mb"), "C2", "o-"),
                  ("Vega central differences", lambda n: v(n, "central", "ms_per_step"),
                   lambda n: v(n, "central", "peak_mb"), "C3", "s--"),
                  ("Vega backward Euler", lambda n: v(n, "backward_euler", "ms_per_step"),
                   lambda n: v(n, "backward_euler", "peak_mb"), "C4", "s--")]
        for label, t, m, color, style in series:
            pts = [(xs[n], t(n), m(n)) for n in sizes if t(n) is not None]
            if not pts:
                continue
            a1.plot([p[0] for p in pts], [p[1] for p in pts], style, color=color, label=label)
            a2.plot([p[0] for p in pts], [p[2] for p in pts], style, color=color, label=label)
        for a, title, unit in ((a1, "time per step", "ms per step (median)"),
                               (a2, "peak resident memory", "VmHWM (MB)")):
            a.set_xscale("log")
            a.set_yscale("log")
            a.set_xlabel("DOFs (3 (n+1)^3)")
            a.set_ylabel(unit)
            a.set_title(title)
            a.grid(True, which="both", alpha=0.3)
        a1.legend(fontsize=8)
        fig.suptitle("Block n^3, h = 1 ms: dynsolid (2 threads) vs VegaFEM (1 thread), 2-core VM",
                     fontsize=10)
        fig.tight_layout()
        fig.savefig(plot, dpi=110)


if __name__ == "__main__":
    main()
