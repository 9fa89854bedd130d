//! Fuzz `Bank::parse`. The first input byte selects a mode: bit 0 set = recompute the CRC
//! before parsing (so mutations reach the validation behind the CRC check), bit 1 set = parse
//! from an odd address (must be rejected). The rest is the bank. A bank that parses is then
//! read through every accessor, including out-of-range indices.
#![no_main]

use bank_format::{AlignedBytes, Bank, reseal};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Some((&mode, rest)) = data.split_first() else {
        return;
    };
    let mut aligned = AlignedBytes::new(rest);
    if mode & 1 != 0 {
        reseal(aligned.as_mut_slice());
    }
    if mode & 2 != 0 {
        let mut shifted = vec![0u8];
        shifted.extend_from_slice(&aligned);
        let shifted = AlignedBytes::new(&shifted);
        assert!(Bank::parse(&shifted[1..]).is_err());
        return;
    }
    let Ok(bank) = Bank::parse(&aligned) else {
        return;
    };
    let n = bank.node_count();
    assert!((1..=65535).contains(&n));
    for k in 0..=n {
        let _ = bank.c_kk_matrix(k);
        for &t in bank.node_triangles(k) {
            assert!(bank.triangles()[t as usize].contains(&(k as u16)));
        }
        let ls = bank.neighbours(k);
        for &l in ls {
            assert!(bank.coupling(usize::from(l), k).is_some());
            assert!(bank.coupling(k, usize::from(l)).is_some());
        }
    }
    assert_eq!(bank.triangle_planes().len(), bank.triangles().len());
    for (plane, tri) in bank.triangle_planes().iter().zip(bank.triangles()) {
        let a = bank.positions()[usize::from(tri[0])];
        assert!(plane.value(a).is_finite());
    }
    let g = bank.grid();
    for c in 0..=g.cell_count() {
        for &i in g.cell_items(c) {
            assert!(usize::from(i) < n);
        }
    }
    for p in bank.positions() {
        assert!(bank.nearest_node(*p).is_some());
    }
    let law = bank.tissue_law();
    let [a, b] = law.domain();
    for i in 0..=64 {
        let f = a + (b - a) * (i as f32 / 64.0);
        assert!(!law.eval(f).is_nan());
    }
    let _ = bank.device();
});
