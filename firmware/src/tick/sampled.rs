//! The sampled render (a bank with contact samples, `SPEC.md` "contact samples"): the patch
//! compliance `W` at the anchor, interpolated from the samples and factored every tick; the
//! tool force `W^-1 d` spread over the contact triangle's vertices for telemetry.

use crate::solve::SolveError;

/// The sampled contact at barycentric point `bary` of `triangle`: the bank's patch compliance
/// `W` there ([`bank_format::Samples::interpolate`]), and the triangle's vertices with positive
/// coordinates, weighted by them (normalised), to spread the tool force over for telemetry's
/// node forces. The rendered force is `W^-1 d`: the paper's eq. 8 for one rigid tool in
/// compliance form.
pub(super) fn sampled_compliance(
    samples: &bank_format::Samples<'_>,
    triangle: u32,
    nodes: [u16; 3],
    bary: [f32; 3],
) -> Result<([f32; 6], TriangleShares), SolveError> {
    let w = samples
        .interpolate(triangle as usize, bary)
        .ok_or(SolveError::NonFinite)?;
    let shares = TriangleShares::of(nodes, bary).ok_or(SolveError::BadWeights)?;
    Ok((w, shares))
}

/// A contact triangle's vertices with a positive barycentric coordinate and their shares of
/// the tool force ([`sampled_compliance`], [`triangle_solve`]).
pub(super) struct TriangleShares {
    nodes: [u16; 3],
    weights: [f32; 3],
    len: usize,
}

impl TriangleShares {
    /// The vertices of `nodes` with a positive (finite) barycentric coordinate, weighted by it,
    /// normalised to sum 1; `None` when none is positive.
    pub(super) fn of(nodes: [u16; 3], bary: [f32; 3]) -> Option<TriangleShares> {
        let mut shares = TriangleShares {
            nodes: [0; 3],
            weights: [0.0; 3],
            len: 0,
        };
        for (&k, &b) in nodes.iter().zip(&bary) {
            if b > 0.0
                && b.is_finite()
                && let (Some(nk), Some(wk)) = (
                    shares.nodes.get_mut(shares.len),
                    shares.weights.get_mut(shares.len),
                )
            {
                (*nk, *wk) = (k, b);
                shares.len += 1;
            }
        }
        let kept: f32 = shares.weights.iter().sum();
        if shares.len == 0 || !(kept > 0.0 && kept.is_finite()) {
            return None;
        }
        for x in shares.weights.iter_mut() {
            *x /= kept;
        }
        Some(shares)
    }

    /// The kept vertices and their weights.
    pub(super) fn split(&self) -> (&[u16], &[f32]) {
        (
            self.nodes.get(..self.len).unwrap_or(&[]),
            self.weights.get(..self.len).unwrap_or(&[]),
        )
    }
}

#[cfg(test)]
#[allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing,
    clippy::needless_range_loop
)]
mod tests {
    extern crate std;
    use bank_format::{AlignedBytes, Mode};
    use std::vec::Vec;

    use super::super::rig::{Rig, counts_for_insertion, input, parse};
    use crate::contact::ContactState;
    use crate::safety::State;

    /// On a bank with contact samples the tick renders `W(anchor)^-1 d` every contact tick
    /// (after the detecting one), whatever the anchor: checked in f64 against the fixture's `W`
    /// field along a press and slide, with the node forces the contact triangle's barycentric
    /// shares of it.
    #[test]
    fn a_sampled_bank_renders_w_inverse_d_at_the_anchor() {
        let bytes = crate::fixtures::sampled_patch();
        let bank = parse(&bytes);
        assert!(bank.samples().is_some());
        let mut lp = Rig::new(&bank).homed().in_mode(Mode::LinearLaw);
        let dev = lp.dev;
        let ws = |s: f32| counts_for_insertion(&dev, s);
        let mut checked = 0;
        for t in 0..=400 {
            let s = 0.095 + 0.03e-3 * t.min(300) as f32;
            let mut counts = ws(s);
            // Slide sideways once in.
            counts[0] += (t.max(250) - 250) * 3;
            let out = lp.tick(input(counts));
            let (
                ContactState::Touching {
                    anchor,
                    displacement,
                    bary,
                    ..
                },
                Some(origin),
            ) = (out.contact, out.patch)
            else {
                continue;
            };
            if out.contact_nodes == 0 {
                continue;
            }
            assert_eq!(origin.anchor, anchor);
            // Telemetry names the contact point for a display's fields.
            assert_eq!(
                lp.telemetry().contact_point,
                Some(bank_format::ContactPoint {
                    triangle: origin.triangle,
                    bary
                })
            );
            let w = crate::fixtures::sampled_w(anchor.map(f64::from));
            let want = crate::fixtures::gauss(
                w.iter().map(|r| r.to_vec()).collect(),
                displacement.iter().map(|&v| f64::from(v)).collect(),
            );
            // The force on the tool is minus the force on the tissue.
            let got = out.tool_force_n.map(|f| -f);
            let err = crate::fixtures::rel_err(&[got], &want);
            assert!(err < 1e-4, "tick {t}: {got:?} vs {want:?} ({err})");
            let mut sum = [0.0f32; 3];
            for c in lp.contacts() {
                let k = bank.triangles()[origin.triangle as usize]
                    .iter()
                    .position(|&v| v == c.node)
                    .unwrap();
                for i in 0..3 {
                    sum[i] += c.force_n[i];
                    assert!((c.force_n[i] - bary[k] * -out.tool_force_n[i]).abs() < 1e-6);
                }
            }
            assert!(crate::fixtures::rel_err(&[sum], &want) < 1e-4);
            checked += 1;
        }
        assert!(checked > 150, "{checked} contact ticks");
    }

    /// Presses and slides along the lattice's triangle edges never fault, at every lattice
    /// level a bank may have: the tip pressed (armed) onto points of the grid line x = 2 cm,
    /// which is the v1-v2 edge of a column of the patch's triangles and passes through their
    /// vertices, and slid along it at depth, renders `W(anchor)^-1 d` with the fixture's
    /// (linear, so exactly interpolated) `W` every contact tick, never `SolveFailed`.
    #[test]
    fn edge_and_vertex_contacts_render_at_every_lattice_level() {
        for level in 1..=bank_format::MAX_SAMPLE_LEVEL {
            let bytes = crate::fixtures::sampled_patch_at_level(level, crate::fixtures::sampled_w);
            let bank = parse(&bytes);
            let mut lp = Rig::new(&bank).homed().in_mode(Mode::LinearLaw);
            lp.tick(input([0; 3]));
            lp.arm().unwrap();
            let dev = lp.dev;
            // Tip at x = 2 cm + dx (yaw), y (pitch), insertion s; straight moves between
            // waypoints, 20 um a tick at most.
            let counts = |[dx, y, s]: [f32; 3]| {
                let mut c = counts_for_insertion(&dev, s);
                c[0] = ((y - 0.02) / 0.1 / dev.joint_per_count()[0]).round() as i32;
                c[1] = (-dx / 0.1 / dev.joint_per_count()[1]).round() as i32;
                c
            };
            let mut waypoints: Vec<[f32; 3]> = std::vec![[0.0, 0.02, 0.05]];
            // Presses 3 mm deep at vertices (y = 1, 2, 3 cm) of the grid line x = 2 cm, the
            // v1-v2 edge of a column of triangles, and between them on it.
            for y in [0.01, 0.0125, 0.02, 0.0233, 0.03, 0.0351] {
                waypoints.extend([[0.0, y, 0.097], [0.0, y, 0.103], [0.0, y, 0.097]]);
            }
            // A slide along that edge at 3 mm depth, through the vertices; then along the
            // patch's sides x = 0 and x = 4 cm (the latter the v1-v2 edges of its column of
            // triangles) with the tip 1 mm beyond, so that the anchor is held on the boundary.
            waypoints.extend([
                [0.0, 0.005, 0.097],
                [0.0, 0.005, 0.103],
                [0.0, 0.035, 0.103],
            ]);
            for dx in [-0.021, 0.021] {
                waypoints.extend([
                    [0.0, 0.035, 0.097],
                    [dx, 0.035, 0.097],
                    [dx, 0.035, 0.103],
                    [dx, 0.005, 0.103],
                    [dx, 0.005, 0.097],
                    [0.0, 0.005, 0.097],
                ]);
            }
            let mut contact_ticks = 0;
            for pair in waypoints.windows(2) {
                let (a, b) = (pair[0], pair[1]);
                let len = (0..3).map(|i| (b[i] - a[i]).abs()).fold(0.0, f32::max);
                let n = (len / 20e-6).ceil().max(1.0) as u32;
                for k in 1..=n {
                    let f = k as f32 / n as f32;
                    let out = lp.tick(input(counts(core::array::from_fn(|i| {
                        a[i] + f * (b[i] - a[i])
                    }))));
                    assert_eq!(
                        (out.state, out.new_fault, out.solve_error),
                        (State::Armed, None, None),
                        "level {level}: {out:?}"
                    );
                    let ContactState::Touching {
                        anchor,
                        displacement,
                        ..
                    } = out.contact
                    else {
                        continue;
                    };
                    if out.contact_nodes == 0 {
                        continue;
                    }
                    let w = crate::fixtures::sampled_w(anchor.map(f64::from));
                    let want = crate::fixtures::gauss(
                        w.iter().map(|r| r.to_vec()).collect(),
                        displacement.iter().map(|&v| f64::from(v)).collect(),
                    );
                    let got = out.tool_force_n.map(|f| -f);
                    let err = crate::fixtures::rel_err(&[got], &want);
                    assert!(err < 1e-4, "level {level}: {got:?} vs {want:?}");
                    contact_ticks += 1;
                }
            }
            assert!(contact_ticks > 3_000, "level {level}: {contact_ticks}");
        }
    }

    /// What the reader accepts, the tick can factor (`bank_format::MIN_PIVOT_REL`, one margin
    /// for both): a sampled bank whose `W` is SPD everywhere but, for y < 2 cm, too
    /// ill-conditioned for the tick's solve (pivot ratio 1e-6) is refused at parse, naming a
    /// triangle there and its sample; with the ratio at 2.5e-5 (within the reader's margin)
    /// presses and a slide over that side, armed, never fault and render `W^-1 d`.
    #[test]
    fn a_sampled_bank_the_reader_accepts_never_fails_the_solve() {
        let patch = |zz: f64| {
            crate::fixtures::sampled_patch_builder(2, move |x| {
                let zz = if x[1] < 0.02 { zz } else { 0.1 };
                [[0.05, 0.0, 0.0], [0.0, 0.05, 0.0], [0.0, 0.0, 0.05 * zz]]
            })
            .build()
        };
        // The first triangle (cell (0, 0)) is refused; its samples are all ill-conditioned.
        let refused = patch(1.0e-6).map(|_| ());
        assert!(
            matches!(
                refused,
                Err(bank_format::BuildError::Rejected(
                    bank_format::BankError::SampleIllConditioned { triangle: 0, .. }
                ))
            ),
            "{refused:?}"
        );
        let bytes = AlignedBytes::new(&patch(2.5e-5).unwrap());
        let bank = parse(&bytes);
        let mut lp = Rig::new(&bank).homed().in_mode(Mode::LinearLaw);
        lp.tick(input([0; 3]));
        lp.arm().unwrap();
        let dev = lp.dev;
        // The fulcrum is 10 cm above the patch's centre (y = 2 cm): pitch moves the tip along
        // y, about 0.1 m per rad.
        let at = |y: f32, s: f32| {
            let mut c = counts_for_insertion(&dev, s);
            c[0] = ((y - 0.02) / 0.1 / dev.joint_per_count()[0]).round() as i32;
            c
        };
        // Down from home to 3 mm above the patch, over to y = 1.2 cm, in, and a slide.
        let mut path: Vec<[i32; 3]> = (0..=2_350)
            .map(|t| at(0.02, 0.05 + 20.0e-6 * t as f32))
            .collect();
        path.extend((0..=400).map(|t| {
            at(
                0.012 * (t as f32 / 400.0) + 0.02 * (1.0 - t as f32 / 400.0),
                0.097,
            )
        }));
        path.extend((0..=120).map(|t| at(0.012, 0.097 + 0.05e-3 * t as f32)));
        path.extend((0..=900).map(|t| at(0.012 + 20.0e-6 * t as f32, 0.103)));
        let mut pressed = 0;
        for (t, &counts) in path.iter().enumerate() {
            let out = lp.tick(input(counts));
            assert_eq!(
                (out.state, out.new_fault, out.solve_error),
                (State::Armed, None, None),
                "{t}: {out:?}"
            );
            if out.contact_nodes > 0 && out.tool_force_n[2] > 0.0 {
                pressed += 1;
            }
        }
        assert!(pressed > 900, "{pressed}");
    }
}
