#!/usr/bin/env bash
# The demo: preprocess the bundled Armadillo (Stanford scan, CGAL data, CC0),
# inspect the hierarchy, export the base mesh and check that recovering every
# node gives back the original mesh.
set -euo pipefail
BUILD=${1:-build}
cd "$(dirname "$0")/.."
OUT=out/demo
mkdir -p "$OUT"
FILIGREE="$BUILD/client/filigree"

echo "== preprocess data/armadillo.off"
"$FILIGREE" preprocess data/armadillo.off -o "$OUT/armadillo.fgh"
echo
echo "== inspect"
"$FILIGREE" inspect "$OUT/armadillo.fgh"
echo
echo "== export"
"$FILIGREE" export-base "$OUT/armadillo.fgh" -o "$OUT/armadillo_base.glb" --ids "$OUT/armadillo_base_ids.txt"
"$FILIGREE" export-base "$OUT/armadillo.fgh" -o "$OUT/armadillo_base.obj"
"$FILIGREE" export-cut "$OUT/armadillo.fgh" --recover 10000 -o "$OUT/armadillo_cut10000.obj"
"$FILIGREE" export-cut "$OUT/armadillo.fgh" --recover all -o "$OUT/armadillo_full.ply"
echo
echo "Demo outputs are in $OUT/ (base mesh as GLB/OBJ, a partial cut, the fully recovered mesh)."
