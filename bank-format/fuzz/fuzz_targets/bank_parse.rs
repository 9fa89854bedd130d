//! Fuzz `Bank::parse`. The first input byte selects a mode: bit 0 set = recompute the CRC
//! before parsing (so mutations reach the validation behind the CRC check), bit 1 set = parse
//! from an odd address (alignment check). The rest is the bank. A bank that parses is then
//! read through every accessor, including out-of-range indices.
#![no_main]

use bank_format::{AlignedBytes, Bank, reseal};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Some((&mode, rest)) = data.split_first() else {
        return;
    };
    let mut bytes = Vec::with_capacity(rest.len() + 1);
    bytes.push(0);
    bytes.extend_from_slice(rest);
    let mut aligned = AlignedBytes::new(&bytes);
    if mode & 1 != 0 {
        reseal(&mut aligned.as_mut_slice()[1..]);
    }
    let start = if mode & 2 != 0 { 0 } else { 1 };
    let slice = if start == 0 {
        // Odd-address view: drop one byte at the front of an aligned copy.
        let shifted = AlignedBytes::new(&bytes[..]);
        let _ = Bank::parse(&shifted[1..]);
        return;
    } else {
        aligned = AlignedBytes::new(&aligned[1..]);
        &aligned[..]
    };
    let Ok(bank) = Bank::parse(slice) else {
        return;
    };
    let n = bank.node_count();
    assert!((1..=65535).contains(&n));
    for k in 0..=n {
        let _ = bank.c_kk_matrix(k);
        for &t in bank.node_triangles(k) {
            assert!(bank.triangles()[t as usize].contains(&(k as u16)));
        }
        let (ls, cs) = bank.neighbours(k);
        assert_eq!(ls.len(), cs.len());
        for &l in ls {
            assert!(bank.coupling(usize::from(l), k).is_some());
        }
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
    let mut prev = f32::NEG_INFINITY;
    for i in 0..=64 {
        let f = a + (b - a) * (i as f32 / 64.0);
        let q = law.eval(f);
        assert!(q.is_finite());
        prev = prev.max(q);
    }
    let _ = bank.device();
});
