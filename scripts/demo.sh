#!/usr/bin/env bash
# Set up lodconvert with pip alone and convert the bundled sample to X3D and glTF.
source "$(dirname "$0")/_env.sh"
make_venv ""
mkdir -p out
.venv/bin/lodconvert samples/torus_knot.ply -o out/torus_knot.x3d --report out/torus_knot.x3d.json
.venv/bin/lodconvert samples/torus_knot.ply -o out/torus_knot.glb --report out/torus_knot.glb.json
ls -l out/
echo "lodconvert is in .venv, not on PATH: run .venv/bin/lodconvert, or 'source .venv/bin/activate' first"
