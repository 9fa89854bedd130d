//! `host specimen` against independent references: the linear and large-deformation models
//! agree at small strain; between frictionless platens every marker follows the homogeneous
//! closed form of uniaxial stress (linear: lateral strain nu times the axial one; neo-Hookean:
//! the lateral stretch of `P_11 = 0` by a scalar Newton iteration here) and the platen force
//! is the closed form's; bad inputs exit non-zero naming what and where. Ignored by default
//! (`--ignored --nocapture`): the 80 mm gel cube's timing and linear-vs-large differences.

#[path = "support/cli.rs"]
mod cli;

use fem::hyperelastic::uniaxial_stress;
use haptic::specimen::geometry::{box_part, whole};
use haptic::specimen::{self, Axis, End, Geometry, Model, Platens, SpecimenConfig};
use haptic::units::Units;
use std::io::Write;
use std::path::Path;
use std::time::Instant;

const E: f64 = 5000.0;

/// A markers CSV with the given points.
fn markers_file(points: &[[f64; 3]]) -> tempfile::NamedTempFile {
    let mut f = tempfile::NamedTempFile::new().unwrap();
    writeln!(f, "x,y,z").unwrap();
    for p in points {
        writeln!(f, "{},{},{}", p[0], p[1], p[2]).unwrap();
    }
    f.flush().unwrap();
    f
}

/// A grid of `n^3` points spread over the box `[lo, hi]` (the corners included).
fn grid(lo: [f64; 3], hi: [f64; 3], n: usize) -> Vec<[f64; 3]> {
    let mut v = Vec::new();
    for i in 0..n {
        for j in 0..n {
            for k in 0..n {
                let t = [i, j, k].map(|a| a as f64 / (n - 1) as f64);
                v.push(std::array::from_fn(|c| lo[c] + t[c] * (hi[c] - lo[c])));
            }
        }
    }
    v
}

fn config(
    lo: [f64; 3],
    hi: [f64; 3],
    units: Units,
    markers: &Path,
    nu: f64,
    strains: &[f64],
) -> SpecimenConfig {
    SpecimenConfig {
        geometry: Geometry::Box { lo, hi },
        units,
        cells: Some(1),
        tolerance: None,
        symmetry: true,
        young_pa: E,
        poisson: nu,
        axis: Axis::Z,
        moving: End::Max,
        platens: Platens::Bonded,
        strains: strains.to_vec(),
        markers: markers.to_path_buf(),
        model: Model::Linear,
        display_law: None,
    }
}

/// Marker displacements of a level, in the markers' units.
fn displacements(level: &specimen::Level, points: &[[f64; 3]]) -> Vec<[f64; 3]> {
    level
        .markers
        .iter()
        .zip(points)
        .map(|(m, p)| std::array::from_fn(|c| m[c] - p[c]))
        .collect()
}

fn max_abs<'a>(v: impl IntoIterator<Item = &'a [f64; 3]>) -> f64 {
    v.into_iter().flatten().fold(0.0, |m, x| m.max(x.abs()))
}

/// At 1e-5 strain between bonded platens (a non-homogeneous field) the neo-Hookean markers and
/// platen force equal the linear ones to 1e-4 relative: the neo-Hookean model's tangent at rest
/// is the linear elasticity tensor, and its nonlinearity is of the order of the strain.
#[test]
fn large_equals_linear_at_small_strain() {
    let (lo, hi) = ([0.0, 0.0, 0.0], [20.0, 15.0, 10.0]);
    let points = grid([1.0, 1.0, 0.5], [19.0, 14.0, 9.5], 4);
    let f = markers_file(&points);
    let mut c = config(lo, hi, Units::Mm, f.path(), 0.3, &[1e-5, 2e-5]);
    let linear = specimen::run(&c).unwrap();
    c.model = Model::Large;
    let large = specimen::run(&c).unwrap();
    for (a, b) in linear.levels.iter().zip(&large.levels) {
        let (da, db) = (displacements(a, &points), displacements(b, &points));
        let diff: Vec<[f64; 3]> = da
            .iter()
            .zip(&db)
            .map(|(x, y)| std::array::from_fn(|k| x[k] - y[k]))
            .collect();
        let rel = max_abs(&diff) / max_abs(&da);
        let df = (a.platen_force_n / b.platen_force_n - 1.0).abs();
        println!("strain {}: markers {rel:.2e}, force {df:.2e}", a.strain);
        assert!(rel < 1e-4 && df < 1e-4, "markers {rel:e}, force {df:e}");
    }
}

/// 10 % between frictionless platens, compressed along x from the min face of an off-origin
/// box in millimetres: every marker's displacement is the homogeneous closed form to 1e-6 of
/// the platen travel (axial `s (x_max - x)`, lateral `(l - 1) (y - y_c)` from the held face's
/// centre), the platen force the closed form's to 1e-6.
#[test]
fn frictionless_platens_give_the_homogeneous_closed_form() {
    let (lo, hi) = ([10.0, -20.0, 5.0], [30.0, 10.0, 30.0]);
    let size = [20.0, 30.0, 25.0];
    let area_m2 = size[1] * size[2] * 1e-6;
    let centre = [0.0, -5.0, 17.5];
    let points = grid([10.0, -20.0, 5.0], [30.0, 10.0, 30.0], 5);
    let f = markers_file(&points);
    let s = 0.1;
    for (model, nu) in [
        (Model::Linear, 0.3),
        (Model::Large, 0.3),
        (Model::Large, 0.499),
    ] {
        let mut c = config(lo, hi, Units::Mm, f.path(), nu, &[s]);
        c.axis = Axis::X;
        c.moving = End::Min;
        c.platens = Platens::Frictionless;
        c.model = model;
        c.cells = Some(2);
        let r = specimen::run(&c).unwrap();
        let lambda = nu * E / ((1.0 + nu) * (1.0 - 2.0 * nu));
        let mu = E / (2.0 * (1.0 + nu));
        let (lateral, force) = match model {
            Model::Large => {
                let (l, p11) = uniaxial_stress(lambda, mu, 1.0 - s);
                (l - 1.0, -p11 * area_m2)
            }
            _ => (nu * s, E * s * area_m2),
        };
        let level = &r.levels[0];
        let travel = s * size[0];
        for (p, d) in points.iter().zip(displacements(level, &points)) {
            let want = [
                s * (hi[0] - p[0]),
                lateral * (p[1] - centre[1]),
                lateral * (p[2] - centre[2]),
            ];
            for k in 0..3 {
                assert!(
                    (d[k] - want[k]).abs() < 1e-6 * travel,
                    "{model:?} nu {nu}: marker {p:?} component {k}: {} vs {}",
                    d[k],
                    want[k]
                );
            }
        }
        println!(
            "{model:?} nu {nu}: force {:.9} N (closed form {force:.9}), lateral strain {lateral:.8}",
            level.platen_force_n
        );
        assert!((level.platen_force_n / force - 1.0).abs() < 1e-6);
    }
}

/// Largest distance between two lists of positions over the largest displacement in `d`.
fn relative_gap(a: &[[f64; 3]], b: &[[f64; 3]], d: &[[f64; 3]]) -> f64 {
    largest_difference(a, b).1 / max_abs(d)
}

/// The eighth equals the whole specimen solved on its mirror image (a mirror-symmetric mesh):
/// a box off the origin in mm, markers in all eight octants and on the symmetry planes,
/// compressed from either end along y between bonded or frictionless platens. Linear: markers
/// and force to 1e-9 relative; large (nu 0.45, 15 %): to 1e-6 (the Newton tolerance, 1e-8 of
/// the displacement norm, times the conditioning).
#[test]
fn the_eighth_equals_the_whole_mirror_symmetric_specimen() {
    let (lo, hi) = ([-10.0, 5.0, 2.0], [14.0, 25.0, 18.0]);
    let mut points = grid([-9.0, 6.0, 3.0], [13.0, 24.0, 17.0], 4);
    points.push([2.0, 15.0, 10.0]);
    points.push([2.0, 7.0, 16.5]);
    let f = markers_file(&points);
    for (model, platens, moving, tol) in [
        (Model::Linear, Platens::Bonded, End::Max, 1e-9),
        (Model::Linear, Platens::Frictionless, End::Min, 1e-9),
        (Model::Large, Platens::Bonded, End::Min, 1e-6),
        (Model::Large, Platens::Frictionless, End::Max, 1e-6),
    ] {
        let mut c = config(lo, hi, Units::Mm, f.path(), 0.45, &[0.15, 0.05]);
        c.axis = Axis::Y;
        c.model = model;
        c.platens = platens;
        c.moving = moving;
        c.cells = Some(2);
        let eighth = specimen::run(&c).unwrap();
        c.symmetry = false;
        let whole = specimen::run(&c).unwrap();
        assert!(eighth.symmetry && !whole.symmetry);
        for (a, b) in eighth.levels.iter().zip(&whole.levels) {
            let d = displacements(b, &points);
            let gap = relative_gap(&a.markers, &b.markers, &d);
            let df = (a.platen_force_n / b.platen_force_n - 1.0).abs();
            println!(
                "{model:?} {platens:?} {moving:?} strain {}: markers {gap:.1e}, force {df:.1e} \
                 ({:.6} N; {} vs {} nodes)",
                a.strain, b.platen_force_n, eighth.nodes, whole.nodes
            );
            assert!(gap < tol && df < tol, "markers {gap:e}, force {df:e}");
        }
    }
}

/// The convergence series: levels 2, 3, 4, ... cells along the eighth's longest side until the
/// largest marker change at the largest strain is within the tolerance. Its reported changes
/// are the differences between runs at those fixed levels, and it stops at the first level
/// within the tolerance (set between two measured changes here).
#[test]
fn the_mesh_is_refined_until_the_markers_converge() {
    let (lo, hi) = ([0.0; 3], [20.0, 20.0, 30.0]);
    let points = grid([0.0; 3], [20.0, 20.0, 30.0], 3);
    let f = markers_file(&points);
    let mut c = config(lo, hi, Units::Mm, f.path(), 0.3, &[0.05, 0.1]);
    let fixed: Vec<specimen::SpecimenReport> = [2, 3, 4]
        .iter()
        .map(|&n| {
            c.cells = Some(n);
            specimen::run(&c).unwrap()
        })
        .collect();
    let change = |i: usize| {
        largest_difference(&fixed[i].levels[1].markers, &fixed[i + 1].levels[1].markers).1
    };
    let (c23, c34) = (change(0), change(1));
    println!("changes: 2->3 cells {c23:.5} mm, 3->4 {c34:.5} mm");
    assert!(c34 < c23);
    c.cells = None;
    c.tolerance = Some(0.5 * (c23 + c34));
    let r = specimen::run(&c).unwrap();
    let levels = &r.convergence.levels;
    assert!(r.convergence.converged);
    assert_eq!(
        levels.iter().map(|l| l.cells).collect::<Vec<_>>(),
        [Some(2), Some(3), Some(4)]
    );
    assert_eq!(levels[0].change, None);
    for (l, want) in levels[1..].iter().zip([c23, c34]) {
        assert!(
            (l.change.unwrap() - want).abs() < 1e-9 * want,
            "{:?} vs {want}",
            l.change
        );
    }
    assert_eq!(r.levels, fixed[2].levels);
    assert_eq!(r.nodes, fixed[2].nodes);
}

/// `--mesh FILE`: the whole box's mirror-symmetric mesh written to a .msh file in mm gives
/// the answer of `--box ... --no-symmetry` at the same level, its units guessed (80 mm is an
/// organ's size in mm) when `--units` is not given.
#[test]
fn a_mesh_file_is_solved_whole() {
    let (lo, hi) = ([0.0; 3], [80.0, 60.0, 40.0]);
    let points = grid([1.0; 3], [79.0, 59.0, 39.0], 3);
    let f = markers_file(&points);
    let mut c = config(lo, hi, Units::Mm, f.path(), 0.3, &[0.1]);
    c.cells = Some(2);
    c.symmetry = false;
    let boxed = specimen::run(&c).unwrap();
    let mesh = whole(&box_part(lo, hi, 2).0, [40.0, 30.0, 20.0]);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("box.msh");
    let mut bytes = Vec::new();
    mesh.write_msh4_ascii(&mut bytes).unwrap();
    std::fs::write(&path, bytes).unwrap();
    c.geometry = Geometry::Mesh {
        path,
        guess_units: true,
    };
    c.units = Units::M;
    c.cells = None;
    let filed = specimen::run(&c).unwrap();
    assert_eq!(filed.units, "mm");
    assert_eq!((filed.cells, filed.convergence.tolerance), (None, None));
    let d = displacements(&boxed.levels[0], &points);
    let gap = relative_gap(&filed.levels[0].markers, &boxed.levels[0].markers, &d);
    let df = (filed.levels[0].platen_force_n / boxed.levels[0].platen_force_n - 1.0).abs();
    assert!(gap < 1e-12 && df < 1e-12, "markers {gap:e}, force {df:e}");
}

/// `--cylinder R,H` along x (Gmsh's eighth): between frictionless platens every marker, in
/// every octant, follows the homogeneous closed form (axial `s (H - x)` from the held max
/// face, radial `nu s r`) to 1e-3 of the travel (not exactly: the mesh's side facets join
/// nodes at different angles and heights, so they are not all parallel to the axis and the
/// uniaxial stress puts a small load on them; measured 8e-5), and the whole cylinder (the
/// eighth mirrored) between bonded platens gives the eighth's markers and force to 1e-9.
#[test]
fn a_cylinder_is_meshed_by_gmsh_and_solved_on_its_eighth() {
    let (r, h) = (10.0, 24.0);
    let mut points = vec![[12.0, 0.0, 0.0], [0.0, 0.0, 0.0], [24.0, 5.0, -5.0]];
    for (y, z) in [(3.0, 4.0), (-3.0, 4.0), (3.0, -4.0), (-3.0, -4.0)] {
        points.push([5.0, y, z]);
        points.push([19.0, y, z]);
    }
    let f = markers_file(&points);
    let nu = 0.3;
    let s = 0.1;
    let mut c = config([0.0; 3], [0.0; 3], Units::Mm, f.path(), nu, &[s]);
    c.geometry = Geometry::Cylinder {
        radius: r,
        height: h,
    };
    c.axis = Axis::X;
    c.moving = End::Min;
    c.platens = Platens::Frictionless;
    c.cells = Some(3);
    let free = specimen::run(&c).unwrap();
    assert_eq!(free.length, h);
    let mut worst = 0.0f64;
    for (p, d) in points.iter().zip(displacements(&free.levels[0], &points)) {
        let want = [s * (h - p[0]), nu * s * p[1], nu * s * p[2]];
        for k in 0..3 {
            worst = worst.max((d[k] - want[k]).abs() / (s * h));
            assert!(
                (d[k] - want[k]).abs() < 1e-3 * s * h,
                "marker {p:?} component {k}: {} vs {}",
                d[k],
                want[k]
            );
        }
    }
    // The faceted section's area is a little below pi R^2 (at most 4 % at 3 elements per
    // radius), so the force is E s A with A between the two.
    let disc = E * s * std::f64::consts::PI * (r * 1e-3).powi(2);
    let force = free.levels[0].platen_force_n;
    println!(
        "frictionless: markers {worst:.1e} of the travel, force {force:.6} N, E s pi R^2 {disc:.6} N"
    );
    assert!(force < disc && force > 0.96 * disc);
    c.platens = Platens::Bonded;
    let eighth = specimen::run(&c).unwrap();
    c.symmetry = false;
    let whole = specimen::run(&c).unwrap();
    let d = displacements(&whole.levels[0], &points);
    let gap = relative_gap(&eighth.levels[0].markers, &whole.levels[0].markers, &d);
    let df = (eighth.levels[0].platen_force_n / whole.levels[0].platen_force_n - 1.0).abs();
    println!(
        "bonded: markers {gap:.1e}, force {df:.1e} ({} vs {} nodes)",
        eighth.nodes, whole.nodes
    );
    assert!(gap < 1e-9 && df < 1e-9, "markers {gap:e}, force {df:e}");
}

/// `host specimen` with `args` ([`cli::run`]).
fn host(args: &[&str]) -> (bool, String, String) {
    cli::run(&[&["specimen"][..], args].concat())
}

/// Arguments of the CLI's JSON test: a 2 x 2 x 4 cm box along z, bonded, 5 and 10 %, the
/// markers file `m`, linear, 2 cells.
fn base_args(m: &str) -> [&str; 23] {
    [
        "--box",
        "0,0,0,2,2,4",
        "--units",
        "cm",
        "--young",
        "5000",
        "--poisson",
        "0.3",
        "--axis",
        "z",
        "--moving",
        "max",
        "--platens",
        "bonded",
        "--strain",
        "0.05,0.1",
        "--markers",
        m,
        "--model",
        "linear",
        "--cells",
        "2",
        "--json",
    ]
}

/// The CLI's JSON has its documented shape (docs/specimen.md): `levels`, each with its
/// `strain` and one `[x, y, z]` per marker in the markers' units; the held face's markers do
/// not move axially. `convergence` has one level with `--cells`; without it, the series with
/// the default tolerance (1 % of the largest travel), stopped at the first level within it,
/// each level's progress on stderr.
#[test]
fn cli_prints_levels_of_markers_as_json() {
    let f = markers_file(&[[1.0, 1.0, 0.0], [2.0, 1.5, 4.0], [1.0, 1.0, 3.0]]);
    let m = f.path().to_str().unwrap();
    let (ok, out, err) = host(&base_args(m));

    assert!(ok, "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    let levels = v["levels"].as_array().unwrap();
    assert_eq!(levels.len(), 2);
    for (level, s) in levels.iter().zip([0.05, 0.1]) {
        assert_eq!(level["strain"].as_f64().unwrap(), s);
        let markers = level["markers"].as_array().unwrap();
        assert_eq!(markers.len(), 3);
        // Bottom face held: that marker stays put; the top-face marker moves down by s * 4 cm
        // and not laterally (bonded).
        let at = |i: usize, k: usize| markers[i][k].as_f64().unwrap();
        assert!((at(0, 2) - 0.0).abs() < 1e-12 && (at(0, 0) - 1.0).abs() < 1e-12);
        assert!((at(1, 2) - (4.0 - 4.0 * s)).abs() < 1e-12);
        assert!((at(1, 0) - 2.0).abs() < 1e-12 && (at(1, 1) - 1.5).abs() < 1e-12);
    }
    assert_eq!(v["convergence"]["levels"].as_array().unwrap().len(), 1);
    assert!(v["convergence"]["tolerance"].is_null());
    // Without --cells: the series, its tolerance 1 % of the largest travel (0.1 * 4 cm).
    let mut args: Vec<&str> = base_args(m).to_vec();
    args.retain(|a| *a != "--cells" && *a != "2");
    let (ok, out, err) = host(&args);
    assert!(ok, "{err}");
    assert!(err.contains("level 2 cells"), "progress on stderr: {err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    let c = &v["convergence"];
    let tolerance = c["tolerance"].as_f64().unwrap();
    assert!((tolerance - 0.004).abs() < 1e-15, "{tolerance}");
    let levels = c["levels"].as_array().unwrap();
    let last = levels.last().unwrap()["change"].as_f64().unwrap();
    assert!(c["converged"].as_bool().unwrap() && last <= tolerance);
    assert!(
        levels[..levels.len() - 1][1..]
            .iter()
            .all(|l| l["change"].as_f64().unwrap() > tolerance)
    );
    assert_eq!(v["cells"], levels.last().unwrap()["cells"]);
}

/// Bad inputs exit non-zero with a message naming the input and where it is wrong.
#[test]
fn bad_inputs_are_refused_with_what_and_where() {
    let f = markers_file(&[[1.0, 1.0, 1.0], [1.0, 2.5, 1.0]]);
    let m = f.path().to_str().unwrap();
    let base = |strain: &'static str, axis: &'static str| {
        vec![
            "--box",
            "0,0,0,2,2,4",
            "--units",
            "cm",
            "--young",
            "5000",
            "--poisson",
            "0.3",
            "--axis",
            axis,
            "--moving",
            "max",
            "--platens",
            "bonded",
            "--strain",
            strain,
            "--markers",
            m,
            "--model",
            "linear",
            "--cells",
            "2",
        ]
    };
    // The second marker (line 3 of the file) is outside the box.
    let (ok, _, err) = host(&base("0.1", "z"));
    assert!(!ok);
    assert!(
        err.contains("line 3") && err.contains("outside the specimen"),
        "{err}"
    );
    for (strain, what) in [
        ("0.1,abc", "item 2 (\"abc\") is not a finite number"),
        ("0.1,1.5", "item 2 is 1.5"),
        ("0", "item 1 is 0"),
    ] {
        let (ok, _, err) = host(&base(strain, "z"));
        assert!(
            !ok && err.contains("--strain") && err.contains(what),
            "{strain}: {err}"
        );
    }
    let (ok, _, err) = host(&base("0.1", "w"));
    assert!(
        !ok && err.contains("--axis") && err.contains("'w'"),
        "{err}"
    );
    let mut args = base("0.1", "z");
    args[1] = "0,0,0,2,2";
    let (ok, _, err) = host(&args);
    assert!(
        !ok && err.contains("--box") && err.contains("need 6"),
        "{err}"
    );
    let mut args = base("0.1", "z");
    let model = args.len() - 3;
    args[model] = "linear-p";
    let (ok, _, err) = host(&args);
    assert!(
        !ok && err.contains("linear-p needs a display law P"),
        "{err}"
    );
    // A mesh file whose top is one vertex: no platen face there.
    let dir = tempfile::tempdir().unwrap();
    let tet = dir.path().join("tet.msh");
    let mesh = fem::mesh::TetMesh {
        nodes: vec![
            [0.0; 3],
            [0.02, 0.0, 0.0],
            [0.0, 0.02, 0.0],
            [0.0, 0.0, 0.04],
        ],
        tets: vec![[0, 1, 2, 3]],
    };
    let mut bytes = Vec::new();
    mesh.write_msh4_ascii(&mut bytes).unwrap();
    std::fs::write(&tet, bytes).unwrap();
    let f = markers_file(&[[0.001, 0.001, 0.001]]);
    let mut args = base("0.1", "z");
    args.splice(0..4, ["--mesh", tet.to_str().unwrap(), "--units", "m"]);
    let i = args.iter().position(|a| *a == "--markers").unwrap();
    args[i + 1] = f.path().to_str().unwrap();
    let i = args.iter().position(|a| *a == "--cells").unwrap();
    args.drain(i..i + 2);
    let (ok, _, err) = host(&args);
    assert!(
        !ok && err.contains("moving platen face") && err.contains("has 1 node"),
        "{err}"
    );
    args.extend(["--cells", "3"]);
    let (ok, _, err) = host(&args);
    assert!(
        !ok && err.contains("--cells") && err.contains("own resolution"),
        "{err}"
    );
}

/// The 80 mm gel cube (nu 0.499, E 5 kPa, bonded, compressed along z from the top, 5, 12.5
/// and 18.25 %) with markers on a 1 cm grid (729, the faces included): each model along its
/// convergence series on the eighth (default tolerance), its levels and wall time, and per
/// strain the largest marker error of `linear` against `large`'s converged answer. Solves at
/// a fixed level too with `SPECIMEN_CELLS=N` (e.g. to time a level alone).
#[test]
#[ignore = "a minute or more: run with --ignored --nocapture for docs/specimen.md"]
fn gel_cube_80mm_linear_vs_large() {
    let points = grid([0.0; 3], [80.0; 3], 9);
    let f = markers_file(&points);
    let mut c = config(
        [0.0; 3],
        [80.0; 3],
        Units::Mm,
        f.path(),
        0.499,
        &[0.05, 0.125, 0.1825],
    );
    c.cells = std::env::var("SPECIMEN_CELLS")
        .ok()
        .map(|v| v.trim().parse().expect("SPECIMEN_CELLS: an integer"));
    let mut reports = Vec::new();
    for model in [Model::Linear, Model::Large] {
        c.model = model;
        let t = Instant::now();
        let r =
            specimen::run_with_progress(&c, &mut |line| println!("  {model:?}: {line}")).unwrap();
        println!(
            "{model:?}: {:.1} s in all, {} nodes at {:?} cells, converged {} (tolerance {:?} mm)",
            t.elapsed().as_secs_f64(),
            r.nodes,
            r.cells,
            r.convergence.converged,
            r.convergence.tolerance
        );
        reports.push(r);
    }
    let (linear, large) = (&reports[0], &reports[1]);
    for (a, b) in linear.levels.iter().zip(&large.levels) {
        let (i, d) = largest_difference(&a.markers, &b.markers);
        println!(
            "  strain {}: force linear {:.4} N, large {:.4} N; linear's largest marker error \
             {d:.3} mm at {:?} (travel {:.2} mm)",
            a.strain,
            a.platen_force_n,
            b.platen_force_n,
            points[i],
            a.strain * 80.0
        );
    }
}

/// The marker with the largest distance between two predictions, and that distance.
fn largest_difference(a: &[[f64; 3]], b: &[[f64; 3]]) -> (usize, f64) {
    a.iter()
        .zip(b)
        .map(|(x, y)| (0..3).map(|k| (x[k] - y[k]).powi(2)).sum::<f64>().sqrt())
        .enumerate()
        .fold((0, 0.0), |m, (i, d)| if d > m.1 { (i, d) } else { m })
}
