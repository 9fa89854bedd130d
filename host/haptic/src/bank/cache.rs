//! The bank caches, so that a command that needs a sampled scene's bank (`host demo`,
//! `host contact probe`, `host sil`) pays the FEM precompute once per set of inputs; the files
//! are kept by [`crate::cache::Store`].
//!
//! A bank's key is FNV-1a 64 over [`inputs_hash`] (the scene file's text, the validated scene
//! itself, say without the `[viscoelastic]` table a caller removed in memory, the bytes of the
//! collision, FEM and Richardson meshes, the bank format version: the hash `host sil`'s bank key
//! starts from too) and the source text of the code that computes and writes the samples
//! ([`SAMPLING_SOURCES`], compiled in), so a build whose sampling differs never reuses another's
//! bank, while every binary of one source tree (the CLI, each test) shares it. Files are named
//! `bank-<key>.bin`; a cached file is validated by the bank reader before use, and one that
//! fails is rebuilt.
//!
//! A bank that is not in the cache takes its contact samples, the costly part, from
//! `samples-<key>.bin` when another scene of the same organ computed them: that key
//! ([`samples_key`]) covers only what the samples depend on (the FEM meshes' bytes, the body,
//! the tool, the lattice), so adding a `[viscoelastic]` table or editing the law rebuilds the
//! bank in a second; a sampled scene's display fields are keyed from it too
//! ([`crate::display::fields::DisplayFields::cached`]). [`BankSpec::Scene`] itself
//! (`host bank build`, the precompute bench) never reads the cache.

use super::sampled::SampleStats;
use super::{BankSpec, BuiltBank, Prepared, SampledParts};
use crate::cache::{FNV_OFFSET, Store, fnv1a};
use crate::scene::{ContactModel, MeshSource, SampledContact, Scene};
use anyhow::Result;
use bank_format::{AlignedBytes, Bank, ContactSamples};
use fem::compliance::FactorStats;
use fem::progress::Progress;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// Sampled banks kept (about 0.1 MiB each).
pub const BANKS: Store = Store {
    kind: "bank",
    kept: 32,
};
/// Sets of contact samples kept (about as large as a bank).
pub const SAMPLES: Store = Store {
    kind: "samples",
    kept: 32,
};

/// The source files whose text decides a sampled bank's bytes besides its inputs: the tool
/// load and patch compliance (`fem`), the sampling stage, the bank writer and reader.
pub const SAMPLING_SOURCES: [&str; 7] = [
    include_str!("../../../fem/src/tool.rs"),
    include_str!("../../../fem/src/compliance/patch.rs"),
    include_str!("../../../fem/src/elasticity/quadratic.rs"),
    include_str!("sampled.rs"),
    include_str!("../bank.rs"),
    include_str!("../../../../bank-format/src/writer.rs"),
    include_str!("../../../../bank-format/src/samples.rs"),
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

/// FNV-1a 64 of the bytes of `file`, one the scene names (the error says so).
pub fn file_hash(scene: &Scene, file: &Path) -> Result<u64> {
    use anyhow::Context;
    let bytes = std::fs::read(file).with_context(|| {
        format!(
            "cannot read {}, named by {}",
            file.display(),
            scene.path.display()
        )
    })?;
    Ok(fnv1a(FNV_OFFSET, &bytes))
}

/// FNV-1a 64 over everything a bank is built from: the scene file's text, the validated
/// scene (its `Debug` text without its path and its files' directories: a scene edited in
/// memory after loading is not its file's), the bytes of every file it reads
/// ([`Scene::input_files`]) or of the embedded liver, and the bank format version. The bank
/// caches key on it (this module and [`crate::sil::bank`], each adding the code that builds).
pub fn inputs_hash(scene: &Scene) -> Result<u64> {
    let mut h = scene.text_hash;
    if scene.mesh == MeshSource::BuiltinLiver {
        h = fnv1a(h, crate::scene::BUILTIN_LIVER);
    }
    for file in scene.input_files() {
        h = fnv1a(h, &file_hash(scene, file)?.to_le_bytes());
    }
    // Where the files lie is no input, their bytes are (above): the same scene reached as
    // `host/scenes/liver.toml` and as `tests/../host/scenes/liver.toml` has one key.
    let mut scene = scene.clone();
    scene.path = PathBuf::new();
    for p in scene.input_files_mut() {
        *p = p.file_name().map(PathBuf::from).unwrap_or_default();
    }
    h = fnv1a(h, format!("{scene:?}").as_bytes());
    h = fnv1a(h, &bank_format::VERSION_MAJOR.to_le_bytes());
    Ok(fnv1a(h, &bank_format::VERSION_MINOR.to_le_bytes()))
}

/// The cache key of a sampled scene's bank (module notes).
fn bank_key(prep: &Prepared) -> Result<u64> {
    Ok(fnv1a(
        inputs_hash(&prep.organ.scene)?,
        &code_hash().to_le_bytes(),
    ))
}

/// The scene's bank ([`BankSpec::Scene`]); a sampled scene's comes from the cache when
/// its inputs are unchanged, and goes into it when built. The second value says whether it
/// came from the cache.
pub fn scene_bank_cached(
    prep: &Prepared,
    progress: Option<&dyn Progress>,
) -> Result<(BuiltBank, bool)> {
    let ContactModel::Sampled(spec) = &prep.organ.scene.contact else {
        return Ok((prep.bank(&BankSpec::Scene { progress })?, false));
    };
    let key = bank_key(prep)?;
    let cached = BANKS.load(key, |bytes| {
        let pairs = Bank::parse(&AlignedBytes::new(&bytes))?.pair_count();
        Ok::<_, bank_format::BankError>(BuiltBank {
            bytes,
            pairs,
            sampled: None,
        })
    });
    if let Some(built) = cached {
        return Ok((built, true));
    }
    let (parts, samples_cached) = sampled_parts_cached(prep, spec, progress)?;
    let mut built = prep.bank(&BankSpec::Sampled(parts))?;
    if samples_cached {
        // What the sampling measured was another run's.
        built.sampled = None;
    }
    BANKS.save(key, &built.bytes);
    Ok((built, samples_cached))
}

/// The cache key of a sampled scene's contact samples: the sampling code, the bytes of the FEM
/// meshes, what the FEM body is built from (the mesh units, material, element, supports), the
/// tool's radius, the lattice (level, R's positions and triangles) and the Richardson pair.
/// The law, the device past R, the display law, gravity and relaxation are not in it: the
/// same organ with another `[viscoelastic]` table shares its samples.
pub fn samples_key(prep: &Prepared, spec: &SampledContact) -> Result<u64> {
    let scene = &prep.organ.scene;
    let mut h = fnv1a(FNV_OFFSET, &code_hash().to_le_bytes());
    let files = [
        Some(&spec.fem_mesh),
        spec.richardson.as_ref().map(|r| &r.mesh),
    ];
    for file in files.into_iter().flatten() {
        h = fnv1a(h, &file_hash(scene, file)?.to_le_bytes());
    }
    let boxes: Vec<_> = scene.fix_boxes.iter().map(|b| (b.bounds, b.axes)).collect();
    let richardson = spec.richardson.as_ref().map(|r| (r.ratio, r.order));
    let body = format!(
        "{:?}",
        (
            scene.mesh_units,
            scene.material,
            scene.element,
            boxes,
            &scene.fix_nodes,
            scene.tip_radius_m.to_bits(),
            spec.element,
            spec.level,
            richardson,
        )
    );
    h = fnv1a(h, body.as_bytes());
    for p in &prep.region.positions {
        for c in p {
            h = fnv1a(h, &c.to_bits().to_le_bytes());
        }
    }
    for t in &prep.region.triangles {
        for k in t {
            h = fnv1a(h, &k.to_le_bytes());
        }
    }
    Ok(h)
}

/// The scene's contact samples ([`Prepared::sampled_parts`]) from the cache (`samples-<key>`,
/// [`samples_key`]), or computed and cached; the second value says whether they came from the
/// cache.
fn sampled_parts_cached(
    prep: &Prepared,
    spec: &SampledContact,
    progress: Option<&dyn Progress>,
) -> Result<(SampledParts, bool)> {
    let key = samples_key(prep, spec)?;
    if let Some(parts) = SAMPLES.load(key, |bytes| decode_parts(&bytes).ok_or(())) {
        return Ok((parts, true));
    }
    let parts = prep.sampled_parts(spec, progress)?;
    SAMPLES.save(key, &encode_parts(&parts));
    Ok((parts, false))
}

/// The first bytes of a samples file (and its layout's version).
const PARTS_MAGIC: &[u8; 8] = b"HSAMPLE1";

/// [`SampledParts`] as bytes, little-endian: the magic, the level (u32), the tip radius
/// (f64), per triangle its sample indices (u32 count, u32s), the `W` blocks (u32 count,
/// 9 f64 each), the statistics, the mesh hashes (u32 count, u64s).
fn encode_parts(p: &SampledParts) -> Vec<u8> {
    let mut out = PARTS_MAGIC.to_vec();
    let n = |out: &mut Vec<u8>, n: usize| out.extend((n as u32).to_le_bytes());
    out.extend(p.samples.level.to_le_bytes());
    out.extend(p.samples.tip_radius_m.to_le_bytes());
    n(&mut out, p.samples.triangle_samples.len());
    for t in &p.samples.triangle_samples {
        n(&mut out, t.len());
        t.iter().for_each(|k| out.extend(k.to_le_bytes()));
    }
    n(&mut out, p.samples.w.len());
    for v in p.samples.w.iter().flatten().flatten() {
        out.extend(v.to_le_bytes());
    }
    let st = &p.stats;
    for k in [
        st.samples,
        st.max_patch_nodes,
        st.fem_vertices,
        st.fem_nodes,
        st.factor.free_dofs,
        st.factor.nnz_k,
        st.factor.nnz_l,
    ] {
        out.extend((k as u64).to_le_bytes());
    }
    for x in [st.gap_max_m, st.gap_mean_m, st.factor_s, st.w_s] {
        out.extend(x.to_le_bytes());
    }
    n(&mut out, p.mesh_hashes.len());
    p.mesh_hashes
        .iter()
        .for_each(|h| out.extend(h.to_le_bytes()));
    out
}

/// [`encode_parts`] read back; `None` for anything else (another layout, a truncated file).
fn decode_parts(bytes: &[u8]) -> Option<SampledParts> {
    let mut r = bytes.strip_prefix(PARTS_MAGIC)?;
    let mut take = |len: usize| -> Option<&[u8]> {
        let (head, rest) = r.split_at_checked(len)?;
        r = rest;
        Some(head)
    };
    let u32_ = |b: &[u8]| u32::from_le_bytes(b.try_into().unwrap_or_default());
    let level = u32_(take(4)?);
    let tip_radius_m = f64::from_le_bytes(take(8)?.try_into().ok()?);
    let count = |b: &[u8]| u32_(b) as usize;
    let triangles = count(take(4)?);
    let mut triangle_samples = Vec::with_capacity(triangles.min(1 << 20));
    for _ in 0..triangles {
        let len = count(take(4)?);
        let body = take(len.checked_mul(4)?)?;
        triangle_samples.push(body.chunks_exact(4).map(u32_).collect());
    }
    let blocks = count(take(4)?);
    let body = take(blocks.checked_mul(72)?)?;
    let f64s: Vec<f64> = body
        .chunks_exact(8)
        .map(|b| f64::from_le_bytes(b.try_into().unwrap_or_default()))
        .collect();
    let w = f64s
        .chunks_exact(9)
        .map(|b| std::array::from_fn(|i| std::array::from_fn(|j| b[3 * i + j])))
        .collect();
    let mut ints = [0usize; 7];
    for k in &mut ints {
        *k = usize::try_from(u64::from_le_bytes(take(8)?.try_into().ok()?)).ok()?;
    }
    let mut reals = [0f64; 4];
    for x in &mut reals {
        *x = f64::from_le_bytes(take(8)?.try_into().ok()?);
    }
    let hashes = count(take(4)?);
    let body = take(hashes.checked_mul(8)?)?;
    let mesh_hashes = body
        .chunks_exact(8)
        .map(|b| u64::from_le_bytes(b.try_into().unwrap_or_default()))
        .collect();
    if !r.is_empty() {
        return None;
    }
    let [
        samples,
        max_patch_nodes,
        fem_vertices,
        fem_nodes,
        free_dofs,
        nnz_k,
        nnz_l,
    ] = ints;
    let [gap_max_m, gap_mean_m, factor_s, w_s] = reals;
    Some(SampledParts {
        samples: ContactSamples {
            level,
            tip_radius_m,
            triangle_samples,
            w,
        },
        stats: SampleStats {
            samples,
            gap_max_m,
            gap_mean_m,
            max_patch_nodes,
            fem_vertices,
            fem_nodes,
            factor: FactorStats {
                free_dofs,
                nnz_k,
                nnz_l,
            },
            factor_s,
            w_s,
        },
        mesh_hashes,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// liver.toml and liver-qlv.toml (the same organ with a `[viscoelastic]` table) share their
    /// samples but not their banks; another Young's modulus or tool radius has its own samples.
    #[test]
    fn the_samples_key_covers_the_body_not_the_relaxation() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes");
        let key = |p: &Prepared| {
            let ContactModel::Sampled(spec) = &p.organ.scene.contact else {
                panic!("the shipped scenes are sampled")
            };
            samples_key(p, spec).unwrap()
        };
        let elastic = Prepared::load(&dir.join("liver.toml")).unwrap();
        let qlv = Prepared::load(&dir.join("liver-qlv.toml")).unwrap();
        assert_eq!(key(&elastic), key(&qlv));
        assert_ne!(bank_key(&elastic).unwrap(), bank_key(&qlv).unwrap());
        let mut stiffer = Prepared::load(&dir.join("liver.toml")).unwrap();
        stiffer.organ.scene.material.young *= 2.0;
        assert_ne!(key(&stiffer), key(&elastic));
        let mut wider = Prepared::load(&dir.join("liver.toml")).unwrap();
        wider.organ.scene.tip_radius_m *= 1.5;
        assert_ne!(key(&wider), key(&elastic));
    }

    /// The samples file reads back to the same parts; a truncated or extended one does not read.
    #[test]
    fn sample_parts_round_trip() {
        let parts = SampledParts {
            samples: ContactSamples {
                level: 2,
                tip_radius_m: 0.003,
                triangle_samples: vec![vec![0, 1, 2, 3, 4, 5], vec![0, 2, 5, 6, 7, 8]],
                w: (0..9)
                    .map(|k| {
                        std::array::from_fn(|i| {
                            std::array::from_fn(|j| (k * 9 + i * 3 + j) as f64 * 1e-4)
                        })
                    })
                    .collect(),
            },
            stats: SampleStats {
                samples: 9,
                gap_max_m: 2.3e-3,
                gap_mean_m: 1.3e-4,
                max_patch_nodes: 82,
                fem_vertices: 11667,
                fem_nodes: 83878,
                factor: FactorStats {
                    free_dofs: 250_000,
                    nnz_k: 9_000_000,
                    nnz_l: 256_300_000,
                },
                factor_s: 21.9,
                w_s: 14.3,
            },
            mesh_hashes: vec![0x0123_4567_89ab_cdef, u64::MAX],
        };
        let bytes = encode_parts(&parts);
        assert_eq!(decode_parts(&bytes), Some(parts));
        assert_eq!(decode_parts(&bytes[..bytes.len() - 1]), None);
        let mut longer = bytes.clone();
        longer.push(0);
        assert_eq!(decode_parts(&longer), None);
        assert_eq!(decode_parts(b"HSAMPLE0"), None);
    }

    /// A scene edited in memory after loading gets its own key, not its file's.
    #[test]
    fn the_key_covers_a_scene_edited_in_memory() {
        let file =
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/liver-qlv.toml");
        let mut prep = Prepared::load(&file).unwrap();
        assert!(matches!(prep.organ.scene.contact, ContactModel::Sampled(_)));
        let with = bank_key(&prep).unwrap();
        assert_eq!(bank_key(&prep).unwrap(), with);
        assert!(prep.organ.scene.viscoelastic.is_some());
        prep.organ.scene.viscoelastic = None;
        assert_ne!(bank_key(&prep).unwrap(), with);
    }

    /// One scene reached by two spellings of its path has one key (the caches share its bank);
    /// a different FEM mesh file gives another.
    #[test]
    fn inputs_hash_ignores_the_path_spelling_not_the_files() {
        let dir = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/.."));
        let a = Scene::load(&dir.join("scenes/liver.toml")).unwrap();
        let b = Scene::load(&dir.join("../tests/../host/scenes/liver.toml")).unwrap();
        assert_ne!(a.input_files(), b.input_files());
        assert_eq!(inputs_hash(&a).unwrap(), inputs_hash(&b).unwrap());
        let mut c = a.clone();
        let ContactModel::Sampled(spec) = &mut c.contact else {
            panic!("the shipped scene is sampled")
        };
        spec.fem_mesh = dir.join("meshes/liver-1k4.msh");
        assert_ne!(inputs_hash(&a).unwrap(), inputs_hash(&c).unwrap());
    }
}
