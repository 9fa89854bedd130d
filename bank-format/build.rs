//! Reads the flash map from the workspace's `memory.x` (the one place it is written) and
//! generates `region.rs`: the firmware and bank regions' addresses and sizes, so the host, the
//! SIL harness and the flasher derive them instead of repeating them.

use std::path::PathBuf;

/// `(origin, length)` of region `name` in the `MEMORY { .. }` block of a linker script.
fn region(script: &str, name: &str) -> Result<(u64, u64), String> {
    let body = script
        .split_once("MEMORY")
        .and_then(|(_, rest)| rest.split_once('{'))
        .and_then(|(_, rest)| rest.split_once('}'))
        .map(|(body, _)| body)
        .ok_or("no MEMORY { .. } block")?;
    let line = body
        .lines()
        .find(|l| l.split(':').next().is_some_and(|n| n.trim() == name))
        .ok_or_else(|| format!("no {name} region in MEMORY"))?;
    let field = |key: &str| -> Result<u64, String> {
        let value = line
            .split(',')
            .find_map(|part| {
                part.trim()
                    .split_once('=')
                    .filter(|(k, _)| k.trim_end().ends_with(key))
            })
            .map(|(_, v)| v.trim())
            .ok_or_else(|| format!("{name}: no {key}"))?;
        number(value).ok_or_else(|| format!("{name}: cannot read {key} = {value}"))
    };
    Ok((field("ORIGIN")?, field("LENGTH")?))
}

/// A linker-script number: decimal or `0x` hex, with an optional `K` or `M` suffix.
fn number(s: &str) -> Option<u64> {
    let (digits, scale) = match s.as_bytes().last()? {
        b'K' | b'k' => (&s[..s.len() - 1], 1024),
        b'M' | b'm' => (&s[..s.len() - 1], 1024 * 1024),
        _ => (s, 1),
    };
    let v = match digits
        .strip_prefix("0x")
        .or_else(|| digits.strip_prefix("0X"))
    {
        Some(hex) => u64::from_str_radix(hex, 16).ok()?,
        None => digits.parse().ok()?,
    };
    v.checked_mul(scale)
}

fn main() {
    let dir = PathBuf::from(std::env::var_os("CARGO_MANIFEST_DIR").expect("cargo sets it"));
    let path = dir.join("../memory.x");
    println!("cargo:rerun-if-changed={}", path.display());
    let script = std::fs::read_to_string(&path).unwrap_or_else(|e| {
        panic!(
            "{}: {e} (bank-format reads the flash map from it)",
            path.display()
        )
    });
    let read =
        |name: &str| region(&script, name).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let (firmware_origin, firmware_len) = read("FLASH");
    let (bank_origin, bank_len) = read("BANK");
    let (ram_origin, ram_len) = read("RAM");
    let out = PathBuf::from(std::env::var_os("OUT_DIR").expect("cargo sets it")).join("region.rs");
    let code = format!(
        "/// Flash address of the firmware region (`memory.x`: FLASH).\n\
         pub const FIRMWARE_ORIGIN: u32 = {firmware_origin:#010x};\n\
         /// Size of the firmware region in bytes (`memory.x`: FLASH).\n\
         pub const FIRMWARE_LEN: usize = {firmware_len};\n\
         /// Flash address of the bank region, where the firmware reads the bank in place \
         (`memory.x`: BANK).\n\
         pub const BANK_ORIGIN: u32 = {bank_origin:#010x};\n\
         /// Size of the bank region in bytes: the largest bank a device holds (`memory.x`: \
         BANK).\n\
         pub const BANK_LEN: usize = {bank_len};\n\
         /// Address of the RAM the images use (`memory.x`: RAM).\n\
         pub const RAM_ORIGIN: u32 = {ram_origin:#010x};\n\
         /// Size of that RAM in bytes (`memory.x`: RAM).\n\
         pub const RAM_LEN: usize = {ram_len};\n"
    );
    std::fs::write(&out, code).unwrap_or_else(|e| panic!("{}: {e}", out.display()));
}
