//! The optional gravity section (kind 24, `SPEC.md` "gravity"): round trip, absence, the
//! reader's rules, and the efforts against the potential's gradient taken numerically.

mod common;

use bank_format::{
    AlignedBytes, Bank, BankError, GRAVITY_COEFF_MAX, GravityCompensation, SectionKind,
    VERSION_MINOR, reseal,
};
use common::*;

const COEFFS: [f32; 8] = [0.05, -0.02, 0.03, 0.4, 0.1, -0.3, 0.02, -0.01];

fn with_gravity(coeffs: [f32; 8]) -> Vec<u8> {
    let mut b = builder();
    b.gravity = Some(GravityCompensation { coeffs });
    b.build().unwrap()
}

#[test]
fn the_gravity_section_round_trips_and_is_optional() {
    let bytes = with_gravity(COEFFS);
    let aligned = AlignedBytes::new(&bytes);
    let bank = Bank::parse(&aligned).unwrap();
    assert_eq!(bank.version().1, VERSION_MINOR);
    assert_eq!(bank.gravity().map(|g| g.coeffs), Some(COEFFS));
    let (_, off, len, count) = section(&bytes, SectionKind::Gravity);
    assert_eq!((len, count), (32, 1));
    assert_eq!(SectionKind::Gravity.code(), 24);
    for (i, c) in COEFFS.iter().enumerate() {
        assert_eq!(get_f32(&bytes, off + 4 * i), *c);
    }
    // Without it: no compensation, and the rest of the bank is unchanged in meaning.
    let plain = AlignedBytes::new(&valid_bytes());
    let plain = Bank::parse(&plain).unwrap();
    assert_eq!(plain.gravity(), None);
    assert_eq!(plain.node_count(), bank.node_count());
}

#[test]
fn bad_gravity_sections_are_refused() {
    let run = |f: &dyn Fn(&mut Vec<u8>)| {
        let mut bytes = with_gravity(COEFFS);
        f(&mut bytes);
        assert!(reseal(&mut bytes));
        parse(&bytes)
    };
    let coeff_at = |bytes: &[u8], i: usize| section(bytes, SectionKind::Gravity).1 + 4 * i;
    assert_eq!(
        run(&|b| {
            let at = coeff_at(b, 5);
            put_f32(b, at, f32::NAN)
        }),
        Err(BankError::NonFinite {
            section: SectionKind::Gravity,
            entry: 0
        })
    );
    assert_eq!(
        run(&|b| {
            let at = coeff_at(b, 6);
            put_f32(b, at, -1.5 * GRAVITY_COEFF_MAX)
        }),
        Err(BankError::GravityOutOfRange { coefficient: 6 })
    );
    // The limit itself is accepted.
    assert_eq!(
        run(&|b| {
            let at = coeff_at(b, 0);
            put_f32(b, at, GRAVITY_COEFF_MAX)
        }),
        Ok(())
    );
    // A count of two with a 32-byte length: wrong size for the kind.
    assert_eq!(
        run(&|b| {
            let (i, ..) = section(b, SectionKind::Gravity);
            put_u32(b, entry_field(i, 3), 2)
        }),
        Err(BankError::SizeMismatch {
            section: SectionKind::Gravity
        })
    );
    // The builder refuses what the reader would.
    let mut b = builder();
    b.gravity = Some(GravityCompensation {
        coeffs: [0.0, 0.0, 0.0, f32::INFINITY, 0.0, 0.0, 0.0, 0.0],
    });
    assert!(b.build().is_err());
}

/// `efforts` is the gradient of `SPEC.md`'s potential `V`: checked against central
/// differences of `V` evaluated in f64 at a few poses.
#[test]
fn the_efforts_are_the_gradient_of_the_potential() {
    let g = GravityCompensation { coeffs: COEFFS };
    let c = COEFFS.map(f64::from);
    let v = |q: [f64; 3]| {
        let (cp, sp, cy, sy, s) = (q[0].cos(), q[0].sin(), q[1].cos(), q[1].sin(), q[2]);
        -(c[0] + s * c[3]) * cp * cy
            - (c[1] + s * c[4]) * cp * sy
            - (c[2] + s * c[5]) * sp
            - c[6] * cy
            - c[7] * sy
    };
    for q in [
        [0.0, 0.0, 0.05],
        [0.3, -0.5, 0.12],
        [-0.7, 0.6, 0.2],
        [1.2, 2.5, 0.0],
    ] {
        let got = g.efforts(
            (q[0] as f32).sin_cos(),
            (q[1] as f32).sin_cos(),
            q[2] as f32,
        );
        for j in 0..3 {
            let h = 1e-6;
            let (mut lo, mut hi) = (q, q);
            lo[j] -= h;
            hi[j] += h;
            let want = (v(hi) - v(lo)) / (2.0 * h);
            assert!(
                (f64::from(got[j]) - want).abs() < 1e-6,
                "q {q:?} joint {j}: {} vs {want}",
                got[j]
            );
        }
    }
}
