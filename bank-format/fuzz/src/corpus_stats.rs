//! Which `BankError` the bank_parse corpus reaches, per error code (0 = parsed): shows how deep
//! the fuzzer gets past the CRC. Applies the same mode byte as the fuzz target.
//! Run from `bank-format/fuzz`: `cargo run --bin corpus_stats`.

use bank_format::{AlignedBytes, Bank, reseal};
use std::collections::BTreeMap;

fn main() -> std::io::Result<()> {
    let mut hist: BTreeMap<u16, (usize, String)> = BTreeMap::new();
    for entry in std::fs::read_dir("corpus/bank_parse")? {
        let data = std::fs::read(entry?.path())?;
        let Some((&mode, rest)) = data.split_first() else {
            continue;
        };
        if mode & 2 != 0 {
            continue;
        }
        let mut aligned = AlignedBytes::new(rest);
        if mode & 1 != 0 {
            reseal(aligned.as_mut_slice());
        }
        let (code, text) = match Bank::parse(&aligned) {
            Ok(_) => (0, "parsed".to_string()),
            Err(e) => (e.code(), format!("{e:?}")),
        };
        let slot = hist.entry(code).or_insert((0, text));
        slot.0 += 1;
    }
    for (code, (count, example)) in &hist {
        println!("{code:>3} {count:>6}  e.g. {example}");
    }
    println!("{} distinct outcomes", hist.len());
    Ok(())
}
