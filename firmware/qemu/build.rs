//! Puts the repository's top-level `memory.x` (firmware and bank regions of the STM32F405
//! flash) on the linker search path for cortex-m-rt's `link.x`.
fn main() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    println!("cargo:rustc-link-search={}", root.display());
    println!("cargo:rerun-if-changed={}", root.join("memory.x").display());
}
