//! Current-mode servo amplifiers driven by a PWM set value and an enable line (the common
//! research-device set-up, e.g. Maxon ESCON): the duty cycle maps linearly to the current set
//! value, `duty_at_min` at `-max_current_a`, 50 % at 0 A, `duty_at_max` at `+max_current_a`
//! (ESCON's default: 10 % and 90 %), and enable low means motor off.
//!
//! [`Amplifier::setpoint`] is the whole mapping, portable and tested here; a board only writes
//! the duty into its timer ([`Setpoint::compare`]) and the enable into its pin. Anything that
//! is not a finite current gives the safe set point: 50 % with the enable low.

/// One amplifier's range, as configured in the amplifier itself (its "set value" scaling).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Amplifier {
    /// The current at `duty_at_max`, A (and its negative at `duty_at_min`).
    pub max_current_a: f32,
    /// Duty cycle at `-max_current_a` (0..1).
    pub duty_at_min: f32,
    /// Duty cycle at `+max_current_a` (0..1).
    pub duty_at_max: f32,
    /// The motor turns the other way for a positive set value (wiring): the current's sign is
    /// flipped before the mapping.
    pub inverted: bool,
}

/// What to write to one amplifier.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Setpoint {
    /// PWM duty cycle, 0..1.
    pub duty: f32,
    /// Enable line.
    pub enable: bool,
}

impl Setpoint {
    /// The safe set point: zero current (50 %), enable low.
    pub const SAFE: Setpoint = Setpoint {
        duty: 0.5,
        enable: false,
    };

    /// The timer compare value for a timer whose full period is `max_duty` counts (a duty that
    /// is not a number gives 50 %, zero current).
    pub fn compare(&self, max_duty: u16) -> u16 {
        let duty = if self.duty.is_finite() {
            self.duty
        } else {
            0.5
        };
        let c = micromath::F32Ext::round(duty.clamp(0.0, 1.0) * f32::from(max_duty));
        // In [0, max_duty] by the clamp; `as` saturates anyway.
        c as u16
    }
}

/// The first motor whose current limit (`limits_a`, the bank's `current_limit_a`) its amplifier
/// cannot deliver: over the amplifier's `max_current_a` (or a range that is not positive and
/// finite, which is never driven). Such a limit would let the supervisor pass currents the
/// amplifier clamps silently, while telemetry reports them as applied.
pub fn out_of_range(amplifiers: &[Amplifier; 3], limits_a: [f32; 3]) -> Option<u32> {
    (0..3u32)
        .zip(amplifiers.iter().zip(limits_a))
        .find(|(_, (amp, limit))| {
            let max = amp.max_current_a;
            // Written so that NaN counts as out of range.
            !(max.is_finite() && max > 0.0 && *limit <= max)
        })
        .map(|(motor, _)| motor)
}

impl Amplifier {
    /// ESCON's default scaling: 10 % = `-max_current_a`, 90 % = `+max_current_a`.
    pub const fn escon(max_current_a: f32, inverted: bool) -> Amplifier {
        Amplifier {
            max_current_a,
            duty_at_min: 0.1,
            duty_at_max: 0.9,
            inverted,
        }
    }

    /// The set point for `current_a` with the amplifier enabled when `enable`: clamped to
    /// `+-max_current_a`; a non-finite current (or a range that is not positive and finite)
    /// gives [`Setpoint::SAFE`].
    pub fn setpoint(&self, current_a: f32, enable: bool) -> Setpoint {
        let range_ok = self.max_current_a.is_finite()
            && self.max_current_a > 0.0
            && (0.0..=1.0).contains(&self.duty_at_min)
            && (0.0..=1.0).contains(&self.duty_at_max);
        if !enable || !current_a.is_finite() || !range_ok {
            return Setpoint::SAFE;
        }
        let signed = if self.inverted { -current_a } else { current_a };
        let x = (signed / self.max_current_a).clamp(-1.0, 1.0);
        let mid = 0.5 * (self.duty_at_min + self.duty_at_max);
        let half = 0.5 * (self.duty_at_max - self.duty_at_min);
        Setpoint {
            duty: mid + half * x,
            enable: true,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: f32, b: f32) -> bool {
        (a - b).abs() <= 1e-6
    }

    #[test]
    fn a_limit_over_the_amplifier_range_is_found() {
        let amps = [
            Amplifier::escon(3.0, false),
            Amplifier::escon(3.0, true),
            Amplifier::escon(2.0, false),
        ];
        assert_eq!(out_of_range(&amps, [3.0, 3.0, 2.0]), None);
        assert_eq!(out_of_range(&amps, [0.5, 1.0, 1.5]), None);
        assert_eq!(out_of_range(&amps, [3.0, 3.0, 2.5]), Some(2));
        assert_eq!(out_of_range(&amps, [20.0, 3.0, 2.5]), Some(0));
        assert_eq!(out_of_range(&amps, [1.0, f32::NAN, 1.0]), Some(1));
        let broken = [amps[0], Amplifier::escon(f32::NAN, false), amps[2]];
        assert_eq!(out_of_range(&broken, [1.0, 1.0, 1.0]), Some(1));
    }

    #[test]
    fn escon_scaling_clamps_and_fails_safe() {
        let amp = Amplifier::escon(2.0, false);
        let duty = |i: f32| amp.setpoint(i, true);
        assert!(close(duty(0.0).duty, 0.5) && duty(0.0).enable);
        assert!(close(duty(2.0).duty, 0.9));
        assert!(close(duty(-2.0).duty, 0.1));
        assert!(close(duty(1.0).duty, 0.7));
        assert!(close(duty(-0.5).duty, 0.4));
        // Over range: clamped, still enabled.
        assert!(close(duty(7.0).duty, 0.9) && duty(7.0).enable);
        assert!(close(duty(-1e30).duty, 0.1));
        // Not a number, infinities, disabled: 50 % and enable low.
        for i in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
            assert_eq!(duty(i), Setpoint::SAFE);
        }
        assert_eq!(amp.setpoint(1.0, false), Setpoint::SAFE);
        // A broken range is never driven.
        assert_eq!(
            Amplifier::escon(f32::NAN, false).setpoint(1.0, true),
            Setpoint::SAFE
        );
        assert_eq!(
            Amplifier::escon(0.0, false).setpoint(1.0, true),
            Setpoint::SAFE
        );
    }

    #[test]
    fn inverted_wiring_flips_the_sign() {
        let amp = Amplifier::escon(2.0, true);
        assert!(close(amp.setpoint(2.0, true).duty, 0.1));
        assert!(close(amp.setpoint(-1.0, true).duty, 0.7));
    }

    #[test]
    fn compare_values() {
        let max = 8_399; // 168 MHz / 20 kHz - 1
        assert_eq!(Setpoint::SAFE.compare(max), 4_200);
        let s = |duty| Setpoint { duty, enable: true };
        assert_eq!(s(0.1).compare(max), 840);
        assert_eq!(s(0.9).compare(max), 7_559);
        assert_eq!(s(-3.0).compare(max), 0);
        assert_eq!(s(2.0).compare(max), max);
        assert_eq!(s(f32::NAN).compare(max), 4_200);
    }
}
