//! Mesh validation: the checks a mesh must pass before it is used for FEM.

use super::TetMesh;
use super::boundary::{check_indices, check_size, surface};
use super::error::{MeshError, nofile};
use crate::vec3::{dot, sub};
use rayon::prelude::*;
use std::collections::HashMap;

/// Tetrahedra with shape quality `6*sqrt(2)*|V| / l_rms^3` below this are degenerate
/// (1 for a regular tetrahedron, 0 for a flat one).
pub const DEGENERATE_QUALITY: f64 = 1e-6;

/// Two nodes closer than this fraction of the bounding-box diagonal are duplicates.
pub const DUPLICATE_NODE_TOLERANCE: f64 = 1e-12;

impl TetMesh {
    /// Shape quality of tetrahedron `t`: `6*sqrt(2)*V / l_rms^3` with `V` the signed volume and
    /// `l_rms` the root-mean-square edge length. 1 for a regular tetrahedron, near 0 for a flat
    /// one, negative when inverted. Panics if `t` or its node ids are out of range.
    pub fn quality(&self, t: usize) -> f64 {
        let p = self.tets[t].map(|i| self.nodes[i]);
        let mut sum_sq = 0.0;
        for i in 0..4 {
            for j in i + 1..4 {
                let e = sub(p[j], p[i]);
                sum_sq += dot(e, e);
            }
        }
        let l_rms = (sum_sq / 6.0).sqrt();
        6.0 * std::f64::consts::SQRT_2 * self.signed_volume(t) / (l_rms * l_rms * l_rms)
    }
}

/// Check `mesh` for everything that would make FEM on it wrong; returns the first problem found.
///
/// The checks run in this order (and within each, in increasing id order), so the result is
/// deterministic: no tetrahedra; node id out of range; node repeated within a tetrahedron;
/// non-finite coordinate; duplicate nodes; unreferenced node; degenerate or inverted
/// tetrahedron; duplicate tetrahedron; face shared by more than two tetrahedra (or two
/// tetrahedra on the same side of a face); boundary edge not shared by exactly two boundary
/// triangles; boundary vertex whose triangles form more than one fan.
pub fn validate(mesh: &TetMesh) -> Result<(), MeshError> {
    if mesh.tets.is_empty() {
        return Err(MeshError::NoTetrahedra {
            file: nofile(),
            nodes: mesh.nodes.len(),
        });
    }
    check_size(mesh)?;
    check_indices(mesh)?;
    check_repeated(mesh)?;
    check_finite(mesh)?;
    check_duplicate_nodes(mesh)?;
    check_unreferenced(mesh)?;
    check_shapes(mesh)?;
    check_duplicate_tets(mesh)?;
    surface(mesh).map(|_| ())
}

fn check_repeated(mesh: &TetMesh) -> Result<(), MeshError> {
    let repeated = |t: &[usize; 4]| (0..4).find(|&i| t[i + 1..].contains(&t[i]));
    if let Some(t) = mesh
        .tets
        .par_iter()
        .position_first(|t| repeated(t).is_some())
    {
        let nodes = mesh.tets[t];
        let node = repeated(&nodes).map_or(0, |i| nodes[i]);
        return Err(MeshError::RepeatedNode {
            file: nofile(),
            tet: t,
            node,
            nodes,
        });
    }
    Ok(())
}

fn check_finite(mesh: &TetMesh) -> Result<(), MeshError> {
    if let Some(i) = mesh
        .nodes
        .par_iter()
        .position_first(|p| !p.iter().all(|x| x.is_finite()))
    {
        return Err(MeshError::NonFiniteCoordinate {
            file: nofile(),
            node: i,
            coords: mesh.nodes[i],
        });
    }
    Ok(())
}

/// Duplicate nodes through a hash grid: cells of size `4 * tol`; a node is compared with the
/// earlier nodes in its cell and, when within `tol` of a cell wall, the neighbouring cells.
/// Reports the first node (in id order) that has an earlier duplicate, with the lowest such id.
fn check_duplicate_nodes(mesh: &TetMesh) -> Result<(), MeshError> {
    let (lo, hi) = mesh.bounding_box();
    let d = sub(hi, lo);
    let tol = DUPLICATE_NODE_TOLERANCE * dot(d, d).sqrt();
    let report = |first: usize, second: usize| {
        let e = sub(mesh.nodes[second], mesh.nodes[first]);
        MeshError::DuplicateNodes {
            file: nofile(),
            first,
            second,
            coords: mesh.nodes[first],
            distance: dot(e, e).sqrt(),
        }
    };
    if !(tol > 0.0 && tol.is_finite()) {
        // All nodes at one point, or a bounding box too large for f64: exact duplicates only.
        let key = |p: &[f64; 3]| p.map(|x| (x + 0.0).to_bits());
        let mut seen: HashMap<[u64; 3], usize> = HashMap::with_capacity(mesh.nodes.len());
        for (j, p) in mesh.nodes.iter().enumerate() {
            if let Some(&i) = seen.get(&key(p)) {
                return Err(report(i, j));
            }
            seen.insert(key(p), j);
        }
        return Ok(());
    }
    let h = 4.0 * tol;
    let rel = tol / h;
    // Head of each cell's chain of node ids, and the chain links (`usize::MAX` ends a chain).
    let mut head: HashMap<[i64; 3], usize> = HashMap::with_capacity(mesh.nodes.len());
    let mut next = vec![usize::MAX; mesh.nodes.len()];
    for (j, p) in mesh.nodes.iter().enumerate() {
        let mut cell = [0i64; 3];
        let mut range = [(0i64, 0i64); 3];
        for a in 0..3 {
            let f = (p[a] - lo[a]) / h;
            let k = f.floor();
            let r = f - k;
            cell[a] = k as i64;
            range[a] = (-((r < rel) as i64), (r > 1.0 - rel) as i64);
        }
        let mut best: Option<usize> = None;
        for dx in range[0].0..=range[0].1 {
            for dy in range[1].0..=range[1].1 {
                for dz in range[2].0..=range[2].1 {
                    let key = [cell[0] + dx, cell[1] + dy, cell[2] + dz];
                    let mut i = head.get(&key).copied().unwrap_or(usize::MAX);
                    while i != usize::MAX {
                        let e = sub(mesh.nodes[i], *p);
                        if dot(e, e).sqrt() <= tol && best.is_none_or(|b| i < b) {
                            best = Some(i);
                        }
                        i = next[i];
                    }
                }
            }
        }
        if let Some(i) = best {
            return Err(report(i, j));
        }
        if let Some(h) = head.insert(cell, j) {
            next[j] = h;
        }
    }
    Ok(())
}

fn check_unreferenced(mesh: &TetMesh) -> Result<(), MeshError> {
    let mut used = vec![false; mesh.nodes.len()];
    for t in &mesh.tets {
        for &v in t {
            used[v] = true;
        }
    }
    if let Some(node) = used.iter().position(|&u| !u) {
        return Err(MeshError::UnreferencedNode {
            file: nofile(),
            node,
        });
    }
    Ok(())
}

/// Quality below the threshold, or NaN (all four nodes at one point).
fn is_degenerate(quality: f64) -> bool {
    quality.is_nan() || quality.abs() < DEGENERATE_QUALITY
}

fn check_shapes(mesh: &TetMesh) -> Result<(), MeshError> {
    let bad = |t: usize| {
        let q = mesh.quality(t);
        is_degenerate(q) || q < 0.0
    };
    if let Some(t) = (0..mesh.tets.len()).into_par_iter().position_first(bad) {
        let quality = mesh.quality(t);
        let volume = mesh.signed_volume(t);
        return Err(if is_degenerate(quality) {
            MeshError::DegenerateTet {
                file: nofile(),
                tet: t,
                quality: quality.abs(),
                volume,
            }
        } else {
            MeshError::InvertedTet {
                file: nofile(),
                tet: t,
                volume,
            }
        });
    }
    Ok(())
}

fn check_duplicate_tets(mesh: &TetMesh) -> Result<(), MeshError> {
    let mut keys: Vec<([usize; 4], usize)> = mesh
        .tets
        .par_iter()
        .enumerate()
        .map(|(t, tet)| {
            let mut k = *tet;
            k.sort_unstable();
            (k, t)
        })
        .collect();
    keys.par_sort_unstable();
    let dup = keys
        .chunk_by(|a, b| a.0 == b.0)
        .filter(|g| g.len() > 1)
        .min_by_key(|g| g[1].1);
    if let Some(g) = dup {
        return Err(MeshError::DuplicateTet {
            file: nofile(),
            first: g[0].1,
            second: g[1].1,
            nodes: g[0].0,
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::structured::box_mesh;

    fn unit_tet() -> TetMesh {
        TetMesh {
            nodes: vec![[0., 0., 0.], [1., 0., 0.], [0., 1., 0.], [0., 0., 1.]],
            tets: vec![[0, 1, 2, 3]],
        }
    }

    #[test]
    fn regular_tet_has_quality_one() {
        let s = 1.0 / 2f64.sqrt();
        let m = TetMesh {
            nodes: vec![[1., 0., -s], [-1., 0., -s], [0., 1., s], [0., -1., s]],
            tets: vec![[0, 1, 2, 3]],
        };
        let q = m.quality(0);
        assert!((q.abs() - 1.0).abs() < 1e-12, "{q}");
    }

    #[test]
    fn box_mesh_is_valid() {
        validate(&box_mesh([0.1, 0.2, 0.3], [3, 2, 4])).unwrap();
        validate(&unit_tet()).unwrap();
    }

    #[test]
    fn near_duplicate_nodes_within_tolerance() {
        let mut m = box_mesh([1.0, 1.0, 1.0], [2, 2, 2]);
        // A node 1e-13 from node 13 (the centre), but distinct bits.
        let c = m.nodes[13];
        m.nodes.push([c[0] + 1e-13, c[1], c[2] - 1e-13]);
        let e = validate(&m).unwrap_err();
        assert!(
            matches!(
                e,
                MeshError::DuplicateNodes {
                    first: 13,
                    second: 27,
                    ..
                }
            ),
            "{e}"
        );
        // 1e-9 apart is not a duplicate (it is unreferenced instead).
        m.nodes[27] = [c[0] + 1e-9, c[1], c[2]];
        let e = validate(&m).unwrap_err();
        assert!(
            matches!(e, MeshError::UnreferencedNode { node: 27, .. }),
            "{e}"
        );
    }

    #[test]
    fn huge_coordinates_do_not_fake_duplicates() {
        let mut m = unit_tet();
        m.nodes[1] = [1e308, 0.0, 0.0];
        m.nodes[2] = [-1e308, 1.0, 0.0];
        // The bounding-box diagonal overflows; distinct nodes must not be reported.
        assert!(!matches!(
            validate(&m),
            Err(MeshError::DuplicateNodes { .. })
        ));
        m.nodes[3] = m.nodes[1];
        let e = validate(&m).unwrap_err();
        assert!(
            matches!(
                e,
                MeshError::DuplicateNodes {
                    first: 1,
                    second: 3,
                    ..
                }
            ),
            "{e}"
        );
    }

    #[test]
    fn degenerate_then_inverted() {
        let mut m = unit_tet();
        m.nodes[3] = [0.3, 0.3, 1e-9];
        let e = validate(&m).unwrap_err();
        assert!(matches!(e, MeshError::DegenerateTet { tet: 0, .. }), "{e}");
        let mut m = unit_tet();
        m.tets[0].swap(0, 1);
        let e = validate(&m).unwrap_err().to_string();
        assert_eq!(e, "tetrahedron 0 is inverted (signed volume -1.67e-1 m^3)");
    }

    #[test]
    fn empty_and_out_of_range() {
        let m = TetMesh {
            nodes: vec![],
            tets: vec![],
        };
        assert!(matches!(validate(&m), Err(MeshError::NoTetrahedra { .. })));
        let mut m = unit_tet();
        m.tets[0][2] = 17;
        let e = validate(&m).unwrap_err().to_string();
        assert_eq!(
            e,
            "tetrahedron 0 refers to node 17, but the mesh has only 4 nodes"
        );
    }
}
