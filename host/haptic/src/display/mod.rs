//! The host display: from telemetry samples to deformed-surface frames for the browser viewer.
//!
//! [`source`] is where the samples come from (the [`Source`] trait: the virtual device, a
//! device on a serial port, the QEMU image).
//! [`Pipeline::run`] takes the newest [`Sample`] of a [`Source`] at a fixed frame rate, maps its
//! contact set to mesh nodes, computes the surface displacement ([`SurfaceModel`]: the nodal
//! [`Deformer`], or a sampled scene's precomputed fields on its fine mesh), applies the scene's
//! display law P to it ([`law`], the paper's eq. 4), and publishes
//! one binary frame ([`encode_frame`]) to the [`server`], which hands each viewer only the newest
//! frame (a slow or vanished browser drops frames; the loop thread never waits for anyone).
//! Optionally every frame is also offered to a recorder (ParaView series, [`crate::record`]).
//!
//! Wire format (little-endian), served once at `/mesh.bin`: `u32 nodes, u32 triangles,
//! f32 rest[3 nodes], u32 tri[3 triangles]`; and per frame over the WebSocket `/ws`:
//! [`FRAME_HEADER_BYTES`] of header (see [`encode_frame`]) then `f32 positions[3 nodes]`.

pub mod fields;
pub mod law;
pub mod server;
pub mod source;

use crate::deform::{Coverage, Deformer, SolveStats};
use bank_format::State;
use source::{LoopStats, Sample, Source};
use std::collections::HashMap;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// Magic of a frame, "HFR1".
pub const FRAME_MAGIC: u32 = u32::from_le_bytes(*b"HFR1");
/// Bytes of a frame header.
pub const FRAME_HEADER_BYTES: usize = 64;

/// The displayed surface: rest positions and triangles over the display nodes.
#[derive(Debug, Clone, PartialEq)]
pub struct DisplayMesh {
    /// Rest positions of the display nodes, m.
    pub rest: Vec<[f32; 3]>,
    /// Triangles (indices into `rest`), outward.
    pub triangles: Vec<[u32; 3]>,
}

impl DisplayMesh {
    /// The boundary `surface` of a volume mesh (node positions `nodes`, m) as the display shows
    /// it: the surface nodes' rest positions, in the order of `surface.nodes`, and the surface's
    /// triangles renumbered onto them.
    pub fn of_surface(nodes: &[[f64; 3]], surface: &fem::mesh::Surface) -> DisplayMesh {
        let index: HashMap<usize, u32> = surface
            .nodes
            .iter()
            .enumerate()
            .map(|(i, &k)| (k, i as u32))
            .collect();
        DisplayMesh {
            rest: surface
                .nodes
                .iter()
                .map(|&k| nodes[k].map(|x| x as f32))
                .collect(),
            triangles: surface
                .triangles
                .iter()
                .map(|t| t.map(|k| index.get(&k).copied().unwrap_or(0)))
                .collect(),
        }
    }

    /// The smallest box around the rest positions: `(lowest, highest)` corner, m.
    pub fn bounding_box(&self) -> ([f64; 3], [f64; 3]) {
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for p in &self.rest {
            for a in 0..3 {
                lo[a] = lo[a].min(f64::from(p[a]));
                hi[a] = hi[a].max(f64::from(p[a]));
            }
        }
        (lo, hi)
    }

    /// The `/mesh.bin` bytes.
    pub fn encode(&self) -> Vec<u8> {
        let mut b = Vec::with_capacity(8 + 12 * self.rest.len() + 12 * self.triangles.len());
        b.extend((self.rest.len() as u32).to_le_bytes());
        b.extend((self.triangles.len() as u32).to_le_bytes());
        self.rest
            .iter()
            .flatten()
            .for_each(|x| b.extend(x.to_le_bytes()));
        self.triangles
            .iter()
            .flatten()
            .for_each(|x| b.extend(x.to_le_bytes()));
        b
    }
}

/// Each node's neighbours along `triangles` (node ids as in the triangles, each list sorted
/// and without repeats): the ring of a contact node whose columns the nodal display prefetches
/// ([`SurfaceModel::Nodal`]).
pub fn surface_neighbours(triangles: &[[usize; 3]]) -> HashMap<usize, Vec<usize>> {
    let mut neighbours: HashMap<usize, Vec<usize>> = HashMap::new();
    for t in triangles {
        for i in 0..3 {
            let (a, b) = (t[i], t[(i + 1) % 3]);
            neighbours.entry(a).or_default().push(b);
            neighbours.entry(b).or_default().push(a);
        }
    }
    for v in neighbours.values_mut() {
        v.sort_unstable();
        v.dedup();
    }
    neighbours
}

/// What a frame says besides the positions.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameInfo {
    /// Frame number.
    pub seq: u32,
    /// Device tick of the sample.
    pub tick: u32,
    /// Safety state.
    pub state: State,
    /// Number of contact nodes.
    pub contacts: u8,
    /// Whether every contact node's own columns were used.
    pub exact: bool,
    /// Tool tip, m.
    pub tip_m: [f32; 3],
    /// Force rendered on the tool, N.
    pub tool_force_n: [f32; 3],
    /// Loop tick rate, Hz.
    pub tick_rate_hz: f32,
    /// Frames produced per second, Hz.
    pub display_fps: f32,
    /// Largest tick jitter so far, µs (negative when unknown).
    pub max_jitter_us: f32,
}

/// One frame: header `u32 magic, u32 seq, u32 tick, u8 state (0 disarmed, 1 armed, 2 fault),
/// u8 contacts, u8 exact, u8 0, f32 tip[3], f32 tool_force[3], f32 tick_rate_hz,
/// f32 display_fps, f32 max_jitter_us, u32 nodes`, zero padding to [`FRAME_HEADER_BYTES`], then
/// `f32 positions[3 nodes]`.
pub fn encode_frame(info: &FrameInfo, positions: &[[f32; 3]], out: &mut Vec<u8>) {
    out.clear();
    out.extend(FRAME_MAGIC.to_le_bytes());
    out.extend(info.seq.to_le_bytes());
    out.extend(info.tick.to_le_bytes());
    let state = match info.state {
        State::Disarmed => 0u8,
        State::Armed => 1,
        State::Fault => 2,
    };
    out.extend([state, info.contacts, u8::from(info.exact), 0]);
    for x in info.tip_m.iter().chain(&info.tool_force_n) {
        out.extend(x.to_le_bytes());
    }
    for x in [info.tick_rate_hz, info.display_fps, info.max_jitter_us] {
        out.extend(x.to_le_bytes());
    }
    out.extend((positions.len() as u32).to_le_bytes());
    out.resize(FRAME_HEADER_BYTES, 0);
    positions
        .iter()
        .flatten()
        .for_each(|x| out.extend(x.to_le_bytes()));
}

/// Display figures of a run.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize)]
pub struct DisplayStats {
    /// Frames produced.
    pub frames: u64,
    /// Frames per second of wall time.
    pub display_fps: f64,
    /// Mean time to produce one frame (deformation and encoding), ms.
    pub mean_frame_ms: f64,
    /// Largest time to produce one frame, ms.
    pub max_frame_ms: f64,
    /// Frames that used a nearby node's columns while a contact node's were being solved.
    pub approximate_frames: u64,
    /// Compliance column solves (in the deformer's worker thread).
    pub columns: SolveStats,
    /// Largest amplitude of the linear model's displacement orthogonal to the constraint
    /// (`|u^r|`, paper eq. 4) over every node and frame, m.
    pub max_radial_linear_m: f64,
    /// The same, as displayed: after the display law P ([`law`]); equal to
    /// `max_radial_linear_m` without P.
    pub max_radial_displayed_m: f64,
}

/// Receives each frame's sample and displacement (a recorder).
pub trait FrameSink {
    /// Called once per frame; must not block for long.
    fn frame(&mut self, info: &FrameInfo, contacts: &[(usize, [f32; 3])], u: &[[f32; 3]]);
}

/// How a frame's surface displacement is computed.
pub enum SurfaceModel {
    /// `u = C[:, S] f_S` on the collision mesh's surface, columns solved on demand.
    Nodal {
        /// The column cache and its solver.
        deformer: Box<Deformer>,
        /// Surface neighbours of each mesh node (for prefetching columns); empty lists
        /// allowed.
        neighbours: HashMap<usize, Vec<usize>>,
    },
    /// `u = U(p) F` on a sampled scene's fine FEM surface, from precomputed fields: no solve
    /// after a contact ([`fields::DisplayFields`]).
    Sampled(Arc<fields::DisplayFields>),
}

/// The frame loop (see the module notes).
pub struct Pipeline<'a> {
    /// The telemetry source.
    pub source: &'a mut dyn Source,
    /// Surface displacement.
    pub surface: SurfaceModel,
    /// The displayed surface.
    pub mesh: Arc<DisplayMesh>,
    /// Mesh node id of each bank node (the bank's `mesh_ids`).
    pub bank_to_mesh: Vec<usize>,
    /// Where frames go.
    pub hub: server::Hub,
    /// Target frame rate, Hz.
    pub fps: f64,
    /// The display law P applied to every frame (paper eq. 4, [`law`]); `None`: the linear
    /// displacement is shown as computed.
    pub display_law: Option<law::DisplayLaw>,
}

/// How long [`Pipeline::run`] waits for a source's first sample beyond its run time.
pub const FIRST_SAMPLE_GRACE: Duration = Duration::from_secs(60);

impl Pipeline<'_> {
    /// Produces frames until `stop` is set or `run_for` has passed since the source's first
    /// sample (a SIL image's first tick comes after QEMU's boot: the run is `run_for` of the
    /// loop, whatever the start-up took); a source that sends no sample at all stops
    /// [`FIRST_SAMPLE_GRACE`] after `run_for`. `sink` sees every frame.
    pub fn run(
        &mut self,
        stop: &AtomicBool,
        run_for: Option<Duration>,
        mut sink: Option<&mut dyn FrameSink>,
    ) -> anyhow::Result<(DisplayStats, LoopStats)> {
        let period = Duration::from_secs_f64(1.0 / self.fps.max(1.0));
        let start = Instant::now();
        let mut until = run_for.map(|d| start + d + FIRST_SAMPLE_GRACE);
        let mut next = start;
        let mut stats = DisplayStats::default();
        let mut busy = Duration::ZERO;
        let mut current: Option<Sample> = None;
        let (mut u, mut positions, mut bytes) = (Vec::new(), Vec::new(), Vec::new());
        let mut contacts: Vec<(usize, [f32; 3])> = Vec::new();
        loop {
            if stop.load(Ordering::Relaxed) || until.is_some_and(|t| Instant::now() >= t) {
                break;
            }
            let now = Instant::now();
            if now < next {
                std::thread::sleep(next - now);
            }
            next += period;
            if Instant::now() > next + 10 * period {
                next = Instant::now();
            }
            let began = Instant::now();
            if let Some(s) = self.source.latest(Duration::ZERO)? {
                if current.is_none() {
                    until = run_for.map(|d| Instant::now() + d);
                }
                current = Some(s);
            }
            let Some(sample) = &current else {
                continue;
            };
            contacts.clear();
            contacts.extend(
                sample.contacts.iter().filter_map(|c| {
                    Some((*self.bank_to_mesh.get(usize::from(c.node))?, c.force_n))
                }),
            );
            let coverage = match &mut self.surface {
                SurfaceModel::Nodal {
                    deformer,
                    neighbours,
                } => {
                    let coverage = deformer.displacement(&contacts, &mut u);
                    if coverage == Coverage::Approximate {
                        stats.approximate_frames += 1;
                    } else {
                        let ring: Vec<usize> = contacts
                            .iter()
                            .flat_map(|c| neighbours.get(&c.0).into_iter().flatten().copied())
                            .collect();
                        deformer.prefetch(&ring);
                    }
                    coverage
                }
                SurfaceModel::Sampled(fields) => {
                    // The linear tool force on the tissue: the contact forces' sum.
                    let force = sample.contacts.iter().fold([0.0f32; 3], |a, c| {
                        std::array::from_fn(|i| a[i] + c.force_n[i])
                    });
                    match sample.contact_point {
                        Some(p) => fields.displacement(p.triangle, p.bary, force, &mut u),
                        None => {
                            u.clear();
                            u.resize(self.mesh.rest.len(), [0.0; 3]);
                        }
                    }
                    Coverage::Exact
                }
            };
            if let Some(direction) =
                law::constraint_direction(sample.contacts.iter().map(|c| &c.force_n))
            {
                let extent = match &self.display_law {
                    Some(p) => p.apply(direction, &mut u),
                    None => law::radial_extent(direction, &u),
                };
                stats.max_radial_linear_m = stats.max_radial_linear_m.max(extent.linear_m.into());
                stats.max_radial_displayed_m =
                    stats.max_radial_displayed_m.max(extent.displayed_m.into());
            }
            positions.clear();
            positions.extend(
                self.mesh
                    .rest
                    .iter()
                    .zip(&u)
                    .map(|(r, d)| [r[0] + d[0], r[1] + d[1], r[2] + d[2]]),
            );
            let loop_stats = self.source.stats();
            let elapsed = began.duration_since(start).as_secs_f64();
            let info = FrameInfo {
                seq: stats.frames as u32,
                tick: sample.tick,
                state: sample.state,
                contacts: contacts.len().min(255) as u8,
                exact: coverage == Coverage::Exact,
                tip_m: sample.tip_m,
                tool_force_n: sample.tool_force_n,
                tick_rate_hz: loop_stats.tick_rate_hz as f32,
                display_fps: if elapsed > 0.0 {
                    (stats.frames as f64 / elapsed) as f32
                } else {
                    0.0
                },
                max_jitter_us: loop_stats.max_jitter_us.map_or(-1.0, |j| j as f32),
            };
            encode_frame(&info, &positions, &mut bytes);
            self.hub.publish(bytes.clone(), &info);
            if let Some(s) = sink.as_deref_mut() {
                s.frame(&info, &contacts, &u);
            }
            stats.frames += 1;
            let spent = began.elapsed();
            busy += spent;
            stats.max_frame_ms = stats.max_frame_ms.max(spent.as_secs_f64() * 1e3);
        }
        if let SurfaceModel::Nodal { deformer, .. } = &self.surface {
            stats.columns = deformer.solve_stats();
        }
        let elapsed = start.elapsed().as_secs_f64();
        if stats.frames > 0 {
            stats.display_fps = stats.frames as f64 / elapsed;
            stats.mean_frame_ms = busy.as_secs_f64() * 1e3 / stats.frames as f64;
        }
        Ok((stats, self.source.stats()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frame_layout_is_as_documented() {
        let info = FrameInfo {
            seq: 7,
            tick: 1234,
            state: State::Armed,
            contacts: 3,
            exact: true,
            tip_m: [0.1, 0.2, 0.3],
            tool_force_n: [0.0, 0.0, 1.5],
            tick_rate_hz: 1000.0,
            display_fps: 60.0,
            max_jitter_us: 80.0,
        };
        let mut b = Vec::new();
        encode_frame(&info, &[[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]], &mut b);
        assert_eq!(b.len(), FRAME_HEADER_BYTES + 24);
        let f = |o: usize| f32::from_le_bytes(b[o..o + 4].try_into().unwrap());
        let w = |o: usize| u32::from_le_bytes(b[o..o + 4].try_into().unwrap());
        assert_eq!(&b[0..4], b"HFR1");
        assert_eq!((w(4), w(8)), (7, 1234));
        assert_eq!(&b[12..16], &[1, 3, 1, 0]);
        assert_eq!([f(16), f(20), f(24)], [0.1, 0.2, 0.3]);
        assert_eq!([f(28), f(32), f(36)], [0.0, 0.0, 1.5]);
        assert_eq!([f(40), f(44), f(48)], [1000.0, 60.0, 80.0]);
        assert_eq!(w(52), 2);
        assert_eq!(f(FRAME_HEADER_BYTES + 20), 6.0);
        let mesh = DisplayMesh {
            rest: vec![[1.0, 2.0, 3.0]],
            triangles: vec![[0, 0, 0]],
        };
        let m = mesh.encode();
        assert_eq!(m.len(), 8 + 12 + 12);
        assert_eq!(&m[0..8], &[1, 0, 0, 0, 1, 0, 0, 0]);
    }

    /// Two triangles over nodes 2, 5, 7 and 9 of a ten-node mesh: the display keeps those four
    /// nodes, in the surface's order, and renumbers the triangles onto them.
    #[test]
    fn a_surface_is_renumbered_onto_its_nodes() {
        let nodes: Vec<[f64; 3]> = (0..10).map(|i| [i as f64, 0.0, 0.5 * i as f64]).collect();
        let surface = fem::mesh::Surface {
            triangles: vec![[2, 5, 7], [7, 5, 9]],
            nodes: vec![2, 5, 7, 9],
        };
        let m = DisplayMesh::of_surface(&nodes, &surface);
        assert_eq!(
            m.rest,
            vec![
                [2.0, 0.0, 1.0],
                [5.0, 0.0, 2.5],
                [7.0, 0.0, 3.5],
                [9.0, 0.0, 4.5]
            ]
        );
        assert_eq!(m.triangles, vec![[0, 1, 2], [2, 1, 3]]);
        assert_eq!(m.bounding_box(), ([2.0, 0.0, 1.0], [9.0, 0.0, 4.5]));
        let n = surface_neighbours(&surface.triangles);
        assert_eq!(n[&2], vec![5, 7]);
        assert_eq!(n[&5], vec![2, 7, 9]);
        assert_eq!(n[&9], vec![5, 7]);
        assert_eq!(n.len(), 4);
    }

    /// A source that always has the same sample (a held press).
    struct Held(Sample);

    impl Source for Held {
        fn latest(&mut self, _timeout: Duration) -> anyhow::Result<Option<Sample>> {
            Ok(Some(self.0.clone()))
        }
        fn stats(&self) -> LoopStats {
            LoopStats::default()
        }
    }

    /// Keeps the last frame computed from every contact node's own columns.
    #[derive(Default)]
    struct LastExact(Option<Vec<[f32; 3]>>);

    impl FrameSink for LastExact {
        fn frame(&mut self, info: &FrameInfo, _: &[(usize, [f32; 3])], u: &[[f32; 3]]) {
            if info.exact {
                self.0 = Some(u.to_vec());
            }
        }
    }

    /// The frame loop on a held oblique press of a soft block, with and without a display law
    /// `P(x) = 3 x`: the shown displacement is the direct solve's `K^-1 f` with its part
    /// orthogonal to `f` tripled and its part along `f` unchanged, node by node; without P it
    /// is the direct solve, and the radial extents are the same before and after.
    #[test]
    fn the_frame_loop_shows_the_display_law() {
        let (mesh, c, surface) = crate::deform::tests::resting_block([0.04, 0.04, 0.02], [4, 4, 2]);
        let k = (0..mesh.nodes.len())
            .find(|&i| {
                let p = mesh.nodes[i];
                (p[0] - 0.02).abs() < 1e-9
                    && (p[1] - 0.02).abs() < 1e-9
                    && (p[2] - 0.02).abs() < 1e-9
            })
            .unwrap();
        let force = [0.1f32, -0.05, -0.3];
        let mut contacts = firmware::tick::Contacts::new();
        contacts
            .push(bank_format::Contact {
                node: 0,
                force_n: force,
            })
            .unwrap();
        let sample = Sample {
            tick: 1,
            state: State::Armed,
            fault: None,
            tip_m: [0.02, 0.02, 0.018],
            contacts,
            contact_point: None,
            tool_force_n: force.map(|f| -f),
            mode: bank_format::Mode::Render,
            currents_a: [0.0; 3],
        };
        let mut f = vec![0.0; 3 * mesh.nodes.len()];
        (0..3).for_each(|i| f[3 * k + i] = f64::from(force[i]));
        let reference = c.displacement(&f);
        let display = DisplayMesh::of_surface(&mesh.nodes, &surface);
        let server =
            server::Server::start(0, display.encode(), serde_json::json!({}), None).unwrap();
        let gain = 3.0;
        let p = law::DisplayLaw::new(
            bank_format::TissueLaw::chebyshev(&[gain * 0.005, gain * 0.005], [0.0, 0.01]).unwrap(),
        )
        .unwrap();
        let fnorm = force
            .iter()
            .map(|x| f64::from(*x).powi(2))
            .sum::<f64>()
            .sqrt();
        let d = force.map(|x| f64::from(x) / fnorm);
        for display_law in [None, Some(p)] {
            let mut source = Held(sample.clone());
            let mut pipeline = Pipeline {
                source: &mut source,
                surface: SurfaceModel::Nodal {
                    deformer: Box::new(Deformer::new(
                        Arc::clone(&c),
                        &mesh.nodes,
                        surface.nodes.clone(),
                        8,
                    )),
                    neighbours: HashMap::new(),
                },
                mesh: Arc::new(display.clone()),
                bank_to_mesh: vec![k],
                hub: server.hub.clone(),
                fps: 200.0,
                display_law,
            };
            let mut sink = LastExact::default();
            let stop = AtomicBool::new(false);
            let (stats, _) = pipeline
                .run(&stop, Some(Duration::from_millis(300)), Some(&mut sink))
                .unwrap();
            let shown = sink.0.expect("an exact frame within 0.3 s");
            let k_radial = if display_law.is_some() {
                f64::from(gain)
            } else {
                1.0
            };
            let mut largest = 0.0f64;
            for (i, &n) in surface.nodes.iter().enumerate() {
                let lin: [f64; 3] = std::array::from_fn(|r| reference[3 * n + r]);
                let s = lin[0] * d[0] + lin[1] * d[1] + lin[2] * d[2];
                let want: [f64; 3] =
                    std::array::from_fn(|r| s * d[r] + k_radial * (lin[r] - s * d[r]));
                largest =
                    largest.max(((0..3).map(|r| (lin[r] - s * d[r]).powi(2)).sum::<f64>()).sqrt());
                for r in 0..3 {
                    let err = (f64::from(shown[i][r]) - want[r]).abs();
                    assert!(
                        err <= 2e-5 * 1e-3 + 1e-5 * want[r].abs(),
                        "node {n}: {:?} vs {want:?}",
                        shown[i]
                    );
                }
            }
            assert!(largest > 1e-4, "the press must bulge the block: {largest}");
            let rel = |a: f64, b: f64| (a / b - 1.0).abs();
            assert!(
                rel(stats.max_radial_linear_m, largest) < 1e-4,
                "{stats:?} vs {largest}"
            );
            assert!(
                rel(stats.max_radial_displayed_m, k_radial * largest) < 1e-4,
                "{stats:?} vs {largest}"
            );
        }
    }
}
