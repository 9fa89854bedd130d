//! P1 elasticity against analytic references: element energy, patch tests, uniaxial
//! compression of a box, a cantilever against Timoshenko beam theory.

use fem::compliance::solve_prescribed;
use fem::elasticity::{Elasticity, Element, FixedSet, Material};
use fem::mesh::TetMesh;
use fem::mesh::structured::{box_mesh, distorted_box_mesh};
use fem::reference::box_compression;

/// A linear field `u(x) = A x + b`.
fn linear_field(mesh: &TetMesh, a: [[f64; 3]; 3], b: [f64; 3]) -> Vec<f64> {
    mesh.nodes
        .iter()
        .flat_map(|p| {
            std::array::from_fn::<f64, 3, _>(|r| {
                b[r] + a[r][0] * p[0] + a[r][1] * p[1] + a[r][2] * p[2]
            })
        })
        .collect()
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// Strain energy density of the linear field `A x` in an isotropic material:
/// `lambda/2 tr(eps)^2 + mu eps:eps`, `eps = sym(A)`.
fn energy_density(m: Material, a: [[f64; 3]; 3]) -> f64 {
    let (lambda, mu) = m.lame();
    let eps: [[f64; 3]; 3] =
        std::array::from_fn(|i| std::array::from_fn(|j| 0.5 * (a[i][j] + a[j][i])));
    let tr = eps[0][0] + eps[1][1] + eps[2][2];
    let mut ee = 0.0;
    for row in eps {
        for v in row {
            ee += v * v;
        }
    }
    0.5 * lambda * tr * tr + mu * ee
}

const A: [[f64; 3]; 3] = [
    [1.0e-3, 2.0e-4, -3.0e-4],
    [5.0e-4, -2.0e-3, 1.0e-4],
    [-4.0e-4, 3.0e-4, 1.5e-3],
];

#[test]
fn single_element_energy_and_rigid_modes() {
    let mesh = TetMesh {
        nodes: vec![
            [0.0, 0.0, 0.0],
            [0.02, 0.001, 0.0],
            [0.003, 0.015, 0.002],
            [0.001, 0.004, 0.01],
        ],
        tets: vec![[0, 1, 2, 3]],
    };
    let mat = Material::new(5.0e3, 0.3).unwrap();
    let body = Elasticity::new(&mesh, mat).unwrap();
    let v = mesh.signed_volume(0);
    // Energy of a linear field is exact: u^T K u / 2 = V W(eps).
    let u = linear_field(&mesh, A, [1e-3, -2e-3, 5e-4]);
    let ku = body.apply(&u);
    let energy = 0.5 * dot(&u, &ku);
    let expected = v * energy_density(mat, A);
    assert!(
        (energy - expected).abs() <= 1e-12 * expected,
        "{energy} vs {expected}"
    );
    // Rigid motions (translation + infinitesimal rotation) carry no force.
    let skew = [[0.0, -0.3, 0.2], [0.3, 0.0, -0.1], [-0.2, 0.1, 0.0]];
    let rigid = linear_field(&mesh, skew, [0.1, -0.2, 0.3]);
    let f = body.apply(&rigid);
    let scale = ku.iter().map(|x| x.abs()).fold(0.0, f64::max) / 1e-3;
    assert!(f.iter().all(|x| x.abs() <= 1e-12 * scale), "{f:?}");
}

#[test]
fn assembled_matrix_matches_element_by_element_product() {
    let mesh = distorted_box([0.04, 0.03, 0.02], [4, 3, 3], 0.2);
    let body = Elasticity::new(&mesh, Material::new(3.0e3, 0.45).unwrap()).unwrap();
    let fixed = FixedSet::none(mesh.nodes.len());
    let dofs = fem::elasticity::DofMap::new(&fixed);
    let k = body.stiffness(&dofs);
    let u = linear_field(&mesh, A, [0.0; 3]);
    let ku_elem = body.apply(&u);
    // Symmetric product from the upper triangle.
    let mut ku = vec![0.0; u.len()];
    for j in 0..k.ncols() {
        for (i, &v) in k.row_idx_of_col(j).zip(k.val_of_col(j)) {
            ku[i] += v * u[j];
            if i != j {
                ku[j] += v * u[i];
            }
        }
    }
    let scale = ku_elem.iter().map(|x| x.abs()).fold(0.0, f64::max);
    for (a, b) in ku.iter().zip(&ku_elem) {
        assert!((a - b).abs() <= 1e-12 * scale);
    }
}

const BOX: [f64; 3] = [0.04, 0.03, 0.02];

/// A structured box with its interior nodes moved randomly (deterministic), so elements are
/// irregular as in a patch test.
fn distorted_box(size: [f64; 3], cells: [usize; 3], amount: f64) -> TetMesh {
    let mesh = distorted_box_mesh(size, cells, amount, 0x2545_f491_4f6c_dd1d)
        .expect("no inverted element");
    let worst = (0..mesh.tets.len())
        .map(|t| mesh.quality(t))
        .fold(1.0, f64::min);
    eprintln!("distorted box ({amount}): worst element quality {worst:.3}");
    mesh
}

fn on_boundary(p: &[f64; 3], size: [f64; 3]) -> bool {
    (0..3).any(|a| p[a] < 1e-12 || p[a] > size[a] - 1e-12)
}

/// Patch test: the boundary of a distorted box follows a linear field; the interior must follow
/// it too, force-free. Returns the largest interior error relative to the field's size.
fn patch_test(poisson: f64, distortion: f64, size: [f64; 3]) -> f64 {
    let mesh = distorted_box(size, [5, 4, 3], distortion);
    let body = Elasticity::new(&mesh, Material::new(3.0e3, poisson).unwrap()).unwrap();
    let exact = linear_field(&mesh, A, [2e-4, -1e-4, 3e-4]);
    let mut held = FixedSet::none(mesh.nodes.len());
    for (i, p) in mesh.nodes.iter().enumerate() {
        if on_boundary(p, size) {
            held.fix_node(i).unwrap();
        }
    }
    let (u, f) = solve_prescribed(&body, &held, &exact).unwrap();
    let umax = exact.iter().map(|x| x.abs()).fold(0.0, f64::max);
    let fmax = f.iter().map(|x| x.abs()).fold(0.0, f64::max);
    let mut worst = 0.0f64;
    let mut interior = 0;
    for (i, p) in mesh.nodes.iter().enumerate() {
        if !on_boundary(p, size) {
            interior += 1;
            for c in 0..3 {
                worst = worst.max((u[3 * i + c] - exact[3 * i + c]).abs() / umax);
                assert!(
                    f[3 * i + c].abs() <= 1e-9 * fmax,
                    "interior node {i} carries force"
                );
            }
        }
    }
    assert!(interior >= 24);
    worst
}

#[test]
fn patch_test_reproduces_linear_field_exactly() {
    let err = patch_test(0.45, 0.3, BOX);
    assert!(err <= 1e-12, "{err:e}");
}

/// Hard cases: nearly incompressible material (nu = 0.4999, lambda / mu = 5000) and sliver
/// elements (a box flattened 50:1, distorted: element quality about 0.01); P1 must still pass
/// the patch test, to a precision set by the conditioning.
#[test]
fn patch_test_holds_when_nearly_incompressible_and_with_slivers() {
    let flat = [0.04, 0.03, 0.0004];
    let incompressible = patch_test(0.4999, 0.3, BOX);
    let slivers = patch_test(0.45, 0.3, flat);
    let both = patch_test(0.4999, 0.3, flat);
    eprintln!(
        "patch test error: nu=0.4999 {incompressible:.1e}, slivers {slivers:.1e}, both {both:.1e}"
    );
    assert!(incompressible <= 1e-12 && slivers <= 1e-12 && both <= 1e-11);
}

/// Free-slip uniaxial compression of a straight box: bottom slides on z = 0, top is pushed
/// down by `delta`, one corner pinned in x, y and one in y. Exact P1 solution:
/// `u_z = -strain z`, `u_x = nu strain x`, `u_y = nu strain y`, force `E A strain`.
#[test]
fn box_uniaxial_compression_is_exact() {
    let size = [0.03, 0.02, 0.025];
    let mesh = box_mesh(size, [6, 4, 5]);
    let e = 4.5e3;
    // Both elements reproduce the linear uniaxial field, near incompressibility included.
    for element in Element::ALL {
        for nu in [0.45, 0.499] {
            let material = Material::new(e, nu).unwrap();
            let body = Elasticity::with_element(&mesh, material, element).unwrap();
            let r = box_compression(&body, &mesh, e, nu, size, 0.02).unwrap();
            assert!(r.displacement_error <= 1e-10, "{element} nu {nu}: {r:?}");
            assert!(r.force_error <= 1e-10, "{element} nu {nu}: {r:?}");
        }
    }
}

/// Mean tip deflection of a cantilever of `element`s clamped at x = 0 under a tip shear `p`
/// spread over the tip face nodes, divided by the Timoshenko value; and the node count.
fn cantilever_ratio(element: Element, nu: f64, cells: [usize; 3]) -> (usize, f64) {
    let (l, b, h) = (0.1, 0.01, 0.01);
    let e = 3.0e3;
    let mesh = box_mesh([l, b, h], cells);
    let body = Elasticity::with_element(&mesh, Material::new(e, nu).unwrap(), element).unwrap();
    let mut fixed = FixedSet::none(mesh.nodes.len());
    fixed
        .fix_box(&mesh, [-1.0, -1.0, -1.0, 1e-9, 1.0, 1.0], [true; 3])
        .unwrap();
    let compliance = fem::compliance::Compliance::factorize(&body, &fixed).unwrap();
    // Consistent nodal loads of a uniform shear traction on the tip face (structured grid:
    // bilinear weights).
    let p = -1.0e-3;
    let (ny, nz) = (cells[1], cells[2]);
    let mut forces = vec![0.0; 3 * mesh.nodes.len()];
    let mut tip = Vec::new();
    for (i, q) in mesh.nodes.iter().enumerate() {
        if q[0] > l - 1e-12 {
            let jy = (q[1] / b * ny as f64).round() as usize;
            let jz = (q[2] / h * nz as f64).round() as usize;
            let wy = if jy == 0 || jy == ny { 0.5 } else { 1.0 };
            let wz = if jz == 0 || jz == nz { 0.5 } else { 1.0 };
            forces[3 * i + 2] = p * wy * wz / (ny * nz) as f64;
            tip.push(i);
        }
    }
    let u = compliance.displacement(&forces);
    let mean: f64 = tip.iter().map(|&i| u[3 * i + 2]).sum::<f64>() / tip.len() as f64;
    let g = e / (2.0 * (1.0 + nu));
    let i_area = b * h * h * h / 12.0;
    let kappa = 10.0 * (1.0 + nu) / (12.0 + 11.0 * nu);
    let timoshenko = p * l * l * l / (3.0 * e * i_area) + p * l / (kappa * g * b * h);
    (mesh.nodes.len(), mean / timoshenko)
}

#[test]
fn cantilever_converges_to_timoshenko() {
    let series: Vec<(usize, f64)> = [
        [10, 2, 2],
        [20, 4, 4],
        [40, 6, 6],
        [60, 8, 8],
        [100, 12, 12],
        [160, 16, 16],
    ]
    .into_iter()
    .map(|cells| cantilever_ratio(Element::P1, 0.45, cells))
    .collect();
    for (nodes, ratio) in &series {
        eprintln!("cantilever: {nodes:6} nodes  tip deflection / Timoshenko = {ratio:.4}");
    }
    for pair in series.windows(2) {
        assert!(
            pair[1].1 > pair[0].1,
            "refinement must reduce locking: {series:?}"
        );
    }
    let last = series.last().unwrap().1;
    assert!(last > 0.93 && last < 1.0, "finest ratio {last}");
}

/// At nu = 0.499 P1 locks on a cantilever (tip deflection a tenth of Timoshenko's); ANP
/// stays within a few percent of its nu = 0.45 value, which is itself closer than P1's (linear
/// tetrahedra are also stiff in bending at this resolution).
#[test]
fn anp_cantilever_does_not_lock() {
    let cells = [40, 6, 6];
    let mut table = Vec::new();
    for nu in [0.45, 0.499] {
        let (_, p1) = cantilever_ratio(Element::P1, nu, cells);
        let (_, anp) = cantilever_ratio(Element::Anp, nu, cells);
        eprintln!("cantilever {cells:?} nu={nu}: tip / Timoshenko  p1 {p1:.4}  anp {anp:.4}");
        table.push((nu, p1, anp));
    }
    let (_, p1_45, anp_45) = table[0];
    let (_, p1_499, anp_499) = table[1];
    assert!(anp_45 > p1_45 && anp_45 < 1.0, "{table:?}");
    assert!(p1_499 < 0.2, "P1 should lock: {table:?}");
    assert!(anp_499 > 0.8 && anp_499 > 0.9 * anp_45, "{table:?}");
    assert!(
        (anp_499 - 1.0).abs() < 0.25 * (p1_499 - 1.0).abs(),
        "{table:?}"
    );
}
