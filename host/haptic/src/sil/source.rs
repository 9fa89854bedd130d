//! The QEMU image as a display source: [`SilSource`] runs a SIL session in real time and reads
//! the image's telemetry from its emulated USART, decoded exactly as from a board
//! ([`crate::display::source`]'s serial source).

use super::harness;
use crate::display::source::{Absorber, LoopStats, Mailbox, Sample, Source};
use anyhow::{Result, anyhow};
use bank_format::DeviceToHost;
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::Duration;

/// The QEMU image through the plant simulator (`haptic::sil`): a scripted hand, the image's
/// telemetry over its emulated USART. Runs in real time (1 ms of wall time per tick) so the
/// display follows it; `latest` reports an error once the run is over.
pub struct SilSource {
    mailbox: Arc<Mailbox>,
    thread: Option<JoinHandle<Result<()>>>,
    last_tick: Option<u32>,
}

impl SilSource {
    /// Starts `session` (made real-time and observed here) on `setup`.
    pub fn start(setup: harness::Setup, mut session: harness::Session) -> Result<SilSource> {
        let mailbox = Arc::new(Mailbox::default());
        let absorber = Mutex::new(Absorber::default());
        let m = Arc::clone(&mailbox);
        session.real_time = true;
        session.observer = Some(harness::LinkObserver(Arc::new(
            move |msg: &DeviceToHost| {
                if let Ok(mut a) = absorber.lock() {
                    a.absorb(msg.clone(), &m);
                }
            },
        )));
        let thread =
            std::thread::Builder::new()
                .name("sil".into())
                .spawn(move || -> Result<()> {
                    let run = harness::run(&setup, &session)?;
                    match run.stopped {
                        Some(why) => Err(anyhow!("the SIL run stopped: {why}")),
                        None => Ok(()),
                    }
                })?;
        Ok(SilSource {
            mailbox,
            thread: Some(thread),
            last_tick: None,
        })
    }
}

impl Source for SilSource {
    fn latest(&mut self, timeout: Duration) -> Result<Option<Sample>> {
        if self.thread.as_ref().is_some_and(|t| t.is_finished())
            && let Some(t) = self.thread.take()
        {
            t.join().map_err(|_| anyhow!("the SIL thread panicked"))??;
            return Err(anyhow!("the SIL run is over"));
        }
        self.mailbox.newer(&mut self.last_tick, timeout)
    }

    fn stats(&self) -> LoopStats {
        self.mailbox.stats()
    }
}
