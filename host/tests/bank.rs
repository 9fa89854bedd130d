//! `host bank build` / `inspect` on the shipped liver scene: the bank validates, damaged and
//! truncated copies are refused without a panic, and a failed build leaves no file behind.

mod force;

use bank_format::{AlignedBytes, Bank};
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn host(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_host"))
        .args(args)
        .output()
        .expect("run host")
}

fn scene() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/liver-nodal.toml")
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn files_in(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

#[test]
fn shipped_scene_builds_a_valid_bank_and_inspect_refuses_damaged_copies() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("liver.bank");
    let o = host(&["bank", "build", s(&scene()), "-o", s(&out)]);
    assert!(o.status.success(), "{}", stderr(&o));
    let summary = String::from_utf8_lossy(&o.stdout);
    assert!(
        summary.contains("region R") && summary.contains("KiB"),
        "{summary}"
    );
    assert_eq!(
        files_in(dir.path()),
        ["liver.bank"],
        "no temporary file left"
    );

    let bytes = std::fs::read(&out).unwrap();
    let aligned = AlignedBytes::new(&bytes);
    let bank = Bank::parse(&aligned).expect("the built bank validates");
    // R: a few hundred nodes of the upper surface, none of them on the bed.
    let n = bank.node_count();
    assert!((150..=450).contains(&n), "|R| = {n}");
    assert!(bank.positions().iter().all(|p| p[2] > 0.01));
    assert!(bank.bytes().len() <= 768 * 1024);
    assert!(
        summary.contains(&format!("{n} reachable surface nodes")),
        "{summary}"
    );

    // The scene's speed thresholds, the cell certificates, pairs stored once and the triangle
    // planes (format 5); format 8 (the link timeout in the device record), and the default
    // scene elastic (no relaxation section).
    assert_eq!(bank.version().0, 8);
    assert_eq!(bank.relaxation(), None);
    assert_eq!(bank.triangle_planes().len(), bank.triangles().len());
    assert_eq!(bank.device().max_tip_speed_m_s, 1.0);
    assert_eq!(bank.device().max_joint_speed, [10.0, 10.0, 1.0]);
    assert_eq!(bank.device().link_timeout_ms, 50);
    let o = host(&["bank", "inspect", s(&out)]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(
        text.contains("overspeed tip 1 m/s; joints 10 rad/s, 10 rad/s, 1 m/s"),
        "{text}"
    );
    assert!(text.contains("\nlink      timeout 50 ms\n"), "{text}");
    // The tool patches at the triangles' centroids, as the build printed them: the 3 mm tip
    // covers a few nodes, never more than the firmware's solve takes.
    let patches = haptic::bank::stats::tool_patches(&bank);
    assert!(
        (1..=firmware::solve::MAX_CONTACT_NODES).contains(&patches.max_nodes),
        "{patches:?}"
    );
    assert!((0.0..=1.0).contains(&patches.max_dropped), "{patches:?}");
    assert!(
        summary.contains(&format!(
            "patches of up to {} nodes at the triangles' centroids; at most {:.1}% of a patch's \
             load dropped",
            patches.max_nodes,
            100.0 * patches.max_dropped
        )),
        "{summary}"
    );
    let o = host(&["bank", "inspect", s(&out), "--json"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).expect("one JSON object");
    assert_eq!(v["nodes"], n);
    let candidates = haptic::bank::stats::grid_candidates(&bank);
    assert!(candidates.max >= 1 && candidates.mean_near_surface > 0.0);
    assert_eq!(v["grid"]["max_candidates"], candidates.max);
    assert_eq!(
        v["grid"]["mean_candidates_near_surface"],
        candidates.mean_near_surface
    );
    assert_eq!(v["crc32"], format!("{:08x}", bank.crc()));
    assert_eq!(v["device"]["max_tip_speed_m_s"], 1.0);
    assert_eq!(v["device"]["link_timeout_ms"], 50);
    assert_eq!(
        v["device"]["max_joint_speed"],
        serde_json::json!([10.0, 10.0, 1.0])
    );

    // One flipped byte in the middle (C_kl data): the CRC catches it.
    let mut damaged = bytes.clone();
    let mid = damaged.len() / 2;
    damaged[mid] ^= 0x10;
    let bad = dir.path().join("damaged.bank");
    std::fs::write(&bad, &damaged).unwrap();
    // Truncated copy.
    let short = dir.path().join("short.bank");
    std::fs::write(&short, &bytes[..bytes.len() - 8]).unwrap();
    // Empty file.
    let empty = dir.path().join("empty.bank");
    std::fs::write(&empty, []).unwrap();
    for (file, expect) in [(&bad, "CRC"), (&short, "too short"), (&empty, "too short")] {
        let o = host(&["bank", "inspect", s(file)]);
        let err = stderr(&o);
        assert!(!o.status.success(), "{}", file.display());
        assert_eq!(o.status.code(), Some(1), "{err}");
        assert!(
            err.contains("invalid bank") && err.to_lowercase().contains(&expect.to_lowercase()),
            "{err}"
        );
        assert!(!err.contains("panicked"), "{err}");
        assert!(o.stdout.is_empty());
    }
}

#[test]
fn failed_builds_leave_no_file() {
    let dir = tempfile::tempdir().unwrap();
    // Over the size limit: refused before anything is written.
    let out = dir.path().join("small.bank");
    let o = host(&[
        "bank",
        "build",
        s(&scene()),
        "-o",
        s(&out),
        "--region-bytes",
        "4096",
    ]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("bank region"), "{}", stderr(&o));
    assert!(
        files_in(dir.path()).is_empty(),
        "{:?}",
        files_in(dir.path())
    );

    // The output is an existing directory: refused, nothing written.
    let target = dir.path().join("occupied");
    std::fs::create_dir(&target).unwrap();
    let o = host(&["bank", "build", s(&scene()), "-o", s(&target)]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("not a regular file"), "{}", stderr(&o));
    assert_eq!(files_in(dir.path()), ["occupied"]);

    // A bad scene: error names the line and key, nothing written.
    let text = std::fs::read_to_string(scene()).unwrap();
    let bad_scene = dir.path().join("bad.toml");
    std::fs::write(&bad_scene, text.replace("poisson = 0.45", "poisson = 0.5")).unwrap();
    let out = dir.path().join("bad.bank");
    let o = host(&["bank", "build", s(&bad_scene), "-o", s(&out)]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("material.poisson"), "{}", stderr(&o));
    assert!(!out.exists());
}

/// The output never destroys: not the scene it reads (through any path), not a FIFO or a
/// device, not a symbolic link (its target gets the bank).
#[test]
fn outputs_never_replace_inputs_links_or_special_files() {
    let dir = tempfile::tempdir().unwrap();
    let scene_copy = dir.path().join("liver.toml");
    let text = std::fs::read_to_string(scene()).unwrap();
    std::fs::write(&scene_copy, &text).unwrap();
    let alias = dir.path().join("alias.toml");
    std::os::unix::fs::symlink(&scene_copy, &alias).unwrap();
    for out in [&scene_copy, &alias] {
        let o = host(&["bank", "build", s(&scene_copy), "-o", s(out)]);
        assert!(!o.status.success());
        assert!(stderr(&o).contains("that is the input"), "{}", stderr(&o));
    }
    assert_eq!(std::fs::read_to_string(&scene_copy).unwrap(), text);

    let fifo = dir.path().join("fifo");
    assert!(
        Command::new("mkfifo")
            .arg(&fifo)
            .status()
            .unwrap()
            .success()
    );
    for out in [fifo.as_path(), Path::new("/dev/null")] {
        let o = host(&["bank", "build", s(&scene_copy), "-o", s(out)]);
        assert!(!o.status.success(), "{out:?}");
        assert!(stderr(&o).contains("not a regular file"), "{}", stderr(&o));
    }
    use std::os::unix::fs::FileTypeExt;
    assert!(
        std::fs::symlink_metadata(&fifo)
            .unwrap()
            .file_type()
            .is_fifo()
    );
    assert!(
        std::fs::symlink_metadata("/dev/null")
            .unwrap()
            .file_type()
            .is_char_device()
    );

    let real = dir.path().join("real.bank");
    let link = dir.path().join("link.bank");
    std::os::unix::fs::symlink("real.bank", &link).unwrap();
    let o = host(&["bank", "build", s(&scene_copy), "-o", s(&link)]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        std::fs::symlink_metadata(&link)
            .unwrap()
            .file_type()
            .is_symlink()
    );
    let bytes = std::fs::read(&real).unwrap();
    assert!(Bank::parse(&AlignedBytes::new(&bytes)).is_ok());
    assert_eq!(
        files_in(dir.path()),
        ["alias.toml", "fifo", "link.bank", "liver.toml", "real.bank"]
    );
}

/// Scenes that cannot work are refused, naming the key: a trocar inside the organ, a home pose
/// with the tip inside it, a fixed set that holds every node, supports that leave it free (the
/// message names the scene file and its `[fixed]` table).
#[test]
fn scenes_that_cannot_work_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(scene()).unwrap();
    let liver = fem::mesh::parse_msh(haptic::scene::BUILTIN_LIVER).unwrap();
    let build = |from: &str, to: &str| {
        let edited = text.replacen(from, to, 1);
        assert!(edited != text, "{from} not in the scene");
        let p = dir.path().join("s.toml");
        std::fs::write(&p, edited).unwrap();
        let out = dir.path().join("s.bank");
        let o = host(&["bank", "build", s(&p), "-o", s(&out)]);
        assert!(!o.status.success(), "{to}");
        assert!(!out.exists());
        stderr(&o)
    };
    let [a, b, c, d] = liver.tets[0].map(|i| liver.nodes[i]);
    let inside: [f64; 3] = std::array::from_fn(|i| (a[i] + b[i] + c[i] + d[i]) / 4.0);
    let e = build(
        "fulcrum_m = [0.0, 0.0, 0.16]",
        &format!("fulcrum_m = [{}, {}, {}]", inside[0], inside[1], inside[2]),
    );
    assert!(e.contains("device.fulcrum_m lies inside the organ"), "{e}");
    // The shaft points straight down from (0, 0, 0.16): the first depth inside the liver.
    let depth = (30..=140)
        .map(|mm| f64::from(mm) * 1e-3)
        .find(|&d| liver.tet_containing([0.0, 0.0, 0.16 - d]).is_some())
        .expect("the liver lies under the trocar");
    let e = build(
        "home = [0.0, 0.0, 0.03]",
        &format!("home = [0.0, 0.0, {depth}]"),
    );
    assert!(
        e.contains("device.home puts the tool tip inside the organ"),
        "{e}"
    );
    let e = build("max = [1.0, 1.0, 0.01]", "max = [1.0, 1.0, 1.0]");
    assert!(e.contains("holds every node"), "{e}");
    let e = build(
        "{ min = [-1.0, -1.0, -1.0], max = [1.0, 1.0, 0.01] },",
        "{ min = [-1.0, -1.0, -1.0], max = [1.0, 1.0, 0.01], axes = \"z\" },",
    );
    assert!(
        e.contains("s.toml: [fixed]") && e.contains("rigid motions"),
        "{e}"
    );
    assert!(!e.contains("--fix-box"), "{e}");
}

/// The rest of the adversary's list: a sweep over no sites, a grid cell too small for any
/// bank, a file that is not a firmware image.
#[test]
fn odd_arguments_are_refused_with_their_name() {
    let o = host(&["bank", "sweep", s(&scene()), "--sites", "0"]);
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("--sites must be at least 1"),
        "{}",
        stderr(&o)
    );
    let dir = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(scene()).unwrap();
    let p = dir.path().join("s.toml");
    let edited = text.replacen("grid_cell_m = 0.006", "grid_cell_m = 1e-9", 1);
    assert!(edited != text);
    std::fs::write(&p, edited).unwrap();
    let o = host(&["bank", "build", s(&p), "-o", s(&dir.path().join("x.bank"))]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("bank.grid_cell_m"), "{}", stderr(&o));
    let edited = text.replacen(
        "torque_constant_nm_per_a = [0.025, 0.025, 0.025]",
        "torque_constant_nm_per_a = [0.0, 0.025, 0.025]",
        1,
    );
    assert!(edited != text);
    std::fs::write(&p, edited).unwrap();
    let o = host(&["bank", "build", s(&p), "-o", s(&dir.path().join("x.bank"))]);
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("must lie in (0, 10], got 0"),
        "{}",
        stderr(&o)
    );
    let garbage = dir.path().join("garbage.elf");
    std::fs::write(&garbage, b"not a firmware image at all").unwrap();
    let o = host(&[
        "sil",
        "--image",
        s(&garbage),
        "--scene",
        s(&scene()),
        "--seconds",
        "0.1",
    ]);
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("not an image for this machine"),
        "{}",
        stderr(&o)
    );
}

/// A scene with the locking-free element builds a valid bank at a Poisson's ratio P1 refuses.
#[test]
fn the_locking_free_element_builds_a_bank() {
    let dir = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(scene()).unwrap();
    let edited = text.replacen("poisson = 0.45", "poisson = 0.499\nelement = \"anp\"", 1);
    let p = dir.path().join("anp.toml");
    std::fs::write(&p, edited).unwrap();
    let out = dir.path().join("anp.bank");
    let o = host(&["bank", "build", s(&p), "-o", s(&out)]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(!stderr(&o).contains("warning"), "{}", stderr(&o));
    let bytes = std::fs::read(&out).unwrap();
    assert!(Bank::parse(&AlignedBytes::new(&bytes)).is_ok());
}

#[test]
fn sweep_prints_a_row_per_rule_and_radius() {
    let sc = scene();
    let args = [
        "bank",
        "sweep",
        "--scene",
        s(&sc),
        "--radii",
        "0,0.03",
        "--sites",
        "20",
        "--precision",
        "f32,bfp16",
    ];
    let o = host(&args);
    assert!(o.status.success(), "{}", stderr(&o));
    let table = String::from_utf8_lossy(&o.stdout);
    let rows: Vec<&str> = table
        .lines()
        .filter(|l| l.starts_with("| radius |") || l.starts_with("| tool |"))
        .collect();
    assert_eq!(rows.len(), 6, "{table}");
    let o = host(&[args.as_slice(), &["--json"]].concat());
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let rows = v["rows"].as_array().unwrap();
    assert_eq!(rows.len(), 6, "{v}");
    // Per (rule, radius) one row per precision, f32 first.
    let (zero, tool, tool16) = (&rows[0], &rows[4], &rows[5]);
    assert_eq!(tool["rule"], "tool");
    assert_eq!(
        (tool["precision"].as_str(), tool16["precision"].as_str()),
        (Some("f32"), Some("bfp16"))
    );
    assert_eq!(
        tool["bank_bytes"].as_u64().unwrap() - tool16["bank_bytes"].as_u64().unwrap(),
        16 * tool["pairs"].as_u64().unwrap(),
        "{v}"
    );
    // Measured: bfp16 1.4e-5, f32 2.8e-7 (patch) and 2.0e-7 (point), against f64.
    assert!(tool16["patch_max"].as_f64().unwrap() <= 5e-5, "{v}");
    // Edges only: the tool patch loses couplings; the tool's pairs: exact forces.
    assert!(zero["patch_max"].as_f64().unwrap() > 1e-3, "{v}");
    assert!(tool["patch_max"].as_f64().unwrap() <= 5e-6, "{v}");
    assert!(tool["point_max"].as_f64().unwrap() <= 5e-6, "{v}");
    assert!(tool["fits_region"].as_bool().unwrap(), "{v}");
}

/// The firmware's loop on the shipped scene's bank (`host bench tick`'s run): every tick runs,
/// none faults, and the scripted path touches exactly where it goes below the surface.
#[test]
fn the_firmware_loop_runs_on_the_shipped_bank_without_faults() {
    let bytes = haptic::bank::scene_bank(&scene()).unwrap();
    let aligned = AlignedBytes::new(&bytes);
    let bank = Bank::parse(&aligned).unwrap();
    let r = haptic::bench::tick::run(&bank, 3000, 0.005).unwrap();
    assert_eq!((r.ticks, r.faults), (3000, 0), "{r:?}");
    // The path (0.05 mm a tick): 100 ticks down to the surface, 100 more to 5 mm, 2,000 of
    // sweep at that depth, 200 back out, then again: 300 of the 3,000 ticks are above the
    // surface, and the tick that detects a contact renders none.
    assert!((2650..=2750).contains(&r.touching), "{r:?}");
    assert!(r.max_contact_nodes >= 1, "{r:?}");
    // The press that ends at tick 2,600 (the second cycle's: the first one's falls inside the
    // loop's 300-tick ramp-in after arming) against the same press driven by the contact
    // probe's firmware tick (`haptic::probe::press`, on a fresh loop): straight along the shaft
    // at the home pose, 0.05 mm a tick from 5 mm above first contact to 5 mm past it, read on
    // arrival. Both tick the same firmware on the same bank with the scene's (linear) law, so
    // this checks the bench's path and its reading (measured: equal to 2e-8); 1 % leaves room
    // for f32 rounding. The probe's own normal press (`host contact probe --depth`) is not the
    // same press: the shaft meets the surface's facet about 19 degrees off its normal, beyond
    // the contact's stick cone (0.2), so the anchor slides and the patch is rebuilt on the way,
    // and the force depends on the path (a normal press to the same point renders 0.7 % more).
    let cal = *bank.device();
    let ws = haptic::kinematics::Workspace::from_device(&cal);
    let [pitch, yaw, _] = cal.home_joint.map(f64::from);
    let contact = ws.tip(pitch, yaw, r.contact_insertion_m);
    // The unit direction of the shaft: the tip 1 m from the fulcrum.
    let far = ws.tip(pitch, yaw, 1.0);
    let shaft: [f64; 3] = std::array::from_fn(|i| far[i] - ws.fulcrum[i]);
    let path = haptic::probe::PressPath {
        step_m: 0.00005,
        hold_ticks: 0,
    };
    let probe = haptic::probe::press(&bank, contact, shaft, 0.005, path, true).unwrap();
    let norm = |v: [f64; 3]| v.iter().map(|x| x * x).sum::<f64>().sqrt();
    let probe = norm(probe);
    let press = f64::from(r.press_force_n.expect("3,000 ticks end two presses"));
    println!("bench tick's press {press} N, the probe's {probe} N");
    assert!(
        (press / probe - 1.0).abs() < 0.01,
        "{press} N against the probe's {probe} N"
    );
    // The press above ticks the same loop on both sides, so it cannot see the loop itself
    // render too much; the probe's normal press there (frictionless: the anchor stays) can:
    // against the linear model's force for it, `W^-1 (D n)`, computed here from the probe's W
    // (the bank's patch compliance at the closest point) with the scene's linear law (Q the
    // identity). Measured 4.8e-4 apart (the tick builds its patch in f32 where the tip's path
    // crosses the bank's f32 triangle); 2e-3 allows for it, and a loop rendering 1 % more
    // fails (10 % more: tried, it does).
    let positions: Vec<[f64; 3]> = bank.positions().iter().map(|p| p.map(f64::from)).collect();
    let triangles: Vec<[usize; 3]> = bank
        .triangles()
        .iter()
        .map(|t| t.map(usize::from))
        .collect();
    let normal =
        haptic::probe::probe(&bank, (&positions, &triangles), contact, Some(0.005), true).unwrap();
    let rendered = normal.force_n.unwrap();
    let expected = force::linear_force(normal.w, normal.normal.map(|x| 0.005 * x));
    let error: [f64; 3] = std::array::from_fn(|i| rendered[i] - expected[i]);
    println!("normal press {rendered:?} N, W^-1 (D n) {expected:?} N");
    assert!(
        norm(error) < 2e-3 * norm(expected),
        "{rendered:?} N against W^-1 (D n) = {expected:?} N"
    );
    // The peak comes in the sweep at that depth (the tip moves sideways at a constant insertion
    // over the curved surface: 0.2605 N measured), which no single press reproduces: between
    // the press's force and the device's cap.
    let cap = bank.device().max_force_n;
    assert!(
        f64::from(r.peak_force_n) >= press && r.peak_force_n < cap,
        "{r:?}"
    );
    // The CLI prints the same run.
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("liver.bank");
    std::fs::write(&file, &bytes).unwrap();
    let out = host(&["bench", "tick", s(&file), "--ticks", "3000"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.contains(&format!("ticks 3000 ({} in contact", r.touching)),
        "{text}"
    );
}
