//! `[material]`: Young's modulus, Poisson's ratio and the element, and what P1 locking does at
//! a Poisson's ratio.

use super::Ctx;
use crate::scene::SceneError;
use crate::scene::schema::RawMaterial;
use fem::elasticity::{Element, Material};

/// `[material]`: `young_pa` in [`YOUNG_RANGE_PA`], `poisson` in (-1, 0.5) (for P1 at most
/// [`P1_LOCKING_REFUSE`]), `element` one of [`Element::ALL`] (default `p1`), then whatever
/// [`Material::new`] rejects.
pub(super) fn parse_material(
    ctx: &Ctx,
    m: &RawMaterial,
) -> Result<(Material, Element), SceneError> {
    let (e, nu) = (*m.young_pa.get_ref(), *m.poisson.get_ref());
    if !(e.is_finite() && e > 0.0) {
        return Err(ctx.err(
            m.young_pa.span(),
            "material.young_pa",
            format!("Young's modulus must be > 0 Pa, got {e}"),
        ));
    }
    if !(YOUNG_RANGE_PA.0..=YOUNG_RANGE_PA.1).contains(&e) {
        return Err(ctx.err(
            m.young_pa.span(),
            "material.young_pa",
            format!(
                "{e} Pa is outside [{:e}, {:e}] Pa, the range this product models (soft tissue is \
                 1e2-1e6 Pa); outside it the bank's f32 compliance under- or overflows",
                YOUNG_RANGE_PA.0, YOUNG_RANGE_PA.1
            ),
        ));
    }
    if !(nu > -1.0 && nu < 0.5) {
        return Err(ctx.err(
            m.poisson.span(),
            "material.poisson",
            format!("Poisson's ratio must lie in (-1, 0.5), got {nu}"),
        ));
    }
    let element = match &m.element {
        Some(name) => name
            .get_ref()
            .parse::<Element>()
            .map_err(|why| ctx.err(name.span(), "material.element", why))?,
        None => Element::P1,
    };
    if element == Element::P1
        && let Locking::Meaningless(why) = p1_locking(nu)
    {
        return Err(ctx.err(
            m.poisson.span(),
            "material.poisson",
            format!("{why} (or use element = \"anp\", free of locking)"),
        ));
    }
    let material = Material::new(e, nu)
        .map_err(|err| ctx.err(m.young_pa.span(), "material", err.to_string()))?;
    Ok((material, element))
}

/// Young's moduli a scene may have, Pa: from a gel to hard plastics. The bank stores compliance
/// in f32, and a 10 cm organ's node compliance is about 1 / (E x 0.01 m): these bounds keep it
/// within 1e-12..1e2 m/N, far inside f32's range and its SPD checks' resolution.
pub const YOUNG_RANGE_PA: (f64, f64) = (1.0, 1.0e10);

/// Poisson's ratio above which P1 tetrahedra are warned about: at 0.45 the locking excess on the
/// shipped livers is 3 % (10k nodes) to 21 % (1.4k); it grows like 1 / (1 - 2 nu) beyond.
pub const P1_LOCKING_WARN: f64 = 0.45;
/// Poisson's ratio above which P1 results are refused as meaningless: at 0.499 P1 answers 1.8x
/// (10k liver) to 2.9x (1.4k liver) too stiff; at 0.4999 a node's compliance is a twentieth of its
/// value at 0.45, a locked answer, not tissue.
pub const P1_LOCKING_REFUSE: f64 = 0.499;

/// What P1 locking does to a result at Poisson's ratio `nu`.
#[derive(Debug, Clone, PartialEq)]
pub enum Locking {
    /// Negligible.
    Fine,
    /// Stiffer than the tissue by the stated amount: warn.
    Stiffens(String),
    /// Locked: refuse, saying why and what to do.
    Meaningless(String),
}

/// P1 locking at Poisson's ratio `nu`, with the stiffening measured against quadratic
/// elements on the shipped livers (bed fixed, a 10 mm flat punch pressed 5 mm; P1 / P2 force
/// 1.21 / 1.03 at 0.45, 1.49 / 1.16 at 0.49, 2.85 / 1.80 at 0.499 on the 1.4k / 10k liver).
pub fn p1_locking(nu: f64) -> Locking {
    if nu > P1_LOCKING_REFUSE {
        Locking::Meaningless(format!(
            "Poisson's ratio {nu} > {P1_LOCKING_REFUSE}: linear tetrahedra lock (at 0.499 they \
             already answer 1.8-2.9x too stiff on the shipped livers, and worse beyond), so the \
             result would describe the element, not the tissue; use at most \
             {P1_LOCKING_REFUSE} and fit the remaining stiffness into the tissue law Q"
        ))
    } else if nu > P1_LOCKING_WARN {
        let (coarse, fine) = if nu <= 0.49 {
            ("1.2-1.5x", "1.03-1.16x")
        } else {
            ("1.5-2.9x", "1.16-1.8x")
        };
        Locking::Stiffens(format!(
            "warning: Poisson's ratio {nu} > {P1_LOCKING_WARN}: linear tetrahedra lock, answering \
             about {coarse} too stiff on a 1.4k-node liver and {fine} on a 10k-node one (P1 \
             against quadratic elements); a finer mesh lessens it"
        ))
    } else {
        Locking::Fine
    }
}
