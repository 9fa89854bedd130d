#!/usr/bin/env python3
"""Generate the tetrahedral meshes shipped in ``host/meshes/`` (reproducibly).

What
----
Linear (P1) tetrahedral meshes, units METRES, written as Gmsh MSH 4.1 (ASCII for
the small meshes, binary for the big ones):

=====================  ==========  =======================================================
file                   ~nodes      geometry
=====================  ==========  =======================================================
liver-1k4.msh          1,394       liver-like organ (paper's mesh size: 1,394 nodes, 6,342 tets)
liver-10k.msh          10,000      same shape, finer (binary)
cylinder-2k.msh        2,000       compression cylinder r = 0.01, h = 0.02, axis z, z in [0, 0.02]
cylinder-10k.msh       10,000      same cylinder, finer (binary)
brain-specimen.msh     2,000       Miller & Chinzei's brain specimen: cylinder r = 0.015, h = 0.013
beam.msh               1,500       cantilever beam [0, 0.1] x [-0.005, 0.005]^2 (unstructured)
generated/liver-100k   100,000     liver, only with ``--only liver-100k`` (binary, git-ignored)
liver-reach-4mm.msh    4,751       liver graded: 4 mm in the tool's reach, up to 8 mm elsewhere (binary)
liver-reach-2.8mm.msh  11,667      same, 2.8 mm in the reach (binary)
generated/...-2mm      27,742      same, 2 mm (6.5 MB, binary, git-ignored like all below)
generated/...-1.4mm    71,605      same, 1.4 mm (17 MB)
generated/...-1mm      177,760     same, 1 mm (44 MB; ~5.5 min, 0.8 GB)
generated/liver-reach-scaled-<h>mm   the reference series: liver-reach-4mm's whole size field
                       scaled by h / 4 mm (gradient and cap too), h = 2.8, 2, 1.4, 1 mm:
                       12,351 / 30,830 / 83,584 / 218,467 nodes, 85 MB in all (1 mm: 18 min on
                       a loaded 2-core machine); ``--reach-series scaled``
=====================  ==========  =======================================================

The ``liver-reach-<h>mm`` family: FEM meshes for the patch-compliance samples of the
default scene and its convergence study (fine in the tool's reach).  Same organ; mesh
size h_fine in the *fine zone*, the points within ZONE_BAND = 10 mm of the boundary that
are also within tip radius + reach margin + 10 mm (3 + 2 + 10 mm) of the tip's workspace
of ``host/scenes/liver.toml`` (trocar at (0, 0, 0.16) m, shaft along -z at rest, pitch and
yaw in [-0.35, 0.35] rad, insertion in [0.03, 0.14] m), measured as ``host/haptic/src/reach.rs``
does (``sector_distance``).  Away from the zone the size grows by 0.3 mm per mm of
distance from it, up to 8 mm.  Gmsh size fields: a ``Distance`` field to the boundary
surfaces and a ``MathEval`` field of it and x, y, z (``_reach_size_field``).  No
node-count target (the size is the parameter); Delaunay surface meshing (see
``REACH_SURFACE_ALGORITHM``); binary when the ASCII file would exceed 0.5 MB.  The script
prints, for each, the boundary edge lengths inside the fine zone (mean, min, max) and the
number of free surface nodes in the reachable region.

The liver-like organ is a smooth closed body about 0.14 x 0.09 x 0.07 m: a big
right lobe (ellipsoid, +x side) fused with a smaller, thinner left lobe (ellipsoid,
-x side), the crease between them rounded by a fillet, and the underside cut flat
at z = 0 with a filleted rim.  Its bounding box is x in [-0.07, 0.07],
y in [-0.045, 0.045], z in [0, 0.07], so ``z <= 0.01`` selects a broad "bed" of
nodes under the right lobe that scenes fix.  The cylinder and the beam are
meshed with unstructured tetrahedra (so e.g. the cylinder's side facets are
slightly tilted, unlike a structured mesh).

Each file contains only the 3-D tetrahedra (one discrete volume entity) and
exactly the nodes they reference, renumbered 1..N in Gmsh's node order (the Rust
reader rejects unreferenced nodes; boundary triangles are not written -- the
reader would ignore them anyway).  All tetrahedra are positively oriented:
``(x1-x0) . ((x2-x0) x (x3-x0)) > 0``.

How to run
----------
Requires the ``gmsh`` Python module, version 4.15.2 (``pip install gmsh==4.15.2``),
and numpy::

    python3 scripts/gen_meshes.py                      # all default meshes -> host/meshes/
    python3 scripts/gen_meshes.py --only liver-1k4     # one mesh
    python3 scripts/gen_meshes.py --only liver-100k    # -> host/meshes/generated/ (git-ignored)
    python3 scripts/gen_meshes.py --liver-nodes 30000  # -> host/meshes/generated/liver-30000.msh
    python3 scripts/gen_meshes.py --reach-series       # the committed liver-reach-*mm meshes
    python3 scripts/gen_meshes.py --reach-series all   # all of them (2, 1.4, 1 mm -> generated/)
    python3 scripts/gen_meshes.py --only liver-reach-1mm   # one of them
    python3 scripts/gen_meshes.py --reach-series scaled    # the reference series (generated/)

The default run (no option) generates the first six rows of the table above (not
liver-100k, not the liver-reach family).

Reproducibility
---------------
Gmsh is pinned to 4.15.2 (a different version prints a warning and may give a
different mesh), meshing runs single-threaded (``General.NumThreads = 1``) with
a fixed ``Mesh.RandomSeed``, and the mesh size of each file is pinned (the table
in ``MESHES``; ``REACH_SERIES`` for the graded livers).  With these settings,
re-running the script gives byte-identical files.  If the pinned size does not
give a node count within +-3 % of the target (e.g. another Gmsh version), the
size is re-tuned deterministically, h <- h * (nodes / target)^(1/3), and the
chosen size is printed (not for the graded livers: they have no target).  The
script then checks the node count (and for liver-1k4 the tet count) is within
+-10 % of the target (again not for the graded livers), that no tetrahedron has
a non-positive volume, that every node is referenced, that no triangle face is
shared by more than two tetrahedra, and re-reads each written file to compare
counts, coordinates and orientation.

Meshing: Frontal-Delaunay surfaces (``Mesh.Algorithm = 6``; Delaunay, 5, for the
liver-reach family), Delaunay volume (``Mesh.Algorithm3D = 1``) with Gmsh and Netgen
optimisation (``Mesh.Optimize = 1``, ``Mesh.OptimizeNetgen = 1``), target size h
(uniform, graded for liver-1k4: see ``MESHES``, or the liver-reach size field).  Node
coordinates are rounded to 1e-12 m.  Takes ~30 s for the default set; liver-100k ~2 min
and 0.5 GB; ``--reach-series`` ~15 s, ``--reach-series all`` ~7.5 min.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

try:
    import gmsh
except ImportError:  # pragma: no cover
    sys.exit("error: the gmsh Python module is required: pip install gmsh==4.15.2")

GMSH_VERSION = "4.15.2"
RANDOM_SEED = 1  # Mesh.RandomSeed (fixed)

# ---------------------------------------------------------------------------------------------
# Geometry (OpenCASCADE kernel).  Each builder creates exactly one volume and returns its tag.
# ---------------------------------------------------------------------------------------------

# Liver-like organ, final coordinates (metres).
RIGHT_LOBE_CENTRE = (0.018, 0.0, 0.029)
RIGHT_LOBE_SEMI_AXES = (0.052, 0.045, 0.041)  # x max = 0.07, z from -0.012 (cut at 0) to 0.07
LEFT_LOBE_CENTRE = (-0.025, 0.010, 0.037)
LEFT_LOBE_SEMI_AXES = (0.045, 0.034, 0.021)  # x min = -0.07
CREASE_FILLET = 0.013  # rounds the crease where the two lobes meet
UNDERSIDE_Z = 0.0  # the underside is cut flat here ...
UNDERSIDE_FILLET = 0.008  # ... and its rim rounded with this radius


def _ellipsoid(occ, centre, semi_axes):
    tag = occ.addSphere(*centre, 1.0)
    occ.dilate([(3, tag)], *centre, *semi_axes)
    return tag


def _edges_of(vol):
    surfs = gmsh.model.getBoundary([(3, vol)], combined=False, oriented=False)
    return sorted({e for _, e in gmsh.model.getBoundary(surfs, combined=False, oriented=False)})


def build_liver() -> int:
    occ = gmsh.model.occ
    right = _ellipsoid(occ, RIGHT_LOBE_CENTRE, RIGHT_LOBE_SEMI_AXES)
    left = _ellipsoid(occ, LEFT_LOBE_CENTRE, LEFT_LOBE_SEMI_AXES)
    fused, _ = occ.fuse([(3, right)], [(3, left)])
    occ.synchronize()
    assert len(fused) == 1, f"lobe fusion gave {fused}"
    vol = fused[0][1]
    # Crease: curves bounding two different surfaces (one of each lobe); seams bound only one.
    crease = [e for e in _edges_of(vol) if len(set(gmsh.model.getAdjacencies(1, e)[0])) == 2]
    assert crease, "no crease curve between the lobes"
    filleted = occ.fillet([vol], crease, [CREASE_FILLET])
    occ.synchronize()
    vol = filleted[0][1]
    # Flat underside.
    box = occ.addBox(-1.0, -1.0, UNDERSIDE_Z - 2.0, 2.0, 2.0, 2.0)
    cut, _ = occ.cut([(3, vol)], [(3, box)])
    occ.synchronize()
    assert len(cut) == 1, f"underside cut gave {cut}"
    vol = cut[0][1]
    rim = []
    for e in _edges_of(vol):
        b = occ.getBoundingBox(1, e)
        # (OCC bounding boxes are padded by ~1e-4 m.)
        if abs(b[2] - UNDERSIDE_Z) < 5e-4 and abs(b[5] - UNDERSIDE_Z) < 5e-4:
            rim.append(e)
    assert rim, "no rim curve on the flat underside"
    filleted = occ.fillet([vol], rim, [UNDERSIDE_FILLET])
    occ.synchronize()
    assert len(filleted) == 1
    return filleted[0][1]


def build_cylinder() -> int:
    tag = gmsh.model.occ.addCylinder(0.0, 0.0, 0.0, 0.0, 0.0, 0.02, 0.01)
    gmsh.model.occ.synchronize()
    return tag


def build_brain_specimen() -> int:
    # Miller & Chinzei (1997): swine brain cylinders ~30 mm across, ~13 mm high (500 mm/min is
    # their strain rate 0.64 /s on this height). Used by scripts/gen_brain_bench.py.
    tag = gmsh.model.occ.addCylinder(0.0, 0.0, 0.0, 0.0, 0.0, 0.013, 0.015)
    gmsh.model.occ.synchronize()
    return tag


def build_beam() -> int:
    tag = gmsh.model.occ.addBox(0.0, -0.005, -0.005, 0.1, 0.01, 0.01)
    gmsh.model.occ.synchronize()
    return tag


# name -> (builder, pinned interior mesh size h [m], surface size factor, target nodes,
#          target tets or None, binary, generated by default?)
# A surface size factor f != 1 meshes the boundary with size f*h, grading to h at depth h
# (liver-1k4: a surface 1.35x coarser gives the paper's tets/nodes ratio, 6342/1394 = 4.55;
# a uniform size gives ~4.05, i.e. ~5,650 tets for 1,394 nodes).
MESHES = {
    "liver-1k4": (build_liver, 0.006328, 1.35, 1394, 6342, False, True),
    "liver-10k": (build_liver, 0.00334, 1.0, 10000, None, True, True),
    "liver-100k": (build_liver, 0.00147, 1.0, 100000, None, True, False),
    "cylinder-2k": (build_cylinder, 0.0015, 1.0, 2000, None, False, True),
    "cylinder-10k": (build_cylinder, 0.000812, 1.0, 10000, None, True, True),
    "brain-specimen": (build_brain_specimen, 0.00172, 1.0, 2000, None, False, True),
    "beam": (build_beam, 0.00227, 1.0, 1500, None, False, True),
}

TUNE_TOL = 0.03  # re-tune the size when the node count is off by more than this
CHECK_TOL = 0.10  # final acceptance

# ---------------------------------------------------------------------------------------------
# Graded livers "liver-reach-<h>mm": fine where the default scene's tool can reach.
# ---------------------------------------------------------------------------------------------

# The default scene's device and tool (host/scenes/liver.toml: [device], [tool]; the default
# bank.reach_margin_m).  The shaft points along -z at rest; pitch about x (inner axis), yaw
# about y (outer, ground-fixed).  Inverse kinematics as host/haptic/src/kinematics.rs: with
# v = x - fulcrum, pitch = asin(v_y / |v|), yaw = atan2(v_x, -v_z) (up to sign; the ranges are
# symmetric).
REACH_FULCRUM = (0.0, 0.0, 0.16)
REACH_PITCH_MAX = 0.35  # |pitch| <= this, rad
REACH_YAW_MAX = 0.35  # |yaw| <= this, rad
REACH_INSERTION = (0.03, 0.14)  # tip distance from the fulcrum, m
REACH_TIP_RADIUS = 0.003  # m
REACH_MARGIN = 0.002  # bank.reach_margin_m (default), m
# Fine zone: within ZONE_BAND of the organ's boundary AND within REACH_TIP_RADIUS +
# REACH_MARGIN + ZONE_WIDEN of the tip's sector (the reachable region widened by ZONE_WIDEN, so
# that a tool patch at the edge of the reach and the organ around it are fine).
ZONE_BAND = 0.010
ZONE_WIDEN = 0.010
ZONE_SECTOR_DIST = REACH_TIP_RADIUS + REACH_MARGIN + ZONE_WIDEN
REACH_GRADIENT = 0.3  # size growth per unit distance from the fine zone
REACH_H_FAR = 0.008  # size cap away from the fine zone, m
ASCII_MAX_BYTES = 500_000  # the reach meshes are written binary when ASCII would be larger
# Surface mesher of the reach meshes: Delaunay (5).  Frontal-Delaunay (6, the other meshes')
# leaves a row of 1.5-3 h edges along the +y end of the crease fillet, which is in the reach
# (at h = 2 mm, 66 fine-zone boundary edges over 1.5 h on that fillet, against 6 with Delaunay).
REACH_SURFACE_ALGORITHM = 5

# name -> (fine-zone size h_fine [m], committed?).  No node-count target: the size is the
# parameter.  Only the files of at most ~4 MB are committed; the others (2 mm: 6.5 MB) go to
# generated/ (git-ignored) and are made with --only or --reach-series all.
REACH_SERIES = {
    f"liver-reach-{h_mm:g}mm": (h_mm / 1000.0, committed)
    for h_mm, committed in ((4.0, True), (2.8, True), (2.0, False), (1.4, False), (1.0, False))
}

# The reference series "liver-reach-scaled-<h>mm" (host/tests/data/patch-study-p2.json): the
# 4 mm mesh's whole size field scaled by h / 4 mm, so the series refines uniformly by the ratio
# 1.4 (the 4 mm member is liver-reach-4mm itself).  All in generated/.
REACH_SCALED_BASE = 0.004
REACH_SCALED = {f"liver-reach-scaled-{h_mm:g}mm": h_mm / 1000.0 for h_mm in (2.8, 2.0, 1.4, 1.0)}


def sector_distance(p):
    """Approximate distance (m) of points p (N,3) from the tip's sector (the spherical-shell
    sector swept by the tip over the joint ranges): the larger of the radial excess and
    rho sin(angular excess).  ``sector_distance(x) <= m`` is exactly host/haptic/src/reach.rs's
    ``Workspace::reaches(x, m)`` (for rho > m).  Like that test it takes the radial and the
    angular excess separately, so near the sector's corners it under-estimates the true
    distance (by up to a factor sqrt(2)); it is negative inside the shell."""
    v = np.asarray(p, dtype=np.float64) - np.asarray(REACH_FULCRUM)
    rho = np.sqrt(np.einsum("ij,ij->i", v, v))
    pitch = np.arcsin(np.clip(v[:, 1] / rho, -1.0, 1.0))
    yaw = np.arctan2(v[:, 0], -v[:, 2])
    dp = np.maximum(np.abs(pitch) - REACH_PITCH_MAX, 0.0)
    dy = np.maximum(np.abs(yaw) - REACH_YAW_MAX, 0.0) * np.cos(pitch)
    d_ang = rho * np.sin(np.minimum(np.hypot(dp, dy), np.pi / 2))
    d_rad = np.maximum(rho - REACH_INSERTION[1], REACH_INSERTION[0] - rho)
    return np.maximum(d_rad, d_ang)


def _sector_distance_expr() -> str:
    """sector_distance() as a Gmsh MathEval expression in x, y, z (no atan2 in MathEval:
    atan2(a, b) = 2 atan(a / (sqrt(a^2 + b^2) + b)), valid for b > 0 or a != 0)."""
    fx, fy, fz = REACH_FULCRUM
    vx, vy, vz = f"(x-({fx!r}))", f"(y-({fy!r}))", f"(z-({fz!r}))"
    rho = f"sqrt({vx}*{vx}+{vy}*{vy}+{vz}*{vz})"
    rxz = f"sqrt({vx}*{vx}+{vz}*{vz})"  # rho cos(pitch)
    pitch = f"asin({vy}/{rho})"
    yaw = f"(2*atan({vx}/({rxz}-{vz})))"
    dp = f"max(abs({pitch})-{REACH_PITCH_MAX!r},0)"
    dy = f"(max(abs({yaw})-{REACH_YAW_MAX!r},0)*{rxz}/{rho})"
    d_ang = f"{rho}*sin(min(sqrt({dp}*{dp}+{dy}*{dy}),{np.pi / 2!r}))"
    d_rad = f"max({rho}-{REACH_INSERTION[1]!r},{REACH_INSERTION[0]!r}-{rho})"
    return f"max({d_rad},{d_ang})"


def _reach_size_field(vol: int, h_fine: float, scaled: bool = False) -> None:
    """Background size: h_fine in the fine zone, growing by REACH_GRADIENT per unit distance
    from it, capped at REACH_H_FAR.  The distance from the zone is taken as
    max(depth - ZONE_BAND, sector distance - ZONE_SECTOR_DIST, 0) (a lower bound of the
    distance to the intersection: never coarser than intended).

    scaled: the liver-reach-4mm size field times h_fine / 4 mm everywhere (gradient and cap
    scaled too), so that a series of them refines the whole mesh by one ratio, as Richardson
    extrapolation assumes (the plain family refines only the fine zone and the transition
    near it)."""
    surfs = [t for _, t in gmsh.model.getBoundary([(3, vol)], combined=False, oriented=False)]
    f = gmsh.model.mesh.field
    dist = f.add("Distance")
    f.setNumbers(dist, "SurfacesList", surfs)
    f.setNumber(dist, "Sampling", 100)
    size = f.add("MathEval")
    away = f"max(0,F{dist}-{ZONE_BAND!r},{_sector_distance_expr()}-{ZONE_SECTOR_DIST!r})"
    if scaled:
        scale = h_fine / REACH_SCALED_BASE
        expr = f"{scale!r}*min({REACH_H_FAR!r},{REACH_SCALED_BASE!r}+{REACH_GRADIENT!r}*{away})"
    else:
        expr = f"min({REACH_H_FAR!r},{h_fine!r}+{REACH_GRADIENT!r}*{away})"
    f.setString(size, "F", expr)
    f.setAsBackgroundMesh(size)


def boundary_faces(tets):
    """Triangles bounding the tetrahedra (faces used once) and the faces' use counts."""
    faces = np.sort(np.concatenate([tets[:, [1, 2, 3]], tets[:, [0, 3, 2]], tets[:, [0, 1, 3]], tets[:, [0, 2, 1]]]), axis=1)
    uniq, counts = np.unique(faces, axis=0, return_counts=True)
    return uniq[counts == 1], counts


def reach_stats(nodes, tets):
    """Boundary edge lengths (m) whose two ends lie in the fine zone (on the boundary the
    depth is 0, so: within ZONE_SECTOR_DIST of the sector), and the number of surface nodes in
    the reachable region R (within tip radius + margin of the sector, z > 0.01: the scene's bed
    is fixed)."""
    tris, _ = boundary_faces(tets)
    edges = np.unique(np.sort(np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]]), axis=1), axis=0)
    sd = sector_distance(nodes)
    in_zone = sd <= ZONE_SECTOR_DIST
    e = edges[in_zone[edges[:, 0]] & in_zone[edges[:, 1]]]
    lengths = np.linalg.norm(nodes[e[:, 0]] - nodes[e[:, 1]], axis=1)
    surf = np.unique(tris)
    n_reach = int(np.sum((sd[surf] <= REACH_TIP_RADIUS + REACH_MARGIN) & (nodes[surf, 2] > 0.01)))
    return lengths, n_reach


# ---------------------------------------------------------------------------------------------
# Meshing
# ---------------------------------------------------------------------------------------------


def _set_options(h: float, surface_factor: float, size_range=None) -> None:
    opt = gmsh.option.setNumber
    opt("General.Terminal", 0)
    opt("General.Verbosity", 2)
    opt("General.NumThreads", 1)
    opt("Mesh.RandomSeed", RANDOM_SEED)
    opt("Geometry.OCCBoundsUseStl", 1)
    opt("Mesh.Algorithm", 6)
    opt("Mesh.Algorithm3D", 1)
    opt("Mesh.Optimize", 1)
    opt("Mesh.OptimizeNetgen", 1)
    opt("Mesh.ElementOrder", 1)
    opt("Mesh.MeshSizeFromCurvature", 0)
    opt("Mesh.MeshSizeFromPoints", 0)
    opt("Mesh.MeshSizeExtendFromBoundary", 0)
    lo, hi = size_range or (h * min(1.0, surface_factor), h * max(1.0, surface_factor))
    opt("Mesh.MeshSizeMin", lo)
    opt("Mesh.MeshSizeMax", hi)


def _graded_size_field(vol: int, h: float, surface_factor: float) -> None:
    """Size surface_factor*h on the boundary of vol, h from depth h inwards."""
    surfs = [t for _, t in gmsh.model.getBoundary([(3, vol)], combined=False, oriented=False)]
    f = gmsh.model.mesh.field
    dist = f.add("Distance")
    f.setNumbers(dist, "SurfacesList", surfs)
    f.setNumber(dist, "Sampling", 50)
    thr = f.add("Threshold")
    f.setNumber(thr, "InField", dist)
    f.setNumber(thr, "SizeMin", h * surface_factor)
    f.setNumber(thr, "SizeMax", h)
    f.setNumber(thr, "DistMin", 0.0)
    f.setNumber(thr, "DistMax", h)
    f.setAsBackgroundMesh(thr)


def mesh_once(builder, h: float, surface_factor: float, reach: bool = False, scaled: bool = False):
    """Mesh the geometry with size h (reach: h in the fine zone, graded up to REACH_H_FAR
    elsewhere, or that whole field scaled: see _reach_size_field); return (nodes (N,3) float64,
    tets (M,4) 0-based)."""
    gmsh.clear()
    far = REACH_H_FAR * h / REACH_SCALED_BASE if scaled else REACH_H_FAR
    _set_options(h, surface_factor, (h, far) if reach else None)
    if reach:
        gmsh.option.setNumber("Mesh.Algorithm", REACH_SURFACE_ALGORITHM)
    gmsh.model.add("m")
    vol = builder()
    if reach:
        _reach_size_field(vol, h, scaled)
    elif surface_factor != 1.0:
        _graded_size_field(vol, h, surface_factor)
    gmsh.model.mesh.generate(3)
    node_tags, coords, _ = gmsh.model.mesh.getNodes()
    coords = np.asarray(coords, dtype=np.float64).reshape(-1, 3)
    _, conn = gmsh.model.mesh.getElementsByType(4, vol)  # linear tetrahedra of the volume
    conn = np.asarray(conn, dtype=np.int64).reshape(-1, 4)
    # Keep only referenced nodes, in Gmsh's node order, renumbered 0..N-1.
    order = np.argsort(node_tags, kind="stable")
    sorted_tags = np.asarray(node_tags)[order]
    used = np.zeros(len(node_tags), dtype=bool)
    pos = np.searchsorted(sorted_tags, conn.ravel())
    assert np.all(sorted_tags[pos] == conn.ravel()), "tet references an unknown node tag"
    idx = order[pos]  # index into node_tags / coords
    used[idx] = True
    # Gmsh's order = ascending tag order.
    keep = order[used[order]]
    new_index = np.full(len(node_tags), -1, dtype=np.int64)
    new_index[keep] = np.arange(len(keep))
    # Round to 1e-12 m (a picometre): exact ASCII round trip, no -4e-18 noise on the planes.
    nodes = np.round(coords[keep], 12) + 0.0  # (+ 0.0 turns -0.0 into 0.0)
    tets = new_index[idx].reshape(-1, 4)
    return nodes, tets


def signed_volumes(nodes, tets):
    p = nodes[tets]
    u, v, w = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0], p[:, 3] - p[:, 0]
    return np.einsum("ij,ij->i", u, np.cross(v, w)) / 6.0


def quality_gamma(nodes, tets):
    """Mean-ratio quality 12 (3 V)^(2/3) / sum(l_ij^2): 1 for a regular tetrahedron, 0 when flat."""
    p = nodes[tets]
    vol = np.abs(signed_volumes(nodes, tets))
    l2 = np.zeros(len(tets))
    for a in range(4):
        for b in range(a + 1, 4):
            d = p[:, a] - p[:, b]
            l2 += np.einsum("ij,ij->i", d, d)
    return 12.0 * (3.0 * vol) ** (2.0 / 3.0) / l2


def check_mesh(name, nodes, tets, target_nodes, target_tets):
    problems = []
    vols = signed_volumes(nodes, tets)
    if np.any(vols <= 0):
        problems.append(f"{int(np.sum(vols <= 0))} tetrahedra with non-positive volume (min {vols.min():.3e})")
    referenced = np.zeros(len(nodes), dtype=bool)
    referenced[tets.ravel()] = True
    if not referenced.all():
        problems.append(f"{int((~referenced).sum())} unreferenced nodes")
    if np.any(np.sort(tets, axis=1)[:, 1:] == np.sort(tets, axis=1)[:, :-1]):
        problems.append("degenerate tetrahedron (repeated node)")
    _, counts = boundary_faces(tets)
    if np.any(counts > 2):
        problems.append(f"{int(np.sum(counts > 2))} faces shared by more than two tetrahedra")
    n_boundary_faces = int(np.sum(counts == 1))
    if target_nodes is not None and abs(len(nodes) / target_nodes - 1.0) > CHECK_TOL:
        problems.append(f"{len(nodes)} nodes, target {target_nodes} +-{CHECK_TOL:.0%}")
    if target_tets is not None and abs(len(tets) / target_tets - 1.0) > CHECK_TOL:
        problems.append(f"{len(tets)} tetrahedra, target {target_tets} +-{CHECK_TOL:.0%}")
    if problems:
        raise SystemExit(f"error: {name}: " + "; ".join(problems))
    return vols, n_boundary_faces


def write_msh(path, nodes, tets, binary: bool):
    """Write nodes/tets as one discrete volume entity (MSH 4.1), nodes 1..N, elements 1..M."""
    gmsh.clear()
    gmsh.option.setNumber("General.Terminal", 0)
    gmsh.model.add("out")
    vol = gmsh.model.addDiscreteEntity(3)
    n = len(nodes)
    gmsh.model.mesh.addNodes(3, vol, np.arange(1, n + 1), nodes.ravel())
    gmsh.model.mesh.addElementsByType(vol, 4, np.arange(1, len(tets) + 1), (tets + 1).ravel())
    gmsh.option.setNumber("Mesh.MshFileVersion", 4.1)
    gmsh.option.setNumber("Mesh.Binary", 1 if binary else 0)
    gmsh.option.setNumber("Mesh.SaveAll", 1)
    gmsh.option.setNumber("Mesh.SaveParametric", 0)
    tmp = path[: -len(".msh")] + ".part.msh"  # gmsh picks the format from the extension
    gmsh.write(tmp)
    os.replace(tmp, path)


def reread(path):
    gmsh.clear()
    gmsh.open(path)
    tags, coords, _ = gmsh.model.mesh.getNodes()
    _, conn = gmsh.model.mesh.getElementsByType(4)
    gmsh.clear()
    return len(tags), len(conn) // 4, np.asarray(coords).reshape(-1, 3)


def generate(name, builder, h0, sf, target_nodes, target_tets, binary, path, reach=False, scaled=False):
    """Mesh, check, write and re-read one file.  reach: a graded liver-reach mesh (h0 is the
    fine-zone size; no node target, no re-tuning; binary None: binary when the ASCII file
    would exceed ASCII_MAX_BYTES)."""
    t0 = time.perf_counter()
    h = h0
    tried = []
    for _ in range(8):
        nodes, tets = mesh_once(builder, h, sf, reach, scaled)
        tried.append((h, len(nodes)))
        if target_nodes is None or abs(len(nodes) / target_nodes - 1.0) <= TUNE_TOL:
            break
        h = float(f"{h * (len(nodes) / target_nodes) ** (1.0 / 3.0):.3g}")
    if len(tried) > 1:
        print(f"  {name}: re-tuned mesh size: " + ", ".join(f"h={a:g} -> {b} nodes" for a, b in tried))
    vols, n_bfaces = check_mesh(name, nodes, tets, target_nodes, target_tets)
    gamma = quality_gamma(nodes, tets)
    if binary is None:
        write_msh(path, nodes, tets, False)
        binary = os.path.getsize(path) > ASCII_MAX_BYTES
        if binary:
            write_msh(path, nodes, tets, True)
    else:
        write_msh(path, nodes, tets, binary)
    n_read, m_read, coords_read = reread(path)
    if n_read != len(nodes) or m_read != len(tets):
        raise SystemExit(f"error: {path}: re-read {n_read} nodes / {m_read} tets, wrote {len(nodes)} / {len(tets)}")
    if np.abs(coords_read - nodes).max() > 1e-15:
        raise SystemExit(f"error: {path}: re-read coordinates differ")
    if signed_volumes(coords_read, tets).min() <= 0:
        raise SystemExit(f"error: {path}: non-positive tetrahedron volume after re-reading")
    lo, hi = nodes.min(axis=0), nodes.max(axis=0)
    size = os.path.getsize(path)
    print(
        f"{os.path.basename(path):18s} h={h:<8g} sf={sf:g} nodes={len(nodes):7d} tets={len(tets):8d} "
        f"boundary_tris={n_bfaces:7d} volume={vols.sum():.4e} m^3 "
        f"gamma min/mean={gamma.min():.3f}/{gamma.mean():.3f} "
        f"bbox=[{lo[0]:+.4f},{hi[0]:+.4f}]x[{lo[1]:+.4f},{hi[1]:+.4f}]x[{lo[2]:+.4f},{hi[2]:+.4f}] "
        f"{'binary' if binary else 'ascii '} {size / 1e6:.2f} MB ({time.perf_counter() - t0:.1f} s)",
        flush=True,
    )
    if reach:
        lengths, n_reach = reach_stats(nodes, tets)
        print(
            f"  {name}: fine zone h={h * 1e3:g} mm: {len(lengths)} boundary edges, length mean "
            f"{lengths.mean() * 1e3:.3f} mm, min {lengths.min() * 1e3:.3f}, max {lengths.max() * 1e3:.3f}; "
            f"{n_reach} free surface nodes in the reachable region",
            flush=True,
        )
    return len(nodes), len(tets), size


def main(argv=None):
    here = os.path.dirname(os.path.abspath(__file__))
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", default=os.path.join(here, "..", "host", "meshes"), help="output directory (default host/meshes)")
    ap.add_argument(
        "--only",
        choices=sorted(MESHES) + list(REACH_SERIES),
        help="generate only this mesh (liver-100k is only generated this way)",
    )
    ap.add_argument(
        "--reach-series",
        nargs="?",
        const="committed",
        choices=["committed", "all", "scaled"],
        help="generate only the graded livers liver-reach-*mm (fine in the default scene's reach): "
        "the committed ones (default), or all of them (the others -> generated/), or the "
        "reference series liver-reach-scaled-*mm (-> generated/)",
    )
    ap.add_argument(
        "--liver-nodes",
        type=int,
        metavar="N",
        help="generate only a liver with about N nodes (size auto-tuned) as <out>/generated/liver-N.msh",
    )
    args = ap.parse_args(argv)
    if sum(map(bool, (args.only, args.liver_nodes, args.reach_series))) > 1:
        ap.error("--only, --liver-nodes and --reach-series are exclusive")

    gmsh.initialize(["gen_meshes"], readConfigFiles=False)
    gmsh.option.setNumber("General.Terminal", 0)
    version = gmsh.__version__
    if version != GMSH_VERSION:
        print(f"warning: gmsh {version} (pinned {GMSH_VERSION}): meshes may differ from the committed ones", file=sys.stderr)
    out = os.path.normpath(args.out)
    gen = os.path.join(out, "generated")

    jobs = []
    if args.liver_nodes:
        n = args.liver_nodes
        if n < 200:
            ap.error("--liver-nodes must be >= 200")
        # Scale the liver-1k4 size by the node ratio (nodes ~ h^-3), then tune.
        h = float(f"{MESHES['liver-10k'][1] * (10000 / n) ** (1 / 3):.3g}")
        jobs.append((f"liver-{n}", build_liver, h, 1.0, n, None, n > 5000, os.path.join(gen, f"liver-{n}.msh"), {}))
    elif args.reach_series == "scaled":
        for name, h in REACH_SCALED.items():
            jobs.append((name, build_liver, h, 1.0, None, None, None, os.path.join(gen, name + ".msh"), {"reach": True, "scaled": True}))
    elif args.reach_series or args.only in REACH_SERIES:
        for name, (h, committed) in REACH_SERIES.items():
            if args.reach_series == "all" or (args.reach_series and committed) or args.only == name:
                d = out if committed else gen
                jobs.append((name, build_liver, h, 1.0, None, None, None, os.path.join(d, name + ".msh"), {"reach": True}))
    else:
        for name, (builder, h, sf, tn, tt, binary, default) in MESHES.items():
            if (args.only is None and default) or args.only == name:
                d = out if default else gen
                jobs.append((name, builder, h, sf, tn, tt, binary, os.path.join(d, name + ".msh"), {}))
    try:
        total = 0
        for *job, kw in jobs:
            os.makedirs(os.path.dirname(job[-1]), exist_ok=True)
            total += generate(*job, **kw)[2]
        if len(jobs) > 1:
            print(f"total {total / 1e6:.2f} MB")
    finally:
        gmsh.finalize()


if __name__ == "__main__":
    main()
