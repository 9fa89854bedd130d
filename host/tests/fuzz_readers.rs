//! A mutation fuzz of every reader of user files: the mesh readers (MSH 1 and 2, MSH 4.1 ASCII
//! and binary, VTU ascii / base64 / appended / raw, legacy VTK ASCII and binary, classic and
//! 5.1, Medit), the surface readers (OBJ, binary STL, binary PLY, VTK polydata ASCII and
//! binary, VTP) followed by the surface checks and repairs,
//! and the bench CSV reader. Each valid sample is mutated deterministically (byte flips,
//! insertions, deletions, duplicated runs, digits replaced by huge numbers, truncation) and
//! every mutant is read in a thread with a time limit. Must hold: no panic, no hang; each
//! input is either read or refused with an error. The counts are printed (and quoted in
//! `docs/file-formats.md`, "Mutation fuzz").

use fem::mesh::{self, Format};
use fem::surface::{CheckOptions, SurfaceFormat, check};
use haptic::rng::SplitMix64;
use std::path::Path;
use std::sync::mpsc;
use std::time::Duration;

/// Mutants per sample file.
const MUTANTS: usize = 300;
/// Longest a reader may take on one small input.
const LIMIT: Duration = Duration::from_secs(5);

/// One to four mutations of `seed`.
fn mutate(seed: &[u8], rng: &mut SplitMix64) -> Vec<u8> {
    let mut b = seed.to_vec();
    for _ in 0..1 + rng.below(4) {
        let at = rng.below(b.len());
        match rng.below(6) {
            0 => {
                if let Some(x) = b.get_mut(at) {
                    *x ^= 1 << rng.below(8);
                }
            }
            1 => b.insert(at, rng.next_u64() as u8),
            2 => {
                let end = (at + 1 + rng.below(64)).min(b.len());
                b.drain(at..end);
            }
            3 => {
                let end = (at + 1 + rng.below(64)).min(b.len());
                let run = b[at..end].to_vec();
                b.splice(at..at, run);
            }
            4 => {
                // The next run of digits becomes a huge or negative number.
                if let Some(start) = b[at..].iter().position(u8::is_ascii_digit) {
                    let start = at + start;
                    let len = b[start..].iter().take_while(|c| c.is_ascii_digit()).count();
                    let big: &[u8] = match rng.below(3) {
                        0 => b"18446744073709551615",
                        1 => b"-1",
                        _ => b"99999999999",
                    };
                    b.splice(start..start + len, big.iter().copied());
                }
            }
            _ => b.truncate(at),
        }
    }
    b
}

/// A surface read and checked with every repair and `--largest` on: `true` when it passes.
fn read_and_check(bytes: &[u8], format: SurfaceFormat) -> bool {
    let opts = CheckOptions {
        repair: true,
        largest: true,
        ..CheckOptions::default()
    };
    fem::surface::read_surface_bytes(bytes, format).is_ok_and(|s| check(&s, opts).is_ok())
}

/// A reader on one input: read (`true`) or refused (`false`).
type Parse = fn(Vec<u8>) -> bool;

#[derive(Default, Debug)]
struct Tally {
    read: usize,
    refused: usize,
    panics: usize,
    hangs: usize,
}

/// Runs `parse` on every mutant of `seed` in a thread with [`LIMIT`].
fn fuzz(name: &str, seed: &[u8], rng: &mut SplitMix64, parse: Parse) -> Tally {
    let mut t = Tally::default();
    for _ in 0..MUTANTS {
        let input = mutate(seed, rng);
        let (tx, rx) = mpsc::channel();
        std::thread::spawn(move || {
            let r = std::panic::catch_unwind(|| parse(input));
            let _ = tx.send(r);
        });
        match rx.recv_timeout(LIMIT) {
            Ok(Ok(true)) => t.read += 1,
            Ok(Ok(false)) => t.refused += 1,
            Ok(Err(_)) => t.panics += 1,
            Err(_) => t.hangs += 1,
        }
    }
    println!("{name:<28} {t:?}");
    t
}

#[test]
fn every_reader_survives_mutated_input() {
    let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("fem/tests/data");
    let mut rng = SplitMix64::new(2026);
    let mut total = Tally::default();
    let mut add = |t: Tally| {
        total.read += t.read;
        total.refused += t.refused;
        total.panics += t.panics;
        total.hangs += t.hangs;
    };
    let meshes: [(&str, Parse); 15] = [
        ("cube_v1.msh", |b| mesh::read_bytes(&b, Format::Msh).is_ok()),
        ("cube_v1_sparse.msh", |b| {
            mesh::read_bytes(&b, Format::Msh).is_ok()
        }),
        ("cube.mesh", |b| mesh::read_bytes(&b, Format::Medit).is_ok()),
        ("cube_v2.msh", |b| mesh::read_bytes(&b, Format::Msh).is_ok()),
        ("cube_v41.msh", |b| {
            mesh::read_bytes(&b, Format::Msh).is_ok()
        }),
        ("cube_v41_bin.msh", |b| {
            mesh::read_bytes(&b, Format::Msh).is_ok()
        }),
        ("cube_v41_sparse.msh", |b| {
            mesh::read_bytes(&b, Format::Msh).is_ok()
        }),
        ("cube.vtu", |b| mesh::read_bytes(&b, Format::Vtu).is_ok()),
        ("cube_ascii.vtu", |b| {
            mesh::read_bytes(&b, Format::Vtu).is_ok()
        }),
        ("cube_appended.vtu", |b| {
            mesh::read_bytes(&b, Format::Vtu).is_ok()
        }),
        ("cube_raw.vtu", |b| {
            mesh::read_bytes(&b, Format::Vtu).is_ok()
        }),
        ("cube.vtk", |b| mesh::read_bytes(&b, Format::Vtk).is_ok()),
        ("cube_bin.vtk", |b| {
            mesh::read_bytes(&b, Format::Vtk).is_ok()
        }),
        ("cube_v51.vtk", |b| {
            mesh::read_bytes(&b, Format::Vtk).is_ok()
        }),
        ("cube_v51_bin.vtk", |b| {
            mesh::read_bytes(&b, Format::Vtk).is_ok()
        }),
    ];
    for (file, parse) in meshes {
        let seed = std::fs::read(data.join(file)).unwrap();
        assert!(
            parse(seed.clone()),
            "{file}: the unmutated sample must read"
        );
        add(fuzz(file, &seed, &mut rng, parse));
    }
    // The surface readers, and the surface checks (with every repair on) on what they read.
    let surfaces = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/surfaces");
    let surface_readers: [(&str, Parse); 6] = [
        ("organ_cm.obj", |b| read_and_check(&b, SurfaceFormat::Obj)),
        ("organ_mm.stl", |b| read_and_check(&b, SurfaceFormat::Stl)),
        ("organ_cm.ply", |b| read_and_check(&b, SurfaceFormat::Ply)),
        ("organ_cm.vtk", |b| read_and_check(&b, SurfaceFormat::Vtk)),
        ("organ_cm_bin.vtk", |b| {
            read_and_check(&b, SurfaceFormat::Vtk)
        }),
        ("organ_cm.vtp", |b| read_and_check(&b, SurfaceFormat::Vtp)),
    ];
    for (file, parse) in surface_readers {
        let seed = std::fs::read(surfaces.join(file)).unwrap();
        assert!(
            parse(seed.clone()),
            "{file}: the unmutated sample must read"
        );
        add(fuzz(file, &seed, &mut rng, parse));
    }
    let csv = Path::new(env!("CARGO_MANIFEST_DIR")).join("data/brain-compression-500mm-min.csv");
    let seed = std::fs::read(csv).unwrap();
    let parse_csv: Parse = |b| {
        let text = String::from_utf8_lossy(&b);
        haptic::calibrate::csv::parse("bench.csv", &text, &["linear_force_n", "force_n"])
            .and_then(|t| t.numbers(0).and(t.numbers(1)))
            .is_ok()
    };
    assert!(parse_csv(seed.clone()));
    add(fuzz("brain-compression.csv", &seed, &mut rng, parse_csv));
    println!("total                        {total:?}");
    assert_eq!((total.panics, total.hangs), (0, 0), "{total:?}");
    // The mutants exercise both outcomes.
    assert!(total.read > 100 && total.refused > 1000, "{total:?}");
}
