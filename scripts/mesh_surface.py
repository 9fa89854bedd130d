#!/usr/bin/env python3
"""Tetrahedral mesh of the volume inside a closed triangulated surface, with Gmsh.

Run by ``host mesh`` (the binary embeds this file and runs it with ``python3``); not meant to be
called by hand.  The one argument is a JSON job file written by the Rust side, which has
already checked the surface (closed, manifold, oriented, one shell, no self-intersection),
scaled it to metres and, with ``--refine-near``, computed the points the scene's tool can
reach (``host/haptic/src/reach.rs``):

    {"surface": "in.stl", "output": "out.msh", "size": 0.008, "fine": 0.003,
     "gradient": 0.3, "reach_points": [[x, y, z], ...], "feature_angle_deg": 40}

The surface is remeshed (``classifySurfaces`` + ``createGeometry``, Gmsh's recipe for STL
input), then the volume: Frontal-Delaunay surfaces, Delaunay volume, Gmsh and Netgen
optimisation (``Mesh.Optimize``, ``Mesh.OptimizeNetgen``: they remove most slivers; the Rust
side measures what is left).  The size at x is ``min(size, fine + gradient * d(x))`` with
d the distance to the nearest reachable point (numpy, brute force), or ``size`` everywhere.
Single-threaded with a fixed seed: reruns give the same mesh.  Writes MSH 4.1 ASCII to
``output`` (a temporary file; the Rust side validates it and writes the final file
atomically).  Progress goes to stderr.

Gmsh is pinned to 4.15.2 (``pip install gmsh==4.15.2``; ``scripts/test-all.sh`` installs it).
"""

import json
import math
import sys
import time

import gmsh
import numpy as np

GMSH_VERSION = "4.15.2"


def main():
    job = json.load(open(sys.argv[1]))
    t0 = time.time()

    def say(msg):
        print(f"  gmsh [{time.time() - t0:5.1f} s] {msg}", file=sys.stderr, flush=True)

    if gmsh.__version__ != GMSH_VERSION:
        say(f"warning: gmsh {gmsh.__version__}, not the pinned {GMSH_VERSION}")
    size = float(job["size"])
    fine = job.get("fine")
    gradient = float(job.get("gradient") or 0.3)
    reach = np.asarray(job.get("reach_points") or [], dtype=float).reshape(-1, 3)

    gmsh.initialize()
    try:
        opt = gmsh.option.setNumber
        opt("General.Terminal", 1)
        opt("General.Verbosity", 2)
        opt("General.NumThreads", 1)
        opt("Mesh.RandomSeed", 1)
        gmsh.merge(job["surface"])
        say("classifying the surface into patches")
        angle = math.radians(float(job.get("feature_angle_deg", 40)))
        gmsh.model.mesh.classifySurfaces(angle, True, True, math.pi)
        gmsh.model.mesh.createGeometry()
        surfaces = [t for _, t in gmsh.model.getEntities(2)]
        loop = gmsh.model.geo.addSurfaceLoop(surfaces)
        gmsh.model.geo.addVolume([loop])
        gmsh.model.geo.synchronize()

        if fine is not None and len(reach):
            fine = float(fine)

            def size_at(dim, tag, x, y, z, lc):
                d2 = np.min(np.sum((reach - (x, y, z)) ** 2, axis=1))
                return min(size, fine + gradient * math.sqrt(d2))

            gmsh.model.mesh.setSizeCallback(size_at)
            opt("Mesh.MeshSizeMin", fine)
        else:
            opt("Mesh.MeshSizeMin", size)
        opt("Mesh.MeshSizeMax", size)
        opt("Mesh.MeshSizeFromPoints", 0)
        opt("Mesh.MeshSizeFromCurvature", 0)
        opt("Mesh.MeshSizeExtendFromBoundary", 0)
        opt("Mesh.Algorithm", 6)
        opt("Mesh.Algorithm3D", 1)
        opt("Mesh.Optimize", 1)
        opt("Mesh.OptimizeNetgen", 1)
        say("meshing the surface")
        gmsh.model.mesh.generate(2)
        say("meshing the volume and optimising (Gmsh, Netgen)")
        gmsh.model.mesh.generate(3)
        opt("Mesh.MshFileVersion", 4.1)
        opt("Mesh.Binary", 0)
        gmsh.write(job["output"])
        say("done")
    finally:
        gmsh.finalize()


if __name__ == "__main__":
    main()
