//! The serial link and `host device` against a fake device on a pseudo-terminal: the serial
//! source decodes telemetry, keeps the link alive and refuses a device that is not the scene
//! displayed; `check` prints the joints of the telemetry's tip (the forward kinematics of known
//! joint values) and the encoder counts they mean; `arm` and `zero` send the commands a person
//! at bring-up needs, following the firmware's state machine; the library's arm guard
//! (`haptic::device::Session::arm`) disarms the device when dropped.
#![cfg(target_os = "linux")]

use bank_format::Contact;
use bank_format::{
    AlignedBytes, Bank, Counters, DeviceToHost, FaultReason, FrameDecoder, HostToDevice, MAX_FRAME,
    Mode, PROTOCOL_VERSION, ResetCause, State, Telemetry, encode_frame,
};
use firmware::tick::Contacts;
use haptic::device::{BankSource, ExpectedBank, Session};
use haptic::display::source::{SerialSource, Source};
use haptic::kinematics::{Workspace, counts_for};
use haptic::link::{Identity, await_identity};
use std::fs::File;
use std::io::{Read, Write};
use std::os::fd::FromRawFd;
use std::path::Path;
use std::process::{Command, Output, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// A pseudo-terminal: (master, slave path, slave). The test plays the device on the master.
/// Both descriptors are opened close-on-exec (`O_CLOEXEC`), not marked so afterwards: the tests
/// run in parallel threads, and a `host` child spawned by another test in between would
/// inherit them and keep this terminal open (a test once failed to open its port, "Unable to
/// acquire exclusive lock", that way).
fn pty() -> (File, String, File) {
    // SAFETY: posix_openpt(3), grantpt(3), unlockpt(3), ptsname_r(3) and open(2) on a fresh
    // descriptor, each checked; ptsname_r writes a NUL-terminated name into the buffer given.
    unsafe {
        let m = libc::posix_openpt(libc::O_RDWR | libc::O_NOCTTY | libc::O_CLOEXEC);
        assert!(m >= 0, "posix_openpt failed");
        assert_eq!(libc::grantpt(m), 0, "grantpt failed");
        assert_eq!(libc::unlockpt(m), 0, "unlockpt failed");
        let mut buf = [0 as libc::c_char; 64];
        assert_eq!(
            libc::ptsname_r(m, buf.as_mut_ptr(), buf.len()),
            0,
            "ptsname_r failed"
        );
        let name = std::ffi::CStr::from_ptr(buf.as_ptr())
            .to_string_lossy()
            .into_owned();
        let s = libc::open(
            buf.as_ptr(),
            libc::O_RDWR | libc::O_NOCTTY | libc::O_CLOEXEC,
        );
        assert!(s >= 0, "opening {name} failed");
        // A non-blocking master: the fake device polls it and can stop.
        libc::fcntl(
            m,
            libc::F_SETFL,
            libc::fcntl(m, libc::F_GETFL) | libc::O_NONBLOCK,
        );
        (File::from_raw_fd(m), name, File::from_raw_fd(s))
    }
}

/// How the fake device behaves.
#[derive(Clone, Copy)]
struct Fake {
    bank_crc: u32,
    tip: [f32; 3],
    /// State at power-up (`Fault` with `LinkSilent` latched, as after a host that died).
    start: State,
    /// Fault (`Overspeed`) after this many armed ticks.
    fault_after: Option<u32>,
    /// The tip after `ZeroEncoders`.
    home_tip: [f32; 3],
    /// Homed already (`ZeroEncoders` references the encoders; `Arm` without it is refused and
    /// latched as `NotReferenced`, as the firmware does).
    referenced: bool,
    /// Its brown-out reset is below level 3: every `Arm` is refused with `BrownOutLevel`
    /// (detail 0, BOR off), as the firmware's configuration check does.
    brown_out: bool,
}

/// The fake device: waits for the host's Hello, answers with `bank_crc` (and, as the firmware
/// does, its reset cause: a brown-out), then sends telemetry with `tip` every 10 ms, until
/// `stop` is set. It follows the firmware's state machine for the host's commands (SetMode
/// only while disarmed, Arm only from Disarmed and referenced, Disarm, ClearFault,
/// ZeroEncoders unless armed) and records every command but heartbeats.
fn device(
    mut master: File,
    fake: Fake,
    stop: Arc<AtomicBool>,
) -> (std::thread::JoinHandle<()>, Arc<Mutex<Vec<HostToDevice>>>) {
    let log = Arc::new(Mutex::new(Vec::new()));
    let seen = Arc::clone(&log);
    let thread = std::thread::spawn(move || {
        let mut rx: FrameDecoder<HostToDevice> = FrameDecoder::new();
        let mut bytes = [0u8; 256];
        let mut buf = [0u8; MAX_FRAME];
        let mut greeted = false;
        let mut tip = fake.tip;
        let (mut tick, mut armed_ticks) = (0, 0);
        let (mut state, mut mode) = (fake.start, Mode::Render);
        let mut fault = (state == State::Fault).then_some(FaultReason::LinkSilent);
        let mut referenced = fake.referenced;
        while !stop.load(Ordering::Relaxed) {
            // Non-blocking: nothing to read (or no host yet) is an error to skip.
            if let Ok(n) = master.read(&mut bytes) {
                for msg in rx.feed_slice(&bytes[..n]).flatten() {
                    match msg {
                        HostToDevice::Heartbeat => continue,
                        HostToDevice::Hello => {
                            let hello = DeviceToHost::Hello {
                                protocol: PROTOCOL_VERSION,
                                bank_crc: Some(fake.bank_crc),
                                scene_id: 7,
                                node_count: 25,
                            };
                            let _ = master.write_all(encode_frame(&hello, &mut buf).unwrap());
                            let reset = DeviceToHost::Reset {
                                cause: ResetCause::BrownOut,
                            };
                            let _ = master.write_all(encode_frame(&reset, &mut buf).unwrap());
                            greeted = true;
                        }
                        HostToDevice::SetMode(m) if state == State::Disarmed => mode = m,
                        HostToDevice::Arm if fake.brown_out => {
                            (state, fault) = (State::Fault, Some(FaultReason::BrownOutLevel));
                        }
                        HostToDevice::Arm if state == State::Disarmed && !referenced => {
                            (state, fault) = (State::Fault, Some(FaultReason::NotReferenced));
                        }
                        HostToDevice::Arm if state == State::Disarmed => state = State::Armed,
                        HostToDevice::Disarm if state == State::Armed => state = State::Disarmed,
                        HostToDevice::ZeroEncoders if state != State::Armed => {
                            tip = fake.home_tip;
                            referenced = true;
                        }
                        HostToDevice::ClearFault if state == State::Fault => {
                            (state, fault) = (State::Disarmed, None);
                        }
                        _ => {}
                    }
                    seen.lock().unwrap().push(msg);
                }
            }
            if greeted {
                tick += 1;
                if state == State::Armed {
                    armed_ticks += 1;
                    if fake.fault_after.is_some_and(|n| armed_ticks > n) {
                        (state, fault) = (State::Fault, Some(FaultReason::Overspeed));
                    }
                }
                let currents_a = match (state, mode) {
                    (State::Armed, Mode::ConstantCurrent { currents_a }) => currents_a,
                    _ => [0.0; 3],
                };
                let t = Telemetry {
                    tick,
                    state,
                    mode,
                    fault,
                    tip_m: tip,
                    contacts: Default::default(),
                    contact_point: None,
                    currents_a,
                    tool_force_n: [0.0; 3],
                    dropped_load: 0.0,
                    counters: Counters::default(),
                };
                let _ =
                    master.write_all(encode_frame(&DeviceToHost::Telemetry(t), &mut buf).unwrap());
            }
            std::thread::sleep(std::time::Duration::from_millis(10));
        }
    });
    (thread, log)
}

/// A disarmed fake device running `bank_crc`'s bank with its tip at `tip`.
fn fake(bank_crc: u32, tip: [f32; 3]) -> Fake {
    Fake {
        bank_crc,
        tip,
        start: State::Disarmed,
        fault_after: None,
        home_tip: tip,
        referenced: true,
        brown_out: false,
    }
}

/// The flat-patch fixture bank, written to `dir`: (its bytes, its path).
fn patch_bank(dir: &Path) -> (AlignedBytes, String) {
    let bytes = firmware::fixtures::flat_patch();
    let path = dir.join("patch.bank");
    std::fs::write(&path, bytes.as_slice()).unwrap();
    (bytes, path.to_str().unwrap().to_string())
}

/// Reads what the host sent to the non-blocking master `device`, waiting up to 5 s for a byte.
fn read_some(device: &mut File, bytes: &mut [u8]) -> usize {
    let end = Instant::now() + Duration::from_secs(5);
    loop {
        match device.read(bytes) {
            Ok(n) if n > 0 => return n,
            Err(e) if e.kind() != std::io::ErrorKind::WouldBlock => panic!("pty read: {e}"),
            _ => {
                assert!(Instant::now() < end, "nothing from the host within 5 s");
                std::thread::sleep(Duration::from_millis(1));
            }
        }
    }
}

/// Plays the device on the pty master `device` in a thread: waits for the host's `Hello`,
/// answers `hello`, and hands the master back when joined.
fn answer_hello(mut device: File, hello: DeviceToHost) -> std::thread::JoinHandle<File> {
    std::thread::spawn(move || {
        let mut rx: FrameDecoder<HostToDevice> = FrameDecoder::new();
        let mut bytes = [0u8; 256];
        loop {
            let n = read_some(&mut device, &mut bytes);
            if rx
                .feed_slice(&bytes[..n])
                .any(|r| r == Ok(HostToDevice::Hello))
            {
                break;
            }
        }
        let mut buf = [0u8; MAX_FRAME];
        device
            .write_all(encode_frame(&hello, &mut buf).unwrap())
            .unwrap();
        device
    })
}

fn hello(protocol: u16, bank_crc: Option<u32>) -> DeviceToHost {
    DeviceToHost::Hello {
        protocol,
        bank_crc,
        scene_id: 0x5ce9e,
        node_count: 321,
    }
}

#[test]
fn serial_source_decodes_telemetry_and_sends_heartbeats() {
    let (device, name, _slave) = pty();
    let answered = answer_hello(device, hello(PROTOCOL_VERSION, Some(0xC0FFEE)));
    let mut src = SerialSource::open(&name, 115_200, 0xC0FFEE, "the bank").unwrap();
    let mut device = answered.join().unwrap();
    assert!(src.steering().is_none());
    let mut contacts = Contacts::new();
    contacts
        .push(Contact {
            node: 4,
            force_n: [0.0, 0.1, -0.3],
        })
        .unwrap();
    let t = Telemetry {
        tick: 500,
        state: State::Armed,
        mode: Mode::Render,
        fault: None,
        tip_m: [0.01, 0.02, 0.05],
        contacts: contacts.clone(),
        contact_point: Some(bank_format::ContactPoint {
            triangle: 17,
            bary: [0.5, 0.25, 0.25],
        }),
        currents_a: [0.1, 0.0, -0.2],
        // Not what the contacts would give under any law: the sample must take it as sent.
        tool_force_n: [0.05, -0.1, 0.7],
        dropped_load: 0.0,
        counters: Counters::default(),
    };
    let mut buf = [0u8; MAX_FRAME];
    let frame = encode_frame(&DeviceToHost::Telemetry(t), &mut buf).unwrap();
    // Line noise first: the decoder resynchronises on the frame delimiter.
    device.write_all(&[0x13, 0x37, 0x00]).unwrap();
    device.write_all(frame).unwrap();
    let s = src
        .latest(Duration::from_secs(5))
        .unwrap()
        .expect("a sample");
    assert_eq!(
        (s.tick, s.state, s.tip_m),
        (500, State::Armed, [0.01, 0.02, 0.05])
    );
    assert_eq!(s.contacts, contacts);
    assert_eq!(
        s.contact_point,
        Some(bank_format::ContactPoint {
            triangle: 17,
            bary: [0.5, 0.25, 0.25]
        })
    );
    assert_eq!(s.tool_force_n, [0.05, -0.1, 0.7]);
    // The host keeps the link alive.
    let mut rx: FrameDecoder<HostToDevice> = FrameDecoder::new();
    let mut got = Vec::new();
    let end = Instant::now() + Duration::from_secs(5);
    let mut bytes = [0u8; 256];
    while !got.contains(&HostToDevice::Heartbeat) {
        assert!(Instant::now() < end, "got {got:?}");
        let n = read_some(&mut device, &mut bytes);
        got.extend(rx.feed_slice(&bytes[..n]).filter_map(|r| r.ok()));
    }
}

/// Over a pty: a device answering with another bank, another protocol or no bank is
/// refused at open, the error saying what to reflash.
#[test]
fn serial_source_refuses_a_device_that_is_not_the_scene_displayed() {
    let cases = [
        (
            hello(PROTOCOL_VERSION, Some(0x1234_5678)),
            vec![
                "0x12345678",
                "0xabcdef01",
                "reflash the bank",
                "scene id 0x5ce9e",
            ],
        ),
        (
            hello(PROTOCOL_VERSION + 1, Some(0xABCD_EF01)),
            vec!["protocol", "reflash the firmware"],
        ),
        (hello(PROTOCOL_VERSION, None), vec!["no valid bank"]),
    ];
    for (answer, want) in cases {
        let (device, name, _slave) = pty();
        let answered = answer_hello(device, answer.clone());
        let err = SerialSource::open(&name, 115_200, 0xABCD_EF01, "the liver bank")
            .err()
            .unwrap_or_else(|| panic!("{answer:?} accepted"));
        let msg = format!("{err:#}");
        for w in want {
            assert!(msg.contains(w), "{answer:?}: {msg:?} lacks {w:?}");
        }
        answered.join().unwrap();
    }
}

/// Over a pty: the Hello is found among other frames and line noise.
#[test]
fn await_identity_skips_other_frames() {
    let (mut device, name, _slave) = pty();
    let mut port = serialport::new(&name, 115_200)
        .timeout(Duration::from_millis(2))
        .open()
        .unwrap();
    let mut buf = [0u8; MAX_FRAME];
    let fault = DeviceToHost::Fault {
        tick: 3,
        reason: FaultReason::LinkSilent,
        detail: 0,
    };
    device
        .write_all(encode_frame(&fault, &mut buf).unwrap())
        .unwrap();
    device.write_all(&[0x55, 0xAA, 0x00]).unwrap();
    device
        .write_all(encode_frame(&hello(7, Some(42)), &mut buf).unwrap())
        .unwrap();
    let id = await_identity(&mut *port, &name, Duration::from_secs(5)).unwrap();
    assert_eq!(
        id,
        Identity {
            protocol: 7,
            bank_crc: Some(42),
            scene_id: 0x5ce9e,
            node_count: 321
        }
    );
    // Silence: a timeout naming the port.
    let err = await_identity(&mut *port, &name, Duration::from_millis(50)).unwrap_err();
    assert!(format!("{err}").contains(&name), "{err}");
}

fn run(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_host"))
        .args(args)
        .output()
        .expect("run host")
}

#[test]
fn device_check_prints_the_joints_of_the_telemetry_tip() {
    let dir = tempfile::tempdir().unwrap();
    let (bank_bytes, bank_path) = patch_bank(dir.path());
    let bank = Bank::parse(&bank_bytes).unwrap();
    let cal = *bank.device();
    // Known joints inside the calibration's ranges: a quarter of the way in from each bound.
    let q: [f64; 3] = std::array::from_fn(|i| {
        let (lo, hi) = (f64::from(cal.joint_min[i]), f64::from(cal.joint_max[i]));
        lo + 0.25 * (hi - lo)
    });
    let w = Workspace::from_device(&cal);
    let tip = w.tip(q[0], q[1], q[2]).map(|x| x as f32);
    let (master, name, _slave) = pty();
    let stop = Arc::new(AtomicBool::new(false));
    let (dev, _) = device(master, fake(bank.crc(), tip), Arc::clone(&stop));
    let out = run(&[
        "device",
        "check",
        "--port",
        &name,
        "--bank",
        &bank_path,
        "--seconds",
        "1.0",
        "--rate",
        "20",
        "--json",
    ]);
    stop.store(true, Ordering::Relaxed);
    drop(_slave);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let (resets, lines): (Vec<serde_json::Value>, Vec<serde_json::Value>) =
        String::from_utf8_lossy(&out.stdout)
            .lines()
            .map(|l| serde_json::from_str(l).expect("one JSON object per line"))
            .partition(|l: &serde_json::Value| l.get("reset_cause").is_some());
    // The device's reset cause, once (it answers each Hello with it).
    assert_eq!(
        resets,
        [serde_json::json!({ "reset_cause": "BrownOut" })],
        "{resets:?}"
    );
    assert!(lines.len() >= 3, "{lines:?}");
    let want_counts = counts_for(&cal, q);
    for l in &lines {
        assert_eq!(l["state"], "Disarmed");
        // The tip went through f32: joints agree to the rounding of a ~0.1 m vector.
        for (key, want) in [
            ("pitch_rad", q[0]),
            ("yaw_rad", q[1]),
            ("insertion_m", q[2]),
        ] {
            let got = l[key].as_f64().unwrap();
            assert!((got - want).abs() < 1e-5, "{key}: {got} vs {want}");
        }
        for i in 0..3 {
            let got = l["counts"][i].as_i64().unwrap();
            assert!(
                (got - i64::from(want_counts[i])).abs() <= 1,
                "counts {i}: {got}"
            );
        }
    }
    dev.join().unwrap();
}

#[test]
fn device_check_refuses_a_device_running_another_bank() {
    let dir = tempfile::tempdir().unwrap();
    let (bank_bytes, bank_path) = patch_bank(dir.path());
    let bank = Bank::parse(&bank_bytes).unwrap();
    let (master, name, slave) = pty();
    let stop = Arc::new(AtomicBool::new(false));
    let (dev, _) = device(master, fake(bank.crc() ^ 1, [0.0; 3]), Arc::clone(&stop));
    let out = run(&[
        "device",
        "check",
        "--port",
        &name,
        "--bank",
        &bank_path,
        "--seconds",
        "1",
    ]);
    stop.store(true, Ordering::Relaxed);
    drop(slave);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("reflash the bank"), "{err}");
    assert!(err.contains(&format!("{:#010x}", bank.crc())), "{err}");
    dev.join().unwrap();
}

/// `host device arm` on `fake`: its output and the commands the device received.
fn arm(fake: Fake, bank: &str, extra: &[&str]) -> (Output, Vec<HostToDevice>) {
    let (master, name, slave) = pty();
    let stop = Arc::new(AtomicBool::new(false));
    let (dev, log) = device(master, fake, Arc::clone(&stop));
    let mut args = vec!["device", "arm", "--port", &name, "--bank", bank, "--json"];
    args.extend_from_slice(extra);
    let out = run(&args);
    stop.store(true, Ordering::Relaxed);
    drop(slave);
    dev.join().unwrap();
    let log = log.lock().unwrap().clone();
    (out, log)
}

#[test]
fn device_arm_sets_constant_currents_and_disarms_at_the_end() {
    let dir = tempfile::tempdir().unwrap();
    let (bytes, bank) = patch_bank(dir.path());
    let crc = Bank::parse(&bytes).unwrap().crc();
    let (out, log) = arm(
        fake(crc, [0.0; 3]),
        &bank,
        &[
            "--mode",
            "current",
            "--currents",
            "0.25,0,-0.5",
            "--seconds",
            "0.5",
        ],
    );
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    let currents_a = [0.25, 0.0, -0.5];
    assert_eq!(
        log,
        [
            HostToDevice::Hello,
            HostToDevice::SetMode(Mode::ConstantCurrent { currents_a }),
            HostToDevice::Arm,
            HostToDevice::Disarm,
        ]
    );
    let lines: Vec<serde_json::Value> = String::from_utf8_lossy(&out.stdout)
        .lines()
        .map(|l| serde_json::from_str(l).expect("one JSON object per line"))
        .collect();
    assert!(lines.len() >= 2, "{lines:?}");
    for l in &lines {
        assert_eq!(l["state"], "Armed");
        assert_eq!(l["currents_a"], serde_json::json!(currents_a));
    }
}

#[test]
fn device_arm_refuses_currents_over_the_bank_limit_before_opening_the_port() {
    let dir = tempfile::tempdir().unwrap();
    let (bytes, bank) = patch_bank(dir.path());
    let limit = Bank::parse(&bytes).unwrap().device().current_limit_a;
    let over = format!("0,{},0", limit[1] + 0.5);
    for currents in [over.as_str(), "0,NaN,0"] {
        // The port does not exist: the refusal must come first.
        let out = run(&[
            "device",
            "arm",
            "--port",
            "/nonexistent/tty",
            "--bank",
            &bank,
            "--mode",
            "current",
            "--currents",
            currents,
        ]);
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{err}");
        assert!(
            err.contains("motor 1 (yaw)") && err.contains("limit"),
            "{err}"
        );
    }
    let out = run(&[
        "device",
        "arm",
        "--port",
        "/dev/null",
        "--bank",
        &bank,
        "--mode",
        "current",
    ]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("needs --currents"), "{err}");
}

#[test]
fn device_arm_clears_a_latched_fault_only_when_asked() {
    let dir = tempfile::tempdir().unwrap();
    let (bytes, bank) = patch_bank(dir.path());
    let crc = Bank::parse(&bytes).unwrap().crc();
    let faulted = Fake {
        start: State::Fault,
        ..fake(crc, [0.0; 3])
    };
    let (out, log) = arm(faulted, &bank, &["--seconds", "0.3"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains("LinkSilent") && err.contains("--clear-fault"),
        "{err}"
    );
    assert_eq!(log, [HostToDevice::Hello], "nothing but Hello was sent");

    let (out, log) = arm(
        faulted,
        &bank,
        &["--seconds", "0.3", "--clear-fault", "--mode", "transparent"],
    );
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    assert_eq!(
        log,
        [
            HostToDevice::Hello,
            HostToDevice::ClearFault,
            HostToDevice::SetMode(Mode::Transparent),
            HostToDevice::Arm,
            HostToDevice::Disarm,
        ]
    );
}

/// A device that was never homed since its reset refuses the arm with `NotReferenced`:
/// `host device arm` fails and says to home it with `host device zero` first (it does not home
/// it itself: only a person with the instrument in its home fixture can).
#[test]
fn device_arm_on_an_unhomed_device_says_to_zero_it_first() {
    let dir = tempfile::tempdir().unwrap();
    let (bytes, bank) = patch_bank(dir.path());
    let crc = Bank::parse(&bytes).unwrap().crc();
    let unhomed = Fake {
        referenced: false,
        ..fake(crc, [0.0; 3])
    };
    let (out, log) = arm(unhomed, &bank, &["--seconds", "0.3"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains("NotReferenced") && err.contains("host device zero"),
        "{err}"
    );
    assert!(!log.contains(&HostToDevice::ZeroEncoders), "{log:?}");
}

/// A device whose brown-out reset is below level 3 refuses every arm with `BrownOutLevel`:
/// `host device arm` fails and names the fix, `host flash --set-bor`.
#[test]
fn device_arm_below_brown_out_level_3_names_the_fix() {
    let dir = tempfile::tempdir().unwrap();
    let (bytes, bank) = patch_bank(dir.path());
    let crc = Bank::parse(&bytes).unwrap().crc();
    let bor_off = Fake {
        brown_out: true,
        ..fake(crc, [0.0; 3])
    };
    let (out, _) = arm(bor_off, &bank, &["--seconds", "0.3"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains("BrownOutLevel")
            && err.contains("below level 3")
            && err.contains("host flash --set-bor"),
        "{err}"
    );
}

#[test]
fn device_arm_reports_a_fault_during_the_run_and_fails() {
    let dir = tempfile::tempdir().unwrap();
    let (bytes, bank) = patch_bank(dir.path());
    let crc = Bank::parse(&bytes).unwrap().crc();
    let faulting = Fake {
        fault_after: Some(20),
        ..fake(crc, [0.0; 3])
    };
    let (out, log) = arm(faulting, &bank, &["--seconds", "5"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains("left the armed state") && err.contains("Overspeed"),
        "{err}"
    );
    assert_eq!(log.last(), Some(&HostToDevice::Disarm));
}

/// The library's arm guard (`haptic::device::Armed`): an error returned from inside an armed
/// run drops the guard without `Armed::disarm`, and the drop sends `Disarm` and waits for the
/// device to leave the armed state, so the device is disarmed before the session (and its
/// link) ends.
#[test]
fn arm_guard_disarms_when_dropped_on_an_error_path() {
    let dir = tempfile::tempdir().unwrap();
    let (bytes, bank_path) = patch_bank(dir.path());
    let bank = ExpectedBank::load(&BankSource::File(bank_path.into())).unwrap();
    assert_eq!(bank.crc, Bank::parse(&bytes).unwrap().crc());
    let (master, name, slave) = pty();
    let stop = Arc::new(AtomicBool::new(false));
    let (dev, log) = device(master, fake(bank.crc, [0.0; 3]), Arc::clone(&stop));
    let mut session = Session::open(&name, 115_200, &bank).unwrap();
    session.ready_to_arm(false).unwrap();
    // Armed, one armed sample seen, then an error: `?` returns with the guard alive.
    fn armed_then_fail(session: &mut Session) -> anyhow::Result<()> {
        let mut armed = session.arm(Mode::Transparent)?;
        let end = Instant::now() + Duration::from_secs(5);
        while armed.latest(Duration::from_millis(20))?.is_none() {
            anyhow::ensure!(Instant::now() < end, "no armed sample within 5 s");
        }
        assert!(armed.is_armed());
        Err(anyhow::anyhow!("the run failed while armed"))
    }
    let err = armed_then_fail(&mut session).unwrap_err();
    assert_eq!(err.to_string(), "the run failed while armed");
    assert_eq!(
        log.lock().unwrap().clone(),
        [
            HostToDevice::Hello,
            HostToDevice::SetMode(Mode::Transparent),
            HostToDevice::Arm,
            HostToDevice::Disarm,
        ],
        "the dropped guard disarmed the device before returning"
    );
    // The device's own telemetry says so.
    let end = Instant::now() + Duration::from_secs(5);
    loop {
        let s = session.source().latest(Duration::from_millis(50)).unwrap();
        if let Some(s) = s {
            assert_eq!(s.state, State::Disarmed);
            break;
        }
        assert!(Instant::now() < end, "no telemetry after the drop");
    }
    // A guard dropped at the end of its scope, with no error, disarms too.
    {
        let _armed = session.arm(Mode::Render).unwrap();
    }
    let sent = log.lock().unwrap().clone();
    assert_eq!(
        sent[4..],
        [
            HostToDevice::SetMode(Mode::Render),
            HostToDevice::Arm,
            HostToDevice::Disarm,
        ]
    );
    drop(session);
    stop.store(true, Ordering::Relaxed);
    drop(slave);
    dev.join().unwrap();
}

#[test]
fn device_arm_disarms_on_ctrl_c() {
    let dir = tempfile::tempdir().unwrap();
    let (bytes, bank) = patch_bank(dir.path());
    let crc = Bank::parse(&bytes).unwrap().crc();
    let (master, name, slave) = pty();
    let stop = Arc::new(AtomicBool::new(false));
    let (dev, log) = device(master, fake(crc, [0.0; 3]), Arc::clone(&stop));
    let mut child = Command::new(env!("CARGO_BIN_EXE_host"))
        .args(["device", "arm", "--port", &name, "--bank", &bank, "--json"])
        .args(["--seconds", "60"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Armed once it prints a line.
    let mut first = String::new();
    std::io::BufRead::read_line(
        &mut std::io::BufReader::new(child.stdout.take().unwrap()),
        &mut first,
    )
    .unwrap();
    assert!(first.contains("Armed"), "{first}");
    // SAFETY: kill(2) on the child's pid, which has not been reaped (no wait yet).
    assert_eq!(unsafe { libc::kill(child.id() as i32, libc::SIGINT) }, 0);
    let out = child.wait_with_output().unwrap();
    stop.store(true, Ordering::Relaxed);
    drop(slave);
    dev.join().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    assert_eq!(log.lock().unwrap().last(), Some(&HostToDevice::Disarm));
}

/// `host device zero` cannot see where the instrument is (the device takes any pose as home,
/// and its tip reads the home pose after any zeroing): it asks the operator to confirm the
/// homing fixture, sends nothing without the confirmation (refused outright without a
/// terminal or `--yes`), and says what it checked (the device applied the command) and what
/// it did not (the pose).
#[test]
fn device_zero_asks_for_the_fixture_and_says_what_it_checked() {
    let dir = tempfile::tempdir().unwrap();
    let (bytes, bank) = patch_bank(dir.path());
    let parsed = Bank::parse(&bytes).unwrap();
    let cal = *parsed.device();
    let q = cal.home_joint.map(f64::from);
    let home = Workspace::from_device(&cal)
        .tip(q[0], q[1], q[2])
        .map(|x| x as f32);
    // Runs `host device zero` against `fake`, with `extra` arguments and, when `answer` is
    // given, a terminal on stdin that has that line typed into it.
    let zero = |fake: Fake, extra: &[&str], answer: Option<&[u8]>| {
        let (master, name, slave) = pty();
        let stop = Arc::new(AtomicBool::new(false));
        let (dev, log) = device(master, fake, Arc::clone(&stop));
        let mut args = vec!["device", "zero", "--port", &name, "--bank", &bank];
        args.extend_from_slice(extra);
        let mut cmd = Command::new(env!("CARGO_BIN_EXE_host"));
        cmd.args(&args);
        let tty = answer.map(|line| {
            let (mut tty_master, _, tty_slave) = pty();
            tty_master.write_all(line).unwrap();
            cmd.stdin(Stdio::from(tty_slave));
            tty_master
        });
        let out = cmd.output().expect("run host");
        drop(tty);
        stop.store(true, Ordering::Relaxed);
        drop(slave);
        dev.join().unwrap();
        let log = log.lock().unwrap().clone();
        (out, log)
    };
    let away = Fake {
        home_tip: home,
        ..fake(parsed.crc(), [0.01, 0.02, -0.03])
    };
    // No terminal to ask at and no --yes: refused before the port is opened.
    let (out, log) = zero(away, &[], None);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains("homing fixture") && err.contains("not a terminal") && err.contains("--yes"),
        "{err}"
    );
    assert!(log.is_empty(), "{log:?}");
    // --yes: zeroed; the output says what was checked and what was not.
    let (out, log) = zero(away, &["--yes"], None);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(log, [HostToDevice::Hello, HostToDevice::ZeroEncoders]);
    assert!(
        text.contains("checked: the device received and applied the command"),
        "{text}"
    );
    assert!(
        text.contains("not checked: that the instrument is in its homing fixture (--yes said so)"),
        "{text}"
    );
    // At a terminal: "n" sends nothing, "y" zeroes.
    let (out, log) = zero(away, &[], Some(b"n\n"));
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains("Is the instrument held in its homing fixture?"),
        "{err}"
    );
    assert!(err.contains("not zeroed (nothing sent)"), "{err}");
    assert_eq!(log, [HostToDevice::Hello]);
    let (out, log) = zero(away, &[], Some(b"y\n"));
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(text.contains("(you confirmed it)"), "{text}");
    assert_eq!(log, [HostToDevice::Hello, HostToDevice::ZeroEncoders]);
    // A device that ignores the command (here: whose home pose is elsewhere) is an error.
    let wrong = Fake {
        home_tip: [0.5, 0.5, 0.5],
        ..away
    };
    let (out, _) = zero(wrong, &["--yes"], None);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("did not apply ZeroEncoders"), "{err}");
}
