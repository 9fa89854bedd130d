//! The optional viscoelastic relaxation section (kind 26, 7.0, `SPEC.md` "viscoelastic
//! relaxation"): round trip, absence (the rest of the bank byte for byte as without it), and
//! each of the reader's rules.

mod common;

use bank_format::{
    AlignedBytes, Bank, BankError, MAX_PRONY_TERMS, RELAXATION_TAU_MAX_S, RELAXATION_TAU_MIN_S,
    Relaxation, SectionKind, VERSION_MAJOR, reseal,
};
use common::*;

/// Two terms: 0.5 at 50 ms, 0.2 at 5 s (g_inf = 0.3).
fn law() -> Relaxation {
    Relaxation {
        count: 2,
        reserved: 0,
        g: [0.5, 0.2, 0.0, 0.0],
        tau_s: [0.05, 5.0, 0.0, 0.0],
    }
}

fn with(r: Relaxation) -> Vec<u8> {
    let mut b = builder();
    b.relaxation = Some(r);
    b.build().unwrap()
}

#[test]
fn the_relaxation_section_round_trips_and_is_optional() {
    assert_eq!(VERSION_MAJOR, 8);
    let bytes = with(law());
    let aligned = AlignedBytes::new(&bytes);
    let bank = Bank::parse(&aligned).unwrap();
    let r = bank.relaxation().copied().unwrap();
    assert_eq!(r, law());
    assert_eq!(r.terms().collect::<Vec<_>>(), [(0.5, 0.05), (0.2, 5.0)]);
    assert!((r.g_inf() - 0.3).abs() < 1e-7);
    let (_, off, len, count) = section(&bytes, SectionKind::Relaxation);
    assert_eq!((len, count), (40, 1));
    assert_eq!(SectionKind::Relaxation.code(), 26);
    assert_eq!(SectionKind::from_code(26), SectionKind::Relaxation);
    assert_eq!(bytes[off..off + 4], 2u32.to_le_bytes());
    assert_eq!(get_f32(&bytes, off + 8 + 4), 0.2);
    assert_eq!(get_f32(&bytes, off + 24), 0.05);
    // Without it: elastic, and every other section holds the same bytes.
    let plain = valid_bytes();
    let plain_bank = AlignedBytes::new(&plain);
    let plain_bank = Bank::parse(&plain_bank).unwrap();
    assert_eq!(plain_bank.relaxation(), None);
    for kind in SectionKind::REQUIRED {
        let (_, a, la, _) = section(&bytes, kind);
        let (_, b, lb, _) = section(&plain, kind);
        assert_eq!(bytes[a..a + la], plain[b..b + lb], "{kind}");
    }
}

#[test]
fn bad_relaxation_sections_are_refused() {
    let run = |f: &dyn Fn(&mut Relaxation)| {
        let mut r = law();
        f(&mut r);
        // Written with the valid law, then patched and resealed (the builder refuses it).
        let mut bytes = with(law());
        let (_, off, ..) = section(&bytes, SectionKind::Relaxation);
        bytes[off..off + 40].copy_from_slice(bytemuck::bytes_of(&r));
        assert!(reseal(&mut bytes));
        let mut b = builder();
        b.relaxation = Some(r);
        let built = b.build();
        let parsed = parse(&bytes);
        assert_eq!(built.is_ok(), parsed.is_ok(), "builder and reader agree");
        parsed
    };
    let section = SectionKind::Relaxation;
    assert_eq!(
        run(&|r| r.tau_s[1] = f32::NAN),
        Err(BankError::NonFinite { section, entry: 0 })
    );
    assert_eq!(
        run(&|r| r.g[0] = f32::INFINITY),
        Err(BankError::NonFinite { section, entry: 0 })
    );
    assert_eq!(
        run(&|r| r.reserved = 1),
        Err(BankError::ReservedNotZero { section })
    );
    assert_eq!(
        run(&|r| r.count = 0),
        Err(BankError::RelaxationCount { count: 0 })
    );
    assert_eq!(
        run(&|r| r.count = MAX_PRONY_TERMS as u32 + 1),
        Err(BankError::RelaxationCount { count: 5 })
    );
    // An entry past the count.
    assert_eq!(
        run(&|r| r.tau_s[3] = 1.0),
        Err(BankError::ReservedNotZero { section })
    );
    assert_eq!(
        run(&|r| r.g[1] = -0.01),
        Err(BankError::RelaxationTerm { term: 1 })
    );
    assert_eq!(
        run(&|r| r.tau_s[0] = 0.0),
        Err(BankError::RelaxationTerm { term: 0 })
    );
    assert_eq!(
        run(&|r| r.tau_s[1] = RELAXATION_TAU_MIN_S * 0.99),
        Err(BankError::RelaxationTerm { term: 1 })
    );
    assert_eq!(
        run(&|r| r.tau_s[1] = RELAXATION_TAU_MAX_S * 1.01),
        Err(BankError::RelaxationTerm { term: 1 })
    );
    // The limits themselves are accepted.
    assert_eq!(
        run(&|r| r.tau_s = [RELAXATION_TAU_MIN_S, RELAXATION_TAU_MAX_S, 0.0, 0.0]),
        Ok(())
    );
    // g_inf must stay positive: sum < 1.
    assert_eq!(run(&|r| r.g[1] = 0.5), Err(BankError::RelaxationSum));
    assert_eq!(run(&|r| r.g[1] = 0.4999), Ok(()));
    // Four terms, the most.
    assert_eq!(
        run(&|r| {
            r.count = 4;
            r.g = [0.1, 0.2, 0.3, 0.1];
            r.tau_s = [0.01, 0.1, 1.0, 10.0];
        }),
        Ok(())
    );
}
