//! The device-link client: a device's serial port, the bank-format link frames over it, the
//! greeting and identity check, and a link thread that keeps the device's link-silence watchdog
//! fed.
//!
//! [`open_device_port`] finds and opens the board's port, [`await_identity`] greets the device
//! and reads its [`Identity`], [`check_identity`] refuses a device that does not run the
//! expected bank (`host flash` uses these three, and [`disarm_connected`] before it halts the
//! chip); [`DeviceLink`] does all of it and then runs a
//! thread that sends a heartbeat every 2 ms and the commands given to it, and hands every
//! message the device sends to a callback (the display's serial source,
//! [`crate::display::source::SerialSource`]). [`crate::device::Session`] is a bring-up
//! session on it (`host device`).

use anyhow::{Context, Result, anyhow, bail};
use bank_format::{
    DeviceToHost, FrameDecoder, HostToDevice, MAX_FRAME, PROTOCOL_VERSION, encode_frame,
};
use std::io::{ErrorKind, Read, Write};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{Receiver, Sender};
use std::sync::{Arc, mpsc};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// How long [`DeviceLink::open`] waits for the device's `Hello`.
const HELLO_TIMEOUT: Duration = Duration::from_secs(3);

/// Interval between heartbeats (the firmware's link-silence watchdog expects one within the
/// bank's `link_timeout_ms`, default [`bank_format::DEFAULT_LINK_TIMEOUT_MS`]).
const HEARTBEAT: Duration = Duration::from_millis(2);

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

/// An open link to a device: a thread reads its frames, sends a heartbeat every 2 ms (the
/// firmware's link-silence watchdog expects one within the bank's `link_timeout_ms`) and the
/// commands given to [`DeviceLink::command`]; it asks for real-time scheduling
/// ([`DeviceLink::realtime`]). Dropping it stops the thread.
pub struct DeviceLink {
    commands: Sender<HostToDevice>,
    stop: Arc<AtomicBool>,
    realtime: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
}

impl DeviceLink {
    /// Opens `port` at `baud`, greets the device and checks its identity ([`await_identity`],
    /// [`check_identity`]): the device must speak [`PROTOCOL_VERSION`] and run the bank whose
    /// CRC is `bank_crc` (`bank` names it in errors, e.g. "the bank of host/scenes/liver.toml"),
    /// else the error says what to reflash. Then the link thread starts; it hands every message
    /// the device sends to `on_message`, until the port closes or fails or the link is dropped.
    pub fn open(
        port: &str,
        baud: u32,
        bank_crc: u32,
        bank: &str,
        on_message: impl FnMut(DeviceToHost) + Send + 'static,
    ) -> Result<DeviceLink> {
        let mut handle = serialport::new(port, baud)
            .timeout(Duration::from_millis(2))
            .open()
            .with_context(|| format!("cannot open serial port {port}"))?;
        let hello = await_identity(&mut *handle, port, HELLO_TIMEOUT)?;
        check_identity(&hello, bank_crc, bank)?;
        let stop = Arc::new(AtomicBool::new(false));
        let (commands, pending) = mpsc::channel();
        let thread = LinkThread {
            port: handle,
            decoder: FrameDecoder::new(),
            pending,
        };
        let st = Arc::clone(&stop);
        let realtime = Arc::new(AtomicBool::new(false));
        let rt = Arc::clone(&realtime);
        let thread = std::thread::Builder::new()
            .name("serial-link".into())
            .spawn(move || {
                // The heartbeat must not wait behind the desktop's other work: a stall longer
                // than the bank's link timeout faults the device (`host bench heartbeat`).
                rt.store(crate::realtime::request(), Ordering::Relaxed);
                thread.run(on_message, &st);
            })?;
        Ok(DeviceLink {
            commands,
            stop,
            realtime,
            thread: Some(thread),
        })
    }

    /// Whether the link thread got real-time scheduling (SCHED_FIFO: needs CAP_SYS_NICE or an
    /// rtprio limit; without it, it runs at normal priority and a busy desktop delays its
    /// heartbeats more, `docs/scenes-and-banks.md`, "Link timeout"). Known once the thread
    /// started.
    pub fn realtime(&self) -> bool {
        self.realtime.load(Ordering::Relaxed)
    }

    /// Sends `msg` to the device (from the link thread, before its next heartbeat); an error
    /// when the link has stopped (the port closed or failed).
    pub fn command(&self, msg: HostToDevice) -> Result<()> {
        self.commands
            .send(msg)
            .map_err(|e| anyhow!("the serial link has stopped; {:?} not sent", e.0))
    }
}

impl Drop for DeviceLink {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// Opens a session on `port` (named `name` in errors): a frame delimiter (0x00), which ends
/// whatever partial frame the device's decoder still holds from an earlier session, then
/// `HostToDevice::Hello`; waits up to `timeout` for the device's `Hello`, sending heartbeats
/// meanwhile; other messages are skipped.
pub fn await_identity<P: Read + Write + ?Sized>(
    port: &mut P,
    name: &str,
    timeout: Duration,
) -> Result<Identity> {
    port.write_all(&[0])
        .and_then(|()| send(port, &HostToDevice::Hello))
        .with_context(|| format!("{name}: cannot send Hello"))?;
    let mut decoder = FrameDecoder::<DeviceToHost>::new();
    let mut buf = [0u8; 512];
    let end = Instant::now() + timeout;
    let mut last_heartbeat = Instant::now();
    while Instant::now() < end {
        if last_heartbeat.elapsed() >= HEARTBEAT {
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

/// What [`disarm_connected`] did.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Disarmed {
    /// No device connected: no port given and none with [`BOARD_USB_ID`], or the port given
    /// does not exist. The text says which.
    NoDevice(String),
    /// `Disarm` was sent on `port`; `state` is the device's state in the first telemetry
    /// after it that is not armed, `None` when none came within the timeout (a firmware
    /// that speaks another protocol, or none running).
    Sent {
        /// The port.
        port: String,
        /// The state the device then reported.
        state: Option<bank_format::State>,
    },
}

/// Sends `Disarm` to the device on `port`, or on the one USB port with [`BOARD_USB_ID`], if
/// one is connected, and waits up to `timeout` for telemetry that is not armed (before
/// `host flash` halts the chip: the motors are then off by the firmware's own hand). The frame
/// goes after a 0x00, which ends any half frame the device holds. A port that exists but
/// cannot be opened (held by another program, no permission) is an error: the device there
/// cannot be disarmed.
pub fn disarm_connected(port: Option<&str>, timeout: Duration) -> Result<Disarmed> {
    let name = match port {
        Some(p) => p.to_string(),
        None => match board_port()? {
            Some(p) => p,
            None => {
                return Ok(Disarmed::NoDevice(format!(
                    "no USB serial port with the board's id {:04x}:{:04x}",
                    BOARD_USB_ID.0, BOARD_USB_ID.1
                )));
            }
        },
    };
    let mut handle = match serialport::new(&name, 115_200)
        .timeout(Duration::from_millis(2))
        .open()
    {
        Ok(h) => h,
        Err(e)
            if e.kind() == serialport::ErrorKind::NoDevice
                || e.kind() == serialport::ErrorKind::Io(ErrorKind::NotFound) =>
        {
            return Ok(Disarmed::NoDevice(format!("no device on {name} ({e})")));
        }
        Err(e) => bail!(
            "cannot open {name} to disarm the device there ({e}): close the program holding \
             it (host device, host demo) or give the right port with --port"
        ),
    };
    handle
        .write_all(&[0])
        .and_then(|()| send(&mut *handle, &HostToDevice::Disarm).map_err(std::io::Error::other))
        .with_context(|| format!("{name}: cannot send Disarm"))?;
    let mut decoder = FrameDecoder::<DeviceToHost>::new();
    let mut buf = [0u8; 512];
    let end = Instant::now() + timeout;
    while Instant::now() < end {
        let n = match handle.read(&mut buf) {
            Ok(0) => break,
            Ok(n) => n,
            Err(e) if e.kind() == ErrorKind::TimedOut => continue,
            Err(_) => break,
        };
        for msg in decoder.feed_slice(buf.get(..n).unwrap_or(&[])).flatten() {
            if let DeviceToHost::Telemetry(t) = msg
                && t.state != bank_format::State::Armed
            {
                return Ok(Disarmed::Sent {
                    port: name,
                    state: Some(t.state),
                });
            }
        }
    }
    Ok(Disarmed::Sent {
        port: name,
        state: None,
    })
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

/// Writes `msg` to `port` as one link frame.
fn send<W: Write + ?Sized>(port: &mut W, msg: &HostToDevice) -> std::io::Result<()> {
    let mut buf = [0u8; MAX_FRAME];
    // Every host message fits a frame (bank-format's tests check the largest).
    let frame = encode_frame(msg, &mut buf)
        .map_err(|e| std::io::Error::other(format!("encoding {msg:?}: {e:?}")))?;
    port.write_all(frame)
}

/// How the device sees the host's heartbeats ([`heartbeat_intervals`]).
#[derive(Clone, Debug)]
pub struct HeartbeatRun {
    /// Time between consecutive heartbeats' arrivals.
    pub intervals: Vec<Duration>,
    /// Busy threads that ran meanwhile.
    pub load_threads: usize,
    /// Whether the stand-in device ran with real-time scheduling (SCHED_FIFO), so that the
    /// intervals are the host link's own and not the stand-in's late reads.
    pub stand_in_realtime: bool,
    /// Whether the link thread ran with real-time scheduling ([`DeviceLink::realtime`]).
    pub link_realtime: bool,
}

impl HeartbeatRun {
    /// The interval at quantile `q` in `[0, 1]` (nearest rank: the smallest interval that at
    /// least `q` of them do not exceed); `None` without intervals.
    pub fn quantile(&self, q: f64) -> Option<Duration> {
        let mut sorted = self.intervals.clone();
        sorted.sort_unstable();
        let rank = (q.clamp(0.0, 1.0) * sorted.len() as f64).ceil() as usize;
        sorted.get(rank.saturating_sub(1)).copied()
    }

    /// How many intervals exceed `limit`.
    pub fn longer_than(&self, limit: Duration) -> usize {
        self.intervals.iter().filter(|&&d| d > limit).count()
    }
}

/// The bank CRC the heartbeat bench's stand-in device announces.
const BENCH_BANK_CRC: u32 = 0x4845_4152;

/// Runs the host's link exactly as `host demo --source serial:...` and `host device` run it
/// ([`DeviceLink::open`]: the greeting, then the link thread's heartbeats) for `duration`
/// against a stand-in device on a pseudo-terminal, which answers `Hello`, sends 100 Hz
/// telemetry like the firmware and records when each heartbeat arrives; meanwhile
/// `load_threads` threads spin to load the CPU. The stand-in asks for real-time scheduling
/// (as the virtual device's loop does; [`HeartbeatRun::stand_in_realtime`] says whether it got
/// it): with it, its reads are not delayed by the load and the intervals are the link
/// thread's own; without it they also hold the stand-in's delays, an upper bound. A device on
/// USB adds its bus's polling (1 ms frames on full speed).
pub fn heartbeat_intervals(duration: Duration, load_threads: usize) -> Result<HeartbeatRun> {
    use serialport::SerialPort;
    let (mut device, host_end) = serialport::TTYPort::pair()
        .context("cannot open a pseudo-terminal for the stand-in device")?;
    let name = host_end
        .name()
        .ok_or_else(|| anyhow!("the pseudo-terminal has no name"))?;
    device.set_timeout(Duration::from_millis(1))?;
    let stop = Arc::new(AtomicBool::new(false));
    let load: Vec<JoinHandle<()>> = (0..load_threads)
        .map(|_| {
            let stop = Arc::clone(&stop);
            std::thread::spawn(move || {
                while !stop.load(Ordering::Relaxed) {
                    std::hint::spin_loop();
                }
            })
        })
        .collect();
    let st = Arc::clone(&stop);
    let stand_in = std::thread::Builder::new()
        .name("stand-in-device".into())
        .spawn(move || {
            let realtime = crate::realtime::request();
            stand_in_device(&mut device, &st).map(|arrivals| (arrivals, realtime))
        })?;
    let link = DeviceLink::open(&name, 115_200, BENCH_BANK_CRC, "the bench's bank", |_| {});
    if link.is_ok() {
        std::thread::sleep(duration);
    }
    let link_realtime = link.as_ref().is_ok_and(DeviceLink::realtime);
    // Dropping the link stops its thread; then the stand-in and the load stop.
    let opened = link.map(drop);
    stop.store(true, Ordering::Relaxed);
    for t in load {
        let _ = t.join();
    }
    let arrivals = stand_in
        .join()
        .map_err(|_| anyhow!("the stand-in device panicked"))?;
    drop(host_end);
    opened?;
    let (arrivals, stand_in_realtime) = arrivals?;
    let intervals = arrivals.windows(2).map(|w| w[1] - w[0]).collect();
    Ok(HeartbeatRun {
        intervals,
        load_threads,
        stand_in_realtime,
        link_realtime,
    })
}

/// The heartbeat bench's device: answers `Hello`, sends telemetry every 10 ms, and returns when
/// each heartbeat arrived once `stop` is set.
fn stand_in_device(port: &mut serialport::TTYPort, stop: &AtomicBool) -> Result<Vec<Instant>> {
    let mut decoder = FrameDecoder::<HostToDevice>::new();
    let mut arrivals = Vec::new();
    let mut buf = [0u8; 512];
    let mut next_telemetry = Instant::now();
    let mut tick = 0u32;
    while !stop.load(Ordering::Relaxed) {
        if Instant::now() >= next_telemetry {
            tick = tick.wrapping_add(10);
            send_device(port, &stand_in_telemetry(tick))?;
            next_telemetry += Duration::from_millis(10);
        }
        let n = match port.read(&mut buf) {
            Ok(n) => n,
            Err(e) if e.kind() == ErrorKind::TimedOut => continue,
            Err(e) => return Err(e).context("the stand-in device's read failed"),
        };
        let now = Instant::now();
        let msgs: Vec<HostToDevice> = decoder
            .feed_slice(buf.get(..n).unwrap_or(&[]))
            .filter_map(Result::ok)
            .collect();
        for msg in msgs {
            match msg {
                HostToDevice::Heartbeat => arrivals.push(now),
                HostToDevice::Hello => send_device(
                    port,
                    &DeviceToHost::Hello {
                        protocol: PROTOCOL_VERSION,
                        bank_crc: Some(BENCH_BANK_CRC),
                        scene_id: 0,
                        node_count: 0,
                    },
                )?,
                _ => {}
            }
        }
    }
    Ok(arrivals)
}

/// A telemetry frame of the firmware's usual size (one contact).
fn stand_in_telemetry(tick: u32) -> DeviceToHost {
    let mut contacts = bank_format::heapless::Vec::new();
    let _ = contacts.push(bank_format::Contact {
        node: 1,
        force_n: [0.1, 0.2, 0.3],
    });
    DeviceToHost::Telemetry(bank_format::Telemetry {
        tick,
        state: bank_format::State::Armed,
        mode: bank_format::Mode::Render,
        fault: None,
        tip_m: [0.01, 0.02, 0.09],
        contacts,
        contact_point: None,
        currents_a: [0.1, 0.2, 0.3],
        tool_force_n: [0.1, 0.2, 0.3],
        dropped_load: 0.0,
        counters: bank_format::Counters::default(),
    })
}

/// Writes a device message as one frame.
fn send_device<W: Write + ?Sized>(port: &mut W, msg: &DeviceToHost) -> Result<()> {
    let mut buf = [0u8; MAX_FRAME];
    let frame = encode_frame(msg, &mut buf).map_err(|e| anyhow!("encoding {msg:?}: {e:?}"))?;
    port.write_all(frame)?;
    Ok(())
}

/// The link thread's state.
struct LinkThread {
    port: Box<dyn serialport::SerialPort>,
    decoder: FrameDecoder<DeviceToHost>,
    /// Commands waiting to be sent.
    pending: Receiver<HostToDevice>,
}

impl LinkThread {
    fn run(mut self, mut on_message: impl FnMut(DeviceToHost), stop: &AtomicBool) {
        let mut buf = [0u8; 512];
        let mut last_heartbeat = Instant::now();
        while !stop.load(Ordering::Relaxed) {
            while let Ok(msg) = self.pending.try_recv() {
                if send(&mut *self.port, &msg).is_err() {
                    return;
                }
            }
            if last_heartbeat.elapsed() >= HEARTBEAT {
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
                    msgs.into_iter().for_each(&mut on_message);
                }
                Err(e) if e.kind() == ErrorKind::TimedOut => {}
                Err(_) => return,
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A port that records what is written and answers every read with `reply` once.
    struct FakePort {
        written: Vec<u8>,
        reply: Vec<u8>,
    }

    impl Read for FakePort {
        fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
            if self.reply.is_empty() {
                return Err(ErrorKind::TimedOut.into());
            }
            let n = self.reply.len().min(buf.len());
            buf[..n].copy_from_slice(&self.reply[..n]);
            self.reply.drain(..n);
            Ok(n)
        }
    }

    impl Write for FakePort {
        fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
            self.written.extend_from_slice(buf);
            Ok(buf.len())
        }
        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }

    /// A session starts with a frame delimiter, then `Hello`: a device whose decoder still
    /// holds half a frame from before (a cable pulled mid-frame) drops that half at the 0x00
    /// and decodes the `Hello`.
    #[test]
    fn a_session_leads_with_a_delimiter_so_a_torn_frame_cannot_swallow_hello() {
        let hello = DeviceToHost::Hello {
            protocol: PROTOCOL_VERSION,
            bank_crc: Some(7),
            scene_id: 1,
            node_count: 2,
        };
        let mut buf = [0u8; MAX_FRAME];
        let mut port = FakePort {
            written: Vec::new(),
            reply: encode_frame(&hello, &mut buf).unwrap().to_vec(),
        };
        let id = await_identity(&mut port, "fake", Duration::from_secs(1)).unwrap();
        assert_eq!(id.bank_crc, Some(7));
        assert_eq!(port.written[0], 0x00, "{:02x?}", port.written);

        let mut device = FrameDecoder::<HostToDevice>::new();
        let torn = encode_frame(&HostToDevice::Disarm, &mut buf)
            .unwrap()
            .to_vec();
        assert!(device.feed_slice(&torn[..torn.len() / 2]).next().is_none());
        let got: Vec<_> = device.feed_slice(&port.written).collect();
        assert!(got[0].is_err(), "the torn frame is dropped: {got:?}");
        assert_eq!(got[1], Ok(HostToDevice::Hello));
    }

    /// Nearest-rank quantiles of 1, 2, ..., 1000 ms.
    #[test]
    fn heartbeat_quantiles_are_nearest_rank() {
        let run = HeartbeatRun {
            intervals: (1..=1000).rev().map(Duration::from_millis).collect(),
            load_threads: 0,
            stand_in_realtime: false,
            link_realtime: false,
        };
        let ms = |q| run.quantile(q).unwrap().as_millis();
        assert_eq!(
            [ms(0.5), ms(0.99), ms(0.999), ms(1.0)],
            [500, 990, 999, 1000]
        );
        assert_eq!(ms(0.0), 1);
        assert_eq!(run.longer_than(Duration::from_millis(990)), 10);
        let empty = HeartbeatRun {
            intervals: Vec::new(),
            load_threads: 0,
            stand_in_realtime: false,
            link_realtime: false,
        };
        assert_eq!(empty.quantile(0.5), None);
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
