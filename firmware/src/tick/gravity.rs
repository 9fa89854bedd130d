//! The feed-forward for the instrument's own weight (step 5 of the tick).

use bank_format::Bank;

use crate::device::{Joints, sin_cos};

/// The joint efforts that hold the instrument still against its own weight at `q` (pitch N m,
/// yaw N m, insertion N): `tau_g(q) = dV/dq` of the bank's gravity section
/// ([`GravityCompensation::efforts`](bank_format::GravityCompensation::efforts), `SPEC.md`
/// "gravity"), zero when the bank has none.
pub fn gravity_efforts(bank: &Bank<'_>, q: &Joints) -> [f32; 3] {
    match bank.gravity() {
        Some(g) => g.efforts(sin_cos(q.pitch), sin_cos(q.yaw), q.insertion),
        None => [0.0; 3],
    }
}

#[cfg(test)]
#[allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing,
    clippy::needless_range_loop
)]
mod tests {
    extern crate std;
    use bank_format::Mode;

    use super::super::rig::{Rig, gravity_bank, input, parse};
    use crate::contact::ContactState;
    use crate::safety::State;

    /// The tick adds exactly `tau_g(q)` (`SPEC.md` "gravity"), written out here in f64 from
    /// the potential's gradient, before the current mapping `i = tau / (transmission Kt)`:
    /// armed, no contact, in `Render` and `Transparent`; not in `ConstantCurrent`; and a bank
    /// without the section gives zero current away from the tissue.
    #[test]
    fn the_tick_adds_the_gravity_feed_forward() {
        let coeffs = [0.05f32, -0.02, 0.03, 0.4, 0.1, -0.3, 0.02, -0.01];
        let g = bank_format::GravityCompensation { coeffs };
        let with = gravity_bank(Some(g));
        let without = gravity_bank(None);
        let bank = parse(&with);
        let plain = parse(&without);
        assert_eq!(bank.gravity(), Some(&g));
        assert_eq!(plain.gravity(), None);
        let cal = *bank.device();
        let counts = [2000, -1500, 300];
        for mode in [Mode::Render, Mode::Transparent] {
            let mut lp = Rig::new(&bank).homed().in_mode(mode).armed();
            let q = lp.device().joints(counts);
            let out = lp.ramped(counts);
            assert_eq!((out.state, out.contact), (State::Armed, ContactState::Free));
            // Hand-written tau_g = dV/dq in f64.
            let c = coeffs.map(f64::from);
            let (p, y, s) = (f64::from(q.pitch), f64::from(q.yaw), f64::from(q.insertion));
            let (sp, cp, sy, cy) = (p.sin(), p.cos(), y.sin(), y.cos());
            let (mc, ms, mp) = (c[0] + s * c[3], c[1] + s * c[4], c[2] + s * c[5]);
            let tau = [
                mc * sp * cy + ms * sp * sy - mp * cp,
                mc * cp * sy - ms * cp * cy + c[6] * sy - c[7] * cy,
                -(c[3] * cp * cy + c[4] * cp * sy + c[5] * sp),
            ];
            for j in 0..3 {
                let want = tau[j]
                    / (f64::from(cal.transmission[j]) * f64::from(cal.torque_constant_nm_per_a[j]));
                assert!(want.abs() > 0.01 && want.abs() < f64::from(cal.current_limit_a[j]));
                let got = f64::from(out.currents_a[j]);
                assert!(
                    (got - want).abs() <= 1e-5 * want.abs().max(1.0),
                    "{mode:?} {j}: {got} vs {want}"
                );
            }
        }
        let mut lp = Rig::new(&bank).homed();
        let currents_a = [0.1, -0.2, 0.3];
        lp.set_mode(Mode::ConstantCurrent { currents_a }).unwrap();
        lp.arm().unwrap();
        assert_eq!(lp.tick(input(counts)).currents_a, currents_a);
        let mut lp = Rig::new(&plain).homed().armed();
        assert_eq!(lp.tick(input(counts)).currents_a, [0.0; 3]);
    }
}
