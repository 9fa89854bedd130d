//! Structured tetrahedral meshes of a box, for tests and benchmarks with analytic references.

use super::TetMesh;

/// A box `[0,lx] x [0,ly] x [0,lz]` split into `nx * ny * nz` cubes of six tetrahedra each
/// (Kuhn / Freudenthal subdivision: every tetrahedron shares the cube's main diagonal, so the
/// subdivision is conforming across cubes).
pub fn box_mesh(size: [f64; 3], cells: [usize; 3]) -> TetMesh {
    let [nx, ny, nz] = cells;
    let id = |i: usize, j: usize, k: usize| i + (nx + 1) * (j + (ny + 1) * k);
    let mut nodes = Vec::with_capacity((nx + 1) * (ny + 1) * (nz + 1));
    for k in 0..=nz {
        for j in 0..=ny {
            for i in 0..=nx {
                nodes.push([
                    size[0] * i as f64 / nx as f64,
                    size[1] * j as f64 / ny as f64,
                    size[2] * k as f64 / nz as f64,
                ]);
            }
        }
    }
    // The six monotone lattice paths from corner (0,0,0) to (1,1,1).
    const PATHS: [[usize; 3]; 6] = [
        [0, 1, 2],
        [0, 2, 1],
        [1, 0, 2],
        [1, 2, 0],
        [2, 0, 1],
        [2, 1, 0],
    ];
    let mut tets = Vec::with_capacity(6 * nx * ny * nz);
    for k in 0..nz {
        for j in 0..ny {
            for i in 0..nx {
                for path in PATHS {
                    let mut c = [i, j, k];
                    let mut t = [id(c[0], c[1], c[2]); 4];
                    for (s, &axis) in path.iter().enumerate() {
                        c[axis] += 1;
                        t[s + 1] = id(c[0], c[1], c[2]);
                    }
                    tets.push(t);
                }
            }
        }
    }
    let mut mesh = TetMesh { nodes, tets };
    for t in 0..mesh.tets.len() {
        if mesh.signed_volume(t) < 0.0 {
            mesh.tets[t].swap(2, 3);
        }
    }
    mesh
}

/// [`box_mesh`] with every interior node moved by up to `amount / 2` of a cell along each axis,
/// pseudo-randomly from `seed` (the workspace's SplitMix64, deterministic), so that elements are irregular as
/// in a patch test while the boundary stays the box's. `amount` below about 0.5 keeps every
/// tetrahedron positively oriented; `None` if a move inverted one.
pub fn distorted_box_mesh(
    size: [f64; 3],
    cells: [usize; 3],
    amount: f64,
    seed: u64,
) -> Option<TetMesh> {
    let mut mesh = box_mesh(size, cells);
    let h = [0, 1, 2].map(|a| size[a] / cells[a] as f64);
    let mut rng = splitmix::SplitMix64::new(seed);
    let mut draw = || rng.unit() - 0.5;
    for p in &mut mesh.nodes {
        if (0..3).all(|a| p[a] > 1e-12 * size[a] && p[a] < size[a] * (1.0 - 1e-12)) {
            for (x, h) in p.iter_mut().zip(h) {
                *x += amount * h * draw();
            }
        }
    }
    (0..mesh.tets.len())
        .all(|t| mesh.signed_volume(t) > 0.0)
        .then_some(mesh)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn box_volume_is_exact_and_all_tets_positive() {
        let m = box_mesh([0.3, 0.2, 0.1], [3, 4, 5]);
        assert_eq!(m.nodes.len(), 4 * 5 * 6);
        assert_eq!(m.tets.len(), 6 * 60);
        let v: f64 = (0..m.tets.len()).map(|t| m.signed_volume(t)).sum();
        assert!((v - 0.006).abs() < 1e-15);
        assert!((0..m.tets.len()).all(|t| m.signed_volume(t) > 0.0));
    }
}
