#!/usr/bin/python3
"""Reads a mesh file with meshio and prints what it holds as JSON.

Used by the io tests to check that files written by dynsolid open in an
independent reader. Run with Debian's /usr/bin/python3 (python3-meshio).

    read_vtu.py FILE [--points N] [--point-sum S] [--cells TYPE=N,...] [--cell-data NAME,...]
                     [--point-data NAME,...] [--cell-data-sum NAME=VALUE,...]
                     [--point-data-sum NAME=VALUE,...] [--expect-arrays JSON_FILE]

Prints {"points": N, "cells": {type: count}, "cell_data": {name: [shape,
sum]}, "point_data": {...}} and exits 1 (with the reasons on stderr) when an
expectation fails, 2 when meshio is missing or cannot read the file.

--expect-arrays names a JSON file {"points": [[x, y, z], ...], "point_data":
{name: [values]}, "faces": [[i, j, k, ...], ...]} that the file must hold
exactly: points as float64, point data as float32 (as PLY stores them), and
the cells, block by block in file order, as those faces.
"""
import argparse
import json
import sys

try:
    import meshio
    import numpy
except ImportError as e:  # pragma: no cover
    print(f"read_vtu.py: {e}: run scripts/setup.sh (python3-meshio)", file=sys.stderr)
    sys.exit(2)


def pairs(text):
    out = {}
    for item in filter(None, (text or "").split(",")):
        key, _, value = item.partition("=")
        out[key] = value
    return out


def names(text):
    return [n for n in (text or "").split(",") if n]


def compare_arrays(mesh, expect_file):
    with open(expect_file) as f:
        expect = json.load(f)
    errors = []
    points = numpy.asarray(mesh.points, dtype=numpy.float64)
    want = numpy.asarray(expect["points"], dtype=numpy.float64)
    if points.shape != want.shape:
        errors.append(f"points: shape {points.shape}, expected {want.shape}")
    elif not numpy.array_equal(points, want):
        i = int(numpy.argwhere(points != want)[0][0])
        errors.append(f"point {i} is {points[i].tolist()}, expected {want[i].tolist()}")
    for name, values in expect.get("point_data", {}).items():
        if name not in mesh.point_data:
            errors.append(f"point data '{name}' missing (have {sorted(mesh.point_data)})")
            continue
        got = numpy.asarray(mesh.point_data[name])
        want = numpy.asarray(values, dtype=numpy.float32)
        if got.dtype != numpy.float32:
            errors.append(f"point data '{name}' is {got.dtype}, expected float32")
        elif got.shape != want.shape or not numpy.array_equal(got, want):
            errors.append(f"point data '{name}' is {got.tolist()}, expected {want.tolist()}")
    faces = [list(map(int, row)) for block in mesh.cells for row in block.data]
    if faces != expect.get("faces", faces):
        errors.append(f"faces are {faces}, expected {expect['faces']}")
    return errors


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("file")
    parser.add_argument("--points", type=int)
    parser.add_argument("--point-sum", type=float)
    parser.add_argument("--cells")
    parser.add_argument("--cell-data")
    parser.add_argument("--point-data")
    parser.add_argument("--cell-data-sum")
    parser.add_argument("--point-data-sum")
    parser.add_argument("--expect-arrays")
    args = parser.parse_args()

    try:
        mesh = meshio.read(args.file)
    except Exception as e:  # meshio raises many kinds
        print(f"read_vtu.py: meshio cannot read {args.file}: {e!r}", file=sys.stderr)
        sys.exit(2)

    cells = {}
    for block in mesh.cells:
        cells[block.type] = cells.get(block.type, 0) + len(block.data)
    cell_data = {}
    for name, blocks in mesh.cell_data.items():
        values = numpy.concatenate([numpy.asarray(b) for b in blocks])
        cell_data[name] = [list(values.shape), float(values.sum())]
    point_data = {
        name: [list(numpy.asarray(v).shape), float(numpy.asarray(v).sum())]
        for name, v in mesh.point_data.items()
    }
    result = {
        "points": int(len(mesh.points)),
        "point_sum": float(numpy.asarray(mesh.points).sum()),
        "cells": cells,
        "cell_data": cell_data,
        "point_data": point_data,
    }
    print(json.dumps(result, sort_keys=True))

    errors = []
    if args.points is not None and result["points"] != args.points:
        errors.append(f"points: expected {args.points}, got {result['points']}")
    if args.point_sum is not None and abs(result["point_sum"] - args.point_sum) > 1e-9 * max(
        1.0, abs(args.point_sum)
    ):
        errors.append(f"sum of coordinates: expected {args.point_sum}, got {result['point_sum']}")
    for cell_type, count in pairs(args.cells).items():
        if cells.get(cell_type, 0) != int(count):
            errors.append(f"cells {cell_type}: expected {count}, got {cells.get(cell_type, 0)}")
    expected_total = sum(int(c) for c in pairs(args.cells).values())
    if args.cells is not None and sum(cells.values()) != expected_total:
        errors.append(f"cells: expected only {args.cells}, got {cells}")
    for name in names(args.cell_data):
        if name not in cell_data:
            errors.append(f"cell data '{name}' missing (have {sorted(cell_data)})")
    for name in names(args.point_data):
        if name not in point_data:
            errors.append(f"point data '{name}' missing (have {sorted(point_data)})")
    for name, value in pairs(args.cell_data_sum).items():
        got = cell_data.get(name, [None, None])[1]
        if got is None or abs(got - float(value)) > 1e-9 * max(1.0, abs(float(value))):
            errors.append(f"cell data '{name}' sum: expected {value}, got {got}")
    for name, value in pairs(args.point_data_sum).items():
        got = point_data.get(name, [None, None])[1]
        if got is None or abs(got - float(value)) > 1e-6 * max(1.0, abs(float(value))):
            errors.append(f"point data '{name}' sum: expected {value}, got {got}")
    if args.expect_arrays:
        errors += compare_arrays(mesh, args.expect_arrays)
    if errors:
        for e in errors:
            print(f"read_vtu.py: {e}", file=sys.stderr)
        sys.exit(1)


if __name__ == "__main__":
    main()
