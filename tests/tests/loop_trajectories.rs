//! The whole haptic loop ([`firmware::tick::HapticLoop`]) on a flat 5 x 5-node patch (z = 0,
//! 1 cm spacing, every pair coupled), driven by encoder counts computed here by inverse
//! kinematics: a press followed by a 500-tick slide across the patch and a lift, contact nodes
//! micrometres apart, a press at the edge of the region. Every tick:
//! no NaN, the force within `max_force_n`, the currents within their limits. And a slide that
//! speeds up past the bank's tip-speed threshold, which must end in `Overspeed` at zero current;
//! the SIL plant's scripted strike, natively, likewise.

#![allow(clippy::needless_range_loop)]

use bank_format::{Bank, DeviceCalibration, FaultReason};
use firmware::contact::ContactState;
use firmware::fixtures::{flat_patch, patch_device};
use firmware::hal::Interlocks;
use firmware::safety::{Fault, State};
use firmware::tick::{Contacts, HapticLoop, LoopInput, LoopOutput};
use haptic::kinematics::{Workspace, counts_for};

/// The encoder counts that put the tip at `tip` (the host's inverse kinematics).
fn counts_for_tip(cal: &DeviceCalibration, tip: [f64; 3]) -> [i32; 3] {
    counts_for(cal, Workspace::from_device(cal).joints_for_tip(tip))
}

fn lerp(a: [f64; 3], b: [f64; 3], t: f64) -> [f64; 3] {
    std::array::from_fn(|i| a[i] + (b[i] - a[i]) * t)
}

fn check(out: &LoopOutput, contacts: &Contacts, cal: &DeviceCalibration) {
    assert!(out.tip_m.iter().all(|x| x.is_finite()), "{out:?}");
    assert!(out.tool_force_n.iter().all(|x| x.is_finite()), "{out:?}");
    let f = out.tool_force_n.iter().map(|x| x * x).sum::<f32>().sqrt();
    assert!(f <= cal.max_force_n * (1.0 + 1e-5), "{out:?}");
    for (i, &lim) in out.currents_a.iter().zip(&cal.current_limit_a) {
        assert!(i.is_finite() && i.abs() <= lim, "{out:?}");
    }
    assert_eq!(contacts.len(), out.contact_nodes, "{out:?}");
    for c in contacts {
        assert!(c.force_n.iter().all(|x| x.is_finite()), "{out:?}");
    }
    assert_eq!(out.state, State::Armed, "{out:?}");
}

#[test]
fn slide_across_the_patch_while_pressed() {
    let bytes = flat_patch();
    let bank = Bank::parse(bytes.as_slice()).unwrap();
    let cal = patch_device();
    let mut lp = HapticLoop::new(&bank);
    lp.zero_encoders();
    lp.arm().unwrap();

    let above = [0.008, 0.012, 0.002];
    let start = [0.008, 0.012, -0.003];
    let end = [0.032, 0.028, -0.003];
    let mut path = Vec::new();
    path.extend((0..=50).map(|t| lerp(above, start, t as f64 / 50.0)));
    let slide_from = path.len();
    path.extend((1..=500).map(|t| lerp(start, end, t as f64 / 500.0)));
    let slide_to = path.len();
    let lifted = [end[0], end[1], 0.002];
    path.extend((1..=50).map(|t| lerp(end, lifted, t as f64 / 50.0)));

    let mut triangles = std::collections::BTreeSet::new();
    let mut max_f = 0.0f32;
    let mut prev_ft: Option<f32> = None;
    let mut max_drop = 0.0f32;
    for (n, &p) in path.iter().enumerate() {
        let out = lp.tick(LoopInput {
            encoder_counts: counts_for_tip(&cal, p),
            overrun: false,
            link_silence_ticks: 0,
            interlocks: Interlocks::default(),
        });
        check(&out, lp.contacts(), &cal);
        for i in 0..3 {
            assert!(
                (f64::from(out.tip_m[i]) - p[i]).abs() < 1e-4,
                "{out:?} vs {p:?}"
            );
        }
        if (slide_from..slide_to).contains(&n) {
            let ContactState::Touching { triangle, .. } = out.contact else {
                panic!("contact lost while sliding at tick {n}: {out:?}");
            };
            triangles.insert(triangle);
            // The 3 mm tip's patch on the 1 cm grid.
            assert!(out.contact_nodes > 0, "{out:?}");
            // Pressed 3 mm: the tool is pushed up, out of the tissue.
            assert!(out.tool_force_n[2] > 0.1, "{out:?}");
            max_f = max_f.max(out.tool_force_n[2]);
            // The stick cone bounds the tangential force and moves the anchor continuously:
            // it builds up while sticking, then holds; no saw-tooth (a sudden release) at
            // triangle edges.
            let f = out.tool_force_n;
            let ft = (f[0] * f[0] + f[1] * f[1]).sqrt();
            assert!(ft < 0.5 * f[2], "{out:?}");
            if let Some(p) = prev_ft {
                max_drop = max_drop.max(p - ft);
            }
            prev_ft = Some(ft);
        }
    }
    // The slide crossed several triangles; the last ticks are above the surface, force-free.
    assert!(triangles.len() >= 4, "{triangles:?}");
    assert!(max_f > 1.0, "{max_f}");
    // A patch swap blends the outgoing solve's force into the new one's over BLEND_TICKS
    // (a swap without it dropped the tangential force by 0.019 N in a tick here).
    assert!(
        max_drop < 0.01,
        "the tangential force fell by {max_drop} N in one tick"
    );
    let tel = lp.telemetry();
    assert_eq!(tel.tick, path.len() as u32);
    assert!(tel.contacts.is_empty());
    assert_eq!(tel.currents_a, [0.0; 3]);
}

/// Press and slide across a grid whose middle rows are 3 um apart: sliver triangles, and contact
/// patches holding pairs of nodes 3 um apart (a nearly singular `C_SS`). The energy-minimal
/// solve never inverts `C_SS`, so the loop stays armed with finite, bounded forces, and the
/// force changes smoothly across the sliver row.
#[test]
fn contact_nodes_micrometres_apart() {
    let ticks = [0.0, 0.01, 0.02, 0.03, 0.04];
    let rows = [0.0, 0.01, 0.02, 0.020_003, 0.03, 0.04];
    let bytes = firmware::fixtures::grid_patch_at(&ticks, &rows, 0.06);
    let bank = Bank::parse(bytes.as_slice()).unwrap();
    let cal = patch_device();
    let mut lp = HapticLoop::new(&bank);
    lp.zero_encoders();
    lp.arm().unwrap();
    // Down onto the sliver row, then across it in y and back, pressed 2 mm.
    let above = [0.017, 0.0185, 0.002];
    let start = [0.017, 0.0185, -0.002];
    let end = [0.017, 0.0215, -0.002];
    let mut path: Vec<[f64; 3]> = (0..=40)
        .map(|t| lerp(above, start, t as f64 / 40.0))
        .collect();
    path.extend((1..=300).map(|t| lerp(start, end, t as f64 / 300.0)));
    let mut close_pairs = 0;
    let mut prev_fz: Option<f32> = None;
    let mut max_step = 0.0f32;
    for (n, p) in path.into_iter().enumerate() {
        let out = lp.tick(LoopInput {
            encoder_counts: counts_for_tip(&cal, p),
            overrun: false,
            link_silence_ticks: 0,
            interlocks: Interlocks::default(),
        });
        check(&out, lp.contacts(), &cal);
        assert!(out.solve_error.is_none(), "{out:?}");
        let pos = bank.positions();
        let nodes: Vec<usize> = lp.contacts().iter().map(|c| usize::from(c.node)).collect();
        if nodes.iter().any(|&a| {
            nodes.iter().any(|&b| {
                a != b && (0..3).map(|i| (pos[a][i] - pos[b][i]).powi(2)).sum::<f32>() < 1e-10
            })
        }) {
            close_pairs += 1;
        }
        let sliding = n > 40;
        if matches!(out.contact, ContactState::Touching { .. }) && sliding {
            if let Some(prev) = prev_fz {
                max_step = max_step.max((out.tool_force_n[2] - prev).abs());
            }
            prev_fz = Some(out.tool_force_n[2]);
        }
    }
    assert!(
        close_pairs > 50,
        "only {close_pairs} ticks had both close nodes in contact"
    );
    // 10 um per tick across the sliver row: no jump in the normal force (it is ~0.5 N).
    assert!(max_step < 0.02, "largest normal-force step {max_step} N");
}

/// A press at the edge of the bank's region, where the rest of the organ is held fixed (the
/// nodes beyond are not in R): the tip's patch is clipped to R's border, the loop stays armed
/// with finite forces, and pressing deeper pushes back harder.
#[test]
fn contact_next_to_the_fixed_boundary() {
    let bytes = flat_patch();
    let bank = Bank::parse(bytes.as_slice()).unwrap();
    let cal = patch_device();
    let mut lp = HapticLoop::new(&bank);
    lp.zero_encoders();
    lp.arm().unwrap();
    // 1 mm inside the patch's x = 0 edge, between two edge nodes.
    let mut last = 0.0f32;
    let mut touching = 0;
    for t in 0..=200 {
        let p = [0.001, 0.015, 0.002 - 4.0e-3 * f64::from(t) / 200.0];
        let out = lp.tick(LoopInput {
            encoder_counts: counts_for_tip(&cal, p),
            overrun: false,
            link_silence_ticks: 0,
            interlocks: Interlocks::default(),
        });
        check(&out, lp.contacts(), &cal);
        assert!(out.solve_error.is_none(), "{out:?}");
        if matches!(out.contact, ContactState::Touching { .. }) && p[2] < -1e-4 {
            touching += 1;
            assert!(out.tool_force_n[2] > last, "{out:?}");
            last = out.tool_force_n[2];
        }
    }
    assert!(touching > 80 && last > 0.1, "{touching} {last}");
}

/// Pressed 3 mm and sliding ever faster across the patch (0.1 mm/tick more every tick): the
/// loop renders while the tip is under the bank's 1 m/s, faults `Overspeed` (detail 3, the tip)
/// at the first tick it moves more than 1 mm, and drives no current from that tick on, though
/// the tool still presses; clearing the fault and arming renders again.
#[test]
fn sliding_faster_than_the_tip_threshold_faults_overspeed() {
    let bytes = flat_patch();
    let bank = Bank::parse(bytes.as_slice()).unwrap();
    let cal = patch_device();
    let mut lp = HapticLoop::new(&bank);
    lp.zero_encoders();
    lp.arm().unwrap();
    let above = [0.004, 0.02, 0.002];
    let start = [0.004, 0.02, -0.003];
    let mut path: Vec<[f64; 3]> = (0..=50)
        .map(|t| lerp(above, start, t as f64 / 50.0))
        .collect();
    // Steps 0.35, 0.45, ... mm: 0.95 mm (0.95 m/s) at the 7th, 1.05 mm at the 8th, the margin
    // (50 um) well beyond the encoders' quantisation (about 13 um per pitch count at the tip).
    let mut x = start[0];
    for n in 0..14 {
        x += (0.35 + 0.1 * f64::from(n)) * 1e-3;
        path.push([x, start[1], start[2]]);
    }
    let limit = f64::from(cal.max_tip_speed_m_s) * f64::from(firmware::TICK_PERIOD_S);
    let dist = |a: [f64; 3], b: [f64; 3]| (0..3).map(|i| (a[i] - b[i]).powi(2)).sum::<f64>().sqrt();
    let first_fast = (1..path.len())
        .find(|&n| dist(path[n], path[n - 1]) > limit)
        .unwrap();
    assert_eq!(first_fast, 51 + 7);
    let mut faults = Vec::new();
    for (n, &p) in path.iter().enumerate() {
        let out = lp.tick(LoopInput {
            encoder_counts: counts_for_tip(&cal, p),
            overrun: false,
            link_silence_ticks: 0,
            interlocks: Interlocks::default(),
        });
        if let Some(f) = out.new_fault {
            faults.push((n, f));
        }
        if n < first_fast {
            check(&out, lp.contacts(), &cal);
            if n > 30 {
                assert!(out.currents_a.iter().any(|&i| i != 0.0), "{out:?}");
            }
        } else {
            assert_eq!(out.state, State::Fault(FaultReason::Overspeed), "{out:?}");
            assert_eq!(out.currents_a, [0.0; 3], "{out:?}");
            assert!(
                matches!(out.contact, ContactState::Touching { .. }),
                "{out:?}"
            );
        }
    }
    assert_eq!(
        faults,
        [(
            first_fast,
            Fault {
                reason: FaultReason::Overspeed,
                detail: 3
            }
        )]
    );
    // Re-arming is explicit: clear, arm; held still, the press renders again.
    let last = *path.last().unwrap();
    let hold = LoopInput {
        encoder_counts: counts_for_tip(&cal, last),
        overrun: false,
        link_silence_ticks: 0,
        interlocks: Interlocks::default(),
    };
    assert!(lp.arm().is_err());
    assert!(lp.clear_fault());
    lp.arm().unwrap();
    let out = lp.tick(hold);
    check(&out, lp.contacts(), &cal);
    assert!(out.currents_a.iter().any(|&i| i != 0.0), "{out:?}");
}

/// The SIL harness's `strike` (`haptic::sil::script`: from 10 mm above the liver, 18 mm down in
/// 20 ms), natively: the simulated gimbal, pulled by the hand, reaches about 1.4 m/s, over the
/// shipped scene's 1 m/s, while still above the surface. The loop, armed at the harness's arm
/// tick, faults `Overspeed` at the tip during the descent, before any contact, and drives no
/// current from then on (the press that follows is felt by nobody). `tests/sil.rs` expects the
/// same of the QEMU image.
#[test]
fn the_sil_strike_trips_overspeed_before_contact() {
    use haptic::sil::harness::ARM_TICK;
    use haptic::sil::plant::{Gimbal, PlantParams, TICK_S};
    use haptic::sil::script::Trajectory;
    use haptic::trajectory::Script;
    let scene = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../host/scenes/liver.toml");
    let raw = haptic::bank::scene_bank(&scene).unwrap();
    let bytes = bank_format::AlignedBytes::new(&raw);
    let bank = Bank::parse(&bytes).unwrap();
    let cal = *bank.device();
    let trajectory = Trajectory::new(&bank, Script::Strike).unwrap();
    let mut gimbal = Gimbal::new(&cal, PlantParams::default());
    let mut lp = HapticLoop::new(&bank);
    // The harness homes the image while the hand rests at home (encoder zero).
    lp.zero_encoders();
    let mut hand_prev = trajectory.at(0.0);
    let (mut faults, mut peak, mut prev_tip) = (Vec::new(), 0.0f32, None::<[f32; 3]>);
    let mut first_contact = None;
    for tick in 1..=2000u32 {
        if tick == ARM_TICK {
            lp.arm().unwrap();
        }
        let out = lp.tick(LoopInput {
            encoder_counts: gimbal.encoder_counts(),
            overrun: false,
            link_silence_ticks: 0,
            interlocks: Interlocks::default(),
        });
        if let Some(f) = out.new_fault {
            faults.push((tick, f));
        }
        if out.contact_nodes > 0 && first_contact.is_none() {
            first_contact = Some(tick);
        }
        if let Some(p) = prev_tip {
            let d: f32 = (0..3).map(|i| (out.tip_m[i] - p[i]).powi(2)).sum();
            peak = peak.max(d.sqrt() / firmware::TICK_PERIOD_S);
        }
        prev_tip = Some(out.tip_m);
        if let Some(&(at, _)) = faults.first() {
            assert_eq!(out.currents_a, [0.0; 3], "tick {tick}: {out:?}");
            assert_eq!(
                out.state,
                State::Fault(FaultReason::Overspeed),
                "tick {tick}"
            );
            assert!(tick >= at);
        }
        let hand = trajectory.at(f64::from(tick) * TICK_S);
        gimbal.step(out.currents_a, hand_prev, hand);
        hand_prev = hand;
    }
    assert_eq!(faults.len(), 1, "{faults:?}");
    let (at, fault) = faults[0];
    assert_eq!(
        fault,
        Fault {
            reason: FaultReason::Overspeed,
            detail: 3
        }
    );
    // The strike starts 1.0 s into the run (0.5 s approach, 0.5 s hover); the fault comes
    // within its 20 ms descent, before the tip reaches the surface.
    assert!((1000..1020).contains(&at), "{at}");
    let touched = first_contact.expect("the strike reaches the liver");
    assert!(touched > at, "contact at {touched}, fault at {at}");
    assert!(peak > 1.2 && peak < 1.6, "peak tip speed {peak} m/s");
}
