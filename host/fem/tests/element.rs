//! The element formulations of `fem::elasticity::Element`: the average nodal pressure (ANP)
//! tetrahedron against P1 and analytic references (patch test, symmetry and SPD, spectrum of
//! `K_ff`); uniaxial compression and the cantilever against Timoshenko, for both elements, are
//! in `fem_exact.rs`.

use fem::compliance::{Compliance, solve_prescribed};
use fem::elasticity::{ANP_STABILISATION, DofMap, Elasticity, Element, FixedSet, Material};
use fem::mesh::TetMesh;
use fem::mesh::structured::{box_mesh, distorted_box_mesh};

const A: [[f64; 3]; 3] = [
    [1.0e-3, 2.0e-4, -3.0e-4],
    [5.0e-4, -2.0e-3, 1.0e-4],
    [-4.0e-4, 3.0e-4, 1.5e-3],
];

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

/// A structured box with its interior nodes moved randomly (deterministic).
fn distorted_box(size: [f64; 3], cells: [usize; 3], amount: f64) -> TetMesh {
    distorted_box_mesh(size, cells, amount, 0x2545_f491_4f6c_dd1d).expect("no inverted element")
}

fn on_boundary(p: &[f64; 3], size: [f64; 3]) -> bool {
    (0..3).any(|a| p[a] < 1e-12 || p[a] > size[a] - 1e-12)
}

fn anp(mesh: &TetMesh, young: f64, poisson: f64) -> Elasticity {
    Elasticity::with_element(mesh, Material::new(young, poisson).unwrap(), Element::Anp).unwrap()
}

#[test]
fn element_names_round_trip() {
    for e in Element::ALL {
        assert_eq!(e.name().parse::<Element>().unwrap(), e);
        assert_eq!(e.to_string(), e.name());
    }
    assert_eq!(Element::default(), Element::P1);
    let err = "p2".parse::<Element>().unwrap_err();
    assert!(err.contains("p1 or anp"), "{err}");
    let mesh = box_mesh([0.01; 3], [1, 1, 1]);
    let m = Material::new(1e3, 0.3).unwrap();
    assert!(Elasticity::with_anp_stabilisation(&mesh, m, 1.5).is_err());
    assert_eq!(Elasticity::new(&mesh, m).unwrap().element(), Element::P1);
}

/// Patch test: the boundary of a distorted box follows a linear field; the interior must follow
/// it exactly and carry no force.
#[test]
fn anp_passes_the_patch_test() {
    let size = [0.04, 0.03, 0.02];
    let mesh = distorted_box(size, [5, 4, 3], 0.3);
    for nu in [0.45, 0.4999] {
        let body = anp(&mesh, 3.0e3, nu);
        let exact = linear_field(&mesh, A, [2e-4, -1e-4, 3e-4]);
        let mut held = FixedSet::none(mesh.nodes.len());
        for (i, p) in mesh.nodes.iter().enumerate() {
            if on_boundary(p, size) {
                held.fix_node(i).unwrap();
            }
        }
        // Residual of the exact field at the interior nodes.
        let f_exact = body.apply(&exact);
        let (u, f) = solve_prescribed(&body, &held, &exact).unwrap();
        let umax = exact.iter().map(|x| x.abs()).fold(0.0, f64::max);
        let fmax = f.iter().map(|x| x.abs()).fold(0.0, f64::max);
        let (mut worst_u, mut worst_f, mut interior) = (0.0f64, 0.0f64, 0);
        for (i, p) in mesh.nodes.iter().enumerate() {
            if !on_boundary(p, size) {
                interior += 1;
                for c in 0..3 {
                    worst_u = worst_u.max((u[3 * i + c] - exact[3 * i + c]).abs() / umax);
                    worst_f = worst_f.max(f_exact[3 * i + c].abs() / fmax);
                }
            }
        }
        eprintln!("ANP patch test nu={nu}: interior error {worst_u:.1e}, residual {worst_f:.1e}");
        assert!(interior >= 24);
        assert!(
            worst_f <= 1e-11 && worst_u <= 1e-10,
            "{worst_f:e} {worst_u:e}"
        );
    }
}

// Free-slip uniaxial compression of a box, exact for both elements: fem_exact.rs.

/// Dense full `K` of a body from `apply` on unit vectors.
fn dense_by_apply(body: &Elasticity) -> faer::Mat<f64> {
    let n = 3 * body.nodes();
    let mut k = faer::Mat::<f64>::zeros(n, n);
    let mut e = vec![0.0; n];
    for j in 0..n {
        e[j] = 1.0;
        for (i, v) in body.apply(&e).into_iter().enumerate() {
            k[(i, j)] = v;
        }
        e[j] = 0.0;
    }
    k
}

/// Dense symmetric `K_ff` from the assembled upper triangle.
fn dense_kff(body: &Elasticity, fixed: &FixedSet) -> faer::Mat<f64> {
    let dofs = DofMap::new(fixed);
    let k = body.stiffness(&dofs);
    let n = dofs.free_count();
    let mut d = faer::Mat::<f64>::zeros(n, n);
    for j in 0..n {
        for (i, &v) in k.row_idx_of_col(j).zip(k.val_of_col(j)) {
            assert!(i <= j, "upper triangle only");
            d[(i, j)] = v;
            d[(j, i)] = v;
        }
    }
    d
}

/// The assembled `K_ff` equals the element-by-element operator of `apply` restricted to the
/// free dofs, that operator is symmetric, and the pattern reaches the two-ring.
#[test]
fn anp_stiffness_is_symmetric_and_matches_apply() {
    let mesh = distorted_box([0.03, 0.02, 0.02], [3, 2, 2], 0.3);
    let body = anp(&mesh, 3.0e3, 0.49);
    let full = dense_by_apply(&body);
    let n = full.nrows();
    let scale = (0..n).map(|i| full[(i, i)].abs()).fold(0.0, f64::max);
    let mut asym = 0.0f64;
    for i in 0..n {
        for j in 0..n {
            asym = asym.max((full[(i, j)] - full[(j, i)]).abs());
        }
    }
    assert!(asym <= 1e-13 * scale, "asymmetry {asym:e} of {scale:e}");
    let mut fixed = FixedSet::none(mesh.nodes.len());
    fixed
        .fix_box(&mesh, [-1.0, -1.0, -1.0, 1.0, 1.0, 1e-9], [true; 3])
        .unwrap();
    let dofs = DofMap::new(&fixed);
    let kff = dense_kff(&body, &fixed);
    let mut diff = 0.0f64;
    let mut free = Vec::new();
    for node in 0..mesh.nodes.len() {
        for c in 0..3 {
            if let Some(f) = dofs.free_dof(node, c) {
                free.push((f, 3 * node + c));
            }
        }
    }
    for &(fi, gi) in &free {
        for &(fj, gj) in &free {
            diff = diff.max((kff[(fi, fj)] - full[(gi, gj)]).abs());
        }
    }
    assert!(
        diff <= 1e-12 * scale,
        "assembly vs apply {diff:e} of {scale:e}"
    );
    // Two-ring coupling exists and lies inside `neighbours`.
    let p1 = Elasticity::new(&mesh, Material::new(3.0e3, 0.49).unwrap()).unwrap();
    let mut beyond_one_ring = 0;
    for a in 0..mesh.nodes.len() {
        for b in 0..mesh.nodes.len() {
            let coupled = (0..3).any(|i| (0..3).any(|j| full[(3 * a + i, 3 * b + j)] != 0.0));
            if coupled {
                assert!(
                    body.neighbours(a).contains(&b),
                    "{a}-{b} outside the pattern"
                );
                if !p1.neighbours(a).contains(&b) {
                    beyond_one_ring += 1;
                }
            }
        }
    }
    assert!(beyond_one_ring > 0);
    // SPD: the sparse Cholesky factorisation succeeds.
    let c = Compliance::factorize(&body, &fixed).unwrap();
    assert!(c.stats().nnz_l > 0);
}

/// The `count` smallest eigenvalues of `K_ff`.
fn lowest_eigenvalues(body: &Elasticity, fixed: &FixedSet, count: usize) -> Vec<f64> {
    let k = dense_kff(body, fixed);
    let eig = k.self_adjoint_eigen(faer::Side::Lower).unwrap();
    let s = eig.S();
    (0..count).map(|i| s[i]).collect()
}

/// No spurious (near-)zero-energy modes: on a small mesh clamped at its base, the lowest
/// eigenvalues of ANP's `K_ff` stay of the order of P1's (both are set by `mu` for the
/// bending-like modes; ANP's are lower because it does not lock). Printed for alpha = 0 to
/// show what the stabilisation buys.
#[test]
fn anp_has_no_spurious_zero_energy_modes() {
    let mesh = distorted_box([0.03, 0.03, 0.03], [3, 3, 3], 0.3);
    let mut fixed = FixedSet::none(mesh.nodes.len());
    fixed
        .fix_box(&mesh, [-1.0, -1.0, -1.0, 1.0, 1.0, 1e-9], [true; 3])
        .unwrap();
    for nu in [0.45, 0.499] {
        let m = Material::new(3.0e3, nu).unwrap();
        let p1 = lowest_eigenvalues(&Elasticity::new(&mesh, m).unwrap(), &fixed, 6);
        let bare = lowest_eigenvalues(
            &Elasticity::with_anp_stabilisation(&mesh, m, 0.0).unwrap(),
            &fixed,
            6,
        );
        let stab = lowest_eigenvalues(
            &Elasticity::with_element(&mesh, m, Element::Anp).unwrap(),
            &fixed,
            6,
        );
        eprintln!("nu={nu} lowest eigenvalues of K_ff (N/m)");
        let fmt = |v: &[f64]| {
            v.iter()
                .map(|x| format!("{x:.3e}"))
                .collect::<Vec<_>>()
                .join(" ")
        };
        eprintln!("  p1        {}", fmt(&p1));
        eprintln!("  anp a=0   {}", fmt(&bare));
        eprintln!("  anp a={ANP_STABILISATION} {}", fmt(&stab));
        assert!(stab[0] > 0.0 && bare[0] > 0.0);
        assert!(stab[0] >= 0.1 * p1[0], "{} vs P1 {}", stab[0], p1[0]);
        assert!(stab[0] <= p1[0] * 1.0001, "ANP must not be stiffer than P1");
    }
}
