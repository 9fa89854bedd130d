//! The large-deformation reference (`fem::hyperelastic`) against independent references: the
//! linear 10-node solve at small strain, the closed form of homogeneous uniaxial compression,
//! hand-computed element inversion, and (ignored by default: `--ignored --nocapture`) a
//! refinement series with its Richardson error estimate and the 80 mm gel cube's timing.

use fem::compliance::solve_prescribed;
use fem::elasticity::Material;
use fem::elasticity::quadratic::EDGES;
use fem::hyperelastic::{
    HyperError, HyperelasticBody, NewtonOptions, Prescribed, Volumetric, solve, uniaxial_stress,
};
use fem::mesh::structured::box_mesh;
use std::time::Instant;

const E: f64 = 5000.0;

fn max_abs(v: impl IntoIterator<Item = f64>) -> f64 {
    v.into_iter().fold(0.0, |m, x| m.max(x.abs()))
}

/// Bonded platens on a cube of side `l`: bottom held, top moved by `top` (all components).
fn bonded(body: &HyperelasticBody, l: f64, top: [f64; 3]) -> Prescribed {
    let mut p = Prescribed::none(body.nodes());
    p.set_where(body.positions(), |x| x[2] <= 1e-12 * l, [Some(0.0); 3])
        .unwrap();
    p.set_where(
        body.positions(),
        |x| x[2] >= l * (1.0 - 1e-12),
        top.map(Some),
    )
    .unwrap();
    p
}

/// Small strain: the neo-Hookean solve equals the linear 10-node solve with the same
/// prescribed displacements (displacements and reactions), compressible and nearly
/// incompressible.
#[test]
fn small_strain_equals_the_linear_quadratic_solve() {
    let l = 0.02;
    let strain = 1e-7;
    for nu in [0.3, 0.499] {
        let mesh = box_mesh([l; 3], [2, 2, 2]);
        let body = HyperelasticBody::new(&mesh, Material::new(E, nu).unwrap()).unwrap();
        // Compression with a sideways shift of the top platen: bending and shear, not a
        // homogeneous field.
        let p = bonded(&body, l, [0.4 * strain * l, 0.0, -strain * l]);
        let sol = solve(&body, &p, &NewtonOptions::default(), &mut |_| {}).unwrap();
        let (u_lin, f_lin) =
            solve_prescribed(body.quadratic(), &p.fixed_set(), &p.field()).unwrap();
        let du = max_abs(sol.u.iter().zip(&u_lin).map(|(a, b)| a - b)) / max_abs(u_lin.clone());
        let held: Vec<usize> = (0..3 * body.nodes())
            .filter(|&d| p.get(d / 3, d % 3).is_some())
            .collect();
        let df = max_abs(held.iter().map(|&d| sol.forces[d] - f_lin[d]))
            / max_abs(held.iter().map(|&d| f_lin[d]));
        println!("nu {nu}: relative difference u {du:.2e}, reactions {df:.2e}");
        assert!(du < 1e-6 && df < 1e-6, "nu {nu}: u {du:e}, f {df:e}");
    }
}

/// Homogeneous uniaxial compression to 30 % between frictionless platens (rollers on three
/// faces, the top face's normal displacement prescribed): lateral stretch and platen force
/// against the closed form of the same strain energy.
#[test]
fn uniaxial_compression_to_30_percent_matches_the_closed_form() {
    let l = 0.02;
    let s = 0.7;
    for (nu, volumetric) in [
        (0.3, Volumetric::Pointwise),
        (0.499, Volumetric::Pointwise),
        (0.499, Volumetric::ElementMean),
    ] {
        let material = Material::new(E, nu).unwrap();
        let mesh = box_mesh([l; 3], [2, 2, 2]);
        let body = HyperelasticBody::with_volumetric(&mesh, material, volumetric).unwrap();
        let x = body.positions();
        let mut p = Prescribed::none(body.nodes());
        for axis in 0..3 {
            let mut c = [None; 3];
            c[axis] = Some(0.0);
            p.set_where(x, |q| q[axis] <= 1e-12 * l, c).unwrap();
        }
        let top: Vec<usize> = (0..x.len())
            .filter(|&i| x[i][2] >= l * (1.0 - 1e-12))
            .collect();
        for &i in &top {
            p.set(i, 2, (s - 1.0) * l).unwrap();
        }
        let mut reports = Vec::new();
        let sol = solve(&body, &p, &NewtonOptions::default(), &mut |r| {
            reports.push(r.clone())
        })
        .unwrap();
        let (lambda, mu) = material.lame();
        let (lat, p33) = uniaxial_stress(lambda, mu, s);
        let force = sol.reaction(top.iter().copied(), 2);
        let expected = p33 * l * l;
        let side: Vec<usize> = (0..x.len())
            .filter(|&i| x[i][0] >= l * (1.0 - 1e-12))
            .collect();
        let stretch =
            1.0 + side.iter().map(|&i| sol.u[3 * i]).sum::<f64>() / (side.len() as f64 * l);
        println!(
            "nu {nu} {volumetric:?}: force {force:.6} N (closed form {expected:.6}), lateral stretch {stretch:.8} \
             ({lat:.8}), {} steps, iterations {:?}",
            reports.len(),
            reports.iter().map(|r| r.iterations).collect::<Vec<_>>()
        );
        assert!(
            (force / expected - 1.0).abs() < 1e-6,
            "force {force} vs {expected}"
        );
        assert!(
            (stretch / lat - 1.0).abs() < 1e-6,
            "stretch {stretch} vs {lat}"
        );
        // The field is homogeneous: every side node has the same lateral displacement.
        for &i in &side {
            assert!((sol.u[3 * i] - (lat - 1.0) * l).abs() < 1e-9 * l);
        }
    }
}

/// A prescribed field that flattens one element before the others: the error names that
/// element and the load at which its volume, hand-computed, reaches zero.
#[test]
fn an_inverted_element_is_reported_by_id() {
    let l = 0.01;
    let mesh = box_mesh([l; 3], [1, 1, 1]);
    let body = HyperelasticBody::new(&mesh, Material::new(E, 0.3).unwrap()).unwrap();
    // Vertex 1 is the corner (l, 0, 0); every other vertex stays, edge nodes follow their
    // edge's midpoint, so each element stays straight and its J is its volume ratio.
    let moved = 1;
    let d = [-0.6 * l, 0.9 * l, 0.35 * l];
    let mut p = Prescribed::none(body.nodes());
    for v in 0..mesh.nodes.len() {
        for (a, &da) in d.iter().enumerate() {
            p.set(v, a, if v == moved { da } else { 0.0 }).unwrap();
        }
    }
    let q = body.quadratic();
    for t in &mesh.tets {
        for &(a, b) in &EDGES {
            let m = q.edge_node(t[a], t[b]).unwrap();
            for (c, &dc) in d.iter().enumerate() {
                let half = |v: usize| if v == moved { 0.5 * dc } else { 0.0 };
                p.set(m, c, half(t[a]) + half(t[b])).unwrap();
            }
        }
    }
    // Volume of tetrahedron t with the moved vertex displaced by `load d`: affine in the load.
    let volume = |t: &[usize; 4], load: f64| {
        let x: Vec<[f64; 3]> = t
            .iter()
            .map(|&v| {
                let mut y = mesh.nodes[v];
                if v == moved {
                    for c in 0..3 {
                        y[c] += load * d[c];
                    }
                }
                y
            })
            .collect();
        let e: Vec<[f64; 3]> = (1..4)
            .map(|k| std::array::from_fn(|c| x[k][c] - x[0][c]))
            .collect();
        (e[0][0] * (e[1][1] * e[2][2] - e[1][2] * e[2][1])
            - e[0][1] * (e[1][0] * e[2][2] - e[1][2] * e[2][0])
            + e[0][2] * (e[1][0] * e[2][1] - e[1][1] * e[2][0]))
            / 6.0
    };
    let mut zeros: Vec<(f64, usize)> = mesh
        .tets
        .iter()
        .enumerate()
        .filter_map(|(i, t)| {
            let (v0, v1) = (volume(t, 0.0), volume(t, 1.0));
            (v1 < 0.0).then(|| (v0 / (v0 - v1), i))
        })
        .collect();
    zeros.sort_by(|a, b| a.0.total_cmp(&b.0));
    let (load_star, expected) = zeros[0];
    assert!(
        zeros.len() == 1 || zeros[1].0 > load_star + 0.05,
        "{zeros:?}"
    );
    let err = solve(&body, &p, &NewtonOptions::default(), &mut |_| {}).unwrap_err();
    println!("{err}");
    match err {
        HyperError::Inverted {
            element, from, to, ..
        } => {
            assert_eq!(element, expected);
            assert!(
                from <= load_star && load_star <= to && to - from < 2e-4,
                "{from} {to}"
            );
        }
        other => panic!("expected an inversion, got {other}"),
    }
}

/// Bad input and an impossible schedule are errors that say what is wrong.
#[test]
fn bad_input_and_failures_are_named_errors() {
    let l = 0.02;
    let mesh = box_mesh([l; 3], [1, 1, 1]);
    let body = HyperelasticBody::new(&mesh, Material::new(E, 0.3).unwrap()).unwrap();
    let opts = NewtonOptions::default();
    // A set for another body.
    let wrong = Prescribed::none(body.nodes() + 1);
    let err = solve(&body, &wrong, &opts, &mut |_| {}).unwrap_err();
    assert!(matches!(err, HyperError::Prescribed(_)), "{err}");
    // Not a number, an axis that does not exist, a node that does not exist.
    let mut p = Prescribed::none(body.nodes());
    assert!(
        p.set(0, 0, f64::NAN)
            .unwrap_err()
            .to_string()
            .contains("node 0 axis 0")
    );
    assert!(p.set(0, 3, 0.0).is_err());
    assert!(p.set(body.nodes(), 0, 0.0).is_err());
    // Only the bottom's z held: the body can slide and spin.
    p.set_where(body.positions(), |x| x[2] <= 0.0, [None, None, Some(0.0)])
        .unwrap();
    let err = solve(&body, &p, &opts, &mut |_| {}).unwrap_err();
    assert!(err.to_string().contains("rigid motions"), "{err}");
    // 30 % bonded compression with one Newton iteration allowed and no halving.
    let p = bonded(&body, l, [0.0, 0.0, -0.3 * l]);
    let strict = NewtonOptions {
        initial_steps: 1,
        min_step: 1.0,
        max_iterations: 1,
        ..opts
    };
    match solve(&body, &p, &strict, &mut |_| {}).unwrap_err() {
        HyperError::NoConvergence {
            step,
            from,
            to,
            iterations,
            ..
        } => {
            assert_eq!((step, from, to, iterations), (1, 0.0, 1.0, 1));
        }
        other => panic!("expected no convergence, got {other}"),
    }
}

/// Platen force of a cube of side `l` between bonded platens at compressive strain `strain`.
fn bonded_force(
    l: f64,
    nu: f64,
    volumetric: Volumetric,
    strain: f64,
    cells: usize,
) -> (f64, usize, f64) {
    let mesh = box_mesh([l; 3], [cells; 3]);
    let material = Material::new(E, nu).unwrap();
    let body = HyperelasticBody::with_volumetric(&mesh, material, volumetric).unwrap();
    let p = bonded(&body, l, [0.0, 0.0, -strain * l]);
    let top: Vec<usize> = (0..body.nodes())
        .filter(|&i| body.positions()[i][2] >= l * (1.0 - 1e-12))
        .collect();
    let start = Instant::now();
    let mut steps = 0;
    let sol = solve(&body, &p, &NewtonOptions::default(), &mut |r| {
        steps += 1;
        eprintln!(
            "  cells {cells}: step {} load {:.4} iterations {} residuals {:?}",
            r.step, r.load, r.iterations, r.residuals
        );
    })
    .unwrap();
    let seconds = start.elapsed().as_secs_f64();
    eprintln!("  cells {cells}: {steps} steps");
    (-sol.reaction(top, 2), body.nodes(), seconds)
}

/// Refinement series of the bonded-platen cube at 20 %: the platen force converges, with the
/// Richardson estimate of the finest level's error.
#[test]
#[ignore = "refinement series, seconds; run with --ignored --nocapture"]
fn bonded_cube_refinement_series() {
    let l = 0.08;
    for (nu, v) in [
        (0.45, Volumetric::Pointwise),
        (0.499, Volumetric::Pointwise),
        (0.499, Volumetric::ElementMean),
    ] {
        let levels: Vec<(usize, (f64, usize, f64))> = [2, 4, 8]
            .into_iter()
            .map(|c| (c, bonded_force(l, nu, v, 0.2, c)))
            .collect();
        for (c, (f, n, t)) in &levels {
            println!("nu {nu} {v:?} cells {c}: {n} nodes, platen force {f:.6} N, {t:.2} s");
        }
        let (f1, f2, f3) = (levels[0].1.0, levels[1].1.0, levels[2].1.0);
        let (order, error) = richardson([0.5, 0.25, 0.125], [f1, f2, f3]);
        println!(
            "nu {nu} {v:?}: observed order {order:.2}, Richardson error of cells 8 {error:.3e} N ({:.3} %)",
            100.0 * error / f3
        );
        assert!((f2 - f3).abs() < (f1 - f2).abs());
    }
}

/// Platen force of the cube of side `l` between bonded platens at compressive strain `strain`
/// from one eighth of it (`cells` per side of the eighth): the eighth `[0, l/2]^3` with
/// rollers on the three symmetry planes (x = 0, y = 0, z = 0: normal displacement zero), the
/// platen face z = l/2 moved by `(0, 0, -strain l / 2)`. The whole platen carries four times
/// the eighth's reaction. Returns (force N, nodes, seconds).
fn eighth_bonded_force(
    l: f64,
    nu: f64,
    volumetric: Volumetric,
    strain: f64,
    cells: usize,
) -> (f64, usize, f64) {
    let half = 0.5 * l;
    let mesh = box_mesh([half; 3], [cells; 3]);
    let material = Material::new(E, nu).unwrap();
    let body = HyperelasticBody::with_volumetric(&mesh, material, volumetric).unwrap();
    let x = body.positions();
    let mut p = Prescribed::none(body.nodes());
    for axis in 0..3 {
        let mut c = [None; 3];
        c[axis] = Some(0.0);
        p.set_where(x, |q| q[axis] <= 1e-12 * l, c).unwrap();
    }
    let on_top = |q: [f64; 3]| q[2] >= half * (1.0 - 1e-12);
    p.set_where(x, on_top, [Some(0.0), Some(0.0), Some(-strain * half)])
        .unwrap();
    let top: Vec<usize> = (0..x.len()).filter(|&i| on_top(x[i])).collect();
    let start = Instant::now();
    let sol = solve(&body, &p, &NewtonOptions::default(), &mut |r| {
        eprintln!(
            "  eighth, cells {cells}: step {} load {:.4} iterations {} halvings {}",
            r.step, r.load, r.iterations, r.halvings
        );
    })
    .unwrap();
    let seconds = start.elapsed().as_secs_f64();
    (-4.0 * sol.reaction(top, 2), body.nodes(), seconds)
}

/// Observed order and error of the finest of three levels with mesh sizes `h` (any ratios),
/// by bisection on `(f1 - f2) / (f2 - f3) = (h1^p - h2^p) / (h2^p - h3^p)`.
fn richardson(h: [f64; 3], f: [f64; 3]) -> (f64, f64) {
    let ratio = (f[0] - f[1]) / (f[1] - f[2]);
    let model = |p: f64| (h[0].powf(p) - h[1].powf(p)) / (h[1].powf(p) - h[2].powf(p));
    let (mut lo, mut hi) = (0.05, 8.0);
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if model(mid) < ratio {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    let p = 0.5 * (lo + hi);
    let c = (f[1] - f[2]) / (h[1].powf(p) - h[2].powf(p));
    (p, c * h[2].powf(p))
}

/// The 80 mm gel cube (nu = 0.499) between bonded platens at 18.25 %: the platen force and
/// time per mesh, whole cube and one eighth by symmetry, with the Richardson error.
#[test]
#[ignore = "timing of the specimen; run with --ignored --nocapture"]
fn gel_cube_80mm_timing() {
    let (l, nu, strain) = (0.08, 0.499, 0.1825);
    for v in [Volumetric::Pointwise, Volumetric::ElementMean] {
        for cells in [2, 4, 6, 8] {
            let (f, n, t) = bonded_force(l, nu, v, strain, cells);
            println!("{v:?} whole, cells {cells}: {n} nodes, platen force {f:.6} N, {t:.2} s");
        }
    }
    for (v, levels) in [
        (Volumetric::ElementMean, &[4, 6, 8, 10][..]),
        (Volumetric::Pointwise, &[4, 6, 8][..]),
    ] {
        let mut forces = Vec::new();
        for &cells in levels {
            let (f, n, t) = eighth_bonded_force(l, nu, v, strain, cells);
            println!(
                "{v:?} eighth, cells {cells} (whole {}): {n} nodes, platen force {f:.6} N, \
                 {t:.2} s",
                2 * cells
            );
            forces.push(f);
        }
        for k in 0..levels.len() - 2 {
            let h = [0, 1, 2].map(|i| 1.0 / levels[k + i] as f64);
            let f = [0, 1, 2].map(|i| forces[k + i]);
            let (order, error) = richardson(h, f);
            println!(
                "{v:?} eighth, cells {:?}: observed order {order:.2}, Richardson error of the \
                 finest {error:.4} N ({:.2} %)",
                &levels[k..k + 3],
                100.0 * error / f[2]
            );
        }
    }
}
