//! Mesh size against precompute cost, per element: assembly, ordering and factorisation of
//! `K_ff` with the bed fixed (`z <= z_min + 10 mm`, as the scenes fix it), and the factor's
//! size.

use super::{Knob, Point, Series};
use anyhow::Result;
use fem::compliance::Compliance;
use fem::elasticity::{DofMap, Elasticity, Element, Material};
use fem::mesh::TetMesh;
use fem::ordering::{Ordering, permutation};
use fem::reference::Punch;
use std::time::Instant;

/// One mesh and element.
#[derive(Debug, Clone)]
pub struct Cost {
    /// Mesh nodes.
    pub nodes: usize,
    /// Assembly, ordering and factorisation, s.
    pub seconds: f64,
    /// Entries of the factor.
    pub nnz_l: usize,
}

/// Times the precompute of `mesh` for each element.
pub fn measure(mesh: &TetMesh) -> Result<[Cost; 2]> {
    let bed = Punch::on_vertices(mesh, &fem::mesh::boundary(mesh)?)?.bed;
    let material = Material::new(3.0e3, 0.45)?;
    let mut out = Vec::new();
    for element in Element::ALL {
        let start = Instant::now();
        let body = Elasticity::with_element(mesh, material, element)?;
        let dofs = DofMap::new(&bed);
        let k = body.stiffness(&dofs);
        let perm = permutation(Ordering::default(), &body, &dofs).map_err(anyhow::Error::msg)?;
        let c = Compliance::factorize_matrix(dofs, &k, perm.as_ref())?;
        out.push(Cost {
            nodes: body.nodes(),
            seconds: start.elapsed().as_secs_f64(),
            nnz_l: c.stats().nnz_l,
        });
    }
    let [p1, anp]: [Cost; 2] = out
        .try_into()
        .map_err(|_| anyhow::anyhow!("two elements measured"))?;
    Ok([p1, anp])
}

/// The knob: factorisation time against nodes (log-log), one series per element.
pub fn section(measured: &[(String, [Cost; 2])]) -> Knob {
    let series = Element::ALL
        .into_iter()
        .enumerate()
        .map(|(slot, element)| Series {
            name: element.to_string(),
            points: measured
                .iter()
                .map(|(name, c)| Point {
                    x: c[slot].nodes as f64,
                    y: c[slot].seconds,
                    label: format!("{name}: nnz(L) {:.1} M", c[slot].nnz_l as f64 / 1e6),
                })
                .collect(),
        })
        .collect();
    let ratio = measured
        .last()
        .map_or(f64::NAN, |(_, c)| c[1].seconds / c[0].seconds);
    Knob {
        id: "mesh-size".into(),
        title: "Mesh size against precompute".into(),
        x_label: "mesh nodes".into(),
        y_label: "assembly + ordering + factorisation of K_ff, s".into(),
        log_x: true,
        log_y: true,
        series,
        chosen: None,
        finding: format!(
            "on the largest mesh measured ANP's precompute takes {ratio:.1} x P1's (the bar for \
             making it the default is 2 x)"
        ),
    }
}
