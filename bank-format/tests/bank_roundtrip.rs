//! Host writer -> no_std reader round trip on a hand-made 4-node, 2-triangle bank.
#![allow(clippy::needless_range_loop)] // index loops read best for 3x3 blocks

mod common;

use bank_format::{
    AlignedBytes, Bank, BankBuilder, BankError, BuildError, HEADER_LEN, LawKind, MAGIC,
    SECTION_ENTRY_LEN, SectionKind, TissueLaw, VERSION_MAJOR, VERSION_MINOR, bank_crc, reseal,
};
use common::*;

fn f32_close(a: f32, b: f64) -> bool {
    (f64::from(a) - b).abs() <= 1e-6 * b.abs().max(1e-12)
}

#[test]
fn every_accessor_returns_what_was_written() {
    let bytes = valid_bytes();
    let aligned = AlignedBytes::new(&bytes);
    let bank = Bank::parse(&aligned).unwrap();

    assert_eq!(&bytes[..8], &MAGIC);
    assert_eq!(bank.version(), (VERSION_MAJOR, VERSION_MINOR));
    assert_eq!(bank.bytes().len(), bytes.len());
    assert_eq!(bank.crc(), bank_crc(&bytes));
    assert_eq!(bank.scene_id(), 0x0123_4567_89ab_cdef);
    assert_eq!(bank.truncation_radius_m(), 0.012);

    assert_eq!(bank.node_count(), 4);
    let pos = positions();
    for (k, p) in bank.positions().iter().enumerate() {
        for i in 0..3 {
            assert_eq!(p[i], pos[k][i] as f32);
        }
    }
    assert_eq!(bank.mesh_ids(), &[700, 701, 1000, 42]);
    assert_eq!(bank.triangles(), &[[0, 1, 2], [0, 2, 3]]);
    assert_eq!(bank.node_triangles(0), &[0, 1]);
    assert_eq!(bank.node_triangles(1), &[0]);
    assert_eq!(bank.node_triangles(2), &[0, 1]);
    assert_eq!(bank.node_triangles(3), &[1]);
    assert_eq!(bank.node_triangles(4), &[] as &[u16]);
    // Both triangles lie in z = 0, counter-clockwise from +z: n = (0, 0, SIDE^2), so m = (0, 0,
    // 1 / SIDE^2) and off = m . a = 0; the plane value is z / SIDE^2.
    let m = (1.0 / (SIDE * SIDE)) as f32;
    for plane in bank.triangle_planes() {
        assert_eq!(plane.m, [0.0, 0.0, m]);
        assert_eq!(plane.off, 0.0);
        assert_eq!(plane.value([0.3, -2.0, 0.001]), 0.001 * m);
    }
    assert_eq!(bank.triangle_planes().len(), 2);

    // Self-compliance, both forms.
    for k in 0..4 {
        let want = block(k, k);
        let got = bank.c_kk_matrix(k).unwrap();
        let six = bank.c_kk(k).unwrap();
        assert_eq!(
            six,
            [
                got[0][0], got[0][1], got[0][2], got[1][1], got[1][2], got[2][2]
            ]
        );
        for i in 0..3 {
            for j in 0..3 {
                assert!(f32_close(got[i][j], want[i][j]));
            }
        }
    }
    assert_eq!(bank.c_kk(4), None);

    // Couplings: both directions in the index, one block per pair (C_lk = C_kl^T exactly),
    // 1-3 truncated: pairs 01, 02, 03, 12, 23.
    let expected_rows: [&[u16]; 4] = [&[1, 2, 3], &[0, 2], &[0, 1, 3], &[0, 2]];
    for (k, row) in expected_rows.iter().enumerate() {
        let ls = bank.neighbours(k);
        assert_eq!(ls, *row);
        for &l in ls.iter() {
            let l = usize::from(l);
            let want = block(k, l);
            let got = bank.coupling(k, l).unwrap();
            let back = bank.coupling(l, k).unwrap();
            for i in 0..3 {
                for j in 0..3 {
                    assert!(f32_close(got[i][j], want[i][j]), "C_{k}{l}[{i}][{j}]");
                    assert_eq!(back[j][i], got[i][j]);
                }
            }
        }
    }
    assert_eq!(bank.coupling(1, 3), None);
    assert_eq!(bank.coupling(0, 9), None);
    assert_eq!(bank.coupling(2, 2), bank.c_kk_matrix(2));
    assert_eq!(bank.neighbours(4), &[] as &[u16]);
    assert_eq!(bank.pair_count(), 5);

    // Grid: 8 mm cells, origin half a cell below the minimum, one node per cell.
    let g = bank.grid();
    assert_eq!(g.cell_size_m(), 0.008);
    assert_eq!(g.origin_m(), [-0.004, -0.004, -0.004]);
    assert_eq!(g.dims(), [2, 2, 1]);
    assert_eq!(g.cell_count(), 4);
    assert_eq!(g.starts(), &[0, 1, 2, 3, 4]);
    assert_eq!(g.items(), &[0, 1, 3, 2]);
    for (k, p) in bank.positions().iter().enumerate() {
        let c = g.cell_index(g.cell_of(*p).unwrap()).unwrap();
        assert_eq!(g.cell_items(c), &[k as u16]);
    }
    assert_eq!(g.cell_of([1.0, 0.0, 0.0]), None);
    assert_eq!(g.cell_of([f32::NAN, 0.0, 0.0]), None);
    assert_eq!(g.cell_items(99), &[] as &[u16]);

    assert_eq!(bank.tissue_law(), &law());
    assert_eq!(bank.device(), &device());
}

#[test]
fn nearest_node_searches_the_27_buckets() {
    let aligned = AlignedBytes::new(&valid_bytes());
    let bank = Bank::parse(&aligned).unwrap();
    assert_eq!(bank.nearest_node([0.001, 0.0, 0.001]).map(|r| r.0), Some(0));
    assert_eq!(
        bank.nearest_node([0.009, 0.0098, 0.0]).map(|r| r.0),
        Some(2)
    );
    let (k, d2) = bank.nearest_node([0.0, 0.011, -0.002]).unwrap();
    assert_eq!(k, 3);
    assert!((d2 - (0.001f32 * 0.001 + 0.002 * 0.002)).abs() < 1e-9);
    // Just outside the grid still finds the corner; far away finds nothing.
    assert_eq!(
        bank.nearest_node([-0.006, -0.006, 0.0]).map(|r| r.0),
        Some(0)
    );
    assert_eq!(bank.nearest_node([0.5, 0.5, 0.5]), None);
    assert_eq!(bank.nearest_node([f32::NAN, 0.0, 0.0]), None);
}

#[test]
fn bytes_past_total_len_are_ignored() {
    // A flash region is erased to 0xFF past the bank.
    let mut bytes = valid_bytes();
    let len = bytes.len();
    bytes.resize(len + 4096, 0xFF);
    let aligned = AlignedBytes::new(&bytes);
    let bank = Bank::parse(&aligned).unwrap();
    assert_eq!(bank.bytes().len(), len);
}

#[test]
fn building_is_deterministic_and_sections_are_8_aligned() {
    let a = valid_bytes();
    assert_eq!(a, valid_bytes());
    assert_eq!(a.len() % 8, 0);
    for kind in SectionKind::REQUIRED {
        let (_, off, len, count) = section(&a, kind);
        assert_eq!(off % 8, 0, "{kind:?}");
        assert_eq!(len, count * kind.element_size().unwrap());
    }
}

#[test]
fn the_reader_exposes_the_section_table_as_written() {
    let bytes = valid_bytes();
    let aligned = AlignedBytes::new(&bytes);
    let bank = Bank::parse(&aligned).unwrap();
    // The required kinds and the f32 blocks (the default precision).
    assert_eq!(bank.sections().len(), SectionKind::REQUIRED.len() + 1);
    for kind in SectionKind::REQUIRED
        .into_iter()
        .chain([SectionKind::NeighbourCkl])
    {
        let (_, off, len, count) = section(&bytes, kind);
        let e = bank
            .sections()
            .iter()
            .find(|e| e.kind == kind.code())
            .unwrap();
        assert_eq!(
            (e.offset as usize, e.len as usize, e.count as usize),
            (off, len, count)
        );
    }
}

/// Insert a section table entry of kind 77 (8 bytes at the end), shifting the sections.
fn with_unknown_section(bytes: &[u8], minor: u16) -> Vec<u8> {
    let count = u16::from_le_bytes([bytes[14], bytes[15]]) as usize;
    let table_end = HEADER_LEN + SECTION_ENTRY_LEN * count;
    let mut out = bytes[..table_end].to_vec();
    let data = &bytes[table_end..];
    let new_total = bytes.len() + SECTION_ENTRY_LEN + 8;
    out.extend_from_slice(&77u32.to_le_bytes());
    out.extend_from_slice(&((new_total - 8) as u32).to_le_bytes());
    out.extend_from_slice(&8u32.to_le_bytes());
    out.extend_from_slice(&1u32.to_le_bytes());
    for i in 0..count {
        let at = entry_field(i, 1);
        let off = u32::from_le_bytes(out[at..at + 4].try_into().unwrap());
        put_u32(&mut out, at, off + SECTION_ENTRY_LEN as u32);
    }
    out.extend_from_slice(data);
    out.extend_from_slice(&[0xAB; 8]);
    put_u16(&mut out, 10, minor);
    put_u16(&mut out, 14, count as u16 + 1);
    put_u32(&mut out, 16, new_total as u32);
    assert!(reseal(&mut out));
    out
}

#[test]
fn a_later_minor_version_with_an_unknown_section_is_read() {
    let bytes = with_unknown_section(&valid_bytes(), 3);
    let aligned = AlignedBytes::new(&bytes);
    let bank = Bank::parse(&aligned).unwrap();
    assert_eq!(bank.version(), (VERSION_MAJOR, 3));
    assert_eq!(bank.node_count(), 4);
}

#[test]
fn tissue_law_is_continuous_monotone_and_linear_outside() {
    let q = law();
    assert_eq!(q.kind(), LawKind::Chebyshev);
    assert_eq!(q.coeffs(), &[2.6, 2.5, 0.1]);
    // Reference in f64: x = (2f - 5) / 5, Q = 2.6 + 2.5 x + 0.1 (2x^2 - 1).
    let reference = |f: f64| {
        let x = (2.0 * f - 5.0) / 5.0;
        2.6 + 2.5 * x + 0.1 * (2.0 * x * x - 1.0)
    };
    let mut prev = f32::NEG_INFINITY;
    for i in 0..=1000 {
        let f = -2.0 + 9.0 * i as f32 / 1000.0;
        let v = q.eval(f);
        assert!(v > prev, "not increasing at {f}");
        prev = v;
        if (0.0..=5.0).contains(&f) {
            assert!((f64::from(v) - reference(f64::from(f))).abs() < 1e-5);
        }
    }
    // Linear continuation with the end slopes: dQ/df = (2.5 + 0.4 x) * 2 / 5.
    let lo_slope = (2.5 - 0.4) * 0.4;
    let hi_slope = (2.5 + 0.4) * 0.4;
    assert!((q.slope(-1.0) - lo_slope as f32).abs() < 1e-6);
    assert!((q.slope(9.0) - hi_slope as f32).abs() < 1e-6);
    assert!((q.slope(2.5) - 1.0).abs() < 1e-6);
    assert!((f64::from(q.eval(-1.0)) - (0.2 - lo_slope)).abs() < 1e-5);
    assert!((f64::from(q.eval(7.0)) - (5.2 + 2.0 * hi_slope)).abs() < 1e-5);
    assert!(q.eval(f32::NAN).is_nan());

    let lin = TissueLaw::linear(0.1, 1.5, [0.0, 4.0]).unwrap();
    assert_eq!(lin.kind(), LawKind::Linear);
    assert_eq!(lin.eval(2.0), 0.1 + 3.0);
    assert_eq!(lin.slope(100.0), 1.5);
    assert_eq!(TissueLaw::from_record(&lin.to_record()), Ok(lin));
}

#[test]
fn tissue_law_constructors_reject_bad_laws() {
    assert_eq!(
        TissueLaw::chebyshev(&[], [0.0, 1.0]),
        Err(BankError::LawCoefficientCount { count: 0 })
    );
    assert_eq!(
        TissueLaw::chebyshev(&[1.0; 17], [0.0, 1.0]),
        Err(BankError::LawCoefficientCount { count: 17 })
    );
    assert_eq!(
        TissueLaw::chebyshev(&[1.0, 1.0], [1.0, 1.0]),
        Err(BankError::LawDomain)
    );
    // A constant is not increasing.
    assert_eq!(
        TissueLaw::chebyshev(&[1.0], [0.0, 1.0]),
        Err(BankError::LawNotMonotone { sample: 0 })
    );
    // 1 + T1 - 0.6 T2: slope 1 - 2.4 x turns negative past x = 1/2.4.
    assert!(matches!(
        TissueLaw::chebyshev(&[1.0, 1.0, -0.6], [0.0, 1.0]),
        Err(BankError::LawNotMonotone { sample }) if sample > 128
    ));
    assert_eq!(
        TissueLaw::linear(0.0, 0.0, [0.0, 1.0]),
        Err(BankError::LawNotMonotone { sample: 0 })
    );
    assert_eq!(
        TissueLaw::linear(f32::NAN, 1.0, [0.0, 1.0]),
        Err(BankError::NonFinite {
            section: SectionKind::TissueLaw,
            entry: 0
        })
    );
}

#[test]
fn the_builder_refuses_bad_input() {
    let b = builder;
    let mut x = b();
    x.mesh_ids.pop();
    assert_eq!(
        x.build(),
        Err(BuildError::LengthMismatch { field: "mesh_ids" })
    );
    let mut x = b();
    x.c_kk.push(block(0, 0));
    assert_eq!(x.build(), Err(BuildError::LengthMismatch { field: "c_kk" }));
    let mut x = b();
    x.triangles.push([0, 1, 4]);
    assert_eq!(
        x.build(),
        Err(BuildError::IndexOutOfRange {
            field: "triangles",
            entry: 2
        })
    );
    let mut x = b();
    x.couplings.push((70_000, 1, block(0, 1)));
    assert_eq!(
        x.build(),
        Err(BuildError::IndexOutOfRange {
            field: "couplings",
            entry: 5
        })
    );
    let mut x = b();
    x.couplings.push((2, 2, block(2, 2)));
    assert_eq!(x.build(), Err(BuildError::SelfCoupling { entry: 5 }));
    let mut x = b();
    x.c_kk[1][0][1] *= 2.0;
    assert_eq!(x.build(), Err(BuildError::AsymmetricCkk { node: 1 }));
    // The reverse direction may be given too, but must agree.
    let mut x = b();
    x.couplings.push((1, 0, block(1, 0)));
    assert!(x.build().is_ok());
    x.couplings.push((2, 0, block(0, 2)));
    assert_eq!(
        x.build(),
        Err(BuildError::InconsistentCoupling { entry: 6 })
    );
    let mut x = b();
    x.grid_cell_size_m = 0.0;
    assert_eq!(x.build(), Err(BuildError::Grid));
    let mut x = b();
    x.grid_cell_size_m = 1e-9;
    assert_eq!(x.build(), Err(BuildError::Grid));
    let mut x = b();
    x.positions_m.clear();
    x.mesh_ids.clear();
    x.c_kk.clear();
    assert_eq!(
        x.build(),
        Err(BuildError::Rejected(BankError::NodeCount { count: 0 }))
    );
    // Whatever the reader would reject, the writer refuses: here a non-finite position.
    let mut x = b();
    x.positions_m[2][1] = f64::INFINITY;
    assert!(x.build().is_err());
    let mut x = b();
    x.positions_m[3][2] = f64::NAN;
    assert!(x.build().is_err());
}

#[test]
fn the_builder_refuses_what_the_reader_rejects() {
    // Dropping the 0-2 coupling (a triangle edge) is refused with the reader's error.
    let mut x: BankBuilder = builder();
    x.couplings.retain(|&(k, l, _)| (k, l) != (0, 2));
    assert_eq!(
        x.build(),
        Err(BuildError::Rejected(BankError::TriangleEdgeNotCoupled {
            triangle: 0
        }))
    );
    // A truncation radius that reaches 1-3 demands that coupling.
    let mut x = builder();
    x.truncation_radius_m = 0.02;
    assert_eq!(
        x.build(),
        Err(BuildError::Rejected(BankError::MissingNeighbour {
            node: 1,
            neighbour: 3
        }))
    );
    x.couplings.push((1, 3, block(1, 3)));
    assert!(x.build().is_ok());
    let mut x = builder();
    x.device.max_force_n = 0.0;
    assert!(matches!(
        x.build(),
        Err(BuildError::Rejected(BankError::Device { .. }))
    ));
}

/// `SPEC.md`'s device table, row by row: every field's offset and type, checked against where
/// the writer put the field's value in the device section (and the record's total size).
#[test]
fn the_device_section_is_laid_out_as_spec_md_says() {
    let spec = include_str!("../SPEC.md");
    let table = spec
        .split_once("### device (`DeviceCalibration`)")
        .expect("device section in SPEC.md")
        .1;
    let rows: Vec<(usize, &str, &str)> = table
        .lines()
        .skip_while(|l| !l.starts_with("| 0 |"))
        .take_while(|l| l.starts_with('|'))
        .map(|l| {
            let cells: Vec<&str> = l.split('|').map(str::trim).collect();
            let field = cells[3].split(':').next().unwrap().trim();
            (cells[1].parse().unwrap(), cells[2].trim_matches('`'), field)
        })
        .collect();
    let d = device();
    let bytes = valid_bytes();
    let (_, off, len, count) = section(&bytes, SectionKind::Device);
    assert_eq!((len, count), (160, 1));
    assert_eq!(len, std::mem::size_of::<bank_format::DeviceCalibration>());
    let s = &bytes[off..off + len];
    let words = |at: usize, n: usize| -> Vec<[u8; 4]> {
        (0..n)
            .map(|i| s[at + 4 * i..at + 4 * i + 4].try_into().unwrap())
            .collect()
    };
    let f32s = |v: &[f32]| v.iter().map(|x| x.to_le_bytes()).collect::<Vec<_>>();
    let u32s = |v: &[u32]| v.iter().map(|x| x.to_le_bytes()).collect::<Vec<_>>();
    let mut end = 0;
    for &(at, ty, field) in &rows {
        assert_eq!(at, end, "{field} should follow the previous field");
        let want = match field {
            "fulcrum_m" => f32s(&d.fulcrum_m),
            "shaft_axis" => f32s(&d.shaft_axis),
            "pitch_axis" => f32s(&d.pitch_axis),
            "yaw_axis" => f32s(&d.yaw_axis),
            "joint_min" => f32s(&d.joint_min),
            "joint_max" => f32s(&d.joint_max),
            "home_joint" => f32s(&d.home_joint),
            "counts_per_rev" => u32s(&d.counts_per_rev),
            "transmission" => f32s(&d.transmission),
            "torque_constant_nm_per_a" => f32s(&d.torque_constant_nm_per_a),
            "current_limit_a" => f32s(&d.current_limit_a),
            "max_force_n" => f32s(&[d.max_force_n]),
            "tip_radius_m" => f32s(&[d.tip_radius_m]),
            "max_tip_speed_m_s" => f32s(&[d.max_tip_speed_m_s]),
            "max_joint_speed" => f32s(&d.max_joint_speed),
            "link_timeout_ms" => u32s(&[d.link_timeout_ms]),
            other => panic!("SPEC.md names an unknown device field {other:?}"),
        };
        let n = match ty {
            "f32" | "u32" => 1,
            "[f32; 3]" | "[u32; 3]" => 3,
            other => panic!("{field}: unexpected type {other:?}"),
        };
        assert_eq!(n, want.len(), "{field}: type {ty}");
        assert_eq!(words(at, n), want, "{field} at offset {at}");
        end = at + 4 * n;
    }
    assert_eq!(rows.len(), 16);
    assert_eq!(end, len, "SPEC.md's device table covers the whole record");
}

#[test]
fn the_speed_thresholds_round_trip_and_bad_ones_are_refused() {
    let mut x = builder();
    x.device.max_tip_speed_m_s = 0.75;
    x.device.max_joint_speed = [4.0, 5.0, 0.6];
    let aligned = AlignedBytes::new(&x.build().unwrap());
    let bank = Bank::parse(&aligned).unwrap();
    assert_eq!(bank.device().max_tip_speed_m_s, 0.75);
    assert_eq!(bank.device().max_joint_speed, [4.0, 5.0, 0.6]);
    assert_eq!(bank.device(), &x.device);
    for (tip, joints, want) in [
        (
            0.0,
            [1.0; 3],
            BankError::Device {
                field: bank_format::DeviceField::MaxTipSpeed,
            },
        ),
        (
            1.0,
            [1.0, 1.0, -1.0],
            BankError::Device {
                field: bank_format::DeviceField::MaxJointSpeed { axis: 2 },
            },
        ),
        (
            f32::NAN,
            [1.0; 3],
            BankError::NonFinite {
                section: SectionKind::Device,
                entry: 0,
            },
        ),
        (
            1.0,
            [f32::INFINITY, 1.0, 1.0],
            BankError::NonFinite {
                section: SectionKind::Device,
                entry: 0,
            },
        ),
    ] {
        let mut x = builder();
        x.device.max_tip_speed_m_s = tip;
        x.device.max_joint_speed = joints;
        assert_eq!(
            x.build(),
            Err(BuildError::Rejected(want)),
            "{tip} {joints:?}"
        );
        assert_eq!(bank_format::validate_device(&x.device), Err(want));
    }
}

/// The link timeout (8.0) round-trips at both ends of its range; outside it, the writer and the
/// reader refuse it (`Device { field: LinkTimeout }`), and so does `validate_device`.
#[test]
fn the_link_timeout_round_trips_and_out_of_range_is_refused() {
    for ms in [5, 37, 100] {
        let mut x = builder();
        x.device.link_timeout_ms = ms;
        let aligned = AlignedBytes::new(&x.build().unwrap());
        let bank = Bank::parse(&aligned).unwrap();
        assert_eq!(bank.device().link_timeout_ms, ms);
        assert_eq!(bank.device(), &x.device);
    }
    let want = BankError::Device {
        field: bank_format::DeviceField::LinkTimeout,
    };
    for ms in [0, 4, 101, u32::MAX] {
        let mut x = builder();
        x.device.link_timeout_ms = ms;
        assert_eq!(x.build(), Err(BuildError::Rejected(want)), "{ms} ms");
        assert_eq!(bank_format::validate_device(&x.device), Err(want));
    }
    assert_eq!(
        want.to_string(),
        "device calibration: link timeout is not in [5, 100] ms"
    );
}

/// The 16-bit storage (`SPEC.md`, "16-bit blocks"): the same bank with each block as 16-bit
/// mantissas and one exponent, 16 bytes less per pair, every entry within half a unit of the
/// block's exponent, `max |C_kl| / 32767`, of the f64 compliance, both directions read from the
/// one stored block.
#[test]
fn bfp16_blocks_round_within_half_a_unit_of_their_exponent() {
    let b = builder();
    let f32_bytes = b.build().unwrap();
    let bytes = b
        .build_with_precision(bank_format::Precision::Bfp16)
        .unwrap();
    assert_eq!(f32_bytes.len() - bytes.len(), 16 * PAIRS.len());
    let aligned = AlignedBytes::new(&bytes);
    let bank = Bank::parse(&aligned).unwrap();
    assert_eq!(bank.precision(), bank_format::Precision::Bfp16);
    assert_eq!(bank.pair_count(), PAIRS.len());
    let mut worst = 0.0f64;
    for &(k, l) in &PAIRS {
        let want = block(k, l);
        let max = want.iter().flatten().fold(0.0f64, |a, v| a.max(v.abs()));
        let got = bank.coupling(k, l).unwrap();
        let back = bank.coupling(l, k).unwrap();
        for i in 0..3 {
            for j in 0..3 {
                let err = (f64::from(got[i][j]) - want[i][j]).abs();
                assert!(err <= max / 32767.0, "C_{k}{l}[{i}][{j}] off by {err:e}");
                worst = worst.max(err / max);
                assert_eq!(back[j][i], got[i][j]);
            }
        }
    }
    // Not better than 16 bits could be: the rounding is really there.
    assert!(worst > 1e-7, "{worst:e}");
    // C_kk stays f32.
    assert_eq!(
        bank.c_kk_matrix(2),
        Bank::parse(&AlignedBytes::new(&f32_bytes))
            .unwrap()
            .c_kk_matrix(2)
    );
}

/// The encoder takes the smallest exponent: the largest mantissa is at least 16384 (else one
/// exponent less would do), at most 32767; zero blocks and huge blocks are handled.
#[test]
fn bfp16_encoder_uses_the_smallest_exponent() {
    for scale in [1e-9, 3.7e-4, 1.0, 32767.0, 32767.5, 65535.0, 6.0e30] {
        let c = [
            [scale, -0.5 * scale, 0.0],
            [0.25 * scale, 0.0, 1e-3 * scale],
            [0.0; 3],
        ];
        let q = bank_format::encode_ckl16(&c).unwrap();
        let top = q.mantissa.iter().map(|m| m.unsigned_abs()).max().unwrap();
        assert!((16384..=32767).contains(&top), "{scale}: {q:?}");
        let d = q.decode();
        for (v, w) in d.iter().zip(c.iter().flatten()) {
            assert!(
                (f64::from(*v) - w).abs() <= scale / 32767.0,
                "{scale}: {v} vs {w}"
            );
        }
    }
    let zero = bank_format::encode_ckl16(&[[0.0; 3]; 3]).unwrap();
    assert_eq!(zero.decode(), [0.0; 9]);
    assert!(bank_format::encode_ckl16(&[[1e39, 0.0, 0.0], [0.0; 3], [0.0; 3]]).is_none());
    assert!(bank_format::encode_ckl16(&[[f64::NAN, 0.0, 0.0], [0.0; 3], [0.0; 3]]).is_none());
}

/// `Bank::upper_couplings` (a node's stored row: its neighbours above it and their blocks) in
/// both precisions: the nodes are exactly the row's entries `l > k`, ascending, and
/// `add_symmetric_part(i, w)` adds exactly `w (C_kl + C_kl^T)` of the decoded block, bit for
/// bit (16-bit mantissa pairs summed as integers, scaled once). Out of range adds nothing.
#[test]
fn upper_couplings_walk_each_stored_row_and_add_its_symmetric_parts() {
    let b = builder();
    for precision in [bank_format::Precision::F32, bank_format::Precision::Bfp16] {
        let aligned = AlignedBytes::new(&b.build_with_precision(precision).unwrap());
        let bank = Bank::parse(&aligned).unwrap();
        let mut seen = 0;
        for k in 0..bank.node_count() {
            let row = bank.upper_couplings(k);
            let want: Vec<u16> = bank
                .neighbours(k)
                .iter()
                .copied()
                .filter(|&l| usize::from(l) > k)
                .collect();
            assert_eq!(row.nodes(), &want[..], "node {k}, {precision:?}");
            for (i, &l) in row.nodes().iter().enumerate() {
                let c = bank.coupling(k, usize::from(l)).unwrap();
                let w = 0.37f32;
                let mut m = [1.0f32, 2.0, 3.0, 4.0, 5.0, 6.0];
                assert!(row.add_symmetric_part(i, w, &mut m));
                let sym = [
                    c[0][0] + c[0][0],
                    c[0][1] + c[1][0],
                    c[0][2] + c[2][0],
                    c[1][1] + c[1][1],
                    c[1][2] + c[2][1],
                    c[2][2] + c[2][2],
                ];
                for (j, (&got, s)) in m.iter().zip(sym).enumerate() {
                    let start = (j + 1) as f32;
                    assert_eq!(got, start + w * s, "node {k}-{l} entry {j}, {precision:?}");
                }
                seen += 1;
            }
            let mut m = [0.0f32; 6];
            assert!(!row.add_symmetric_part(row.nodes().len(), 1.0, &mut m));
            assert_eq!(m, [0.0; 6]);
        }
        assert_eq!(seen, bank.pair_count());
    }
    assert!(
        Bank::parse(&AlignedBytes::new(&b.build().unwrap()))
            .unwrap()
            .upper_couplings(usize::MAX)
            .nodes()
            .is_empty()
    );
}
