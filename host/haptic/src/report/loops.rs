//! Hard cases of the force loop, run through the firmware's own code natively
//! (`firmware::tick::HapticLoop` on the scene's bank, encoder counts in, currents out, as the
//! MCU runs it; `host/tests/loop_vs_host.rs` drives it the same way), and of its contact solve
//! (`firmware::solve`): grazing motion, edge and vertex hits, a 5 cm strike in one tick, two
//! contact nodes 1 um apart, a contact at the reachable region's edge.

use super::precision::{F32_BOUND, relative};
use super::{HardCase, Verdict};
use crate::bank::Prepared;
use crate::contact::{ContactSurface, SurfaceHit, patch_force, weighted_tool_force};
use crate::kinematics::{Workspace, counts_for};
use crate::sil::script::surface_insertion;
use anyhow::{Result, anyhow};
use bank_format::{Bank, Mode};
use fem::compliance::{Block3, contact_forces};
use firmware::contact::ContactState;
use firmware::hal::Interlocks;
use firmware::safety::State;
use firmware::solve::{Factor, MAX_DOFS, alpha_weights, solve_triangle_alpha, solve_weighted};
use firmware::tick::{HapticLoop, LoopInput, LoopOutput};

/// A loop on `bank` in the linear law, homed at encoder zero, armed at joint values `q0`
/// after a few ticks there, its ramp-in over.
fn armed_loop<'b>(bank: &'b Bank<'b>, q0: [f64; 3]) -> Result<HapticLoop<'b>> {
    let mut lp = HapticLoop::new(bank);
    lp.zero_encoders();
    lp.set_mode(Mode::LinearLaw)
        .map_err(|e| anyhow!("setting the linear law: {e:?}"))?;
    for _ in 0..5 {
        tick(&mut lp, q0);
    }
    lp.arm().map_err(|e| anyhow!("arming the loop: {e:?}"))?;
    for _ in 0..firmware::tick::RAMP_IN_TICKS {
        tick(&mut lp, q0);
    }
    Ok(lp)
}

fn tick(lp: &mut HapticLoop<'_>, q: [f64; 3]) -> LoopOutput {
    let counts = counts_for(lp.bank().device(), q);
    lp.tick(LoopInput {
        encoder_counts: counts,
        overrun: false,
        link_silence_ticks: 0,
        interlocks: Interlocks::default(),
    })
}

fn norm(v: [f32; 3]) -> f64 {
    v.iter().map(|&x| f64::from(x).powi(2)).sum::<f64>().sqrt()
}

/// The centre of the device's pitch and yaw ranges.
fn centre_angles(bank: &Bank) -> [f64; 2] {
    let c = bank.device();
    [0, 1].map(|i| 0.5 * (f64::from(c.joint_min[i]) + f64::from(c.joint_max[i])))
}

/// Every row of this module.
pub fn cases(p: &Prepared, bank: &Bank) -> Result<Vec<HardCase>> {
    Ok(vec![
        grazing(bank)?,
        edge_and_vertex(p, bank)?,
        strike(bank)?,
        close_nodes(p, bank)?,
        region_edge(p, bank)?,
    ])
}

/// The tip slides across the surface at +-50 um about first contact, so the contact appears
/// and vanishes over and over: forces stay finite and small, no solve fails.
fn grazing(bank: &Bank) -> Result<HardCase> {
    let [pitch, yaw0] = centre_angles(bank);
    let ticks = 2000;
    let span = 0.08;
    let at = |t: usize| yaw0 - 0.5 * span + span * t as f64 / ticks as f64;
    let s0 = surface_insertion(bank, [pitch, at(0)])?;
    let mut lp = armed_loop(bank, [pitch, at(0), s0])?;
    let (mut touching, mut switches, mut errors, mut worst) = (0, 0, 0, 0.0f64);
    let mut was = false;
    let mut last_state = State::Armed;
    for t in 0..ticks {
        let yaw = at(t);
        let s = surface_insertion(bank, [pitch, yaw])?;
        let q = [pitch, yaw, s + 5e-5 * (t as f64 * 0.05).sin()];
        let out = tick(&mut lp, q);
        let now = matches!(out.contact, ContactState::Touching { .. });
        touching += usize::from(now);
        switches += usize::from(now != was);
        was = now;
        errors += usize::from(out.solve_error.is_some());
        worst = worst.max(norm(out.tool_force_n));
        last_state = out.state;
    }
    let max_force = f64::from(bank.device().max_force_n);
    let ok = worst.is_finite() && errors == 0 && last_state == State::Armed && worst < max_force;
    Ok(HardCase {
        case: "grazing motion".into(),
        measurement: format!(
            "{ticks} ticks sliding {span} rad of yaw at +-50 um about the surface: {touching} \
             ticks touching, {switches} contact switches, {errors} solve errors, state \
             {last_state:?}, largest rendered force {worst:.3} N"
        ),
        reference: format!("finite, no solve error, below the device's {max_force} N cap"),
        verdict: if ok {
            Verdict::Bounded
        } else {
            Verdict::Weakness
        },
        value: Some(worst),
        reference_value: Some(max_force),
    })
}

/// Contacts exactly on a triangle's edge midpoint and vertex: the firmware's alpha and
/// energy-minimal solves against f64.
fn edge_and_vertex(p: &Prepared, bank: &Bank) -> Result<HardCase> {
    let ids: Vec<usize> = bank.mesh_ids().iter().map(|&i| i as usize).collect();
    let d: [f32; 3] = [0.0005, 0.0, -0.004];
    let d64 = d.map(f64::from);
    let tris = bank.triangles();
    let mut worst = 0.0f64;
    let mut count = 0;
    for &tri in tris.iter().step_by((tris.len() / 20).max(1)) {
        let nodes: Vec<usize> = tri.iter().map(|&k| ids[usize::from(k)]).collect();
        let c = p.compliance.blocks(&nodes, None)?;
        for bary in [[0.5f32, 0.5, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]] {
            let fw = |e| anyhow!("firmware solve on {tri:?} at {bary:?}: {e:?}");
            let alpha = alpha_weights(bary);
            let imposed: Vec<[f64; 3]> = alpha
                .iter()
                .map(|&w| d64.map(|x| f64::from(w) * x))
                .collect();
            let want = contact_forces(&c, &imposed)?.forces;
            let got = solve_triangle_alpha(bank, tri, bary, d).map_err(fw)?;
            worst = worst.max(relative(got.forces(), &want));
            let w: Vec<f64> = bary.iter().map(|&b| f64::from(b)).collect();
            let ft = weighted_tool_force(&c, &w, d64)?;
            let want: Vec<[f64; 3]> = w.iter().map(|&b| ft.map(|f| b * f)).collect();
            let got = solve_weighted(bank, &tri, &bary, d).map_err(fw)?;
            worst = worst.max(relative(got.forces(), &want));
            count += 1;
        }
    }
    Ok(HardCase {
        case: "edge and vertex hits".into(),
        measurement: format!(
            "{count} contacts at edge midpoints and vertices (barycentric zeros): worst f32 \
             relative force error {worst:.1e} (alpha and energy-minimal forms)"
        ),
        reference: format!("f64 solve of the same contact; bound {F32_BOUND:.0e}"),
        verdict: if worst <= F32_BOUND {
            Verdict::MatchesReference
        } else {
            Verdict::Weakness
        },
        value: Some(worst),
        reference_value: Some(F32_BOUND),
    })
}

/// The encoders jump 5 cm of insertion between two ticks, from 1 cm above the surface to 4 cm
/// inside it: the supervisor must fault with zero current, not render the deep press.
fn strike(bank: &Bank) -> Result<HardCase> {
    let [pitch, yaw] = centre_angles(bank);
    let s0 = surface_insertion(bank, [pitch, yaw])?;
    let mut lp = armed_loop(bank, [pitch, yaw, s0 - 0.01])?;
    for _ in 0..20 {
        tick(&mut lp, [pitch, yaw, s0 - 0.01]);
    }
    let out = tick(&mut lp, [pitch, yaw, s0 + 0.04]);
    let zero = out.currents_a.iter().all(|&a| a == 0.0);
    let (measurement, verdict) = match (out.state, out.new_fault) {
        (State::Fault(_), Some(f)) if zero => (
            format!(
                "refused: fault {:?} (detail {}) in the tick of the jump, currents 0",
                f.reason, f.detail
            ),
            Verdict::Refused,
        ),
        _ => (
            format!(
                "not refused: state {:?}, currents {:?} A, force {:.2} N",
                out.state,
                out.currents_a,
                norm(out.tool_force_n)
            ),
            Verdict::Weakness,
        ),
    };
    Ok(HardCase {
        case: "a 5 cm strike in one tick".into(),
        measurement,
        reference: "50 m/s is far above the tip-speed limit: an overspeed or encoder-jump fault, \
                    zero current"
            .into(),
        verdict,
        value: Some(norm(out.tool_force_n)),
        reference_value: Some(0.0),
    })
}

/// Two contact nodes 1 um apart: node `k` of a triangle edge and the point 1 um along the edge
/// towards `l`, whose compliance blocks are the P1 interpolation of the nodal ones (exact for
/// the finite-element field: `C(x, .) = (1 - t) C(k, .) + t C(l, .)`). Their 6 x 6 `C_SS` is
/// nearly singular; the firmware's Cholesky (`firmware::solve::Factor`, its pivot check) must
/// refuse it or solve it within the f32 bound of the f64 answer.
fn close_nodes(p: &Prepared, bank: &Bank) -> Result<HardCase> {
    let ids: Vec<usize> = bank.mesh_ids().iter().map(|&i| i as usize).collect();
    let tri = bank
        .triangles()
        .first()
        .ok_or_else(|| anyhow!("the bank has no triangle"))?;
    let (k, l) = (ids[usize::from(tri[0])], ids[usize::from(tri[1])]);
    let edge = fem::vec3::norm(fem::vec3::sub(p.organ.mesh.nodes[l], p.organ.mesh.nodes[k]));
    let t = 1e-6 / edge;
    let c = p.compliance.blocks(&[k, l], None)?;
    let mix = |a: Block3, b: Block3, wa: f64, wb: f64| -> Block3 {
        std::array::from_fn(|i| std::array::from_fn(|j| wa * a[i][j] + wb * b[i][j]))
    };
    let c_xk = mix(c[0][0], c[1][0], 1.0 - t, t);
    let c_xl = mix(c[0][1], c[1][1], 1.0 - t, t);
    let c_xx = mix(c_xk, c_xl, 1.0 - t, t);
    let c_kx = fem::compliance::transpose(c_xk);
    let css = vec![vec![c[0][0], c_kx], vec![c_xk, c_xx]];
    let u = [[0.0, 0.0, -0.004], [0.0, 0.0, -0.004]];
    let cond = super::precision::blocks_condition(&css)?;
    let mut a = [[0.0f32; MAX_DOFS]; MAX_DOFS];
    for (i, row) in a.iter_mut().enumerate().take(6) {
        for (j, e) in row.iter_mut().enumerate().take(6) {
            *e = css[i / 3][j / 3][i % 3][j % 3] as f32;
        }
    }
    let mut b = [0.0f32; MAX_DOFS];
    for (i, e) in b.iter_mut().enumerate().take(6) {
        *e = u[i / 3][i % 3] as f32;
    }
    let answer = Factor::<MAX_DOFS>::new(a, 6).and_then(|f| {
        f.check()?;
        f.solve(&b)
    });
    let (measurement, verdict, value) = match answer {
        Err(e) => (
            format!("refused by the firmware's factorisation: {e:?} (cond(C_SS) = {cond:.1e})"),
            Verdict::Refused,
            None,
        ),
        Ok(x) => {
            let want = contact_forces(&css, &u)?.forces;
            let got = [[x[0], x[1], x[2]], [x[3], x[4], x[5]]];
            let err = relative(&got, &want);
            (
                format!("solved: cond(C_SS) = {cond:.1e}, f32 relative force error {err:.1e}"),
                if err <= F32_BOUND {
                    Verdict::MatchesReference
                } else {
                    Verdict::Weakness
                },
                Some(err),
            )
        }
    };
    Ok(HardCase {
        case: "contact nodes 1 um apart".into(),
        measurement,
        reference: "a refusal, or the f64 solve within the f32 bound".into(),
        verdict,
        value,
        reference_value: Some(cond),
    })
}

/// The tool pressed 3 mm at the reachable region's edge (of R's boundary nodes the shaft meets
/// within 45 degrees of the surface's normal, the one farthest from R's centre; a node the
/// shaft only grazes would make a shallow press, which is the grazing row's case): the
/// firmware's patch loses the load on nodes outside R; the rendered force against the host's
/// f64 patch on the whole surface.
fn region_edge(p: &Prepared, bank: &Bank) -> Result<HardCase> {
    let mut count = std::collections::HashMap::<(usize, usize), usize>::new();
    for t in &p.region.triangles {
        for i in 0..3 {
            let (a, b) = (t[i] as usize, t[(i + 1) % 3] as usize);
            *count.entry((a.min(b), a.max(b))).or_default() += 1;
        }
    }
    let n = p.region.positions.len().max(1) as f64;
    let centre: [f64; 3] =
        std::array::from_fn(|c| p.region.positions.iter().map(|q| q[c]).sum::<f64>() / n);
    let dist = |a: usize| fem::vec3::norm(fem::vec3::sub(p.region.positions[a], centre));
    let ws = Workspace::from_device(bank.device());
    let cal = bank.device();
    let depth = 0.003;
    // The press towards R's node `a`, `s` metres past it along the shaft.
    let along = |a: usize, s: f64| {
        let target = p.region.positions[a];
        let dir = fem::vec3::sub(target, ws.fulcrum);
        let unit = fem::vec3::scale(dir, 1.0 / fem::vec3::norm(dir));
        ws.joints_for_tip(fem::vec3::add(target, fem::vec3::scale(unit, s)))
    };
    // Area-weighted outward normals of R's nodes (R's triangles are counter-clockwise seen
    // from outside).
    let mut normal = vec![[0.0f64; 3]; p.region.positions.len()];
    for t in &p.region.triangles {
        let v = t.map(|k| p.region.positions[k as usize]);
        let n = fem::vec3::cross(fem::vec3::sub(v[1], v[0]), fem::vec3::sub(v[2], v[0]));
        for &k in t {
            normal[k as usize] = fem::vec3::add(normal[k as usize], n);
        }
    }
    let head_on = |a: usize| {
        let shaft = fem::vec3::sub(p.region.positions[a], ws.fulcrum);
        let cos = -fem::vec3::dot(shaft, normal[a])
            / (fem::vec3::norm(shaft) * fem::vec3::norm(normal[a]));
        cos >= std::f64::consts::FRAC_1_SQRT_2
    };
    let in_range = |q: [f64; 3]| {
        (0..3).all(|i| q[i] >= f64::from(cal.joint_min[i]) && q[i] <= f64::from(cal.joint_max[i]))
    };
    // R's boundary nodes (on an edge of one R triangle only) the device can press, the one
    // farthest from R's centre.
    let edge_node = count
        .iter()
        .filter(|e| *e.1 == 1)
        .flat_map(|((a, b), _)| [*a, *b])
        .filter(|&a| head_on(a) && in_range(along(a, -0.01)) && in_range(along(a, depth)))
        .max_by(|&a, &b| dist(a).total_cmp(&dist(b)))
        .ok_or_else(|| {
            anyhow!(
                "no node on the reachable region's edge is within the joints' ranges and faces \
                 the shaft"
            )
        })?;
    let along = |s: f64| along(edge_node, s);
    let mut lp = armed_loop(bank, along(-0.01))?;
    let steps = 1300;
    let mut out = tick(&mut lp, along(-0.01));
    for i in 0..=steps {
        out = tick(
            &mut lp,
            along(-0.01 + (0.01 + depth) * i as f64 / steps as f64),
        );
    }
    let surface = ContactSurface::new(&p.organ.mesh, &p.organ.surface);
    let fixed = &p.organ.fixed;
    let free = |k: usize| (0..3).all(|c| !fixed.is_fixed(k, c));
    let (measurement, verdict, value, reference) = match (&out.contact, out.patch) {
        (ContactState::Touching { displacement, .. }, Some(origin))
            if out.state == State::Armed =>
        {
            let ids: Vec<usize> = bank.mesh_ids().iter().map(|&i| i as usize).collect();
            let hit = SurfaceHit {
                triangle: 0,
                nodes: origin.nodes.map(|k| ids[usize::from(k)]),
                bary: origin.bary.map(f64::from),
                point: origin.anchor.map(f64::from),
            };
            let patch = surface.tool_patch(&hit, f64::from(origin.radius_m), free);
            let d = displacement.map(f64::from);
            let full = patch_force(&p.compliance, &patch, d)?;
            let full_n = fem::vec3::norm(full);
            let err = fem::vec3::norm(std::array::from_fn(|c| {
                f64::from(out.tool_force_n[c]) + full[c]
            })) / full_n;
            (
                format!(
                    "pressed {:.2} mm into the surface: {} contact nodes kept, {:.1} % of the \
                     patch's load dropped (nodes outside R or uncoupled), rendered {:.3} N \
                     against {full_n:.3} N for the whole patch: {:.1} % off",
                    1e3 * norm(*displacement),
                    out.contact_nodes,
                    100.0 * f64::from(out.dropped_load),
                    norm(out.tool_force_n),
                    100.0 * err
                ),
                if err.is_finite() && err <= 0.1 {
                    Verdict::Bounded
                } else {
                    Verdict::Weakness
                },
                Some(err),
                Some(0.1),
            )
        }
        _ => (
            format!(
                "no rendered contact: state {:?}, fault {:?}, contact {:?}",
                out.state, out.fault, out.contact
            ),
            if matches!(out.state, State::Fault(_)) && out.currents_a.iter().all(|&a| a == 0.0) {
                Verdict::Refused
            } else {
                Verdict::Weakness
            },
            None,
            None,
        ),
    };
    Ok(HardCase {
        case: "contact at the reachable region's edge".into(),
        measurement,
        reference: "the host's f64 tool patch on the whole surface; bounded if within 10 %".into(),
        verdict,
        value,
        reference_value: reference,
    })
}
