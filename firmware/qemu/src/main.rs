//! The software-in-the-loop image: the firmware exactly as it would be flashed, run by QEMU's
//! `netduinoplus2` (an STM32F405) against the host's plant simulator. It has the board image's
//! structure (`firmware/board`), so the SIL tests exercise what the board runs:
//!
//! - The bank is not compiled in. QEMU loads the bank file into the flash's bank region
//!   (`-device loader,file=x.bank,addr=..`, the `BANK` origin of the top-level `memory.x`), as
//!   flashing would, and the image validates it at boot with [`Bank::parse`] on
//!   `__bank_start..__bank_end` (linker symbols of `memory.x`). An invalid bank leaves the
//!   motors at zero current and the reason on the link ([`firmware::app`]).
//! - **The tick runs at high priority**: an embassy executor driven by a spare interrupt
//!   ([`TICK_IRQ`], pended in software, priority below SysTick and above thread mode) runs the
//!   1 kHz tick task on an embassy-time `Ticker`; the time driver is SysTick ([`systick`]).
//! - **The link runs in thread mode, below the tick**: a second executor runs the link task,
//!   which moves bytes between USART1 ([`usart`]) and the tick's queues
//!   ([`firmware::link`]); the tick never touches the UART. It idles on WFI, which under
//!   QEMU's `-icount shift=3,sleep=off` makes runs deterministic.
//! - The link task may send at most a budget of bytes per tick, read at boot from the file
//!   `sil-link-budget` in QEMU's working directory (the harness writes it to model a slow
//!   UART; absent: unlimited, as QEMU's USART is instantaneous).
//! - The plant (encoders in, currents out) is a lockstep semihosting channel ([`plant`]) that
//!   holds virtual time while the host answers.
//! - The board's boot checks of its hardware are not run: no reset cause (QEMU has no reset
//!   flags), no amplifier ranges, and no brown-out level ([`App::check_brown_out`]): the
//!   emulated chip has no supply to sag and no option bytes of a board, so the image does not
//!   read `FLASH_OPTCR`; the board image does, and `host flash --set-bor` programs it.
//!
//! The image exits (semihosting) when the plant channel closes: code 0 for a clean close, 1
//! for a plant error, 101 for a panic.
#![no_std]
#![no_main]

mod plant;
mod systick;
mod usart;

use bank_format::{Bank, BankError};
use core::sync::atomic::{AtomicBool, AtomicPtr, Ordering};
use cortex_m::interrupt::InterruptNumber;
use cortex_m::peripheral::NVIC;
use cortex_m_rt::exception;
use embassy_executor::raw::Executor;
use embassy_time::{Duration, Ticker, Timer};
use firmware::app::App;
use firmware::deadline::TickWatch;
use firmware::hal::CycleCounter;
use firmware::link::{DriverEnd, Link};
use semihosting::io::Read;

use crate::plant::{PlantChannel, PlantError};
use crate::systick::InstructionCounter;
use crate::usart::Usart1;

unsafe extern "C" {
    static __bank_start: u8;
    static __bank_end: u8;
}

/// The flash's bank region, as the linker script places it.
fn bank_region() -> &'static [u8] {
    // SAFETY: `memory.x` defines `__bank_start..__bank_end` as the BANK flash region, which is
    // mapped, read-only and never written while the firmware runs.
    unsafe {
        let start = &raw const __bank_start;
        let end = &raw const __bank_end;
        core::slice::from_raw_parts(start, end as usize - start as usize)
    }
}

/// An interrupt the image does not otherwise use (UART4's, 52), pended in software to run the
/// tick's executor.
#[derive(Clone, Copy)]
struct TickIrq;

// SAFETY: 52 is a valid STM32F405 interrupt number (UART4), unused by this image.
unsafe impl InterruptNumber for TickIrq {
    fn number(self) -> u16 {
        52
    }
}

/// The tick's interrupt.
const TICK_IRQ: TickIrq = TickIrq;
/// Its NVIC priority: below SysTick (0, so the period count advances during a long tick and
/// an overrun is seen), above thread mode.
const TICK_PRIORITY: u8 = 0x40;

/// Set by the pender when a thread-mode task was woken; cleared before each poll.
static WORK: AtomicBool = AtomicBool::new(true);

/// Wake an executor (called by embassy when a task is woken): the thread-mode loop (null
/// context) or the tick's interrupt (its number as context).
#[unsafe(export_name = "__pender")]
fn pender(context: *mut ()) {
    if context.is_null() {
        WORK.store(true, Ordering::Release);
    } else {
        NVIC::pend(TICK_IRQ);
    }
}

/// The tick's executor, polled from [`TICK_IRQ`]'s handler (null until `main` starts it).
static TICK_EXECUTOR: AtomicPtr<Executor> = AtomicPtr::new(core::ptr::null_mut());

/// Device interrupts: only [`TICK_IRQ`] is enabled.
#[exception]
unsafe fn DefaultHandler(irqn: i16) {
    if irqn == TICK_IRQ.number() as i16 {
        // SAFETY: the pointer is null or the `'static` executor `main` stored before it
        // unmasked this interrupt; the handler does not preempt itself, so the executor is
        // never polled re-entrantly.
        if let Some(executor) = unsafe { TICK_EXECUTOR.load(Ordering::Acquire).as_ref() } {
            unsafe { executor.poll() };
        }
    } else {
        semihosting::eprintln!("sil image: unexpected interrupt {irqn}");
        semihosting::process::exit(1)
    }
}

/// The 1 kHz tick: wait for the period, run one [`App::tick`], answer the plant, measure.
///
/// Overruns are detected exactly as on the board (`firmware/board`): a
/// [`TickWatch`] on the core-cycle counter (here SysTick's position, [`InstructionCounter`]:
/// virtual core cycles), and on an overrun the ticker restarts from now as the watch's
/// schedule does, so SIL runs the board's overrun path. The whole-tick figure stays measured
/// from the SysTick interrupt that started the period, which this image knows (the board
/// measures from the watch's due time instead).
#[embassy_executor::task]
async fn haptic(mut app: App<'static, 'static>, mut plant: PlantChannel) {
    let counter = InstructionCounter;
    let mut watch = TickWatch::new(systick::COUNTS_PER_PERIOD);
    let mut ticker = Ticker::every(Duration::from_hz(u64::from(firmware::TICK_HZ)));
    let mut overrun = false;
    loop {
        ticker.next().await;
        watch.begin(counter.cycles());
        let replied = app
            .tick(&mut plant, &counter, overrun)
            .and_then(|report| plant.reply(&report));
        match replied {
            Ok(()) => {}
            Err(PlantError::Closed) => semihosting::process::exit(0),
            Err(e) => {
                semihosting::eprintln!("sil image: plant channel: {e}");
                semihosting::process::exit(1)
            }
        }
        // Whole tick, from the SysTick interrupt that started it (executor wake included).
        let whole = counter.since_period_start();
        overrun = watch.end(counter.cycles()).overrun;
        app.record_tick_cycles(whole);
        if overrun {
            // Start afresh from now instead of catching up with back-to-back ticks, which
            // would starve the link task of the time to report the fault; the watch has
            // restarted its schedule from now too.
            ticker.reset();
        }
    }
}

/// How many empty polls of the UART, after a received byte, before the link task moves on
/// (about 10 instructions each: some 2,000 of the tick period's 125,000).
const RX_POLLS_AFTER_A_BYTE: u32 = 200;

/// Outgoing bytes the link task takes from the link per call.
const TX_CHUNK: usize = 16;

/// The link grace of the application ([`App::new`]): QEMU's USART holds one byte at a time and
/// carries a few a tick, so a 20-byte command spans several ticks, during which the bytes alone
/// keep the link alive. 20 ticks is a choice, not a measurement of the longest frame gap; the
/// SIL tests run with it without a `LinkSilent`. A host that goes silent still faults after
/// the bank's link timeout (`link_timeout_ms` ticks) without a byte; one that sends only
/// garbage after that timeout + 20 ticks without a valid frame.
const LINK_GRACE_TICKS: u32 = 20;

/// The link: received bytes decoded into the tick's command queue ([`DriverEnd::put_rx`]),
/// queued messages out (encoded as frames here, by [`DriverEnd::take_tx`]); neither in the
/// tick. At most `budget` bytes sent per tick
/// period. Busy while there is traffic, asleep until the next period otherwise.
#[embassy_executor::task]
async fn link(mut end: DriverEnd<'static>, mut uart: Usart1, budget: u32) {
    let (mut period, mut left) = (systick::period(), budget);
    // Bytes taken from the link but not yet written (taken in chunks: one `take_tx` call per
    // byte cost about 40 instructions a byte of thread-mode time).
    let (mut chunk, mut pos, mut len) = ([0u8; TX_CHUNK], 0usize, 0usize);
    loop {
        let mut busy = false;
        // QEMU's USART holds one received byte; the next one is delivered by QEMU's I/O thread
        // once this one is read. After a byte, keep polling a little while (as an RX
        // interrupt would catch it), so a frame does not trickle in at one byte per tick.
        let mut polls = 0;
        while polls < RX_POLLS_AFTER_A_BYTE {
            match uart.read_byte() {
                Some(b) => {
                    end.put_rx(&[b]);
                    busy = true;
                    polls = 0;
                }
                None if busy => polls += 1,
                None => break,
            }
        }
        let now = systick::period();
        if now != period {
            (period, left) = (now, budget);
        }
        while left > 0 {
            if pos >= len {
                let want = TX_CHUNK.min(usize::try_from(left).unwrap_or(TX_CHUNK));
                (pos, len) = (0, end.take_tx(chunk.get_mut(..want).unwrap_or(&mut [])));
                if len == 0 {
                    break;
                }
            }
            // QEMU's transmit register is always free; a full one waits for the next pass (the
            // byte stays in `chunk`, so a frame is never torn).
            let Some(&byte) = chunk.get(pos) else { break };
            if !uart.try_write(byte) {
                break;
            }
            pos += 1;
            left -= 1;
            busy = true;
        }
        if busy {
            embassy_futures::yield_now().await;
        } else {
            Timer::after_ticks(1).await;
        }
    }
}

/// The link budget from `sil-link-budget` (decimal bytes per tick), unlimited without it.
fn link_budget() -> u32 {
    let Ok(mut f) = semihosting::fs::File::open(c"sil-link-budget") else {
        return u32::MAX;
    };
    let mut buf = [0u8; 16];
    let n = f.read(&mut buf).unwrap_or(0);
    let text = buf.get(..n).and_then(|b| core::str::from_utf8(b).ok());
    match text.map(str::trim).map(str::parse::<u32>) {
        Some(Ok(v)) => v,
        _ => {
            semihosting::eprintln!("sil image: sil-link-budget is not a number of bytes");
            semihosting::process::exit(1)
        }
    }
}

#[cortex_m_rt::entry]
fn main() -> ! {
    static mut BANK: Option<Result<Bank<'static>, BankError>> = None;
    static mut LINK: Link = Link::new();
    static mut EXECUTOR: Option<Executor> = None;
    static mut TICK: Option<Executor> = None;

    let bank: &'static Result<Bank<'static>, BankError> = BANK.insert(Bank::parse(bank_region()));
    if let Err(e) = bank {
        semihosting::eprintln!("sil image: bank region invalid: {e}");
    }
    let (tick_end, driver_end) = LINK.split();
    let app = App::new(bank.as_ref().map_err(|e| *e), tick_end, LINK_GRACE_TICKS);
    let uart = Usart1::init();
    let budget = link_budget();
    let plant = match PlantChannel::open() {
        Ok(p) => p,
        Err(e) => {
            semihosting::eprintln!("sil image: plant channel: {e}");
            semihosting::process::exit(1)
        }
    };
    let mut core = cortex_m::Peripherals::take().unwrap_or_else(|| semihosting::process::exit(1));
    // SAFETY: priorities are set before the interrupt is unmasked and never changed after.
    unsafe { core.NVIC.set_priority(TICK_IRQ, TICK_PRIORITY) };
    systick::start(&mut core.SYST);

    let tick_executor: &'static Executor =
        TICK.insert(Executor::new(TICK_IRQ.number() as usize as *mut ()));
    TICK_EXECUTOR.store(
        core::ptr::from_ref(tick_executor).cast_mut(),
        Ordering::Release,
    );
    tick_executor
        .spawner()
        .spawn(haptic(app, plant).unwrap_or_else(|_| semihosting::process::exit(1)));
    // SAFETY: the handler only polls the executor initialised above.
    unsafe { NVIC::unmask(TICK_IRQ) };
    NVIC::pend(TICK_IRQ);

    let executor: &'static Executor = EXECUTOR.insert(Executor::new(core::ptr::null_mut()));
    executor
        .spawner()
        .spawn(link(driver_end, uart, budget).unwrap_or_else(|_| semihosting::process::exit(1)));
    loop {
        if WORK.swap(false, Ordering::AcqRel) {
            // SAFETY: polled only from this thread-mode loop, never re-entrantly.
            unsafe { executor.poll() };
        }
        // Sleep until the next interrupt unless a wake arrived meanwhile. WFI (not the stock
        // executor's WFE, on which QEMU spins) lets `-icount ... sleep=off` skip idle time.
        cortex_m::interrupt::free(|_| {
            if !WORK.load(Ordering::Acquire) {
                cortex_m::asm::wfi();
            }
        });
    }
}

/// A panic stops the image; the plant then sees its channel close and holds zero current.
#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    semihosting::eprintln!("sil image: panic: {info}");
    semihosting::process::exit(101)
}
