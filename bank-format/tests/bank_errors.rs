//! Every `BankError` variant, each produced by corrupting exactly one thing in a valid bank.
//!
//! Corruptions behind the CRC check are followed by `reseal` (the CRC is recomputed) so that
//! the deeper validation is reached; `crc_mismatch` is the one that leaves the CRC stale.
#![allow(clippy::needless_range_loop)] // index loops read best for 3x3 blocks

mod common;

use bank_format::{
    AlignedBytes, Bank, BankError as E, BuildError, DeviceField as F, SectionKind as K,
};
use common::*;

/// Codes of retired variants, never reused (31: `CklAsymmetric`, gone in 4.0 when each pair's
/// block came to be stored once).
const RETIRED: [u16; 1] = [31];

/// The highest `BankError` code: the variants counted in its definition plus the retired codes
/// (codes run 1..=this), so a new variant without a case below fails
/// `every_variant_has_a_case`.
fn last_code() -> u16 {
    variant_count() + RETIRED.len() as u16
}

/// The number of `BankError` variants, counted in its definition.
fn variant_count() -> u16 {
    let src = include_str!("../src/error.rs");
    let (_, body) = src
        .split_once("pub enum BankError {")
        .expect("BankError in src/error.rs");
    let body = &body[..body.find("\n}").expect("end of BankError")];
    let variants = body
        .lines()
        .filter(|l| {
            l.strip_prefix("    ")
                .is_some_and(|r| r.starts_with(|c: char| c.is_ascii_uppercase()))
        })
        .count();
    u16::try_from(variants).expect("a few dozen variants")
}

/// Section-relative byte offsets used below.
const DEV_SHAFT: usize = 12;
const DEV_PITCH: usize = 24;
const DEV_YAW: usize = 36;
const DEV_MIN: usize = 48;
const DEV_MAX: usize = 60;
const DEV_HOME: usize = 72;
const DEV_COUNTS: usize = 84;
const DEV_TRANS: usize = 96;
const DEV_KT: usize = 108;
const DEV_LIMIT: usize = 120;
const DEV_FORCE: usize = 132;
const DEV_TIP: usize = 136;
const DEV_TIP_SPEED: usize = 140;
const DEV_JOINT_SPEED: usize = 144;
const DEV_LINK_TIMEOUT: usize = 156;

fn set_entry(kind: K, field: usize, value: u32) -> Result<(), E> {
    corrupt(|b| {
        let (i, ..) = section(b, kind);
        put_u32(b, entry_field(i, field), value);
    })
}

fn device_f32(at: usize, v: f32) -> Result<(), E> {
    corrupt_section(K::Device, |s| put_f32(s, at, v))
}

macro_rules! cases {
    ($($name:ident: $pat:pat => $body:expr;)*) => {
        mod run {
            use super::*;
            $(pub fn $name() -> Result<(), E> { $body })*
        }
        $(
            #[test]
            fn $name() {
                let got = run::$name();
                assert!(matches!(got, Err($pat)), "{}: got {:?}", stringify!($name), got);
                // Display works for every error.
                assert!(!got.unwrap_err().to_string().is_empty());
            }
        )*
        #[test]
        fn every_variant_has_a_case() {
            let codes = [$(run::$name().unwrap_err().code()),*];
            let last = last_code();
            assert!(last >= 40, "BankError has {last} codes?");
            assert!(codes.iter().all(|c| (1..=last).contains(c) && !RETIRED.contains(c)), "{codes:?}");
            for code in (1..=last).filter(|c| !RETIRED.contains(c)) {
                assert!(codes.contains(&code), "no test produces error code {code}");
            }
        }
    };
}

/// A flat `n` x `n` grid at `spacing` (m), two triangles a square, `C_kk = c I`; every pair
/// closer than `truncation` (m) coupled by `0.05 c I` (each pair's compliance SPD), grid cells
/// of `cell` (m). Valid in every rule but the tick's limits (`SPEC.md`, "Limits the tick's cost
/// rests on"), which the callers break; built, so that the writer's own run of the reader
/// refuses it.
fn hostile_grid(n: usize, spacing: f64, truncation: f64, cell: f64) -> Result<(), E> {
    let c = 1.0e-3;
    let diag = |v: f64| -> [[f64; 3]; 3] {
        std::array::from_fn(|i| std::array::from_fn(|j| if i == j { v } else { 0.0 }))
    };
    let positions_m: Vec<[f64; 3]> = (0..n * n)
        .map(|k| [spacing * (k % n) as f64, spacing * (k / n) as f64, 0.0])
        .collect();
    let id = |i: usize, j: usize| (i + n * j) as u32;
    let mut triangles = Vec::new();
    for j in 0..n - 1 {
        for i in 0..n - 1 {
            triangles.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
            triangles.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
        }
    }
    let mut couplings = Vec::new();
    for k in 0..n * n {
        for l in k + 1..n * n {
            let (a, b) = (positions_m[k], positions_m[l]);
            let d = ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)).sqrt();
            // Triangle edges always (check 13), the rest within the radius.
            if d < truncation || d < spacing * 1.5 {
                couplings.push((k as u32, l as u32, diag(0.05 * c)));
            }
        }
    }
    finish_hostile(bank_format::BankBuilder {
        c_kk: vec![diag(c); n * n],
        couplings,
        mesh_ids: (0..(n * n) as u32).collect(),
        triangles,
        positions_m,
        grid_cell_size_m: cell,
        truncation_radius_m: truncation,
        ..builder()
    })
}

/// `b` built: `Ok` when valid, else the reader's error (the writer runs it on its output).
fn finish_hostile(b: bank_format::BankBuilder) -> Result<(), E> {
    match b.build() {
        Ok(bytes) => parse(&bytes),
        Err(BuildError::Rejected(e)) => Err(e),
        Err(other) => panic!("{other:?}"),
    }
}

/// A fan: node 0 at the centre of `count` triangles, the rim nodes on a 5 mm circle; edges
/// coupled, 5 mm cells.
fn fan(count: usize) -> Result<(), E> {
    finish_hostile(fan_builder(count))
}

fn fan_builder(count: usize) -> bank_format::BankBuilder {
    let c = 1.0e-3;
    let diag = |v: f64| -> [[f64; 3]; 3] {
        std::array::from_fn(|i| std::array::from_fn(|j| if i == j { v } else { 0.0 }))
    };
    let mut positions_m = vec![[0.0, 0.0, 0.0]];
    for i in 0..count {
        let a = std::f64::consts::TAU * i as f64 / count as f64;
        positions_m.push([0.005 * a.cos(), 0.005 * a.sin(), 0.0]);
    }
    let rim = |i: usize| (1 + i % count) as u32;
    let triangles: Vec<[u32; 3]> = (0..count).map(|i| [0, rim(i), rim(i + 1)]).collect();
    let mut couplings = Vec::new();
    for i in 0..count {
        couplings.push((0, rim(i), diag(0.05 * c)));
        let (a, b) = (rim(i), rim(i + 1));
        couplings.push((a.min(b), a.max(b), diag(0.05 * c)));
    }
    bank_format::BankBuilder {
        c_kk: vec![diag(c); count + 1],
        couplings,
        mesh_ids: (0..=count as u32).collect(),
        triangles,
        positions_m,
        grid_cell_size_m: 0.005,
        truncation_radius_m: 0.0,
        ..builder()
    }
}

/// The tick's limits hold for banks just inside them: 16 triangles about a node, a cell of
/// 128 candidates, 128 neighbours.
#[test]
fn banks_at_the_ticks_limits_are_valid() {
    assert_eq!(fan(bank_format::MAX_NODE_TRIANGLES), Ok(()));
    // 8 x 8 nodes, 98 triangles, in one 2 cm cell (and its neighbours' margins).
    assert_eq!(hostile_grid(8, 0.001, 0.0, 0.02), Ok(()));
    // 12 x 12 nodes at 1 mm, every pair within 6.4 mm coupled: at most 118 neighbours.
    assert_eq!(hostile_grid(12, 0.001, 0.0064, 0.002), Ok(()));
}

/// A bank over the tick's limits is refused by `Bank::parse` (the firmware's) only:
/// `Bank::parse_unbounded` and `BankBuilder::build_unbounded`, for the host's own banks (the
/// tool-coupling probe), take it, with every other rule checked.
#[test]
fn the_unbounded_reader_takes_what_only_the_limits_refuse() {
    let b = fan_builder(17);
    let bytes = b.build_unbounded(bank_format::Precision::F32).unwrap();
    let aligned = AlignedBytes::new(&bytes);
    assert_eq!(
        Bank::parse(&aligned).map(|_| ()),
        Err(E::TooManyTriangles { node: 0, count: 17 })
    );
    let bank = Bank::parse_unbounded(&aligned).unwrap();
    assert_eq!(bank.node_triangles(0).len(), 17);
    // Still everything else: a flipped byte fails the CRC.
    let mut bad = bytes.clone();
    bad[40] ^= 1;
    assert!(matches!(
        Bank::parse_unbounded(&AlignedBytes::new(&bad)),
        Err(E::CrcMismatch { .. })
    ));
}

/// A valid bank with a two-term relaxation section, `f` applied to the section, resealed,
/// parsed.
fn relaxation(f: impl FnOnce(&mut bank_format::Relaxation)) -> Result<(), E> {
    let mut r = bank_format::Relaxation {
        count: 2,
        reserved: 0,
        g: [0.3, 0.2, 0.0, 0.0],
        tau_s: [0.1, 10.0, 0.0, 0.0],
    };
    let mut b = builder();
    b.relaxation = Some(r);
    let mut bytes = b.build().unwrap();
    f(&mut r);
    let (_, off, ..) = section(&bytes, K::Relaxation);
    bytes[off..off + 40].copy_from_slice(bytemuck::bytes_of(&r));
    assert!(bank_format::reseal(&mut bytes));
    parse(&bytes)
}

/// `f` applied to a valid bank with contact samples, resealed, parsed.
fn corrupt_sampled(f: impl FnOnce(&mut Vec<u8>)) -> Result<(), E> {
    let mut bytes = sampled_builder().build().unwrap();
    f(&mut bytes);
    assert!(bank_format::reseal(&mut bytes));
    parse(&bytes)
}

cases! {
    too_short_for_header: E::TooShort { needed: 32, got: 16 } => parse(&valid_bytes()[..16]);
    too_short_for_total_len: E::TooShort { .. } => {
        let b = valid_bytes();
        let n = b.len();
        match parse(&b[..n - 8]) {
            Err(E::TooShort { needed, got }) if needed == n && got == n - 8 => {
                Err(E::TooShort { needed, got })
            }
            other => other,
        }
    };
    misaligned: E::Misaligned => {
        let mut b = vec![0u8];
        b.extend(valid_bytes());
        let aligned = AlignedBytes::new(&b);
        Bank::parse(&aligned[1..]).map(|_| ())
    };
    bad_magic: E::BadMagic => corrupt(|b| b[0] = b'X');
    // A bank of the previous major version (its device record is 4 bytes shorter).
    unsupported_version: E::UnsupportedVersion { major: 7, .. } => corrupt(|b| put_u16(b, 8, 7));
    unsupported_later_version: E::UnsupportedVersion { major: 9, .. } => corrupt(|b| put_u16(b, 8, 9));
    bad_header_length: E::BadHeaderLength { header_len: 24 } => corrupt(|b| put_u16(b, 12, 24));
    too_many_sections: E::TooManySections { count: 33 } => corrupt(|b| put_u16(b, 14, 33));
    bad_total_length_unaligned: E::BadTotalLength { .. } => {
        let mut b = valid_bytes();
        let n = b.len() as u32;
        put_u32(&mut b, 16, n - 4);
        parse(&b)
    };
    bad_total_length_inside_table: E::BadTotalLength { total_len: 64 } => {
        let mut b = valid_bytes();
        put_u32(&mut b, 16, 64);
        parse(&b)
    };
    crc_mismatch: E::CrcMismatch { .. } => {
        let mut b = valid_bytes();
        let (_, off, ..) = section(&b, K::Positions);
        b[off + 5] ^= 0x10;
        parse(&b)
    };
    reserved_header_flags: E::ReservedNotZero { section: K::Header } => corrupt(|b| put_u32(b, 24, 1));
    reserved_section_kind: E::ReservedSectionKind { entry: 3 } => corrupt(|b| put_u32(b, entry_field(3, 0), 0));
    section_out_of_bounds: E::SectionOutOfBounds { section: K::Positions } => {
        let total = valid_bytes().len() as u32;
        set_entry(K::Positions, 1, total)
    };
    section_length_overflows: E::SectionOutOfBounds { section: K::MeshIds } => set_entry(K::MeshIds, 2, u32::MAX);
    section_misaligned: E::SectionMisaligned { section: K::Positions } => corrupt(|b| {
        let (i, off, ..) = section(b, K::Positions);
        put_u32(b, entry_field(i, 1), off as u32 + 4);
    });
    section_overlap: E::SectionOverlap { section: K::MeshIds } => corrupt(|b| {
        let (_, pos_off, ..) = section(b, K::Positions);
        let (i, ..) = section(b, K::MeshIds);
        put_u32(b, entry_field(i, 1), pos_off as u32);
    });
    section_overlaps_table: E::SectionOverlap { section: K::Meta } => set_entry(K::Meta, 1, 32);
    duplicate_section: E::DuplicateSection { section: K::Positions } => set_entry(K::MeshIds, 0, K::Positions.code());
    missing_section: E::MissingSection { section: K::Device } => set_entry(K::Device, 0, 99);
    size_mismatch: E::SizeMismatch { section: K::Positions } => set_entry(K::Positions, 3, 5);
    count_mismatch: E::CountMismatch { section: K::MeshIds } => corrupt(|b| {
        let (i, ..) = section(b, K::MeshIds);
        put_u32(b, entry_field(i, 2), 12);
        put_u32(b, entry_field(i, 3), 3);
    });
    node_count_zero: E::NodeCount { count: 0 } => corrupt(|b| {
        let (i, ..) = section(b, K::Positions);
        put_u32(b, entry_field(i, 2), 0);
        put_u32(b, entry_field(i, 3), 0);
    });
    non_finite_position: E::NonFinite { section: K::Positions, entry: 1 } =>
        corrupt_section(K::Positions, |s| put_f32(s, 12 + 4, f32::NAN));
    non_finite_ckk: E::NonFinite { section: K::Ckk, entry: 3 } =>
        corrupt_section(K::Ckk, |s| put_f32(s, 3 * 24 + 8, f32::INFINITY));
    non_finite_ckl: E::NonFinite { section: K::NeighbourCkl, entry: 2 } =>
        corrupt_section(K::NeighbourCkl, |s| put_f32(s, 2 * 36, f32::NAN));
    non_finite_grid: E::NonFinite { section: K::Grid, entry: 0 } =>
        corrupt_section(K::Grid, |s| put_f32(s, 4, f32::NAN));
    non_finite_law: E::NonFinite { section: K::TissueLaw, entry: 0 } =>
        corrupt_section(K::TissueLaw, |s| put_f32(s, 16, f32::NAN));
    non_finite_device: E::NonFinite { section: K::Device, entry: 0 } => device_f32(0, f32::NEG_INFINITY);
    non_finite_tip_speed: E::NonFinite { section: K::Device, entry: 0 } =>
        device_f32(DEV_TIP_SPEED, f32::INFINITY);
    non_finite_joint_speed: E::NonFinite { section: K::Device, entry: 0 } =>
        device_f32(DEV_JOINT_SPEED + 8, f32::NAN);
    non_finite_meta: E::NonFinite { section: K::Meta, entry: 0 } =>
        corrupt_section(K::Meta, |s| put_f32(s, 8, f32::NAN));
    triangle_index_out_of_range: E::IndexOutOfRange { section: K::Triangles, entry: 1 } =>
        corrupt_section(K::Triangles, |s| put_u16(s, 6 + 4, 4));
    node_triangle_index_out_of_range: E::IndexOutOfRange { section: K::NodeTriItems, entry: 2 } =>
        corrupt_section(K::NodeTriItems, |s| put_u16(s, 2 * 2, 2));
    grid_item_out_of_range: E::IndexOutOfRange { section: K::GridItems, entry: 1 } =>
        corrupt_section(K::GridItems, |s| put_u16(s, 2, 9));
    neighbour_index_out_of_range: E::IndexOutOfRange { section: K::NeighbourIndex, entry: 2 } =>
        corrupt_section(K::NeighbourIndex, |s| put_u16(s, 4, 4));
    bad_neighbour_starts: E::BadCsrStarts { section: K::NeighbourStarts, entry: 0 } =>
        corrupt_section(K::NeighbourStarts, |s| put_u32(s, 0, 1));
    bad_grid_starts_end: E::BadCsrStarts { section: K::GridStarts, entry: 4 } =>
        corrupt_section(K::GridStarts, |s| put_u16(s, 8, 3));
    bad_node_triangle_starts_decrease: E::BadCsrStarts { section: K::NodeTriStarts, entry: 2 } =>
        corrupt_section(K::NodeTriStarts, |s| put_u32(s, 8, 1));
    // Coupling starts [0, 3, 4, 5, 5] made [0, 2, 4, 5, 5]: node 0 has three entries l > 0.
    coupling_starts_disagree: E::BadCsrStarts { section: K::CouplingStarts, entry: 1 } =>
        corrupt_section(K::CouplingStarts, |s| put_u32(s, 4, 2));
    coupling_starts_end: E::BadCsrStarts { section: K::CouplingStarts, entry: 4 } =>
        corrupt_section(K::CouplingStarts, |s| put_u32(s, 16, 4));
    degenerate_triangle: E::DegenerateTriangle { triangle: 1 } =>
        corrupt_section(K::Triangles, |s| put_u16(s, 6 + 4, 0));
    node_triangle_mismatch: E::NodeTriangleMismatch { node: 1 } =>
        corrupt_section(K::NodeTriItems, |s| put_u16(s, 2 * 2, 1));
    // Both triangles lie in z = 0 with n = (0, 0, SIDE^2): m = (0, 0, 1e4) 1/m, off = 0.
    plane_count_mismatch: E::CountMismatch { section: K::TrianglePlanes } => corrupt(|b| {
        let (i, ..) = section(b, K::TrianglePlanes);
        put_u32(b, entry_field(i, 2), 16);
        put_u32(b, entry_field(i, 3), 1);
    });
    non_finite_plane: E::NonFinite { section: K::TrianglePlanes, entry: 1 } =>
        corrupt_section(K::TrianglePlanes, |s| put_f32(s, 16 + 4, f32::NAN));
    // Triangle 1's normal flipped: the plane of a triangle facing the other way.
    triangle_plane_flipped: E::TrianglePlane { triangle: 1 } =>
        corrupt_section(K::TrianglePlanes, |s| put_f32(s, 16 + 8, -1.0e4));
    // Triangle 0's scale off by 1e-5 (ten times the tolerance): m is n / |n|^2, not near it.
    triangle_plane_scale: E::TrianglePlane { triangle: 0 } =>
        corrupt_section(K::TrianglePlanes, |s| put_f32(s, 8, 1.0e4 * (1.0 + 1.0e-5)));
    // Triangle 0's plane moved 1 mm along its normal (off = m . a + 10).
    triangle_plane_offset: E::TrianglePlane { triangle: 0 } =>
        corrupt_section(K::TrianglePlanes, |s| put_f32(s, 12, 10.0));
    // Triangle 0's plane in triangle 1's place (node 3 lifted 4 mm, so the two differ).
    triangle_plane_of_another_triangle: E::TrianglePlane { triangle: 1 } => {
        let mut b = builder();
        b.positions_m[3][2] = 0.004;
        let mut bytes = b.build().unwrap();
        let (_, off, ..) = section(&bytes, K::TrianglePlanes);
        let first: [u8; 16] = bytes[off..off + 16].try_into().unwrap();
        bytes[off + 16..off + 32].copy_from_slice(&first);
        assert!(bank_format::reseal(&mut bytes));
        parse(&bytes)
    };
    // Node 1 moved onto the diagonal 0-2: triangle 0 has zero area, hence no plane.
    zero_area_triangle: E::TrianglePlane { triangle: 0 } => {
        let mut b = builder();
        b.positions_m[1] = [0.5 * SIDE, 0.5 * SIDE, 0.0];
        match b.build() {
            Err(BuildError::Rejected(e)) => Err(e),
            other => panic!("{other:?}"),
        }
    };
    grid_cell_size_zero: E::GridGeometry => corrupt_section(K::Grid, |s| put_f32(s, 12, 0.0));
    grid_dimension_zero: E::GridGeometry => corrupt_section(K::Grid, |s| put_u16(s, 18, 0));
    reserved_grid: E::ReservedNotZero { section: K::Grid } => corrupt_section(K::Grid, |s| put_u16(s, 22, 1));
    grid_item_wrong_cell: E::GridItemWrongCell { cell: 0, entry: 0 } =>
        corrupt_section(K::GridItems, |s| { put_u16(s, 0, 1); put_u16(s, 2, 0); });
    grid_items_not_sorted: E::GridItemsNotSorted { cell: 0 } => corrupt(|b| {
        let (_, st, ..) = section(b, K::GridStarts);
        let (_, it, ..) = section(b, K::GridItems);
        put_u16(b, st + 2, 2);
        put_u16(b, st + 4, 2);
        put_u16(b, it + 2, 0);
    });
    triangle_count: E::TriangleCount { count: 65536 } => {
        let mut b = builder();
        b.triangles = vec![[0, 1, 2]; bank_format::MAX_TRIANGLES + 1];
        match b.build() {
            Err(BuildError::Rejected(e)) => Err(e),
            other => panic!("{other:?}"),
        }
    };
    // The first cell's list [0, 1] made [1, 1]: not ascending, and triangle 0 missing.
    cell_candidates: E::CellCandidates { cell: 0 } =>
        corrupt_section(K::CellTriItems, |s| put_u16(s, 0, 1));
    cell_candidate_out_of_range: E::IndexOutOfRange { section: K::CellTriItems, entry: 0 } =>
        corrupt_section(K::CellTriItems, |s| put_u16(s, 0, 7));
    // Every cell claims clearance 1, the occupied ones too.
    cell_clearance_occupied: E::CellClearance { .. } =>
        corrupt_section(K::CellClearance, |s| s.fill(1));
    // A free cell claiming more than one above a neighbour (node 3 moved 5 cm away and out of
    // the triangles, so the grid has free cells).
    cell_clearance_not_lipschitz: E::CellClearance { .. } => {
        let mut b = builder();
        b.positions_m[3] = [0.0, 0.05, 0.0];
        b.triangles = vec![[0, 1, 2]];
        let mut bytes = b.build().expect("valid with small cells");
        let (_, off, len, _) = section(&bytes, K::CellClearance);
        let free = bytes[off..off + len].iter().position(|&c| c > 0).expect("a free cell");
        bytes[off + free] += 2;
        assert!(bank_format::reseal(&mut bytes));
        parse(&bytes)
    };
    ckk_not_spd: E::CkkNotSpd { node: 2 } => corrupt_section(K::Ckk, |s| put_f32(s, 2 * 24, -1.0e-3));
    neighbour_self: E::NeighbourSelf { node: 0 } => corrupt_section(K::NeighbourIndex, |s| put_u16(s, 0, 0));
    neighbour_not_sorted: E::NeighbourNotSorted { node: 0 } => corrupt_section(K::NeighbourIndex, |s| {
        put_u16(s, 0, 2);
        put_u16(s, 2, 1);
    });
    neighbour_not_reciprocal: E::NeighbourNotReciprocal { node: 1, neighbour: 3 } =>
        corrupt_section(K::NeighbourIndex, |s| put_u16(s, 4 * 2, 3));
    pair_not_spd: E::PairNotSpd { node: 0, neighbour: 1 } => corrupt_section(K::NeighbourCkl, |s| {
        // C_01 (block 0, the pair's only one) 0.02 I: larger than C_00's and C_11's diagonals.
        for i in 0..9 {
            put_f32(s, 4 * i, if i % 4 == 0 { 0.02 } else { 0.0 });
        }
    });
    missing_neighbour: E::MissingNeighbour { node: 1, neighbour: 3 } =>
        corrupt_section(K::Meta, |s| put_f32(s, 8, 0.02));
    triangle_edge_not_coupled: E::TriangleEdgeNotCoupled { triangle: 0 } => {
        let mut x = builder();
        x.couplings.retain(|&(k, l, _)| (k, l) != (0, 2));
        match x.build() {
            Err(BuildError::Rejected(e)) => Err(e),
            other => panic!("{other:?}"),
        }
    };
    reserved_meta: E::ReservedNotZero { section: K::Meta } => corrupt_section(K::Meta, |s| put_u32(s, 12, 7));
    bad_truncation_radius: E::BadTruncationRadius => corrupt_section(K::Meta, |s| put_f32(s, 8, -1.0));
    law_kind: E::LawKind { kind: 7 } => corrupt_section(K::TissueLaw, |s| put_u32(s, 0, 7));
    law_coefficient_count: E::LawCoefficientCount { count: 17 } =>
        corrupt_section(K::TissueLaw, |s| put_u32(s, 4, 17));
    law_unused_coefficient: E::ReservedNotZero { section: K::TissueLaw } =>
        corrupt_section(K::TissueLaw, |s| put_f32(s, 16 + 4 * 15, 1.0));
    law_domain: E::LawDomain => corrupt_section(K::TissueLaw, |s| put_f32(s, 8, 6.0));
    law_not_monotone: E::LawNotMonotone { sample: 0 } =>
        corrupt_section(K::TissueLaw, |s| put_f32(s, 16 + 4, -2.5));
    device_shaft_axis: E::Device { field: F::ShaftAxis } => device_f32(DEV_SHAFT + 8, -0.9);
    device_pitch_axis: E::Device { field: F::PitchAxis } => device_f32(DEV_PITCH, 2.0);
    device_yaw_axis: E::Device { field: F::YawAxis } => device_f32(DEV_YAW + 4, 0.0);
    device_axes_not_orthogonal: E::Device { field: F::AxesNotOrthogonal } =>
        corrupt_section(K::Device, |s| {
            // Pitch axis = yaw axis: both unit, not orthogonal.
            put_f32(s, DEV_PITCH, 0.0);
            put_f32(s, DEV_PITCH + 4, 1.0);
        });
    device_joint_range: E::Device { field: F::JointRange { axis: 1 } } => device_f32(DEV_MAX + 4, -0.9);
    device_joint_range_angle: E::Device { field: F::JointRange { axis: 0 } } => device_f32(DEV_MAX, 4.0);
    device_joint_range_insertion: E::Device { field: F::JointRange { axis: 2 } } =>
        device_f32(DEV_MIN + 8, -0.01);
    device_home_joint: E::Device { field: F::HomeJoint { axis: 2 } } => device_f32(DEV_HOME + 8, 0.5);
    device_counts_per_rev: E::Device { field: F::CountsPerRev { axis: 1 } } =>
        corrupt_section(K::Device, |s| put_u32(s, DEV_COUNTS + 4, 0));
    device_transmission: E::Device { field: F::Transmission { axis: 2 } } => device_f32(DEV_TRANS + 8, 0.0);
    device_torque_constant: E::Device { field: F::TorqueConstant { axis: 0 } } => device_f32(DEV_KT, -0.03);
    device_current_limit: E::Device { field: F::CurrentLimit { axis: 2 } } => device_f32(DEV_LIMIT + 8, 25.0);
    device_max_force: E::Device { field: F::MaxForce } => device_f32(DEV_FORCE, 0.0);
    device_tip_radius: E::Device { field: F::TipRadius } => device_f32(DEV_TIP, 0.1);
    device_max_tip_speed_zero: E::Device { field: F::MaxTipSpeed } => device_f32(DEV_TIP_SPEED, 0.0);
    device_max_tip_speed_negative: E::Device { field: F::MaxTipSpeed } => device_f32(DEV_TIP_SPEED, -1.0);
    device_max_joint_speed_pitch: E::Device { field: F::MaxJointSpeed { axis: 0 } } =>
        device_f32(DEV_JOINT_SPEED, 0.0);
    device_max_joint_speed_yaw: E::Device { field: F::MaxJointSpeed { axis: 1 } } =>
        device_f32(DEV_JOINT_SPEED + 4, -3.0);
    device_max_joint_speed_insertion: E::Device { field: F::MaxJointSpeed { axis: 2 } } =>
        device_f32(DEV_JOINT_SPEED + 8, -0.0);
    device_link_timeout_short: E::Device { field: F::LinkTimeout } =>
        corrupt_section(K::Device, |s| put_u32(s, DEV_LINK_TIMEOUT, 4));
    device_link_timeout_long: E::Device { field: F::LinkTimeout } =>
        corrupt_section(K::Device, |s| put_u32(s, DEV_LINK_TIMEOUT, 101));
    ckl_exponent: E::CklExponent { entry: 1 } => {
        let mut bytes = builder().build_with_precision(bank_format::Precision::Bfp16).unwrap();
        let (_, off, ..) = section(&bytes, K::NeighbourCkl16);
        put_u16(&mut bytes, off + 20 + 18, (-127i16) as u16);
        assert!(bank_format::reseal(&mut bytes));
        parse(&bytes)
    };
    ckl_missing: E::MissingSection { section: K::NeighbourCkl } => set_entry(K::NeighbourCkl, 0, 99);
    // The optional gravity section's entry made an empty 16-bit C_kl beside the f32 one.
    ckl_in_both_precisions: E::DuplicateSection { section: K::NeighbourCkl16 } => {
        let mut b = builder();
        b.gravity = Some(bank_format::GravityCompensation { coeffs: [0.0; 8] });
        let mut bytes = b.build().unwrap();
        let (i, ..) = section(&bytes, K::Gravity);
        put_u32(&mut bytes, entry_field(i, 0), K::NeighbourCkl16.code());
        put_u32(&mut bytes, entry_field(i, 2), 0);
        put_u32(&mut bytes, entry_field(i, 3), 0);
        assert!(bank_format::reseal(&mut bytes));
        parse(&bytes)
    };
    gravity_out_of_range: E::GravityOutOfRange { coefficient: 3 } => {
        let mut b = builder();
        b.gravity = Some(bank_format::GravityCompensation { coeffs: [0.0; 8] });
        let mut bytes = b.build().unwrap();
        let (_, off, ..) = section(&bytes, K::Gravity);
        put_f32(&mut bytes, off + 12, 150.0);
        assert!(bank_format::reseal(&mut bytes));
        parse(&bytes)
    };
    relaxation_count: E::RelaxationCount { count: 5 } => relaxation(|r| r.count = 5);
    relaxation_term: E::RelaxationTerm { term: 1 } => relaxation(|r| r.tau_s[1] = 1.0e-3);
    relaxation_sum: E::RelaxationSum => relaxation(|r| r.g[0] = 0.9);
    samples_incomplete: E::MissingSection { section: K::PatchCompliance } => corrupt_sampled(|b| {
        let (i, ..) = section(b, K::PatchCompliance);
        put_u32(b, entry_field(i, 0), 99);
    });
    sample_level_zero: E::SampleHeader { level: 0 } => corrupt_sampled(|b| {
        let (_, off, ..) = section(b, K::SampleHeader);
        put_u32(b, off, 0);
    });
    sample_level_too_high: E::SampleHeader { level: 9 } => corrupt_sampled(|b| {
        let (_, off, ..) = section(b, K::SampleHeader);
        put_u32(b, off, 9);
    });
    sample_radius_negative: E::SampleHeader { level: 2 } => corrupt_sampled(|b| {
        let (_, off, ..) = section(b, K::SampleHeader);
        put_f32(b, off + 4, -0.001);
    });
    sample_ids_count: E::CountMismatch { section: K::TriangleSamples } => corrupt_sampled(|b| {
        let (i, ..) = section(b, K::TriangleSamples);
        put_u32(b, entry_field(i, 3), 10);
        put_u32(b, entry_field(i, 2), 20);
    });
    sample_id_out_of_range: E::IndexOutOfRange { section: K::TriangleSamples, entry: 4 } =>
        corrupt_sampled(|b| {
            let (_, off, ..) = section(b, K::TriangleSamples);
            put_u16(b, off + 8, 500);
        });
    sample_not_finite: E::NonFinite { section: K::PatchCompliance, entry: 1 } =>
        corrupt_sampled(|b| {
            let (_, off, ..) = section(b, K::PatchCompliance);
            put_f32(b, off + 24 + 4, f32::INFINITY);
        });
    sample_not_spd: E::SampleNotSpd { sample: 2 } => corrupt_sampled(|b| {
        let (_, off, ..) = section(b, K::PatchCompliance);
        put_f32(b, off + 48 + 12, -1.0e-3);
    });
    // Sample 2 (of triangle 0) SPD by the C_kk test (smallest pivot 1e-6 of the diagonal,
    // above 1e-7) but too ill-conditioned for the tick's solve (under twice MIN_PIVOT_REL).
    sample_ill_conditioned: E::SampleIllConditioned { triangle: 0, sample: 2 } =>
        corrupt_sampled(|b| {
            let (_, off, ..) = section(b, K::PatchCompliance);
            for (k, v) in [1.0e-3, 0.0, 0.0, 1.0e-3, 0.0, 1.0e-9].into_iter().enumerate() {
                put_f32(b, off + 48 + 4 * k, v);
            }
        });
    // The tick's limits (`SPEC.md`, "Limits the tick's cost rests on"): hostile but otherwise
    // valid banks, refused.
    too_many_candidates: E::TooManyCandidates { cell: 0, count: 162 } =>
        hostile_grid(10, 0.0005, 0.0, 0.02);
    too_many_neighbours: E::TooManyNeighbours { count: 143, .. } =>
        hostile_grid(12, 0.001, 0.02, 0.002);
    too_many_triangles: E::TooManyTriangles { node: 0, count: 17 } => fan(17);
    sample_discontinuous: E::SampleDiscontinuous { triangle: 0 } => corrupt_sampled(|b| {
        // Triangle 0's lattice point (0, 1) (index 3) is the midpoint of the edge 0-2 it
        // shares with triangle 1; make it name triangle 0's own point (1, 0) (the midpoint of
        // its edge 0-1) instead.
        let (_, off, ..) = section(b, K::TriangleSamples);
        let other = u16::from_le_bytes([b[off + 2], b[off + 3]]);
        put_u16(b, off + 2 * 3, other);
    });
}

#[test]
fn sampled_bank_round_trips() {
    let b = sampled_builder();
    let bytes = AlignedBytes::new(&b.build().unwrap());
    let bank = Bank::parse(&bytes).unwrap();
    let s = bank.samples().expect("samples");
    assert_eq!(s.level(), 2);
    // Two triangles of 6 lattice points sharing the 3 points of their common edge.
    assert_eq!(s.count(), 9);
    assert!(
        Bank::parse(&AlignedBytes::new(&valid_bytes()))
            .unwrap()
            .samples()
            .is_none()
    );
    // At a vertex, W is that vertex's C_kk (the samples mix the vertices' blocks).
    let w = s.interpolate(0, [1.0, 0.0, 0.0]).unwrap();
    let c = bank.c_kk(0).unwrap();
    for (a, e) in w.iter().zip(&c) {
        assert!((a - e).abs() <= 1e-6 * e.abs().max(1e-9), "{w:?} vs {c:?}");
    }
}

#[test]
fn error_codes_are_distinct_and_stable() {
    assert_eq!(E::TooShort { needed: 0, got: 0 }.code(), 1);
    assert_eq!(E::Device { field: F::MaxForce }.code(), 40);
    assert_eq!(E::CellClearance { cell: 0 }.code(), 43);
    assert_eq!(
        E::PairNotSpd {
            node: 0,
            neighbour: 0
        }
        .code(),
        32
    );
    assert_eq!(E::GravityOutOfRange { coefficient: 0 }.code(), 44);
    assert_eq!(E::CklExponent { entry: 0 }.code(), 45);
    assert_eq!(E::TrianglePlane { triangle: 0 }.code(), 46);
    assert_eq!(E::SampleDiscontinuous { triangle: 0 }.code(), 49);
    assert_eq!(E::TooManyCandidates { cell: 0, count: 0 }.code(), 50);
    assert_eq!(E::TooManyNeighbours { node: 0, count: 0 }.code(), 51);
    assert_eq!(E::TooManyTriangles { node: 0, count: 0 }.code(), 52);
    assert_eq!(E::RelaxationCount { count: 0 }.code(), 53);
    assert_eq!(E::RelaxationTerm { term: 0 }.code(), 54);
    assert_eq!(E::RelaxationSum.code(), 55);
    assert_eq!(
        E::SampleIllConditioned {
            triangle: 0,
            sample: 0
        }
        .code(),
        last_code()
    );
}
