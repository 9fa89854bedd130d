//! Where the display's telemetry comes from: the [`Source`] trait and the serial-link source.
//!
//! A source yields [`Sample`]s (tip, contact set S with the forces `f_S` on the tissue, the
//! force rendered on the tool, safety state) at whatever rate it has them; the display takes the
//! newest one per frame. Sources: the virtual device ([`crate::virtual_device`], the firmware's
//! loop on the PC), a device on a serial port ([`SerialSource`], bank-format link frames), and
//! the QEMU image through the plant simulator ([`crate::sil::source::SilSource`], its telemetry
//! over the emulated USART: the same frames a board sends).

use anyhow::{Context, Result, anyhow, bail};
use bank_format::{
    DeviceToHost, FaultReason, FrameDecoder, HostToDevice, MAX_FRAME, Mode, PROTOCOL_VERSION,
    ResetCause, State, encode_frame,
};
use firmware::tick::Contacts;
use std::io::{ErrorKind, Read};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Condvar, Mutex};
use std::thread::JoinHandle;
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

/// A device on a serial port: a reader thread decodes `DeviceToHost::Telemetry` frames,
/// sends a heartbeat every 2 ms (the firmware's link-silence watchdog expects one within 10
/// ticks) and the commands given to [`SerialSource::command`].
pub struct SerialSource {
    mailbox: Arc<Mailbox>,
    commands: std::sync::mpsc::Sender<HostToDevice>,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
    last_tick: Option<u32>,
}

impl SerialSource {
    /// Opens `port` at `baud`, greets the device and checks its identity ([`await_identity`],
    /// [`check_identity`]): the device must speak [`PROTOCOL_VERSION`] and run the bank whose
    /// CRC is `bank_crc` (the bank of `scene`, the scene displayed), else the error says what to
    /// reflash.
    pub fn open(port: &str, baud: u32, bank_crc: u32, scene: &str) -> Result<SerialSource> {
        let mut handle = serialport::new(port, baud)
            .timeout(Duration::from_millis(2))
            .open()
            .with_context(|| format!("cannot open serial port {port}"))?;
        let hello = await_identity(&mut *handle, port, HELLO_TIMEOUT)?;
        check_identity(&hello, bank_crc, scene)?;
        let mailbox = Arc::new(Mailbox::default());
        let stop = Arc::new(AtomicBool::new(false));
        let (commands, pending) = std::sync::mpsc::channel();
        let link = Link {
            port: handle,
            decoder: FrameDecoder::new(),
            absorber: Absorber::default(),
            pending,
        };
        let (m, st) = (Arc::clone(&mailbox), Arc::clone(&stop));
        let thread = std::thread::Builder::new()
            .name("serial-link".into())
            .spawn(move || link.run(&m, &st))?;
        Ok(SerialSource {
            mailbox,
            commands,
            stop,
            thread: Some(thread),
            last_tick: None,
        })
    }

    /// Sends `msg` to the device (from the link thread, before its next heartbeat); an error
    /// when the link has stopped (the port closed or failed).
    pub fn command(&self, msg: HostToDevice) -> Result<()> {
        self.commands
            .send(msg)
            .map_err(|e| anyhow!("the serial link has stopped; {:?} not sent", e.0))
    }
}

/// How long [`SerialSource::open`] waits for the device's `Hello`.
const HELLO_TIMEOUT: Duration = Duration::from_secs(3);

/// The USB vendor and product id of the board's CDC-ACM port (`usb_vid_pid` in
/// firmware/board/src/board.rs; a test keeps the two equal).
pub const BOARD_USB_ID: (u16, u16) = (0x1209, 0x0001);

/// What a device says it is ([`DeviceToHost::Hello`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Identity {
    /// Its link protocol version.
    pub protocol: u16,
    /// CRC of the valid bank it runs, `None` without one.
    pub bank_crc: Option<u32>,
    /// The bank's scene id.
    pub scene_id: u64,
    /// Nodes in the bank's R.
    pub node_count: u16,
}

/// Sends `HostToDevice::Hello` on `port` (named `name` in errors) and waits up to `timeout`
/// for the device's `Hello`, sending heartbeats meanwhile; other messages are skipped.
pub fn await_identity(
    port: &mut dyn serialport::SerialPort,
    name: &str,
    timeout: Duration,
) -> Result<Identity> {
    send(port, &HostToDevice::Hello).with_context(|| format!("{name}: cannot send Hello"))?;
    let mut decoder = FrameDecoder::<DeviceToHost>::new();
    let mut buf = [0u8; 512];
    let end = Instant::now() + timeout;
    let mut last_heartbeat = Instant::now();
    while Instant::now() < end {
        if last_heartbeat.elapsed() >= Duration::from_millis(2) {
            send(port, &HostToDevice::Heartbeat)
                .with_context(|| format!("{name}: cannot send a heartbeat"))?;
            last_heartbeat = Instant::now();
        }
        let n = match port.read(&mut buf) {
            Ok(0) => bail!("{name}: the port closed before the device said Hello"),
            Ok(n) => n,
            Err(e) if e.kind() == ErrorKind::TimedOut => continue,
            Err(e) => return Err(e).with_context(|| format!("{name}: read failed")),
        };
        for msg in decoder.feed_slice(buf.get(..n).unwrap_or(&[])).flatten() {
            if let DeviceToHost::Hello {
                protocol,
                bank_crc,
                scene_id,
                node_count,
            } = msg
            {
                return Ok(Identity {
                    protocol,
                    bank_crc,
                    scene_id,
                    node_count,
                });
            }
        }
    }
    bail!(
        "{name}: no Hello from the device within {:.1} s (is this the device's port, and its \
         firmware running?)",
        timeout.as_secs_f64()
    )
}

/// Refuses a device that does not speak [`PROTOCOL_VERSION`] or does not run the bank whose
/// CRC is `bank_crc` (`bank`, e.g. "the bank of host/scenes/liver.toml"), saying what to
/// reflash.
pub fn check_identity(device: &Identity, bank_crc: u32, bank: &str) -> Result<()> {
    if device.protocol != PROTOCOL_VERSION {
        bail!(
            "the device speaks link protocol {}, this host {PROTOCOL_VERSION}: reflash the \
             firmware built from this tree (host flash --scene S, or --bank F)",
            device.protocol
        );
    }
    match device.bank_crc {
        None => bail!(
            "the device has no valid bank: flash {bank} (host flash --bank-only --scene S or \
             --bank F)"
        ),
        Some(crc) if crc != bank_crc => bail!(
            "the device runs bank {crc:#010x} (scene id {:#x}, {} nodes), not {bank} \
             ({bank_crc:#010x}): reflash the bank (host flash --bank-only --scene S or --bank F)",
            device.scene_id,
            device.node_count
        ),
        Some(_) => Ok(()),
    }
}

/// Opens the device's serial port: `port` if given, else the one USB port with
/// [`BOARD_USB_ID`], retried until `timeout` (the device enumerates after its reset).
pub fn open_device_port(
    port: Option<&str>,
    timeout: Duration,
) -> Result<(Box<dyn serialport::SerialPort>, String)> {
    let end = Instant::now() + timeout;
    loop {
        let name = match port {
            Some(p) => Some(p.to_string()),
            None => board_port()?,
        };
        let last = match &name {
            Some(n) => match serialport::new(n, 115_200)
                .timeout(Duration::from_millis(2))
                .open()
            {
                Ok(h) => return Ok((h, n.clone())),
                Err(e) => format!("cannot open {n}: {e}"),
            },
            None => format!(
                "no USB serial port with the board's id {:04x}:{:04x}",
                BOARD_USB_ID.0, BOARD_USB_ID.1
            ),
        };
        if Instant::now() >= end {
            bail!(
                "{last} within {:.1} s of the reset (is the board's USB cable plugged in? give \
                 the port with --port)",
                timeout.as_secs_f64()
            );
        }
        std::thread::sleep(Duration::from_millis(200));
    }
}

/// The serial port with [`BOARD_USB_ID`], if exactly one; several are an error.
fn board_port() -> Result<Option<String>> {
    let ports = serialport::available_ports().context("cannot list the serial ports")?;
    let ours: Vec<String> = ports
        .into_iter()
        .filter(|p| {
            matches!(&p.port_type, serialport::SerialPortType::UsbPort(u)
                if (u.vid, u.pid) == BOARD_USB_ID)
        })
        .map(|p| p.port_name)
        .collect();
    match ours.as_slice() {
        [] => Ok(None),
        [one] => Ok(Some(one.clone())),
        many => bail!(
            "several ports have the board's USB id ({}): give one with --port",
            many.join(", ")
        ),
    }
}

impl Drop for SerialSource {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
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

fn send(port: &mut dyn serialport::SerialPort, msg: &HostToDevice) -> Result<()> {
    let mut buf = [0u8; MAX_FRAME];
    let frame = encode_frame(msg, &mut buf).map_err(|e| anyhow!("encoding {msg:?}: {e:?}"))?;
    port.write_all(frame)?;
    Ok(())
}

/// The serial reader thread's state.
struct Link {
    port: Box<dyn serialport::SerialPort>,
    decoder: FrameDecoder<DeviceToHost>,
    absorber: Absorber,
    /// Commands waiting to be sent.
    pending: std::sync::mpsc::Receiver<HostToDevice>,
}

/// Turns a device's link messages into samples and stats (serial and SIL sources). The tool
/// force is telemetry's `tool_force_n`, the force the firmware rendered (protocol 4).
#[derive(Default)]
pub(crate) struct Absorber {
    first_tick: Option<(u32, Instant)>,
    stats: LoopStats,
}

impl Link {
    fn run(mut self, mailbox: &Mailbox, stop: &AtomicBool) {
        let mut buf = [0u8; 512];
        let mut last_heartbeat = Instant::now();
        while !stop.load(Ordering::Relaxed) {
            while let Ok(msg) = self.pending.try_recv() {
                if send(&mut *self.port, &msg).is_err() {
                    return;
                }
            }
            if last_heartbeat.elapsed() >= Duration::from_millis(2) {
                if send(&mut *self.port, &HostToDevice::Heartbeat).is_err() {
                    return;
                }
                last_heartbeat = Instant::now();
            }
            match self.port.read(&mut buf) {
                Ok(0) => return,
                Ok(n) => {
                    let msgs: Vec<DeviceToHost> = self
                        .decoder
                        .feed_slice(buf.get(..n).unwrap_or(&[]))
                        .filter_map(|r| r.ok())
                        .collect();
                    msgs.into_iter()
                        .for_each(|m| self.absorber.absorb(m, mailbox));
                }
                Err(e) if e.kind() == ErrorKind::TimedOut => {}
                Err(_) => return,
            }
        }
    }
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

    /// The board's USB id here is the one the board image announces.
    #[test]
    fn board_usb_id_is_the_board_images() {
        let board =
            std::fs::read_to_string(crate::mcu::repo_root().join("firmware/board/src/board.rs"))
                .unwrap();
        let want = format!(
            "usb_vid_pid: ({:#06x}, {:#06x}),",
            BOARD_USB_ID.0, BOARD_USB_ID.1
        );
        assert!(board.contains(&want), "board.rs lacks {want:?}");
    }
}
