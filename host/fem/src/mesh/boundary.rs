//! The boundary surface of a tetrahedral mesh, and the topological (manifold) checks on it.

use super::TetMesh;
use super::error::{MeshError, nofile};
use rayon::prelude::*;

/// The boundary surface of a tetrahedral mesh.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Surface {
    /// Boundary triangles (faces of exactly one tetrahedron), oriented so that the normal
    /// `(b - a) x (c - a)` points out of the body.
    pub triangles: Vec<[usize; 3]>,
    /// Sorted, unique ids of the nodes on the boundary.
    pub nodes: Vec<usize>,
}

/// Local faces of a tetrahedron `[x0, x1, x2, x3]`: face `f` is opposite vertex `f`, ordered so
/// that its normal points outward when the tetrahedron is positively oriented.
const LOCAL_FACES: [[usize; 3]; 4] = [[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]];

/// The boundary surface of `mesh`: every face that belongs to exactly one tetrahedron, oriented
/// outward (a tetrahedron with negative volume has its faces flipped, so the orientation is
/// outward for it too).
///
/// Errors: a node id out of range, a face shared by more than two tetrahedra, two tetrahedra on
/// the same side of their common face, a boundary edge not shared by exactly two boundary
/// triangles, or a boundary vertex whose triangles form more than one fan.
pub fn boundary(mesh: &TetMesh) -> Result<Surface, MeshError> {
    check_size(mesh)?;
    check_indices(mesh)?;
    surface(mesh)
}

/// Reject meshes whose ids do not fit the packed 32-bit keys used here.
pub(crate) fn check_size(mesh: &TetMesh) -> Result<(), MeshError> {
    if mesh.nodes.len() >= u32::MAX as usize || mesh.tets.len() >= (1 << 30) {
        return Err(MeshError::TooLarge {
            file: nofile(),
            nodes: mesh.nodes.len(),
            tets: mesh.tets.len(),
        });
    }
    Ok(())
}

/// The first tetrahedron (in id order) with a node id out of range.
pub(crate) fn check_indices(mesh: &TetMesh) -> Result<(), MeshError> {
    let n = mesh.nodes.len();
    if let Some(t) = mesh
        .tets
        .par_iter()
        .position_first(|t| t.iter().any(|&v| v >= n))
    {
        let node = mesh.tets[t].iter().copied().find(|&v| v >= n).unwrap_or(n);
        return Err(MeshError::NodeIndexOutOfRange {
            file: nofile(),
            tet: t,
            node,
            num_nodes: n,
        });
    }
    Ok(())
}

/// Outward-oriented node triple of local face `f` of tetrahedron `t` (flipped if `t` is inverted).
fn oriented_face(mesh: &TetMesh, t: usize, f: usize) -> [usize; 3] {
    let tet = mesh.tets[t];
    let [i, j, k] = LOCAL_FACES[f];
    let mut tri = [tet[i], tet[j], tet[k]];
    if mesh.signed_volume(t) < 0.0 {
        tri.swap(1, 2);
    }
    tri
}

/// Whether a triple is an even permutation of its sorted order (all entries distinct).
fn is_even(tri: [usize; 3]) -> bool {
    let [a, b, c] = tri;
    // Rotate the smallest entry to the front; then even means the other two are increasing.
    let (x, y) = if a < b && a < c {
        (b, c)
    } else if b < a && b < c {
        (c, a)
    } else {
        (a, b)
    };
    x < y
}

/// Boundary extraction and manifold checks. Requires ids in range and [`check_size`].
pub(crate) fn surface(mesh: &TetMesh) -> Result<Surface, MeshError> {
    // Every face as one u128: sorted node ids in the top 96 bits, `4 * tet + local face` below.
    let mut faces: Vec<u128> = mesh
        .tets
        .par_iter()
        .enumerate()
        .flat_map_iter(|(t, tet)| {
            LOCAL_FACES.iter().enumerate().map(move |(f, l)| {
                let mut k = [tet[l[0]], tet[l[1]], tet[l[2]]];
                k.sort_unstable();
                ((k[0] as u128) << 96)
                    | ((k[1] as u128) << 64)
                    | ((k[2] as u128) << 32)
                    | (4 * t + f) as u128
            })
        })
        .collect();
    faces.par_sort_unstable();

    let mut triangles = Vec::new();
    for group in faces.chunk_by(|a, b| a >> 32 == b >> 32) {
        let who = |x: u128| {
            let tf = (x & 0xffff_ffff) as usize;
            (tf / 4, tf % 4)
        };
        match group {
            [one] => {
                let (t, f) = who(*one);
                triangles.push(oriented_face(mesh, t, f));
            }
            [x, y] => {
                let (t1, f1) = who(*x);
                let (t2, f2) = who(*y);
                let a = oriented_face(mesh, t1, f1);
                let b = oriented_face(mesh, t2, f2);
                if is_even(a) == is_even(b) {
                    let mut face = a;
                    face.sort_unstable();
                    return Err(MeshError::OverlappingTets {
                        file: nofile(),
                        face,
                        tets: [t1, t2],
                    });
                }
            }
            _ => {
                let key = group[0] >> 32;
                let face = [
                    (key >> 64) as u32 as usize,
                    (key >> 32) as u32 as usize,
                    key as u32 as usize,
                ];
                return Err(MeshError::NonManifoldFace {
                    file: nofile(),
                    face,
                    tets: group.iter().map(|&x| who(x).0).collect(),
                });
            }
        }
    }
    drop(faces);

    // Every boundary edge must have exactly two boundary triangles.
    let mut edges: Vec<u64> = triangles
        .iter()
        .flat_map(|&[a, b, c]| [(a, b), (b, c), (c, a)])
        .map(|(a, b)| ((a.min(b) as u64) << 32) | a.max(b) as u64)
        .collect();
    edges.par_sort_unstable();
    for group in edges.chunk_by(|a, b| a == b) {
        if group.len() != 2 {
            let e = group[0];
            return Err(MeshError::NonManifoldEdge {
                file: nofile(),
                edge: [(e >> 32) as usize, e as u32 as usize],
                triangles: group.len(),
            });
        }
    }
    drop(edges);

    // Around every boundary vertex the triangles must form a single fan (a disc). With the edge
    // check passed, the link of a vertex (the opposite edges of its triangles) is a union of
    // cycles; count them.
    let mut links: Vec<(u32, u32, u32)> = triangles
        .iter()
        .flat_map(|&[a, b, c]| [(a, b, c), (b, c, a), (c, a, b)])
        .map(|(v, x, y)| (v as u32, x as u32, y as u32))
        .collect();
    links.par_sort_unstable();
    let mut nodes = Vec::new();
    let mut local: Vec<u32> = Vec::new();
    let mut parent: Vec<usize> = Vec::new();
    for group in links.chunk_by(|a, b| a.0 == b.0) {
        let v = group[0].0 as usize;
        nodes.push(v);
        local.clear();
        local.extend(group.iter().flat_map(|&(_, x, y)| [x, y]));
        local.sort_unstable();
        local.dedup();
        parent.clear();
        parent.extend(0..local.len());
        let find = |parent: &mut Vec<usize>, mut i: usize| {
            while parent[i] != i {
                parent[i] = parent[parent[i]];
                i = parent[i];
            }
            i
        };
        for &(_, x, y) in group {
            let (Ok(i), Ok(j)) = (local.binary_search(&x), local.binary_search(&y)) else {
                continue;
            };
            let (ri, rj) = (find(&mut parent, i), find(&mut parent, j));
            parent[ri] = rj;
        }
        let fans = (0..local.len())
            .filter(|&i| find(&mut parent, i) == i)
            .count();
        if fans != 1 {
            return Err(MeshError::NonManifoldVertex {
                file: nofile(),
                node: v,
                fans,
            });
        }
    }
    Ok(Surface { triangles, nodes })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::structured::box_mesh;
    use crate::vec3::{cross, dot, sub};

    #[test]
    fn parity() {
        assert!(is_even([1, 2, 3]) && is_even([2, 3, 1]) && is_even([3, 1, 2]));
        assert!(!is_even([1, 3, 2]) && !is_even([3, 2, 1]) && !is_even([2, 1, 3]));
    }

    #[test]
    fn single_tet_boundary_is_outward() {
        let m = TetMesh {
            nodes: vec![[0., 0., 0.], [1., 0., 0.], [0., 1., 0.], [0., 0., 1.]],
            tets: vec![[0, 1, 2, 3]],
        };
        let s = boundary(&m).unwrap();
        assert_eq!(s.triangles.len(), 4);
        assert_eq!(s.nodes, vec![0, 1, 2, 3]);
        let centroid = [0.25; 3];
        for [a, b, c] in s.triangles {
            let (pa, pb, pc) = (m.nodes[a], m.nodes[b], m.nodes[c]);
            let n = cross(sub(pb, pa), sub(pc, pa));
            assert!(dot(n, sub(pa, centroid)) > 0.0);
        }
        // Inverted: still outward.
        let inv = TetMesh {
            nodes: m.nodes.clone(),
            tets: vec![[0, 2, 1, 3]],
        };
        for [a, b, c] in boundary(&inv).unwrap().triangles {
            let (pa, pb, pc) = (m.nodes[a], m.nodes[b], m.nodes[c]);
            let n = cross(sub(pb, pa), sub(pc, pa));
            assert!(dot(n, sub(pa, centroid)) > 0.0);
        }
    }

    #[test]
    fn box_boundary_counts() {
        let m = box_mesh([1.0, 2.0, 3.0], [2, 3, 4]);
        let s = boundary(&m).unwrap();
        // 2 triangles per boundary square.
        assert_eq!(s.triangles.len(), 2 * 2 * (2 * 3 + 3 * 4 + 2 * 4));
        assert_eq!(s.nodes.len(), 3 * 4 * 5 - 2 * 3);
    }

    #[test]
    fn out_of_range_is_an_error_not_a_panic() {
        let m = TetMesh {
            nodes: vec![[0.0; 3]; 3],
            tets: vec![[0, 1, 2, 3]],
        };
        let e = boundary(&m).unwrap_err().to_string();
        assert_eq!(
            e,
            "tetrahedron 0 refers to node 3, but the mesh has only 3 nodes"
        );
    }
}
