//! `host device check` against a fake device on a pseudo-terminal: it answers the host's
//! `Hello` and streams telemetry whose tip is the forward kinematics of known joint values;
//! the command must print those joints back (and the encoder counts they mean), and refuse a
//! device that runs another bank.
#![cfg(target_os = "linux")]

use bank_format::{
    Bank, Counters, DeviceToHost, FrameDecoder, HostToDevice, MAX_FRAME, Mode, PROTOCOL_VERSION,
    State, Telemetry, encode_frame,
};
use host::kinematics::{Workspace, counts_for};
use std::fs::File;
use std::io::{Read, Write};
use std::os::fd::FromRawFd;
use std::process::{Command, Output};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

/// A pseudo-terminal: (master, slave path, slave). The test plays the device on the master.
fn pty() -> (File, String, File) {
    let (mut m, mut s) = (0, 0);
    // SAFETY: openpty writes two new descriptors into `m` and `s`; null name/termios/winsize
    // are allowed.
    let rc = unsafe {
        libc::openpty(
            &mut m,
            &mut s,
            std::ptr::null_mut(),
            std::ptr::null(),
            std::ptr::null(),
        )
    };
    assert_eq!(rc, 0, "openpty failed");
    // SAFETY: `s` is a valid descriptor; ttyname returns NULL or a NUL-terminated static buffer,
    // read at once.
    let name = unsafe {
        let p = libc::ttyname(s);
        assert!(!p.is_null(), "ttyname of the pseudo-terminal failed");
        std::ffi::CStr::from_ptr(p).to_string_lossy().into_owned()
    };
    // SAFETY: fcntl(2) on the two fresh descriptors: close-on-exec (the `host` child must not
    // hold them), and a non-blocking master (the fake device polls it and can stop).
    unsafe {
        libc::fcntl(m, libc::F_SETFD, libc::FD_CLOEXEC);
        libc::fcntl(s, libc::F_SETFD, libc::FD_CLOEXEC);
        libc::fcntl(
            m,
            libc::F_SETFL,
            libc::fcntl(m, libc::F_GETFL) | libc::O_NONBLOCK,
        );
    }
    // SAFETY: both descriptors are fresh and owned by the returned files only.
    unsafe { (File::from_raw_fd(m), name, File::from_raw_fd(s)) }
}

/// The fake device: waits for the host's Hello, answers with `bank_crc`, then sends
/// telemetry with `tip` every 10 ms, until `stop` is set.
fn device(
    mut master: File,
    bank_crc: u32,
    tip: [f32; 3],
    stop: Arc<AtomicBool>,
) -> std::thread::JoinHandle<()> {
    std::thread::spawn(move || {
        let mut rx: FrameDecoder<HostToDevice> = FrameDecoder::new();
        let mut bytes = [0u8; 256];
        let mut buf = [0u8; MAX_FRAME];
        let mut greeted = false;
        let mut tick = 0;
        while !stop.load(Ordering::Relaxed) {
            // Non-blocking: nothing to read (or no host yet) is an error to skip.
            if let Ok(n) = master.read(&mut bytes) {
                let hello = rx
                    .feed_slice(&bytes[..n])
                    .any(|r| r == Ok(HostToDevice::Hello));
                if hello && !greeted {
                    let hello = DeviceToHost::Hello {
                        protocol: PROTOCOL_VERSION,
                        bank_crc: Some(bank_crc),
                        scene_id: 7,
                        node_count: 25,
                    };
                    let _ = master.write_all(encode_frame(&hello, &mut buf).unwrap());
                    greeted = true;
                }
            }
            if greeted {
                tick += 1;
                let t = Telemetry {
                    tick,
                    state: State::Disarmed,
                    mode: Mode::Render,
                    fault: None,
                    tip_m: tip,
                    contacts: Default::default(),
                    currents_a: [0.0; 3],
                    tool_force_n: [0.0; 3],
                    dropped_load: 0.0,
                    counters: Counters::default(),
                };
                let _ =
                    master.write_all(encode_frame(&DeviceToHost::Telemetry(t), &mut buf).unwrap());
            }
            std::thread::sleep(std::time::Duration::from_millis(10));
        }
    })
}

fn run(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_host"))
        .args(args)
        .output()
        .expect("run host")
}

#[test]
fn device_check_prints_the_joints_of_the_telemetry_tip() {
    let bank_bytes = firmware::fixtures::flat_patch();
    let bank = Bank::parse(&bank_bytes).unwrap();
    let cal = *bank.device();
    let dir = tempfile::tempdir().unwrap();
    let bank_path = dir.path().join("patch.bank");
    std::fs::write(&bank_path, bank_bytes.as_slice()).unwrap();
    // Known joints inside the calibration's ranges: a quarter of the way in from each bound.
    let q: [f64; 3] = std::array::from_fn(|i| {
        let (lo, hi) = (f64::from(cal.joint_min[i]), f64::from(cal.joint_max[i]));
        lo + 0.25 * (hi - lo)
    });
    let w = Workspace::from_device(&cal);
    let tip = w.tip(q[0], q[1], q[2]).map(|x| x as f32);
    let (master, name, _slave) = pty();
    let stop = Arc::new(AtomicBool::new(false));
    let dev = device(master, bank.crc(), tip, Arc::clone(&stop));
    let out = run(&[
        "device",
        "check",
        "--port",
        &name,
        "--bank",
        bank_path.to_str().unwrap(),
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
    let lines: Vec<serde_json::Value> = String::from_utf8_lossy(&out.stdout)
        .lines()
        .map(|l| serde_json::from_str(l).expect("one JSON object per line"))
        .collect();
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
    let bank_bytes = firmware::fixtures::flat_patch();
    let bank = Bank::parse(&bank_bytes).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let bank_path = dir.path().join("patch.bank");
    std::fs::write(&bank_path, bank_bytes.as_slice()).unwrap();
    let (master, name, slave) = pty();
    let stop = Arc::new(AtomicBool::new(false));
    let dev = device(master, bank.crc() ^ 1, [0.0; 3], Arc::clone(&stop));
    let out = run(&[
        "device",
        "check",
        "--port",
        &name,
        "--bank",
        bank_path.to_str().unwrap(),
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
