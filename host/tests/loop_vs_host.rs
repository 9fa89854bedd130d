//! The firmware's f32 contact solve on a real bank (the shipped liver scene) against the host's
//! f64 solve on the untruncated compliance of the same contact set: point contacts and the
//! paper's alpha-weighted triangle contacts. The bank is the scene's with f32 blocks, so the
//! comparison holds the f32 arithmetic alone; what the shipped 16-bit storage adds is
//! `exact_contacts.rs`'s, against its rounding bound.

use bank_format::{AlignedBytes, Bank};
use fem::compliance::{Compliance, contact_forces};
use fem::elasticity::{Elasticity, FixedSet};
use fem::mesh::TetMesh;
use haptic::scene::Scene;
use std::path::Path;
use std::process::Command;

/// The shipped liver scene with `precision = "f32"`: its bank built by `host bank build`, and
/// the host's f64 reference (the full, untruncated compliance of the same scene).
struct Liver {
    bank_bytes: AlignedBytes,
    mesh: TetMesh,
    fixed: FixedSet,
    compliance: Compliance,
}

impl Liver {
    fn build() -> Liver {
        let shipped = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/liver-nodal.toml");
        let text = std::fs::read_to_string(&shipped).unwrap();
        let edited = text.replacen("precision = \"bfp16\"", "precision = \"f32\"", 1);
        assert_ne!(edited, text, "the scene's precision line changed");
        let dir = tempfile::tempdir().unwrap();
        let scene_path = dir.path().join("liver-f32.toml");
        std::fs::write(&scene_path, edited).unwrap();
        let bank_path = dir.path().join("liver.bank");
        let built = Command::new(env!("CARGO_BIN_EXE_host"))
            .args(["bank", "build"])
            .arg(&scene_path)
            .arg("-o")
            .arg(&bank_path)
            .output()
            .unwrap();
        assert!(
            built.status.success(),
            "{}",
            String::from_utf8_lossy(&built.stderr)
        );
        let bank_bytes = AlignedBytes::new(&std::fs::read(&bank_path).unwrap());
        let scene = Scene::load(&scene_path).unwrap();
        let (mesh, _, _) = scene.load_mesh().unwrap();
        let fixed = scene.fixed_set(&mesh).unwrap();
        let body = Elasticity::new(&mesh, scene.material).unwrap();
        let compliance = Compliance::factorize(&body, &fixed).unwrap();
        Liver {
            bank_bytes,
            mesh,
            fixed,
            compliance,
        }
    }

    fn bank(&self) -> Bank<'_> {
        Bank::parse(&self.bank_bytes).unwrap()
    }
}

#[test]
fn firmware_forces_match_the_host_f64_reference_on_the_liver_bank() {
    let liver = Liver::build();
    let bank = liver.bank();
    let compliance = &liver.compliance;
    let ids: Vec<usize> = bank.mesh_ids().iter().map(|&i| i as usize).collect();

    let d = [0.0f32, 0.0, -0.005];
    let bary = [0.2f32, 0.3, 0.5];
    let alpha = firmware::solve::alpha_weights(bary);
    let mut worst: f64 = 0.0;
    let triangles = bank.triangles();
    for tri in triangles.iter().step_by((triangles.len() / 25).max(1)) {
        let nodes: Vec<usize> = tri.iter().map(|&k| ids[k as usize]).collect();
        let c_ss = compliance.blocks(&nodes, None).unwrap();
        // Triangle, alpha weights.
        let imposed: Vec<[f64; 3]> = alpha
            .iter()
            .map(|&a| d.map(|x| f64::from(a) * f64::from(x)))
            .collect();
        let reference = contact_forces(&c_ss, &imposed).unwrap();
        let got = firmware::solve::solve_triangle_alpha(&bank, *tri, bary, d).unwrap();
        worst = worst.max(relative(got.forces(), &reference.forces));
        // Point contact at the first vertex.
        let single = contact_forces(&[vec![c_ss[0][0]]], &[d.map(f64::from)]).unwrap();
        let got = firmware::solve::solve_point(&bank, tri[0], d).unwrap();
        worst = worst.max(relative(got.forces(), &single.forces));
    }
    eprintln!(
        "firmware f32 vs host f64, untruncated compliance: worst relative force error {worst:.2e}"
    );
    // Measured 3.4e-7; 5e-6 fails on a tenfold loss of precision.
    assert!(worst <= 5e-6, "{worst:e}");
}

fn relative(got: &[[f32; 3]], want: &[[f64; 3]]) -> f64 {
    let mut num = 0.0;
    let mut den = 0.0;
    for (g, w) in got.iter().zip(want) {
        for c in 0..3 {
            num += (f64::from(g[c]) - w[c]).powi(2);
            den += w[c] * w[c];
        }
    }
    assert_eq!(got.len(), want.len());
    (num / den).sqrt()
}

/// The whole tick (encoder counts -> kinematics -> contact -> tool patch -> solve) on the
/// shipped liver bank, pressing along the shaft and then sliding, against the host's f64 patch and solve on the
/// untruncated compliance for the contact state the tick reports, on the bank's surface (R's
/// triangles). Asserts the f32 tick against f64 on the contact set the firmware kept and on
/// the whole patch (the bank's truncation drops no node of it), and prints both for each
/// contact set the press went through.
#[test]
fn full_tick_forces_match_the_host_f64_reference_on_the_liver_bank() {
    use firmware::contact::ContactState;
    use firmware::tick::{HapticLoop, LoopInput};
    use haptic::contact::{ContactSurface, SurfaceHit, patch_force};

    let liver = Liver::build();
    let bank = liver.bank();
    let (mesh, fixed, compliance) = (&liver.mesh, &liver.fixed, &liver.compliance);
    let ids: Vec<usize> = bank.mesh_ids().iter().map(|&i| i as usize).collect();
    // The bank's surface (R's triangles) in mesh ids: the patch lives on it.
    let region = fem::mesh::Surface {
        triangles: bank
            .triangles()
            .iter()
            .map(|t| t.map(|k| ids[usize::from(k)]))
            .collect(),
        nodes: ids.clone(),
    };
    let surface = ContactSurface::new(mesh, &region);
    let cal = *bank.device();

    let mut lp = HapticLoop::new(&bank);
    lp.set_mode(bank_format::Mode::LinearLaw)
        .expect("the mode is set before arming");
    // Straight down the trocar (pitch = yaw = 0), 0.02 mm per tick, slightly off-centre.
    let per_unit: Vec<f64> = (0..3)
        .map(|i| {
            f64::from(cal.counts_per_rev[i]) * f64::from(cal.transmission[i])
                / std::f64::consts::TAU
        })
        .collect();
    // (contact set, node force error, tool force error, truncation error, dropped mesh nodes)
    let mut sets: Vec<(Vec<u16>, f64, f64, f64, usize)> = Vec::new();
    let mut touching = 0;
    let (mut last_origin, mut swapped_at) = (None, 0);
    for t in 0..5000 {
        // Press along the shaft for 2,500 ticks, then sweep the yaw: a slide across triangles.
        let (press, slide) = (f64::from(t.min(2500)), f64::from(t.max(2500) - 2500));
        let q = [0.05, -0.04 + 0.1 * slide / 2500.0, 0.06 + 2.0e-5 * press];
        let counts: [i32; 3] = std::array::from_fn(|i| {
            ((q[i] - f64::from(cal.home_joint[i])) * per_unit[i]).round() as i32
        });
        let out = lp.tick(LoopInput {
            encoder_counts: counts,
            overrun: false,
            link_silence_ticks: 0,
            interlocks: firmware::hal::Interlocks::default(),
        });
        assert!(out.solve_error.is_none(), "{out:?}");
        let ContactState::Touching { displacement, .. } = out.contact else {
            continue;
        };
        let d: Vec<f64> = displacement.iter().map(|&x| f64::from(x)).collect();
        let depth = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        if depth < 1e-4 {
            continue; // grazing: relative errors of tiny forces say nothing
        }
        if depth > 0.02 {
            break;
        }
        // The patch in use was built where the contact was when it last re-patched; for
        // BLEND_TICKS after a swap the force still blends in the outgoing patch's
        // (`firmware::tick::BLEND_TICKS`), so those ticks have no single-patch reference.
        let origin = out.patch.unwrap();
        if last_origin != Some(origin) {
            last_origin = Some(origin);
            swapped_at = t;
        }
        if t - swapped_at < firmware::tick::BLEND_TICKS as _ {
            continue;
        }
        touching += 1;
        let hit = SurfaceHit {
            triangle: 0,
            nodes: origin.nodes.map(|k| ids[usize::from(k)]),
            bary: origin.bary.map(f64::from),
            point: origin.anchor.map(f64::from),
        };
        let free = |k: usize| (0..3).all(|c| !fixed.is_fixed(k, c));
        let patch = surface.tool_patch(&hit, f64::from(origin.radius_m), free);
        let got: Vec<(usize, [f32; 3])> = lp
            .contacts()
            .iter()
            .map(|c| (ids[usize::from(c.node)], c.force_n))
            .collect();
        // The firmware keeps only nodes the bank couples to every heavier one (and at most
        // eight): the reference for the solve is the host's patch restricted to those nodes,
        // renormalised; the full patch's force measures what the truncation costs.
        assert!(
            got.iter().all(|g| patch.iter().any(|p| p.0 == g.0)),
            "tick {t}"
        );
        let kept: f64 = patch
            .iter()
            .filter(|p| got.iter().any(|g| g.0 == p.0))
            .map(|p| p.1)
            .sum();
        let reduced: Vec<(usize, f64)> = got
            .iter()
            .map(|g| (g.0, patch.iter().find(|p| p.0 == g.0).unwrap().1 / kept))
            .collect();
        let d3 = [d[0], d[1], d[2]];
        let f_tool = patch_force(compliance, &reduced, d3).unwrap();
        let f_full = patch_force(compliance, &patch, d3).unwrap();
        let want: Vec<[f64; 3]> = reduced.iter().map(|(_, w)| f_tool.map(|f| w * f)).collect();
        let got_f: Vec<[f32; 3]> = got.iter().map(|g| g.1).collect();
        let err = relative(&got_f, &want);
        let norm = |v: [f64; 3]| (v.iter().map(|x| x * x).sum::<f64>()).sqrt();
        // The tool force the tick renders is minus the sum on the tissue (linear law, no cap).
        let tool_err = norm(std::array::from_fn(|c| {
            f64::from(out.tool_force_n[c]) + f_tool[c]
        })) / norm(f_tool);
        let trunc = norm(std::array::from_fn(|c| {
            f64::from(out.tool_force_n[c]) + f_full[c]
        })) / norm(f_full);
        let key: Vec<u16> = lp.contacts().iter().map(|c| c.node).collect();
        let dropped = patch.len() - got.len();
        match sets.iter_mut().find(|s| s.0 == key) {
            Some(s) => {
                s.1 = s.1.max(err);
                s.2 = s.2.max(tool_err);
                s.3 = s.3.max(trunc);
                s.4 = s.4.max(dropped);
            }
            None => sets.push((key, err, tool_err, trunc, dropped)),
        }
    }
    assert!(
        touching > 100,
        "the press touched for {touching} ticks only"
    );
    for (nodes, err, tool, trunc, dropped) in &sets {
        eprintln!(
            "contact set {nodes:?}: f32 vs f64 node forces {err:.2e}, tool force {tool:.2e}; \
             vs the untruncated patch (up to {dropped} node(s) not coupled in the bank): {trunc:.2e}"
        );
        // Measured 4.2e-7 at most.
        assert!(*err <= 5e-6 && *tool <= 5e-6, "{nodes:?}: {err:e} {tool:e}");
        // The bank couples every pair one tool patch can load (the "tool" rule): no patch node
        // is dropped, so the tick's force is the untruncated patch's too.
        assert_eq!(*dropped, 0, "{nodes:?}");
        assert!(
            *trunc <= 5e-6,
            "{nodes:?}: vs the untruncated patch {trunc:e}"
        );
    }
}
