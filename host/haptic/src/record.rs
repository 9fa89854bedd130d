//! `--record <dir>`: the deformation sequence as a ParaView series, `<dir>/demo.pvd` listing
//! `<dir>/frame_NNNNNN.vtu` files (every file written atomically: temp file, fsync, rename).
//!
//! What a `.vtu` holds depends on the scene's contact model ([`Recorded`]):
//! - nodal models: the whole tetrahedral organ, its points the deformed positions `x + u` with
//!   `u = K_ff^-1 f` for the frame's contact forces (one sequential solve with the kept
//!   factorisation, the volume counterpart of the display's `C[:, S] f_S`), point data
//!   `displacement` (m) and `force` (N, non-zero on the contact nodes);
//! - the sampled model: the displayed fine FEM surface (triangles) with the displacement the
//!   viewer shows, `u = U(p) F` from the display fields, point data `displacement` (m); no solve.
//!
//! Every frame also carries the tool force (N) as field data `tool_force`. The recorder runs in
//! its own thread and takes at most [`RECORD_FPS`] frames per second; when it is busy, frames
//! are skipped, never waited for.

use crate::display::{DisplayMesh, FrameInfo, FrameSink};
use crate::fsio::write_atomic;
use anyhow::{Context, Result};
use faer::{Mat, Par};
use fem::compliance::Compliance;
use fem::mesh::TetMesh;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::mpsc::{Receiver, SyncSender, TrySendError, sync_channel};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// Largest recording rate, frames per second.
pub const RECORD_FPS: f64 = 20.0;

/// What the recorder writes per frame.
pub enum Recorded {
    /// The whole tetrahedral organ, deformed by a solve with the kept factorisation (nodal
    /// contact models: the frame's contacts are forces on mesh nodes).
    Volume {
        /// The organ.
        mesh: Arc<TetMesh>,
        /// Its factorised stiffness.
        compliance: Arc<Compliance>,
    },
    /// The displayed surface with the frame's displacement as shown (sampled contact model).
    Surface(Arc<DisplayMesh>),
}

struct Job {
    time_s: f64,
    tool_force_n: [f32; 3],
    contacts: Vec<(usize, [f32; 3])>,
    u: Vec<[f32; 3]>,
}

/// The recorder: a [`FrameSink`] feeding a writer thread.
pub struct Recorder {
    jobs: Option<SyncSender<Job>>,
    thread: Option<JoinHandle<Result<usize>>>,
    started: Instant,
    last: Option<Instant>,
}

impl Recorder {
    /// Creates `dir` if needed and starts the writer thread.
    pub fn start(dir: &Path, what: Recorded) -> Result<Recorder> {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("cannot create the recording directory {}", dir.display()))?;
        let (tx, rx) = sync_channel(1);
        let dir = dir.to_path_buf();
        let thread = std::thread::Builder::new()
            .name("recorder".into())
            .spawn(move || write_all(&dir, &what, &rx))?;
        Ok(Recorder {
            jobs: Some(tx),
            thread: Some(thread),
            started: Instant::now(),
            last: None,
        })
    }

    /// Stops after the frame in progress; returns how many frames were written.
    pub fn finish(mut self) -> Result<usize> {
        self.jobs.take();
        match self.thread.take().map(|t| t.join()) {
            Some(Ok(r)) => r,
            Some(Err(_)) => anyhow::bail!("the recorder thread panicked"),
            None => Ok(0),
        }
    }
}

impl FrameSink for Recorder {
    fn frame(&mut self, info: &FrameInfo, contacts: &[(usize, [f32; 3])], u: &[[f32; 3]]) {
        let now = Instant::now();
        if self
            .last
            .is_some_and(|l| now - l < Duration::from_secs_f64(1.0 / RECORD_FPS))
        {
            return;
        }
        let Some(jobs) = &self.jobs else { return };
        let job = Job {
            time_s: (now - self.started).as_secs_f64(),
            tool_force_n: info.tool_force_n,
            contacts: contacts.to_vec(),
            u: u.to_vec(),
        };
        match jobs.try_send(job) {
            Ok(()) => self.last = Some(now),
            Err(TrySendError::Full(_)) | Err(TrySendError::Disconnected(_)) => {}
        }
    }
}

fn write_all(dir: &Path, what: &Recorded, jobs: &Receiver<Job>) -> Result<usize> {
    let mut entries: Vec<(f64, PathBuf)> = Vec::new();
    while let Ok(job) = jobs.recv() {
        let name = PathBuf::from(format!("frame_{:06}.vtu", entries.len()));
        let text = match what {
            Recorded::Volume { mesh, compliance } => {
                let mut forces = vec![0.0; 3 * mesh.nodes.len()];
                for &(k, f) in &job.contacts {
                    if k < mesh.nodes.len() {
                        (0..3).for_each(|i| forces[3 * k + i] += f64::from(f[i]));
                    }
                }
                let u = solve_sequential(compliance, &forces);
                let cells = Cells::Tetrahedra(&mesh.tets);
                vtu(&mesh.nodes, cells, &u, Some(&forces), job.tool_force_n)
            }
            Recorded::Surface(surface) => {
                let rest: Vec<[f64; 3]> = surface.rest.iter().map(|p| p.map(f64::from)).collect();
                let mut u: Vec<f64> = job.u.iter().flatten().map(|&x| f64::from(x)).collect();
                u.resize(3 * rest.len(), 0.0);
                let cells = Cells::Triangles(&surface.triangles);
                vtu(&rest, cells, &u, None, job.tool_force_n)
            }
        };
        write_atomic(&dir.join(&name), text.as_bytes(), &[])?;
        entries.push((job.time_s, name));
        write_atomic(&dir.join("demo.pvd"), pvd(&entries).as_bytes(), &[])?;
    }
    Ok(entries.len())
}

/// `u = K_ff^-1 f` (node-major, zeros at fixed dofs) on one thread.
fn solve_sequential(c: &Compliance, forces: &[f64]) -> Vec<f64> {
    let dofs = c.dofs();
    let mut rhs = Mat::<f64>::zeros(dofs.free_count(), 1);
    for node in 0..dofs.nodes() {
        for comp in 0..3 {
            if let Some(d) = dofs.free_dof(node, comp) {
                rhs[(d, 0)] = forces[3 * node + comp];
            }
        }
    }
    if dofs.free_count() > 0 {
        c.solve_in_place(rhs.as_mut(), Par::Seq);
    }
    let free: Vec<f64> = (0..dofs.free_count()).map(|i| rhs[(i, 0)]).collect();
    dofs.expand(&free)
}

/// The cells of a recorded frame.
#[derive(Clone, Copy)]
enum Cells<'a> {
    Tetrahedra(&'a [[usize; 4]]),
    Triangles(&'a [[u32; 3]]),
}

/// One `.vtu` (ASCII): deformed points `rest + u`, the cells, point data `displacement` (and
/// `force` when given), field data `tool_force`.
fn vtu(
    rest: &[[f64; 3]],
    cells: Cells<'_>,
    u: &[f64],
    forces: Option<&[f64]>,
    tool_force_n: [f32; 3],
) -> String {
    let n = rest.len();
    let (t, per, kind) = match cells {
        Cells::Tetrahedra(c) => (c.len(), 4, 10),
        Cells::Triangles(c) => (c.len(), 3, 5),
    };
    let mut s = String::with_capacity(120 * n + 40 * t);
    s.push_str("<?xml version=\"1.0\"?>\n<VTKFile type=\"UnstructuredGrid\" version=\"1.0\" byte_order=\"LittleEndian\">\n<UnstructuredGrid>\n");
    let [fx, fy, fz] = tool_force_n;
    let _ = writeln!(
        s,
        "<FieldData>\n<DataArray type=\"Float64\" Name=\"tool_force\" NumberOfComponents=\"3\" NumberOfTuples=\"1\" format=\"ascii\">\n{fx:e} {fy:e} {fz:e}\n</DataArray>\n</FieldData>"
    );
    let _ = writeln!(s, "<Piece NumberOfPoints=\"{n}\" NumberOfCells=\"{t}\">");
    s.push_str("<PointData Vectors=\"displacement\">\n");
    for (name, data) in [("displacement", Some(u)), ("force", forces)] {
        let Some(data) = data else { continue };
        let _ = writeln!(
            s,
            "<DataArray type=\"Float64\" Name=\"{name}\" NumberOfComponents=\"3\" format=\"ascii\">"
        );
        for v in data.chunks_exact(3) {
            let _ = writeln!(s, "{:e} {:e} {:e}", v[0], v[1], v[2]);
        }
        s.push_str("</DataArray>\n");
    }
    s.push_str("</PointData>\n<Points>\n<DataArray type=\"Float64\" NumberOfComponents=\"3\" format=\"ascii\">\n");
    for (p, d) in rest.iter().zip(u.chunks_exact(3)) {
        let _ = writeln!(s, "{:e} {:e} {:e}", p[0] + d[0], p[1] + d[1], p[2] + d[2]);
    }
    s.push_str("</DataArray>\n</Points>\n<Cells>\n<DataArray type=\"Int64\" Name=\"connectivity\" format=\"ascii\">\n");
    match cells {
        Cells::Tetrahedra(c) => c
            .iter()
            .for_each(|c| _ = writeln!(s, "{} {} {} {}", c[0], c[1], c[2], c[3])),
        Cells::Triangles(c) => c
            .iter()
            .for_each(|c| _ = writeln!(s, "{} {} {}", c[0], c[1], c[2])),
    }
    s.push_str("</DataArray>\n<DataArray type=\"Int64\" Name=\"offsets\" format=\"ascii\">\n");
    for i in 1..=t {
        let _ = writeln!(s, "{}", per * i);
    }
    s.push_str("</DataArray>\n<DataArray type=\"UInt8\" Name=\"types\" format=\"ascii\">\n");
    for _ in 0..t {
        let _ = writeln!(s, "{kind}");
    }
    s.push_str("</DataArray>\n</Cells>\n</Piece>\n</UnstructuredGrid>\n</VTKFile>\n");
    s
}

/// The `.pvd` collection: one `DataSet` per frame with its time in seconds.
fn pvd(entries: &[(f64, PathBuf)]) -> String {
    let mut s = String::from(
        "<?xml version=\"1.0\"?>\n<VTKFile type=\"Collection\" version=\"0.1\">\n<Collection>\n",
    );
    for (t, f) in entries {
        let _ = writeln!(
            s,
            "<DataSet timestep=\"{t:.6}\" group=\"\" part=\"0\" file=\"{}\"/>",
            f.display()
        );
    }
    s.push_str("</Collection>\n</VTKFile>\n");
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A frame's info with the tool force `tool_force_n`.
    fn info(tool_force_n: [f32; 3]) -> FrameInfo {
        FrameInfo {
            seq: 0,
            tick: 1,
            state: bank_format::State::Armed,
            contacts: 1,
            exact: true,
            tip_m: [0.0; 3],
            tool_force_n,
            tick_rate_hz: 1000.0,
            display_fps: 60.0,
            max_jitter_us: 0.0,
        }
    }

    #[test]
    fn recorded_frames_read_back_deformed_with_every_point() {
        let (mesh, c, _) = crate::deform::tests::resting_block([0.04, 0.02, 0.02], [4, 2, 2]);
        let top = (0..mesh.nodes.len())
            .find(|&i| mesh.nodes[i][2] > 0.0199)
            .unwrap();
        let f = [0.0f32, 0.0, -0.2];
        let mut forces = vec![0.0; 3 * mesh.nodes.len()];
        forces[3 * top + 2] = f64::from(f[2]);
        let reference = c.displacement(&forces);

        let dir = tempfile::tempdir().unwrap();
        let mesh = Arc::new(mesh);
        let what = Recorded::Volume {
            mesh: Arc::clone(&mesh),
            compliance: Arc::clone(&c),
        };
        let mut rec = Recorder::start(dir.path(), what).unwrap();
        rec.frame(&info([0.0, 0.0, 0.2]), &[(top, f)], &[]);
        assert_eq!(rec.finish().unwrap(), 1);

        let back = fem::mesh::read(&dir.path().join("frame_000000.vtu")).unwrap();
        assert_eq!(back.nodes.len(), mesh.nodes.len());
        assert_eq!(back.tets, mesh.tets);
        for (i, (p, q)) in back.nodes.iter().zip(&mesh.nodes).enumerate() {
            for a in 0..3 {
                let want = q[a] + reference[3 * i + a];
                assert!((p[a] - want).abs() < 1e-12, "node {i}: {p:?} vs {want}");
            }
        }
        assert!(
            reference[3 * top + 2] < -1e-4,
            "the press moves the node down"
        );
        let pvd = std::fs::read_to_string(dir.path().join("demo.pvd")).unwrap();
        assert!(pvd.contains("file=\"frame_000000.vtu\""));
        assert!(!dir.path().join("demo.pvd.tmp").exists());
    }

    #[test]
    fn a_sampled_scene_records_the_displayed_surface_as_shown() {
        let surface = Arc::new(DisplayMesh {
            rest: vec![[0.0, 0.0, 0.0], [0.01, 0.0, 0.0], [0.0, 0.01, 0.0]],
            triangles: vec![[0, 1, 2]],
        });
        let dir = tempfile::tempdir().unwrap();
        let mut rec = Recorder::start(dir.path(), Recorded::Surface(surface)).unwrap();
        let u = [[0.0, 0.0, -0.002], [0.0, 0.0, -0.001], [0.0, 0.0, 0.0]];
        rec.frame(&info([0.0, 0.0, 0.25]), &[], &u);
        assert_eq!(rec.finish().unwrap(), 1);
        let text = std::fs::read_to_string(dir.path().join("frame_000000.vtu")).unwrap();
        // Points at rest + u (f32 widened to f64 exactly), one triangle (VTK type 5).
        let points = text.split("<Points>").nth(1).unwrap();
        let values: Vec<f64> = points
            .split_once("ascii\">")
            .unwrap()
            .1
            .split("</DataArray>")
            .next()
            .unwrap()
            .split_whitespace()
            .map(|x| x.parse().unwrap())
            .collect();
        let want: Vec<f64> = [0.0, 0.0, -0.002f32, 0.01, 0.0, -0.001, 0.0, 0.01, 0.0]
            .iter()
            .map(|&x| f64::from(x))
            .collect();
        assert_eq!(values, want);
        assert!(text.contains("NumberOfCells=\"1\""));
        assert!(text.contains(">\n0 1 2\n</DataArray>"));
        assert!(text.contains(">\n5\n</DataArray>"));
        assert!(text.contains(">\n0e0 0e0 2.5e-1\n</DataArray>"), "{text}");
        assert!(!text.contains("Name=\"force\""));
    }
}
