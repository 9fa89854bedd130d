//! Markers: points inside the specimen, read from a CSV file (header `x,y,z`), located in the
//! tetrahedron that contains each one and displaced by the 10-node element's quadratic shape
//! functions.

use crate::calibrate::csv;
use anyhow::{Result, bail};
use fem::elasticity::quadratic::{EDGES, QuadraticBody};
use fem::mesh::TetMesh;
use std::path::Path;

/// Markers read from a file: positions in the file's units and the 1-based line of each.
#[derive(Debug, Clone, PartialEq)]
pub struct MarkerFile {
    /// The positions, in the file's units.
    pub points: Vec<[f64; 3]>,
    /// The 1-based line of each point in the file.
    pub lines: Vec<u64>,
}

/// Reads a markers CSV: a header row with columns `x`, `y` and `z` (other columns ignored),
/// one marker per row, `#` lines are comments. Refuses a file without markers, naming it.
pub fn read(path: &Path) -> Result<MarkerFile> {
    let table = csv::read(path, &["x", "y", "z"])?;
    table.require_rows(1, "one marker per row")?;
    let cols = [table.numbers(0)?, table.numbers(1)?, table.numbers(2)?];
    Ok(MarkerFile {
        points: (0..table.len())
            .map(|i| [cols[0][i], cols[1][i], cols[2][i]])
            .collect(),
        lines: table.lines.clone(),
    })
}

/// A marker's place in the mesh: its element and its barycentric coordinates there.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Located {
    /// The element (tetrahedron id in the mesh).
    pub element: usize,
    /// Barycentric coordinates of the marker, summing to 1, each within the tolerance of
    /// `[0, 1]`.
    pub barycentric: [f64; 4],
}

/// Barycentric coordinates of `p` in the tetrahedron `x` (Cramer's rule on the edge vectors
/// from vertex 0), or `None` if it is degenerate.
fn barycentric(x: [[f64; 3]; 4], p: [f64; 3]) -> Option<[f64; 4]> {
    let e: [[f64; 3]; 3] = std::array::from_fn(|k| std::array::from_fn(|c| x[k + 1][c] - x[0][c]));
    let r: [f64; 3] = std::array::from_fn(|c| p[c] - x[0][c]);
    let det3 = |a: [f64; 3], b: [f64; 3], c: [f64; 3]| {
        a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0])
            + a[2] * (b[0] * c[1] - b[1] * c[0])
    };
    let d = det3(e[0], e[1], e[2]);
    if d == 0.0 || !d.is_finite() {
        return None;
    }
    let l1 = det3(r, e[1], e[2]) / d;
    let l2 = det3(e[0], r, e[2]) / d;
    let l3 = det3(e[0], e[1], r) / d;
    Some([1.0 - l1 - l2 - l3, l1, l2, l3])
}

/// Locates each of `points` (metres) in `mesh`: the element whose smallest barycentric
/// coordinate is largest (the one it is most inside). A point whose best coordinate is below
/// `-tolerance` lies outside the mesh: the error gives its index in `points`.
pub fn locate(mesh: &TetMesh, points: &[[f64; 3]], tolerance: f64) -> Result<Vec<Located>, usize> {
    let corners: Vec<[[f64; 3]; 4]> = mesh.tets.iter().map(|t| t.map(|v| mesh.nodes[v])).collect();
    points
        .iter()
        .enumerate()
        .map(|(i, &p)| {
            let mut best: Option<(f64, Located)> = None;
            for (element, &x) in corners.iter().enumerate() {
                let Some(l) = barycentric(x, p) else { continue };
                let inside = l.iter().copied().fold(f64::INFINITY, f64::min);
                if best.as_ref().is_none_or(|(b, _)| inside > *b) {
                    best = Some((
                        inside,
                        Located {
                            element,
                            barycentric: l,
                        },
                    ));
                }
                if inside >= 0.0 {
                    break;
                }
            }
            match best {
                Some((inside, located)) if inside >= -tolerance => Ok(located),
                _ => Err(i),
            }
        })
        .collect()
}

/// The displacement at a located point of the node-major field `u` of `body` (nodes of the
/// 10-node tetrahedra): `sum_a N_a u_a` with the quadratic shape functions
/// `N_i = L_i (2 L_i - 1)` at the vertices and `N_ab = 4 L_a L_b` at the edge midpoints.
pub fn displacement(
    mesh: &TetMesh,
    body: &QuadraticBody,
    u: &[f64],
    at: &Located,
) -> Result<[f64; 3]> {
    let t = mesh.tets[at.element];
    let l = at.barycentric;
    let mut d = [0.0; 3];
    let mut add = |node: usize, n: f64| {
        for (c, dc) in d.iter_mut().enumerate() {
            *dc += n * u[3 * node + c];
        }
    };
    for i in 0..4 {
        add(t[i], l[i] * (2.0 * l[i] - 1.0));
    }
    for &(a, b) in &EDGES {
        let Some(m) = body.edge_node(t[a], t[b]) else {
            bail!(
                "element {}: no edge node between vertices {} and {}",
                at.element,
                t[a],
                t[b]
            );
        };
        add(m, 4.0 * l[a] * l[b]);
    }
    Ok(d)
}

#[cfg(test)]
mod tests {
    use super::*;
    use fem::elasticity::Material;
    use fem::mesh::structured::box_mesh;

    /// Barycentric coordinates of a hand-placed point in the unit corner tetrahedron.
    #[test]
    fn barycentric_of_the_unit_tetrahedron() {
        let x = [[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        let l = barycentric(x, [0.1, 0.2, 0.3]).unwrap();
        let want = [0.4, 0.1, 0.2, 0.3];
        for k in 0..4 {
            assert!((l[k] - want[k]).abs() < 1e-15, "{l:?}");
        }
    }

    /// A quadratic displacement field is interpolated exactly by the 10-node element at any
    /// point; a point outside the box is reported by its index.
    #[test]
    fn quadratic_fields_are_interpolated_exactly() {
        let mesh = box_mesh([0.02, 0.03, 0.01], [2, 3, 1]);
        let body = QuadraticBody::new(&mesh, Material::new(1000.0, 0.3).unwrap()).unwrap();
        let field = |p: [f64; 3]| {
            [
                p[0] * p[1] + 0.5 * p[2],
                p[2] * p[2] - p[0],
                3.0 * p[0] * p[2] + p[1] * p[1],
            ]
        };
        let u: Vec<f64> = body.positions().iter().flat_map(|&p| field(p)).collect();
        let points = [
            [0.013, 0.021, 0.004],
            [0.0, 0.03, 0.01],
            [0.005, 0.0011, 0.0099],
        ];
        let located = locate(&mesh, &points, 1e-12).unwrap();
        for (p, at) in points.iter().zip(&located) {
            let d = displacement(&mesh, &body, &u, at).unwrap();
            let want = field(*p);
            for c in 0..3 {
                assert!((d[c] - want[c]).abs() < 1e-15, "{p:?}: {d:?} vs {want:?}");
            }
        }
        assert_eq!(
            locate(&mesh, &[[0.01, 0.01, 0.005], [0.01, 0.031, 0.005]], 1e-12),
            Err(1)
        );
    }
}
