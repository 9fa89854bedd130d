//! `host demo`: the headless figures, Ctrl-C, its errors, recording (through the library's
//! `haptic::demo::run`), and the viewer in headless Chromium.

mod support;
use support::chromium;

use haptic::demo::{DemoConfig, Frontend};
use haptic::display::source::SourceSpec;
use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

fn host() -> Command {
    Command::new(env!("CARGO_BIN_EXE_host"))
}

/// One demo test at a time: each runs a 1 kHz loop, a display and sometimes QEMU or Chromium,
/// and two at once on a 2-core machine starve the viewer's screenshot of its frames.
fn one_at_a_time() -> std::sync::MutexGuard<'static, ()> {
    static LOCK: std::sync::Mutex<()> = std::sync::Mutex::new(());
    LOCK.lock().unwrap_or_else(|e| e.into_inner())
}

/// The peak force of a headless press run (`v`, its JSON summary) against the force the
/// firmware's tick renders for a press of `depth` at the run's press point with the scene's
/// law (`host contact probe --depth D --law`), within 10 %: the run presses straight down the
/// shaft, 18 degrees off the contact triangle's normal along which the probe presses (3.6 %
/// apart at 8 mm).
fn assert_peak_is_the_probes(v: &serde_json::Value, depth: f64) {
    let peak = v["peak_force_n"].as_f64().unwrap();
    let at: Vec<f64> = v["press_point_m"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect();
    let scene = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/liver.toml");
    let liver = haptic::organ::Organ::load(&scene).unwrap();
    let bytes = haptic::bank::scene_bank(&scene).unwrap();
    let aligned = bank_format::AlignedBytes::new(&bytes);
    let bank = bank_format::Bank::parse(&aligned).unwrap();
    let organ = (&liver.mesh.nodes[..], &liver.surface.triangles[..]);
    let pressed = haptic::probe::probe(&bank, organ, [at[0], at[1], at[2]], Some(depth), true)
        .unwrap()
        .force_n
        .unwrap();
    let want = pressed.iter().map(|x| x * x).sum::<f64>().sqrt();
    assert!(
        (peak / want - 1.0).abs() < 0.1,
        "peak {peak} N, probe {want} N: {v}"
    );
}

#[test]
fn headless_press_prints_the_figures_as_json() {
    let _turn = one_at_a_time();
    let out = host()
        .args(["demo", "--headless", "--seconds", "3", "--script", "press"])
        .args(["--json", "--port", "0"])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    // With --json, stdout is exactly one JSON object (the viewer's address goes to stderr).
    let json = String::from_utf8(out.stdout).unwrap();
    let v: serde_json::Value = serde_json::from_str(&json).unwrap();
    for key in [
        "tick_rate_hz",
        "max_jitter_us",
        "display_fps",
        "peak_force_n",
    ] {
        assert!(v[key].as_f64().is_some(), "{key} missing in {json}");
    }
    // The press reaches 8 mm into the liver along the shaft 1.5 s into the 3 s run.
    assert_peak_is_the_probes(&v, 0.008);
    assert_eq!(v["faults"], 0, "{json}");
    // The shipped scene has no display law P: the surface is shown as the linear model
    // computes it, and the press bulges it sideways.
    let radial = v["max_radial_linear_m"].as_f64().unwrap();
    assert!(radial > 1e-4, "{json}");
    assert_eq!(v["max_radial_displayed_m"].as_f64(), Some(radial), "{json}");
    // A 1 kHz loop, and at least half the display's 60 frames a second over the run.
    let rate = v["tick_rate_hz"].as_f64().unwrap();
    assert!((900.0..1100.0).contains(&rate), "{json}");
    assert!(v["frames"].as_u64().unwrap() >= 90, "{json}");
}

/// Ctrl-C (SIGINT) ends a run as the end of its `--seconds` would: the figures are printed
/// and the demo exits 0, long before its two minutes.
#[test]
fn ctrl_c_ends_the_run_with_its_figures() {
    let _turn = one_at_a_time();
    let t0 = Instant::now();
    let mut child = host()
        .args([
            "demo",
            "--headless",
            "--seconds",
            "120",
            "--json",
            "--port",
            "0",
        ])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Running once the viewer's address is printed (on stderr, with --json).
    let mut err = BufReader::new(child.stderr.take().unwrap());
    let mut line = String::new();
    while !line.starts_with("viewer") {
        line.clear();
        assert!(
            err.read_line(&mut line).unwrap() > 0,
            "the demo ended before serving"
        );
    }
    std::thread::sleep(Duration::from_secs(2));
    // SAFETY: kill(2) on the child's pid, which has not been reaped (no wait yet).
    assert_eq!(unsafe { libc::kill(child.id() as i32, libc::SIGINT) }, 0);
    let out = child.wait_with_output().unwrap();
    assert!(out.status.success(), "{:?}", out.status);
    assert!(t0.elapsed() < Duration::from_secs(60), "{:?}", t0.elapsed());
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    // At least half the display's 60 frames a second over the 2 s before the signal.
    assert!(v["frames"].as_u64().unwrap() >= 60, "{v}");
    assert_eq!(v["faults"], 0, "{v}");
}

/// The same display on the QEMU image (`--source sil`): its telemetry over the emulated USART,
/// paced to real time; the scripted 6 mm press renders the probe's force, at 1 kHz, with no fault.
#[test]
fn sil_source_drives_the_display() {
    let _turn = one_at_a_time();
    let out = host()
        .args([
            "demo",
            "--source",
            "sil",
            "--headless",
            // The press reaches its 6 mm at 1.5 s of the image's time; the run's seconds
            // count from when the SIL source starts, QEMU's boot included, and one suite run
            // reached only half the depth in 3 s: 5 s leaves room for a slow start.
            "--seconds",
            "5",
            "--script",
            "press",
            "--json",
            "--port",
            "0",
        ])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    let json = String::from_utf8_lossy(&out.stdout);
    let v: serde_json::Value = serde_json::from_str(&json).unwrap();
    let rate = v["tick_rate_hz"].as_f64().unwrap();
    assert!((900.0..1100.0).contains(&rate), "{json}");
    // The SIL session's press (`haptic::sil::script`) goes 6 mm deep.
    assert_peak_is_the_probes(&v, 0.006);
    assert_eq!(v["faults"], 0, "{json}");
    assert!(v["frames"].as_u64().unwrap() >= 90, "{json}");
}

/// Headless runs take any free port unless told otherwise, so two can run at once.
#[test]
fn two_headless_runs_at_once() {
    let _turn = one_at_a_time();
    let run = || {
        host()
            .args(["demo", "--headless", "--seconds", "2", "--json"])
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap()
    };
    let (a, b) = (run(), run());
    for child in [a, b] {
        let out = child.wait_with_output().unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(out.status.success(), "{err}");
        assert!(err.contains("viewer    http://127.0.0.1:"), "{err}");
        let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        assert_eq!(v["faults"], 0);
    }
}

#[test]
fn bad_sources_and_meshes_are_refused_with_a_clear_message() {
    let _turn = one_at_a_time();
    let out = host().args(["demo", "--source", "usb"]).output().unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("serial:<port>"));

    let out = host()
        .args(["demo", "--mesh", "/nonexistent/organ.msh"])
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("/nonexistent/organ.msh"));

    let out = host()
        .args(["demo", "--source", "serial:/nonexistent/tty", "--port", "0"])
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("/nonexistent/tty"));
}

/// A demo run without a terminal: notes and progress go nowhere, the viewer's address is
/// kept.
struct Quiet(std::sync::Mutex<Option<String>>);

impl Frontend for Quiet {
    fn note(&self, _: &str) {}

    fn progress(&self, _: &str) -> Box<dyn fem::progress::Progress + '_> {
        struct Nothing;
        impl fem::progress::Progress for Nothing {
            fn start(&self, _: u64) {}
            fn advance(&self, _: u64) {}
        }
        Box::new(Nothing)
    }

    fn viewer(&self, url: &str) {
        *self.0.lock().unwrap() = Some(url.to_string());
    }
}

/// The library's demo ([`haptic::demo::run`]), headless for 3 s with `--record`: every recorded
/// frame is the displayed surface, and the run's summary counts them.
#[test]
fn recorded_sequence_is_the_displayed_surface() {
    let _turn = one_at_a_time();
    let dir = tempfile::tempdir().unwrap();
    let rec = dir.path().join("rec");
    let config = DemoConfig {
        scene: None,
        mesh: None,
        units: None,
        source: SourceSpec::Virtual,
        baud: 921_600,
        port: 0,
        headless: true,
        seconds: Some(3.0),
        script: None,
        fps: 60.0,
        record: Some(rec.clone()),
        cache_nodes: 256,
    };
    let ui = Quiet(std::sync::Mutex::new(None));
    let summary = haptic::demo::run(&config, &ui, &AtomicBool::new(false)).unwrap();
    let url = ui.0.lock().unwrap().clone().expect("the viewer's address");
    assert!(url.starts_with("http://127.0.0.1:"), "{url}");
    let nodes = summary.display_nodes;
    let pvd = std::fs::read_to_string(rec.join("demo.pvd")).unwrap();
    let files: Vec<&str> = pvd
        .lines()
        .filter_map(|l| l.split("file=\"").nth(1)?.split('"').next())
        .collect();
    assert!(files.len() >= 5, "{pvd}");
    assert_eq!(summary.recorded, Some(files.len()));
    // The default scene is sampled: every frame is the displayed fine surface (triangles, VTK
    // type 5) with the displacement the viewer shows; the press moves it where the tool pushes.
    let array = |text: &str, name: &str| -> Vec<f64> {
        let body = text.split(&format!("Name=\"{name}\"")).nth(1).unwrap();
        let body = body.split_once('>').unwrap().1;
        let body = body.split("</DataArray>").next().unwrap();
        body.split_whitespace()
            .map(|x| x.parse().unwrap())
            .collect()
    };
    let mut pressed = 0;
    for f in &files {
        let text = std::fs::read_to_string(rec.join(f)).unwrap();
        assert!(text.contains(&format!("NumberOfPoints=\"{nodes}\"")), "{f}");
        let types = array(&text, "types");
        assert!(!types.is_empty() && types.iter().all(|&t| t == 5.0), "{f}");
        let u = array(&text, "displacement");
        assert_eq!(u.len(), 3 * nodes, "{f}");
        let force = array(&text, "tool_force");
        let push = force.iter().map(|x| x * x).sum::<f64>().sqrt();
        let moved = u.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        if push > 0.03 {
            pressed += 1;
            // At least 0.03 N on the tissue's ~18 N/m (n.W.n ~ 0.056 m/N): 1.7 mm under the tool.
            assert!(
                moved > 1e-3,
                "{f}: {push} N but the surface moved {moved} m"
            );
        } else if push == 0.0 {
            assert_eq!(moved, 0.0, "{f}: no force, yet the surface moved");
        }
    }
    assert!(pressed > 0, "the press never pushed: {pvd}");
    let leftovers = std::fs::read_dir(&rec)
        .unwrap()
        .filter(|e| {
            e.as_ref()
                .unwrap()
                .path()
                .extension()
                .is_some_and(|x| x == "tmp")
        })
        .count();
    assert_eq!(leftovers, 0);
}

#[test]
fn stalled_viewers_do_not_hold_up_the_frames() {
    let _turn = one_at_a_time();
    let mut child = host()
        .args([
            "demo",
            "--headless",
            "--seconds",
            "120",
            "--fps",
            "500",
            "--port",
            "0",
        ])
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let stdout = child.stdout.take().unwrap();
    let _demo = Demo(child);
    let addr = viewer_addr(stdout);
    // Two viewers that complete the WebSocket handshake and then never read.
    let mut stalled = Vec::new();
    for _ in 0..2 {
        let mut s = TcpStream::connect(&addr).unwrap();
        write!(
            s,
            "GET /ws HTTP/1.1\r\nHost: {addr}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n\
             Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\r\n"
        )
        .unwrap();
        stalled.push(s);
    }
    wait_for("both viewers", || status(&addr)["viewers"] == 2);
    // 1,500 frames of 7.4 kB are 11 MB per viewer, more than any socket buffer holds: a
    // pipeline that waited for its viewers would be stuck by then. Frames keep coming.
    let frames = || status(&addr)["frames"].as_u64().unwrap();
    let start = frames();
    wait_for("1,500 frames", || frames() > start + 1500);
    let later = frames();
    wait_for("frames after the buffers filled", || frames() > later + 100);
    drop(stalled);
}

/// The viewer's address from the first `viewer http://...` line the demo prints.
fn viewer_addr(stdout: std::process::ChildStdout) -> String {
    let line = BufReader::new(stdout)
        .lines()
        .map(Result::unwrap)
        .find(|l| l.starts_with("viewer"))
        .expect("the demo prints its viewer address");
    line.split_whitespace()
        .nth(1)
        .unwrap()
        .trim_start_matches("http://")
        .trim_end_matches('/')
        .to_string()
}

// ---- the viewer in headless Chromium ----

/// Kills the demo when the test ends, however it ends.
struct Demo(Child);

impl Drop for Demo {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

fn http(addr: &str, method: &str, path: &str, body: &str) -> String {
    let mut s = TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    write!(
        s,
        "{method} {path} HTTP/1.0\r\nHost: {addr}\r\nContent-Length: {}\r\n\r\n{body}",
        body.len()
    )
    .unwrap();
    let mut r = String::new();
    s.read_to_string(&mut r).unwrap();
    let (head, body) = r.split_once("\r\n\r\n").unwrap();
    assert!(
        head.contains(" 200 ") || head.contains(" 204 "),
        "{method} {path}: {head}"
    );
    body.to_string()
}

fn status(addr: &str) -> serde_json::Value {
    serde_json::from_str(&http(addr, "GET", "/api/status", "")).unwrap()
}

fn wait_for(what: &str, mut ok: impl FnMut() -> bool) {
    let end = Instant::now() + Duration::from_secs(60);
    while !ok() {
        assert!(Instant::now() < end, "timed out waiting for {what}");
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// How many pixels differ from the background (the top-left pixel's colour).
fn covered(image: &image::Rgb) -> usize {
    let background = image.pixels[0];
    image.pixels.iter().filter(|p| **p != background).count()
}

/// Screenshot of `url` (1000 x 700) by headless Chromium with software WebGL.
/// A screenshot of `url` into `out`; `None` when Chromium wrote none or did not finish within
/// 90 s (it was then killed).
fn screenshot(url: &str, out: &Path) -> Option<image::Rgb> {
    let profile = tempfile::tempdir().unwrap();
    let mut child = Command::new(chromium())
        .args([
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-quic",
            "--no-first-run",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            "--use-angle=swiftshader",
            "--enable-unsafe-swiftshader",
            "--window-size=1000,700",
            "--virtual-time-budget=4000",
        ])
        .arg(format!("--user-data-dir={}", profile.path().display()))
        .arg(format!("--screenshot={}", out.display()))
        .arg(url)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let started = std::time::Instant::now();
    let status = loop {
        if let Some(status) = child.try_wait().unwrap() {
            break status;
        }
        if started.elapsed() > Duration::from_secs(90) {
            let _ = child.kill();
            let _ = child.wait();
            return None;
        }
        std::thread::sleep(Duration::from_millis(100));
    };
    assert!(status.success(), "chromium failed on {url}");
    out.exists().then(|| image::Rgb::read(out))
}

mod image {
    use std::path::Path;

    /// An 8-bit RGB image.
    pub struct Rgb {
        pub width: usize,
        pub height: usize,
        pub pixels: Vec<[u8; 3]>,
    }

    impl Rgb {
        pub fn read(path: &Path) -> Rgb {
            let decoder = png::Decoder::new(std::fs::File::open(path).unwrap());
            let mut reader = decoder.read_info().unwrap();
            let mut buf = vec![0; reader.output_buffer_size()];
            let info = reader.next_frame(&mut buf).unwrap();
            let step = info.color_type.samples();
            assert_eq!(info.bit_depth, png::BitDepth::Eight);
            let pixels = buf[..info.buffer_size()]
                .chunks_exact(step)
                .map(|p| [p[0], p[1], p[2]])
                .collect();
            Rgb {
                width: info.width as usize,
                height: info.height as usize,
                pixels,
            }
        }
    }
}

#[test]
fn viewer_renders_the_liver_and_the_press_deforms_it_under_the_tool() {
    let _turn = one_at_a_time();
    // The demo's stderr goes to a file, so that a demo that stops early says why.
    let log = tempfile::NamedTempFile::new().unwrap();
    let mut child = host()
        .args(["demo", "--port", "0", "--seconds", "180"])
        .stdout(Stdio::piped())
        .stderr(log.reopen().unwrap())
        .spawn()
        .unwrap();
    let stdout = child.stdout.take().unwrap();
    let _demo = Demo(child);
    let line = BufReader::new(stdout)
        .lines()
        .map(Result::unwrap)
        .find(|l| l.starts_with("viewer"))
        .unwrap();
    let url = line.split_whitespace().nth(1).unwrap().to_string();
    let addr = url
        .trim_start_matches("http://")
        .trim_end_matches('/')
        .to_string();
    wait_for("the first frames", || {
        status(&addr)["frames"].as_u64() > Some(10)
    });

    // The page and its assets are served from the binary.
    let page = http(&addr, "GET", "/", "");
    assert!(page.contains("viewer.js"));
    let info: serde_json::Value =
        serde_json::from_str(&http(&addr, "GET", "/api/info", "")).unwrap();
    // The default scene is sampled: the display is its FEM mesh's surface
    // (liver-reach-2.8mm), not the 620 surface nodes of the collision mesh.
    assert_eq!(info["display_nodes"], 4242);

    let dir = tempfile::tempdir().unwrap();
    // Tool hidden (`tool=0`): only the organ changes between the two screenshots. Chromium
    // takes the screenshot when its virtual-time budget ends, which a busy machine can reach
    // before the WebSocket delivered frames: the page's own report (tagged per attempt) says
    // what it had, and the shot is retaken until it had frames (and, after the press, the
    // contact). A shot whose canvas is blank is retaken too: headless Chromium can capture the
    // page in the instant after a viewport change cleared the canvas and before the next draw
    // (a blank organ in one shot of a fresh machine's run); six blank shots in a row still fail.
    let shot = |name: &str, contact: bool| {
        for attempt in 0..6 {
            let tag = format!("{name}-{attempt}");
            let png = dir.path().join(format!("{tag}.png"));
            let Some(image) = screenshot(&format!("{url}?tool=0&tag={tag}"), &png) else {
                // Chromium hung (a loaded machine) or wrote no picture: retake.
                continue;
            };
            let report = status(&addr)["report"].clone();
            if report["tag"] == tag.as_str()
                && covered(&image) * 20 > image.pixels.len()
                && report["frames"].as_u64() >= Some(3)
                && (!contact || report["contacts"].as_u64() > Some(0))
            {
                return (image, report);
            }
        }
        panic!(
            "the page never showed received frames in a screenshot ({name}); the demo's \
             stderr:\n{}",
            std::fs::read_to_string(log.path()).unwrap_or_default()
        );
    };
    let (before, _) = shot("before", false);

    // Not a blank canvas (`shot` checked that the organ covers a good part of the view): the
    // organ is shaded in many tones.
    let mut tones: Vec<[u8; 3]> = before.pixels.clone();
    tones.sort_unstable();
    tones.dedup();
    assert!(
        tones.len() > 100,
        "{} colours: flat, unshaded?",
        tones.len()
    );

    // Press 8 mm into the top of the organ and wait for the tool to settle in contact.
    let aim = &info["press_point"];
    http(
        &addr,
        "POST",
        "/api/steer",
        &format!("{{\"aim\": {aim}, \"depth\": 0.008}}"),
    );
    let mut last_tip = serde_json::Value::Null;
    wait_for("a settled contact", || {
        let f = status(&addr)["frame"].clone();
        let settled =
            f["contacts"].as_u64() > Some(0) && f["exact"] == true && f["tip_m"] == last_tip;
        last_tip = f["tip_m"].clone();
        settled
    });
    let force = status(&addr)["frame"]["tool_force_n"].clone();
    let (after, report) = shot("after", true);
    // The HUD's force trace holds the frames it received, and its newest point is the
    // settled force the frames carry (the same |F|, to f32).
    let trace = &report["trace"];
    let magnitude = force
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap().powi(2))
        .sum::<f64>()
        .sqrt();
    assert!(trace["points"].as_u64() >= Some(3), "{report}");
    assert!(trace["span_s"].as_f64().unwrap() > 0.0, "{report}");
    let last = trace["last_n"].as_f64().unwrap();
    assert!(
        magnitude > 0.0 && (last / magnitude - 1.0).abs() < 0.05,
        "trace's newest |F| {last} N, the frame's {magnitude} N: {report}"
    );
    assert!(trace["max_n"].as_f64().unwrap() >= last);
    let tip = &report["tip_px"];
    let (tx, ty) = (tip[0].as_f64().unwrap(), tip[1].as_f64().unwrap());

    // The rendered mesh changed, and where it changed most is around the tool tip. The organ is
    // tinted by displacement, so an 8 mm press shifts the tone of the whole lobe a little (by how
    // much depends on the settled contact): the test looks at the pixels that changed by at least
    // half the largest change, the indented, most displaced surface.
    assert_eq!((after.width, after.height), (before.width, before.height));
    let change = |a: &[u8; 3], b: &[u8; 3]| (0..3).map(|c| a[c].abs_diff(b[c])).max().unwrap_or(0);
    // The HUD (force, tick rate, the force trace) changes too: only count the pixels beside or
    // below it (it ends about 250 px down).
    let below_hud = |i: usize| i % before.width > 460 || i / before.width > 270;
    let pairs = || {
        before
            .pixels
            .iter()
            .zip(&after.pixels)
            .enumerate()
            .filter(|(i, _)| below_hud(*i))
    };
    let largest = pairs().map(|(_, (a, b))| change(a, b)).max().unwrap_or(0);
    assert!(
        largest > 48,
        "the largest change is {largest}; force {force}"
    );
    let changed: Vec<(f64, f64)> = pairs()
        .filter(|(_, (a, b))| 2 * u16::from(change(a, b)) >= u16::from(largest))
        .map(|(i, _)| ((i % before.width) as f64, (i / before.width) as f64))
        .collect();
    assert!(
        changed.len() > 100,
        "only {} pixels changed by half the largest change ({largest}); force {force}",
        changed.len()
    );
    let n = changed.len() as f64;
    let (cx, cy) = changed
        .iter()
        .fold((0.0, 0.0), |(x, y), p| (x + p.0 / n, y + p.1 / n));
    let near = changed
        .iter()
        .filter(|p| (p.0 - tx).hypot(p.1 - ty) < 150.0)
        .count();
    assert!(
        (cx - tx).hypot(cy - ty) < 60.0 && near as f64 > 0.9 * n,
        "change centred at ({cx:.0}, {cy:.0}), tip at ({tx:.0}, {ty:.0}); {near} of {n} within 150 px"
    );
}
