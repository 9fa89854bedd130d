//! Hard cases whose answer is exact or a refusal: free-slip box compression near
//! incompressibility (exact linear solution), a contact imposed on a fixed node (refused), a
//! degenerate sliver (refused on load; the patch test on distorted meshes with near-slivers is
//! `host/fem/tests/fem_exact.rs`), and the
//! tissue law Q evaluated outside its fitted domain (tangent continuation, clamped at 0 where
//! the firmware applies it).

use super::{HardCase, Verdict};
use anyhow::Result;
use bank_format::TissueLaw;
use fem::compliance::{ComplianceError, dirichlet_forces};
use fem::elasticity::{Elasticity, Element, FixedSet, Material};
use fem::mesh::TetMesh;
use fem::mesh::structured::box_mesh;
use fem::reference::box_compression;

/// Poisson's ratios of the box compression rows.
const BOX_POISSON: [f64; 2] = [0.499, 0.4999];
/// Relative error under which an exact solution counts as reproduced (f64 solve).
const EXACT: f64 = 1e-9;

/// The rows for the elastic model (no bank or device needed).
pub fn elastic_cases() -> Result<Vec<HardCase>> {
    let mut out = Vec::new();
    let size = [0.03, 0.02, 0.025];
    let mesh = box_mesh(size, [6, 4, 5]);
    for nu in BOX_POISSON {
        for element in Element::ALL {
            let body = Elasticity::with_element(&mesh, Material::new(4.5e3, nu)?, element)?;
            let r = box_compression(&body, &mesh, 4.5e3, nu, size, 0.02)?;
            let worst = r.displacement_error.max(r.force_error);
            out.push(HardCase {
                case: format!("nu = {nu}, {element}: free-slip box compression"),
                measurement: format!(
                    "displacement error {:.1e}, force error {:.1e} (relative)",
                    r.displacement_error, r.force_error
                ),
                reference: "exact linear solution u = (nu e x, nu e y, -e z), F = E A e".into(),
                verdict: if worst <= EXACT {
                    Verdict::MatchesReference
                } else {
                    Verdict::Weakness
                },
                value: Some(worst),
                reference_value: Some(0.0),
            });
        }
    }
    out.push(fixed_contact(&mesh)?);
    out.push(sliver()?);
    Ok(out)
}

/// Imposing a displacement on a node of the fixed bed must be refused, not solved.
fn fixed_contact(mesh: &TetMesh) -> Result<HardCase> {
    let body = Elasticity::new(mesh, Material::new(4.5e3, 0.45)?)?;
    let mut fixed = FixedSet::none(mesh.nodes.len());
    fixed.fix_box(mesh, [-1.0, -1.0, -1.0, 1.0, 1.0, 1e-9], [true; 3])?;
    let node = (0..mesh.nodes.len())
        .find(|&i| fixed.is_fixed(i, 2))
        .ok_or_else(|| anyhow::anyhow!("the box has no bottom node"))?;
    let answer = dirichlet_forces(&body, &fixed, &[node], &[[0.0, 0.0, -1e-3]]);
    let (measurement, verdict) = match answer {
        Err(ComplianceError::FixedContactNode(n)) => (
            format!("refused: node {n} has fixed components"),
            Verdict::Refused,
        ),
        Err(e) => (
            format!("refused with another error: {e}"),
            Verdict::Weakness,
        ),
        Ok(_) => (
            "solved (a contact on a fixed node)".into(),
            Verdict::Weakness,
        ),
    };
    Ok(HardCase {
        case: "contact at the fixed boundary".into(),
        measurement,
        reference: "no displacement can be imposed on a fixed node".into(),
        verdict,
        value: None,
        reference_value: None,
    })
}

/// Two tetrahedra, the second flattened to a sliver of quality about 1e-8 (its fifth vertex
/// pulled almost onto the opposite face): the mesh must be refused on load (below
/// `DEGENERATE_QUALITY`), not assembled into a near-singular `K`.
fn sliver() -> Result<HardCase> {
    let toward = 0.01 / 3.0;
    let t = 1.0 - 1e-8;
    let mut mesh = TetMesh {
        nodes: vec![
            [0.0, 0.0, 0.0],
            [0.01, 0.0, 0.0],
            [0.0, 0.01, 0.0],
            [0.0, 0.0, 0.01],
            [0.01 + t * (toward - 0.01); 3],
        ],
        tets: vec![[0, 1, 2, 3], [1, 2, 3, 4]],
    };
    if mesh.signed_volume(1) < 0.0 {
        mesh.tets[1].swap(2, 3);
    }
    let quality = mesh.quality(1);
    let (measurement, verdict) = match fem::mesh::validate(&mesh) {
        Err(e) => (format!("refused on load: {e}"), Verdict::Refused),
        Ok(()) => ("accepted".to_string(), Verdict::Weakness),
    };
    Ok(HardCase {
        case: format!("sliver tetrahedron, quality {quality:.1e}"),
        measurement,
        reference: format!(
            "degenerate elements (quality < {:.0e}) are refused",
            fem::mesh::DEGENERATE_QUALITY
        ),
        verdict,
        value: Some(quality),
        reference_value: Some(fem::mesh::DEGENERATE_QUALITY),
    })
}

/// Q outside its fitted domain: the tangent continuation of the nearer end, finite and
/// increasing above; below the domain the firmware clamps at 0.
pub fn law_outside_domain(law: &TissueLaw) -> HardCase {
    let [lo, hi] = law.domain();
    let span = hi - lo;
    let probes = [hi + span, hi + 10.0 * span, (lo - span).max(-span)];
    let values: Vec<f32> = probes.iter().map(|&f| law.eval(f)).collect();
    let finite = values.iter().all(|v| v.is_finite());
    let increasing = values[0] > law.eval(hi) && values[1] > values[0];
    HardCase {
        case: "Q evaluated outside its fitted domain".into(),
        measurement: format!(
            "Q({:.3}) = {:.3} N, Q({:.3}) = {:.3} N above the domain [{lo:.3}, {hi:.3}] N; \
             Q({:.3}) = {:.3} N below (rendered as max(Q, 0))",
            probes[0], values[0], probes[1], values[1], probes[2], values[2]
        ),
        reference: "tangent line at the nearer end: finite, increasing".into(),
        verdict: if finite && increasing {
            Verdict::Bounded
        } else {
            Verdict::Weakness
        },
        value: Some(f64::from(values[1])).filter(|v| v.is_finite()),
        reference_value: None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_sliver_is_refused() {
        let case = sliver().unwrap();
        assert_eq!(case.verdict, Verdict::Refused, "{case:?}");
    }
}
