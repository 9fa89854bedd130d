//! Instructions and error of the maths on the tick's path, on the MCU under QEMU: for each call
//! site's operation, the implementation in use and its alternatives (`docs/firmware-loop.md`,
//! "The card's crates"). Not part of the image; run by hand:
//!
//! ```sh
//! cd firmware/qemu && cargo build --release --bin mathbench
//! qemu-system-arm -M netduinoplus2 -nographic -monitor none -icount shift=3,sleep=off \
//!   -semihosting-config enable=on,target=native \
//!   -kernel target/thumbv7em-none-eabihf/release/mathbench
//! ```
//!
//! Prints one JSON object per (operation, implementation): instructions per call (mean and
//! max over the inputs, the measurement's own overhead subtracted) and the largest error
//! against an f64 reference computed here (libm's f64 functions, f64 elimination). Counts come
//! from SysTick, which under `-icount shift=3` advances 1.344 counts per instruction (168 counts
//! = 125 instructions), read before and after each call.
#![no_std]
#![no_main]

use core::hint::black_box;
use cortex_m::peripheral::SYST;
use cortex_m::peripheral::syst::SystClkSource;
use firmware::cholesky::Cholesky as HandCholesky;
use micromath::F32Ext;
use nalgebra::{Cholesky, SMatrix, SVector};

/// SysTick counts elapsed while running `f(a)`, as instructions (the counter counts down and
/// wraps at 2^24). `f` is called through an opaque function pointer, so the compiler can
/// neither inline it nor move its work across the counter reads.
fn instructions<A, R>(f: fn(A) -> R, a: A) -> (R, u32) {
    let f = black_box(f);
    let a = black_box(a);
    let start = SYST::get_current();
    let r = f(a);
    let end = SYST::get_current();
    let counts = start.wrapping_sub(end) & 0x00ff_ffff;
    (black_box(r), counts * 125 / 168)
}

fn identity(x: f32) -> f32 {
    x
}
fn libm_sqrt(x: f32) -> f32 {
    libm::sqrtf(x)
}
fn micromath_sqrt(x: f32) -> f32 {
    F32Ext::sqrt(x)
}
fn firmware_sqrt(x: f32) -> f32 {
    // What the firmware's `vec3::sqrt` and the solve call today: nalgebra's ComplexField.
    nalgebra::ComplexField::sqrt(x)
}
fn libm_sincos(t: f32) -> (f32, f32) {
    libm::sincosf(t)
}
fn micromath_sincos(t: f32) -> (f32, f32) {
    F32Ext::sin_cos(t)
}
fn hand_sincos(t: f32) -> (f32, f32) {
    firmware::device::sin_cos(t)
}
fn libm_round(x: f32) -> f32 {
    libm::roundf(x)
}
fn micromath_round(x: f32) -> f32 {
    F32Ext::round(x)
}
fn nalgebra_factor(m: [[f32; 3]; 3]) -> Option<Cholesky<f32, nalgebra::U3>> {
    Cholesky::new(SMatrix::<f32, 3, 3>::from(m))
}
fn hand_factor(m: [[f32; 3]; 3]) -> Option<HandCholesky<3>> {
    HandCholesky::new(&m)
}
fn nalgebra_solve((c, d): (Cholesky<f32, nalgebra::U3>, [f32; 3])) -> [f32; 3] {
    let x = c.solve(&SVector::<f32, 3>::from(d));
    [x.x, x.y, x.z]
}
fn hand_solve((c, d): (HandCholesky<3>, [f32; 3])) -> [f32; 3] {
    c.solve(&d)
}

struct Stats {
    calls: u32,
    sum: u32,
    max: u32,
    err: f64,
}

impl Stats {
    const fn new() -> Stats {
        Stats {
            calls: 0,
            sum: 0,
            max: 0,
            err: 0.0,
        }
    }
    fn add(&mut self, n: u32, overhead: u32, err: f64) {
        let n = n.saturating_sub(overhead);
        self.calls += 1;
        self.sum += n;
        self.max = self.max.max(n);
        // A NaN error is the worst.
        if err.is_nan() || err > self.err {
            self.err = err;
        }
    }
    /// One JSON line; `error` names the error field (`None`: no error is measured here, e.g.
    /// a factorisation, whose error shows in the solve with it).
    fn print(&self, op: &str, imp: &str, error: Option<&str>) {
        semihosting::print!(
            "{{\"operation\": \"{op}\", \"implementation\": \"{imp}\", \"calls\": {}, \
             \"mean_instructions\": {:.1}, \"max_instructions\": {}",
            self.calls,
            f64::from(self.sum) / f64::from(self.calls.max(1)),
            self.max,
        );
        match error {
            Some(name) => semihosting::println!(", \"{name}\": {:.3e}}}", self.err),
            None => semihosting::println!("}}"),
        }
    }
}

/// A pseudo-random SPD 3 x 3 matrix `M M^T + 0.1 I`, scaled like a compliance (m/N).
fn spd(seed: u64) -> [[f32; 3]; 3] {
    let mut s = seed;
    let mut next = move || {
        s = s
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        (s >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    };
    let m: [[f64; 3]; 3] = core::array::from_fn(|_| core::array::from_fn(|_| next()));
    core::array::from_fn(|i| {
        core::array::from_fn(|j| {
            let mut v: f64 = (0..3).map(|k| m[i][k] * m[j][k]).sum();
            if i == j {
                v += 0.1;
            }
            (1e-3 * v) as f32
        })
    })
}

/// `a^-1 b` in f64 by Cramer's rule (the reference).
fn solve_f64(a: &[[f32; 3]; 3], b: &[f32; 3]) -> [f64; 3] {
    let a: [[f64; 3]; 3] = a.map(|r| r.map(f64::from));
    let det = |m: &[[f64; 3]; 3]| {
        m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
            - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
    };
    let d = det(&a);
    core::array::from_fn(|c| {
        let mut m = a;
        for r in 0..3 {
            m[r][c] = f64::from(b[r]);
        }
        det(&m) / d
    })
}

fn rel_err(x: [f32; 3], want: [f64; 3]) -> f64 {
    let n = libm::sqrt(want.iter().map(|v| v * v).sum());
    let e = libm::sqrt(
        x.iter()
            .zip(&want)
            .map(|(&g, w)| (f64::from(g) - w) * (f64::from(g) - w))
            .sum(),
    );
    e / n
}

#[cortex_m_rt::entry]
fn main() -> ! {
    let Some(mut p) = cortex_m::Peripherals::take() else {
        semihosting::process::exit(1)
    };
    p.SYST.set_clock_source(SystClkSource::Core);
    p.SYST.set_reload(0x00ff_ffff);
    p.SYST.clear_current();
    p.SYST.enable_counter();
    let mut empty = Stats::new();
    for i in 0..64 {
        let (_, n) = instructions(identity, i as f32);
        empty.add(n, 0, 0.0);
    }
    let overhead = empty.sum / empty.calls;
    semihosting::println!("{{\"measurement_overhead_instructions\": {overhead}}}");

    // sqrt: vector norms (contact, patch, the force cap, the law's direction), 1e-8..1e2.
    let (mut a, mut b, mut c) = (Stats::new(), Stats::new(), Stats::new());
    for i in 0..64 {
        // Inputs and references go through black_box before any measurement, so their (soft
        // f64) work cannot be scheduled between the counter reads.
        let x = black_box(libm::powf(10.0, -8.0 + 10.0 * i as f32 / 63.0));
        let want = black_box(libm::sqrt(f64::from(x)));
        let (r, n) = instructions(libm_sqrt, x);
        a.add(n, overhead, (f64::from(r) - want).abs() / want);
        let (r, n) = instructions(micromath_sqrt, x);
        b.add(n, overhead, (f64::from(r) - want).abs() / want);
        let (r, n) = instructions(firmware_sqrt, x);
        c.add(n, overhead, (f64::from(r) - want).abs() / want);
    }
    a.print("sqrt", "libm::sqrtf", Some("max_rel_error"));
    b.print("sqrt", "micromath sqrt", Some("max_rel_error"));
    c.print("sqrt", "nalgebra ComplexField::sqrt", Some("max_rel_error"));

    // sin and cos of pitch and yaw (the kinematics), over the joint range +-0.35 rad.
    let (mut a, mut b, mut c) = (Stats::new(), Stats::new(), Stats::new());
    for i in 0..64 {
        let t = black_box(-0.35 + 0.7 * i as f32 / 63.0);
        let (ws, wc) = black_box((libm::sin(f64::from(t)), libm::cos(f64::from(t))));
        let err = |(s, c): (f32, f32)| (f64::from(s) - ws).abs().max((f64::from(c) - wc).abs());
        let (r, n) = instructions(libm_sincos, t);
        a.add(n, overhead, err(r));
        let (r, n) = instructions(micromath_sincos, t);
        b.add(n, overhead, err(r));
        let (r, n) = instructions(hand_sincos, t);
        c.add(n, overhead, err(r));
    }
    a.print("sin_cos", "libm::sincosf", Some("max_abs_error"));
    b.print("sin_cos", "micromath sin_cos", Some("max_abs_error"));
    c.print(
        "sin_cos",
        "hand-written f32 (firmware::device::sin_cos)",
        Some("max_abs_error"),
    );

    // round: PWM compare values (the board's amplifier), 0..8400 counts.
    let (mut a, mut b) = (Stats::new(), Stats::new());
    for i in 0..64 {
        let x = black_box(8400.0 * i as f32 / 63.0 + 0.37);
        let want = black_box(libm::round(f64::from(x)));
        let (r, n) = instructions(libm_round, x);
        a.add(n, overhead, (f64::from(r) - want).abs());
        let (r, n) = instructions(micromath_round, x);
        b.add(n, overhead, (f64::from(r) - want).abs());
    }
    a.print("round", "libm::roundf", Some("max_abs_error"));
    b.print("round", "micromath round", Some("max_abs_error"));

    // The 3 x 3 Cholesky of B C_SS B^T: factor (patch rebuilds) and solve (every contact tick).
    let (mut fa, mut fb, mut sa, mut sb) = (Stats::new(), Stats::new(), Stats::new(), Stats::new());
    for seed in 1..33u64 {
        let m = black_box(spd(seed));
        let d = black_box([1e-3, -2e-3, 0.5e-3]);
        let want = black_box(solve_f64(&m, &d));
        // (Symmetric: nalgebra's column-major reading of the rows is the same matrix.)
        let (hb, n) = instructions(hand_factor, m);
        fb.add(n, overhead, 0.0);
        let (na, n) = instructions(nalgebra_factor, m);
        fa.add(n, overhead, 0.0);
        let (Some(na), Some(hb)) = (na, hb) else {
            semihosting::process::exit(2)
        };
        let (x, n) = instructions(nalgebra_solve, (na, d));
        sa.add(n, overhead, rel_err(x, want));
        let (x, n) = instructions(hand_solve, (hb, d));
        sb.add(n, overhead, rel_err(x, want));
    }
    fa.print("cholesky3_factor", "nalgebra Cholesky", None);
    fb.print(
        "cholesky3_factor",
        "hand-written (firmware::cholesky)",
        None,
    );
    sa.print(
        "cholesky3_solve",
        "nalgebra Cholesky",
        Some("max_rel_error"),
    );
    sb.print(
        "cholesky3_solve",
        "hand-written (firmware::cholesky)",
        Some("max_rel_error"),
    );
    semihosting::process::exit(0)
}

#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    semihosting::eprintln!("mathbench: panic: {info}");
    semihosting::process::exit(101)
}
