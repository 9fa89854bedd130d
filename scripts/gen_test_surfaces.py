#!/usr/bin/env python3
"""Generate the small test surfaces of ``host mesh`` (host/tests/data/surfaces/).

Regenerate (from the repository root; needs ``pip install gmsh==4.15.2 numpy``):

    python3 scripts/gen_test_surfaces.py

The organ is the liver-like body of ``scripts/gen_meshes.py`` (``build_liver``: two fused
ellipsoidal lobes, flat filleted underside, 0.14 x 0.09 x 0.07 m), its boundary triangulated
by Gmsh at 8 mm (single-threaded, fixed seed: reruns give the same files).  Written:

  organ_cm.obj        the surface in centimetres, outward faces (OBJ)
  organ_mm.stl        the same in millimetres, binary STL
  organ_cm.ply        the same in centimetres, binary little-endian PLY (float32 vertices)
  organ_cm.vtk        the same, legacy VTK POLYDATA ASCII
  organ_cm_bin.vtk    the same, legacy VTK POLYDATA binary (big-endian, double points)
  organ_cm.vtp        the same, VTK XML PolyData, ascii data arrays
  organ_holes.obj     organ_cm with two holes: the faces around two vertices removed
                      (boundary loops of those vertices' valences)
  organ_flipped.obj   organ_cm with the faces whose centroid lies within 3 cm of the top of
                      the right lobe reversed (a flipped patch: inconsistent orientation)
  organ_selfx.obj     organ_cm with its topmost vertex pushed 8 cm down, through the flat
                      underside (its faces cross the underside's)
  organ_two_shells.obj organ_cm plus a closed 1 cm sphere 3 cm beside the organ (two shells)

Each file's expected verdict is tested in host/tests/mesh_cli.rs; the script prints the
counts those tests rely on.
"""

import os
import sys

import gmsh
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import gen_meshes  # noqa: E402  (the liver geometry)

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
OUT = os.path.join(ROOT, "host", "tests", "data", "surfaces")
H = 0.008  # surface triangle size, m


def organ_surface():
    """(vertices in m, outward triangles 0-based) of the liver's boundary."""
    gmsh.initialize()
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.option.setNumber("General.NumThreads", 1)
        gmsh.option.setNumber("Mesh.RandomSeed", 1)
        gmsh.model.add("organ")
        vol = gen_meshes.build_liver()
        gmsh.option.setNumber("Mesh.MeshSizeMin", H)
        gmsh.option.setNumber("Mesh.MeshSizeMax", H)
        gmsh.option.setNumber("Mesh.Algorithm", 6)
        gmsh.model.mesh.generate(2)
        tags, coords, _ = gmsh.model.mesh.getNodes()
        pos = {int(t): i for i, t in enumerate(tags)}
        pts = np.asarray(coords).reshape(-1, 3)
        tris = []
        for dim, s in gmsh.model.getBoundary([(3, vol)], combined=False, oriented=True):
            types, _, nodes = gmsh.model.mesh.getElements(2, abs(s))
            for ty, ns in zip(types, nodes):
                assert int(ty) == 2
                for i in range(0, len(ns), 3):
                    t = [pos[int(n)] for n in ns[i : i + 3]]
                    tris.append(t)
    finally:
        gmsh.finalize()
    tris = np.array(tris)
    used = np.unique(tris)
    remap = -np.ones(len(pts), dtype=int)
    remap[used] = np.arange(len(used))
    pts, tris = pts[used], remap[tris]
    # Orient every face outward: a closed surface's faces from Gmsh share its orientation per
    # surface entity; make each agree with the outward direction from the centroid of the body
    # is not enough for a non-convex organ, so orient by the signed volume per entity instead.
    tris = orient_outward(pts, tris)
    return pts, tris


def orient_outward(pts, tris):
    """Make neighbouring faces agree (breadth-first over shared edges), then outward."""
    from collections import defaultdict, deque

    edges = defaultdict(list)
    for f, t in enumerate(tris):
        for k in range(3):
            a, b = t[k], t[(k + 1) % 3]
            edges[(min(a, b), max(a, b))].append(f)
    tris = tris.copy()
    done = np.zeros(len(tris), bool)
    done[0] = True
    queue = deque([0])
    while queue:
        f = queue.popleft()
        t = tris[f]
        for k in range(3):
            a, b = t[k], t[(k + 1) % 3]
            for g in edges[(min(a, b), max(a, b))]:
                if g == f or done[g]:
                    continue
                u = tris[g]
                same = any(u[j] == a and u[(j + 1) % 3] == b for j in range(3))
                if same:
                    tris[g] = u[[0, 2, 1]]
                done[g] = True
                queue.append(g)
    assert done.all(), "the organ surface is not connected"
    if signed_volume(pts, tris) < 0:
        tris = tris[:, [0, 2, 1]]
    return tris


def signed_volume(pts, tris):
    a, b, c = pts[tris[:, 0]], pts[tris[:, 1]], pts[tris[:, 2]]
    return float(np.sum(np.einsum("ij,ij->i", a, np.cross(b, c))) / 6.0)


def write_obj(name, pts, tris, comment):
    with open(os.path.join(OUT, name), "w") as f:
        f.write(f"# {comment}\n# made by scripts/gen_test_surfaces.py\n")
        for p in pts:
            f.write(f"v {p[0]:.6f} {p[1]:.6f} {p[2]:.6f}\n")
        for t in tris:
            f.write(f"f {t[0] + 1} {t[1] + 1} {t[2] + 1}\n")


def write_stl(name, pts, tris):
    head = b"binary STL made by scripts/gen_test_surfaces.py".ljust(80, b" ")
    rec = np.zeros(len(tris), dtype=[("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")])
    rec["v"] = pts[tris].astype("<f4")
    with open(os.path.join(OUT, name), "wb") as f:
        f.write(head + np.uint32(len(tris)).tobytes() + rec.tobytes())


def write_ply(name, pts, tris):
    head = (
        "ply\nformat binary_little_endian 1.0\ncomment made by scripts/gen_test_surfaces.py\n"
        f"element vertex {len(pts)}\nproperty float x\nproperty float y\nproperty float z\n"
        f"element face {len(tris)}\nproperty list uchar int vertex_indices\nend_header\n"
    )
    face = np.zeros(len(tris), dtype=[("n", "u1"), ("v", "<i4", 3)])
    face["n"] = 3
    face["v"] = tris
    with open(os.path.join(OUT, name), "wb") as f:
        f.write(head.encode() + pts.astype("<f4").tobytes() + face.tobytes())


def write_vtk(name, pts, tris, binary):
    head = f"# vtk DataFile Version 3.0\nmade by scripts/gen_test_surfaces.py\n{'BINARY' if binary else 'ASCII'}\nDATASET POLYDATA\n"
    cells = np.hstack([np.full((len(tris), 1), 3), tris]).astype(">i4")
    with open(os.path.join(OUT, name), "wb") as f:
        f.write(head.encode())
        f.write(f"POINTS {len(pts)} double\n".encode())
        if binary:
            f.write(pts.astype(">f8").tobytes() + b"\n")
        else:
            f.write("".join(f"{p[0]:.6f} {p[1]:.6f} {p[2]:.6f}\n" for p in pts).encode())
        f.write(f"POLYGONS {len(tris)} {4 * len(tris)}\n".encode())
        if binary:
            f.write(cells.tobytes() + b"\n")
        else:
            f.write("".join(" ".join(str(x) for x in c) + "\n" for c in cells).encode())


def write_vtp(name, pts, tris):
    pts_text = " ".join(f"{x:.6f}" for x in pts.ravel())
    conn = " ".join(str(int(x)) for x in tris.ravel())
    offs = " ".join(str(3 * (i + 1)) for i in range(len(tris)))
    with open(os.path.join(OUT, name), "w") as f:
        f.write(
            '<?xml version="1.0"?>\n<!-- made by scripts/gen_test_surfaces.py -->\n'
            '<VTKFile type="PolyData" version="0.1" byte_order="LittleEndian">\n<PolyData>\n'
            f'<Piece NumberOfPoints="{len(pts)}" NumberOfPolys="{len(tris)}">\n'
            f'<Points><DataArray type="Float64" NumberOfComponents="3" format="ascii">{pts_text}</DataArray></Points>\n'
            '<Polys>\n'
            f'<DataArray type="Int32" Name="connectivity" format="ascii">{conn}</DataArray>\n'
            f'<DataArray type="Int32" Name="offsets" format="ascii">{offs}</DataArray>\n'
            "</Polys>\n</Piece>\n</PolyData>\n</VTKFile>\n"
        )


def sphere(centre, r, n=8):
    """A closed UV sphere, outward."""
    pts = [(centre[0], centre[1], centre[2] + r)]
    for i in range(1, n):
        th = np.pi * i / n
        for j in range(2 * n):
            ph = np.pi * j / n
            pts.append((centre[0] + r * np.sin(th) * np.cos(ph), centre[1] + r * np.sin(th) * np.sin(ph), centre[2] + r * np.cos(th)))
    pts.append((centre[0], centre[1], centre[2] - r))
    m = 2 * n
    ring = lambda i, j: 1 + (i - 1) * m + (j % m)  # noqa: E731
    tris = [(0, ring(1, j), ring(1, j + 1)) for j in range(m)]
    for i in range(1, n - 1):
        for j in range(m):
            tris += [(ring(i, j), ring(i + 1, j), ring(i + 1, j + 1)), (ring(i, j), ring(i + 1, j + 1), ring(i, j + 1))]
    last = len(pts) - 1
    tris += [(last, ring(n - 1, j + 1), ring(n - 1, j)) for j in range(m)]
    return np.array(pts), np.array(tris)


def main():
    os.makedirs(OUT, exist_ok=True)
    pts, tris = organ_surface()
    cm = pts * 100.0
    print(f"organ: {len(pts)} vertices, {len(tris)} faces, volume {signed_volume(pts, tris):.6e} m^3", file=sys.stderr)
    write_obj("organ_cm.obj", cm, tris, "liver-like organ, centimetres")
    write_stl("organ_mm.stl", pts * 1000.0, tris)
    # The OBJ's 6-decimal coordinates, so every file holds the same numbers.
    cm = np.round(cm, 6)
    write_ply("organ_cm.ply", cm, tris)
    write_vtk("organ_cm.vtk", cm, tris, binary=False)
    write_vtk("organ_cm_bin.vtk", cm, tris, binary=True)
    write_vtp("organ_cm.vtp", cm, tris)

    # Two holes: the fans of two vertices on the top of each lobe.
    def nearest(p):
        return int(np.argmin(np.sum((cm - p) ** 2, axis=1)))

    holes = [nearest((1.8, 0.0, 7.0)), nearest((-2.5, 1.0, 5.8))]
    keep = ~np.any(np.isin(tris, holes), axis=1)
    sizes = [int(np.sum(np.any(tris == v, axis=1))) for v in holes]
    print(f"organ_holes: vertices {holes} removed, loops of {sizes} edges", file=sys.stderr)
    # The removed vertices stay in the file, unused.
    write_obj("organ_holes.obj", cm, tris[keep], f"organ_cm with two holes, loops of {sizes[0]} and {sizes[1]} edges")

    cent = cm[tris].mean(axis=1)
    patch = np.sum((cent - (1.8, 0.0, 7.0)) ** 2, axis=1) < 3.0**2
    flipped = tris.copy()
    flipped[patch] = flipped[patch][:, [0, 2, 1]]
    print(f"organ_flipped: {int(patch.sum())} of {len(tris)} faces reversed", file=sys.stderr)
    write_obj("organ_flipped.obj", cm, flipped, f"organ_cm with {int(patch.sum())} faces reversed")

    top = int(np.argmax(cm[:, 2]))
    moved = cm.copy()
    moved[top, 2] -= 8.0
    print(f"organ_selfx: vertex {top} moved from z = {cm[top, 2]:.3f} to {moved[top, 2]:.3f} cm", file=sys.stderr)
    write_obj("organ_selfx.obj", moved, tris, f"organ_cm with vertex {top + 1} pushed through the underside")

    sp, st = sphere((10.0, 0.0, 3.0), 1.0)
    both_p = np.vstack([cm, sp])
    both_t = np.vstack([tris, st + len(cm)])
    print(f"organ_two_shells: the organ ({len(tris)} faces) and a sphere ({len(st)} faces)", file=sys.stderr)
    write_obj("organ_two_shells.obj", both_p, both_t, "organ_cm and a 1 cm sphere beside it")


if __name__ == "__main__":
    main()
