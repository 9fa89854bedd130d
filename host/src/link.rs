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
//! [`crate::display::source::SerialSource`], and so `host device`).

use anyhow::{Context, Result, anyhow, bail};
use bank_format::{
    DeviceToHost, FrameDecoder, HostToDevice, MAX_FRAME, PROTOCOL_VERSION, encode_frame,
};
use std::io::{ErrorKind, Read};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{Receiver, Sender};
use std::sync::{Arc, mpsc};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// How long [`DeviceLink::open`] waits for the device's `Hello`.
const HELLO_TIMEOUT: Duration = Duration::from_secs(3);

/// Interval between heartbeats (the firmware's link-silence watchdog expects one within 10
/// ticks).
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
/// firmware's link-silence watchdog expects one within 10 ticks) and the commands given to
/// [`DeviceLink::command`]. Dropping it stops the thread.
pub struct DeviceLink {
    commands: Sender<HostToDevice>,
    stop: Arc<AtomicBool>,
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
        let thread = std::thread::Builder::new()
            .name("serial-link".into())
            .spawn(move || thread.run(on_message, &st))?;
        Ok(DeviceLink {
            commands,
            stop,
            thread: Some(thread),
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

impl Drop for DeviceLink {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
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
fn send(port: &mut dyn serialport::SerialPort, msg: &HostToDevice) -> Result<()> {
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
