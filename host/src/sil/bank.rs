//! The bank a SIL run loads when none is given: the scene's, built once per set of inputs
//! into `target/sil/` (QEMU loads it from a file into the flash's bank region).

use crate::bank::scene_bank;
use crate::fsio::write_atomic;
use crate::scene::Scene;
use anyhow::{Context, Result};
use std::hash::{Hash, Hasher};
use std::path::{Path, PathBuf};

/// `target/sil/<scene stem>-<key>.bank`, built when missing. The key hashes what the bank is made
/// from: the scene file's bytes and those of every file it reads ([`Scene::input_files`]: the
/// meshes), the bank format version and the building executable (its path and modification
/// time), so an edited scene or mesh, a new format or a rebuilt host never reuses a stale bank.
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

/// The cache key of `scene`'s bank ([`cached`]).
fn key(scene: &Path) -> Result<u64> {
    let text = std::fs::read(scene)
        .with_context(|| format!("cannot read the scene {}", scene.display()))?;
    let mut key = std::collections::hash_map::DefaultHasher::new();
    text.hash(&mut key);
    let parsed = Scene::parse(scene, &String::from_utf8_lossy(&text))?;
    for input in parsed.input_files() {
        std::fs::read(input)
            .with_context(|| {
                format!(
                    "cannot read {}, named by {}",
                    input.display(),
                    scene.display()
                )
            })?
            .hash(&mut key);
    }
    (bank_format::VERSION_MAJOR, bank_format::VERSION_MINOR).hash(&mut key);
    if let Ok(exe) = std::env::current_exe() {
        exe.hash(&mut key);
        std::fs::metadata(&exe)
            .and_then(|m| m.modified())
            .ok()
            .hash(&mut key);
    }
    Ok(key.finish())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An edited mesh gives a new key, as an edited scene does; the same inputs the same key.
    #[test]
    fn the_key_covers_the_scene_and_its_mesh() {
        let dir = tempfile::tempdir().unwrap();
        let shipped = Path::new(env!("CARGO_MANIFEST_DIR")).join("meshes/liver-1k4.msh");
        let mesh = dir.path().join("organ.msh");
        std::fs::copy(&shipped, &mesh).unwrap();
        let scene = dir.path().join("organ.toml");
        let text = std::fs::read_to_string(
            Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/liver-nodal.toml"),
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
