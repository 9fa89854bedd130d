//! Where the display's telemetry comes from: the [`Source`] trait and the serial-link source.
//!
//! A source yields [`Sample`]s (tip, contact set S with the forces `f_S` on the tissue, the
//! force rendered on the tool, safety state) at whatever rate it has them; the display takes the
//! newest one per frame. Sources: the virtual device ([`crate::virtual_device`], the firmware's
//! loop on the PC), a device on a serial port ([`SerialSource`], bank-format link frames over
//! the device-link client [`crate::link`]), and the QEMU image through the plant simulator
//! ([`crate::sil::source::SilSource`], its telemetry over the emulated USART: the same frames a
//! board sends).

use crate::link::DeviceLink;
use anyhow::{Result, anyhow};
use bank_format::{DeviceToHost, FaultReason, HostToDevice, Mode, ResetCause, State};
use firmware::tick::Contacts;
use std::sync::{Arc, Condvar, Mutex};
use std::time::{Duration, Instant};

/// One telemetry sample, in the bank's frame (m, N).
#[derive(Debug, Clone, PartialEq)]
pub struct Sample {
    /// Device tick number.
    pub tick: u32,
    /// Safety state.
    pub state: State,
    /// Latched fault, if any.
    pub fault: Option<FaultReason>,
    /// Tool tip, m.
    pub tip_m: [f32; 3],
    /// Contact set S (bank node indices) and the forces on the tissue `f_S`, N.
    pub contacts: Contacts,
    /// Where the contact is on the bank's collision surface (protocol 6), for a sampled
    /// scene's display fields.
    pub contact_point: Option<bank_format::ContactPoint>,
    /// Force rendered on the tool, N.
    pub tool_force_n: [f32; 3],
    /// Rendering mode.
    pub mode: Mode,
    /// Motor currents commanded, A.
    pub currents_a: [f32; 3],
}

/// Loop timing as measured by the source, when it can measure it.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize)]
pub struct LoopStats {
    /// Ticks per second of wall time since the start.
    pub tick_rate_hz: f64,
    /// Largest lateness of a tick start behind its schedule, µs (`None` when unknown).
    pub max_jitter_us: Option<f64>,
    /// 99th percentile of that lateness, µs (10 µs resolution; `None` when unknown).
    pub p99_jitter_us: Option<f64>,
    /// Largest tool force seen on any tick (not only the sampled ones), N.
    pub peak_force_n: f64,
    /// Faults raised so far.
    pub faults: u32,
    /// Whether the loop thread runs with real-time priority (virtual device only).
    pub realtime: bool,
    /// Why the device last started, as it reported (after its `Hello`; `None` until then,
    /// and for sources without a reset register).
    pub reset_cause: Option<ResetCause>,
}

/// A telemetry stream.
pub trait Source: Send {
    /// The newest sample, waiting at most `timeout` for one newer than the last returned;
    /// `Ok(None)` when nothing new arrived. An error means the source is gone.
    fn latest(&mut self, timeout: Duration) -> Result<Option<Sample>>;

    /// Loop timing so far.
    fn stats(&self) -> LoopStats;

    /// A handle that points the tool at joint values `[pitch (rad), yaw (rad), insertion (m)]`
    /// (for the mouse or a script); `None` when a real hand holds the device.
    fn steering(&self) -> Option<Steering> {
        None
    }
}

/// Points the tool at joint values `[pitch, yaw, insertion]` (rad, rad, m).
pub type Steering = Arc<dyn Fn([f64; 3]) + Send + Sync>;

#[derive(Default)]
struct Published {
    sample: Option<Sample>,
    stats: LoopStats,
}

/// The newest sample and stats of a source thread, for readers that must never hold it up.
#[derive(Default)]
pub struct Mailbox {
    published: Mutex<Published>,
    fresh: Condvar,
}

impl Mailbox {
    /// Replaces the newest sample and the stats.
    pub fn publish(&self, sample: Sample, stats: LoopStats) {
        if let Ok(mut p) = self.published.lock() {
            p.sample = Some(sample);
            p.stats = stats;
        }
        self.fresh.notify_all();
    }

    /// Replaces the stats only.
    pub fn publish_stats(&self, stats: LoopStats) {
        if let Ok(mut p) = self.published.lock() {
            p.stats = stats;
        }
    }

    /// The newest sample if its tick differs from `*last`, waiting at most `timeout`; `*last`
    /// becomes that sample's tick.
    pub fn newer(&self, last: &mut Option<u32>, timeout: Duration) -> Result<Option<Sample>> {
        let poisoned = || anyhow!("the source thread panicked");
        let guard = self.published.lock().map_err(|_| poisoned())?;
        let seen = *last;
        let (guard, _) = self
            .fresh
            .wait_timeout_while(guard, timeout, |p| {
                p.sample.as_ref().map(|s| s.tick) == seen
            })
            .map_err(|_| poisoned())?;
        let s = guard.sample.clone().filter(|s| Some(s.tick) != seen);
        if let Some(s) = &s {
            *last = Some(s.tick);
        }
        Ok(s)
    }

    /// The stats.
    pub fn stats(&self) -> LoopStats {
        self.published.lock().map(|p| p.stats).unwrap_or_default()
    }
}

/// `--source` values.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum SourceSpec {
    /// The firmware loop on the PC.
    Virtual,
    /// The QEMU firmware image through the plant simulator.
    Sil,
    /// A device on a serial port.
    Serial(String),
}

impl std::str::FromStr for SourceSpec {
    type Err = String;
    fn from_str(s: &str) -> Result<SourceSpec, String> {
        match s {
            "virtual" => Ok(SourceSpec::Virtual),
            "sil" => Ok(SourceSpec::Sil),
            _ => match s.strip_prefix("serial:") {
                Some(port) if !port.is_empty() => Ok(SourceSpec::Serial(port.to_string())),
                _ => Err(format!(
                    "unknown source {s:?}: expected virtual, sil or serial:<port>"
                )),
            },
        }
    }
}

/// A device on a serial port: the link thread ([`DeviceLink`]) decodes `DeviceToHost::Telemetry`
/// frames, sends a heartbeat every 2 ms (the firmware's link-silence watchdog expects one within
/// the bank's `link_timeout_ms`) and the commands given to [`SerialSource::command`].
pub struct SerialSource {
    link: DeviceLink,
    mailbox: Arc<Mailbox>,
    last_tick: Option<u32>,
}

impl SerialSource {
    /// Opens `port` at `baud`, greets the device and checks its identity
    /// ([`crate::link::await_identity`], [`crate::link::check_identity`]): the device must
    /// speak [`bank_format::PROTOCOL_VERSION`] and run the bank whose CRC is `bank_crc` (the
    /// bank of `scene`, the scene displayed), else the error says what to reflash.
    pub fn open(port: &str, baud: u32, bank_crc: u32, scene: &str) -> Result<SerialSource> {
        let mailbox = Arc::new(Mailbox::default());
        let m = Arc::clone(&mailbox);
        let mut absorber = Absorber::default();
        let link = DeviceLink::open(port, baud, bank_crc, scene, move |msg| {
            absorber.absorb(msg, &m)
        })?;
        Ok(SerialSource {
            link,
            mailbox,
            last_tick: None,
        })
    }

    /// Sends `msg` to the device (from the link thread, before its next heartbeat); an error
    /// when the link has stopped (the port closed or failed).
    pub fn command(&self, msg: HostToDevice) -> Result<()> {
        self.link.command(msg)
    }
}

impl Source for SerialSource {
    fn latest(&mut self, timeout: Duration) -> Result<Option<Sample>> {
        self.mailbox.newer(&mut self.last_tick, timeout)
    }

    fn stats(&self) -> LoopStats {
        self.mailbox.stats()
    }
}

/// Turns a device's link messages into samples and stats (serial and SIL sources). The tool
/// force is telemetry's `tool_force_n`, the force the firmware rendered (protocol 4).
#[derive(Default)]
pub(crate) struct Absorber {
    first_tick: Option<(u32, Instant)>,
    stats: LoopStats,
}

impl Absorber {
    pub(crate) fn absorb(&mut self, msg: DeviceToHost, mailbox: &Mailbox) {
        match msg {
            DeviceToHost::Telemetry(t) => {
                let now = Instant::now();
                let (t0, i0) = *self.first_tick.get_or_insert((t.tick, now));
                if now > i0 {
                    self.stats.tick_rate_hz =
                        f64::from(t.tick.wrapping_sub(t0)) / (now - i0).as_secs_f64();
                }
                let tool_force_n = t.tool_force_n;
                let f = tool_force_n.iter().map(|x| x * x).sum::<f32>().sqrt();
                self.stats.peak_force_n = self.stats.peak_force_n.max(f64::from(f));
                let sample = Sample {
                    tick: t.tick,
                    state: t.state,
                    fault: t.fault,
                    tip_m: t.tip_m,
                    contacts: t.contacts,
                    contact_point: t.contact_point,
                    tool_force_n,
                    mode: t.mode,
                    currents_a: t.currents_a,
                };
                mailbox.publish(sample, self.stats);
            }
            DeviceToHost::Fault { .. } => {
                self.stats.faults += 1;
                mailbox.publish_stats(self.stats);
            }
            DeviceToHost::Reset { cause } => {
                self.stats.reset_cause = Some(cause);
                mailbox.publish_stats(self.stats);
            }
            DeviceToHost::Hello { .. } | DeviceToHost::Plant { .. } => {}
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn source_names_parse() {
        assert_eq!("virtual".parse(), Ok(SourceSpec::Virtual));
        assert_eq!("sil".parse(), Ok(SourceSpec::Sil));
        assert_eq!(
            "serial:/dev/ttyACM0".parse(),
            Ok(SourceSpec::Serial("/dev/ttyACM0".into()))
        );
        assert!("serial:".parse::<SourceSpec>().is_err());
        assert!("qemu".parse::<SourceSpec>().unwrap_err().contains("qemu"));
    }
}
