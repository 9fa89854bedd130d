//! Tool loads ([`fem::tool`]) against independent references: the mirror symmetries and the
//! centroid of a parabolic pressure on a flat face, its exact integral `pi a^2 / 2`, uniform
//! refinement, barycentric and P2 shape-function values for a point tool, the P2 consistent
//! load of a uniform pressure, a brute-force closest point, and the errors.

use fem::elasticity::quadratic::QuadraticBody;
use fem::elasticity::{Material, Stiffness};
use fem::mesh::structured::box_mesh;
use fem::mesh::{Surface, TetMesh, boundary};
use fem::reference::split_1_to_8;
use fem::tool::{ToolError, ToolSurface};
use fem::vec3::{cross, dot, norm, scale, sub};
use std::f64::consts::PI;
use std::time::Instant;

/// A 10 cm x 10 cm x 5 cm slab, 1 cm cells on its top face `z = 0.05`.
const SLAB: [f64; 3] = [0.1, 0.1, 0.05];

fn slab() -> TetMesh {
    box_mesh(SLAB, [10, 10, 2])
}

fn liver() -> TetMesh {
    fem::mesh::load(
        &std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../meshes/liver-1k4.msh"),
    )
    .unwrap()
}

fn p2(mesh: &TetMesh) -> QuadraticBody {
    QuadraticBody::new(mesh, Material::new(3.0e3, 0.45).unwrap()).unwrap()
}

/// Both tool surfaces of a mesh, with the node positions of each numbering.
fn surfaces(mesh: &TetMesh) -> Vec<(&'static str, ToolSurface, Vec<[f64; 3]>)> {
    let surface = boundary(mesh).unwrap();
    let body = p2(mesh);
    vec![
        (
            "p1",
            ToolSurface::linear(mesh, &surface).unwrap(),
            mesh.nodes.clone(),
        ),
        (
            "p2",
            ToolSurface::quadratic(mesh, &surface, &body).unwrap(),
            body.positions().to_vec(),
        ),
    ]
}

fn sum(w: &[(usize, f64)]) -> f64 {
    w.iter().map(|e| e.1).sum()
}

fn moment(w: &[(usize, f64)], positions: &[[f64; 3]]) -> [f64; 3] {
    let mut m = [0.0; 3];
    for &(i, wi) in w {
        for c in 0..3 {
            m[c] += wi * positions[i][c];
        }
    }
    m
}

fn assert_valid(w: &[(usize, f64)], what: &str) {
    assert!(!w.is_empty(), "{what}");
    assert!(w.windows(2).all(|p| p[0].0 < p[1].0), "{what}: not sorted");
    assert!(w.iter().all(|e| e.1 != 0.0 && e.1.is_finite()), "{what}");
    assert!((sum(w) - 1.0).abs() < 1e-12, "{what}: sum {}", sum(w));
}

#[test]
fn weights_are_sorted_and_sum_to_one_on_the_liver() {
    let mesh = liver();
    let surface = boundary(&mesh).unwrap();
    for (name, tool, _) in surfaces(&mesh) {
        for &v in surface.nodes.iter().step_by(11) {
            for radius in [0.0, 0.002, 0.005, 0.05] {
                let w = tool.tool_weights(mesh.nodes[v], radius).unwrap();
                assert_valid(&w, &format!("{name} node {v} radius {radius}"));
                if name == "p1" {
                    assert!(w.iter().all(|e| e.1 > 0.0));
                }
            }
        }
    }
}

/// A map of the face's plane, in coordinates centred on the tool.
type Mirror = fn([f64; 2]) -> [f64; 2];

/// The slab's top face is split along one diagonal direction, so its symmetries about a node
/// are the two diagonal mirrors and the half turn.
#[test]
fn weights_have_the_mirror_symmetries_of_the_face() {
    let mesh = slab();
    let c = [0.05, 0.05, 0.05];
    let mirrors: [(&str, Mirror); 3] = [
        ("x <-> y", |[x, y]| [y, x]),
        ("x <-> -y", |[x, y]| [-y, -x]),
        ("half turn", |[x, y]| [-x, -y]),
    ];
    for (name, tool, positions) in surfaces(&mesh) {
        for radius in [0.0231, 0.0127, 0.045] {
            let w = tool.tool_weights(c, radius).unwrap();
            assert_valid(&w, name);
            let weight_at = |p: [f64; 3]| {
                w.iter()
                    .find(|e| norm(sub(positions[e.0], p)) < 1e-12)
                    .map_or(0.0, |e| e.1)
            };
            let mut worst = 0.0f64;
            for &(i, wi) in &w {
                let p = positions[i];
                assert!(
                    (p[2] - 0.05).abs() < 1e-15,
                    "{name}: node {i} is off the top face"
                );
                for (mirror, f) in mirrors {
                    let [x, y] = f([p[0] - c[0], p[1] - c[1]]);
                    let image = weight_at([c[0] + x, c[1] + y, p[2]]);
                    worst = worst.max((image - wi).abs());
                    assert!(
                        (image - wi).abs() < 1e-12,
                        "{name} radius {radius} {mirror}: node {i} {wi} vs {image}"
                    );
                }
            }
            eprintln!(
                "{name} radius {radius}: {} nodes, worst asymmetry {worst:.1e}",
                w.len()
            );
        }
    }
}

#[test]
fn weighted_mean_node_is_the_centre_on_a_flat_face() {
    let mesh = slab();
    for (name, tool, positions) in surfaces(&mesh) {
        for (c, radius) in [
            ([0.05, 0.05, 0.05], 0.0231),
            ([0.0437, 0.0519, 0.05], 0.0171),
            ([0.0612, 0.0333, 0.05], 0.0082),
            ([0.0612, 0.0333, 0.05], 0.0),
        ] {
            let w = tool.tool_weights(c, radius).unwrap();
            let err = norm(sub(moment(&w, &positions), c));
            eprintln!("{name} centre {c:?} radius {radius}: |sum w x - c| = {err:.1e} m");
            assert!(err < 1e-12, "{name} {c:?} {radius}: {err:e}");
        }
    }
}

#[test]
fn pressure_integral_of_a_flat_disk_is_half_pi_a_squared() {
    let mesh = slab();
    let tool = ToolSurface::linear(&mesh, &boundary(&mesh).unwrap()).unwrap();
    for (c, radius) in [
        ([0.05, 0.05, 0.05], 0.0231),
        ([0.0437, 0.0519, 0.05], 0.0171),
        ([0.0612, 0.0333, 0.05], 0.0082),
        ([0.0612, 0.0333, 0.05], 0.00091),
        ([0.05, 0.05, 0.05], 0.04),
    ] {
        let got = tool.pressure_integral(c, radius).unwrap();
        let exact = PI * radius * radius / 2.0;
        let err = (got - exact) / exact;
        eprintln!("centre {c:?} radius {radius}: relative error {err:.1e}");
        assert!(err.abs() < 1e-8 && err <= 1e-14, "{err:e}");
    }
    // A centre above the face: the ball cuts a disk of radius rho = sqrt(a^2 - d^2), and
    // p = (rho^2 - r^2) / a^2 integrates to pi rho^4 / (2 a^2).
    let (a, d) = (0.015, 0.006);
    let got = tool.pressure_integral([0.047, 0.052, 0.05 + d], a).unwrap();
    let exact = PI * (a * a - d * d).powi(2) / (2.0 * a * a);
    assert!(((got - exact) / exact).abs() < 1e-8, "{got} vs {exact}");
    assert_eq!(
        tool.pressure_integral([0.05, 0.05, 0.05], 0.0).unwrap(),
        0.0
    );
}

#[test]
fn centroid_and_integral_survive_uniform_refinement() {
    let coarse = box_mesh(SLAB, [5, 5, 1]);
    let fine = split_1_to_8(&coarse);
    let finer = split_1_to_8(&fine);
    let (c, radius) = ([0.0437, 0.0519, 0.05], 0.0213);
    let mut integrals = Vec::new();
    for mesh in [&coarse, &fine, &finer] {
        let tool = ToolSurface::linear(mesh, &boundary(mesh).unwrap()).unwrap();
        let w = tool.tool_weights(c, radius).unwrap();
        assert_valid(&w, "refined");
        let err = norm(sub(moment(&w, &mesh.nodes), c));
        assert!(err < 1e-12, "{} nodes: {err:e}", mesh.nodes.len());
        integrals.push(tool.pressure_integral(c, radius).unwrap());
    }
    for p in &integrals {
        assert!((p / integrals[0] - 1.0).abs() < 1e-9, "{integrals:?}");
    }
}

/// A point of a top-face triangle given by its barycentric coordinates.
fn top_triangle(mesh: &TetMesh, surface: &Surface) -> [usize; 3] {
    *surface
        .triangles
        .iter()
        .find(|t| {
            t.iter().all(|&v| {
                let p = mesh.nodes[v];
                p[2] == 0.05 && p[0] > 0.03 && p[0] < 0.07 && p[1] > 0.03 && p[1] < 0.07
            })
        })
        .unwrap()
}

#[test]
fn point_tool_gives_the_shape_functions_at_the_centre() {
    let mesh = slab();
    let surface = boundary(&mesh).unwrap();
    let body = p2(&mesh);
    let linear = ToolSurface::linear(&mesh, &surface).unwrap();
    let quadratic = ToolSurface::quadratic(&mesh, &surface, &body).unwrap();
    let t = top_triangle(&mesh, &surface);
    for l in [[0.2, 0.3, 0.5], [0.6, 0.1, 0.3], [0.0, 0.25, 0.75]] {
        let c: [f64; 3] = std::array::from_fn(|k| (0..3).map(|i| l[i] * mesh.nodes[t[i]][k]).sum());
        let mut want: Vec<(usize, f64)> = (0..3).map(|i| (t[i], l[i])).collect();
        want.retain(|e| e.1 != 0.0);
        want.sort_by_key(|e| e.0);
        let got = linear.tool_weights(c, 0.0).unwrap();
        let nonzero = want.len();
        assert_eq!(got.len(), nonzero);
        for (g, w) in got.iter().zip(&want) {
            assert_eq!(g.0, w.0);
            assert!((g.1 - w.1).abs() < 1e-12, "{got:?} vs {want:?}");
        }
        // P2: L_i (2 L_i - 1) at the vertices, 4 L_i L_j at the edge nodes.
        let mut want: Vec<(usize, f64)> = (0..3)
            .map(|i| (t[i], l[i] * (2.0 * l[i] - 1.0)))
            .chain((0..3).map(|i| {
                let j = (i + 1) % 3;
                (body.edge_node(t[i], t[j]).unwrap(), 4.0 * l[i] * l[j])
            }))
            .collect();
        want.retain(|e| e.1 != 0.0);
        want.sort_by_key(|e| e.0);
        let got = quadratic.tool_weights(c, 0.0).unwrap();
        assert_eq!(got.len(), want.len(), "{got:?} vs {want:?}");
        for (g, w) in got.iter().zip(&want) {
            assert_eq!(g.0, w.0);
            assert!((g.1 - w.1).abs() < 1e-12, "{got:?} vs {want:?}");
        }
        // Within the tolerance of the surface is still on it.
        let above = [c[0], c[1], c[2] + 1e-13];
        assert_eq!(linear.tool_weights(above, 0.0).unwrap().len(), nonzero);
    }
}

/// With a huge radius the pressure is uniform over the whole slab: the P2 consistent load
/// gives the vertices nothing and each edge node a third of its triangles' area.
#[test]
fn p2_weights_of_a_wide_tool_approach_the_uniform_consistent_load() {
    let mesh = slab();
    let surface = boundary(&mesh).unwrap();
    let body = p2(&mesh);
    let tool = ToolSurface::quadratic(&mesh, &surface, &body).unwrap();
    let mut want = vec![0.0; body.nodes()];
    let mut total = 0.0;
    for &[a, b, c] in &surface.triangles {
        let [pa, pb, pc] = [a, b, c].map(|v| mesh.nodes[v]);
        let area = 0.5 * norm(cross(sub(pb, pa), sub(pc, pa)));
        total += area;
        for (p, q) in [(a, b), (b, c), (c, a)] {
            want[body.edge_node(p, q).unwrap()] += area / 3.0;
        }
    }
    let w = tool.tool_weights([0.05, 0.05, 0.05], 1e4).unwrap();
    assert_valid(&w, "wide");
    let mut worst = 0.0f64;
    for &(i, wi) in &w {
        if i < body.vertices() {
            assert!(wi.abs() < 1e-12, "vertex {i}: {wi}");
        } else {
            worst = worst.max((wi - want[i] / total).abs() / (want[i] / total));
        }
    }
    assert!(worst < 1e-9, "{worst:e}");
    // A narrow tool: positive edge weights, and some vertex weights negative.
    let w = tool.tool_weights([0.05, 0.05, 0.05], 0.0231).unwrap();
    assert!(
        w.iter()
            .filter(|e| e.0 >= body.vertices())
            .all(|e| e.1 > 0.0)
    );
    assert!(w.iter().any(|e| e.0 < body.vertices() && e.1 < 0.0));
}

/// Distance to a triangle computed independently of the library: the projection on the plane
/// when it falls inside (signed areas), else the closest of the three edges.
fn brute_distance(q: [f64; 3], t: [[f64; 3]; 3]) -> f64 {
    let n = cross(sub(t[1], t[0]), sub(t[2], t[0]));
    let n = scale(n, 1.0 / norm(n));
    let h = dot(sub(q, t[0]), n);
    let proj = sub(q, scale(n, h));
    let inside = (0..3).all(|k| {
        let (a, b) = (t[k], t[(k + 1) % 3]);
        dot(cross(sub(b, a), sub(proj, a)), n) >= 0.0
    });
    if inside {
        return h.abs();
    }
    (0..3)
        .map(|k| {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            let e = sub(b, a);
            let s = (dot(sub(q, a), e) / dot(e, e)).clamp(0.0, 1.0);
            norm(sub(q, [a[0] + s * e[0], a[1] + s * e[1], a[2] + s * e[2]]))
        })
        .fold(f64::INFINITY, f64::min)
}

/// Pseudo-random points in a box (SplitMix64, deterministic).
fn random_points(lo: [f64; 3], hi: [f64; 3], count: usize) -> Vec<[f64; 3]> {
    let mut rng = splitmix::SplitMix64::new(0x2545_f491_4f6c_dd1d);
    let mut draw = || rng.unit();
    (0..count)
        .map(|_| std::array::from_fn(|a| lo[a] + (hi[a] - lo[a]) * draw()))
        .collect()
}

fn check_closest(mesh: &TetMesh, surface: &Surface, tool: &ToolSurface, q: [f64; 3]) {
    let at = tool.closest_point(q);
    let corners = |t: usize| surface.triangles[t].map(|v| mesh.nodes[v]);
    let best = (0..surface.triangles.len())
        .map(|t| brute_distance(q, corners(t)))
        .fold(f64::INFINITY, f64::min);
    assert!(
        (at.distance - best).abs() <= 1e-12 * best.max(1e-3),
        "{q:?}: {} vs {best}",
        at.distance
    );
    let t = corners(at.triangle);
    assert!((brute_distance(q, t) - at.distance).abs() <= 1e-12 * best.max(1e-3));
    assert!(
        at.bary.iter().all(|&l| l >= -1e-12) && (at.bary.iter().sum::<f64>() - 1.0).abs() < 1e-12
    );
    let p: [f64; 3] = std::array::from_fn(|k| (0..3).map(|i| at.bary[i] * t[i][k]).sum());
    assert!(norm(sub(p, at.point)) < 1e-12);
    let n = cross(sub(t[1], t[0]), sub(t[2], t[0]));
    assert!(norm(sub(scale(n, 1.0 / norm(n)), at.normal)) < 1e-12);
}

#[test]
fn closest_point_matches_brute_force() {
    let mesh = liver();
    let surface = boundary(&mesh).unwrap();
    let tool = ToolSurface::linear(&mesh, &surface).unwrap();
    let (lo, hi) = mesh.bounding_box();
    // Inside, around and far outside the organ.
    let pad = [0.02; 3];
    for q in random_points(
        sub(lo, pad),
        [hi[0] + 0.02, hi[1] + 0.02, hi[2] + 0.02],
        400,
    )
    .into_iter()
    .chain([[0.0, 0.0, 1.0], [-3.0, 2.0, -1.0], [0.0, 0.0, 0.07]])
    {
        check_closest(&mesh, &surface, &tool, q);
    }
    // Outward normals: straight above the top, the normal points up.
    let at = tool.closest_point([0.03, 0.0, 0.2]);
    assert!(at.normal[2] > 0.5, "{at:?}");
    let nan = tool.closest_point([f64::NAN, 0.0, 0.0]);
    assert!(nan.distance.is_nan());
}

/// A surface of about 100k triangles (a 1 m x 1 m x 1 cm plate of 160 x 160 cells): queries
/// stay fast and exact.
#[test]
fn large_surface_queries() {
    let mesh = box_mesh([1.0, 1.0, 0.01], [160, 160, 1]);
    let surface = boundary(&mesh).unwrap();
    let start = Instant::now();
    let tool = ToolSurface::linear(&mesh, &surface).unwrap();
    let build = start.elapsed();
    assert!(tool.len() > 100_000);
    let points = random_points([-0.05, -0.05, -0.02], [1.05, 1.05, 0.03], 2000);
    let start = Instant::now();
    let found: Vec<_> = points.iter().map(|&q| tool.closest_point(q)).collect();
    let closest = start.elapsed() / points.len() as u32;
    let start = Instant::now();
    for at in &found {
        let w = tool.tool_weights(at.point, 0.01).unwrap();
        assert_valid(&w, "plate");
    }
    let weights = start.elapsed() / found.len() as u32;
    eprintln!(
        "{} triangles: build {build:?}, closest point {closest:?}, weights (a = 1 cm) {weights:?}",
        tool.len()
    );
    for &q in points.iter().step_by(100) {
        check_closest(&mesh, &surface, &tool, q);
    }
    assert!(closest.as_secs_f64() < 1e-3 && weights.as_secs_f64() < 1e-2);
}

#[test]
fn bad_requests_are_errors_naming_the_centre_and_radius() {
    let mesh = slab();
    let surface = boundary(&mesh).unwrap();
    let tool = ToolSurface::linear(&mesh, &surface).unwrap();
    let c = [0.05, 0.05, 0.05];
    for radius in [-0.001, f64::NAN, f64::INFINITY] {
        let e = tool.tool_weights(c, radius).unwrap_err();
        assert!(matches!(e, ToolError::BadRadius { .. }), "{e}");
        let msg = e.to_string();
        assert!(
            msg.contains(&radius.to_string()) && msg.contains("(0.05, 0.05, 0.05)"),
            "{msg}"
        );
    }
    let e = tool.tool_weights([f64::NAN, 0.0, 0.0], 0.01).unwrap_err();
    assert!(matches!(e, ToolError::BadCentre { .. }), "{e}");
    let e = tool.tool_weights([0.05, 0.05, 0.5], 0.1).unwrap_err();
    assert_eq!(
        e.to_string(),
        "no surface within 0.1 m of the tool centre (0.05, 0.05, 0.5) m: the closest surface \
         point is 0.45 m away"
    );
    assert!(matches!(
        tool.tool_weights([0.05, 0.05, 0.0501], 0.0),
        Err(ToolError::NoSurface { .. })
    ));
    assert!(matches!(
        tool.pressure_integral(c, -1.0),
        Err(ToolError::BadRadius { .. })
    ));

    // Construction.
    let empty = Surface::default();
    assert_eq!(
        ToolSurface::linear(&mesh, &empty).unwrap_err(),
        ToolError::EmptySurface
    );
    let mut bad = surface.clone();
    bad.triangles[3][1] = mesh.nodes.len() + 5;
    assert!(matches!(
        ToolSurface::linear(&mesh, &bad),
        Err(ToolError::NoSuchNode { triangle: 3, .. })
    ));
    let mut flat = surface.clone();
    flat.triangles[2] = [0, 1, 2]; // three nodes on a line
    assert_eq!(
        ToolSurface::linear(&mesh, &flat).unwrap_err(),
        ToolError::DegenerateTriangle { triangle: 2 }
    );
    let other = p2(&box_mesh(SLAB, [5, 5, 1]));
    let e = ToolSurface::quadratic(&mesh, &surface, &other).unwrap_err();
    assert!(matches!(e, ToolError::BodyMismatch { .. }), "{e}");
}
