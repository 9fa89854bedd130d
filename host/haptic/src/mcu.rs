//! The MCU side of the toolchain, in one place: where the repository is, cargo builds of the
//! firmware images (each its own workspace, `firmware/qemu` and `firmware/board`) and of
//! `no_std` crates for the MCU target, rustup's `llvm-objdump`, and what an image's ELF file
//! says about its size and its stack (read with the `object` crate, as `flash` reads the
//! segments it programs). [`law_cost`] counts what evaluating the tissue law costs on the MCU,
//! on the disassembly of `bank-format` built for it.

pub mod law_cost;

use anyhow::{Context, Result, bail};
use object::elf::{FileHeader32, SHF_ALLOC, SHT_NOBITS, SHT_PROGBITS};
use object::read::elf::{FileHeader as _, SectionHeader as _};
use std::ffi::OsString;
use std::path::{Path, PathBuf};
use std::process::Command;

/// The MCU's Rust target (Cortex-M4F).
pub const TARGET: &str = "thumbv7em-none-eabihf";

/// The repository root (two levels above this package, `host/haptic`).
pub fn repo_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .ancestors()
        .nth(2)
        .map_or_else(|| PathBuf::from("."), Path::to_path_buf)
}

/// The cargo to run: the one running this build (`$CARGO`), else `cargo` on the path.
fn cargo() -> OsString {
    std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into())
}

/// The software-in-the-loop image's path once [`build_qemu_image`] has built it.
pub fn qemu_image_path() -> PathBuf {
    repo_root()
        .join("firmware/qemu/target")
        .join(TARGET)
        .join("release/firmware-qemu")
}

/// Build the QEMU image (`cargo build --release` in `firmware/qemu`; a no-op when it is up to
/// date) and return its path. Needs the `thumbv7em-none-eabihf` target.
pub fn build_qemu_image() -> Result<PathBuf> {
    build_image(&repo_root().join("firmware/qemu"), "the QEMU image", "")?;
    Ok(qemu_image_path())
}

/// `cargo build --release --quiet` in `dir` (a firmware image's own workspace, with its own
/// target dir), failing with its stderr; `what` names the image, `hint` follows "failed".
pub fn build_image(dir: &Path, what: &str, hint: &str) -> Result<()> {
    let cargo = cargo();
    let out = Command::new(&cargo)
        .args(["build", "--release", "--quiet"])
        .current_dir(dir)
        .env_remove("CARGO_TARGET_DIR")
        .output()
        .with_context(|| {
            format!(
                "cannot run {} in {}",
                cargo.to_string_lossy(),
                dir.display()
            )
        })?;
    if !out.status.success() {
        bail!(
            "building {what} in {} failed{hint}:\n{}",
            dir.display(),
            String::from_utf8_lossy(&out.stderr)
        );
    }
    Ok(())
}

/// Build the workspace package `package` for [`TARGET`] (release) and return the rlib cargo
/// reports for it (its `compiler-artifact` message): not the newest `lib<crate>-*.rlib` of the
/// target's `deps`, which may be another build's (the firmware images' LTO builds leave
/// bitcode-only rlibs there when they share a target dir).
pub fn build_rlib(package: &str) -> Result<PathBuf> {
    let root = repo_root();
    eprintln!("building {package} for {TARGET} ...");
    let out = Command::new(cargo())
        .args(["build", "--release", "-p", package, "--target", TARGET])
        .args(["--message-format", "json-render-diagnostics"])
        .current_dir(&root)
        .stderr(std::process::Stdio::inherit())
        .output()
        .context("running cargo")?;
    if !out.status.success() {
        bail!("cargo build -p {package} --target {TARGET} failed");
    }
    let name = package.replace('-', "_");
    String::from_utf8_lossy(&out.stdout)
        .lines()
        .filter_map(|l| serde_json::from_str::<serde_json::Value>(l).ok())
        .filter(|m| m["reason"] == "compiler-artifact" && m["target"]["name"] == name.as_str())
        .flat_map(|m| {
            m["filenames"]
                .as_array()
                .into_iter()
                .flatten()
                .filter_map(|f| f.as_str().map(PathBuf::from))
                .collect::<Vec<_>>()
        })
        .find(|f| f.extension().is_some_and(|e| e == "rlib"))
        .with_context(|| format!("cargo reported no rlib for {package}"))
}

/// The `llvm-objdump` that `rustup component add llvm-tools` installs.
pub fn objdump() -> Result<PathBuf> {
    let out = Command::new("rustc")
        .args(["--print", "sysroot"])
        .output()
        .context("running rustc --print sysroot")?;
    let sysroot = PathBuf::from(String::from_utf8_lossy(&out.stdout).trim());
    let rustlib = sysroot.join("lib").join("rustlib");
    let found = std::fs::read_dir(&rustlib)
        .into_iter()
        .flatten()
        .filter_map(|e| e.ok())
        .map(|e| e.path().join("bin").join("llvm-objdump"))
        .find(|p| p.exists());
    found.with_context(|| {
        format!(
            "llvm-objdump not found under {}: install it with `rustup component add llvm-tools`, or pass --objdump",
            rustlib.display()
        )
    })
}

/// Flash bytes (allocated sections with contents: `.vector_table`, `.text`, `.rodata`, `.data`'s
/// load image) and allocated RAM (`.data`, `.bss`, `.uninit`; the stack takes the rest) of an
/// ELF32 image.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub struct ImageSize {
    /// Flash bytes.
    pub flash: u64,
    /// Static RAM bytes.
    pub ram: u64,
}

/// One allocated or loaded section of an ELF32 file: type, flags, address, file offset, size.
struct Section {
    kind: u32,
    flags: u32,
    addr: u32,
    offset: u32,
    len: u32,
}

/// The bytes of the little-endian ELF32 file at `path` and its section headers.
fn elf_sections(path: &Path) -> Result<(Vec<u8>, Vec<Section>)> {
    let b = std::fs::read(path).with_context(|| format!("cannot read {}", path.display()))?;
    let header = FileHeader32::<object::Endianness>::parse(&*b)
        .map_err(|e| anyhow::anyhow!("{}: not an ELF32 file ({e})", path.display()))?;
    let endian = header
        .endian()
        .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
    if endian != object::Endianness::Little {
        bail!("{}: not a little-endian ELF32 file", path.display());
    }
    let sections = header
        .section_headers(endian, &*b)
        .map_err(|e| anyhow::anyhow!("{}: bad ELF section table ({e})", path.display()))?
        .iter()
        .map(|s| Section {
            kind: s.sh_type(endian),
            flags: s.sh_flags(endian),
            addr: s.sh_addr(endian),
            offset: s.sh_offset(endian),
            len: s.sh_size(endian),
        })
        .collect();
    Ok((b, sections))
}

/// Read [`ImageSize`] from the section headers of the little-endian ELF32 file at `path`;
/// `ram_start..ram_start + ram_len` is the RAM region (allocated sections there count as RAM).
pub fn image_size(path: &Path, ram_start: u32, ram_len: u32) -> Result<ImageSize> {
    let mut size = ImageSize { flash: 0, ram: 0 };
    for s in elf_sections(path)?.1 {
        if s.flags & SHF_ALLOC == 0 {
            continue;
        }
        if s.kind != SHT_NOBITS {
            size.flash += u64::from(s.len);
        }
        if s.addr >= ram_start && u64::from(s.addr) < u64::from(ram_start) + u64::from(ram_len) {
            size.ram += u64::from(s.len);
        }
    }
    Ok(size)
}

/// The initial stack pointer of the ELF32 image at `path`: the first word of the vector
/// table, the loaded section that starts at `flash_origin` (where the core reads it at reset).
pub fn initial_stack_pointer(path: &Path, flash_origin: u32) -> Result<u32> {
    let (b, sections) = elf_sections(path)?;
    let table = sections
        .iter()
        .find(|s| s.kind == SHT_PROGBITS && s.addr == flash_origin)
        .with_context(|| {
            format!(
                "{}: no section at the flash origin {flash_origin:#010x} (no vector table)",
                path.display()
            )
        })?;
    let o = table.offset as usize;
    b.get(o..o + 4)
        .map(|s| u32::from_le_bytes([s[0], s[1], s[2], s[3]]))
        .with_context(|| {
            format!(
                "{}: the vector table is past the file's end",
                path.display()
            )
        })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn image_size_rejects_a_non_elf_file() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("x");
        std::fs::write(&p, b"not an elf").unwrap();
        let e = image_size(&p, 0x2000_0000, 1024).unwrap_err().to_string();
        assert!(e.contains("not an ELF32 file"), "{e}");
    }
}
