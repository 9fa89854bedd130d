//! STM32F4 GPIO register arithmetic for the code that must not go through a HAL: the panic and
//! fault handlers, which drive the amplifier enables to their off level with direct register
//! writes, and the first instructions of boot, which make those pins outputs at their off level
//! before anything else runs. Plain functions (`const`, so a board computes its tables at
//! compile time), tested natively; the image does the volatile writes.
//!
//! Register map (RM0090): port `x` (A = 0, B = 1, ...) at `0x4002_0000 + 0x400 x`; `MODER` at
//! offset `0x00` (two bits per pin, `01` = general-purpose output); `BSRR` at `0x18` (writing a
//! 1 to bit `n` sets pin `n`, to bit `16 + n` resets it, zeros change nothing, one store is
//! atomic); the port clocks are `RCC_AHB1ENR` (`0x4002_3830`) bit `x`.

/// Address of GPIOA; port `x` is at `GPIO_BASE + x * GPIO_STRIDE`.
pub const GPIO_BASE: u32 = 0x4002_0000;
/// Distance between two ports' register blocks.
pub const GPIO_STRIDE: u32 = 0x400;
/// Offset of `MODER` in a port's block.
pub const MODER_OFFSET: u32 = 0x00;
/// Offset of `BSRR` in a port's block.
pub const BSRR_OFFSET: u32 = 0x18;
/// Address of `RCC_AHB1ENR` (bit `x` clocks port `x`).
pub const RCC_AHB1ENR: u32 = 0x4002_3830;
/// Ports A to I (the largest STM32F4 packages; an LQFP64 has A, B, C, D2 and H0-H1).
pub const PORTS: usize = 9;

/// A GPIO port.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[allow(missing_docs)]
pub enum Port {
    A = 0,
    B,
    C,
    D,
    E,
    F,
    G,
    H,
    I,
}

/// One GPIO pin.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct GpioPin {
    /// Its port.
    pub port: Port,
    /// Its number in the port, 0..=15 ([`GpioPin::is_valid`]).
    pub pin: u8,
}

impl GpioPin {
    /// Pin `pin` of `port`.
    pub const fn new(port: Port, pin: u8) -> GpioPin {
        GpioPin { port, pin }
    }

    /// The pin number is 0..=15 (a board checks its pins at compile time).
    pub const fn is_valid(&self) -> bool {
        self.pin < 16
    }

    /// Port index (A = 0).
    pub const fn port_index(&self) -> u32 {
        self.port as u32
    }

    /// Address of the port's `BSRR`.
    pub const fn bsrr_address(&self) -> u32 {
        port_bsrr_address(self.port_index())
    }

    /// Address of the port's `MODER`.
    pub const fn moder_address(&self) -> u32 {
        GPIO_BASE + GPIO_STRIDE * self.port_index() + MODER_OFFSET
    }

    /// The `BSRR` word that drives this pin `high` (or low) and leaves the others alone.
    pub const fn bsrr_word(&self, high: bool) -> u32 {
        let bit = 1u32 << (self.pin & 15);
        if high { bit } else { bit << 16 }
    }

    /// `MODER` bits of this pin (mask) and the value that makes it an output.
    pub const fn moder_output(&self) -> (u32, u32) {
        let shift = 2 * (self.pin & 15) as u32;
        (0b11 << shift, 0b01 << shift)
    }
}

/// Address of `BSRR` of the port with index `port` (A = 0).
pub const fn port_bsrr_address(port: u32) -> u32 {
    GPIO_BASE + GPIO_STRIDE * port + BSRR_OFFSET
}

/// Address of `MODER` of the port with index `port` (A = 0).
pub const fn port_moder_address(port: u32) -> u32 {
    GPIO_BASE + GPIO_STRIDE * port + MODER_OFFSET
}

/// What it takes to hold a set of pins at one level, port by port: entry `x` of each array is
/// port `x`'s (zero where the set has no pin on that port). Write each non-zero `bsrr` word to
/// [`port_bsrr_address`] to drive the pins (every pin of a port in the same store); at boot,
/// first set [`PinLevels::rcc_ahb1enr`] in `RCC_AHB1ENR`, write the `BSRR` words (the output
/// latch, before the pins become outputs), then `MODER = (MODER & !moder_mask) | moder_output`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PinLevels {
    /// `BSRR` word per port.
    pub bsrr: [u32; PORTS],
    /// `MODER` bits of the set's pins, per port.
    pub moder_mask: [u32; PORTS],
    /// `MODER` value making them outputs, per port.
    pub moder_output: [u32; PORTS],
    /// `RCC_AHB1ENR` bits clocking the ports used.
    pub rcc_ahb1enr: u32,
}

/// The [`PinLevels`] that hold every pin of `pins` `high` (or low).
pub const fn pin_levels(pins: &[GpioPin], high: bool) -> PinLevels {
    let mut levels = PinLevels {
        bsrr: [0; PORTS],
        moder_mask: [0; PORTS],
        moder_output: [0; PORTS],
        rcc_ahb1enr: 0,
    };
    let mut rest = pins;
    while let [p, tail @ ..] = rest {
        let x = p.port_index();
        let (mask, out) = p.moder_output();
        or_at(&mut levels.bsrr, x, p.bsrr_word(high));
        or_at(&mut levels.moder_mask, x, mask);
        or_at(&mut levels.moder_output, x, out);
        levels.rcc_ahb1enr |= 1 << x;
        rest = tail;
    }
    levels
}

/// `words[index] |= bits` (no index past the end: [`Port`] has [`PORTS`] values).
const fn or_at(words: &mut [u32; PORTS], index: u32, bits: u32) {
    let mut rest: &mut [u32] = words;
    let mut i = 0;
    while let [w, tail @ ..] = rest {
        if i == index {
            *w |= bits;
        }
        rest = tail;
        i += 1;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn addresses_and_words_follow_rm0090() {
        let pc10 = GpioPin::new(Port::C, 10);
        assert!(pc10.is_valid());
        assert!(!GpioPin::new(Port::A, 16).is_valid());
        assert_eq!(pc10.bsrr_address(), 0x4002_0818);
        assert_eq!(pc10.moder_address(), 0x4002_0800);
        assert_eq!(GpioPin::new(Port::A, 0).bsrr_address(), 0x4002_0018);
        assert_eq!(GpioPin::new(Port::I, 0).bsrr_address(), 0x4002_2018);
        assert_eq!(pc10.bsrr_word(true), 1 << 10);
        assert_eq!(pc10.bsrr_word(false), 1 << 26);
        assert_eq!(GpioPin::new(Port::B, 15).bsrr_word(false), 1 << 31);
        assert_eq!(pc10.moder_output(), (0b11 << 20, 0b01 << 20));
        assert_eq!(port_bsrr_address(2), pc10.bsrr_address());
        assert_eq!(port_moder_address(2), pc10.moder_address());
    }

    #[test]
    fn pins_of_one_port_share_one_store() {
        let pins = [
            GpioPin::new(Port::C, 10),
            GpioPin::new(Port::C, 11),
            GpioPin::new(Port::C, 12),
        ];
        let low = pin_levels(&pins, false);
        let mut expected = [0; PORTS];
        expected[2] = (1 << 26) | (1 << 27) | (1 << 28);
        assert_eq!(low.bsrr, expected);
        assert_eq!(low.rcc_ahb1enr, 1 << 2);
        assert_eq!(low.moder_mask[2], 0b11_11_11 << 20);
        assert_eq!(low.moder_output[2], 0b01_01_01 << 20);
        assert!(
            low.moder_mask
                .iter()
                .enumerate()
                .all(|(i, &m)| i == 2 || m == 0)
        );
        // Active-low enables are switched off high: set bits instead.
        assert_eq!(
            pin_levels(&pins, true).bsrr[2],
            (1 << 10) | (1 << 11) | (1 << 12)
        );
    }

    #[test]
    fn pins_on_several_ports() {
        let pins = [
            GpioPin::new(Port::A, 8),
            GpioPin::new(Port::B, 0),
            GpioPin::new(Port::A, 15),
            GpioPin::new(Port::H, 1),
        ];
        const_check();
        let l = pin_levels(&pins, false);
        assert_eq!(l.bsrr[0], (1 << 24) | (1 << 31));
        assert_eq!(l.bsrr[1], 1 << 16);
        assert_eq!(l.bsrr[7], 1 << 17);
        assert_eq!(l.bsrr.iter().filter(|&&w| w != 0).count(), 3);
        assert_eq!(l.rcc_ahb1enr, 0b1000_0011);
        assert_eq!(l.moder_output[0], (1 << 16) | (1 << 30));
        assert_eq!(pin_levels(&[], false).rcc_ahb1enr, 0);
    }

    /// The tables are computed at compile time, as a board does.
    fn const_check() {
        const LEVELS: PinLevels = pin_levels(&[GpioPin::new(Port::D, 2)], false);
        assert_eq!(LEVELS.bsrr[3], 1 << 18);
    }
}
