//! What the mesh size does beyond the precompute: for each mesh of the scene's organ, the
//! scene's bank rebuilt on it ([`Prepared`], as `host bank build` does), and
//!
//! - the **contact models** on the same press (5 mm along the shaft, aimed from the trocar at
//!   the reachable region's centre): point contact (the nearest vertex), the paper's alpha
//!   weights on the contact triangle (`f_S = C_SS^-1 u*_S`, eq. 7, with `u*_v = alpha_v d`),
//!   the energy-minimal triangle (`f = (B C_SS B^T)^-1 d`), and the tool patch at the scene's
//!   tip radius and twice it (capped as the firmware caps it); the force along the press, f64
//!   on the full compliance;
//! - the **bank's size** at the scene's truncation;
//! - the **display**: the wall time of one frame with the contact nodes' columns cached
//!   (superposition `u = C[:, S] f_S` on every surface node, eq. 3, plus encoding, as
//!   [`crate::display::Pipeline`] does it), and the latency of a new contact node's columns
//!   (three column solves with the factorisation, [`Deformer::displacement_exact`]).

use super::{HardCase, Knob, Point, Series, Verdict};
use crate::bank::{BankSpec, Prepared};
use crate::contact::{ContactSurface, capped_patch, patch_force};
use crate::deform::Deformer;
use crate::display::{FrameInfo, encode_frame};
use crate::kinematics::Workspace;
use crate::scene::{MeshSource, Scene};
use anyhow::{Context, Result};
use fem::compliance::contact_forces;
use fem::mesh::TetMesh;
use fem::vec3::{dot, norm, scale, sub};
use firmware::solve::{MAX_CONTACT_NODES, alpha_weights};
use std::sync::Arc;
use std::time::Instant;

/// The press depth, m.
const DEPTH: f64 = 0.005;
/// Frames timed per mesh.
const FRAMES: usize = 40;
/// New contact nodes whose column latency is timed per mesh.
const NEW_NODES: usize = 4;

/// One contact model's force on one mesh.
#[derive(Debug, Clone)]
pub struct ModelForce {
    /// The model.
    pub model: String,
    /// Contact nodes it loads (after the firmware's cap).
    pub nodes: usize,
    /// Force along the press, N.
    pub force_n: f64,
}

/// Everything measured on one mesh.
#[derive(Debug, Clone)]
pub struct MeshRun {
    /// The mesh's name.
    pub name: String,
    /// Mesh nodes.
    pub nodes: usize,
    /// Reachable nodes (the bank's R).
    pub region: usize,
    /// Bank bytes.
    pub bank_bytes: usize,
    /// Wall time of the bank's blocks and writing (after the factorisation), s.
    pub bank_s: f64,
    /// Contact models.
    pub forces: Vec<ModelForce>,
    /// Mean and largest wall time of one display frame, ms.
    pub frame_ms: (f64, f64),
    /// Mean and largest latency of a new contact node's display columns, ms.
    pub column_ms: (f64, f64),
    /// Display (surface) nodes.
    pub display_nodes: usize,
}

/// The press of every mesh: from the trocar towards the centre of the scene's reachable
/// region.
pub fn press_ray(p: &Prepared) -> ([f64; 3], [f64; 3]) {
    let ws = Workspace::from_device(&p.organ.scene.device);
    let n = p.region.positions.len().max(1) as f64;
    let centre: [f64; 3] =
        std::array::from_fn(|c| p.region.positions.iter().map(|q| q[c]).sum::<f64>() / n);
    let d = sub(centre, ws.fulcrum);
    (ws.fulcrum, scale(d, 1.0 / norm(d)))
}

/// Measures `mesh` with the scene's material, supports, device and bank options.
pub fn measure(
    scene: &Scene,
    name: &str,
    mesh: &TetMesh,
    ray: ([f64; 3], [f64; 3]),
) -> Result<MeshRun> {
    let dir = tempfile::tempdir().context("a temporary directory for the mesh")?;
    let path = dir
        .path()
        .join(format!("{}.msh", name.replace([' ', ':'], "-")));
    let mut file = std::io::BufWriter::new(
        std::fs::File::create(&path).with_context(|| format!("creating {}", path.display()))?,
    );
    mesh.write_msh4_ascii(&mut file)
        .with_context(|| format!("writing {}", path.display()))?;
    drop(file);
    let mut s = scene.clone();
    s.mesh = MeshSource::File(path);
    s.mesh_units = Some(crate::units::Units::M);
    let q = Prepared::from_scene(s).with_context(|| format!("the scene on {name}"))?;
    let t = Instant::now();
    let bank = q.bank(&BankSpec::Scene { progress: None })?;
    let bank_s = t.elapsed().as_secs_f64();

    let surface = ContactSurface::new(&q.organ.mesh, &q.organ.surface);
    let hit = surface
        .ray_entry(ray.0, ray.1)
        .with_context(|| format!("{name}: the press misses the organ"))?;
    let fixed = &q.organ.fixed;
    let free = |k: usize| (0..3).all(|c| !fixed.is_fixed(k, c));
    let press = scale(ray.1, DEPTH);
    let along = |f: [f64; 3]| dot(f, ray.1);
    let mut forces = Vec::new();
    let vertex = (0..3)
        .max_by(|&a, &b| hit.bary[a].total_cmp(&hit.bary[b]))
        .map_or(hit.nodes[0], |a| hit.nodes[a]);
    let c = q.compliance.blocks(&[vertex], None)?;
    forces.push(ModelForce {
        model: "point (nearest vertex)".into(),
        nodes: 1,
        force_n: along(contact_forces(&c, &[press])?.forces[0]),
    });
    let c = q.compliance.blocks(&hit.nodes, None)?;
    let alpha = alpha_weights(hit.bary.map(|b| b as f32));
    let imposed: Vec<[f64; 3]> = alpha
        .iter()
        .map(|&a| press.map(|x| f64::from(a) * x))
        .collect();
    let f = contact_forces(&c, &imposed)?.forces;
    forces.push(ModelForce {
        model: "triangle, alpha weights (paper)".into(),
        nodes: 3,
        force_n: f.iter().map(|&v| along(v)).sum(),
    });
    forces.push(ModelForce {
        model: "triangle, energy-minimal".into(),
        nodes: 3,
        force_n: along(patch_force(
            &q.compliance,
            &surface.tool_patch(&hit, 0.0, free),
            press,
        )?),
    });
    let tip = q.organ.scene.tip_radius_m;
    for r in [tip, 2.0 * tip].into_iter().filter(|r| *r > 0.0) {
        let patch = surface.tool_patch(&hit, r, free);
        let (kept, _) = capped_patch(&patch, MAX_CONTACT_NODES);
        forces.push(ModelForce {
            model: format!("tool patch r = {:.1} mm", r * 1e3),
            nodes: kept.len(),
            force_n: along(patch_force(&q.compliance, &kept, press)?),
        });
    }

    // The display: every surface node, as `host demo` shows it.
    let display = q.organ.surface.nodes.clone();
    let rest: Vec<[f32; 3]> = display
        .iter()
        .map(|&k| q.organ.mesh.nodes[k].map(|x| x as f32))
        .collect();
    let near = surface.tool_patch(&hit, 3.0 * tip.max(0.002), free);
    let (nodes, region) = (q.organ.mesh.nodes.len(), q.region.len());
    let positions = q.organ.mesh.nodes.clone();
    let mut deformer = Deformer::new(Arc::new(q.compliance), &positions, display.clone(), 64);
    let mut u = Vec::new();
    let f = [0.0f32, 0.0, -0.5];
    let mut latency = Vec::new();
    for &(k, _) in near.iter().take(NEW_NODES) {
        let t = Instant::now();
        deformer.displacement_exact(&[(k, f)], &mut u);
        latency.push(t.elapsed().as_secs_f64() * 1e3);
    }
    let contacts: Vec<(usize, [f32; 3])> =
        near.iter().take(NEW_NODES).map(|&(k, _)| (k, f)).collect();
    let mut frame = Vec::new();
    let (mut positions, mut bytes) = (Vec::new(), Vec::new());
    for seq in 0..FRAMES {
        let t = Instant::now();
        deformer.displacement(&contacts, &mut u);
        positions.clear();
        positions.extend(
            rest.iter()
                .zip(&u)
                .map(|(r, d)| [r[0] + d[0], r[1] + d[1], r[2] + d[2]]),
        );
        let info = FrameInfo {
            seq: seq as u32,
            tick: seq as u32,
            state: bank_format::State::Armed,
            contacts: contacts.len() as u8,
            exact: true,
            tip_m: [0.0; 3],
            tool_force_n: [0.0; 3],
            tick_rate_hz: 1000.0,
            display_fps: 60.0,
            max_jitter_us: -1.0,
        };
        encode_frame(&info, &positions, &mut bytes);
        frame.push(t.elapsed().as_secs_f64() * 1e3);
    }
    let stats = |v: &[f64]| {
        (
            v.iter().sum::<f64>() / v.len().max(1) as f64,
            v.iter().copied().fold(0.0, f64::max),
        )
    };
    Ok(MeshRun {
        name: name.to_string(),
        nodes,
        region,
        bank_bytes: bank.bytes.len(),
        bank_s,
        forces,
        frame_ms: stats(&frame),
        column_ms: stats(&latency),
        display_nodes: display.len(),
    })
}

/// Relative change of each model's force from the coarsest to the finest mesh.
pub fn spread(runs: &[MeshRun]) -> Vec<(String, usize, f64)> {
    let (Some(first), Some(last)) = (runs.first(), runs.last()) else {
        return Vec::new();
    };
    first
        .forces
        .iter()
        .zip(&last.forces)
        .map(|(a, b)| {
            (
                a.model.clone(),
                b.nodes,
                ((b.force_n - a.force_n) / b.force_n).abs(),
            )
        })
        .collect()
}

/// The knobs: contact models under refinement; bank size; display.
pub fn section(runs: &[MeshRun], instructions: &dyn Fn(usize) -> Option<f64>) -> Vec<Knob> {
    let models: Vec<String> = runs
        .first()
        .map(|r| r.forces.iter().map(|f| f.model.clone()).collect())
        .unwrap_or_default();
    let contact = Knob {
        id: "contact-refinement".into(),
        title: "Contact model under mesh refinement".into(),
        x_label: "mesh nodes".into(),
        y_label: "force along a 5 mm press, N".into(),
        log_x: true,
        log_y: false,
        series: models
            .iter()
            .enumerate()
            .map(|(i, m)| Series {
                name: m.clone(),
                points: runs
                    .iter()
                    .filter_map(|r| {
                        let f = r.forces.get(i)?;
                        Some(Point {
                            x: r.nodes as f64,
                            y: f.force_n,
                            label: format!("{}: {} nodes", r.name, f.nodes),
                        })
                    })
                    .collect(),
            })
            .collect(),
        chosen: None,
        finding: spread(runs)
            .iter()
            .map(|(m, n, s)| {
                let cost =
                    instructions(*n).map_or("not measured (no QEMU)".into(), |i| format!("{i:.0}"));
                format!(
                    "{m}: {:.0} % change coarsest to finest, {n} nodes, worst MCU tick {cost} \
                     instructions",
                    100.0 * s
                )
            })
            .collect::<Vec<_>>()
            .join("; "),
    };
    let fits = |b: usize| b <= bank_format::region::BANK_LEN;
    let bank = Knob {
        id: "mesh-bank".into(),
        title: "Mesh size against bank size (the scene's truncation)".into(),
        x_label: "mesh nodes".into(),
        y_label: "bank bytes".into(),
        log_x: true,
        log_y: true,
        series: vec![Series {
            name: "bank".into(),
            points: runs
                .iter()
                .map(|r| Point {
                    x: r.nodes as f64,
                    y: r.bank_bytes as f64,
                    label: format!(
                        "{}: R = {} nodes, built in {:.1} s{}",
                        r.name,
                        r.region,
                        r.bank_s,
                        if fits(r.bank_bytes) {
                            ""
                        } else {
                            ", too large for the MCU"
                        }
                    ),
                })
                .collect(),
        }],
        chosen: runs.first().map(|r| Point {
            x: r.nodes as f64,
            y: r.bank_bytes as f64,
            label: "the scene's mesh".into(),
        }),
        finding: format!(
            "the MCU's bank region holds {} bytes; {}",
            bank_format::region::BANK_LEN,
            runs.iter()
                .map(|r| format!(
                    "{}: {} bytes ({})",
                    r.name,
                    r.bank_bytes,
                    if fits(r.bank_bytes) {
                        "fits"
                    } else {
                        "does NOT fit"
                    }
                ))
                .collect::<Vec<_>>()
                .join(", ")
        ),
    };
    let ms = |f: fn(&MeshRun) -> f64, name: &str| Series {
        name: name.into(),
        points: runs
            .iter()
            .map(|r| Point {
                x: r.nodes as f64,
                y: f(r).max(1e-6),
                label: format!("{}: {} display nodes", r.name, r.display_nodes),
            })
            .collect(),
    };
    let display = Knob {
        id: "mesh-display".into(),
        title: "Mesh size against display frame time and column latency".into(),
        x_label: "mesh nodes".into(),
        y_label: "wall time, ms (this machine)".into(),
        log_x: true,
        log_y: true,
        series: vec![
            ms(|r| r.frame_ms.0, "frame, mean"),
            ms(|r| r.frame_ms.1, "frame, worst"),
            ms(|r| r.column_ms.0, "new contact node's columns, mean"),
            ms(|r| r.column_ms.1, "new contact node's columns, worst"),
        ],
        chosen: None,
        finding: runs
            .last()
            .map(|r| {
                format!(
                    "on {} ({} nodes): a frame takes {:.2} ms (mean), a new contact node's \
                     columns {:.1} ms (mean; the display shows a nearby node's columns \
                     meanwhile); at 60 fps a frame has 16.7 ms",
                    r.name, r.nodes, r.frame_ms.0, r.column_ms.0
                )
            })
            .unwrap_or_default(),
    };
    vec![contact, bank, display]
}

/// The refinement rows: each contact model's force change over the meshes measured.
pub fn refinement_cases(runs: &[MeshRun]) -> Vec<HardCase> {
    let names: Vec<String> = runs
        .iter()
        .map(|r| format!("{} ({})", r.name, r.nodes))
        .collect();
    spread(runs)
        .into_iter()
        .map(|(model, _, s)| HardCase {
            case: format!("refinement x{}: {model}", runs.len()),
            measurement: format!(
                "force change coarsest to finest {:.1} % over {}",
                100.0 * s,
                names.join(", ")
            ),
            reference: "a converging model changes by less than 10 % (a point force's \
                        displacement is unbounded: its force falls with the element size)"
                .into(),
            verdict: if s <= 0.1 {
                Verdict::Bounded
            } else {
                Verdict::Weakness
            },
            value: Some(s),
            reference_value: Some(0.1),
        })
        .collect()
}
