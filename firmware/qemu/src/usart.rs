//! USART1 of the STM32F405 (0x4001_1000) with plain register access: the host link. QEMU's
//! netduinoplus2 connects it to its first `-serial` back end; it needs no clock set-up there
//! (on a board, RCC and the baud rate would be configured first). Polled by the link task in
//! thread mode, never by the tick.

use core::ptr::{read_volatile, write_volatile};

const BASE: usize = 0x4001_1000;
const SR: *mut u32 = BASE as *mut u32;
const DR: *mut u32 = (BASE + 0x04) as *mut u32;
const CR1: *mut u32 = (BASE + 0x0C) as *mut u32;
/// SR: a byte was received.
const SR_RXNE: u32 = 1 << 5;
/// SR: the transmit data register is empty.
const SR_TXE: u32 = 1 << 7;
/// CR1: USART, transmitter and receiver enable.
const CR1_UE_TE_RE: u32 = (1 << 13) | (1 << 3) | (1 << 2);

/// The link UART.
pub struct Usart1(());

impl Usart1 {
    /// Enable transmitter and receiver.
    pub fn init() -> Usart1 {
        // SAFETY: USART1's CR1 register, owned by this single instance.
        unsafe { write_volatile(CR1, CR1_UE_TE_RE) };
        Usart1(())
    }

    /// The received byte, if one is waiting.
    pub fn read_byte(&mut self) -> Option<u8> {
        // SAFETY: USART1's SR and DR registers; reading DR clears RXNE.
        unsafe { (read_volatile(SR) & SR_RXNE != 0).then(|| read_volatile(DR) as u8) }
    }

    /// Send `byte` if the transmit register is free; `false` if it is not.
    pub fn try_write(&mut self, byte: u8) -> bool {
        // SAFETY: USART1's SR and DR registers.
        unsafe {
            if read_volatile(SR) & SR_TXE == 0 {
                return false;
            }
            write_volatile(DR, u32::from(byte));
        }
        true
    }
}
