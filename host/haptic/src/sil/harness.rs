//! Runs the software-in-the-loop image under QEMU against the plant simulator.
//!
//! QEMU (`-M netduinoplus2`, an STM32F405) loads the firmware image as it would be flashed and
//! the bank file at the bank region's address (`-device loader,file=..,addr=..`, the address
//! [`bank_format::region::BANK_ORIGIN`] from `memory.x`).
//! Three channels connect it to this harness:
//!
//! - **plant** (lockstep): two named pipes in a temporary working directory, opened by the
//!   image through semihosting. Per tick the harness writes `HostToDevice::Plant { tick,
//!   encoder_counts }`, the image runs the tick and answers `DeviceToHost::Plant { tick,
//!   currents_a, .. }`, then the harness advances the gimbal 1 ms with those currents. The
//!   virtual CPU is stopped inside the semihosting call while the harness computes, so virtual
//!   time only advances with the image's instructions (`-icount shift=3,sleep=off`: 8 ns per
//!   instruction, idle time skipped) and every run is deterministic;
//! - **link**: USART1 on a TCP socket (`-serial tcp:..`), the same frames a board exchanges
//!   with its host (commands in, faults and decimated telemetry out). It is asynchronous like a
//!   real UART: the tick at which a command lands depends on wall-clock scheduling, so the
//!   harness records each tick's safety state instead of assuming one;
//! - **exit**: semihosting gives the image's exit code (0 after the harness closes the plant
//!   pipes) and its diagnostics on stderr.

use super::plant::{Gimbal, PlantParams, TICK_S};
use super::script::Trajectory;
use crate::trajectory::Script;
use anyhow::{Context, Result, bail};
use bank_format::region::BANK_ORIGIN;
use bank_format::{
    Bank, DeviceCalibration, DeviceToHost, FaultReason, FrameDecoder, FrameStats, HostToDevice,
    MAX_FRAME, PhaseCycles, State, Telemetry, decode_plant, encode_frame, encode_plant,
};
use std::fs::File;
use std::io::{Read, Write};
use std::net::{TcpListener, TcpStream};
use std::os::unix::fs::OpenOptionsExt;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// Instructions per 1 ms tick under `-icount shift=3` (8 ns each; see [`Session::icount_shift`]).
pub const INSTRUCTIONS_PER_TICK: u32 = 125_000;
/// Tick at which the default session homes the device (`ZeroEncoders`): the hand rests at the
/// home pose for the scripts' first 100 ms, and the firmware arms only once homed.
pub const HOME_TICK: u32 = 10;
/// Tick at which the default session arms the device.
pub const ARM_TICK: u32 = 20;

/// Where the pieces are.
#[derive(Clone, Debug)]
pub struct Setup {
    /// The QEMU binary.
    pub qemu: PathBuf,
    /// The firmware image (ELF).
    pub image: PathBuf,
    /// The bank file QEMU loads into the bank region.
    pub bank: PathBuf,
}

/// Something the harness sends on the link before answering a tick's plant frame.
#[derive(Clone, Debug, PartialEq)]
pub enum LinkSend {
    /// A command, framed.
    Command(HostToDevice),
    /// Raw bytes (corrupt or truncated frames for fault injection).
    Raw(Vec<u8>),
}

/// One run: the hand's script, its length and what happens on the link.
#[derive(Clone, Debug)]
pub struct Session {
    /// The hand's path.
    pub trajectory: Trajectory,
    /// The device (from the bank the trajectory was planned on).
    pub calibration: DeviceCalibration,
    /// Mechanical constants of the plant.
    pub plant: PlantParams,
    /// Ticks to run (1 kHz).
    pub ticks: u32,
    /// `(tick, what)`: sent just before the plant frame of that tick.
    pub link: Vec<(u32, LinkSend)>,
    /// A heartbeat every this many ticks (0: none).
    pub heartbeat_every: u32,
    /// No heartbeat from this tick on (host link silent).
    pub heartbeat_until: Option<u32>,
    /// `(tick, counts)`: encoder counts fed instead of the plant's at that tick.
    pub encoder_override: Vec<(u32, [i32; 3])>,
    /// QEMU's `-icount shift`: each instruction takes 2^shift ns of virtual time. 3 (a
    /// 125 MIPS core) is what the image's instruction counter assumes; a larger shift slows the
    /// virtual CPU 2^(shift - 3) times, to provoke overruns.
    pub icount_shift: u8,
    /// Hold each tick until its time in wall time (1 ms per tick from the start), for a live
    /// display; otherwise the run goes as fast as QEMU does.
    pub real_time: bool,
    /// Called with every message the image sends on the link, as it arrives.
    pub observer: Option<LinkObserver>,
    /// At most this many link bytes sent by the image per tick (a slow UART: 921,600 baud
    /// carries 92 a millisecond); `None`: as fast as QEMU's USART, which is instantaneous.
    pub link_bytes_per_tick: Option<u32>,
}

/// A callback for the image's link messages ([`Session::observer`]).
#[derive(Clone)]
pub struct LinkObserver(pub Arc<dyn Fn(&DeviceToHost) + Send + Sync>);

impl std::fmt::Debug for LinkObserver {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("LinkObserver")
    }
}

impl Session {
    /// `script` for `seconds` on `bank`: `Hello` at tick 1, `ZeroEncoders` at [`HOME_TICK`]
    /// (the hand at home), `Arm` at [`ARM_TICK`], a heartbeat every 5 ticks.
    pub fn new(bank: &Bank, script: Script, seconds: f64) -> Result<Session> {
        Session::with_trajectory(bank, Trajectory::new(bank, script)?, seconds)
    }

    /// [`Session::new`] with any hand trajectory (e.g. a recorded one,
    /// [`Trajectory::from_csv`]).
    pub fn with_trajectory(bank: &Bank, trajectory: Trajectory, seconds: f64) -> Result<Session> {
        if !(seconds.is_finite() && seconds > 0.0 && seconds <= 3600.0) {
            bail!("--seconds must be in (0, 3600], got {seconds}");
        }
        Ok(Session {
            trajectory,
            calibration: *bank.device(),
            plant: PlantParams::default(),
            ticks: (seconds / TICK_S).round().max(1.0) as u32,
            link: vec![
                (1, LinkSend::Command(HostToDevice::Hello)),
                (HOME_TICK, LinkSend::Command(HostToDevice::ZeroEncoders)),
                (ARM_TICK, LinkSend::Command(HostToDevice::Arm)),
            ],
            heartbeat_every: 5,
            heartbeat_until: None,
            encoder_override: Vec::new(),
            icount_shift: 3,
            real_time: false,
            observer: None,
            link_bytes_per_tick: None,
        })
    }
}

/// What happened in one tick.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct TickRecord {
    /// Tick number (1-based).
    pub tick: u32,
    /// Encoder counts fed to the image.
    pub encoder_counts: [i32; 3],
    /// The plant's joints when the counts were taken.
    pub joints: [f64; 3],
    /// The image's motor currents, A.
    pub currents_a: [f32; 3],
    /// The force the image rendered on the tool, N.
    pub force_n: [f32; 3],
    /// The image's safety state after the tick.
    #[serde(serialize_with = "ser_state")]
    pub state: State,
    /// Contact nodes.
    pub contact_nodes: u8,
    /// Instructions of the loop body.
    pub body_instructions: u32,
    /// Instructions of the whole previous tick (executor, link and plant I/O included).
    pub tick_instructions: u32,
    /// The loop body's instructions split at the code's phase boundaries (they sum to
    /// `body_instructions`).
    pub phase_instructions: PhaseCycles,
}

fn ser_state<S: serde::Serializer>(s: &State, ser: S) -> Result<S::Ok, S::Error> {
    ser.serialize_str(&format!("{s:?}"))
}

/// A message from the link and the harness's tick when it arrived.
#[derive(Clone, Debug, PartialEq)]
pub struct LinkEvent {
    /// Plant ticks completed when the message was decoded.
    pub at_tick: u32,
    /// The message.
    pub msg: DeviceToHost,
}

/// The outcome of a run.
#[derive(Debug)]
pub struct Run {
    /// Ticks requested.
    pub requested_ticks: u32,
    /// Every answered tick, in order.
    pub ticks: Vec<TickRecord>,
    /// Messages from the link, in order.
    pub link: Vec<LinkEvent>,
    /// Frames from the image dropped by the harness's decoder.
    pub link_stats: FrameStats,
    /// Why the plant exchange stopped early, if it did.
    pub stopped: Option<String>,
    /// The image's exit code (`None`: killed).
    pub exit_code: Option<i32>,
    /// The image's stderr (semihosting).
    pub stderr: String,
    /// Wall time of the plant exchange, s.
    pub wall_s: f64,
}

impl Run {
    /// `DeviceToHost::Fault` messages: `(tick, reason, detail)`.
    pub fn faults(&self) -> Vec<(u32, FaultReason, u32)> {
        self.link
            .iter()
            .filter_map(|e| match e.msg {
                DeviceToHost::Fault {
                    tick,
                    reason,
                    detail,
                } => Some((tick, reason, detail)),
                _ => None,
            })
            .collect()
    }

    /// Telemetry messages, in order.
    pub fn telemetry(&self) -> Vec<&Telemetry> {
        self.link
            .iter()
            .filter_map(|e| match &e.msg {
                DeviceToHost::Telemetry(t) => Some(t),
                _ => None,
            })
            .collect()
    }

    /// Plant frames not answered.
    pub fn missed_plant_frames(&self) -> u32 {
        self.requested_ticks.saturating_sub(self.ticks.len() as u32)
    }

    /// Overruns: the image's own count (last telemetry), or ticks longer than the period
    /// seen in the plant reports, whichever is larger.
    pub fn overruns(&self) -> u32 {
        let counted = self.telemetry().last().map_or(0, |t| t.counters.overruns);
        let seen = self
            .ticks
            .iter()
            .filter(|t| t.tick_instructions > INSTRUCTIONS_PER_TICK)
            .count() as u32;
        counted.max(seen)
    }

    /// Largest rendered tool force, N.
    pub fn peak_force_n(&self) -> f32 {
        self.ticks
            .iter()
            .map(|t| t.force_n.iter().map(|f| f * f).sum::<f32>().sqrt())
            .fold(0.0, f32::max)
    }
}

/// [`run`] for each `(setup, session)` of `jobs`, as many at once as the machine has cores,
/// the results in `jobs`' order. Each run is its own QEMU process, pipes and socket, and its
/// plant exchange is lockstep under `-icount`; what runs beside it moves only the
/// asynchronous link (the tick an arm command lands on, by a tick or so) and its `wall_s`, so
/// runs whose wall time is the figure (`host bench sil`) go one at a time through [`run`].
pub fn run_all(jobs: &[(&Setup, Session)]) -> Vec<Result<Run>> {
    let width = std::thread::available_parallelism()
        .map_or(1, |n| n.get())
        .clamp(1, jobs.len().max(1));
    let next = std::sync::atomic::AtomicUsize::new(0);
    let done: Mutex<Vec<Option<Result<Run>>>> = Mutex::new(jobs.iter().map(|_| None).collect());
    std::thread::scope(|s| {
        for _ in 0..width {
            s.spawn(|| {
                loop {
                    let k = next.fetch_add(1, Ordering::Relaxed);
                    let Some((setup, session)) = jobs.get(k) else {
                        break;
                    };
                    let r = run(setup, session);
                    done.lock().unwrap_or_else(|e| e.into_inner())[k] = Some(r);
                }
            });
        }
    });
    done.into_inner()
        .unwrap_or_else(|e| e.into_inner())
        .into_iter()
        .map(|r| r.unwrap_or_else(|| Err(anyhow::anyhow!("internal: a SIL run was not made"))))
        .collect()
}

/// Run `session` on the image under QEMU. Errors are set-up failures (QEMU missing, pipes,
/// socket); an image that stops early is a [`Run`] with `stopped` set.
pub fn run(setup: &Setup, session: &Session) -> Result<Run> {
    for (what, p) in [("image", &setup.image), ("bank", &setup.bank)] {
        if !p.is_file() {
            bail!("the {what} file {} does not exist", p.display());
        }
    }
    check_image(&setup.image)?;
    let dir = tempfile::tempdir().context("cannot create a temporary directory for the pipes")?;
    let (in_path, out_path) = (
        dir.path().join("sil-plant-in"),
        dir.path().join("sil-plant-out"),
    );
    mkfifo(&in_path)?;
    mkfifo(&out_path)?;
    if let Some(budget) = session.link_bytes_per_tick {
        // Read by the image at boot (firmware/qemu: `link_budget`).
        std::fs::write(dir.path().join("sil-link-budget"), budget.to_string())
            .context("cannot write the link budget for the image")?;
    }
    let listener = TcpListener::bind("127.0.0.1:0").context("cannot listen on 127.0.0.1")?;
    let port = listener.local_addr()?.port();

    let mut child = Command::new(&setup.qemu)
        .args(["-M", "netduinoplus2", "-nographic", "-monitor", "none"])
        .arg("-icount")
        .arg(format!("shift={},sleep=off", session.icount_shift))
        .args(["-semihosting-config", "enable=on,target=native"])
        .arg("-serial")
        .arg(format!("tcp:127.0.0.1:{port}"))
        .arg("-device")
        .arg(format!(
            "loader,file={},addr={BANK_ORIGIN:#x}",
            std::path::absolute(&setup.bank)?.display()
        ))
        .arg("-kernel")
        .arg(std::path::absolute(&setup.image)?)
        .current_dir(dir.path())
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .with_context(|| {
            format!(
                "cannot start {} (install it: apt-get install qemu-system-arm)",
                setup.qemu.display()
            )
        })?;
    let stderr = child.stderr.take().map(|mut e| {
        std::thread::spawn(move || {
            let mut s = String::new();
            let _ = e.read_to_string(&mut s);
            s
        })
    });
    let started = Instant::now();
    // On its own thread with SIGPIPE blocked: a write to the pipe of an image that died is
    // then an EPIPE error, not the end of a process whose SIGPIPE is at its default (`host`).
    let result = std::thread::scope(|s| {
        s.spawn(|| {
            block_sigpipe();
            exchange(&mut child, &listener, &in_path, &out_path, session)
        })
        .join()
        .unwrap_or_else(|_| Err(anyhow::anyhow!("the plant exchange thread panicked")))
    });
    // Closing the pipes (inside `exchange`) ends the image; give it a moment, then kill.
    let exit_code = wait_or_kill(&mut child, Duration::from_secs(10));
    let stderr = stderr.and_then(|h| h.join().ok()).unwrap_or_default();
    let (ticks, link, link_stats, stopped) =
        result.map_err(|e| e.context(format!("the QEMU run failed; image stderr:\n{stderr}")))?;
    Ok(Run {
        requested_ticks: session.ticks,
        ticks,
        link,
        link_stats,
        stopped,
        exit_code,
        stderr,
        wall_s: started.elapsed().as_secs_f64(),
    })
}

/// How long QEMU may take to start and connect its serial port and plant pipes: a few hundred
/// milliseconds on an idle machine, seconds on a loaded 2-core one (a suite's parallel tests);
/// reached only when something is wrong, so generous.
const QEMU_START_TIMEOUT: Duration = Duration::from_secs(60);

type Exchanged = (Vec<TickRecord>, Vec<LinkEvent>, FrameStats, Option<String>);

/// Connect the link and the plant pipes, run the ticks, close everything.
fn exchange(
    child: &mut Child,
    listener: &TcpListener,
    in_path: &Path,
    out_path: &Path,
    session: &Session,
) -> Result<Exchanged> {
    let deadline = Instant::now() + QEMU_START_TIMEOUT;
    let link = accept_until(listener, child, deadline)?;
    // The image opens its output first, then its input; open them in the same order.
    let mut from_image = File::options()
        .read(true)
        .custom_flags(libc::O_NONBLOCK)
        .open(out_path)
        .with_context(|| format!("cannot open {}", out_path.display()))?;
    let mut to_image = loop {
        match File::options()
            .write(true)
            .custom_flags(libc::O_NONBLOCK)
            .open(in_path)
        {
            Ok(f) => break f,
            Err(e) if e.raw_os_error() == Some(libc::ENXIO) => {
                alive_before(child, deadline, "open its plant pipes")?;
                std::thread::sleep(Duration::from_millis(1));
            }
            Err(e) => return Err(e).with_context(|| format!("cannot open {}", in_path.display())),
        }
    };
    set_blocking(&from_image)?;
    set_blocking(&to_image)?;

    let done = Arc::new(AtomicU32::new(0));
    let reader = spawn_link_reader(
        link.try_clone()?,
        Arc::clone(&done),
        session.observer.clone(),
    );
    let mut link_tx = link;

    // Watchdog: a run far slower than expected (a hung image) is killed, which closes the
    // pipes and ends the exchange with an error instead of hanging.
    let finished = Arc::new(AtomicBool::new(false));
    let budget = Duration::from_secs(30) + Duration::from_millis(u64::from(session.ticks) * 5);
    let pid = child.id() as libc::pid_t;
    let watchdog = {
        let finished = Arc::clone(&finished);
        std::thread::spawn(move || {
            let start = Instant::now();
            while !finished.load(Ordering::Acquire) {
                if start.elapsed() > budget {
                    // SAFETY: plain kill(2) of the QEMU child this harness started.
                    unsafe { libc::kill(pid, libc::SIGKILL) };
                    return;
                }
                std::thread::sleep(Duration::from_millis(20));
            }
        })
    };

    let mut gimbal = Gimbal::new(&session.calibration, session.plant);
    let mut records = Vec::with_capacity(session.ticks as usize);
    let mut buf = [0u8; MAX_FRAME];
    let mut stopped = None;
    let mut hand_prev = session.trajectory.at(0.0);
    let started = Instant::now();
    for tick in 1..=session.ticks {
        if session.real_time {
            let due = started + Duration::from_millis(u64::from(tick));
            if let Some(wait) = due.checked_duration_since(Instant::now()) {
                std::thread::sleep(wait);
            }
        }
        for (_, send) in session.link.iter().filter(|(t, _)| *t == tick) {
            send_link(&mut link_tx, send)?;
        }
        let beat = session.heartbeat_every > 0
            && tick.is_multiple_of(session.heartbeat_every)
            && session.heartbeat_until.is_none_or(|u| tick < u);
        if beat {
            send_link(&mut link_tx, &LinkSend::Command(HostToDevice::Heartbeat))?;
        }
        let counts = session
            .encoder_override
            .iter()
            .find(|(t, _)| *t == tick)
            .map_or_else(|| gimbal.encoder_counts(), |o| o.1);
        let message = encode_plant(
            &HostToDevice::Plant {
                tick,
                encoder_counts: counts,
            },
            &mut buf,
        )?;
        if let Err(e) = to_image.write_all(message) {
            stopped = Some(format!(
                "tick {tick}: the image closed its plant input ({e})"
            ));
            break;
        }
        let reply = match read_plant(&mut from_image) {
            Ok(Some(m)) => m,
            Ok(None) => {
                stopped = Some(format!("tick {tick}: the image closed its plant output"));
                break;
            }
            Err(e) => {
                stopped = Some(format!("tick {tick}: {e}"));
                break;
            }
        };
        let DeviceToHost::Plant {
            tick: t,
            currents_a,
            force_n,
            state,
            contact_nodes,
            body_cycles,
            tick_cycles,
            phase_cycles,
        } = reply
        else {
            stopped = Some(format!(
                "tick {tick}: expected a plant frame, got {reply:?}"
            ));
            break;
        };
        if t != tick {
            stopped = Some(format!("tick {tick}: the image answered for tick {t}"));
            break;
        }
        records.push(TickRecord {
            tick,
            encoder_counts: counts,
            joints: gimbal.joints(),
            currents_a,
            force_n,
            state,
            contact_nodes,
            body_instructions: body_cycles,
            tick_instructions: tick_cycles,
            phase_instructions: phase_cycles,
        });
        let hand = session.trajectory.at(f64::from(tick) * TICK_S);
        gimbal.step(currents_a, hand_prev, hand);
        hand_prev = hand;
        done.store(tick, Ordering::Release);
    }
    drop(to_image);
    drop(from_image);
    finished.store(true, Ordering::Release);
    let _ = watchdog.join();
    let _ = wait_or_kill(child, Duration::from_secs(10));
    drop(link_tx);
    let (link, stats) = reader
        .join()
        .map_err(|_| anyhow::anyhow!("the link reader thread panicked"))?;
    Ok((records, link, stats, stopped))
}

/// Read the socket until it closes, decoding the image's link frames.
fn spawn_link_reader(
    mut sock: TcpStream,
    done: Arc<AtomicU32>,
    observer: Option<LinkObserver>,
) -> std::thread::JoinHandle<(Vec<LinkEvent>, FrameStats)> {
    std::thread::spawn(move || {
        let events = Mutex::new(Vec::new());
        let mut decoder = FrameDecoder::<DeviceToHost>::new();
        let mut buf = [0u8; 4096];
        while let Ok(n) = sock.read(&mut buf) {
            if n == 0 {
                break;
            }
            for r in decoder.feed_slice(&buf[..n]) {
                if let (Ok(msg), Some(o)) = (&r, &observer) {
                    (o.0)(msg);
                }
                if let Ok(msg) = r
                    && let Ok(mut ev) = events.lock()
                {
                    ev.push(LinkEvent {
                        at_tick: done.load(Ordering::Acquire),
                        msg,
                    });
                }
            }
        }
        (events.into_inner().unwrap_or_default(), decoder.stats())
    })
}

/// Sends one link message.
fn send_link(sock: &mut TcpStream, send: &LinkSend) -> Result<()> {
    let mut buf = [0u8; MAX_FRAME];
    let bytes: &[u8] = match send {
        LinkSend::Command(c) => encode_frame(c, &mut buf)?,
        LinkSend::Raw(r) => r,
    };
    sock.write_all(bytes).context("link socket write failed")
}

/// The next frame from the image's plant output (`None` at end of file).
/// The image's next plant message (`SPEC.md`, "Plant channel": a length byte, then postcard);
/// `None` when the image closed the pipe before a message began.
fn read_plant(f: &mut File) -> Result<Option<DeviceToHost>> {
    let mut len = [0u8; 1];
    match f.read_exact(&mut len) {
        Ok(()) => {}
        Err(e) if e.kind() == std::io::ErrorKind::UnexpectedEof => return Ok(None),
        Err(e) => return Err(e).context("plant pipe read failed"),
    }
    let mut body = vec![0u8; usize::from(len[0])];
    f.read_exact(&mut body)
        .context("the image closed its plant output inside a message")?;
    decode_plant(&body)
        .map(Some)
        .map_err(|e| anyhow::anyhow!("bad plant message from the image: {e}"))
}

fn accept_until(listener: &TcpListener, child: &mut Child, deadline: Instant) -> Result<TcpStream> {
    listener.set_nonblocking(true)?;
    loop {
        match listener.accept() {
            Ok((s, _)) => {
                s.set_nonblocking(false)?;
                s.set_nodelay(true)?;
                return Ok(s);
            }
            Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => {
                alive_before(child, deadline, "connect its serial port")?;
                std::thread::sleep(Duration::from_millis(1));
            }
            Err(e) => return Err(e).context("accepting QEMU's serial connection failed"),
        }
    }
}

/// Fails if QEMU has exited or `deadline` has passed while waiting for it to `what`.
fn alive_before(child: &mut Child, deadline: Instant, what: &str) -> Result<()> {
    if let Some(status) = child.try_wait()? {
        bail!("QEMU exited ({status}) before it could {what}");
    }
    if Instant::now() > deadline {
        bail!(
            "QEMU did not {what} within {} s",
            QEMU_START_TIMEOUT.as_secs()
        );
    }
    Ok(())
}

fn wait_or_kill(child: &mut Child, timeout: Duration) -> Option<i32> {
    let end = Instant::now() + timeout;
    loop {
        match child.try_wait() {
            Ok(Some(status)) => return status.code(),
            Ok(None) if Instant::now() < end => std::thread::sleep(Duration::from_millis(2)),
            _ => {
                let _ = child.kill();
                return child.wait().ok().and_then(|s| s.code());
            }
        }
    }
}

/// Block SIGPIPE for the calling thread (a write to a closed pipe then fails with EPIPE).
fn block_sigpipe() {
    // SAFETY: sigset_t is plain data initialised by sigemptyset; pthread_sigmask only changes
    // the calling thread's mask.
    unsafe {
        let mut set: libc::sigset_t = std::mem::zeroed();
        libc::sigemptyset(&mut set);
        libc::sigaddset(&mut set, libc::SIGPIPE);
        libc::pthread_sigmask(libc::SIG_BLOCK, &set, std::ptr::null_mut());
    }
}

/// Refuses a file that is not a 32-bit little-endian ARM ELF executable (QEMU would otherwise
/// run whatever it is and dump registers).
fn check_image(path: &Path) -> Result<()> {
    let mut head = [0u8; 20];
    let n = File::open(path)
        .and_then(|mut f| f.read(&mut head))
        .with_context(|| format!("cannot read the image {}", path.display()))?;
    // ELF magic, ELFCLASS32, ELFDATA2LSB; e_type EXEC (2); e_machine ARM (40).
    let elf = n == head.len()
        && head[..6] == [0x7f, b'E', b'L', b'F', 1, 1]
        && u16::from_le_bytes([head[16], head[17]]) == 2
        && u16::from_le_bytes([head[18], head[19]]) == 40;
    if !elf {
        bail!(
            "{}: not an image for this machine (a 32-bit ARM ELF executable, e.g. \
             firmware/qemu's release build)",
            path.display()
        );
    }
    Ok(())
}

fn mkfifo(path: &Path) -> Result<()> {
    use std::os::unix::ffi::OsStrExt;
    let c = std::ffi::CString::new(path.as_os_str().as_bytes())
        .with_context(|| format!("bad pipe path {}", path.display()))?;
    // SAFETY: mkfifo(3) with a valid NUL-terminated path.
    if unsafe { libc::mkfifo(c.as_ptr(), 0o600) } != 0 {
        return Err(std::io::Error::last_os_error())
            .with_context(|| format!("cannot create the pipe {}", path.display()));
    }
    Ok(())
}

fn set_blocking(f: &File) -> Result<()> {
    use std::os::fd::AsRawFd;
    let fd = f.as_raw_fd();
    // SAFETY: fcntl(2) on a file descriptor this function's caller owns.
    let ok = unsafe {
        let flags = libc::fcntl(fd, libc::F_GETFL);
        flags >= 0 && libc::fcntl(fd, libc::F_SETFL, flags & !libc::O_NONBLOCK) == 0
    };
    if !ok {
        return Err(std::io::Error::last_os_error()).context("cannot make a plant pipe blocking");
    }
    Ok(())
}
