//! The tissue's laws: `[law]` (Q, the force law), `[display_law]` (P, the display law) and
//! `[viscoelastic]` (the relaxation).

use super::{Ctx, range};
use crate::scene::schema::{RawDisplayLaw, RawLaw, RawViscoelastic};
use crate::scene::{LawSpec, SceneError, Viscoelastic};
use bank_format::TissueLaw;

/// `[law]`: `domain_n` a non-empty range when given; `kind` "linear" (no `coeffs`; `gain` > 0,
/// default 1; `offset_n` default 0; `domain_n` default [0, `fmax`]) or "chebyshev" (no `gain` or
/// `offset_n`; `coeffs` and `domain_n` required); then what [`TissueLaw`] rejects. `fmax` is
/// `device.max_force_n`, N.
pub(super) fn parse_law(
    ctx: &Ctx,
    l: &RawLaw,
    fmax: f64,
) -> Result<(LawSpec, TissueLaw), SceneError> {
    let law_key_span = l.kind.span();
    let domain = match &l.domain_n {
        Some(dn) => Some(range(ctx, dn, "law.domain_n")?),
        None => None,
    };
    match l.kind.get_ref().as_str() {
        "linear" => {
            if let Some(c) = &l.coeffs {
                return Err(ctx.err(c.span(), "law.coeffs", "only for kind = \"chebyshev\""));
            }
            let gain = l.gain.as_ref().map_or(1.0, |g| *g.get_ref());
            let offset = l.offset_n.as_ref().map_or(0.0, |o| *o.get_ref());
            if !(gain > 0.0 && gain.is_finite()) {
                let span = l.gain.as_ref().map_or(law_key_span.clone(), |g| g.span());
                return Err(ctx.err(span, "law.gain", format!("must be > 0, got {gain}")));
            }
            if !offset.is_finite() || offset < 0.0 {
                let span = l
                    .offset_n
                    .as_ref()
                    .map_or(law_key_span.clone(), |o| o.span());
                return Err(ctx.err(
                    span,
                    "law.offset_n",
                    format!(
                        "must be >= 0, got {offset}: Q(0) < 0 would pull the tool into the \
                         tissue at first contact"
                    ),
                ));
            }
            let domain_n = domain.unwrap_or([0.0, fmax]);
            let law = TissueLaw::linear(offset as f32, gain as f32, domain_n.map(|v| v as f32))
                .map_err(|e| ctx.err(law_key_span.clone(), "law", e.to_string()))?;
            Ok((
                LawSpec::Linear {
                    offset_n: offset,
                    gain,
                    domain_n,
                },
                law,
            ))
        }
        "chebyshev" => {
            for (present, key) in [
                (l.gain.as_ref().map(|g| g.span()), "law.gain"),
                (l.offset_n.as_ref().map(|g| g.span()), "law.offset_n"),
            ] {
                if let Some(span) = present {
                    return Err(ctx.err(span, key, "only for kind = \"linear\""));
                }
            }
            let Some(c) = &l.coeffs else {
                return Err(ctx.err(law_key_span, "law.coeffs", "required for chebyshev"));
            };
            let Some(domain_n) = domain else {
                return Err(ctx.err(law_key_span, "law.domain_n", "required for chebyshev"));
            };
            let coeffs: Vec<f32> = c.get_ref().iter().map(|&v| v as f32).collect();
            let law = TissueLaw::chebyshev(&coeffs, domain_n.map(|v| v as f32))
                .map_err(|e| ctx.err(c.span(), "law.coeffs", e.to_string()))?;
            if let Some(q0) = pull_at_first_contact(&law) {
                return Err(ctx.err(
                    c.span(),
                    "law.coeffs",
                    format!(
                        "the law gives Q(0) = {q0} N: it would pull the tool into the tissue at \
                         first contact"
                    ),
                ));
            }
            Ok((
                LawSpec::Chebyshev {
                    coeffs: c.get_ref().clone(),
                    domain_n,
                },
                law,
            ))
        }
        other => Err(ctx.err(
            law_key_span,
            "law.kind",
            format!("unknown law {other:?} (use \"linear\" or \"chebyshev\")"),
        )),
    }
}

/// How far below zero Q(0) may be, relative to Q at the end of its domain (the largest force
/// it renders): a fit to measured data leaves residuals of that order (the shipped brain data's
/// fits: up to 0.5 % of full scale at their worst point), and a pull that small is below what
/// the device resolves.
pub const PULL_TOLERANCE: f32 = 0.005;

/// `Some(Q(0))` when a tissue law would pull the tool in at first contact: Q(0) below
/// `-PULL_TOLERANCE` times Q at the end of its domain, or not a number.
pub fn pull_at_first_contact(law: &TissueLaw) -> Option<f32> {
    let q0 = law.eval(0.0);
    let full = law.eval(law.domain()[1]).abs();
    (q0.is_nan() || q0 < -PULL_TOLERANCE * full).then_some(q0)
}

/// `[display_law]` (optional table): `kind` "chebyshev", `domain_m` a non-empty range, then what
/// [`TissueLaw::chebyshev`] rejects in `coeffs`.
pub(super) fn parse_display_law(ctx: &Ctx, p: &RawDisplayLaw) -> Result<TissueLaw, SceneError> {
    if p.kind.get_ref() != "chebyshev" {
        return Err(ctx.err(
            p.kind.span(),
            "display_law.kind",
            format!("unknown law {:?} (use \"chebyshev\")", p.kind.get_ref()),
        ));
    }
    let domain = range(ctx, &p.domain_m, "display_law.domain_m")?;
    let coeffs: Vec<f32> = p.coeffs.get_ref().iter().map(|&v| v as f32).collect();
    TissueLaw::chebyshev(&coeffs, domain.map(|v| v as f32))
        .map_err(|e| ctx.err(p.coeffs.span(), "display_law.coeffs", e.to_string()))
}

/// `[viscoelastic]`: [`Viscoelastic::record`]'s rules, the error on the table's `g` line
/// (`tau_s`'s for a time constant).
pub(super) fn parse_viscoelastic(
    ctx: &Ctx,
    v: &RawViscoelastic,
) -> Result<Viscoelastic, SceneError> {
    let out = Viscoelastic {
        g: v.g.get_ref().clone(),
        tau_s: v.tau_s.get_ref().clone(),
    };
    match out.record() {
        Ok(_) => Ok(out),
        Err(m) if m.contains("tau =") => Err(ctx.err(v.tau_s.span(), "viscoelastic.tau_s", m)),
        Err(m) => Err(ctx.err(v.g.span(), "viscoelastic.g", m)),
    }
}
