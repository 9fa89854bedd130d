//! `[contact]`: the contact model and, for a sampled one, its FEM mesh, element, lattice and
//! Richardson extrapolation.

use super::Ctx;
use crate::scene::schema::RawContact;
use crate::scene::{
    ContactModel, DEFAULT_SAMPLE_LEVEL, FemElement, Richardson, SampledContact, SceneError,
};
use std::path::Path;

/// `[contact]`: `model` "sampled" (default) or "nodal"; with "sampled", `fem_mesh` (required: a
/// path relative to the scene file), `fem_element` "p1", "anp" or "p2" (default), `sample_level`
/// in `1..=`[`bank_format::MAX_SAMPLE_LEVEL`] (default [`DEFAULT_SAMPLE_LEVEL`]); with "nodal",
/// none of them.
pub(super) fn parse_contact(
    ctx: &Ctx,
    path: &Path,
    c: &RawContact,
) -> Result<ContactModel, SceneError> {
    let sampled = match &c.model {
        None => true,
        Some(m) => match m.get_ref().as_str() {
            "sampled" => true,
            "nodal" => false,
            other => {
                return Err(ctx.err(
                    m.span(),
                    "contact.model",
                    format!("must be \"sampled\" or \"nodal\", got {other:?}"),
                ));
            }
        },
    };
    if !sampled {
        let extra = [
            c.fem_mesh.as_ref().map(|v| (v.span(), "contact.fem_mesh")),
            c.fem_element
                .as_ref()
                .map(|v| (v.span(), "contact.fem_element")),
            c.sample_level
                .as_ref()
                .map(|v| (v.span(), "contact.sample_level")),
        ];
        if let Some((span, key)) = extra.into_iter().flatten().next() {
            return Err(ctx.err(span, key, "only a sampled contact model takes this key"));
        }
        return Ok(ContactModel::Nodal);
    }
    let Some(mesh) = &c.fem_mesh else {
        let at = ctx.text.find("[contact]").unwrap_or(0);
        return Err(ctx.err(
            at..at,
            "contact.fem_mesh",
            "missing: the sampled contact model needs the FEM mesh its patch compliance is \
             computed on",
        ));
    };
    if mesh.get_ref().starts_with("builtin:") {
        return Err(ctx.err(
            mesh.span(),
            "contact.fem_mesh",
            "must be a mesh file (a path relative to the scene file)",
        ));
    }
    let dir = path.parent().unwrap_or(Path::new("."));
    let element = match &c.fem_element {
        None => FemElement::Quadratic,
        Some(e) => e
            .get_ref()
            .parse::<FemElement>()
            .map_err(|why| ctx.err(e.span(), "contact.fem_element", why))?,
    };
    let level = match &c.sample_level {
        None => DEFAULT_SAMPLE_LEVEL,
        Some(l) => {
            let v = *l.get_ref();
            if !(1..=bank_format::MAX_SAMPLE_LEVEL).contains(&v) {
                return Err(ctx.err(
                    l.span(),
                    "contact.sample_level",
                    format!(
                        "must lie in 1..={} (lattice steps per collision triangle side), got {v}",
                        bank_format::MAX_SAMPLE_LEVEL
                    ),
                ));
            }
            v
        }
    };
    let richardson = match (&c.richardson_mesh, &c.richardson_ratio, &c.richardson_order) {
        (None, None, None) => None,
        (Some(m), Some(r), order) => {
            let ratio = *r.get_ref();
            if !(ratio > 1.01 && ratio <= 4.0) {
                return Err(ctx.err(
                    r.span(),
                    "contact.richardson_ratio",
                    format!("must lie in (1.01, 4] (coarse mesh size / fine), got {ratio}"),
                ));
            }
            let order = match order {
                None => 2.0,
                Some(o) => {
                    let v = *o.get_ref();
                    if !(0.5..=4.0).contains(&v) {
                        return Err(ctx.err(
                            o.span(),
                            "contact.richardson_order",
                            format!("must lie in [0.5, 4], got {v}"),
                        ));
                    }
                    v
                }
            };
            Some(Richardson {
                mesh: dir.join(m.get_ref()),
                ratio,
                order,
            })
        }
        _ => {
            let at = ctx.text.find("richardson").unwrap_or(0);
            return Err(ctx.err(
                at..at,
                "contact.richardson_mesh",
                "richardson_mesh and richardson_ratio go together (richardson_order is \
                 optional, default 2)",
            ));
        }
    };
    Ok(ContactModel::Sampled(SampledContact {
        fem_mesh: dir.join(mesh.get_ref()),
        element,
        level,
        richardson,
    }))
}
