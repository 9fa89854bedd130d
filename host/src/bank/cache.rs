//! A cache of sampled banks, so that a command that needs a sampled scene's bank (`host demo`,
//! `host contact probe`, `host sil`) pays the FEM precompute once per set of inputs.
//!
//! The key is FNV-1a 64 over [`crate::scene::Scene::inputs_hash`] (the scene file's text, the
//! validated scene itself, say without the `[viscoelastic]` table a caller removed in memory,
//! the bytes of the collision, FEM and Richardson meshes, the bank format version: the hash
//! `host sil`'s bank key starts from too) and the source text of the code that computes and
//! writes the samples ([`SAMPLING_SOURCES`], compiled in), so a build whose sampling differs
//! never reuses another's bank, while every binary of one source tree (the CLI, each test)
//! shares it.
//! Files live in `$HAPTIC_CACHE_DIR`, else `$XDG_CACHE_HOME/haptic-host`, else
//! `~/.cache/haptic-host`, named `bank-<key>.bin`, written atomically; a cached file is
//! validated by the bank reader before use, and one that fails is rebuilt. A sampled scene's
//! display fields ([`DisplayFields`]) go beside it as `fields-<key>.bin`, keyed by the bank's
//! key, the bank's CRC and the text of the code that computes them.

use super::{BuiltBank, Prepared};
use crate::display::fields::DisplayFields;
use crate::scene::{ContactModel, FNV_OFFSET, fnv1a};
use anyhow::Result;
use bank_format::{AlignedBytes, Bank};
use fem::progress::Progress;
use std::path::PathBuf;
use std::sync::OnceLock;

/// The cache directory (module notes), `None` without a home directory.
pub fn cache_dir() -> Option<PathBuf> {
    if let Some(d) = std::env::var_os("HAPTIC_CACHE_DIR") {
        return Some(PathBuf::from(d));
    }
    if let Some(d) = std::env::var_os("XDG_CACHE_HOME") {
        return Some(PathBuf::from(d).join("haptic-host"));
    }
    std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".cache").join("haptic-host"))
}

/// The source files whose text decides a sampled bank's bytes besides its inputs: the tool
/// load and patch compliance (`fem`), the sampling stage, the bank writer and reader.
pub const SAMPLING_SOURCES: [&str; 7] = [
    include_str!("../../fem/src/tool.rs"),
    include_str!("../../fem/src/compliance/patch.rs"),
    include_str!("../../fem/src/elasticity/quadratic.rs"),
    include_str!("sampled.rs"),
    include_str!("../bank.rs"),
    include_str!("../../../bank-format/src/writer.rs"),
    include_str!("../../../bank-format/src/samples.rs"),
];

/// FNV-1a 64 over [`SAMPLING_SOURCES`].
fn code_hash() -> u64 {
    static HASH: OnceLock<u64> = OnceLock::new();
    *HASH.get_or_init(|| {
        SAMPLING_SOURCES
            .iter()
            .fold(FNV_OFFSET, |h, s| fnv1a(h, s.as_bytes()))
    })
}

/// The cache key of a sampled scene's bank (module notes).
fn bank_key(prep: &Prepared) -> Result<u64> {
    Ok(fnv1a(
        prep.organ.scene.inputs_hash()?,
        &code_hash().to_le_bytes(),
    ))
}

/// The scene's bank ([`Prepared::build_bank`]); a sampled scene's comes from the cache when
/// its inputs are unchanged, and goes into it when built. The second value says whether it
/// came from the cache.
pub fn scene_bank_cached(
    prep: &Prepared,
    progress: Option<&dyn Progress>,
) -> Result<(BuiltBank, bool)> {
    let ContactModel::Sampled(_) = &prep.organ.scene.contact else {
        return Ok((prep.build_bank(progress)?, false));
    };
    let key = bank_key(prep)?;
    let file = cache_dir().map(|d| d.join(format!("bank-{key:016x}.bin")));
    if let Some(f) = &file
        && let Ok(bytes) = std::fs::read(f)
        && let Ok(bank) = Bank::parse(&AlignedBytes::new(&bytes))
    {
        let pairs = bank.pair_count();
        return Ok((
            BuiltBank {
                bytes,
                pairs,
                sampled: None,
            },
            true,
        ));
    }
    let built = prep.build_bank(progress)?;
    if let Some(f) = &file {
        store(f, &built.bytes);
    }
    Ok((built, false))
}

/// The source files whose text decides the display fields besides the bank's inputs.
const FIELDS_SOURCES: [&str; 2] = [
    include_str!("../display/fields.rs"),
    include_str!("../../fem/src/elasticity/mod.rs"),
];

/// A sampled scene's display fields ([`DisplayFields::compute`] for `bank`, the scene's bank)
/// from the cache, or computed and cached; `None` for a nodal scene. The second value says
/// whether they came from the cache.
pub fn display_fields_cached(
    prep: &Prepared,
    bank: &Bank,
    progress: Option<&dyn Progress>,
) -> Result<Option<(DisplayFields, bool)>> {
    let (ContactModel::Sampled(_), Some(_)) = (&prep.organ.scene.contact, bank.samples()) else {
        return Ok(None);
    };
    let key = FIELDS_SOURCES
        .iter()
        .fold(fnv1a(bank_key(prep)?, &bank.crc().to_le_bytes()), |h, s| {
            fnv1a(h, s.as_bytes())
        });
    let file = cache_dir().map(|d| d.join(format!("fields-{key:016x}.bin")));
    if let Some(f) = &file
        && let Ok(bytes) = std::fs::read(f)
        && let Ok(fields) = DisplayFields::decode(&bytes)
    {
        return Ok(Some((fields, true)));
    }
    let Some(fields) = DisplayFields::for_bank(prep, bank, progress)? else {
        return Ok(None);
    };
    if let Some(f) = &file {
        store(f, &fields.encode());
    }
    Ok(Some((fields, false)))
}

/// Writes a cache file; one that cannot be written only costs the next run the precompute.
fn store(f: &std::path::Path, bytes: &[u8]) {
    let written = f
        .parent()
        .map(std::fs::create_dir_all)
        .transpose()
        .ok()
        .and_then(|_| crate::fsio::write_atomic(f, bytes, &[]).ok());
    if written.is_none() {
        eprintln!("note: could not write the cache file {}", f.display());
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A scene edited in memory after loading gets its own key, not its file's.
    #[test]
    fn the_key_covers_a_scene_edited_in_memory() {
        let file = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/liver-qlv.toml");
        let mut prep = Prepared::load(&file).unwrap();
        assert!(matches!(prep.organ.scene.contact, ContactModel::Sampled(_)));
        let with = bank_key(&prep).unwrap();
        assert_eq!(bank_key(&prep).unwrap(), with);
        assert!(prep.organ.scene.viscoelastic.is_some());
        prep.organ.scene.viscoelastic = None;
        assert_ne!(bank_key(&prep).unwrap(), with);
    }
}
