//! The specimen's meshes: the part of a box or a cylinder cut by its three symmetry planes
//! (the two lateral mid-planes through the compression axis and the axial mid-plane), meshed
//! so that its faces on those planes are exactly plane, and the whole specimen as that part
//! mirrored across the three planes (a mirror-symmetric mesh by construction).
//!
//! The part kept is the one on the larger side of every plane: `x_k >= c_k` for the centre
//! `c`. A box part is [`box_mesh`] (structured, six tetrahedra per cube); a cylinder part (a
//! quarter of the disc, half the height) is meshed by Gmsh through its pinned Python module
//! (`scripts/mesh_cylinder.py`, embedded here and run with `python3` or `$HOST_PYTHON`).

use anyhow::{Context, Result};
use fem::mesh::TetMesh;
use fem::mesh::structured::box_mesh;

const CYLINDER_SCRIPT: &str = include_str!("../../../../scripts/mesh_cylinder.py");

/// A node lies on a symmetry plane when its distance to it is at most this fraction of the
/// part's largest side; such nodes are snapped onto the plane.
const ON_PLANE: f64 = 1e-9;

/// The mesh of the box `[lo, hi]`'s part `[c, hi]` (`c` the box's centre), metres, with
/// `cells` cubes along the part's longest side and cubes of about the same size along the
/// others (at least one); returns the mesh and the cells along x, y and z.
pub fn box_part(lo: [f64; 3], hi: [f64; 3], cells: usize) -> (TetMesh, [usize; 3]) {
    let centre: [f64; 3] = std::array::from_fn(|k| 0.5 * (lo[k] + hi[k]));
    let size: [f64; 3] = std::array::from_fn(|k| hi[k] - centre[k]);
    let longest = size.iter().copied().fold(0.0, f64::max);
    let counts = size.map(|s| ((cells as f64 * s / longest).round() as usize).max(1));
    let mut mesh = box_mesh(size, counts);
    for p in &mut mesh.nodes {
        for k in 0..3 {
            p[k] += centre[k];
        }
    }
    (mesh, counts)
}

/// The mesh of the cylinder of `radius` and `height` (metres) whose axis is the line through
/// the origin along `axis` (0, 1, 2), base at 0 and top at `height`: its part in the positive
/// quadrant of the two lateral axes and the upper half of the height, by Gmsh at element size
/// `size` (metres). The part's faces on the symmetry planes are snapped exactly onto them.
pub fn cylinder_part(radius: f64, height: f64, axis: usize, size: f64) -> Result<TetMesh> {
    let dir = tempfile::tempdir().context("cannot make a temporary directory for Gmsh")?;
    let job = serde_json::json!({
        "radius": radius,
        "half_height": 0.5 * height,
        "size": size,
    });
    let local = crate::meshing::run_gmsh_job(dir.path(), CYLINDER_SCRIPT, job, "--cylinder: ")?;
    // Gmsh's frame: the axis is z, the part in x >= 0, y >= 0, z in [0, height / 2].
    let lateral = [(axis + 1) % 3, (axis + 2) % 3];
    let mut mesh = TetMesh {
        nodes: local
            .nodes
            .iter()
            .map(|q| {
                let mut p = [0.0; 3];
                p[lateral[0]] = q[0];
                p[lateral[1]] = q[1];
                p[axis] = q[2] + 0.5 * height;
                p
            })
            .collect(),
        tets: local.tets,
    };
    // The map (x, y, z) -> (lateral0, lateral1, axis) is a rotation for every axis (a cyclic
    // permutation), so the orientation is kept; check it anyway with the validation.
    let mut centre = [0.0; 3];
    centre[axis] = 0.5 * height;
    snap(&mut mesh, centre);
    fem::mesh::validate(&mesh).context("--cylinder: Gmsh's mesh fails validation")?;
    Ok(mesh)
}

/// The part's largest side.
fn extent(mesh: &TetMesh) -> f64 {
    let (lo, hi) = mesh.bounding_box();
    (0..3).map(|k| hi[k] - lo[k]).fold(0.0, f64::max)
}

/// Moves the nodes within [`ON_PLANE`] of a plane `x_k = centre_k` exactly onto it.
fn snap(mesh: &mut TetMesh, centre: [f64; 3]) {
    let tol = ON_PLANE * extent(mesh);
    for p in &mut mesh.nodes {
        for k in 0..3 {
            if (p[k] - centre[k]).abs() <= tol {
                p[k] = centre[k];
            }
        }
    }
}

/// `mesh` and its mirror image across the plane `x_k = c` (nodes on the plane shared, the
/// mirrored tetrahedra reoriented).
fn mirror(mesh: &TetMesh, k: usize, c: f64) -> TetMesh {
    let tol = ON_PLANE * extent(mesh);
    let mut nodes = mesh.nodes.clone();
    let image: Vec<usize> = mesh
        .nodes
        .iter()
        .enumerate()
        .map(|(i, p)| {
            if (p[k] - c).abs() <= tol {
                i
            } else {
                let mut q = *p;
                q[k] = 2.0 * c - p[k];
                nodes.push(q);
                nodes.len() - 1
            }
        })
        .collect();
    let mut tets = mesh.tets.clone();
    tets.extend(mesh.tets.iter().map(|t| {
        let [a, b, c, d] = t.map(|v| image[v]);
        [a, b, d, c]
    }));
    TetMesh { nodes, tets }
}

/// The whole specimen: `part` mirrored across the three planes `x_k = centre_k`.
pub fn whole(part: &TetMesh, centre: [f64; 3]) -> TetMesh {
    (0..3).fold(part.clone(), |m, k| mirror(&m, k, centre[k]))
}

/// The mirror image of `p` in the part (`x_k >= centre_k`) and, per component, the sign that
/// maps the image's displacement back to `p`'s (`-1` where the point was reflected).
pub fn reflect(p: [f64; 3], centre: [f64; 3]) -> ([f64; 3], [f64; 3]) {
    let mut q = p;
    let mut sign = [1.0; 3];
    for k in 0..3 {
        if p[k] < centre[k] {
            q[k] = 2.0 * centre[k] - p[k];
            sign[k] = -1.0;
        }
    }
    (q, sign)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The mirrored box is the whole box: 8 times the part's volume, the box's bounding box,
    /// every element positively oriented, nodes on the planes shared (the node count of the
    /// whole structured lattice).
    #[test]
    fn the_mirrored_part_is_the_whole_box() {
        let (lo, hi) = ([1.0, -2.0, 0.5], [3.0, 2.0, 1.5]);
        let (part, cells) = box_part(lo, hi, 4);
        assert_eq!(cells, [2, 4, 1]);
        let centre = [2.0, 0.0, 1.0];
        let w = whole(&part, centre);
        let volume = |m: &TetMesh| (0..m.tets.len()).map(|t| m.signed_volume(t)).sum::<f64>();
        assert!((volume(&w) - 8.0).abs() < 1e-12, "{}", volume(&w));
        assert!((0..w.tets.len()).all(|t| w.signed_volume(t) > 0.0));
        assert_eq!(w.bounding_box(), (lo, hi));
        assert_eq!(w.nodes.len(), 5 * 9 * 3);
        fem::mesh::validate(&w).unwrap();
        let (q, s) = reflect([1.5, 1.0, 0.7], centre);
        assert_eq!((q, s), ([2.5, 1.0, 1.3], [-1.0, 1.0, -1.0]));
    }
}
