//! The loop's tests: the per-tick sequence, the modes, the ramp-in and the supervisor's faults
//! through the tick (the sampled, nodal and gravity parts test theirs beside them).

#![allow(clippy::needless_range_loop)]

extern crate std;

use bank_format::{
    AlignedBytes, Bank, BankBuilder, DeviceCalibration, FaultReason, Mode, TissueLaw,
};
use std::vec::Vec;

use super::rig::{Rig, check, counts_for_insertion, gravity_bank, input, norm, parse};
use super::{BAD_COMMAND_SET_MODE_ARMED, HapticLoop, LoopInput, RAMP_IN_TICKS};
use crate::contact::ContactState;
use crate::device::Joints;
use crate::fixtures::{flat_patch, patch_device};
use crate::hal::Interlocks;
use crate::safety::{ArmRefused, Fault, SafetyConfig, State};
use crate::solve::SolveError;

#[test]
fn press_and_release() {
    let bytes = flat_patch();
    let bank = parse(&bytes);
    let cal = patch_device();
    let mut lp = Rig::new(&bank).homed();
    assert_eq!(lp.arm(), Ok(()));
    // Down from 5 mm above the surface to 4 mm deep, 0.05 mm per tick, and back up.
    let down: Vec<f32> = (0..=180).map(|t| 0.095 + 0.05e-3 * t as f32).collect();
    let path: Vec<f32> = down.iter().chain(down.iter().rev()).copied().collect();
    let mut fz = Vec::new();
    for &s in &path {
        let out = lp.at(s);
        check(&out, &cal);
        assert_eq!(out.state, State::Armed, "{out:?}");
        let depth = -out.tip_m[2];
        if depth > 1e-4 {
            assert!(
                matches!(out.contact, ContactState::Touching { .. }),
                "{out:?}"
            );
            // Pressed at a node of the 1 cm grid with a 3 mm tip: the node and its ring of
            // six carry it, once the patch is built (under 16 ticks, 0.8 mm, after
            // contact; the contact triangle carries it before).
            let n = out.contact_nodes;
            assert!(n == 7 || (n <= 3 && depth < 0.8e-3), "{out:?}");
            // The tool is pushed back up, out of the tissue.
            assert!(out.tool_force_n[2] > 0.0, "{out:?}");
            // Insertion motor pushes the shaft back: negative effort along +insertion.
            assert!(out.currents_a[2] < 0.0, "{out:?}");
        }
        if depth < -1e-6 {
            assert_eq!(out.contact, ContactState::Free);
            assert_eq!(out.tool_force_n, [0.0; 3]);
            assert_eq!(out.currents_a, [0.0; 3]);
            assert!(out.contact_nodes == 0);
        }
        fz.push(out.tool_force_n[2]);
    }
    // Rises while pressing (monotone within rounding), peaks at the bottom, back to zero.
    let peak = fz.iter().copied().fold(0.0f32, f32::max);
    assert!(peak > 0.5 && peak <= cal.max_force_n, "peak {peak}");
    for w in fz[..down.len()].windows(2) {
        assert!(w[1] >= w[0] - 1e-4, "{w:?}");
    }
    assert_eq!(*fz.last().unwrap(), 0.0);
    let tel = lp.telemetry();
    assert_eq!(tel.tick, path.len() as u32);
    assert_eq!(tel.state, bank_format::State::Armed);
    assert!(tel.contacts.is_empty());
}

/// The flat patch with the relaxation `g`, `tau_s` (s), or elastic.
fn relaxing_patch(g: &[f32], tau_s: &[f32]) -> AlignedBytes {
    let side: Vec<f64> = (0..crate::fixtures::PATCH_SIDE)
        .map(|i| crate::fixtures::PATCH_SPACING_M * i as f64)
        .collect();
    let mut b = crate::fixtures::grid_builder(&side, &side, 0.06, patch_device());
    if !g.is_empty() {
        let mut r = bank_format::Relaxation {
            count: g.len() as u32,
            reserved: 0,
            g: [0.0; 4],
            tau_s: [0.0; 4],
        };
        r.g[..g.len()].copy_from_slice(g);
        r.tau_s[..tau_s.len()].copy_from_slice(tau_s);
        b.relaxation = Some(r);
    }
    AlignedBytes::new(&b.build().unwrap())
}

/// A press (3 mm at 10 mm/s), a 2 s hold and a release on a bank with a two-term
/// relaxation: every tick's force is the QLV convolution (`firmware::relax`, (1)) of the
/// elastic bank's force on the same path, evaluated independently of the recursion as
/// the direct sum over the history's segments (each segment's integral in closed form,
/// f64); nothing after the release; and in `LinearLaw` the relaxed bank renders the elastic
/// force bit for bit.
#[test]
fn a_relaxing_bank_renders_the_qlv_convolution_of_the_elastic_force() {
    let (g, tau) = ([0.4f64, 0.25], [0.05f64, 0.8]);
    let elastic = relaxing_patch(&[], &[]);
    let relaxing = relaxing_patch(&[0.4, 0.25], &[0.05, 0.8]);
    let elastic = parse(&elastic);
    let relaxing = parse(&relaxing);
    let mut path: Vec<f32> = (0..=400).map(|t| 0.097 + 0.01e-3 * t as f32).collect();
    path.extend(std::iter::repeat_n(0.101, 2000));
    path.extend((0..=400).rev().map(|t| 0.097 + 0.01e-3 * t as f32));
    let run = |bank: &Bank, mode: Mode| -> Vec<[f32; 3]> {
        let mut lp = Rig::new(bank).homed().in_mode(mode);
        path.iter().map(|&s| lp.at(s).tool_force_n).collect()
    };
    let q = run(&elastic, Mode::Render);
    let f = run(&relaxing, Mode::Render);
    assert_eq!(
        run(&relaxing, Mode::LinearLaw),
        run(&elastic, Mode::LinearLaw)
    );
    let peak = q.iter().map(|v| norm(*v)).fold(0.0, f32::max);
    assert!(
        peak > 0.3 && peak < patch_device().max_force_n * 0.9,
        "{peak}"
    );
    let g_inf = 1.0 - g.iter().sum::<f64>();
    let dt = 1.0e-3;
    let mut worst = 0.0f64;
    let release = 400 + 2000;
    for n in 0..release {
        for i in 0..3 {
            // F(n) = g_inf Q(n) + sum_k g_k sum_j e^{-(n-j) dt/tau} (tau/dt)(1 - e^{-dt/tau})
            // (Q(j) - Q(j-1)): the convolution (1) of the linear interpolation of Q.
            let qi = |j: usize| if j == 0 { 0.0 } else { f64::from(q[j - 1][i]) };
            let mut want = g_inf * qi(n + 1);
            for (gk, tk) in g.iter().zip(tau) {
                let seg = tk / dt * (1.0 - (-dt / tk).exp());
                for j in 1..=n + 1 {
                    let age = (n + 1 - j) as f64 * dt;
                    want += gk * seg * (-age / tk).exp() * (qi(j) - qi(j - 1));
                }
            }
            worst = worst.max((f64::from(f[n][i]) - want).abs() / f64::from(peak));
        }
    }
    assert!(worst < 1e-5, "worst {worst:e} of the peak");
    // Relaxed in the hold: at its end (2 s) the 50 ms term is gone and the 0.8 s one has
    // e^-2.5 of its share left: the force is g_inf of the elastic one plus under 0.025.
    let end = release - 1;
    let excess = f64::from(f[end][2] / q[end][2]) - g_inf;
    assert!((0.0..0.025).contains(&excess), "{excess}");
    // Out of contact: nothing.
    assert_eq!(*f.last().unwrap(), [0.0; 3]);
    for (a, b) in f.iter().zip(&q).skip(release) {
        if *b == [0.0; 3] {
            assert_eq!(*a, [0.0; 3]);
        }
    }
}

/// Pressed 3 mm into the tissue while disarmed, then armed: the rendered force and the
/// currents rise from zero over `RAMP_IN_TICKS`, in equal steps, instead of the whole
/// force in the first armed tick; the same after a fault's `ClearFault` + `Arm`. The
/// gravity feed-forward ramps with them.
#[test]
fn the_force_ramps_in_after_each_arm() {
    let bytes = flat_patch();
    let bank = parse(&bytes);
    let mut lp = Rig::new(&bank).homed();
    let out = lp.pressed(0.095, 0.05e-3, 160);
    let s = lp.counts(0.103);
    assert_eq!(out.state, State::Disarmed);
    let full = out.tool_force_n;
    assert!(norm(full) > 0.5, "{out:?}");
    let check_ramp = |lp: &mut HapticLoop| {
        let mut currents = Vec::new();
        for k in 1..=RAMP_IN_TICKS {
            let out = lp.tick(input(s));
            assert_eq!(out.state, State::Armed);
            let share = k as f32 / RAMP_IN_TICKS as f32;
            for i in 0..3 {
                assert!(
                    (out.tool_force_n[i] - share * full[i]).abs() <= 1e-5 * norm(full),
                    "tick {k}: {out:?}"
                );
            }
            currents.push(out.currents_a[2]);
        }
        // The insertion current falls (pushes back) in equal steps to its full value.
        let step = currents[RAMP_IN_TICKS as usize - 1] / RAMP_IN_TICKS as f32;
        assert!(step < 0.0);
        for (k, c) in currents.iter().enumerate() {
            assert!(
                (c - step * (k + 1) as f32).abs() <= 1e-4 * step.abs(),
                "{k}"
            );
        }
        assert_eq!(lp.tick(input(s)).tool_force_n, full);
    };
    lp.arm().unwrap();
    check_ramp(&mut lp);
    // A fault while pressed (the host went silent), cleared and armed again: from zero.
    let out = lp.tick(LoopInput {
        link_silence_ticks: 11,
        ..input(s)
    });
    assert_eq!(out.state, State::Fault(FaultReason::LinkSilent));
    assert!(lp.clear_fault());
    lp.arm().unwrap();
    check_ramp(&mut lp);

    // The gravity feed-forward: a third of it a third of the way in.
    let g = bank_format::GravityCompensation {
        coeffs: [0.05, -0.02, 0.03, 0.4, 0.1, -0.3, 0.02, -0.01],
    };
    let with = gravity_bank(Some(g));
    let bank = parse(&with);
    let counts = [2000, -1500, 300];
    let mut lp = Rig::new(&bank).homed().armed();
    let third: Vec<[f32; 3]> = (0..RAMP_IN_TICKS / 3)
        .map(|_| lp.tick(input(counts)).currents_a)
        .collect();
    let whole = lp.ramped(counts).currents_a;
    for j in 0..3 {
        let got = third.last().unwrap()[j];
        assert!((got - whole[j] / 3.0).abs() <= 1e-5 * whole[j].abs(), "{j}");
        assert!(third[0][j].abs() <= whole[j].abs() / RAMP_IN_TICKS as f32 * 1.0001);
    }
}

/// Arming needs the encoders referenced (a `ZeroEncoders` since the loop started, i.e.
/// since the chip's reset): refused and latched `NotReferenced` before; an encoder jump
/// loses the reference again.
#[test]
fn arming_needs_a_reference_which_an_encoder_jump_loses() {
    let bytes = flat_patch();
    let bank = parse(&bytes);
    let mut lp = HapticLoop::new(&bank);
    assert!(!lp.referenced());
    lp.tick(input([0, 0, 0]));
    assert_eq!(lp.arm(), Err(ArmRefused::NotReferenced));
    let out = lp.tick(input([0, 0, 0]));
    assert_eq!(
        (out.state, out.currents_a),
        (State::Fault(FaultReason::NotReferenced), [0.0; 3])
    );
    assert!(lp.clear_fault());
    assert!(lp.zero_encoders());
    assert!(lp.referenced());
    lp.arm().unwrap();
    assert_eq!(lp.tick(input([0, 0, 0])).state, State::Armed);
    let out = lp.tick(input([0, 0, 100_000]));
    assert_eq!(out.state, State::Fault(FaultReason::EncoderJump));
    assert!(!lp.referenced());
    assert!(lp.clear_fault());
    assert_eq!(lp.arm(), Err(ArmRefused::NotReferenced));
}

/// A jump loses the reference whatever the supervisor reports for the tick: while another
/// fault is latched (`LinkSilent`, which `raise` keeps over the jump's `EncoderJump`) and
/// in the same tick as an interlock (reported before jumps). Both end with `Arm` refused
/// `NotReferenced` after `ClearFault`, and arm again once homed.
#[test]
fn a_jump_hidden_by_another_fault_still_loses_the_reference() {
    let bytes = flat_patch();
    let bank = parse(&bytes);
    let jump = [0, 0, 100_000];

    // LinkSilent latched, then the jump while it is.
    let mut lp = Rig::new(&bank).homed();
    lp.tick(input([0; 3]));
    lp.arm().unwrap();
    let out = lp.tick(LoopInput {
        link_silence_ticks: 1_000,
        ..input([0; 3])
    });
    assert_eq!(out.state, State::Fault(FaultReason::LinkSilent));
    let out = lp.tick(input(jump));
    assert_eq!(out.state, State::Fault(FaultReason::LinkSilent));
    assert_eq!(out.new_fault, None);
    assert!(!lp.referenced());
    assert!(lp.clear_fault());
    assert_eq!(lp.arm(), Err(ArmRefused::NotReferenced));
    // Homed again where the counts now stand, it arms.
    assert!(lp.clear_fault());
    assert!(lp.zero_encoders());
    assert_eq!(lp.tick(input(jump)).state, State::Disarmed);
    assert_eq!(lp.arm(), Ok(()));

    // An amplifier fault in the same tick as the jump.
    let mut lp = Rig::new(&bank).homed();
    lp.tick(input([0; 3]));
    lp.arm().unwrap();
    let mut amp = Interlocks::default();
    amp.amplifier_fault[1] = true;
    let out = lp.tick(LoopInput {
        interlocks: amp,
        ..input(jump)
    });
    assert_eq!(out.state, State::Fault(FaultReason::AmplifierFault));
    assert_eq!(out.currents_a, [0.0; 3]);
    assert!(!lp.referenced());
    lp.tick(input(jump));
    assert!(lp.clear_fault());
    assert_eq!(lp.arm(), Err(ArmRefused::NotReferenced));
}

#[test]
fn linear_law_and_transparent_modes() {
    let bytes = flat_patch();
    let bank = parse(&bytes);
    let mut lp = Rig::new(&bank).homed().armed();
    lp.pressed(0.099, 0.03e-3, 100);
    let s = lp.counts(0.102);
    let render = lp.ramped(s);
    let render_contacts = lp.contacts().clone();
    // The mode is set while disarmed.
    assert!(lp.disarm());
    lp.set_mode(Mode::LinearLaw).unwrap();
    lp.arm().unwrap();
    let linear = lp.ramped(s);
    // The node forces (linear model) sum to minus the linear tool force.
    let sum: [f32; 3] = core::array::from_fn(|i| lp.contacts().iter().map(|c| c.force_n[i]).sum());
    for i in 0..3 {
        assert!(
            (sum[i] + linear.tool_force_n[i]).abs() < 1e-4,
            "{sum:?} {linear:?}"
        );
    }
    assert_eq!(&render_contacts, lp.contacts());
    assert!((render.tool_force_n[2] - linear.tool_force_n[2]).abs() > 1e-3);
    // The mode is set while disarmed.
    assert!(lp.disarm());
    lp.set_mode(Mode::Transparent).unwrap();
    lp.arm().unwrap();
    let out = lp.tick(input(s));
    assert_eq!(out.currents_a, [0.0; 3]);
    assert_eq!(out.contact_nodes, 7);
}

/// A host's `ConstantCurrent` command reaches the supervisor as sent: a current over its
/// motor's limit (-9 A against 2 A) or a NaN is a `BadCommand` fault naming the motor, with
/// zero current, not a request silently clamped to the limit.
#[test]
fn constant_current_over_the_limit_or_not_finite_is_a_bad_command() {
    let bytes = flat_patch();
    let bank = parse(&bytes);
    let cal = patch_device();
    assert_eq!(cal.current_limit_a, [2.0; 3]);
    for (currents_a, motor) in [
        ([0.5, -9.0, 0.0], 1),
        ([0.5, 0.0, f32::NAN], 2),
        ([f32::INFINITY, 0.0, 0.0], 0),
        ([0.0, 2.0 + 1e-3, 0.0], 1),
    ] {
        let mut lp = Rig::new(&bank).homed();
        assert_eq!(lp.set_mode(Mode::ConstantCurrent { currents_a }), Ok(()));
        lp.arm().unwrap();
        let out = lp.tick(input([0, 0, 0]));
        let want = Fault {
            reason: FaultReason::BadCommand,
            detail: motor,
        };
        assert_eq!(out.new_fault, Some(want), "{currents_a:?}");
        assert_eq!(out.state, State::Fault(FaultReason::BadCommand));
        assert_eq!(out.currents_a, [0.0; 3]);
    }
    // Within the limits (the limit itself included) it is driven as given.
    let mut lp = Rig::new(&bank).homed();
    let ok = [0.5, -2.0, 2.0];
    lp.set_mode(Mode::ConstantCurrent { currents_a: ok })
        .unwrap();
    lp.arm().unwrap();
    let out = lp.tick(input([0, 0, 0]));
    assert_eq!((out.state, out.currents_a), (State::Armed, ok));
}

/// `SetMode` while armed is refused (the mode stays) and reported as a latched
/// `BadCommand` (detail 3): a mode change under the user's hand, e.g. from rendering to
/// constant currents, would bypass what the user was feeling.
#[test]
fn set_mode_while_armed_is_refused_and_reported() {
    let bytes = flat_patch();
    let bank = parse(&bytes);
    let mut lp = Rig::new(&bank).homed().armed();
    assert_eq!(lp.tick(input([0, 0, 0])).state, State::Armed);
    let want = Fault {
        reason: FaultReason::BadCommand,
        detail: BAD_COMMAND_SET_MODE_ARMED,
    };
    assert_eq!(
        lp.set_mode(Mode::ConstantCurrent {
            currents_a: [1.0; 3]
        }),
        Err(want)
    );
    assert_eq!(lp.mode(), Mode::Render);
    let out = lp.tick(input([0, 0, 0]));
    assert_eq!(
        (out.state, out.currents_a),
        (State::Fault(FaultReason::BadCommand), [0.0; 3])
    );
    // Reported by the refusal, not again by the tick.
    assert_eq!(out.new_fault, None);
    assert_eq!(out.fault, Some(want));
    // Disarmed (after clearing), the mode can be set.
    assert!(lp.clear_fault());
    assert_eq!(lp.set_mode(Mode::Transparent), Ok(()));
    assert_eq!(lp.mode(), Mode::Transparent);
}

/// A 5 cm strike in one tick, from 2 cm above the patch to 3 cm into it. With the default
/// thresholds it is an encoder jump: checked before any geometry, so the glitch is not
/// swept for contacts (before, detection ran along the whole jump and found the surface).
/// With the jump check relaxed, a 50 m/s move, over the 1 m/s overspeed threshold: only
/// the last 1 mm of it is swept (`contact::path_tail`), under the surface, so no contact;
/// `Overspeed`, zero current. With the overspeed check relaxed too, the sweep is still cut
/// to `MAX_DETECT_PIECES` cells' pieces: the bank and the motion cannot lengthen the
/// detection; a 12 mm strike through the surface, within that cap (13.4 mm), is found and
/// rendered.
#[test]
fn strike_in_one_tick() {
    let bytes = flat_patch();
    let bank = parse(&bytes);
    let cal = patch_device();
    // Default thresholds: 5 cm in 1 ms is an encoder jump -> fault, zero current, no
    // contact.
    let mut lp = Rig::new(&bank).homed().armed();
    check(&lp.at(0.08), &cal);
    let out = lp.at(0.13);
    check(&out, &cal);
    assert_eq!(out.contact, ContactState::Free);
    assert_eq!(out.state, State::Fault(FaultReason::EncoderJump));
    assert_eq!(out.new_fault.unwrap().detail, 2);
    assert_eq!((out.currents_a, out.tool_force_n), ([0.0; 3], [0.0; 3]));
    // Held there, the tip is under the surface untracked: no contact, no force.
    let out = lp.at(0.13);
    assert_eq!(
        (out.contact, out.currents_a),
        (ContactState::Free, [0.0; 3])
    );

    // With the jump check relaxed, it is what it would physically be, a 50 m/s strike: the
    // tip's overspeed (threshold 1 m/s), zero current; only its last millimetre is swept.
    let mut config = SafetyConfig::new(&cal);
    config.max_counts_per_tick = [u32::MAX; 3];
    let mut lp = Rig::with_config(&bank, config).homed();
    lp.arm().unwrap();
    check(&lp.at(0.08), &cal);
    let out = lp.at(0.13);
    check(&out, &cal);
    assert_eq!(out.contact, ContactState::Free);
    assert_eq!(out.state, State::Fault(FaultReason::Overspeed));
    assert_eq!(out.new_fault.unwrap().detail, 3);
    assert_eq!(out.currents_a, [0.0; 3]);

    // With the overspeed check relaxed too: the sweep is cut to three pieces of the 10 mm
    // grid (13 mm), all under the surface here, so still no contact.
    config.max_tip_speed_m_s = f32::INFINITY;
    config.max_joint_speed = [f32::INFINITY; 3];
    let mut lp = Rig::with_config(&bank, config).homed();
    assert!((lp.max_path_m - 0.99 * 3.0 * 0.45 * 0.01).abs() < 1e-6);
    lp.arm().unwrap();
    check(&lp.ramped(lp.counts(0.08)), &cal);
    let out = lp.at(0.13);
    assert_eq!((out.contact, out.state), (ContactState::Free, State::Armed));
    // A 12 mm strike through the surface, within the cap, is found and rendered.
    let mut lp = Rig::with_config(&bank, config).homed();
    lp.arm().unwrap();
    check(&lp.ramped(lp.counts(0.095)), &cal);
    let out = lp.at(0.107);
    check(&out, &cal);
    assert!(matches!(out.contact, ContactState::Touching { .. }));
    assert_eq!(out.tool_force_n, [0.0; 3]);
    let out = lp.at(0.107);
    check(&out, &cal);
    assert_eq!(out.state, State::Armed, "{out:?}");
    assert!(out.tool_force_n[2] > 0.5, "{out:?}");
    assert!(out.currents_a[2] < 0.0);
}

/// The tip pressed into the patch and rendering, then driven down 1.2 mm in one tick
/// (1.2 m/s, over the bank's 1 m/s but no encoder jump): `Overspeed` at the tip, zero current
/// from that tick on, reported once; explicit clear and arm render again.
#[test]
fn overspeed_at_the_tip_zeroes_the_currents_from_that_tick_on() {
    let bytes = flat_patch();
    let bank = parse(&bytes);
    let cal = patch_device();
    assert_eq!(cal.max_tip_speed_m_s, 1.0);
    let mut lp = Rig::new(&bank).homed().armed();
    // 0.5 m/s down to 3 mm deep: fast, but under the threshold.
    let mut s = 0.095;
    while s < 0.103 {
        s += 0.5e-3;
        let out = lp.at(s);
        check(&out, &cal);
        assert_eq!(out.state, State::Armed, "{out:?}");
    }
    let pressed = lp.at(s);
    assert!(pressed.currents_a[2] < 0.0, "{pressed:?}");
    let out = lp.at(s + 1.2e-3);
    check(&out, &cal);
    assert_eq!(out.state, State::Fault(FaultReason::Overspeed));
    assert_eq!(
        out.new_fault,
        Some(Fault {
            reason: FaultReason::Overspeed,
            detail: 3
        })
    );
    assert_eq!(out.currents_a, [0.0; 3]);
    // Still pressed, force computed, but nothing driven and nothing reported again.
    for k in 0..50 {
        let out = lp.at(s + 1.2e-3 - 1e-5 * k as f32);
        assert!(out.tool_force_n[2] > 0.0, "{out:?}");
        assert_eq!((out.currents_a, out.new_fault), ([0.0; 3], None));
        assert_eq!(out.fault.map(|f| f.reason), Some(FaultReason::Overspeed));
    }
    assert_eq!(lp.telemetry().fault, Some(FaultReason::Overspeed));
    assert!(lp.arm().is_err(), "re-arming needs the fault cleared first");
    assert!(lp.clear_fault());
    lp.arm().unwrap();
    let out = lp.at(s);
    assert_eq!(out.state, State::Armed);
    assert!(out.currents_a[2] < 0.0, "{out:?}");
}

/// A fast pitch close to the fulcrum: 15 rad/s (threshold 10) moves the tip only 0.75 m/s,
/// so the joint's own threshold trips (detail 0); the constant currents stop that tick.
#[test]
fn overspeed_of_a_joint_near_the_fulcrum() {
    let bytes = flat_patch();
    let bank = parse(&bytes);
    let cal = patch_device();
    let mut lp = Rig::new(&bank).homed();
    let per_rad = 1.0 / lp.device().joint_per_count()[0];
    lp.set_mode(Mode::ConstantCurrent {
        currents_a: [0.5, 0.5, 0.5],
    })
    .unwrap();
    lp.arm().unwrap();
    let pitch_counts = |q: f32| [(q * per_rad).round() as i32, 0, 0];
    // 5 rad/s for 20 ticks (0.25 m/s at the tip, 5 cm from the fulcrum).
    let mut q = 0.0f32;
    for _ in 0..20 {
        q += 0.005;
        let out = lp.tick(input(pitch_counts(q)));
        assert_eq!(out.currents_a, [0.5, 0.5, 0.5], "{out:?}");
    }
    q += 0.015;
    let out = lp.tick(input(pitch_counts(q)));
    check(&out, &cal);
    assert_eq!(
        out.new_fault,
        Some(Fault {
            reason: FaultReason::Overspeed,
            detail: 0
        })
    );
    assert_eq!(out.currents_a, [0.0; 3]);
    assert_eq!(lp.tick(input(pitch_counts(q))).currents_a, [0.0; 3]);
}

#[test]
fn disarmed_gives_zero_current() {
    let bytes = flat_patch();
    let bank = parse(&bytes);
    let cal = patch_device();
    let mut lp = Rig::new(&bank).homed();
    let dev = lp.dev;
    for t in 0..200 {
        let out = lp.tick(LoopInput {
            encoder_counts: counts_for_insertion(&dev, 0.095 + 0.05e-3 * t as f32),
            overrun: false,
            // No host at all: not a fault while disarmed.
            link_silence_ticks: t,
            interlocks: Interlocks::default(),
        });
        check(&out, &cal);
        assert_eq!(out.state, State::Disarmed);
        assert_eq!(out.currents_a, [0.0; 3]);
    }
    // Pressed 5 mm: a force is computed but not applied.
    assert_eq!(lp.telemetry().contacts.len(), 7);
    assert_eq!(lp.telemetry().currents_a, [0.0; 3]);
    // Arm, then disarm: zero again.
    lp.arm().unwrap();
    let s = lp.counts(0.105);
    assert!(lp.tick(input(s)).currents_a[2] < 0.0);
    assert!(lp.disarm());
    assert_eq!(lp.tick(input(s)).currents_a, [0.0; 3]);
}

#[test]
fn link_silence_faults() {
    let bytes = flat_patch();
    let bank = parse(&bytes);
    let mut lp = Rig::new(&bank).homed().armed();
    lp.pressed(0.098, 0.05e-3, 100);
    let s = lp.counts(0.103);
    for silent in 0..=10 {
        let out = lp.tick(LoopInput {
            link_silence_ticks: silent,
            ..input(s)
        });
        assert_eq!(out.state, State::Armed);
        assert!(out.currents_a[2] < 0.0);
    }
    let out = lp.tick(LoopInput {
        link_silence_ticks: 11,
        ..input(s)
    });
    assert_eq!(out.state, State::Fault(FaultReason::LinkSilent));
    assert_eq!(out.new_fault.unwrap().reason, FaultReason::LinkSilent);
    assert_eq!(out.currents_a, [0.0; 3]);
    assert_eq!(lp.telemetry().fault, Some(FaultReason::LinkSilent));
    assert_eq!(lp.telemetry().state, bank_format::State::Fault);
    // Latched until cleared; then disarmed, and arming works again.
    assert_eq!(lp.tick(input(s)).currents_a, [0.0; 3]);
    assert_eq!(lp.tick(input(s)).new_fault, None);
    assert!(lp.clear_fault());
    assert_eq!(lp.tick(input(s)).state, State::Disarmed);
    lp.arm().unwrap();
    assert!(lp.tick(input(s)).currents_a[2] < 0.0);
}

#[test]
fn encoder_jump_faults() {
    let bytes = flat_patch();
    let bank = parse(&bytes);
    let cal = patch_device();
    let mut lp = Rig::new(&bank).homed().armed();
    lp.tick(input([0, 0, 0]));
    let out = lp.tick(input([i32::MAX, i32::MIN, 0]));
    check(&out, &cal);
    assert_eq!(out.state, State::Fault(FaultReason::EncoderJump));
    assert_eq!(out.currents_a, [0.0; 3]);
    let out = lp.tick(input([0, 0, 0]));
    assert_eq!(out.currents_a, [0.0; 3]);
}

#[test]
fn overrun_faults() {
    let bytes = flat_patch();
    let bank = parse(&bytes);
    let mut lp = Rig::new(&bank).homed().armed();
    let s = lp.counts(0.103);
    lp.tick(input(s));
    let out = lp.tick(LoopInput {
        overrun: true,
        ..input(s)
    });
    assert_eq!(out.state, State::Fault(FaultReason::Overrun));
    assert_eq!(out.currents_a, [0.0; 3]);
    assert_eq!(lp.counters().overruns, 1);
    assert_eq!(lp.telemetry().counters.overruns, 1);
}

#[test]
fn zero_encoders_rebases() {
    let bytes = flat_patch();
    let bank = parse(&bytes);
    let mut lp = Rig::new(&bank).homed();
    lp.tick(input([100_000, 0, 5]));
    lp.arm().unwrap();
    assert!(!lp.zero_encoders(), "refused while armed");
    lp.disarm();
    assert!(lp.zero_encoders());
    // The same raw counts are now the home pose, and the re-zero is not a jump.
    let out = lp.tick(input([100_000, 0, 5]));
    assert_eq!(out.state, State::Disarmed);
    let home = lp
        .device()
        .tip(&Joints::from_array(patch_device().home_joint));
    assert_eq!(out.tip_m, home);
}

#[test]
fn solve_failure_faults_with_zero_current() {
    // Every pair of nodes has an SPD 6 x 6 compliance (what the bank checks), but the
    // triangle's 9 x 9 `C_SS` (kernel [[1, -a, -a], [-a, 1, -a], [-a, -a, 1]], a = 0.6) is
    // indefinite: at the centroid `B C_SS B^T` is negative definite and the solve fails.
    let p = std::vec![[0.0, 0.0, 0.0], [0.01, 0.0, 0.0], [0.0, 0.01, 0.0]];
    let c = 1.0e-3;
    let diag =
        |v: f64| core::array::from_fn(|i| core::array::from_fn(|j| if i == j { v } else { 0.0 }));
    let b = BankBuilder {
        c_kk: std::vec![diag(c); 3],
        couplings: std::vec![
            (0, 1, diag(-0.6 * c)),
            (0, 2, diag(-0.6 * c)),
            (1, 2, diag(-0.6 * c)),
        ],
        mesh_ids: std::vec![0, 1, 2],
        triangles: std::vec![[0, 1, 2]],
        positions_m: p,
        grid_cell_size_m: 0.005,
        truncation_radius_m: 0.005,
        scene_id: 1,
        law: TissueLaw::chebyshev(&[2.6, 2.5, -0.1], [0.0, 5.0]).unwrap(),
        gravity: None,
        relaxation: None,
        samples: None,
        device: DeviceCalibration {
            fulcrum_m: [0.01 / 3.0, 0.01 / 3.0, 0.1],
            ..patch_device()
        },
    };
    let bytes = AlignedBytes::new(&b.build().unwrap());
    let bank = parse(&bytes);
    let cal = bank.device();
    let mut lp = Rig::new(&bank).homed().armed();
    let mut fault = None;
    for t in 0..=100 {
        let out = lp.at(0.098 + 0.04e-3 * t as f32);
        check(&out, cal);
        if matches!(out.contact, ContactState::Touching { .. }) {
            assert_eq!(out.tool_force_n, [0.0; 3]);
            assert_eq!(out.currents_a, [0.0; 3]);
            assert!(out.contact_nodes == 0);
            fault = fault.or(out.new_fault.map(|f| (f, out.solve_error)));
        }
    }
    let (f, e) = fault.expect("the press must fault");
    assert_eq!(f.reason, FaultReason::SolveFailed);
    assert!(
        matches!(
            e,
            Some(SolveError::NotPositiveDefinite | SolveError::IllConditioned { .. })
        ),
        "{e:?}"
    );
    assert_eq!(lp.telemetry().fault, Some(FaultReason::SolveFailed));
}
