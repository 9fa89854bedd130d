//! The bonded indenter (`fem::hyperelastic::indent`) against independent references: the
//! nodes of a disc counted by hand on a structured block, the linear 10-node solve at small
//! depth, separate solves to each stop of one load path, and a press through the block's
//! held base reported as a failure.

use fem::compliance::solve_prescribed;
use fem::elasticity::Material;
use fem::hyperelastic::indent::{IndentError, Indenter, indent};
use fem::hyperelastic::{HyperError, HyperelasticBody, NewtonOptions, Prescribed, solve};
use fem::mesh::boundary;
use fem::mesh::structured::box_mesh;

const L: f64 = 0.02;

/// A 20 mm block of 2 x 2 x 2 cells (E 3 kPa, nu 0.45), base held; the indenter is the disc of
/// `radius` around the top face's centre.
fn block(radius: f64) -> (HyperelasticBody, Prescribed, Indenter) {
    let mesh = box_mesh([L; 3], [2, 2, 2]);
    let body = HyperelasticBody::new(&mesh, Material::new(3000.0, 0.45).unwrap()).unwrap();
    let mut held = Prescribed::none(body.nodes());
    held.set_where(body.positions(), |x| x[2] <= 1e-12, [Some(0.0); 3])
        .unwrap();
    let surface = boundary(&mesh).unwrap();
    let tool = Indenter::disc(&body, &surface, [0.5 * L, 0.5 * L, L], radius).unwrap();
    (body, held, tool)
}

/// The top face's 10-node grid has a node every 5 mm (vertices, edge and face-diagonal
/// midpoints): a 5.1 mm disc at its centre holds the centre and its 4 neighbours (the
/// diagonal ones are 7.07 mm away); a 1 mm disc holds one node and is refused.
#[test]
fn the_disc_holds_the_surface_nodes_within_the_radius() {
    let (body, _, tool) = block(0.0051);
    let mut got: Vec<[i64; 3]> = tool
        .nodes()
        .iter()
        .map(|&n| body.positions()[n].map(|x| (x * 1e4).round() as i64))
        .collect();
    got.sort_unstable();
    assert_eq!(
        got,
        vec![
            [50, 100, 200],
            [100, 50, 200],
            [100, 100, 200],
            [100, 150, 200],
            [150, 100, 200]
        ]
    );
    let mesh = box_mesh([L; 3], [2, 2, 2]);
    let surface = boundary(&mesh).unwrap();
    let err = Indenter::disc(&body, &surface, [0.5 * L, 0.5 * L, L], 0.001).unwrap_err();
    assert!(err.to_string().contains("1 surface node(s)"), "{err}");
}

/// At a depth of 1e-7 of the block the neo-Hookean force equals the linear solve of the same
/// prescribed displacements (computed here independently), for a press and an oblique pull.
#[test]
fn a_shallow_indent_is_the_linear_solve() {
    let (body, held, tool) = block(0.0051);
    for d in [[0.0, 0.0, -1e-7 * L], [0.5e-7 * L, 0.0, 1e-7 * L]] {
        let got = indent(&body, &held, &tool, d, &[1.0], &NewtonOptions::default()).unwrap();
        let mut p = held.clone();
        for &n in tool.nodes() {
            for (a, &v) in d.iter().enumerate() {
                p.set(n, a, v).unwrap();
            }
        }
        let (_, f) = solve_prescribed(body.quadratic(), &p.fixed_set(), &p.field()).unwrap();
        let want: [f64; 3] =
            std::array::from_fn(|a| tool.nodes().iter().map(|&n| f[3 * n + a]).sum());
        let norm = want.iter().map(|x| x * x).sum::<f64>().sqrt();
        for a in 0..3 {
            assert!((got[0].linear[a] - want[a]).abs() < 1e-12 * norm);
            assert!(
                (got[0].large[a] - want[a]).abs() < 1e-6 * norm,
                "{d:?}: {:?} against {want:?}",
                got[0].large
            );
        }
    }
}

/// The forces at the stops of one load path (40 % and 100 % of a 4 mm press) equal separate
/// solves to each depth (`fem::hyperelastic::solve`), and the linear force is proportional.
#[test]
fn one_path_stops_where_separate_solves_end() {
    let (body, held, tool) = block(0.0051);
    let d = [0.0, 0.0, -0.004];
    let path = indent(
        &body,
        &held,
        &tool,
        d,
        &[0.4, 1.0],
        &NewtonOptions::default(),
    )
    .unwrap();
    for stop in &path {
        let mut p = held.clone();
        for &n in tool.nodes() {
            for (a, &v) in d.iter().enumerate() {
                p.set(n, a, stop.load * v).unwrap();
            }
        }
        let s = solve(&body, &p, &NewtonOptions::default(), &mut |_| {}).unwrap();
        let fz = s.reaction(tool.nodes().iter().copied(), 2);
        assert!(
            (stop.large[2] - fz).abs() < 1e-8 * fz.abs(),
            "load {}: {} against {fz}",
            stop.load,
            stop.large[2]
        );
    }
    assert!((path[0].linear[2] / path[1].linear[2] - 0.4).abs() < 1e-14);
    // 20 % of the block's height: the neo-Hookean press is measurably off the linear one.
    let ratio = path[1].large[2] / path[1].linear[2];
    assert!((ratio - 1.0).abs() > 0.01, "ratio {ratio}");
}

/// A press deeper than the block would push the indenter through its held base: the solve
/// reports the failure (an inverted element or no convergence), no force.
#[test]
fn a_press_through_the_base_is_an_error() {
    let (body, held, tool) = block(0.0051);
    let options = NewtonOptions {
        min_step: 1e-3,
        ..NewtonOptions::default()
    };
    let err = indent(&body, &held, &tool, [0.0, 0.0, -1.5 * L], &[1.0], &options).unwrap_err();
    assert!(
        matches!(
            err,
            IndentError::Large(HyperError::Inverted { .. } | HyperError::NoConvergence { .. })
        ),
        "{err}"
    );
    // An indenter on held nodes is refused by name.
    let mut all = held.clone();
    for &n in tool.nodes() {
        all.set(n, 0, 0.0).unwrap();
    }
    let err = indent(&body, &all, &tool, [0.0, 0.0, -0.001], &[1.0], &options).unwrap_err();
    assert!(err.to_string().contains("held by the supports"), "{err}");
}
