//! The instrument: `[tool]`, `[device]` (trocar pose, joints, motors, safety thresholds, link
//! timeout, friction offsets) and `[gravity]`.

use super::{Ctx, finite, positive3, range, unit};
use crate::scene::schema::{RawDevice, RawGravity, RawTool};
use crate::scene::{DEFAULT_MAX_TIP_SPEED_M_S, DEFAULT_SPEED_LEVER_M, SceneError};
use bank_format::DeviceCalibration;

/// `[tool]`: `tip_radius_m` in [0, 0.05]; returns it.
pub(super) fn parse_tool(ctx: &Ctx, tool: &RawTool) -> Result<f64, SceneError> {
    let tip = *tool.tip_radius_m.get_ref();
    if !(0.0..=0.05).contains(&tip) {
        return Err(ctx.err(
            tool.tip_radius_m.span(),
            "tool.tip_radius_m",
            format!("must lie in [0, 0.05] m, got {tip}"),
        ));
    }
    Ok(tip)
}

/// `[device]` (all but `friction_offset`, see [`parse_friction_offset`]): finite fulcrum,
/// orthonormal unit axes, non-empty joint ranges (pitch inside (-pi/2, pi/2), yaw inside
/// [-pi, pi], insertion >= 0), `home` inside the ranges (default: 0 clamped into the pitch and yaw
/// ranges, minimum insertion), counts > 0, non-zero finite gear ratios, torque constants > 0,
/// current limits in (0, 20], `max_force_n` in (0, 50], the speed thresholds
/// ([`parse_speed_limits`]); then [`bank_format::validate_device`]. `tip` is the tool's tip
/// radius, m.
pub(super) fn parse_device(
    ctx: &Ctx,
    d: &RawDevice,
    tip: f64,
) -> Result<DeviceCalibration, SceneError> {
    finite(ctx, &d.fulcrum_m, "device.fulcrum_m")?;
    let shaft = unit(ctx, &d.shaft_axis, "device.shaft_axis")?;
    let pitch_axis = unit(ctx, &d.pitch_axis, "device.pitch_axis")?;
    let yaw_axis = unit(ctx, &d.yaw_axis, "device.yaw_axis")?;
    let dot = |a: [f64; 3], b: [f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    for (a, b, key, span) in [
        (shaft, pitch_axis, "device.pitch_axis", d.pitch_axis.span()),
        (shaft, yaw_axis, "device.yaw_axis", d.yaw_axis.span()),
        (pitch_axis, yaw_axis, "device.yaw_axis", d.yaw_axis.span()),
    ] {
        if dot(a, b).abs() > 1e-3 {
            return Err(ctx.err(
                span,
                key,
                "shaft_axis, pitch_axis and yaw_axis must be pairwise orthogonal",
            ));
        }
    }
    let pitch = range(ctx, &d.pitch_range_rad, "device.pitch_range_rad")?;
    let yaw = range(ctx, &d.yaw_range_rad, "device.yaw_range_rad")?;
    let ins = range(ctx, &d.insertion_range_m, "device.insertion_range_m")?;
    let half_pi = std::f64::consts::FRAC_PI_2;
    if pitch[0] <= -half_pi || pitch[1] >= half_pi {
        return Err(ctx.err(
            d.pitch_range_rad.span(),
            "device.pitch_range_rad",
            "pitch must stay inside (-pi/2, pi/2)",
        ));
    }
    if yaw[0] < -std::f64::consts::PI || yaw[1] > std::f64::consts::PI {
        return Err(ctx.err(
            d.yaw_range_rad.span(),
            "device.yaw_range_rad",
            "yaw must stay inside [-pi, pi]",
        ));
    }
    if ins[0] < 0.0 {
        return Err(ctx.err(
            d.insertion_range_m.span(),
            "device.insertion_range_m",
            "insertion must be >= 0 m",
        ));
    }
    let home = match &d.home {
        Some(h) => {
            finite(ctx, h, "device.home")?;
            let h3 = *h.get_ref();
            for (j, r) in [pitch, yaw, ins].iter().enumerate() {
                if !(r[0] <= h3[j] && h3[j] <= r[1]) {
                    return Err(ctx.err(
                        h.span(),
                        "device.home",
                        format!("joint {j} home {} is outside [{}, {}]", h3[j], r[0], r[1]),
                    ));
                }
            }
            h3
        }
        None => [
            0.0f64.clamp(pitch[0], pitch[1]),
            0.0f64.clamp(yaw[0], yaw[1]),
            ins[0],
        ],
    };
    if d.counts_per_rev.get_ref().contains(&0) {
        return Err(ctx.err(
            d.counts_per_rev.span(),
            "device.counts_per_rev",
            "counts per revolution must be > 0",
        ));
    }
    finite(ctx, &d.gear_ratio, "device.gear_ratio")?;
    if d.gear_ratio.get_ref().iter().any(|g| g.abs() < 1e-6) {
        return Err(ctx.err(
            d.gear_ratio.span(),
            "device.gear_ratio",
            "gear ratios must be non-zero (|ratio| >= 1e-6; the sign is the motor direction)",
        ));
    }
    let kt = positive3(
        ctx,
        &d.torque_constant_nm_per_a,
        "device.torque_constant_nm_per_a",
        // The largest DC motors of haptic devices have a few tenths of N m/A.
        10.0,
    )?;
    let imax = positive3(ctx, &d.current_limit_a, "device.current_limit_a", 20.0)?;
    let fmax = *d.max_force_n.get_ref();
    if !(fmax > 0.0 && fmax <= 50.0) {
        return Err(ctx.err(
            d.max_force_n.span(),
            "device.max_force_n",
            format!("must lie in (0, 50] N, got {fmax}"),
        ));
    }
    let (tip_speed, joint_speed) = parse_speed_limits(ctx, d)?;
    let link_timeout_ms = parse_link_timeout(ctx, d)?;
    let f32s = |a: [f64; 3]| a.map(|x| x as f32);
    let device = DeviceCalibration {
        fulcrum_m: f32s(*d.fulcrum_m.get_ref()),
        shaft_axis: f32s(shaft),
        pitch_axis: f32s(pitch_axis),
        yaw_axis: f32s(yaw_axis),
        joint_min: f32s([pitch[0], yaw[0], ins[0]]),
        joint_max: f32s([pitch[1], yaw[1], ins[1]]),
        home_joint: f32s(home),
        counts_per_rev: *d.counts_per_rev.get_ref(),
        transmission: f32s(*d.gear_ratio.get_ref()),
        torque_constant_nm_per_a: kt,
        current_limit_a: imax,
        max_force_n: fmax as f32,
        tip_radius_m: tip as f32,
        max_tip_speed_m_s: tip_speed as f32,
        max_joint_speed: f32s(joint_speed),
        link_timeout_ms,
    };
    bank_format::validate_device(&device)
        .map_err(|e| ctx.err(d.fulcrum_m.span(), "device", e.to_string()))?;
    Ok(device)
}

/// `device.link_timeout_ms` (optional, default [`bank_format::DEFAULT_LINK_TIMEOUT_MS`]): a whole
/// number of ms in [`bank_format::LINK_TIMEOUT_MS_MIN`]`..=`[`bank_format::LINK_TIMEOUT_MS_MAX`]
/// (`bank-format` `SPEC.md`, "Link timeout").
pub(super) fn parse_link_timeout(ctx: &Ctx, d: &RawDevice) -> Result<u32, SceneError> {
    let Some(v) = &d.link_timeout_ms else {
        return Ok(bank_format::DEFAULT_LINK_TIMEOUT_MS);
    };
    let (lo, hi) = (
        bank_format::LINK_TIMEOUT_MS_MIN,
        bank_format::LINK_TIMEOUT_MS_MAX,
    );
    let ms = *v.get_ref();
    if ms.fract() == 0.0 && ms >= f64::from(lo) && ms <= f64::from(hi) {
        // Whole and within [5, 100]: exact as u32.
        return Ok(ms as u32);
    }
    Err(ctx.err(
        v.span(),
        "device.link_timeout_ms",
        format!(
            "must be a whole number of ms in [{lo}, {hi}], got {ms} (the host's heartbeat comes \
             every 2 ms; `host bench heartbeat` measures how late it can be)"
        ),
    ))
}

/// `device.max_tip_speed_m_s` (optional, default [`DEFAULT_MAX_TIP_SPEED_M_S`]) finite and > 0;
/// `device.max_joint_speed` (optional, default derived from the tip's, see
/// [`DEFAULT_SPEED_LEVER_M`]) finite, > 0 and below the firmware's encoder-jump speeds
/// ([`firmware::safety::DEFAULT_JUMP_SPEED`]): a move faster than those counts as an encoder
/// glitch, so a threshold at or above them would never report an overspeed. Returns the tip's
/// (m/s) and the joints' (rad/s, rad/s, m/s).
pub(super) fn parse_speed_limits(ctx: &Ctx, d: &RawDevice) -> Result<(f64, [f64; 3]), SceneError> {
    let jump = firmware::safety::DEFAULT_JUMP_SPEED.map(f64::from);
    let tip = match &d.max_tip_speed_m_s {
        Some(v) => {
            let x = *v.get_ref();
            if !(x.is_finite() && x > 0.0) {
                return Err(ctx.err(
                    v.span(),
                    "device.max_tip_speed_m_s",
                    format!("must be > 0 m/s, got {x}"),
                ));
            }
            x
        }
        None => DEFAULT_MAX_TIP_SPEED_M_S,
    };
    let below_jump = |v: [f64; 3]| (0..3).all(|j| v[j] < jump[j]);
    let joints = match &d.max_joint_speed {
        Some(v) => {
            finite(ctx, v, "device.max_joint_speed")?;
            let x = *v.get_ref();
            if !x.iter().all(|&s| s > 0.0) {
                return Err(ctx.err(
                    v.span(),
                    "device.max_joint_speed",
                    format!("every value must be > 0 (rad/s, rad/s, m/s), got {x:?}"),
                ));
            }
            if !below_jump(x) {
                return Err(ctx.err(
                    v.span(),
                    "device.max_joint_speed",
                    format!(
                        "{x:?} must stay below the firmware's encoder-jump speeds {jump:?} \
                         (rad/s, rad/s, m/s), above which a move counts as an encoder glitch"
                    ),
                ));
            }
            x
        }
        None => {
            let derived = [
                tip / DEFAULT_SPEED_LEVER_M,
                tip / DEFAULT_SPEED_LEVER_M,
                tip,
            ];
            if !below_jump(derived) {
                let span = d.max_tip_speed_m_s.as_ref().map_or(0..0, |v| v.span());
                return Err(ctx.err(
                    span,
                    "device.max_tip_speed_m_s",
                    format!(
                        "the default device.max_joint_speed derived from it, {derived:?}, is not \
                         below the firmware's encoder-jump speeds {jump:?}: give \
                         device.max_joint_speed"
                    ),
                ));
            }
            derived
        }
    };
    Ok((tip, joints))
}

/// `device.friction_offset` (optional): finite, default 0. Checked after `[law]` and
/// `[display_law]`, as it always was, so a file with several errors reports the same one.
pub(super) fn parse_friction_offset(ctx: &Ctx, d: &RawDevice) -> Result<[f64; 3], SceneError> {
    match &d.friction_offset {
        Some(f) => {
            finite(ctx, f, "device.friction_offset")?;
            Ok(*f.get_ref())
        }
        None => Ok([0.0; 3]),
    }
}

/// `[gravity]`: eight finite coefficients, each within the bank's
/// [`bank_format::GRAVITY_COEFF_MAX`] (N m or N).
pub(super) fn parse_gravity(
    ctx: &Ctx,
    g: &RawGravity,
) -> Result<[f64; bank_format::GRAVITY_COEFFS], SceneError> {
    finite(ctx, &g.coeffs, "gravity.coeffs")?;
    let c = *g.coeffs.get_ref();
    let max = f64::from(bank_format::GRAVITY_COEFF_MAX);
    if let Some(i) = c.iter().position(|v| v.abs() > max) {
        return Err(ctx.err(
            g.coeffs.span(),
            "gravity.coeffs",
            format!(
                "coefficient {i} is {}: beyond +-{max} (N m or N), a unit or sign error",
                c[i]
            ),
        ));
    }
    Ok(c)
}
