//! `host flash` without a board: the layout check against probe-rs's STM32F405RGTx, the plan
//! of `--dry-run` (firmware + bank, `--bank-only`), the checks that refuse a bank or an image
//! before any probe is opened, and the "no probe" error; `--set-bor`'s option word (old ->
//! new, by hand from RM0090's bit map), its dry run and its refusals; the `Disarm` sent to a
//! connected device (a fake one on a pseudo-terminal) before the probe opens.
//!
//! The reference for every plan is the STM32F405's sector map written out by hand from the
//! reference manual (RM0090 §3.3, table 5), not probe-rs's description under test.

use bank_format::region::{BANK_LEN, BANK_ORIGIN, FIRMWARE_LEN, FIRMWARE_ORIGIN};
use bank_format::{VERSION_MAJOR, reseal};
use flash::{Layout, Part, What};
use std::path::Path;
use std::process::{Command, Output};

/// RM0090 table 5 (1 MB devices): sectors 0-3 of 16 KiB, 4 of 64 KiB, 5-11 of 128 KiB.
fn f405_sectors() -> Vec<(u64, u64)> {
    let mut sizes = vec![16 << 10; 4];
    sizes.push(64 << 10);
    sizes.extend([128 << 10; 7]);
    let mut at = 0x0800_0000;
    sizes
        .into_iter()
        .map(|s| {
            let sector = (at, s);
            at += s;
            sector
        })
        .collect()
}

/// The sectors of [`f405_sectors`] that hold a byte of `start..end`.
fn sectors_touching(start: u64, end: u64) -> Vec<(u64, u64)> {
    f405_sectors()
        .into_iter()
        .filter(|&(a, s)| a < end && start < a + s)
        .collect()
}

/// A minimal ARM ELF32 executable: one `PT_LOAD` program header per `(paddr, vaddr, data,
/// memsz)`, the data after the headers.
fn elf(segments: &[(u32, u32, Vec<u8>, u32)], machine: u16) -> Vec<u8> {
    let phoff = 52u32;
    let mut data_at = phoff + 32 * segments.len() as u32;
    let mut out = vec![0x7f, b'E', b'L', b'F', 1, 1, 1, 0, 0, 0, 0, 0, 0, 0, 0, 0];
    let u16le = |out: &mut Vec<u8>, v: u16| out.extend(v.to_le_bytes());
    let u32le = |out: &mut Vec<u8>, v: u32| out.extend(v.to_le_bytes());
    u16le(&mut out, 2); // ET_EXEC
    u16le(&mut out, machine);
    u32le(&mut out, 1); // EV_CURRENT
    u32le(&mut out, 0x0800_0101); // entry
    u32le(&mut out, phoff);
    u32le(&mut out, 0); // no section headers
    u32le(&mut out, 0x0500_0400); // EABI5, hard float
    u16le(&mut out, 52);
    u16le(&mut out, 32);
    u16le(&mut out, segments.len() as u16);
    u16le(&mut out, 40);
    u16le(&mut out, 0);
    u16le(&mut out, 0);
    for (paddr, vaddr, bytes, memsz) in segments {
        u32le(&mut out, 1); // PT_LOAD
        u32le(&mut out, data_at);
        u32le(&mut out, *vaddr);
        u32le(&mut out, *paddr);
        u32le(&mut out, bytes.len() as u32);
        u32le(&mut out, *memsz);
        u32le(&mut out, 5); // R X
        u32le(&mut out, 4);
        data_at += bytes.len() as u32;
    }
    for (_, _, bytes, _) in segments {
        out.extend(bytes);
    }
    out
}

const EM_ARM: u16 = 40;

/// A firmware image: `.text` at the start of flash, `.data` loaded from flash at 0x0800_6000
/// into RAM, `.bss` in RAM (no file bytes: not programmed).
fn image() -> Vec<u8> {
    let text: Vec<u8> = (0..0x5000u32).map(|i| (i % 251) as u8).collect();
    let data = vec![0x5a; 0x100];
    elf(
        &[
            (0x0800_0000, 0x0800_0000, text, 0x5000),
            (0x0800_6000, 0x2000_0000, data, 0x100),
            (0x2000_0100, 0x2000_0100, Vec::new(), 0x1000),
        ],
        EM_ARM,
    )
}

/// A valid bank followed by erased flash (0xFF) up to `len` bytes: the reader ignores bytes
/// past the bank's `total_len`, as the firmware does reading its region.
fn bank(len: usize) -> Vec<u8> {
    let mut b = firmware::fixtures::flat_patch().as_slice().to_vec();
    assert!(b.len() <= len);
    b.resize(len, 0xFF);
    b
}

fn host(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_host"))
        .args(args)
        .output()
        .expect("run host")
}

fn write(dir: &Path, name: &str, bytes: &[u8]) -> String {
    let p = dir.join(name);
    std::fs::write(&p, bytes).unwrap();
    p.to_str().unwrap().to_string()
}

fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

fn json(out: &Output) -> serde_json::Value {
    assert!(out.status.success(), "{}", stderr(out));
    serde_json::from_slice(&out.stdout).expect("stdout is one JSON object")
}

fn spans(v: &serde_json::Value, key: &str) -> Vec<(u64, u64)> {
    v[key]
        .as_array()
        .unwrap()
        .iter()
        .map(|e| (e["address"].as_u64().unwrap(), e["size"].as_u64().unwrap()))
        .collect()
}

#[test]
fn memory_x_fits_probe_rs_description_on_sector_boundaries() {
    let layout = Layout::new().expect("memory.x fits STM32F405RGTx");
    assert_eq!(layout.chip(), "STM32F405RGTx");
    // The firmware region ends, and the bank region starts, on a sector boundary of RM0090.
    let starts: Vec<u64> = f405_sectors().iter().map(|s| s.0).collect();
    let fw_end = u64::from(FIRMWARE_ORIGIN) + FIRMWARE_LEN as u64;
    assert!(starts.contains(&u64::from(BANK_ORIGIN)) && starts.contains(&fw_end));
    assert!(fw_end <= u64::from(BANK_ORIGIN));
}

#[test]
fn layouts_sharing_a_sector_or_outside_flash_are_refused() {
    let target = || flash::target().expect("built-in target");
    // Firmware up to 0x0804_1000, bank from there: both in sector 6 (0x0804_0000..0x0806_0000).
    let err = Layout::with_regions(target(), 0x0800_0000..0x0804_1000, 0x0804_1000..0x0810_0000)
        .err()
        .expect("shared sector refused")
        .to_string();
    assert!(
        err.contains("share the sector 0x08040000..0x08060000"),
        "{err}"
    );
    // A bank region running past the 1 MiB of flash.
    let err = Layout::with_regions(target(), 0x0800_0000..0x0804_0000, 0x0804_0000..0x0810_4000)
        .err()
        .expect("region outside flash refused")
        .to_string();
    assert!(err.contains("not inside the chip's flash"), "{err}");
    // Adjacent regions on the sector 5 / sector 6 boundary are fine.
    assert!(
        Layout::with_regions(target(), 0x0800_0000..0x0804_0000, 0x0804_0000..0x0810_0000).is_ok()
    );
}

#[test]
fn plan_erases_the_sectors_the_data_touches_and_programs_each_part() {
    let layout = Layout::new().unwrap();
    let fw = flash::firmware_segments(&image(), &layout.firmware_region()).unwrap();
    // Physical (load) addresses, file bytes only: .bss is not programmed.
    assert_eq!(
        fw.iter()
            .map(|p| (p.address, p.data.len()))
            .collect::<Vec<_>>(),
        [(0x0800_0000, 0x5000), (0x0800_6000, 0x100)]
    );
    let bank_len = 200_000;
    let mut parts = fw;
    parts.push(Part {
        what: What::Bank,
        address: u64::from(BANK_ORIGIN),
        data: bank(bank_len),
    });
    let plan = layout.plan(&parts).unwrap();
    let mut want = sectors_touching(0x0800_0000, 0x0800_6100);
    want.extend(sectors_touching(
        u64::from(BANK_ORIGIN),
        u64::from(BANK_ORIGIN) + bank_len as u64,
    ));
    let got: Vec<(u64, u64)> = plan.erase.iter().map(|s| (s.address, s.size)).collect();
    // Sectors 0 and 1 (the image), 6 and 7 (the 200 kB bank); nothing in between.
    assert_eq!(got, want);
    assert_eq!(got.len(), 4);
    // A part outside its region is refused.
    let stray = Part {
        what: What::Bank,
        address: 0x0803_0000,
        data: vec![0; 16],
    };
    let err = layout.plan(&[stray]).unwrap_err().to_string();
    assert!(err.contains("outside the bank region"), "{err}");
}

#[test]
fn images_that_do_not_fit_the_firmware_region_are_refused() {
    let region = Layout::new().unwrap().firmware_region();
    // A segment loaded into the bank region.
    let into_bank = elf(&[(BANK_ORIGIN, BANK_ORIGIN, vec![1; 64], 64)], EM_ARM);
    let err = flash::firmware_segments(&into_bank, &region)
        .unwrap_err()
        .to_string();
    assert!(err.contains("outside the firmware region"), "{err}");
    // One byte past the region's end.
    let end = FIRMWARE_ORIGIN + FIRMWARE_LEN as u32;
    let over = elf(&[(end - 16, end - 16, vec![1; 17], 17)], EM_ARM);
    assert!(flash::firmware_segments(&over, &region).is_err());
    // Not ARM (x86-64's e_machine 62), not an ELF, no loadable bytes.
    let x86 = elf(&[(FIRMWARE_ORIGIN, FIRMWARE_ORIGIN, vec![1; 4], 4)], 62);
    assert!(
        flash::firmware_segments(&x86, &region)
            .unwrap_err()
            .to_string()
            .contains("not a little-endian ARM executable")
    );
    assert!(flash::firmware_segments(b"#!/bin/sh\n", &region).is_err());
    let empty = elf(&[(0x2000_0000, 0x2000_0000, Vec::new(), 64)], EM_ARM);
    assert!(
        flash::firmware_segments(&empty, &region)
            .unwrap_err()
            .to_string()
            .contains("no loadable segments")
    );
}

#[test]
fn banks_are_checked_with_the_firmware_reader() {
    let good = bank(65_536);
    let crc = flash::check_bank(&good, BANK_LEN as u64).unwrap();
    assert_eq!(crc, u32::from_le_bytes(good[20..24].try_into().unwrap()));
    // Larger than the region.
    let err = flash::check_bank(&bank(65_536), 65_535)
        .unwrap_err()
        .to_string();
    assert!(err.contains("more than the 65535 bytes"), "{err}");
    // A flipped byte: the CRC no longer matches.
    let mut corrupt = good.clone();
    corrupt[100] ^= 0x01;
    assert!(
        flash::check_bank(&corrupt, BANK_LEN as u64)
            .unwrap_err()
            .to_string()
            .contains("fails the firmware's validation")
    );
    // A major version the firmware does not read (resealed, so only the version is wrong).
    let mut newer = good.clone();
    newer[8..10].copy_from_slice(&(VERSION_MAJOR + 1).to_le_bytes());
    assert!(reseal(&mut newer));
    let err = flash::check_bank(&newer, BANK_LEN as u64)
        .unwrap_err()
        .to_string();
    assert!(err.contains("version"), "{err}");
}

#[test]
fn dry_run_json_plans_firmware_and_bank() {
    let dir = tempfile::tempdir().unwrap();
    let elf = write(dir.path(), "fw.elf", &image());
    let bank_len = 140_000;
    let bank = write(dir.path(), "b.bank", &bank(bank_len));
    let v = json(&host(&[
        "flash",
        "--dry-run",
        "--json",
        "--elf",
        &elf,
        "--bank",
        &bank,
    ]));
    assert_eq!(v["chip"], "STM32F405RGTx");
    let bank_end = u64::from(BANK_ORIGIN) + bank_len as u64;
    let mut want = sectors_touching(0x0800_0000, 0x0800_6100);
    want.extend(sectors_touching(u64::from(BANK_ORIGIN), bank_end));
    assert_eq!(spans(&v, "erase"), want);
    assert_eq!(
        spans(&v, "program"),
        [
            (0x0800_0000, 0x5000),
            (0x0800_6000, 0x100),
            (u64::from(BANK_ORIGIN), bank_len as u64)
        ]
    );
    let what: Vec<&str> = v["program"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p["what"].as_str().unwrap())
        .collect();
    assert_eq!(what, ["firmware", "firmware", "bank"]);
    // Exactly the three keys of the documented object.
    let keys: Vec<&String> = v.as_object().unwrap().keys().collect();
    assert_eq!(keys, ["chip", "erase", "program"]);
}

#[test]
fn dry_run_bank_only_touches_nothing_below_the_bank_region() {
    let dir = tempfile::tempdir().unwrap();
    let bank = write(dir.path(), "b.bank", &bank(300_000));
    let v = json(&host(&[
        "flash",
        "--dry-run",
        "--json",
        "--bank-only",
        "--bank",
        &bank,
    ]));
    let (erase, program) = (spans(&v, "erase"), spans(&v, "program"));
    assert_eq!(
        erase,
        sectors_touching(u64::from(BANK_ORIGIN), u64::from(BANK_ORIGIN) + 300_000)
    );
    assert_eq!(program, [(u64::from(BANK_ORIGIN), 300_000)]);
    assert!(
        erase.iter().chain(&program).all(|&(a, _)| a >= 0x0804_0000),
        "{v}"
    );
    assert_eq!(v["program"][0]["what"], "bank");
    // The text plan says the same.
    let out = host(&["flash", "--dry-run", "--bank-only", "--bank", &bank]);
    assert!(out.status.success(), "{}", stderr(&out));
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("erase     3 sectors, 393216 bytes"), "{text}");
    assert!(
        text.contains("disarm    first: Disarm to the device on the port with the board's USB id"),
        "{text}"
    );
}

/// Without `--dry-run` the command would open a probe next; a bank or image refused says so
/// and never reaches the probe (the error is the bank's, not "no debug probe").
#[test]
fn bad_banks_and_images_are_refused_before_any_probe_is_opened() {
    let dir = tempfile::tempdir().unwrap();
    let elf = write(dir.path(), "fw.elf", &image());
    let oversized = write(dir.path(), "big.bank", &bank(BANK_LEN + 1));
    let mut bytes = bank(65_536);
    bytes[64] ^= 0x80;
    let corrupt = write(dir.path(), "bad.bank", &bytes);
    let good = write(dir.path(), "good.bank", &bank(65_536));
    let stray = write(
        dir.path(),
        "stray.elf",
        &elf_into(u64::from(BANK_ORIGIN) as u32),
    );
    let cases: [(&[&str], &str); 4] = [
        (
            &["--elf", &elf, "--bank", &oversized],
            "more than the 786432 bytes of the bank region",
        ),
        (
            &["--elf", &elf, "--bank", &corrupt],
            "fails the firmware's validation",
        ),
        (
            &["--bank-only", "--bank", &corrupt],
            "fails the firmware's validation",
        ),
        (
            &["--elf", &stray, "--bank", &good],
            "outside the firmware region",
        ),
    ];
    for (args, want) in cases {
        let out = host(&[&["flash"], args].concat());
        let err = stderr(&out);
        assert!(!out.status.success(), "{args:?} accepted");
        assert!(err.contains(want), "{args:?}: {err}");
        assert!(!err.contains("probe") && !err.contains("panicked"), "{err}");
    }
}

fn elf_into(address: u32) -> Vec<u8> {
    elf(&[(address, address, vec![7; 32], 32)], EM_ARM)
}

/// No such probe attached: a non-zero exit with what to check, no panic. The test names a
/// probe id no device has (`--probe`), so it never writes to a board a developer has plugged
/// in; without `--probe` and no probe attached the same path reports "no debug probe found".
#[test]
fn flash_without_a_probe_fails_with_what_to_check() {
    let dir = tempfile::tempdir().unwrap();
    let elf = write(dir.path(), "fw.elf", &image());
    let bank = write(dir.path(), "b.bank", &bank(65_536));
    let out = host(&[
        "flash",
        "--elf",
        &elf,
        "--bank",
        &bank,
        "--probe",
        "fffe:fffd:no-such-probe",
        "--port",
        "/dev/no-such-port",
    ]);
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains("no device connected to disarm (no device on /dev/no-such-port"),
        "{err}"
    );
    assert!(
        err.contains("no debug probe fffe:fffd:no-such-probe found"),
        "{err}"
    );
    assert!(err.contains("udev") && err.contains("permission"), "{err}");
    assert!(!err.contains("panicked"), "{err}");
    // A malformed selector is refused before anything else.
    let out = host(&["flash", "--bank", &bank, "--probe", "stlink"]);
    assert!(!out.status.success());
    assert!(stderr(&out).contains("VID:PID"), "{}", stderr(&out));
}

/// `--scene` builds the bank in memory as `host bank build` writes it: the plan programs
/// exactly that file's bytes, and the text plan reports its CRC. On the nodal liver, whose
/// bank builds in a second: a sampled scene's bank comes from the bank cache, which
/// `report_sampled.rs` holds byte for byte to a fresh sampling.
#[test]
fn dry_run_with_a_scene_programs_the_bank_host_bank_build_writes() {
    let scene = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/liver-nodal.toml");
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("liver.bank");
    let built = host(&[
        "bank",
        "build",
        scene.to_str().unwrap(),
        "-o",
        file.to_str().unwrap(),
    ]);
    assert!(built.status.success(), "{}", stderr(&built));
    let bytes = std::fs::read(&file).unwrap();
    let args = [
        "flash",
        "--dry-run",
        "--bank-only",
        "--scene",
        scene.to_str().unwrap(),
    ];
    let v = json(&host(&[&args[..], &["--json"]].concat()));
    assert_eq!(
        spans(&v, "program"),
        [(u64::from(BANK_ORIGIN), bytes.len() as u64)]
    );
    let out = host(&args);
    assert!(out.status.success(), "{}", stderr(&out));
    let crc = u32::from_le_bytes(bytes[20..24].try_into().unwrap());
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains(&format!("bank crc  {crc:#010x}")), "{text}");
}

/// `--set-bor`'s word: `BOR_LEV` (bits 3:2) cleared, every other bit as read, `OPTLOCK` (bit 0)
/// set and `OPTSTRT` (bit 1) clear; the expected words are written out by hand from RM0090's
/// FLASH_OPTCR map (nWRP 27:16, RDP 15:8, nRST_STDBY 7, nRST_STOP 6, WDG_SW 5, BOR_LEV 3:2).
#[test]
fn set_bor_clears_bor_lev_and_keeps_every_other_bit() {
    let cases = [
        // Factory option bytes: BOR off (11).
        (0x0FFF_AAED, 0x0FFF_AAE1),
        // Level 1 (10) and level 2 (01).
        (0x0FFF_AAE9, 0x0FFF_AAE1),
        (0x0FFF_AAE5, 0x0FFF_AAE1),
        // Sectors 0 and 1 write-protected, the hardware watchdog (WDG_SW = 0), BOR off.
        (0x0FFC_AACD, 0x0FFC_AAC1),
    ];
    for (old, new) in cases {
        let change = flash::bor_level3(old).unwrap();
        assert_eq!((change.old, change.new), (old, new), "{old:#010x}");
        assert!(change.is_needed());
    }
    // At level 3 already: nothing to write.
    let change = flash::bor_level3(0x0FFF_AAE1).unwrap();
    assert_eq!(change.new, 0x0FFF_AAE1);
    assert!(!change.is_needed());
    assert_eq!(flash::OPTCR_FACTORY, 0x0FFF_AAED);
    assert!(flash::bor_level_name(0x0FFF_AAED).starts_with("off"));
    assert!(flash::bor_level_name(0x0FFF_AAE1).starts_with("level 3"));
    // Read protection other than level 0: refused, naming the level; RDP is never written.
    for (old, level) in [(0x0FFF_00ED, 1), (0x0FFF_55ED, 1), (0x0FFF_CCED, 2)] {
        let err = flash::bor_level3(old).unwrap_err().to_string();
        assert!(
            err.contains("read-protected") && err.contains(&format!("level {level}")),
            "{old:#010x}: {err}"
        );
    }
}

/// The dry run of `--set-bor` needs no probe and shows the rule, the factory word's change and
/// the `Disarm` it would send first.
#[test]
fn dry_run_set_bor_shows_the_option_word_and_the_disarm() {
    let out = host(&["flash", "--set-bor", "--dry-run"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let text = String::from_utf8_lossy(&out.stdout);
    for want in [
        "FLASH_OPTCR 0x40023c14: BOR_LEV (bits 3:2) := 00",
        "RDP (bits 15:8) never written",
        "0x0fffaaed -> 0x0fffaae1",
        "asks before writing",
        "disarm    first: Disarm to the device on the port with the board's USB id",
    ] {
        assert!(text.contains(want), "{want:?} not in {text}");
    }
}

/// `--set-bor` without a terminal to ask at and without `--yes` is refused before any port or
/// probe is opened; with `--yes` it goes on to the disarm and the probe (none here). It takes
/// no firmware or bank.
#[test]
fn set_bor_is_confirmed_or_refused_before_the_probe() {
    let out = host(&[
        "flash",
        "--set-bor",
        "--probe",
        "fffe:fffd:no-such-probe",
        "--port",
        "/dev/no-such-port",
    ]);
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains("stdin is not a terminal") && err.contains("--yes"),
        "{err}"
    );
    assert!(!err.contains("probe") && !err.contains("disarm"), "{err}");
    let out = host(&[
        "flash",
        "--set-bor",
        "--yes",
        "--probe",
        "fffe:fffd:no-such-probe",
        "--port",
        "/dev/no-such-port",
    ]);
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("no device connected to disarm"), "{err}");
    assert!(
        err.contains("no debug probe fffe:fffd:no-such-probe found"),
        "{err}"
    );
    let dir = tempfile::tempdir().unwrap();
    let bank = write(dir.path(), "b.bank", &bank(65_536));
    let out = host(&["flash", "--set-bor", "--bank", &bank, "--dry-run"]);
    assert!(!out.status.success());
    assert!(
        stderr(&out).contains("cannot be used with"),
        "{}",
        stderr(&out)
    );
}

/// A device connected on the port given (a fake one on a pseudo-terminal that answers
/// `Disarm` with disarmed telemetry) is sent `Disarm` before the probe is opened, and the
/// output says so.
#[cfg(target_os = "linux")]
#[test]
fn flash_disarms_a_connected_device_first() {
    use bank_format::{
        Counters, DeviceToHost, FrameDecoder, HostToDevice, MAX_FRAME, Mode, State, Telemetry,
        encode_frame,
    };
    use std::io::{Read, Write};
    use std::sync::atomic::{AtomicBool, Ordering};
    use std::sync::{Arc, Mutex};
    let (mut master, name, _slave) = pty();
    let stop = Arc::new(AtomicBool::new(false));
    let seen = Arc::new(Mutex::new(Vec::new()));
    let device = {
        let (stop, seen) = (Arc::clone(&stop), Arc::clone(&seen));
        std::thread::spawn(move || {
            let mut rx: FrameDecoder<HostToDevice> = FrameDecoder::new();
            let (mut bytes, mut buf) = ([0u8; 256], [0u8; MAX_FRAME]);
            while !stop.load(Ordering::Relaxed) {
                if let Ok(n) = master.read(&mut bytes) {
                    for msg in rx.feed_slice(&bytes[..n]).flatten() {
                        if msg == HostToDevice::Disarm {
                            let t = Telemetry {
                                tick: 1,
                                state: State::Disarmed,
                                mode: Mode::Render,
                                fault: None,
                                tip_m: [0.0; 3],
                                contacts: Default::default(),
                                contact_point: None,
                                currents_a: [0.0; 3],
                                tool_force_n: [0.0; 3],
                                dropped_load: 0.0,
                                counters: Counters::default(),
                            };
                            let frame = encode_frame(&DeviceToHost::Telemetry(t), &mut buf);
                            let _ = master.write_all(frame.unwrap());
                        }
                        seen.lock().unwrap().push(msg);
                    }
                }
                std::thread::sleep(std::time::Duration::from_millis(1));
            }
        })
    };
    let dir = tempfile::tempdir().unwrap();
    let elf = write(dir.path(), "fw.elf", &image());
    let bank = write(dir.path(), "b.bank", &bank(65_536));
    let out = host(&[
        "flash",
        "--elf",
        &elf,
        "--bank",
        &bank,
        "--probe",
        "fffe:fffd:no-such-probe",
        "--port",
        &name,
    ]);
    stop.store(true, Ordering::Relaxed);
    device.join().unwrap();
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains(&format!(
            "sent Disarm to the device on {name}: it reports Disarmed"
        )),
        "{err}"
    );
    assert!(
        err.contains("no debug probe fffe:fffd:no-such-probe found"),
        "{err}"
    );
    assert_eq!(*seen.lock().unwrap(), [HostToDevice::Disarm]);
}

/// A pseudo-terminal, both ends close-on-exec: (non-blocking master, slave path, slave).
#[cfg(target_os = "linux")]
fn pty() -> (std::fs::File, String, std::fs::File) {
    use std::os::fd::FromRawFd;
    // SAFETY: posix_openpt(3), grantpt(3), unlockpt(3), ptsname_r(3) and open(2) on a fresh
    // descriptor, each checked; ptsname_r writes a NUL-terminated name into the buffer given.
    unsafe {
        let m = libc::posix_openpt(libc::O_RDWR | libc::O_NOCTTY | libc::O_CLOEXEC);
        assert!(m >= 0, "posix_openpt failed");
        assert_eq!(libc::grantpt(m), 0, "grantpt failed");
        assert_eq!(libc::unlockpt(m), 0, "unlockpt failed");
        let mut buf = [0 as libc::c_char; 64];
        assert_eq!(libc::ptsname_r(m, buf.as_mut_ptr(), buf.len()), 0);
        let name = std::ffi::CStr::from_ptr(buf.as_ptr())
            .to_string_lossy()
            .into_owned();
        let s = libc::open(
            buf.as_ptr(),
            libc::O_RDWR | libc::O_NOCTTY | libc::O_CLOEXEC,
        );
        assert!(s >= 0, "opening {name} failed");
        libc::fcntl(
            m,
            libc::F_SETFL,
            libc::fcntl(m, libc::F_GETFL) | libc::O_NONBLOCK,
        );
        (
            std::fs::File::from_raw_fd(m),
            name,
            std::fs::File::from_raw_fd(s),
        )
    }
}
