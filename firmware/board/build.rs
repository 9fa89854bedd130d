//! Links the image with cortex-m-rt's `link.x`, which includes the repository's top-level
//! `memory.x` (firmware and bank regions of the STM32F405 flash): its directory goes on the
//! linker search path; then this crate's `stack.x` (the stack in CCM). Set here rather than in
//! rustflags so that a `RUSTFLAGS` in the environment cannot drop them.
fn main() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    println!("cargo:rustc-link-search={}", root.display());
    println!("cargo:rustc-link-arg-bins=-Tlink.x");
    println!("cargo:rerun-if-changed={}", root.join("memory.x").display());
    // The stack in CCM (see stack.x), from this crate's directory.
    let here = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    println!("cargo:rustc-link-search={}", here.display());
    println!("cargo:rustc-link-arg-bins=-Tstack.x");
    println!("cargo:rerun-if-changed={}", here.join("stack.x").display());
}
