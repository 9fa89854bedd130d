//! Small 3-vector helpers on `[f32; 3]` shared by the loop's modules (f32; a correctly rounded
//! square root, so the MCU image and a native build compute bit for bit alike).

/// `sqrt(x)`, correctly rounded (IEEE 754) on every target, so the MCU and a native build agree
/// bit for bit: the Cortex-M4F's `VSQRT.F32` on the MCU (three instructions with the call;
/// libm's software `sqrtf` took 53, `docs/firmware-loop.md`, "The card's crates"),
/// `libm::sqrtf` elsewhere.
#[cfg(all(target_arch = "arm", target_abi = "eabihf"))]
pub(crate) fn sqrt(x: f32) -> f32 {
    // SAFETY: `firmware_vsqrt_f32` (below) reads s0 and writes s0, as the hard-float AAPCS
    // passes and returns an f32; it touches no memory.
    unsafe { firmware_vsqrt_f32(x) }
}

#[cfg(all(target_arch = "arm", target_abi = "eabihf"))]
unsafe extern "C" {
    fn firmware_vsqrt_f32(x: f32) -> f32;
}

// A leaf function: the inline `asm!` register class for s-registers needs a target feature
// Rust does not name on this target, and the assembler must be told the M4F's FPU.
#[cfg(all(target_arch = "arm", target_abi = "eabihf"))]
core::arch::global_asm!(
    ".section .text.firmware_vsqrt_f32,\"ax\",%progbits",
    ".global firmware_vsqrt_f32",
    ".type firmware_vsqrt_f32,%function",
    ".fpu fpv4-sp-d16",
    ".thumb_func",
    "firmware_vsqrt_f32:",
    "vsqrt.f32 s0, s0",
    "bx lr",
    ".size firmware_vsqrt_f32, . - firmware_vsqrt_f32",
);

/// `sqrt(x)`, correctly rounded (`libm::sqrtf`; the MCU uses `VSQRT.F32`, the same result).
#[cfg(not(all(target_arch = "arm", target_abi = "eabihf")))]
pub(crate) fn sqrt(x: f32) -> f32 {
    libm::sqrtf(x)
}

/// `a - b`.
pub(crate) fn sub(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

/// `a + b`.
pub(crate) fn add(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

/// `s a`.
pub(crate) fn scale(a: [f32; 3], s: f32) -> [f32; 3] {
    [a[0] * s, a[1] * s, a[2] * s]
}

/// `a . b`.
pub(crate) fn dot(a: [f32; 3], b: [f32; 3]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// `a x b`.
pub(crate) fn cross(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// `|a - b|^2`.
pub(crate) fn dist2(a: [f32; 3], b: [f32; 3]) -> f32 {
    let d = sub(a, b);
    dot(d, d)
}

/// `a / |a|`, `None` for a zero or non-finite vector.
pub(crate) fn unit(a: [f32; 3]) -> Option<[f32; 3]> {
    let n = sqrt(dot(a, a));
    (n > 0.0 && n.is_finite()).then(|| a.map(|x| x / n))
}
