//! Fung's quasi-linear viscoelasticity (QLV) in the tick: the force the loop renders relaxes
//! while the tool holds still (bank format 7.0, `SPEC.md` "viscoelastic relaxation").
//!
//! **Model.** With the reduced relaxation function `G(t) = g_inf + sum_k g_k exp(-t / tau_k)`,
//! `G(0) = 1`, and the elastic response `Q_e(t)` (the force on the tissue the loop renders
//! without relaxation: the tissue law Q of the linear model's force, a 3-vector), the rendered
//! force is the hereditary integral
//!
//! ```text
//! F(t) = integral G(t - s) dQ_e(s) = g_inf Q_e(t) + sum_k h_k(t),
//! h_k(t) = g_k integral_{-inf}^{t} exp(-(t - s) / tau_k) dQ_e(s)            (1)
//! ```
//!
//! per axis of the force (Fung, *Biomechanics*, 2nd ed., 1993, ch. 7).
//!
//! **Discretisation.** Between ticks `n - 1` and `n` (period `dt`) take `Q_e` linear (the
//! loop only knows it at the ticks). Then (1) integrates in closed form:
//!
//! ```text
//! h_k(n) = a_k h_k(n-1) + b_k (Q_e(n) - Q_e(n-1)),
//! a_k = exp(-dt / tau_k),   b_k = g_k (1 - a_k) / (dt / tau_k)                 (2)
//! ```
//!
//! exact for a piecewise-linear `Q_e` (the recursive form of the convolution used for Prony
//! series in finite-element codes, e.g. Taylor, Pister & Goudreau, Int. J. Numer. Meth. Eng.
//! 2, 1970). So the only error against the continuous convolution of the true `Q_e` is the
//! error of its linear interpolation, `e(t) <= dt^2 / 8 max |Q_e''|`, which (1) carries into
//! `h_k` at most as `2 g_k max |e|` (integrate (1) by parts): second order in `dt`, where a
//! step (zero-order hold) input would be first order. `a_k` and `b_k` are computed once, when
//! the loop is built, in f64 (`libm::expm1`, `1 - a_k` without cancellation) and rounded to
//! f32; the tick applies (2) as `h -= c_k h; h += b_k dQ` with `c_k = 1 - a_k`, so a slow term's
//! decay per tick is not lost in the rounding of `a_k` to 1. Rounding: the decrement `c_k h` is
//! rounded to an ulp of `h` (`2^-24 |h|`), a relative error of `2^-24 tau / dt` in the decay
//! rate: 6e-4 at `tau` = 10 s, 0.2 at an hour, the bank's limit (whence the limit). Constant
//! cost: every tick, touching or not, updates every term (two multiplies and three adds a
//! term and axis, the sum of the `h_k` taken in the same pass), no exponential in the tick.
//!
//! **Contact.** The tissue's memory is the state `h_k`; it is not the tool's. When the contact
//! ends (or the tick renders no force: a free tool, the detecting tick, a solve error, a mode
//! other than `Render`) the elastic response is zero, and the update (2) runs with `Q_e(n) =
//! 0`: the elastic force falls to zero over that tick, the `h_k` carry what is left of the
//! history (after a hold, negative: the surface is still below its rest shape and creeping
//! back) and decay with `tau_k`. No force is rendered without contact. When the tool presses
//! again before the tissue has recovered, the negative residue lowers the force: the tissue is
//! softer for a while, as a relaxed one is. The memory is the pressed site's, but the state has
//! no site: a tool that has rendered no contact force for longer than the shortest time
//! constant may come down anywhere, so the memory is then reset (the old site taken as
//! recovered), never carried to another site; within that time a press meets the residue, at the
//! old site or near it. The contact is unilateral: a total force pointing
//! against the elastic force (the tissue pulling the tool in) is never rendered, its component
//! along `Q_e` is removed (continuous: unchanged where that component is zero), and nothing is
//! rendered while `Q_e = 0`.
//!
//! **Stability and passivity.** (a) The recursion is stable: `0 < a_k < 1`, so a bounded input
//! gives bounded state and, with `Q_e` fixed, `h_k` decays to zero; the rendered force tends to
//! `g_inf Q_e`. Integrating (1) by parts, `|h_k| <= 2 g_k max|Q_e|`, so `|F| < 2 max |Q_e|`,
//! and the device's force cap applies after it as to the elastic force. (b) The loop never sees
//! a stiffer law than the elastic one, which it already renders stably: the force's change
//! with this tick's `Q_e` is `dF(n) / dQ_e(n) = g_inf + sum_k b_k <= g_inf + sum_k g_k = 1`
//! (since `(1 - a) / x <= 1` for `x = dt / tau`), so the rendered stiffness is at most the
//! elastic law's, and the sampled-data passivity condition of Colgate & Schenkel (IEEE TRO
//! 1997: device damping `b > K T / 2 + |B|`), a bound on the stiffness `K` rendered, holds
//! whenever it held without relaxation. (c) Relaxation only removes energy: for a linear
//! elastic response `Q_e = K x` (per axis), (1) is the generalised Maxwell model, a spring
//! `g_inf K` in parallel with Maxwell arms of spring `g_k K` and dashpot `g_k K tau_k`. With
//! `E = g_inf K x^2 / 2 + sum_k h_k^2 / (2 g_k K)`, `dE/dt = F x' - sum_k h_k^2 / (g_k K tau_k)
//! <= F x'`: the tissue stores at most the work the tool does on it, the rest is dissipated.
//! The update (2) is the exact response to the interpolated input, so it inherits the
//! inequality for that input. For a nonlinear monotone Q this energy argument does not carry
//! over as such; (a) and (b) do.

use bank_format::{MAX_PRONY_TERMS, Relaxation};

use crate::solve::SolveError;

/// The relaxation state of the loop and its per-tick coefficients (module notes, (2)).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Qlv {
    g_inf: f32,
    /// Terms in use (1..=[`MAX_PRONY_TERMS`]); the arrays hold zeros past it.
    terms: usize,
    /// `c_k = 1 - exp(-dt / tau_k)`.
    decay: [f32; MAX_PRONY_TERMS],
    /// `b_k = g_k (1 - exp(-dt / tau_k)) / (dt / tau_k)`.
    gain: [f32; MAX_PRONY_TERMS],
    /// `h_k`, N, per axis.
    h: [[f32; 3]; MAX_PRONY_TERMS],
    /// `Q_e` of the previous tick, N (zero when it rendered no contact).
    q_prev: [f32; 3],
    /// This tick has pressed ([`Qlv::press`]); cleared by [`Qlv::end_tick`].
    pressed: bool,
    /// Ticks since the last press.
    free_ticks: u32,
    /// The shortest time constant, in ticks (rounded up): after this many free ticks the
    /// memory is reset (module notes, "Contact").
    forget_after: u32,
}

impl Qlv {
    /// The relaxed state (no history) for the bank's law at tick period `dt_s` (s, > 0): the
    /// coefficients of (2), in f64 then rounded to f32.
    pub fn new(law: &Relaxation, dt_s: f32) -> Qlv {
        let mut decay = [0.0; MAX_PRONY_TERMS];
        let mut gain = [0.0; MAX_PRONY_TERMS];
        let mut terms = 0;
        let mut tau_min = f64::INFINITY;
        for ((g, tau), (c, b)) in law.terms().zip(decay.iter_mut().zip(gain.iter_mut())) {
            let x = f64::from(dt_s) / f64::from(tau);
            let one_minus_a = -libm::expm1(-x);
            *c = one_minus_a as f32;
            *b = (f64::from(g) * one_minus_a / x) as f32;
            tau_min = tau_min.min(f64::from(tau));
            terms += 1;
        }
        // `as` saturates (an infinite or NaN ratio gives u32::MAX or 0), never panics.
        let forget_after = libm::ceil(tau_min / f64::from(dt_s)) as u32;
        Qlv {
            g_inf: law.g_inf(),
            terms,
            decay,
            gain,
            h: [[0.0; 3]; MAX_PRONY_TERMS],
            q_prev: [0.0; 3],
            pressed: false,
            free_ticks: 0,
            forget_after,
        }
    }

    /// One tick in contact with elastic response `q_e` (N, on the tissue, finite): the state
    /// updated by (2), and the force to render, `g_inf Q_e + sum_k h_k`, with a component
    /// against `Q_e` removed and nothing for `Q_e = 0` (module notes, "Contact"). A non-finite
    /// force is an error (the tick faults, as for the elastic force) and resets the state, so
    /// one bad tick does not poison every later one.
    pub fn press(&mut self, q_e: [f32; 3]) -> Result<[f32; 3], SolveError> {
        self.pressed = true;
        self.free_ticks = 0;
        let h = self.update(q_e);
        let f = [
            self.g_inf * q_e[0] + h[0],
            self.g_inf * q_e[1] + h[1],
            self.g_inf * q_e[2] + h[2],
        ];
        // `f . Q_e` is not finite when a component of `f` is not (an infinite one times a zero
        // component of `Q_e` is NaN), so one test covers the three (it also refuses a product
        // that overflows, at forces far beyond any device's cap).
        let along = dot(f, q_e);
        if !along.is_finite() {
            self.reset();
            return Err(SolveError::NonFinite);
        }
        if along > 0.0 {
            return Ok(f);
        }
        // The rare case: the total would pull the tool in (or there is no elastic force).
        let qq = dot(q_e, q_e);
        if qq <= 0.0 {
            return Ok([0.0; 3]);
        }
        let s = along / qq;
        let out = [f[0] - s * q_e[0], f[1] - s * q_e[1], f[2] - s * q_e[2]];
        if out.iter().all(|v| v.is_finite()) {
            Ok(out)
        } else {
            self.reset();
            Err(SolveError::NonFinite)
        }
    }

    /// One tick without a contact force (free, or nothing rendered): (2) with `Q_e = 0`; the
    /// memory decays, and is reset once the tool has been free for longer than the shortest
    /// time constant (module notes, "Contact"). Not checked here: with a zero input the state
    /// cannot grow past what the last pressed (finite) `Q_e` gave it, and a press checks the
    /// whole sum before rendering.
    pub fn release(&mut self) {
        self.update([0.0; 3]);
        self.free_ticks = self.free_ticks.saturating_add(1);
        if self.free_ticks == self.forget_after.saturating_add(1) {
            self.reset();
        }
    }

    /// The end of a tick: one that did not [`Qlv::press`] (no contact force rendered: free,
    /// the detecting tick, an error, another mode) is a [`Qlv::release`]. Called once a tick,
    /// so every tick updates the state exactly once.
    pub fn end_tick(&mut self) {
        if !self.pressed {
            self.release();
        }
        self.pressed = false;
    }

    /// Back to the relaxed tissue (no history).
    pub fn reset(&mut self) {
        self.h = [[0.0; 3]; MAX_PRONY_TERMS];
        self.q_prev = [0.0; 3];
    }

    /// `g_inf`, the share of the elastic force left after full relaxation.
    pub fn g_inf(&self) -> f32 {
        self.g_inf
    }

    /// The update (2) of every term with this tick's `Q_e`; returns `sum_k h_k` (one pass over
    /// the state).
    fn update(&mut self, q_e: [f32; 3]) -> [f32; 3] {
        let dq = [
            q_e[0] - self.q_prev[0],
            q_e[1] - self.q_prev[1],
            q_e[2] - self.q_prev[2],
        ];
        self.q_prev = q_e;
        let mut sum = [0.0f32; 3];
        for ((h, c), b) in self
            .h
            .iter_mut()
            .zip(&self.decay)
            .zip(&self.gain)
            .take(self.terms)
        {
            for ((hi, d), si) in h.iter_mut().zip(dq).zip(sum.iter_mut()) {
                *hi -= c * *hi;
                *hi += b * d;
                *si += *hi;
            }
        }
        sum
    }
}

fn dot(a: [f32; 3], b: [f32; 3]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::indexing_slicing)]
mod tests {
    extern crate std;
    use super::*;
    use std::vec::Vec;

    const DT: f64 = 1.0e-3;

    fn law(g: &[f32], tau: &[f32]) -> Relaxation {
        let mut r = Relaxation {
            count: g.len() as u32,
            reserved: 0,
            g: [0.0; 4],
            tau_s: [0.0; 4],
        };
        r.g[..g.len()].copy_from_slice(g);
        r.tau_s[..tau.len()].copy_from_slice(tau);
        r
    }

    /// The QLV response (1) in f64 to the ramp-and-hold `Q_e(t) = r min(t, t_r)`, in closed
    /// form: during the ramp `h_k = g_k r tau_k (1 - e^{-t / tau_k})`, in the hold
    /// `h_k = g_k r tau_k (1 - e^{-t_r / tau_k}) e^{-(t - t_r) / tau_k}`.
    fn ramp_hold(g: &[f64], tau: &[f64], r: f64, t_r: f64, t: f64) -> f64 {
        let g_inf = 1.0 - g.iter().sum::<f64>();
        let q = r * t.min(t_r);
        let h: f64 = g
            .iter()
            .zip(tau)
            .map(|(&g, &tau)| {
                if t <= t_r {
                    g * r * tau * (1.0 - (-t / tau).exp())
                } else {
                    g * r * tau * (1.0 - (-t_r / tau).exp()) * (-(t - t_r) / tau).exp()
                }
            })
            .sum();
        g_inf * q + h
    }

    /// The recursion against the closed form, for a ramp of 0.2 s to 2 N along a slanted axis
    /// and a 10 s hold, with four terms spanning 5 ms to 20 s: within 2e-5 of the peak at every
    /// tick (f32), on every axis.
    #[test]
    fn a_ramp_and_hold_matches_the_closed_form() {
        let g = [0.3f32, 0.2, 0.15, 0.1];
        let tau = [0.005f32, 0.08, 1.5, 20.0];
        let mut qlv = Qlv::new(&law(&g, &tau), DT as f32);
        let (g64, tau64) = (g.map(f64::from), tau.map(f64::from));
        let axis = [0.6f64, 0.0, 0.8];
        let (t_r, peak) = (0.2, 2.0);
        let r = peak / t_r;
        let mut worst = 0.0f64;
        let mut at_end = 0.0;
        for n in 1..=10_200 {
            let t = n as f64 * DT;
            let q = r * t.min(t_r);
            let f = qlv.press(axis.map(|a| (a * q) as f32)).unwrap();
            let want = ramp_hold(&g64, &tau64, r, t_r, t);
            for i in 0..3 {
                worst = worst.max((f64::from(f[i]) - axis[i] * want).abs() / peak);
            }
            at_end = f64::from(f[2]) / axis[2];
        }
        assert!(worst < 2e-5, "worst {worst:e} of the peak");
        // And it relaxes as it should: at 10 s into the hold the terms up to 80 ms are gone,
        // the 1.5 s one nearly, the 20 s one about 60 % left: g_inf and that one.
        let expect = peak * (0.25 + 0.1 * 20.0 / 0.2 * (1.0 - (-0.01f64).exp()) * (-0.5f64).exp());
        assert!((at_end - expect).abs() < 1e-3, "{at_end} vs {expect}");
    }

    /// A smooth input (`w t - sin w t`, increasing, so the force never turns against it), where
    /// (2) is not exact: the error against the continuous
    /// convolution (numerical quadrature of (1) in f64 on a 100x finer grid) is second order
    /// in dt, within the interpolation bound `2 sum g_k dt^2 / 8 max |Q''|` plus rounding.
    #[test]
    fn a_smooth_input_is_within_the_interpolation_bound() {
        let (g, tau) = ([0.4f32, 0.3], [0.01f32, 0.5]);
        let mut qlv = Qlv::new(&law(&g, &tau), DT as f32);
        let w = 2.0 * core::f64::consts::PI * 5.0;
        let q = |t: f64| w * t - (w * t).sin();
        // Continuous h_k by the exact recursion on the fine grid (its interpolation error is
        // 1e4 times smaller).
        let fine = 100;
        let dtf = DT / fine as f64;
        let mut h = [0.0f64; 2];
        let mut worst = 0.0f64;
        for n in 1..=1000 {
            for m in 1..=fine {
                let t1 = (n - 1) as f64 * DT + m as f64 * dtf;
                let dq = q(t1) - q(t1 - dtf);
                for k in 0..2 {
                    let x = dtf / f64::from(tau[k]);
                    h[k] = (-x).exp() * h[k] + f64::from(g[k]) * (1.0 - (-x).exp()) / x * dq;
                }
            }
            let t = n as f64 * DT;
            let want = 0.3 * q(t) + h[0] + h[1];
            let f = qlv.press([0.0, 0.0, q(t) as f32]).unwrap();
            worst = worst.max((f64::from(f[2]) - want).abs());
        }
        let bound = 2.0 * 0.7 * DT * DT / 8.0 * w * w;
        assert!(worst < bound + 1e-4, "{worst:e} vs {bound:e}");
        assert!(worst > 0.0);
    }

    /// Release after a hold: no force without contact, the memory decays (negative after a
    /// hold: the tissue softer for a while), and long after a press is the relaxed tissue's
    /// again.
    #[test]
    fn release_decays_the_memory_and_renders_nothing() {
        let r = law(&[0.5], &[0.1]);
        let mut qlv = Qlv::new(&r, DT as f32);
        for n in 1..=100 {
            qlv.press([0.0, 0.0, 0.01 * n as f32]).unwrap();
        }
        for _ in 0..1000 {
            qlv.press([0.0, 0.0, 1.0]).unwrap();
        }
        qlv.release();
        let h0 = qlv.h[0][2];
        // After the hold (h ~ 0.5 e^{-10} ~ 0) the drop of Q_e leaves about -0.5 N.
        assert!((f64::from(h0) + 0.5 * 0.1 / 1e-3 * (1.0 - (-0.01f64).exp())).abs() < 1e-3);
        for _ in 0..99 {
            qlv.release();
        }
        // One tau after the end of contact (99 ticks after h0; the reset would come a tick
        // later): e^{-0.99} of it left.
        assert!((qlv.h[0][2] / h0 - (-0.99f32).exp()).abs() < 1e-4);
        // A light press soon after: the residue would pull; rendered is zero along Q_e.
        let f = qlv.press([0.0, 0.0, 0.05]).unwrap();
        assert!(f.iter().all(|v| v.abs() < 1e-7), "{f:?}");
        // Nothing is rendered for a zero elastic force.
        assert_eq!(qlv.press([0.0; 3]).unwrap(), [0.0; 3]);
        // Long after: relaxed; a press renders G(0) = 1 times the step less the first tick's
        // relaxation, as a fresh tissue.
        for _ in 0..20_000 {
            qlv.release();
        }
        let mut fresh = Qlv::new(&r, DT as f32);
        let a = qlv.press([0.0, 0.0, 1.0]).unwrap();
        let b = fresh.press([0.0, 0.0, 1.0]).unwrap();
        assert!((a[2] - b[2]).abs() < 1e-6, "{a:?} vs {b:?}");
    }

    /// The memory is not carried to another site: free for the shortest time constant (5 ms,
    /// 5 ticks, of two terms) it is still there, one tick longer it is gone, and a press then
    /// is a fresh tissue's, bit for bit, though the long term (10 s) had barely decayed.
    #[test]
    fn the_memory_is_forgotten_after_the_shortest_time_constant_free() {
        let r = law(&[0.3, 0.4], &[10.0, 0.005]);
        let mut qlv = Qlv::new(&r, DT as f32);
        assert_eq!(qlv.forget_after, 5);
        for n in 1..=300 {
            qlv.press([0.0, 0.01 * n.min(100) as f32, 0.0]).unwrap();
            qlv.end_tick();
        }
        for _ in 0..5 {
            qlv.end_tick();
        }
        assert!(qlv.h[0][1].abs() > 1e-4, "{:?}", qlv.h);
        qlv.end_tick();
        assert_eq!(qlv.h, [[0.0; 3]; MAX_PRONY_TERMS]);
        let mut fresh = Qlv::new(&r, DT as f32);
        for n in 1..=50 {
            let q = [0.02 * n as f32, 0.0, 0.0];
            assert_eq!(qlv.press(q), fresh.press(q), "{n}");
        }
    }

    /// A non-finite force is an error and leaves a relaxed state behind (also a state that went
    /// non-finite while released); the coefficients keep
    /// the incremental stiffness at or below the elastic law's (module notes, (b)).
    #[test]
    fn overflow_is_an_error_and_the_stiffness_never_exceeds_the_elastic() {
        let r = law(&[0.3, 0.6], &[0.002, 3600.0]);
        let mut qlv = Qlv::new(&r, DT as f32);
        assert!(qlv.press([1.0e18, 0.0, 0.0]).is_ok());
        assert_eq!(qlv.press([f32::MAX, 0.0, 0.0]), Err(SolveError::NonFinite));
        qlv.end_tick();
        assert_eq!(qlv, Qlv::new(&r, DT as f32));
        // A state driven to infinity while released is caught by the next press.
        qlv.h[1][2] = f32::INFINITY;
        qlv.release();
        assert_eq!(qlv.press([0.0, 0.0, 1.0]), Err(SolveError::NonFinite));
        qlv.end_tick();
        assert_eq!(qlv, Qlv::new(&r, DT as f32));
        let stiffness = qlv.g_inf() + qlv.gain.iter().sum::<f32>();
        assert!(stiffness <= 1.0 + 1e-6, "{stiffness}");
        // The slow term's decay survives rounding: c = dt / tau to 1e-6 relative.
        let c = f64::from(qlv.decay[1]);
        assert!((c / (1e-3 / 3600.0) - 1.0).abs() < 1e-6, "{c:e}");
        let taus: Vec<f32> = r.terms().map(|(_, t)| t).collect();
        assert_eq!(taus, [0.002, 3600.0]);
    }
}
