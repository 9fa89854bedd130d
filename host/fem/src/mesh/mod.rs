//! Tetrahedral meshes: reading (Gmsh `.msh`, VTK `.vtu`/`.vtk`), validation, boundary surface.
//!
//! Node ids are 0-based positions in the file's node order; tetrahedron ids are 0-based positions
//! among the file's tetrahedra. Every error names the file and the offending id.
//!
//! - [`load`] = [`read`] + [`validate`]; [`read_bytes`] parses in-memory file contents.
//! - Formats: Gmsh MSH 1 and 2 ASCII (own parser), MSH 4.1 ASCII and binary (via `mshio`),
//!   legacy VTK `.vtk` ASCII and binary, classic and 5.1 layouts (own parser), VTK XML `.vtu`
//!   (own reader: ascii, base64 and raw appended data, optionally zlib-compressed), Medit
//!   `.mesh` ASCII (own parser). Gmsh node tags may be arbitrary and are mapped to positions. (`vtkio` is not used: it cannot read meshio's
//!   `.vtu` files nor VTK 5.1 files, and prints to stderr or panics on malformed input.)
//! - Elements of dimension < 3 (points, lines, surface triangles) are ignored and counted
//!   ([`Ignored`], from [`read_counted`]); 3D elements other than 4-node tetrahedra are an error
//!   ([`MeshError::UnsupportedElement`]).
//! - [`boundary`] gives the outward-oriented boundary triangles.
//!
//! No input makes these functions panic.

use crate::vec3::{cross, dot, sub};

mod boundary;
pub mod error;
mod gmsh;
mod io;
mod medit;
pub mod quality;
pub mod structured;
pub(crate) mod text;
mod validate;
mod vtk;
mod vtu;

pub use boundary::{Surface, boundary};
pub use error::{MeshError, Origin};
pub(crate) use io::MAX_MESH_BYTES;
pub use io::{Format, load, parse_msh, read, read_bytes, read_bytes_counted, read_counted};
pub use validate::{DEGENERATE_QUALITY, DUPLICATE_NODE_TOLERANCE, validate};
pub(crate) use vtk::read_vtk_polydata;
pub(crate) use vtu::read_vtp;

/// The elements of dimension < 3 a reader skipped (points, lines, surface triangles...): each
/// kind's name and count, in the order the file first lists them. Displays as
/// `"12 3-node triangle, 4 2-node line"` (empty when nothing was skipped).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Ignored(pub Vec<(String, usize)>);

impl Ignored {
    /// Count one more element of `kind`.
    pub(crate) fn add(&mut self, kind: &str) {
        self.add_many(kind, 1);
    }

    /// Count `n` more elements of `kind`.
    pub(crate) fn add_many(&mut self, kind: &str, n: usize) {
        match self.0.iter_mut().find(|(k, _)| k == kind) {
            Some((_, count)) => *count += n,
            None => self.0.push((kind.to_string(), n)),
        }
    }

    /// Elements skipped in all.
    pub fn total(&self) -> usize {
        self.0.iter().map(|(_, n)| n).sum()
    }
}

impl std::fmt::Display for Ignored {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        for (i, (kind, n)) in self.0.iter().enumerate() {
            let sep = if i == 0 { "" } else { ", " };
            write!(f, "{sep}{n} {kind}")?;
        }
        Ok(())
    }
}

/// A linear (P1) tetrahedral mesh in SI units (metres).
///
/// Tetrahedra are positively oriented: `(x1-x0) . ((x2-x0) x (x3-x0)) > 0`.
#[derive(Debug, Clone, PartialEq)]
pub struct TetMesh {
    /// Node coordinates in metres.
    pub nodes: Vec<[f64; 3]>,
    /// Four node ids per tetrahedron.
    pub tets: Vec<[usize; 4]>,
}

impl TetMesh {
    /// Signed volume of tetrahedron `t` (positive when correctly oriented).
    pub fn signed_volume(&self, t: usize) -> f64 {
        let [a, b, c, d] = self.tets[t].map(|i| self.nodes[i]);
        let u = sub(b, a);
        let v = sub(c, a);
        let w = sub(d, a);
        dot(u, cross(v, w)) / 6.0
    }

    /// A tetrahedron that holds `p` strictly inside (each of its four barycentric coordinates
    /// above one millionth), if any: a point on the surface or outside gives `None`.
    pub fn tet_containing(&self, p: [f64; 3]) -> Option<usize> {
        let vol = |a: [f64; 3], b: [f64; 3], c: [f64; 3], d: [f64; 3]| {
            dot(sub(b, a), cross(sub(c, a), sub(d, a)))
        };
        (0..self.tets.len()).find(|&t| {
            let [a, b, c, d] = self.tets[t].map(|i| self.nodes[i]);
            let whole = vol(a, b, c, d);
            let least = 1e-6 * whole;
            whole > 0.0
                && vol(p, b, c, d) > least
                && vol(a, p, c, d) > least
                && vol(a, b, p, d) > least
                && vol(a, b, c, p) > least
        })
    }

    /// Axis-aligned bounding box `(min, max)` of the nodes.
    pub fn bounding_box(&self) -> ([f64; 3], [f64; 3]) {
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for p in &self.nodes {
            for a in 0..3 {
                lo[a] = lo[a].min(p[a]);
                hi[a] = hi[a].max(p[a]);
            }
        }
        (lo, hi)
    }
}
