//! `[bank]`: the coupling rule, truncation radius, precision, contact set and grid cell, and
//! the reach margin.

use super::Ctx;
use crate::scene::schema::RawBank;
use crate::scene::{BankOptions, Couplings, SceneError};

/// Collision grid cells a scene may ask for, m.
pub const GRID_CELL_RANGE_M: (f64, f64) = (1e-4, 1.0);

/// `[bank]`: `couplings` "radius" (default) or "tool"; `truncation_radius_m` finite and >= 0
/// (required with "radius", default 0 with "tool"); `precision` "f32" (default);
/// `max_contact_nodes` in 1..=[`bank_format::MAX_CONTACTS`] (default the maximum);
/// `grid_cell_m` > 0 (default `None`, the builder's choice); `reach_margin_m` >= 0 (default
/// 0.002 m).
pub(super) fn parse_bank(ctx: &Ctx, b: &RawBank) -> Result<BankOptions, SceneError> {
    let couplings = match &b.couplings {
        None => Couplings::Radius,
        Some(c) => match c.get_ref().as_str() {
            "radius" => Couplings::Radius,
            "tool" => Couplings::Tool,
            other => {
                return Err(ctx.err(
                    c.span(),
                    "bank.couplings",
                    format!("must be \"radius\" or \"tool\", got {other:?}"),
                ));
            }
        },
    };
    let r = match (&b.truncation_radius_m, couplings) {
        (Some(r), _) => {
            let v = *r.get_ref();
            if !(v.is_finite() && v >= 0.0) {
                return Err(ctx.err(
                    r.span(),
                    "bank.truncation_radius_m",
                    format!("must be >= 0 m, got {v}"),
                ));
            }
            v
        }
        (None, Couplings::Tool) => 0.0,
        (None, Couplings::Radius) => {
            let at = ctx.text.find("[bank]").unwrap_or(0);
            return Err(ctx.err(
                at..at,
                "bank.truncation_radius_m",
                "missing: required unless bank.couplings = \"tool\"".to_string(),
            ));
        }
    };
    let precision = match &b.precision {
        None => bank_format::Precision::F32,
        Some(p) => bank_format::Precision::from_name(p.get_ref()).ok_or_else(|| {
            ctx.err(
                p.span(),
                "bank.precision",
                format!(
                    "storage precision {:?} is not one of bank format 5.0's: \"f32\" or \"bfp16\" \
                     (16-bit mantissas, one exponent per block)",
                    p.get_ref()
                ),
            )
        })?,
    };
    let max_contact_nodes = match &b.max_contact_nodes {
        Some(m) => {
            let v = *m.get_ref();
            if v == 0 || v as usize > bank_format::MAX_CONTACTS {
                return Err(ctx.err(
                    m.span(),
                    "bank.max_contact_nodes",
                    format!(
                        "must lie in 1..={} (the link's contact list), got {v}",
                        bank_format::MAX_CONTACTS
                    ),
                ));
            }
            v
        }
        None => bank_format::MAX_CONTACTS as u32,
    };
    let grid_cell_m = match &b.grid_cell_m {
        Some(g) => {
            let v = *g.get_ref();
            if !(GRID_CELL_RANGE_M.0..=GRID_CELL_RANGE_M.1).contains(&v) {
                return Err(ctx.err(
                    g.span(),
                    "bank.grid_cell_m",
                    format!(
                        "{v} m is outside [{}, {}] m: smaller cells than a tenth of a millimetre \
                         make a grid too large for the bank, larger ones hold the whole organ",
                        GRID_CELL_RANGE_M.0, GRID_CELL_RANGE_M.1
                    ),
                ));
            }
            Some(v)
        }
        None => None,
    };
    let reach_margin_m = match &b.reach_margin_m {
        Some(g) => {
            let v = *g.get_ref();
            if !(v.is_finite() && v >= 0.0) {
                return Err(ctx.err(
                    g.span(),
                    "bank.reach_margin_m",
                    format!("must be >= 0 m, got {v}"),
                ));
            }
            v
        }
        None => 0.002,
    };
    Ok(BankOptions {
        couplings,
        truncation_radius_m: r,
        max_contact_nodes,
        grid_cell_m,
        reach_margin_m,
        precision,
    })
}
