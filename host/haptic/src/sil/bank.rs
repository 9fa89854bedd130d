//! The bank a SIL run loads when none is given: the scene's, built once per set of inputs
//! into `target/sil/` (QEMU loads it from a file into the flash's bank region).

use crate::bank::cache::inputs_hash;
use crate::bank::scene_bank;
use crate::cache::fnv1a;
use crate::fsio::write_atomic;
use crate::scene::Scene;
use anyhow::{Context, Result};
use std::path::{Path, PathBuf};

/// `target/sil/<scene stem>-<key>.bank`, built when missing. The key hashes what the bank is made
/// from ([`inputs_hash`]: the scene, every file it reads, the bank format version) and the
/// building executable (its path and modification time), so an edited scene or mesh, a new
/// format or a rebuilt host never reuses a stale bank.
/// Older cached banks of the same scene are removed.
pub fn cached(scene: &Path) -> Result<PathBuf> {
    let stem = scene
        .file_stem()
        .and_then(|s| s.to_str())
        .with_context(|| format!("{}: not a scene file path", scene.display()))?;
    let key = key(scene)?;
    let dir = crate::mcu::repo_root().join("target/sil");
    let name = format!("{stem}-{key:016x}.bank");
    let out = dir.join(&name);
    if !out.exists() {
        let bytes = scene_bank(scene)?;
        std::fs::create_dir_all(&dir)
            .with_context(|| format!("cannot create {}", dir.display()))?;
        write_atomic(&out, &bytes, &[scene])?;
        // Best effort: a stale bank left behind costs disk, not correctness.
        let stale = |n: &str| {
            n != name
                && n.strip_prefix(stem)
                    .and_then(|r| r.strip_prefix('-'))
                    .and_then(|r| r.strip_suffix(".bank"))
                    .is_some_and(|k| k.len() == 16 && k.bytes().all(|b| b.is_ascii_hexdigit()))
        };
        for entry in std::fs::read_dir(&dir).into_iter().flatten().flatten() {
            if entry.file_name().to_str().is_some_and(stale) {
                let _ = std::fs::remove_file(entry.path());
            }
        }
    }
    Ok(out)
}

/// The cache key of `scene`'s bank ([`cached`]): the scene's [`inputs_hash`], then the building
/// executable's path and modification time.
fn key(scene: &Path) -> Result<u64> {
    let mut key = inputs_hash(&Scene::load(scene)?)?;
    if let Ok(exe) = std::env::current_exe() {
        key = fnv1a(key, exe.as_os_str().as_encoded_bytes());
        let modified = std::fs::metadata(&exe)
            .and_then(|m| m.modified())
            .ok()
            .and_then(|t| t.duration_since(std::time::UNIX_EPOCH).ok())
            .map_or(0, |d| d.as_nanos());
        key = fnv1a(key, &modified.to_le_bytes());
    }
    Ok(key)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An edited mesh gives a new key, as an edited scene does; the same inputs the same key.
    #[test]
    fn the_key_covers_the_scene_and_its_mesh() {
        let dir = tempfile::tempdir().unwrap();
        let shipped = Path::new(env!("CARGO_MANIFEST_DIR")).join("../meshes/liver-1k4.msh");
        let mesh = dir.path().join("organ.msh");
        std::fs::copy(&shipped, &mesh).unwrap();
        let scene = dir.path().join("organ.toml");
        let text = std::fs::read_to_string(
            Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/liver-nodal.toml"),
        )
        .unwrap();
        let edited = text.replacen("mesh = \"builtin:liver-1k4\"", "mesh = \"organ.msh\"", 1);
        assert_ne!(edited, text, "the shipped scene's mesh line changed");
        std::fs::write(&scene, &edited).unwrap();
        let first = key(&scene).unwrap();
        assert_eq!(key(&scene).unwrap(), first);
        let mut bytes = std::fs::read(&mesh).unwrap();
        let last = bytes.len() - 2;
        bytes.insert(last, b'\n');
        std::fs::write(&mesh, &bytes).unwrap();
        assert_ne!(key(&scene).unwrap(), first, "the mesh changed");
        std::fs::write(&scene, format!("{edited}\n# edited\n")).unwrap();
        let third = key(&scene).unwrap();
        assert_ne!(third, first);
        std::fs::remove_file(&mesh).unwrap();
        let err = key(&scene).unwrap_err();
        assert!(format!("{err:#}").contains("organ.msh"), "{err:#}");
    }
}
