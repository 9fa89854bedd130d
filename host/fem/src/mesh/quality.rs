//! Element quality beyond degeneracy: dihedral angles and radius ratios, for meshing reports.

use super::TetMesh;
use crate::vec3::{cross, dot, norm, scale, sub};

/// The six interior dihedral angles of tetrahedron `p`, radians, at edges (0,1), (0,2),
/// (0,3), (1,2), (1,3), (2,3).
pub fn dihedral_angles(p: [[f64; 3]; 4]) -> [f64; 6] {
    // Outward normal of the face opposite vertex k.
    let normal = |k: usize| {
        let f: Vec<[f64; 3]> = (0..4).filter(|&i| i != k).map(|i| p[i]).collect();
        let n = cross(sub(f[1], f[0]), sub(f[2], f[0]));
        let n = if dot(n, sub(p[k], f[0])) > 0.0 {
            scale(n, -1.0)
        } else {
            n
        };
        scale(n, 1.0 / norm(n))
    };
    let n = [normal(0), normal(1), normal(2), normal(3)];
    let edges = [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)];
    edges.map(|(i, j)| {
        let (k, l) = match (i, j) {
            (0, 1) => (2, 3),
            (0, 2) => (1, 3),
            (0, 3) => (1, 2),
            (1, 2) => (0, 3),
            (1, 3) => (0, 2),
            _ => (0, 1),
        };
        std::f64::consts::PI - dot(n[k], n[l]).clamp(-1.0, 1.0).acos()
    })
}

/// Radius ratio `3 r_in / r_circ` of tetrahedron `p`: 1 for a regular one, 0 for a flat one.
pub fn radius_ratio(p: [[f64; 3]; 4]) -> f64 {
    let a = sub(p[1], p[0]);
    let b = sub(p[2], p[0]);
    let c = sub(p[3], p[0]);
    let six_v = dot(a, cross(b, c));
    let faces = [(0, 1, 2), (0, 1, 3), (0, 2, 3), (1, 2, 3)];
    let area: f64 = faces
        .iter()
        .map(|&(i, j, k)| 0.5 * norm(cross(sub(p[j], p[i]), sub(p[k], p[i]))))
        .sum();
    if six_v == 0.0 || area == 0.0 {
        return 0.0;
    }
    let r_in = (six_v.abs() / 2.0) / area; // 3 V / A
    let dd = |v: [f64; 3]| dot(v, v);
    let centre = scale(
        [
            dd(a) * cross(b, c)[0] + dd(b) * cross(c, a)[0] + dd(c) * cross(a, b)[0],
            dd(a) * cross(b, c)[1] + dd(b) * cross(c, a)[1] + dd(c) * cross(a, b)[1],
            dd(a) * cross(b, c)[2] + dd(b) * cross(c, a)[2] + dd(c) * cross(a, b)[2],
        ],
        1.0 / (2.0 * six_v),
    );
    3.0 * r_in / norm(centre)
}

/// A mesh's worst elements.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct QualitySummary {
    /// Smallest dihedral angle, degrees, and its tetrahedron.
    pub min_dihedral_deg: (f64, usize),
    /// Largest dihedral angle, degrees.
    pub max_dihedral_deg: f64,
    /// Smallest radius ratio and its tetrahedron.
    pub min_radius_ratio: (f64, usize),
    /// Mean radius ratio.
    pub mean_radius_ratio: f64,
    /// Tetrahedra with a dihedral angle below [`SLIVER_DIHEDRAL_DEG`] (slivers).
    pub slivers: usize,
}

/// Tetrahedra with a dihedral angle below this (degrees) are counted as slivers.
pub const SLIVER_DIHEDRAL_DEG: f64 = 5.0;

impl TetMesh {
    /// The worst dihedral angles and radius ratios (`None` without tetrahedra).
    pub fn quality_summary(&self) -> Option<QualitySummary> {
        let mut s = QualitySummary {
            min_dihedral_deg: (f64::INFINITY, 0),
            max_dihedral_deg: 0.0,
            min_radius_ratio: (f64::INFINITY, 0),
            mean_radius_ratio: 0.0,
            slivers: 0,
        };
        for (t, tet) in self.tets.iter().enumerate() {
            let p = tet.map(|i| self.nodes[i]);
            let d = dihedral_angles(p).map(f64::to_degrees);
            let lo = d.iter().copied().fold(f64::INFINITY, f64::min);
            let hi = d.iter().copied().fold(0.0, f64::max);
            if lo < s.min_dihedral_deg.0 {
                s.min_dihedral_deg = (lo, t);
            }
            s.max_dihedral_deg = s.max_dihedral_deg.max(hi);
            s.slivers += usize::from(lo < SLIVER_DIHEDRAL_DEG);
            let r = radius_ratio(p);
            if r < s.min_radius_ratio.0 {
                s.min_radius_ratio = (r, t);
            }
            s.mean_radius_ratio += r;
        }
        if self.tets.is_empty() {
            return None;
        }
        s.mean_radius_ratio /= self.tets.len() as f64;
        Some(s)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn regular_and_corner_tetrahedra() {
        // Regular: every dihedral angle is acos(1/3) = 70.529 deg, radius ratio 1.
        let s = 1.0 / 2f64.sqrt();
        let reg = [
            [1.0, 0.0, -s],
            [-1.0, 0.0, -s],
            [0.0, 1.0, s],
            [0.0, -1.0, s],
        ];
        for d in dihedral_angles(reg) {
            assert!((d - (1.0f64 / 3.0).acos()).abs() < 1e-12, "{d}");
        }
        assert!((radius_ratio(reg) - 1.0).abs() < 1e-12);
        // The corner tetrahedron (0, e1, e2, e3): three right angles at the corner edges, and
        // acos(1/sqrt 3) = 54.7356 deg at the others. r_in = 1 / (3 + sqrt 3), r_circ = sqrt 3 / 2.
        let corner = [[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        let d = dihedral_angles(corner);
        for k in 0..3 {
            assert!((d[k] - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
            assert!((d[k + 3] - (1.0 / 3f64.sqrt()).acos()).abs() < 1e-12);
        }
        let expect = 3.0 / (3.0 + 3f64.sqrt()) / (3f64.sqrt() / 2.0);
        assert!((radius_ratio(corner) - expect).abs() < 1e-12);
        // A sliver: four nearly coplanar points on a square.
        let sliver = [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.0, 1.0, 0.01],
            [0.0, 1.0, 0.0],
        ];
        let m = TetMesh {
            nodes: sliver.to_vec(),
            tets: vec![[0, 1, 2, 3]],
        };
        let q = m.quality_summary().unwrap();
        assert!(
            q.min_dihedral_deg.0 < 2.0 && q.max_dihedral_deg > 178.0,
            "{q:?}"
        );
        assert_eq!(q.slivers, 1);
        assert!(q.min_radius_ratio.0 < 0.05);
    }
}
