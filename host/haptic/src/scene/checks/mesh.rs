//! `mesh` and `mesh_units`: where the organ mesh comes from and its units.

use super::Ctx;
use crate::scene::schema::RawScene;
use crate::scene::{BUILTIN_LIVER_NAME, MeshSource, SceneError};
use crate::units::Units;
use std::path::Path;
use toml::Spanned;

/// `mesh`: [`BUILTIN_LIVER_NAME`], no other `builtin:` name, or a file path resolved against
/// the scene file's directory.
pub(super) fn parse_mesh(
    ctx: &Ctx,
    path: &Path,
    mesh: &Spanned<String>,
) -> Result<MeshSource, SceneError> {
    if mesh.get_ref() == BUILTIN_LIVER_NAME {
        Ok(MeshSource::BuiltinLiver)
    } else if mesh.get_ref().starts_with("builtin:") {
        Err(ctx.err(
            mesh.span(),
            "mesh",
            format!(
                "unknown built-in mesh {:?} (available: {BUILTIN_LIVER_NAME:?})",
                mesh.get_ref()
            ),
        ))
    } else {
        let dir = path.parent().unwrap_or(Path::new("."));
        Ok(MeshSource::File(dir.join(mesh.get_ref())))
    }
}

/// `mesh_units`: "m", "cm" or "mm", only for a mesh file (the embedded liver is in metres). It
/// holds for every mesh of the organ: `mesh` and a sampled `[contact]`'s `fem_mesh` and
/// `richardson_mesh` ([`crate::scene::Scene::read_organ_mesh`]).
pub(super) fn parse_mesh_units(
    ctx: &Ctx,
    raw: &RawScene,
    mesh: &MeshSource,
) -> Result<Option<Units>, SceneError> {
    let Some(u) = &raw.mesh_units else {
        return Ok(None);
    };
    let units: Units = u
        .get_ref()
        .parse()
        .map_err(|e| ctx.err(u.span(), "mesh_units", e))?;
    if units == Units::M {
        return Ok(Some(units));
    }
    if *mesh == MeshSource::BuiltinLiver {
        return Err(ctx.err(
            u.span(),
            "mesh_units",
            format!(
                "the embedded liver is in metres: mesh_units must be \"m\", got {:?}",
                units.name()
            ),
        ));
    }
    Ok(Some(units))
}
