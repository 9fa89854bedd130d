//! The refinement series on a box (design notes, "a trap worth knowing"): the same press with
//! point contact and with a tool tip of finite radius, on three mesh sizes. A point force has
//! unbounded displacement (Boussinesq), so the point contact's force keeps falling as the mesh
//! is refined (about in proportion to the mesh size); the tip's pressure patch converges. The
//! liver series is `host bench refinement`; both run `haptic::bench::refinement::press`.

use fem::elasticity::Material;
use fem::mesh::structured::box_mesh;
use haptic::bench::refinement::{Config, press};

/// Force (N) on the tool pressing 1 mm into the top centre of a 40 x 40 x 20 mm box held at
/// its base, for point contact and a 5 mm tip: `(point, tip)`.
fn box_press(cells: usize) -> (f64, f64) {
    let (l, h) = (0.04, 0.02);
    let mesh = box_mesh([l, l, h], [cells, cells, cells / 2]);
    let config = Config {
        material: Material::new(3000.0, 0.3).unwrap(),
        bed_m: 1e-9,
        // Slightly off the grid's nodes and diagonals, so no quadrature point sits on an edge.
        from: [0.0203, 0.0198, 0.05],
        depth_m: 0.001,
        radii_m: vec![0.005],
    };
    let f = press(&mesh, &config).unwrap();
    assert_eq!(f.tips.len(), 1);
    (f.point_force_n, f.tips[0].2)
}

#[test]
fn point_contact_softens_under_refinement_and_the_tip_converges() {
    let levels = [8, 16, 32];
    let forces: Vec<(f64, f64)> = levels.iter().map(|&n| box_press(n)).collect();
    for (n, (p, t)) in levels.iter().zip(&forces) {
        println!(
            "box h = {:.2} mm: point {p:.5} N, 5 mm tip {t:.5} N",
            40.0 / *n as f64
        );
    }
    let ratio = |i: usize, f: fn(&(f64, f64)) -> f64| f(&forces[i + 1]) / f(&forces[i]);
    let (point, tip) = (|x: &(f64, f64)| x.0, |x: &(f64, f64)| x.1);
    // Point contact: each halving of h takes a large share of the force away.
    assert!(ratio(0, point) < 0.8 && ratio(1, point) < 0.8, "{forces:?}");
    // Tip: the change shrinks level by level and is small at the finest.
    let (c0, c1) = (1.0 - ratio(0, tip), 1.0 - ratio(1, tip));
    assert!(c1 < 0.6 * c0, "{forces:?}");
    assert!(c1.abs() < 0.05, "{forces:?}");
}
