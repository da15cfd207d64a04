#!/usr/bin/python3
"""Summarises dynsolid-sim stats.json files as a Table-1 style markdown table.

usage: summarize.py OUT_DIR scene [scene ...]
"""
import json
import os
import sys


def main():
    out, scenes = sys.argv[1], sys.argv[2:]
    print("| scene | #CC | levels | cells | nodes | #FE | %BE | %LE | %PE | boundary Euler "
          "| steps | ms/step | substeps | CG iters/step | kinetic J | strain J |")
    print("| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: "
          "| ---: | ---: | ---: | ---: | ---: | ---: |")
    for s in scenes:
        with open(os.path.join(out, s, "stats.json")) as f:
            j = json.load(f)
        e, p = j["elements"], j["fractions_percent"]
        fe = e["cubic"] + e["linear"] + e["pyramid"]
        row = (f"| {s} | {j['control_cells']} | {j['levels']} | {j['cells']} | {j['nodes']} "
               f"| {fe} | {p['cubic']:.1f} | {p['linear']:.1f} | {p['pyramid']:.1f} "
               f"| {j['boundary']['euler_characteristic']} ")
        if j.get("steps", 0) > 0:
            row += (f"| {j['steps']} | {j['ms_per_step']:.3f} | {j['dynamics']['substeps']} "
                    f"| {j['cg_iterations']['mean_per_step']:.1f} "
                    f"| {j['energy_j']['kinetic']:.4g} | {j['energy_j']['strain']:.4g} |")
        else:
            row += "| 0 (not stepped) | | | | | |"
        print(row)


if __name__ == "__main__":
    main()
