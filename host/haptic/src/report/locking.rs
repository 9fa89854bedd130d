//! The element under near-incompressibility: the punch of [`fem::reference::Punch`] (bed
//! fixed, a 10 mm flat punch pressed 5 mm into the top) with P1 and ANP against 10-node
//! tetrahedra (P2) on the same mesh, at nu = 0.45 to 0.4999. Cost axis: entries of the
//! Cholesky factor of `K_ff` (memory, and the time of every column solve, scale with it).

use super::{HardCase, Knob, Point, Series, Verdict};
use anyhow::Result;
use fem::compliance::Compliance;
use fem::elasticity::quadratic::QuadraticBody;
use fem::elasticity::{Elasticity, Element, Material};
use fem::mesh::TetMesh;
use fem::reference::Punch;

/// Poisson's ratios measured.
pub const POISSON: [f64; 4] = [0.45, 0.49, 0.499, 0.4999];
/// Young's modulus of the study, Pa (forces are linear in it).
const YOUNG_PA: f64 = 3.0e3;
/// |force / P2 - 1| up to which an element matches the reference on the same mesh. The
/// punched region is mesh-defined (surface nodes within the radius, edge nodes too for P2), so
/// the same-mesh comparison carries a few percent of boundary discretisation at every nu.
pub const SAME_MESH_TOLERANCE: f64 = 0.06;

/// One mesh's measurements.
#[derive(Debug, Clone)]
pub struct Row {
    /// Poisson's ratio.
    pub nu: f64,
    /// Punch force of P1, ANP and P2, N.
    pub force: [f64; 3],
}

/// Measures the punch on `mesh` (named `name`) at every ratio of [`POISSON`]; `step` reports
/// progress.
pub fn measure(name: &str, mesh: &TetMesh, step: &dyn Fn(&str)) -> Result<(Vec<Row>, [usize; 2])> {
    let surface = fem::mesh::boundary(mesh)?;
    let linear = Punch::on_vertices(mesh, &surface)?;
    let mut rows = Vec::new();
    let mut nnz = [0; 2];
    for nu in POISSON {
        step(&format!("locking: {name}, nu = {nu}"));
        let material = Material::new(YOUNG_PA, nu)?;
        let mut force = [0.0; 3];
        for (slot, element) in Element::ALL.into_iter().enumerate() {
            let body = Elasticity::with_element(mesh, material, element)?;
            force[slot] = linear.force(&body)?;
            if nu == POISSON[0] {
                nnz[slot] = Compliance::factorize(&body, &linear.bed)?.stats().nnz_l;
            }
        }
        let body = QuadraticBody::new(mesh, material)?;
        force[2] = Punch::on_quadratic(mesh, &surface, &body)?.force(&body)?;
        rows.push(Row { nu, force });
    }
    Ok((rows, nnz))
}

/// The knob and the hard-case rows of the measurements of several meshes.
pub fn section(measured: &[(String, Vec<Row>, [usize; 2])]) -> (Knob, Vec<HardCase>) {
    let mut series = Vec::new();
    let mut cases = Vec::new();
    for (name, rows, nnz) in measured {
        for (slot, element) in Element::ALL.into_iter().enumerate() {
            let points = rows
                .iter()
                .map(|r| Point {
                    x: nnz[slot] as f64 / 1e6,
                    y: 100.0 * (r.force[slot] / r.force[2] - 1.0).abs(),
                    label: format!("nu = {}", r.nu),
                })
                .collect();
            series.push(Series {
                name: format!("{element} {name}"),
                points,
            });
            for r in rows {
                let ratio = r.force[slot] / r.force[2];
                let verdict = if (ratio - 1.0).abs() <= SAME_MESH_TOLERANCE {
                    Verdict::MatchesReference
                } else {
                    Verdict::Weakness
                };
                let mut measurement = format!(
                    "punch force {:.4} N = {ratio:.3} x P2's {:.4} N",
                    r.force[slot], r.force[2]
                );
                if verdict == Verdict::Weakness && ratio > 1.0 {
                    measurement += &format!(": locks, {:.0} % too stiff", 100.0 * (ratio - 1.0));
                }
                cases.push(HardCase {
                    case: format!("nu = {}, {element}, {name}", r.nu),
                    measurement,
                    reference: format!(
                        "10-node tetrahedra on the same mesh, within {:.0} %",
                        100.0 * SAME_MESH_TOLERANCE
                    ),
                    verdict,
                    value: Some(r.force[slot]),
                    reference_value: Some(r.force[2]),
                });
            }
        }
    }
    let worst = |slot: usize| {
        measured
            .iter()
            .flat_map(|(_, rows, _)| rows.iter().map(move |r| r.force[slot] / r.force[2]))
            .fold(1.0f64, |m, v| {
                if (v - 1.0).abs() > (m - 1.0).abs() {
                    v
                } else {
                    m
                }
            })
    };
    let knob = Knob {
        id: "element".into(),
        title: "Element under near-incompressibility".into(),
        x_label: "Cholesky factor entries nnz(L), millions".into(),
        y_label: "punch force error against P2, %".into(),
        log_x: false,
        log_y: true,
        series,
        chosen: None,
        finding: format!(
            "P1 reaches {:.2} x the 10-node force (locking as nu -> 0.5), ANP {:.3} x at worst, \
             for {:.1} x P1's factor",
            worst(0),
            worst(1),
            measured
                .first()
                .map_or(f64::NAN, |(_, _, n)| n[1] as f64 / n[0] as f64)
        ),
    };
    (knob, cases)
}
