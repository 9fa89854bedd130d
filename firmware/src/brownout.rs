//! The brown-out reset threshold the STM32F405's option bytes set, from `FLASH_OPTCR`
//! (RM0090 §3.9.10; the register at [`FLASH_OPTCR`] holds the option bytes loaded at reset):
//! portable, so that the decoding is tested natively; the board reads the register at boot.
//!
//! `BOR_LEV` (bits 3:2) selects the supply voltage below which the chip is held in reset:
//! `00` level 3 (supply range 2.70 to 3.60 V), `01` level 2 (2.40 to 2.70 V), `10` level 1
//! (2.10 to 2.40 V), `11` BOR off (only the power-on/power-down reset, at about 1.7 V). The
//! factory option bytes leave it off. The board runs the core at 168 MHz with 5 flash wait
//! states, which the datasheet allows from 2.7 V only: below level 3 the chip can run on a
//! sagging supply at a speed its flash cannot serve, so the application refuses to arm
//! ([`crate::app::App::check_brown_out`]) until `host flash --set-bor` programs level 3.

use bank_format::FaultReason;

/// Address of `FLASH_OPTCR` on the STM32F4 (RM0090 §3.9.10: FLASH interface at
/// `0x4002_3C00`, offset `0x14`).
pub const FLASH_OPTCR: u32 = 0x4002_3C14;
/// Position of `BOR_LEV` in `FLASH_OPTCR`.
pub const BOR_LEV_SHIFT: u32 = 2;
/// The `BOR_LEV` bits of `FLASH_OPTCR`.
pub const BOR_LEV_MASK: u32 = 0b11 << BOR_LEV_SHIFT;

/// The brown-out reset threshold the option bytes select.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BorLevel {
    /// BOR off (`BOR_LEV` = 11): only the power-on/power-down reset, at about 1.7 V.
    Off,
    /// Level 1 (`BOR_LEV` = 10): reset below about 2.1 V.
    Level1,
    /// Level 2 (`BOR_LEV` = 01): reset below about 2.4 V.
    Level2,
    /// Level 3 (`BOR_LEV` = 00): reset below about 2.7 V, the lowest supply of 168 MHz.
    Level3,
}

impl BorLevel {
    /// The level's number as the fault's detail reports it: 0 for BOR off, else 1 to 3.
    pub fn number(self) -> u32 {
        match self {
            BorLevel::Off => 0,
            BorLevel::Level1 => 1,
            BorLevel::Level2 => 2,
            BorLevel::Level3 => 3,
        }
    }
}

/// The brown-out level `FLASH_OPTCR` = `optcr` selects (its other bits do not matter).
pub fn level_from_optcr(optcr: u32) -> BorLevel {
    match (optcr & BOR_LEV_MASK) >> BOR_LEV_SHIFT {
        0b00 => BorLevel::Level3,
        0b01 => BorLevel::Level2,
        0b10 => BorLevel::Level1,
        _ => BorLevel::Off,
    }
}

/// The configuration fault a brown-out level calls for: [`FaultReason::BrownOutLevel`] with
/// the level's number ([`BorLevel::number`]) below level 3, none at level 3.
pub fn fault(level: BorLevel) -> Option<(FaultReason, u32)> {
    match level {
        BorLevel::Level3 => None,
        other => Some((FaultReason::BrownOutLevel, other.number())),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// RM0090's reset value of FLASH_OPTCR (factory option bytes: no write protection, RDP
    /// level 0 = 0xAA, the user bits 1, BOR off, OPTLOCK set) and the same word with each
    /// `BOR_LEV` code written out by hand.
    #[test]
    fn each_optcr_word_decodes_to_its_level() {
        let cases = [
            (0x0FFF_AAED, BorLevel::Off),
            (0x0FFF_AAE9, BorLevel::Level1),
            (0x0FFF_AAE5, BorLevel::Level2),
            (0x0FFF_AAE1, BorLevel::Level3),
            // The other bits (RDP level 1, write protection, OPTSTRT/OPTLOCK) do not matter.
            (0x0000_0000, BorLevel::Level3),
            (0xFFFF_FFF3, BorLevel::Level3),
            (0x0000_000C, BorLevel::Off),
            (0x0000_0008, BorLevel::Level1),
            (0x0000_0004, BorLevel::Level2),
        ];
        for (optcr, level) in cases {
            assert_eq!(level_from_optcr(optcr), level, "{optcr:#010x}");
        }
    }

    #[test]
    fn only_level_3_leaves_no_fault() {
        assert_eq!(fault(BorLevel::Level3), None);
        assert_eq!(fault(BorLevel::Off), Some((FaultReason::BrownOutLevel, 0)));
        assert_eq!(
            fault(BorLevel::Level1),
            Some((FaultReason::BrownOutLevel, 1))
        );
        assert_eq!(
            fault(BorLevel::Level2),
            Some((FaultReason::BrownOutLevel, 2))
        );
    }
}
