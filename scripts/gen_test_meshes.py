#!/usr/bin/env python3
"""Generate the small test meshes used by host/tests/mesh_io.rs.

Regenerate (from the repository root):

    pip install gmsh==4.15.2 meshio==5.3.5
    python3 scripts/gen_test_meshes.py

Writes into host/fem/tests/data/:

  cube_v2.msh, cube_v41.msh, cube_v41_bin.msh   the same 5 cm cube mesh (Gmsh, ~45 nodes,
                                                ~100 tetrahedra) as MSH 2.2 ASCII, 4.1 ASCII,
                                                4.1 binary; they include Gmsh's points, lines and
                                                surface triangles, which readers must skip
  cube.vtk                                      legacy VTK ASCII (Gmsh's writer, version 2.0,
                                                with vertex/line/triangle cells too)
  cube.vtu, cube_raw.vtu, cube_ascii.vtu        VTK XML (meshio): inline base64 zlib-compressed
                                                (meshio's default), inline base64 uncompressed,
                                                ASCII; tets + triangles
  cube_appended.vtu                             VTK XML as VTK/ParaView write it: raw appended,
                                                zlib blocks, UInt64 headers, big-endian
  cube_v51.vtk                                  legacy VTK 5.1 ASCII (OFFSETS/CONNECTIVITY, meshio)
  cube_bin.vtk, cube_v51_bin.vtk                legacy VTK 4.2 and 5.1 binary (meshio)
  cube_v1.msh                                   MSH version 1 (Gmsh's writer: $NOD/$ELM, with
                                                points, lines and triangles)
  cube_v1_sparse.msh                            MSH version 1, node numbers 10 * (N - i) + 3
                                                (decreasing, sparse), the boundary triangles first
  cube.mesh                                     Medit ASCII (Gmsh's writer: Vertices, Edges,
                                                Triangles, Tetrahedra)
  cube_v41_sparse.msh                           MSH 4.1 ASCII with renumbered, sparse node tags
  noncontiguous_tags_v2.msh                     MSH 2.2 ASCII, node tags scrambled and sparse,
                                                nodes listed out of tag order (valid)

and into host/fem/tests/data/bad/ one tiny file per problem the reader or validator must report
(hand-written MSH 2.2 ASCII or legacy VTK ASCII; see BAD below). All files in both folders hold
the same node order, so the valid ones must read to identical meshes.

Node ids in error messages are 0-based positions in node order (tag 1 -> node 0 for the
hand-written files, whose tags are 1..N).
"""

import os
import sys
import zlib

import gmsh
import meshio
import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DATA = os.path.join(ROOT, "host", "fem", "tests", "data")
BAD = os.path.join(DATA, "bad")

L = 0.05  # cube edge, metres
H = 0.025  # target mesh size


def cube_with_gmsh():
    """Mesh the cube, write the Gmsh-written files, return (points, tets, triangles) 0-based."""
    gmsh.initialize()
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add("cube")
        gmsh.model.occ.addBox(0, 0, 0, L, L, L)
        gmsh.model.occ.synchronize()
        gmsh.option.setNumber("Mesh.MeshSizeMin", H)
        gmsh.option.setNumber("Mesh.MeshSizeMax", H)
        gmsh.option.setNumber("Mesh.RandomSeed", 1)
        gmsh.model.mesh.generate(3)

        gmsh.option.setNumber("Mesh.Binary", 0)
        gmsh.option.setNumber("Mesh.MshFileVersion", 2.2)
        gmsh.write(os.path.join(DATA, "cube_v2.msh"))
        gmsh.option.setNumber("Mesh.MshFileVersion", 4.1)
        gmsh.write(os.path.join(DATA, "cube_v41.msh"))
        gmsh.option.setNumber("Mesh.Binary", 1)
        gmsh.write(os.path.join(DATA, "cube_v41_bin.msh"))
        gmsh.option.setNumber("Mesh.Binary", 0)
        gmsh.write(os.path.join(DATA, "cube.vtk"))
        gmsh.option.setNumber("Mesh.MshFileVersion", 1.0)
        gmsh.write(os.path.join(DATA, "cube_v1.msh"))
        gmsh.write(os.path.join(DATA, "cube.mesh"))
        gmsh.option.setNumber("Mesh.MshFileVersion", 4.1)

        tags, coords, _ = gmsh.model.mesh.getNodes()
        pos = {int(t): i for i, t in enumerate(tags)}
        points = np.asarray(coords).reshape(-1, 3)
        tets, tris = [], []
        for dim, out in ((3, tets), (2, tris)):
            types, _, nodes = gmsh.model.mesh.getElements(dim)
            for ty, ns in zip(types, nodes):
                k = {4: 4, 2: 3}[int(ty)]
                out.extend([[pos[int(n)] for n in ns[i : i + k]] for i in range(0, len(ns), k)])

        # Sparse tags: node i gets tag 1000 + 7 * i.
        old = [int(t) for t in tags]
        gmsh.model.mesh.renumberNodes(old, [1000 + 7 * i for i in range(len(old))])
        gmsh.write(os.path.join(DATA, "cube_v41_sparse.msh"))
    finally:
        gmsh.finalize()
    # Gmsh writes nodes in tag order, which is getNodes()'s order here (the Rust test checks
    # that every file reads to the same node order).
    return points, np.array(tets), np.array(tris)


def write_meshio(points, tets, tris):
    cells = [("tetra", tets), ("triangle", tris)]
    m = meshio.Mesh(points, cells)
    meshio.write(os.path.join(DATA, "cube.vtu"), m, binary=True, compression="zlib")
    meshio.write(os.path.join(DATA, "cube_raw.vtu"), m, binary=True, compression=None)
    meshio.write(os.path.join(DATA, "cube_ascii.vtu"), m, binary=False)
    meshio.vtk.write(os.path.join(DATA, "cube_v51.vtk"), m, fmt_version="5.1", binary=False)
    meshio.vtk.write(os.path.join(DATA, "cube_bin.vtk"), m, fmt_version="4.2", binary=True)
    meshio.vtk.write(os.path.join(DATA, "cube_v51_bin.vtk"), m, fmt_version="5.1", binary=True)


def write_appended_vtu(points, tets, tris, block=256):
    """VTK XML as VTK/ParaView write it: raw appended data, UInt64 headers, zlib blocks of
    `block` bytes (small, to get several blocks), UInt8 cell types, big-endian for coverage."""
    conn = np.concatenate([tris.reshape(-1), tets.reshape(-1)]).astype(">i8")
    offsets = np.concatenate([3 * np.arange(1, len(tris) + 1), 3 * len(tris) + 4 * np.arange(1, len(tets) + 1)]).astype(">i8")
    types = np.array([5] * len(tris) + [10] * len(tets), dtype=np.uint8)
    arrays = [
        ("Points", "Float64", 3, np.asarray(points, dtype=">f8")),
        ("connectivity", "Int64", 1, conn),
        ("offsets", "Int64", 1, offsets),
        ("types", "UInt8", 1, types),
    ]
    blob, xml_arrays = b"", []
    for name, ty, comps, a in arrays:
        raw = a.tobytes()
        chunks = [raw[i : i + block] for i in range(0, len(raw), block)]
        packed = [zlib.compress(c) for c in chunks]
        last = len(chunks[-1]) if len(chunks[-1]) != block else 0
        header = np.array([len(chunks), block, last] + [len(p) for p in packed], dtype=">u8")
        xml_arrays.append(
            f'<DataArray type="{ty}" Name="{name}" NumberOfComponents="{comps}" '
            f'format="appended" offset="{len(blob)}"/>'
        )
        blob += header.tobytes() + b"".join(packed)
    pts, (c, o, t) = xml_arrays[0], xml_arrays[1:]
    head = (
        '<?xml version="1.0"?>\n'
        '<VTKFile type="UnstructuredGrid" version="1.0" byte_order="BigEndian" '
        'header_type="UInt64" compressor="vtkZLibDataCompressor">\n<UnstructuredGrid>\n'
        f'<Piece NumberOfPoints="{len(points)}" NumberOfCells="{len(types)}">\n'
        f"<PointData>\n</PointData>\n<CellData>\n</CellData>\n"
        f"<Points>\n{pts}\n</Points>\n<Cells>\n{c}\n{o}\n{t}\n</Cells>\n"
        "</Piece>\n</UnstructuredGrid>\n"
        '<AppendedData encoding="raw">\n   _'
    )
    with open(os.path.join(DATA, "cube_appended.vtu"), "wb") as f:
        f.write(head.encode() + blob + b"\n</AppendedData>\n</VTKFile>\n")


def write_noncontiguous_v2(points, tets):
    """MSH 2.2 with node tags 10 * (n - i) + 3 (decreasing, sparse), nodes in the same order."""
    tag = [10 * (len(points) - i) + 3 for i in range(len(points))]
    lines = ["$MeshFormat", "2.2 0 8", "$EndMeshFormat", "$Nodes", str(len(points))]
    lines += [f"{tag[i]} {float(p[0])!r} {float(p[1])!r} {float(p[2])!r}" for i, p in enumerate(points)]
    lines += ["$EndNodes", "$Elements", str(len(tets))]
    lines += [
        f"{500 + 2 * e} 4 2 1 1 " + " ".join(str(tag[n]) for n in t) for e, t in enumerate(tets)
    ]
    lines += ["$EndElements", ""]
    with open(os.path.join(DATA, "noncontiguous_tags_v2.msh"), "w") as f:
        f.write("\n".join(lines))


def write_sparse_v1(points, tets, tris):
    """MSH version 1 with node numbers 10 * (N - i) + 3 and the triangles before the tets."""
    tag = [10 * (len(points) - i) + 3 for i in range(len(points))]
    lines = ["$NOD", str(len(points))]
    lines += [f"{tag[i]} {float(p[0])!r} {float(p[1])!r} {float(p[2])!r}" for i, p in enumerate(points)]
    lines += ["$ENDNOD", "$ELM", str(len(tris) + len(tets))]
    lines += [f"{e + 1} 2 1 1 3 " + " ".join(str(tag[n]) for n in t) for e, t in enumerate(tris)]
    lines += [
        f"{900 + e} 4 2 1 4 " + " ".join(str(tag[n]) for n in t) for e, t in enumerate(tets)
    ]
    lines += ["$ENDELM", ""]
    with open(os.path.join(DATA, "cube_v1_sparse.msh"), "w") as f:
        f.write("\n".join(lines))


# ---------------------------------------------------------------------------------------------
# Bad files: small meshes in centimetre-sized boxes.

S = 0.01


def vol(p, t):
    a, b, c, d = (np.asarray(p[i], float) for i in t)
    return np.dot(b - a, np.cross(c - a, d - a)) / 6.0


def positive(p, t):
    """Reorder a tet (0-based ids) to positive volume."""
    t = list(t)
    if vol(p, t) < 0:
        t[2], t[3] = t[3], t[2]
    return t


def msh2(nodes, elements):
    """MSH 2.2 ASCII text. nodes: (x, y, z) tuples, written with tags 1..N, or preformatted
    "tag x y z" lines; elements: (Gmsh type, [node tags]) pairs."""
    out = ["$MeshFormat", "2.2 0 8", "$EndMeshFormat", "$Nodes", str(len(nodes))]
    for i, n in enumerate(nodes):
        out.append(n if isinstance(n, str) else f"{i + 1} " + " ".join(repr(float(x)) for x in n))
    out += ["$EndNodes", "$Elements", str(len(elements))]
    for i, (ty, ns) in enumerate(elements):
        out.append(f"{i + 1} {ty} 2 1 1 " + " ".join(str(n) for n in ns))
    out += ["$EndElements", ""]
    return "\n".join(out)


def tets_msh2(nodes, tets):
    """MSH 2.2 of 0-based tets (written with 1-based tags)."""
    return msh2(nodes, [(4, [i + 1 for i in t]) for t in tets])


def vtk_legacy(nodes, cells):
    """Legacy VTK ASCII. cells: list of (vtk type, [0-based ids])."""
    out = ["# vtk DataFile Version 4.2", "bad test mesh", "ASCII", "DATASET UNSTRUCTURED_GRID"]
    out.append(f"POINTS {len(nodes)} double")
    out += [" ".join(repr(float(x)) for x in p) for p in nodes]
    out.append(f"CELLS {len(cells)} {sum(len(c) + 1 for _, c in cells)}")
    out += [f"{len(c)} " + " ".join(map(str, c)) for _, c in cells]
    out.append(f"CELL_TYPES {len(cells)}")
    out += [str(t) for t, _ in cells]
    return "\n".join(out) + "\n"


# The unit cube's corners, vertex index i + 2j + 4k, and its 5-tet decomposition (4 corner tets
# around a central one).
CUBE = [(S * i, S * j, S * k) for k in (0, 1) for j in (0, 1) for i in (0, 1)]
FIVE = [[0, 1, 2, 4], [3, 1, 2, 7], [5, 1, 4, 7], [6, 2, 4, 7], [1, 2, 4, 7]]
FIVE = [positive(CUBE, t) for t in FIVE]
# The corner tetrahedron of the same box.
TET = [(0.0, 0.0, 0.0), (S, 0.0, 0.0), (0.0, S, 0.0), (0.0, 0.0, S)]


def bad_files(cube_v2_text):
    files = {}

    # Validation errors, in validate()'s order.
    files["no_tets.msh"] = msh2(TET[:3], [(15, [1]), (1, [1, 2]), (2, [1, 2, 3])])
    t5 = TET + [(S, S, S)]
    files["index_out_of_range.vtk"] = vtk_legacy(
        t5, [(10, [0, 1, 2, 3]), (10, positive(t5, [1, 2, 3, 4])[:3] + [9])]
    )
    files["repeated_node.msh"] = tets_msh2(t5, [[0, 1, 2, 3], positive(t5, [1, 2, 3, 4]), [1, 2, 3, 2]])
    nf = [f"{i + 1} {x!r} {y!r} {z!r}" for i, (x, y, z) in enumerate(TET)]
    nf[2] = "3 0.0 nan 0.0"
    files["non_finite.msh"] = tets_msh2(nf, [[0, 1, 2, 3]])
    # Node 8 is a copy of node 1; tet 1 uses it instead of node 1 (a crack).
    five_dup = [list(t) for t in FIVE]
    five_dup[1] = [8 if v == 1 else v for v in FIVE[1]]
    files["duplicate_nodes.msh"] = tets_msh2(CUBE + [CUBE[1]], five_dup)
    files["unreferenced.msh"] = tets_msh2(CUBE + [(2 * S, 2 * S, 2 * S)], FIVE)
    # Tet 1 = nodes 0, 1, 2 and node 4, a point 1e-12 m above node 3: flat.
    dg = CUBE[:4] + [(S, S, 1e-12)] + CUBE[4:]
    shift = [[v if v < 4 else v + 1 for v in t] for t in FIVE]
    files["degenerate.msh"] = tets_msh2(dg, [shift[0], positive(dg, [0, 1, 2, 4])] + shift[1:])
    inv = [list(t) for t in FIVE]
    inv[3][2], inv[3][3] = inv[3][3], inv[3][2]
    files["inverted.msh"] = tets_msh2(CUBE, inv)
    # Tet 5 repeats tet 2 with its nodes rotated (an even permutation: same orientation).
    a, b, c, d = FIVE[2]
    files["duplicate_tet.msh"] = tets_msh2(CUBE, FIVE + [[b, c, a, d]])
    # Three tets on one face: two above it (overlapping), one below.
    nm = TET[:3] + [(0.0, 0.0, S), (0.003, 0.003, 2 * S), (0.003, 0.003, -S)]
    files["nonmanifold_face.msh"] = tets_msh2(nm, [positive(nm, [0, 1, 2, k]) for k in (3, 4, 5)])
    # Two tets on the same side of their common face (a fold), no third one.
    files["overlapping.msh"] = tets_msh2(nm[:5], [positive(nm, [0, 1, 2, k]) for k in (3, 4)])
    # Two tets sharing only the edge between nodes 0 and 1.
    ne = TET + [(0.0, -S, -0.2 * S), (0.0, -0.2 * S, -S)]
    files["nonmanifold_edge.msh"] = tets_msh2(ne, [[0, 1, 2, 3], positive(ne, [0, 1, 4, 5])])
    # Two tets sharing only node 0.
    nv = TET + [(-S, 0.0, 0.0), (0.0, -S, 0.0), (0.0, 0.0, -S)]
    files["nonmanifold_vertex.msh"] = tets_msh2(nv, [[0, 1, 2, 3], positive(nv, [0, 4, 5, 6])])

    # Reader errors.
    # Cut at a line end inside $Nodes.
    cut = cube_v2_text.rindex("\n", 0, cube_v2_text.index("$EndNodes") - 40) + 1
    files["truncated.msh"] = cube_v2_text[:cut]
    bn = [f"{i + 1} {x!r} {y!r} {z!r}" for i, (x, y, z) in enumerate(TET)]
    bn[1] = "2 0.01 0.0O 0.0"  # letter O instead of zero
    files["bad_number.msh"] = tets_msh2(bn, [[0, 1, 2, 3]])
    edges = ((0, 1), (1, 2), (0, 2), (0, 3), (2, 3), (1, 3))
    mid = [tuple((np.array(TET[a]) + np.array(TET[b])) / 2) for a, b in edges]
    files["tet10.msh"] = msh2(TET + mid, [(2, [1, 2, 3]), (11, list(range(1, 11)))])
    files["hex.msh"] = msh2(CUBE, [(5, [1, 2, 4, 3, 5, 6, 8, 7])])
    files["hex.vtk"] = vtk_legacy(CUBE, [(10, FIVE[0]), (12, [0, 1, 3, 2, 4, 5, 7, 6])])
    files["unknown_node_tag.msh"] = msh2(TET, [(4, [1, 2, 3, 99])])
    files["version40.msh"] = "$MeshFormat\n4 0 8\n$EndMeshFormat\n"
    files["version1.msh"] = "$NOD\n1\n1 0 0 0\n$ENDNOD\n$ELM\n0\n$ENDELM\n"
    files["binary_v2.msh"] = "$MeshFormat\n2.2 1 8\n\x01\x00\x00\x00\n$EndMeshFormat\n"
    files["cube.stl"] = "solid cube\nendsolid cube\n"
    return files


def main():
    os.makedirs(BAD, exist_ok=True)
    points, tets, tris = cube_with_gmsh()
    write_meshio(points, tets, tris)
    write_noncontiguous_v2(points, tets)
    write_sparse_v1(points, tets, tris)
    write_appended_vtu(points, tets, tris)
    with open(os.path.join(DATA, "cube_v2.msh")) as f:
        cube_v2 = f.read()
    for name, text in bad_files(cube_v2).items():
        with open(os.path.join(BAD, name), "w", newline="\n") as f:
            f.write(text)
    total = sum(abs(vol(points, t)) for t in tets)
    print(f"cube: {len(points)} nodes, {len(tets)} tets, {len(tris)} boundary triangles, "
          f"volume {total:.6e} m^3 (expected {L ** 3:.6e})", file=sys.stderr)


if __name__ == "__main__":
    main()
