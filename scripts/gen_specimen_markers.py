#!/usr/bin/env python3
"""Generate the SYNTHETIC marker data of a compressed gel cube that `host specimen --measured`
is tested on and that the report's "linear model at large strain" figure is measured against.
Nothing in it is measured: the "measured" positions are the large-deformation reference's
prediction plus a CT voxel's noise. Two files under host/data/:

- specimen-gel-cube-markers.csv: the markers' rest positions (header x,y,z, mm): a 5 x 5 x 5
  grid at 5, 12.5, 20, 27.5 and 35 mm on each axis (125 markers, none on a face);
- specimen-gel-cube-measured.csv: their "measured" positions (header x,y,z, mm), the layout of
  `--measured`: one row per marker and level, level by level in the strain order, the markers
  in the markers file's order (125 x 4 = 500 rows).

The truth (the case the tests and the report re-solve)
------------------------------------------------------
- specimen: the cube [0, 40 mm]^3, `--cells 4` (solved on its symmetric eighth, [0, 20 mm]^3 in
  4 x 4 x 4 cubes, six 10-node tetrahedra each, 729 nodes; the markers mirrored): the generator and every check use this same mesh, so a prediction with the
  truth parameters differs from the data by the noise alone (and the Newton solver's
  tolerance), not by discretisation;
- material: compressible neo-Hookean (`--model large`), E = 5000 Pa, nu = 0.49 (the
  volumetric energy on the element mean, as `host specimen` integrates it above nu 0.45);
- loading: bonded platens, compressed along z from the top (`--axis z --moving max`),
  nominal strains 5, 10, 15 and 20 %.

The noise (a CT's voxel)
------------------------
Voxel 0.3 mm. Each coordinate of each position gets an independent uniform error in
[-0.15, +0.15] mm (a position known to within its voxel): standard deviation
0.3 / sqrt(12) = 0.0866 mm per coordinate, so the expected RMS of a marker's 3-D error is
sqrt(3) x 0.0866 = 0.150 mm. Python's Mersenne Twister, seed 20261208; positions written to
0.0001 mm.

Run from the repository root; `HOST` is the `host` command (default: `cargo run --release -q
-p host --`; the committed files were made with the `checked` profile's binary,
`HOST=target/checked/host`, whose floating-point results are the release build's).
"""

import json
import os
import random
import shlex
import subprocess
import sys
import tempfile

VOXEL_MM = 0.3
SEED = 20261208
STRAINS = [0.05, 0.10, 0.15, 0.20]
GRID_MM = [5.0, 12.5, 20.0, 27.5, 35.0]
ARGS = [
    "specimen", "--box", "0,0,0,40,40,40", "--units", "mm", "--cells", "4",
    "--young", "5000", "--poisson", "0.49", "--axis", "z", "--moving", "max",
    "--platens", "bonded", "--model", "large", "--json",
    "--strain", ",".join(str(s) for s in STRAINS),
]
OUT = "host/data"
HEADER = (
    "# SYNTHETIC, not measured: scripts/gen_specimen_markers.py (host/data/README.md).\n"
    "# 40 mm gel cube, --cells 4, neo-Hookean E = 5000 Pa, nu = 0.49, bonded, along z from\n"
    "# the top, strains 0.05,0.1,0.15,0.2; noise uniform +-0.15 mm per coordinate (0.3 mm\n"
    "# voxel), seed 20261208.\n"
)


def main():
    host = shlex.split(os.environ.get("HOST", "cargo run --release -q -p host --"))
    markers = [(x, y, z) for x in GRID_MM for y in GRID_MM for z in GRID_MM]
    markers_path = os.path.join(OUT, "specimen-gel-cube-markers.csv")
    with open(markers_path, "w") as f:
        f.write(HEADER + "# The markers' rest positions, mm.\nx,y,z\n")
        for p in markers:
            f.write("%g,%g,%g\n" % p)
    out = subprocess.run(host + ARGS + ["--markers", markers_path], check=True,
                         capture_output=True, text=True).stdout
    levels = json.loads(out)["levels"]
    rng = random.Random(SEED)
    half = VOXEL_MM / 2
    rows = []
    for level in levels:
        for p in level["markers"]:
            rows.append([c + rng.uniform(-half, half) for c in p])
    with tempfile.NamedTemporaryFile("w", dir=OUT, delete=False) as f:
        f.write(HEADER + "# Measured positions, mm: 125 markers at each strain, level by"
                " level.\nx,y,z\n")
        for r in rows:
            f.write("%.4f,%.4f,%.4f\n" % tuple(r))
    os.replace(f.name, os.path.join(OUT, "specimen-gel-cube-measured.csv"))
    print("wrote %s and %d measured rows" % (markers_path, len(rows)), file=sys.stderr)


if __name__ == "__main__":
    main()
