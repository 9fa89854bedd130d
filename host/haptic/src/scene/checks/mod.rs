//! The checks of a scene's values, one module per table (`[device]` with `[tool]` and
//! `[gravity]`, the instrument; `[law]` with `[display_law]` and `[viscoelastic]`, the tissue's
//! laws): every error names the file, the line and the key.

pub(super) mod bank;
mod contact;
mod device;
mod fixed;
pub(super) mod law;
pub(super) mod material;
mod mesh;

use super::schema::RawScene;
use super::{ContactModel, Scene, SceneError, line_of};
use crate::cache::{FNV_OFFSET, fnv1a};
use bank::parse_bank;
use contact::parse_contact;
use device::{parse_device, parse_friction_offset, parse_gravity, parse_tool};
use fixed::parse_fixed;
use law::{parse_display_law, parse_law, parse_viscoelastic};
use material::parse_material;
use mesh::{parse_mesh, parse_mesh_units};
use std::ops::Range;
use std::path::Path;
use toml::Spanned;

/// Parses and validates scene text, table by table, in the order that decides which of several
/// errors a file reports; `path` names it in errors and anchors a relative mesh path.
pub(super) fn scene(path: &Path, text: &str) -> Result<Scene, SceneError> {
    let ctx = Ctx {
        file: path.display().to_string(),
        text,
    };
    let raw = parse_toml(&ctx)?;
    let mesh = parse_mesh(&ctx, path, &raw.mesh)?;
    let mesh_units = parse_mesh_units(&ctx, &raw, &mesh)?;
    let (material, element) = parse_material(&ctx, &raw.material)?;
    let (fix_boxes, fix_nodes, fix_nodes_line) = parse_fixed(&ctx, &raw.fixed)?;
    let tip_radius_m = parse_tool(&ctx, &raw.tool)?;
    let device = parse_device(&ctx, &raw.device, tip_radius_m)?;
    // Checked by `parse_device`; the linear law's default domain is [0, max_force_n].
    let max_force_n = *raw.device.max_force_n.get_ref();
    let (law_spec, law) = parse_law(&ctx, &raw.law, max_force_n)?;
    let display_law = raw
        .display_law
        .as_ref()
        .map(|p| parse_display_law(&ctx, p))
        .transpose()?;
    let friction_offset = parse_friction_offset(&ctx, &raw.device)?;
    let gravity = raw
        .gravity
        .as_ref()
        .map(|g| parse_gravity(&ctx, g))
        .transpose()?;
    let viscoelastic = raw
        .viscoelastic
        .as_ref()
        .map(|v| parse_viscoelastic(&ctx, v))
        .transpose()?;
    let bank = parse_bank(&ctx, &raw.bank)?;
    let contact = match &raw.contact {
        Some(c) => parse_contact(&ctx, path, c)?,
        None => ContactModel::Nodal,
    };
    if matches!(contact, ContactModel::Sampled(_)) && !fix_nodes.is_empty() {
        let at = ctx.text.find("nodes").unwrap_or(0);
        return Err(ctx.err(
            at..at,
            "fixed.nodes",
            "node ids name nodes of `mesh`, not of [contact] fem_mesh: a sampled contact \
             takes its supports from fixed.boxes only",
        ));
    }
    Ok(Scene {
        path: path.to_path_buf(),
        mesh,
        mesh_units,
        material,
        element,
        fix_boxes,
        fix_nodes,
        fix_nodes_line,
        tip_radius_m,
        device,
        law,
        law_spec,
        display_law,
        friction_offset,
        gravity,
        viscoelastic,
        bank,
        contact,
        text_hash: fnv1a(FNV_OFFSET, text.as_bytes()),
    })
}

/// The scene file being checked, for the errors: its name and its text.
struct Ctx<'a> {
    file: String,
    text: &'a str,
}

impl Ctx<'_> {
    /// The error `message` about `key`, on the line of `span`.
    fn err(&self, span: Range<usize>, key: &str, message: impl Into<String>) -> SceneError {
        SceneError {
            file: self.file.clone(),
            line: Some(line_of(self.text, span.start)),
            key: key.to_string(),
            message: message.into(),
        }
    }
}

/// Every value of `v` finite.
fn finite<const N: usize>(ctx: &Ctx, v: &Spanned<[f64; N]>, key: &str) -> Result<(), SceneError> {
    if v.get_ref().iter().all(|x| x.is_finite()) {
        Ok(())
    } else {
        Err(ctx.err(v.span(), key, "values must be finite"))
    }
}

/// `v` a finite, non-empty range `[min, max]`; returns it.
fn range(ctx: &Ctx, v: &Spanned<[f64; 2]>, key: &str) -> Result<[f64; 2], SceneError> {
    finite(ctx, v, key)?;
    let [a, b] = *v.get_ref();
    if a >= b {
        return Err(ctx.err(
            v.span(),
            key,
            format!("empty range [{a}, {b}]: need min < max"),
        ));
    }
    Ok([a, b])
}

/// `v` a finite unit vector (length within 1e-3 of 1); returns it normalised.
fn unit(ctx: &Ctx, v: &Spanned<[f64; 3]>, key: &str) -> Result<[f64; 3], SceneError> {
    finite(ctx, v, key)?;
    let a = *v.get_ref();
    let n = (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt();
    if (n - 1.0).abs() > 1e-3 {
        return Err(ctx.err(
            v.span(),
            key,
            format!("must be a unit vector, has length {n}"),
        ));
    }
    Ok(a.map(|x| x / n))
}

/// Every value of `v` finite and in `(0, max]`; returns them as f32.
fn positive3(
    ctx: &Ctx,
    v: &Spanned<[f64; 3]>,
    key: &str,
    max: f64,
) -> Result<[f32; 3], SceneError> {
    finite(ctx, v, key)?;
    for &x in v.get_ref() {
        if !(x > 0.0 && x <= max) {
            return Err(ctx.err(
                v.span(),
                key,
                format!("every value must lie in (0, {max}], got {x}"),
            ));
        }
    }
    Ok(v.get_ref().map(|x| x as f32))
}

/// The whole file: TOML syntax, missing and unknown keys, value types. The error's key is the
/// field the TOML error names (`(syntax)` when it names none).
fn parse_toml(ctx: &Ctx) -> Result<RawScene, SceneError> {
    toml::from_str(ctx.text).map_err(|e| {
        let message = e.message().trim().to_string();
        let key = message
            .split('`')
            .nth(1)
            .filter(|_| message.contains("field"))
            .unwrap_or("(syntax)")
            .to_string();
        SceneError {
            file: ctx.file.clone(),
            line: e.span().map(|s| line_of(ctx.text, s.start)),
            key,
            message,
        }
    })
}
