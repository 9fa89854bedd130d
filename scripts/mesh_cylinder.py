#!/usr/bin/env python3
"""Tetrahedral mesh of one eighth of a cylinder (a quarter of the disc, half the height), with
Gmsh.

Run by ``host specimen --cylinder`` (the binary embeds this file and runs it with ``python3``
or ``$HOST_PYTHON``); not meant to be called by hand.  The one argument is a JSON job file
written by the Rust side, in metres:

    {"radius": 0.01, "half_height": 0.005, "size": 0.002, "output": "part.msh"}

The part is ``x >= 0, y >= 0, 0 <= z <= half_height`` of the cylinder of that radius about the
z axis (OpenCASCADE's cylinder with a 90 degree opening angle): its faces on x = 0, y = 0 and
z = 0 are the specimen's symmetry planes, which the Rust side mirrors the part across.  Element
size ``size`` everywhere (``Mesh.MeshSizeMin`` = ``Mesh.MeshSizeMax``), Frontal-Delaunay
surfaces, Delaunay volume, Gmsh and Netgen optimisation.  Single-threaded with a fixed seed:
reruns give the same mesh.  Writes MSH 4.1 ASCII (linear tetrahedra only) to ``output``.
Progress goes to stderr.

Gmsh is pinned to 4.15.2 (``pip install gmsh==4.15.2``; ``scripts/test-all.sh`` installs it).
"""

import json
import math
import sys
import time

import gmsh

GMSH_VERSION = "4.15.2"


def main():
    job = json.load(open(sys.argv[1]))
    t0 = time.time()

    def say(msg):
        print(f"  gmsh [{time.time() - t0:5.1f} s] {msg}", file=sys.stderr, flush=True)

    if gmsh.__version__ != GMSH_VERSION:
        say(f"warning: gmsh {gmsh.__version__}, not the pinned {GMSH_VERSION}")
    radius = float(job["radius"])
    half = float(job["half_height"])
    size = float(job["size"])
    gmsh.initialize()
    try:
        opt = gmsh.option.setNumber
        opt("General.Terminal", 1)
        opt("General.Verbosity", 2)
        opt("General.NumThreads", 1)
        opt("Mesh.RandomSeed", 1)
        opt("Mesh.MeshSizeMin", size)
        opt("Mesh.MeshSizeMax", size)
        opt("Mesh.MeshSizeFromPoints", 0)
        opt("Mesh.MeshSizeExtendFromBoundary", 0)
        opt("Mesh.Algorithm", 6)
        opt("Mesh.Algorithm3D", 1)
        opt("Mesh.Optimize", 1)
        opt("Mesh.OptimizeNetgen", 1)
        opt("Mesh.MshFileVersion", 4.1)
        opt("Mesh.Binary", 0)
        gmsh.model.add("cylinder_part")
        gmsh.model.occ.addCylinder(0, 0, 0, 0, 0, half, radius, angle=math.pi / 2)
        gmsh.model.occ.synchronize()
        volumes = gmsh.model.getEntities(3)
        gmsh.model.addPhysicalGroup(3, [t for _, t in volumes], 1)
        say(f"meshing the eighth cylinder r {radius} m, half height {half} m at {size} m")
        gmsh.model.mesh.generate(3)
        gmsh.write(job["output"])
        say("written")
    finally:
        gmsh.finalize()


if __name__ == "__main__":
    main()
