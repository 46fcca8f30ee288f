#!/bin/sh
# Rebuilds the Draco fixtures of tests/gltf.rs from grid.gltf (written by make_grid.py)
# with gltf-pipeline (Google's Draco encoder, compiled to WebAssembly: draco3d), from the
# repository's web/node_modules (`cd web && npm install`). The compression levels pick
# the three mesh codings a Draco decoder meets: 0 sequential, 5 EdgeBreaker standard,
# 7 (gltf-pipeline's default) EdgeBreaker valence.
set -e
cd "$(dirname "$0")"
P=../../../../../web/node_modules/.bin/gltf-pipeline
python3 make_grid.py
for cl in 0 5 7; do
    "$P" -i grid.gltf -o "grid-draco-cl$cl.gltf" -d --draco.compressionLevel "$cl"
done
"$P" -i grid.gltf -o grid-draco-fallback.gltf -d --draco.uncompressedFallback
