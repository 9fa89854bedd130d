#!/usr/bin/env python3
"""Independent scipy/CHOLMOD peer of ``host compliance`` (speed comparison only, not a test).

Computes, for a P1 linear-elastic tetrahedral mesh, the compliance tensors of
Cotin, Delingette & Ayache (IEEE TVCG 1999): C(n, k) = 3x3 block of K_ff^-1
(displacement of node n per unit force on node k, m/N), after fixing every dof
of the nodes inside the ``--fix-box`` boxes.  It shares no code with the Rust
implementation:

1. read the ``.msh`` (meshio, or the gmsh Python API if meshio is missing);
   only the linear tetrahedra are used; node i = i-th node of the file;
2. assemble K (3 dofs per node, node-major numbering 3*i+c; isotropic,
   B^T D B V per tetrahedron, vectorised numpy, ``scipy.sparse`` COO -> CSC);
3. fix all dofs of the nodes inside any box (inclusive bounds);
4. factor K_ff with CHOLMOD (scikit-sparse ``sksparse.cholmod``, i.e.
   ``cholesky`` = ``analyze`` + ``cholesky_inplace``, default ordering and
   supernodal/simplicial choice); without scikit-sparse, fall back to scipy ``splu``
   (SuperLU, much slower) with a warning;
5. solve for the 3 columns of each requested node, ``--block`` (256)
   right-hand sides at a time, and gather the rows of the requested nodes.

stdout: one JSON object ``{"nodes", "dofs" (free), "columns" (requested
nodes), "assemble_s", "factor_s", "columns_s", "nnz_L", "peak_rss_mb"}`` plus
``"solver"`` (cholmod or splu), ``"symbolic_s"`` (ordering + symbolic analysis,
included in ``factor_s``) and ``"trace_sum"`` (sum of trace C(n, n) over the
requested nodes, m/N, a cheap cross-check).  ``assemble_s`` is element
matrices + COO -> CSC + extraction of K_ff (mesh reading is not timed),
``factor_s`` the ordering and symbolic + numeric factorisation, ``columns_s``
the solves and the gathering of the requested rows.  ``peak_rss_mb`` is the
process's peak resident set after the solves; ``nnz_L`` (nonzeros of the
factor L, diagonal included) is counted after that, from an explicit copy of L.
With ``--blocks-out F``: ``{"nodes": [...], "blocks": [[[9 numbers] ...] ...]}``,
``blocks[a][b]`` = C(nodes[a], nodes[b]) row-major, m/N (the shape the Rust
CLI prints).  A requested node that is fixed gets zero blocks.

Install
-------
::

    apt-get install -y libsuitesparse-dev libopenblas0-pthread   # CHOLMOD + an optimised BLAS
    pip install scikit-sparse meshio==5.3.5                      # numpy, scipy too

CHOLMOD uses the system ``libblas.so.3``; with Debian's default reference
BLAS the supernodal factorisation is several times slower, hence
``libopenblas0-pthread``.  SuiteSparse 5.x (Debian 12) needs
``scikit-sparse<0.5`` (0.4.16 works); 0.5 needs SuiteSparse 7.

Run
---
::

    python3 host/benches/peer/compliance_peer.py host/meshes/liver-1k4.msh \\
        --young 3000 --poisson 0.45 --fix-box -1,-1,-1,1,1,0.01 --surface-free \\
        [--threads 1] [--blocks-out /tmp/peer-blocks.json]
    python3 host/benches/peer/compliance_peer.py mesh.msh --fix-box ... --nodes 0,5,17
"""

from __future__ import annotations

import os
import sys


def _preparse_threads(argv):
    """--threads must act before numpy/scipy load their BLAS."""
    for i, a in enumerate(argv):
        if a == "--threads" and i + 1 < len(argv):
            return argv[i + 1]
        if a.startswith("--threads="):
            return a.split("=", 1)[1]
    return None


_THREADS = _preparse_threads(sys.argv[1:])
if _THREADS is not None:
    for _var in (
        "OMP_NUM_THREADS",
        "OPENBLAS_NUM_THREADS",
        "MKL_NUM_THREADS",
        "BLIS_NUM_THREADS",
        "VECLIB_MAXIMUM_THREADS",
        "NUMEXPR_NUM_THREADS",
    ):
        os.environ[_var] = _THREADS

import argparse  # noqa: E402
import contextlib  # noqa: E402
import json  # noqa: E402
import resource  # noqa: E402
import time  # noqa: E402
import warnings  # noqa: E402

import numpy as np  # noqa: E402
import scipy.sparse as sp  # noqa: E402

try:
    from sksparse.cholmod import analyze as _cholmod_analyze
    from sksparse.cholmod import cholesky as _cholmod_cholesky
except ImportError:  # pragma: no cover
    _cholmod_analyze = _cholmod_cholesky = None


# ---------------------------------------------------------------------------------------------
# Mesh
# ---------------------------------------------------------------------------------------------


def read_mesh(path):
    """Return (points (N,3) float64, tets (M,4) int64, 0-based in file node order)."""
    try:
        import meshio
    except ImportError:
        meshio = None
    if meshio is not None:
        with contextlib.redirect_stdout(sys.stderr):  # meshio 5.3 prints a stray newline
            m = meshio.read(path)
        tets = [c.data for c in m.cells if c.type == "tetra"]
        if not tets:
            raise SystemExit(f"error: {path}: no linear tetrahedra")
        return np.ascontiguousarray(m.points[:, :3], dtype=np.float64), np.vstack(tets).astype(np.int64)
    import gmsh  # fallback

    gmsh.initialize(readConfigFiles=False)
    gmsh.option.setNumber("General.Terminal", 0)
    gmsh.open(path)
    tags, coords, _ = gmsh.model.mesh.getNodes()
    _, conn = gmsh.model.mesh.getElementsByType(4)
    gmsh.finalize()
    order = np.argsort(tags)
    pos = order[np.searchsorted(np.asarray(tags)[order], conn)]
    return np.asarray(coords, dtype=np.float64).reshape(-1, 3), pos.reshape(-1, 4).astype(np.int64)


def boundary_nodes(tets):
    """Nodes of the faces that belong to exactly one tetrahedron."""
    faces = np.concatenate([tets[:, [1, 2, 3]], tets[:, [0, 2, 3]], tets[:, [0, 1, 3]], tets[:, [0, 1, 2]]])
    faces.sort(axis=1)
    _, inv, counts = np.unique(faces, axis=0, return_inverse=True, return_counts=True)
    return np.unique(faces[counts[inv.ravel()] == 1])


# ---------------------------------------------------------------------------------------------
# Assembly
# ---------------------------------------------------------------------------------------------


def assemble_stiffness(points, tets, young, poisson):
    """Global P1 stiffness (3N x 3N, CSC), dof 3*i+c."""
    lam = young * poisson / ((1.0 + poisson) * (1.0 - 2.0 * poisson))
    mu = young / (2.0 * (1.0 + poisson))
    p = points[tets]  # (M,4,3)
    jac = np.stack([p[:, 1] - p[:, 0], p[:, 2] - p[:, 0], p[:, 3] - p[:, 0]], axis=2)  # columns = edges
    det = np.linalg.det(jac)
    if np.any(det <= 0):
        bad = int(np.argmin(det))
        raise SystemExit(f"error: tetrahedron {bad} has non-positive volume {det[bad] / 6:.3e}")
    vol = det / 6.0
    inv = np.linalg.inv(jac)  # rows of inv(J) = gradients of barycentric coords 1..3
    grad = np.empty((len(tets), 4, 3))
    grad[:, 1:] = inv
    grad[:, 0] = -inv.sum(axis=1)
    # K[a,i,b,j] = V (lam g_a,i g_b,j + mu g_a,j g_b,i + mu delta_ij g_a . g_b)
    gg = np.einsum("mai,mbj->maibj", grad, grad)
    dots = np.einsum("mak,mbk->mab", grad, grad)
    ke = lam * gg + mu * gg.transpose(0, 1, 4, 3, 2)  # (a,i,b,j) -> (a,j,b,i)
    ke[:, :, [0, 1, 2], :, [0, 1, 2]] += mu * dots[None]
    ke *= vol[:, None, None, None, None]
    dof = (3 * tets[:, :, None] + np.arange(3)[None, None, :]).reshape(-1, 12).astype(np.int32)
    rows = np.repeat(dof, 12, axis=1).ravel()
    cols = np.tile(dof, (1, 12)).ravel()
    n = 3 * len(points)
    return sp.coo_matrix((ke.reshape(-1), (rows, cols)), shape=(n, n)).tocsc()


def parse_box(s):
    v = [float(x) for x in s.split(",")]
    if len(v) != 6:
        raise argparse.ArgumentTypeError("expected xmin,ymin,zmin,xmax,ymax,zmax")
    return v


# ---------------------------------------------------------------------------------------------
# Main
# ---------------------------------------------------------------------------------------------


def main(argv=None):
    ap = argparse.ArgumentParser(description="scipy/CHOLMOD peer of `host compliance` (benchmark)")
    ap.add_argument("mesh", help="Gmsh .msh (or anything meshio reads), metres")
    ap.add_argument("--young", "-E", type=float, default=3000.0, help="Young's modulus, Pa (default 3000)")
    ap.add_argument("--poisson", "--nu", type=float, default=0.45, help="Poisson ratio (default 0.45)")
    ap.add_argument("--fix-box", type=parse_box, action="append", default=[], metavar="XMIN,YMIN,ZMIN,XMAX,YMAX,ZMAX", help="fix all dofs of nodes inside (inclusive); repeatable")
    g = ap.add_mutually_exclusive_group(required=True)
    g.add_argument("--nodes", help="comma-separated 0-based node ids")
    g.add_argument("--surface-free", action="store_true", help="all free nodes of the boundary surface")
    ap.add_argument("--block", type=int, default=256, help="right-hand sides per solve (default 256)")
    ap.add_argument("--threads", type=int, help="BLAS/OpenMP threads (set before numpy loads)")
    ap.add_argument("--blocks-out", metavar="FILE", help="write the 3x3 blocks as JSON")
    ap.add_argument("--no-nnz", action="store_true", help="skip counting nnz(L) (needs a copy of L)")
    # argparse would take "-1,-1,..." for an option: glue such values to their flag.
    argv = list(sys.argv[1:] if argv is None else argv)
    for i in range(len(argv) - 2, -1, -1):
        if argv[i] in ("--fix-box", "--nodes") and argv[i + 1].startswith("-"):
            argv[i : i + 2] = [argv[i] + "=" + argv[i + 1]]
    args = ap.parse_args(argv)
    if not args.fix_box:
        ap.error("at least one --fix-box is needed (K is singular otherwise)")

    points, tets = read_mesh(args.mesh)
    n_nodes = len(points)

    t0 = time.perf_counter()
    k = assemble_stiffness(points, tets, args.young, args.poisson)
    fixed_node = np.zeros(n_nodes, dtype=bool)
    for b in args.fix_box:
        lo, hi = np.array(b[:3]), np.array(b[3:])
        fixed_node |= np.all((points >= lo) & (points <= hi), axis=1)
    if not fixed_node.any():
        raise SystemExit("error: no node inside the --fix-box boxes")
    free_dof = np.repeat(~fixed_node, 3)
    dof_map = np.full(3 * n_nodes, -1, dtype=np.int64)  # global dof -> free dof index
    dof_map[free_dof] = np.arange(int(free_dof.sum()))
    k_ff = k[free_dof][:, free_dof].tocsc()
    k_ff.sort_indices()
    del k
    assemble_s = time.perf_counter() - t0

    if args.surface_free:
        req = boundary_nodes(tets)
        req = req[~fixed_node[req]]
    else:
        req = np.array([int(x) for x in args.nodes.split(",") if x.strip()], dtype=np.int64)
        if req.size == 0 or req.min() < 0 or req.max() >= n_nodes:
            raise SystemExit(f"error: --nodes must be ids in 0..{n_nodes - 1}")
    m = len(req)
    req_dofs = (3 * req[:, None] + np.arange(3)).ravel()  # global dofs of the requested nodes
    req_free = dof_map[req_dofs]  # -1 where fixed
    col_dofs = np.flatnonzero(req_free >= 0)  # positions (in 0..3m) that have a free dof

    t0 = time.perf_counter()
    symbolic_s = None
    if _cholmod_cholesky is not None:
        solver = "cholmod"
        factor = _cholmod_analyze(k_ff)  # fill-reducing ordering + symbolic factorisation
        symbolic_s = time.perf_counter() - t0
        factor.cholesky_inplace(k_ff)  # numeric factorisation
        solve = factor  # factor(b) solves K_ff x = b
    else:
        from scipy.sparse.linalg import splu

        warnings.warn("scikit-sparse not installed: falling back to scipy splu (SuperLU), much slower")
        solver = "splu"
        factor = splu(k_ff, permc_spec="COLAMD")
        solve = factor.solve
    factor_s = time.perf_counter() - t0

    t0 = time.perf_counter()
    nf = k_ff.shape[0]
    out = np.zeros((3 * m, 3 * m)) if args.blocks_out else None
    rows_free = req_free[col_dofs]
    checksum = 0.0
    for s in range(0, len(col_dofs), args.block):
        cols = col_dofs[s : s + args.block]
        rhs = np.zeros((nf, len(cols)), order="F")
        rhs[req_free[cols], np.arange(len(cols))] = 1.0
        x = solve(rhs)
        sub = x[rows_free]  # displacements of the requested (free) dofs
        checksum += float(np.trace(sub[s : s + len(cols)]))
        if out is not None:
            out[np.ix_(col_dofs, cols)] = sub
    columns_s = time.perf_counter() - t0

    peak_rss_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # before L's copy
    nnz_l = None
    if not args.no_nnz:
        if solver == "cholmod":
            nnz_l = int(factor.L().nnz)
        else:
            nnz_l = int(factor.L.nnz)

    result = {
        "nodes": n_nodes,
        "dofs": int(nf),
        "columns": int(m),
        "assemble_s": round(assemble_s, 6),
        "factor_s": round(factor_s, 6),
        "columns_s": round(columns_s, 6),
        "nnz_L": nnz_l,
        "peak_rss_mb": round(peak_rss_mb, 1),
        "solver": solver,
        "symbolic_s": None if symbolic_s is None else round(symbolic_s, 6),  # part of factor_s
        "trace_sum": checksum,  # sum of trace C(n,n) over requested nodes, m/N (sanity check)
    }
    print(json.dumps(result))

    if out is not None:
        blocks = out.reshape(m, 3, m, 3).transpose(0, 2, 1, 3).reshape(m, m, 9)
        with open(args.blocks_out, "w") as f:
            f.write('{"nodes":' + json.dumps(req.tolist()) + ',"blocks":[')
            for a in range(m):
                if a:
                    f.write(",")
                f.write("[" + ",".join("[" + ",".join(repr(float(v)) for v in blk) + "]" for blk in blocks[a]) + "]")
            f.write("]}\n")


if __name__ == "__main__":
    main()
