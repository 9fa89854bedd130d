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
=====================  ==========  =======================================================

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

Reproducibility
---------------
Gmsh is pinned to 4.15.2 (a different version prints a warning and may give a
different mesh), meshing runs single-threaded (``General.NumThreads = 1``) with
a fixed ``Mesh.RandomSeed``, and the mesh size of each default file is pinned
(the table in ``MESHES``).  With these settings, re-running the script gives
byte-identical files.  If the pinned size does not give a node count within
+-3 % of the target (e.g. another Gmsh version), the size is re-tuned
deterministically, h <- h * (nodes / target)^(1/3), and the chosen size is
printed.  The script then checks the node count (and for liver-1k4 the tet
count) is within +-10 % of the target, that no tetrahedron has a non-positive
volume, that every node is referenced, that no triangle face is shared by more
than two tetrahedra, and re-reads each written file to compare counts,
coordinates and orientation.

Meshing: Frontal-Delaunay surfaces (``Mesh.Algorithm = 6``), Delaunay volume
(``Mesh.Algorithm3D = 1``) with Gmsh and Netgen optimisation
(``Mesh.Optimize = 1``, ``Mesh.OptimizeNetgen = 1``), target size h (uniform, or
graded for liver-1k4: see ``MESHES``).  Node coordinates are rounded to 1e-12 m.
Takes ~30 s for the default set; liver-100k ~2 min and 0.5 GB.
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
# Meshing
# ---------------------------------------------------------------------------------------------


def _set_options(h: float, surface_factor: float) -> None:
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
    opt("Mesh.MeshSizeMin", h * min(1.0, surface_factor))
    opt("Mesh.MeshSizeMax", h * max(1.0, surface_factor))


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


def mesh_once(builder, h: float, surface_factor: float):
    """Mesh the geometry with size h; return (nodes (N,3) float64, tets (M,4) 0-based)."""
    gmsh.clear()
    _set_options(h, surface_factor)
    gmsh.model.add("m")
    vol = builder()
    if surface_factor != 1.0:
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
    faces = np.sort(np.concatenate([tets[:, [1, 2, 3]], tets[:, [0, 3, 2]], tets[:, [0, 1, 3]], tets[:, [0, 2, 1]]]), axis=1)
    _, counts = np.unique(faces, axis=0, return_counts=True)
    if np.any(counts > 2):
        problems.append(f"{int(np.sum(counts > 2))} faces shared by more than two tetrahedra")
    n_boundary_faces = int(np.sum(counts == 1))
    if abs(len(nodes) / target_nodes - 1.0) > CHECK_TOL:
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


def generate(name, builder, h0, sf, target_nodes, target_tets, binary, path):
    t0 = time.perf_counter()
    h = h0
    tried = []
    for _ in range(8):
        nodes, tets = mesh_once(builder, h, sf)
        tried.append((h, len(nodes)))
        if abs(len(nodes) / target_nodes - 1.0) <= TUNE_TOL:
            break
        h = float(f"{h * (len(nodes) / target_nodes) ** (1.0 / 3.0):.3g}")
    if len(tried) > 1:
        print(f"  {name}: re-tuned mesh size: " + ", ".join(f"h={a:g} -> {b} nodes" for a, b in tried))
    vols, n_bfaces = check_mesh(name, nodes, tets, target_nodes, target_tets)
    gamma = quality_gamma(nodes, tets)
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
    return len(nodes), len(tets), size


def main(argv=None):
    here = os.path.dirname(os.path.abspath(__file__))
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", default=os.path.join(here, "..", "host", "meshes"), help="output directory (default host/meshes)")
    ap.add_argument("--only", choices=sorted(MESHES), help="generate only this mesh (liver-100k is only generated this way)")
    ap.add_argument(
        "--liver-nodes",
        type=int,
        metavar="N",
        help="generate only a liver with about N nodes (size auto-tuned) as <out>/generated/liver-N.msh",
    )
    args = ap.parse_args(argv)
    if args.only and args.liver_nodes:
        ap.error("--only and --liver-nodes are exclusive")

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
        jobs.append((f"liver-{n}", build_liver, h, 1.0, n, None, n > 5000, os.path.join(gen, f"liver-{n}.msh")))
    else:
        for name, (builder, h, sf, tn, tt, binary, default) in MESHES.items():
            if (args.only is None and default) or args.only == name:
                d = out if default else gen
                jobs.append((name, builder, h, sf, tn, tt, binary, os.path.join(d, name + ".msh")))
    try:
        total = 0
        for job in jobs:
            os.makedirs(os.path.dirname(job[-1]), exist_ok=True)
            total += generate(*job)[2]
        if len(jobs) > 1:
            print(f"total {total / 1e6:.2f} MB")
    finally:
        gmsh.finalize()


if __name__ == "__main__":
    main()
