//! Free-slip compression of a meshed cylinder. P1 is exact on a straight box, but a meshed
//! cylinder's side facets are slightly tilted, so the uniaxial field is not traction-free and
//! F / (E A_mesh strain) differs from 1; it must converge to 1 under refinement.

use fem::compliance::solve_prescribed;
use fem::elasticity::{Elasticity, FixedSet, Material};
use std::path::Path;

/// `F / (E A strain)` for the shipped cylinder `name`, with `A` the meshed top-face area.
fn force_ratio(name: &str) -> (usize, f64) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../meshes")
        .join(name);
    let mesh = fem::mesh::load(&path).unwrap();
    let surface = fem::mesh::boundary(&mesh).unwrap();
    let (lo, hi) = mesh.bounding_box();
    let height = hi[2] - lo[2];
    let tol = 1e-9 * height;
    let (e, nu, strain) = (3.0e3, 0.45, 0.01);
    let body = Elasticity::new(&mesh, Material::new(e, nu).unwrap()).unwrap();
    let mut held = FixedSet::none(mesh.nodes.len());
    let mut u_held = vec![0.0; 3 * mesh.nodes.len()];
    let mut top = Vec::new();
    for (i, p) in mesh.nodes.iter().enumerate() {
        if p[2] < lo[2] + tol {
            held.fix_component(i, 2).unwrap();
        } else if p[2] > hi[2] - tol {
            held.fix_component(i, 2).unwrap();
            u_held[3 * i + 2] = -strain * height;
            top.push(i);
        }
    }
    // Remove the in-plane rigid motions with the minimal pins: the bottom node nearest the
    // axis in x, y; a second bottom node on the rim in the tangential direction.
    let bottom: Vec<usize> = (0..mesh.nodes.len())
        .filter(|&i| mesh.nodes[i][2] < lo[2] + tol)
        .collect();
    let r = |i: usize| mesh.nodes[i][0].hypot(mesh.nodes[i][1]);
    let centre = *bottom
        .iter()
        .min_by(|&&a, &&b| r(a).total_cmp(&r(b)))
        .unwrap();
    let rim = *bottom
        .iter()
        .max_by(|&&a, &&b| r(a).total_cmp(&r(b)))
        .unwrap();
    held.fix_component(centre, 0).unwrap();
    held.fix_component(centre, 1).unwrap();
    let p = mesh.nodes[rim];
    held.fix_component(rim, if p[0].abs() > p[1].abs() { 1 } else { 0 })
        .unwrap();
    let (_, f) = solve_prescribed(&body, &held, &u_held).unwrap();
    let force: f64 = -top.iter().map(|&i| f[3 * i + 2]).sum::<f64>();
    let area: f64 = surface
        .triangles
        .iter()
        .filter(|t| t.iter().all(|&v| mesh.nodes[v][2] > hi[2] - tol))
        .map(|t| {
            let [a, b, c] = t.map(|v| mesh.nodes[v]);
            0.5 * ((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])).abs()
        })
        .sum();
    (mesh.nodes.len(), force / (e * area * strain))
}

#[test]
fn meshed_cylinder_force_ratio_converges_to_one() {
    let coarse = force_ratio("cylinder-2k.msh");
    let fine = force_ratio("cylinder-10k.msh");
    for (nodes, ratio) in [coarse, fine] {
        eprintln!("cylinder {nodes:6} nodes: F / (E A_mesh strain) = {ratio:.6}");
    }
    assert!(
        coarse.1 > 1.0 && fine.1 > 1.0,
        "tilted facets stiffen: {coarse:?} {fine:?}"
    );
    assert!(
        (fine.1 - 1.0) < (coarse.1 - 1.0),
        "no convergence: {coarse:?} {fine:?}"
    );
    assert!((coarse.1 - 1.0) < 5e-3 && (fine.1 - 1.0) < 2e-3);
}
