#!/usr/bin/env bash
# Regenerates the seed corpora the targets make themselves (each target
# writes its seeds when DYNSOLID_FUZZ_WRITE_SEEDS names a directory), from
# a built fuzz tree (scripts/fuzz_smoke.sh builds it). The mesh_reader
# seeds are the test meshes with a first byte choosing the reader; the
# script seeds are clients/scripts/*.txt.
#   tests/fuzz/make_seeds.sh
set -euo pipefail
cd "$(dirname "$0")/../.."
BIN=build/fuzz/tests/fuzz
for name in scene journal solid_state surface_decoder command; do
  mkdir -p "tests/fuzz/corpus/$name"
  DYNSOLID_FUZZ_WRITE_SEEDS="tests/fuzz/corpus/$name" "$BIN/${name}_fuzz" >/dev/null 2>&1
done
out=tests/fuzz/corpus/mesh_reader
mkdir -p "$out"
for f in tests/io/data/*.msh scenes/meshes/*.msh; do
  { printf '\000'; cat "$f"; } > "$out/$(basename "$f")"
done
for f in tests/io/data/*.vtk scenes/meshes/*.vtk; do
  { printf '\001'; cat "$f"; } > "$out/$(basename "$f")"
done
mkdir -p tests/fuzz/corpus/script
cp clients/scripts/*.txt tests/fuzz/corpus/script/
ls tests/fuzz/corpus/*/
