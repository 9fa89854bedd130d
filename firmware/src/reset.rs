//! Why the chip started, from the STM32F4's reset flags (RCC_CSR, RM0090):
//! portable, so that the decoding is tested natively; the board reads the register and clears
//! the flags (RMVF) at boot, so that each boot reads its own reset.
//!
//! Several flags are set by one reset: every internal reset source (both watchdogs, a software
//! reset, a low-power reset) drives the NRST pin low through the reset pulse generator, so the
//! pin flag comes with all of them, and a power-on/power-down reset sets the brown-out flag as
//! well. The cause is the most specific flag: the watchdogs, the low-power reset, software,
//! power-on, brown-out, and the pin only when nothing else is set.

use bank_format::{FaultReason, ResetCause};

/// RCC_CSR bit: low-power management reset.
pub const LPWRRSTF: u32 = 1 << 31;
/// RCC_CSR bit: window watchdog reset.
pub const WWDGRSTF: u32 = 1 << 30;
/// RCC_CSR bit: independent watchdog reset.
pub const IWDGRSTF: u32 = 1 << 29;
/// RCC_CSR bit: software reset.
pub const SFTRSTF: u32 = 1 << 28;
/// RCC_CSR bit: power-on / power-down reset.
pub const PORRSTF: u32 = 1 << 27;
/// RCC_CSR bit: NRST pin reset.
pub const PINRSTF: u32 = 1 << 26;
/// RCC_CSR bit: brown-out reset (also set by a power-on reset).
pub const BORRSTF: u32 = 1 << 25;

/// The reset cause the RCC_CSR value `csr` tells.
pub fn cause_from_rcc_csr(csr: u32) -> ResetCause {
    let order = [
        (IWDGRSTF, ResetCause::IndependentWatchdog),
        (WWDGRSTF, ResetCause::WindowWatchdog),
        (LPWRRSTF, ResetCause::LowPower),
        (SFTRSTF, ResetCause::Software),
        (PORRSTF, ResetCause::PowerOn),
        (BORRSTF, ResetCause::BrownOut),
        (PINRSTF, ResetCause::Pin),
    ];
    order
        .iter()
        .find(|(bit, _)| csr & bit != 0)
        .map_or(ResetCause::Unknown, |&(_, cause)| cause)
}

/// The fault a reset latches at boot, if any: a watchdog reset means the loop hung or the core
/// locked up mid-session ([`FaultReason::WatchdogReset`], detail 0 independent, 1 window).
/// Every other reset (and this one too) leaves the encoders unreferenced, which refuses `Arm`
/// until the host homes the device ([`crate::tick::HapticLoop::zero_encoders`]).
pub fn latched_fault(cause: ResetCause) -> Option<(FaultReason, u32)> {
    match cause {
        ResetCause::IndependentWatchdog => Some((FaultReason::WatchdogReset, 0)),
        ResetCause::WindowWatchdog => Some((FaultReason::WatchdogReset, 1)),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The flags each reset sets on an STM32F4 (RM0090's reset circuit: internal resets pulse
    /// NRST; a power-on reset sets the brown-out flag too), and the cause reported.
    #[test]
    fn each_reset_is_told_by_its_own_flag() {
        let cases = [
            (PORRSTF | BORRSTF | PINRSTF, ResetCause::PowerOn),
            (BORRSTF | PINRSTF, ResetCause::BrownOut),
            (PINRSTF, ResetCause::Pin),
            (SFTRSTF | PINRSTF, ResetCause::Software),
            (IWDGRSTF | PINRSTF, ResetCause::IndependentWatchdog),
            (WWDGRSTF | PINRSTF, ResetCause::WindowWatchdog),
            (LPWRRSTF | PINRSTF, ResetCause::LowPower),
            (0, ResetCause::Unknown),
            // The other bits of the register (clock enables, RMVF) do not matter.
            (0x00FF_FFFF | PINRSTF, ResetCause::Pin),
        ];
        for (csr, cause) in cases {
            assert_eq!(cause_from_rcc_csr(csr), cause, "{csr:#010x}");
        }
        assert_eq!(
            cause_from_rcc_csr(IWDGRSTF | WWDGRSTF),
            ResetCause::IndependentWatchdog
        );
    }

    #[test]
    fn only_the_watchdogs_latch_a_fault() {
        assert_eq!(
            latched_fault(ResetCause::IndependentWatchdog),
            Some((FaultReason::WatchdogReset, 0))
        );
        assert_eq!(
            latched_fault(ResetCause::WindowWatchdog),
            Some((FaultReason::WatchdogReset, 1))
        );
        for cause in [
            ResetCause::PowerOn,
            ResetCause::Pin,
            ResetCause::BrownOut,
            ResetCause::Software,
            ResetCause::LowPower,
            ResetCause::Unknown,
        ] {
            assert_eq!(latched_fault(cause), None, "{cause:?}");
        }
    }
}
