//! Contact detection and tracking on a curved patch: a spherical cap (radius 5 cm, 6 x 6 cm
//! footprint, 5 mm spacing) built here. Every tick checks no NaN, barycentric coordinates in
//! `[0, 1]` summing to 1, `displacement = tip - anchor`, the anchor on its triangle (or, while
//! a slide's walk is under way, in its plane between it and the tip), and the release rule.

#![allow(clippy::needless_range_loop)]

use bank_format::{AlignedBytes, Bank};
use firmware::contact::{ContactState, ContactTracker};

const R: f64 = 0.05;
const H: f64 = 0.005;
const N: usize = 13;

fn cap_z(x: f64, y: f64) -> f64 {
    (R * R - x * x - y * y).sqrt() - R
}

/// Centre of the sphere.
const C: [f32; 3] = [0.0, 0.0, -R as f32];

fn cap() -> AlignedBytes {
    let mut p = Vec::new();
    for j in 0..N {
        for i in 0..N {
            let (x, y) = (-0.03 + H * i as f64, -0.03 + H * j as f64);
            p.push([x, y, cap_z(x, y)]);
        }
    }
    let id = |i: usize, j: usize| (i + N * j) as u32;
    let mut triangles = Vec::new();
    for j in 0..N - 1 {
        for i in 0..N - 1 {
            let (a, b, c, d) = (id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1));
            // Alternate the diagonal so both orientations are exercised.
            if (i + j) % 2 == 0 {
                triangles.push([a, b, c]);
                triangles.push([a, c, d]);
            } else {
                triangles.push([a, b, d]);
                triangles.push([b, c, d]);
            }
        }
    }
    let b = firmware::fixtures::surface_builder(
        p,
        triangles,
        0.012,
        H,
        firmware::fixtures::bench_device([0.0, 0.0, 0.1]),
    );
    AlignedBytes::new(&b.build().expect("valid cap bank"))
}

/// The point at radius `r` from the centre above `(x, y)` on the sphere.
fn at_radius(x: f32, y: f32, r: f32) -> [f32; 3] {
    let surf = [x, y, cap_z(f64::from(x), f64::from(y)) as f32];
    let d: [f32; 3] = std::array::from_fn(|i| surf[i] - C[i]);
    let l = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
    std::array::from_fn(|i| C[i] + d[i] * r / l)
}

fn normal(bank: &Bank, nodes: [u16; 3]) -> [f32; 3] {
    let p = |k: u16| bank.positions()[usize::from(k)];
    let (a, b, c) = (p(nodes[0]), p(nodes[1]), p(nodes[2]));
    let e1: [f32; 3] = std::array::from_fn(|i| b[i] - a[i]);
    let e2: [f32; 3] = std::array::from_fn(|i| c[i] - a[i]);
    [
        e1[1] * e2[2] - e1[2] * e2[1],
        e1[2] * e2[0] - e1[0] * e2[2],
        e1[0] * e2[1] - e1[1] * e2[0],
    ]
}

/// Check every invariant of one tick's state; returns the triangle if touching.
fn check(bank: &Bank, s: &ContactState, tip: [f32; 3]) -> Option<u32> {
    let ContactState::Touching {
        triangle,
        nodes,
        bary,
        anchor,
        displacement,
    } = *s
    else {
        return None;
    };
    assert_eq!(bank.triangles()[triangle as usize], nodes);
    for k in bary {
        assert!(
            k.is_finite() && (-1.0e-5..=1.0 + 1.0e-5).contains(&k),
            "{bary:?}"
        );
    }
    assert!((bary.iter().sum::<f32>() - 1.0).abs() < 1.0e-5, "{bary:?}");
    let p = |k: u16| bank.positions()[usize::from(k)];
    let n = normal(bank, nodes);
    let on: [f32; 3] = std::array::from_fn(|i| (0..3).map(|v| bary[v] * p(nodes[v])[i]).sum());
    let dist = |a: [f32; 3], b: [f32; 3]| (0..3).map(|i| (a[i] - b[i]).powi(2)).sum::<f32>().sqrt();
    for i in 0..3 {
        assert!(anchor[i].is_finite() && displacement[i].is_finite());
        assert!((displacement[i] - (tip[i] - anchor[i])).abs() < 1.0e-7);
    }
    // On its triangle; or, while a slide's walk is under way (`firmware::contact`, at most
    // `SLIDE_STEPS_PER_TICK` steps a tick), the slide's target: in the plane of the triangle
    // the slide started on (whose point `on` is), no farther from `on` than the tip's
    // tangential distance plus the stick cone's allowance (20% of the depth).
    let off = dist(on, anchor);
    if off >= 1.0e-6 {
        let nn = dist(n, [0.0; 3]);
        let height: f32 = (0..3).map(|i| (anchor[i] - on[i]) * n[i]).sum::<f32>() / nn;
        assert!(
            height.abs() < 1.0e-6 && off <= 1.2 * dist(tip, on) + 1.0e-6,
            "anchor off its triangle by {off}, the tip {} from its point",
            dist(tip, on)
        );
    }
    let dn: f32 = (0..3).map(|i| displacement[i] * n[i]).sum();
    assert!(dn <= 0.0, "a pulling contact was kept");
    Some(triangle)
}

#[test]
fn long_slide_on_a_spherical_cap() {
    let bytes = cap();
    let bank = Bank::parse(&bytes).unwrap();
    let mut tr = ContactTracker::new();
    let rf = R as f32;
    // Approach from above, press 2 mm along the radius, then slide along a loop at that depth.
    let start = at_radius(-0.022, -0.018, rf + 0.004);
    let mut prev = start;
    let mut tips = vec![at_radius(-0.022, -0.018, rf + 0.001)];
    tips.push(at_radius(-0.022, -0.018, rf - 0.002));
    let steps = 600;
    for i in 1..=steps {
        let u = i as f32 / steps as f32 * std::f32::consts::TAU;
        // A loop across most of the cap, about 14 cm long: ~0.25 mm per tick.
        let (x, y) = (
            -0.022 * u.cos() + 0.004 * (3.0 * u).sin(),
            -0.018 * u.cos() + 0.02 * u.sin(),
        );
        tips.push(at_radius(x, y, rf - 0.002));
    }
    let mut seen = Vec::new();
    for (tick, &tip) in tips.iter().enumerate() {
        let s = tr.update(&bank, prev, tip);
        let tri = check(&bank, &s, tip);
        if tick == 0 {
            assert_eq!(tri, None);
        } else {
            let tri = tri.unwrap_or_else(|| panic!("contact lost at tick {tick}, tip {tip:?}"));
            if seen.last() != Some(&tri) {
                seen.push(tri);
            }
        }
        prev = tip;
    }
    assert!(seen.len() > 30, "only {} triangles visited", seen.len());
    // Pull out radially: still touching while below, free once clearly outside.
    let (x, y) = (-0.022f32, -0.018f32);
    let mut released = false;
    for i in 0..=40 {
        let tip = at_radius(x, y, rf - 0.002 + 0.0001 * i as f32);
        let s = tr.update(&bank, prev, tip);
        let touching = check(&bank, &s, tip).is_some();
        if i <= 15 {
            assert!(touching, "released too early at depth step {i}");
        }
        if !touching {
            released = true;
        }
        if released {
            assert!(!touching, "re-entered without coming back in");
        }
        prev = tip;
    }
    assert!(released);
}

#[test]
fn strikes_grazing_and_from_behind_on_the_cap() {
    let bytes = cap();
    let bank = Bank::parse(&bytes).unwrap();
    let rf = R as f32;
    // 5 cm strikes in one tick from several directions: detected at the surface.
    for (x, y) in [
        (0.0f32, 0.0f32),
        (0.017, -0.011),
        (-0.024, 0.021),
        (0.003, 0.026),
    ] {
        let from = at_radius(x, y, rf + 0.05);
        let to = at_radius(x, y, rf - 0.003);
        let mut tr = ContactTracker::new();
        let s = tr.update(&bank, from, to);
        check(&bank, &s, to).unwrap_or_else(|| panic!("tunnelled at {x}, {y}"));
        let ContactState::Touching { anchor, .. } = s else {
            unreachable!()
        };
        let r: f32 = (0..3)
            .map(|i| (anchor[i] - C[i]).powi(2))
            .sum::<f32>()
            .sqrt();
        // On the chordal mesh: between the sphere and its sag (< 0.1 mm for 5 mm chords).
        assert!(r <= rf + 1.0e-6 && r > rf - 2.0e-4, "{r}");
    }
    // Tangent chords above the surface: never a contact.
    let mut tr = ContactTracker::new();
    for i in 0..40 {
        let a = at_radius(-0.02 + 0.001 * i as f32, 0.004, rf + 1.0e-4);
        let b = at_radius(-0.019 + 0.001 * i as f32, 0.004, rf + 1.0e-4);
        let s = tr.update(&bank, a, b);
        assert_eq!(s, ContactState::Free, "spurious hit at step {i}");
    }
    // From behind: starting inside and leaving, or moving inside.
    for (x, y) in [(0.0f32, 0.0f32), (0.012, -0.02)] {
        let mut tr = ContactTracker::new();
        let inside = at_radius(x, y, rf - 0.003);
        let outside = at_radius(x, y, rf + 0.003);
        assert_eq!(tr.update(&bank, inside, outside), ContactState::Free);
        let mut tr = ContactTracker::new();
        let deeper = at_radius(x + 0.004, y, rf - 0.006);
        assert_eq!(tr.update(&bank, inside, deeper), ContactState::Free);
    }
}

/// Where the random walk's tip is, from the sphere alone (independent of the tracker): a tick
/// clearly above the sphere must be free; a tick clearly below the meshed cap, reached from
/// above without leaving the footprint, must touch (a missed contact fails here), and so must
/// every later one while the tip stays below and inside.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Expect {
    /// Clearly above the surface: free.
    Out,
    /// Pressed in from above within the footprint: touching.
    In,
    /// Below the surface's level after leaving the footprint (entered from the side or from
    /// behind, where the mesh has no surface): either.
    Either,
}

#[test]
fn random_walk_keeps_invariants() {
    let bytes = cap();
    let bank = Bank::parse(&bytes).unwrap();
    let mut tr = ContactTracker::new();
    let mut rng = firmware::fixtures::SplitMix64::new(0x2545_f491_4f6c_dd1d);
    let mut rnd = move || rng.unit_f32() - 0.5;
    let rf = R as f32;
    // The mesh's triangles lie up to 0.324 mm inside the sphere: the 5 mm grid is regular in
    // x and y, so at the footprint's corners, where the sphere is steep, a cell's diagonal spans
    // about 11 mm of it (the largest gap, sampled on a 21-point lattice of every triangle, is in
    // the corner cell). A tip deeper than that is under the mesh. The footprint ends at +-30 mm,
    // kept 2 mm clear of.
    let (sag, above, edge) = (3.5e-4f32, 3.0e-4f32, 0.028f32);
    let mut prev = at_radius(0.0, 0.0, rf + 0.003);
    let (mut x, mut y, mut r) = (0.0f32, 0.0f32, rf + 0.003);
    let mut expect = Expect::Out;
    let (mut touching_ticks, mut pressed_in) = (0, 0);
    for tick in 0..20_000 {
        x = (x + 0.002 * rnd()).clamp(-0.035, 0.035);
        y = (y + 0.002 * rnd()).clamp(-0.035, 0.035);
        r = (r + 0.001 * rnd()).clamp(rf - 0.006, rf + 0.006);
        let tip = at_radius(x, y, r);
        let s = tr.update(&bank, prev, tip);
        let touching = check(&bank, &s, tip).is_some();
        let inside = x.abs() < edge && y.abs() < edge;
        // Above the sphere is above the mesh only over the footprint: past its edge, a slide
        // that left the mesh keeps the plane of its last triangle, which the sphere does not
        // follow.
        if r > rf + above && inside {
            expect = Expect::Out;
        } else if !inside {
            expect = Expect::Either;
        } else if r < rf - sag && expect == Expect::Out {
            expect = Expect::In;
            pressed_in += 1;
        }
        match expect {
            Expect::Out if r > rf + above && inside => {
                assert!(
                    !touching,
                    "a contact above the surface at tick {tick}, tip {tip:?}"
                )
            }
            Expect::In if r < rf - sag => {
                assert!(
                    touching,
                    "missed or lost contact at tick {tick}, tip {tip:?}, {} mm under the sphere",
                    1e3 * (rf - r)
                )
            }
            _ => {}
        }
        if touching {
            touching_ticks += 1;
        }
        prev = tip;
    }
    // The walk presses in from above many times, and touches for a good share of it.
    assert!(pressed_in > 20, "{pressed_in}");
    assert!(touching_ticks > 1000, "{touching_ticks}");
}
