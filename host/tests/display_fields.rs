//! The default (sampled) scene's display fields against direct solves: at
//! lattice points of the collision surface, `u = U(p) F` on the fine FEM surface equals the
//! P1 body's displacement under the tool load scaled to the bank's `W` (computed here with
//! `Compliance::displacement`, one solve per load, not the fields' chunked solves), and the
//! load-weighted mean displacement under the tool is `W F`, the tip's displacement; the cache
//! file round-trips and a damaged one is refused.

use bank_format::{AlignedBytes, Bank};
use haptic::bank::Prepared;
use haptic::bank::cache::scene_bank_cached;
use haptic::bank::sampled::lattice_points;
use haptic::display::fields::DisplayFields;
use haptic::scene::ContactModel;
use std::path::Path;

#[test]
fn fields_match_direct_solves_and_put_the_tool_at_w_f() {
    let scene = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/liver.toml");
    let prep = Prepared::load(&scene).unwrap();
    let ContactModel::Sampled(spec) = &prep.organ.scene.contact else {
        panic!("the default scene is sampled");
    };
    let (built, _) = scene_bank_cached(&prep, None).unwrap();
    let aligned = AlignedBytes::new(&built.bytes);
    let bank = Bank::parse(&aligned).unwrap();
    let samples = bank.samples().unwrap();
    let (fields, _) = DisplayFields::cached(&prep, &bank, None).unwrap().unwrap();

    // The P1 body of the FEM mesh, built here on its own.
    let mesh = fem::mesh::load(&spec.fem_mesh).unwrap();
    let boundary = fem::mesh::boundary(&mesh).unwrap();
    assert_eq!(fields.mesh.rest.len(), boundary.nodes.len());
    for (r, &n) in fields.mesh.rest.iter().zip(&boundary.nodes) {
        assert_eq!(*r, mesh.nodes[n].map(|x| x as f32));
    }
    let fixed = prep.organ.scene.fixed_set(&mesh).unwrap();
    let body = fem::elasticity::Elasticity::with_element(
        &mesh,
        prep.organ.scene.material,
        Default::default(),
    )
    .unwrap();
    let c = fem::compliance::Compliance::factorize(&body, &fixed).unwrap();
    let tool = fem::tool::ToolSurface::linear(&mesh, &boundary).unwrap();
    let radius = f64::from(samples.tip_radius_m());
    let (lattice, points) =
        lattice_points(&prep.region.positions, &prep.region.triangles, spec.level);
    let display_index = |n: usize| boundary.nodes.binary_search(&n).unwrap();

    let force = [0.02f32, -0.01, 0.1];
    let mut u = Vec::new();
    for s in (0..points.len()).step_by(points.len() / 6) {
        let (t, b) = lattice.points[s];
        fields.displacement(t as u32, b.map(|x| x as f32), force, &mut u);
        let load = tool
            .tool_weights(tool.closest_point(points[s]).point, radius)
            .unwrap();
        let w6 = samples.sample(s).unwrap().map(f64::from);
        let w = [
            [w6[0], w6[1], w6[2]],
            [w6[1], w6[3], w6[4]],
            [w6[2], w6[4], w6[5]],
        ];
        let f = force.map(f64::from);
        let d: [f64; 3] = std::array::from_fn(|i| (0..3).map(|j| w[i][j] * f[j]).sum());
        // The tool's weighted mean displacement is W F.
        let mean: [f64; 3] = std::array::from_fn(|i| {
            load.iter()
                .map(|&(n, wt)| wt * f64::from(u[display_index(n)][i]))
                .sum()
        });
        let err = (0..3).map(|i| (mean[i] - d[i]).powi(2)).sum::<f64>().sqrt()
            / d.iter().map(|x| x * x).sum::<f64>().sqrt();
        assert!(
            err < 5e-3,
            "sample {s}: mean {mean:?} vs W F {d:?} ({err:.1e})"
        );

        // Direct: the P1 load that moves the tool's mean point by d, one solve each.
        let under = |g: [f64; 3]| {
            let mut forces = vec![0.0; 3 * mesh.nodes.len()];
            for &(n, wt) in &load {
                for i in 0..3 {
                    forces[3 * n + i] += wt * g[i];
                }
            }
            c.displacement(&forces)
        };
        let mut w_p1 = [[0.0; 3]; 3];
        for k in 0..3 {
            let x = under(std::array::from_fn(|i| f64::from(u8::from(i == k))));
            for (r, row) in w_p1.iter_mut().enumerate() {
                row[k] = load.iter().map(|&(n, wt)| wt * x[3 * n + r]).sum();
            }
        }
        let direct = under(haptic::linalg::solve3(&w_p1, d));
        let (mut worst, mut peak) = (0.0f64, 0.0f64);
        for (i, &n) in boundary.nodes.iter().enumerate() {
            for r in 0..3 {
                worst = worst.max((f64::from(u[i][r]) - direct[3 * n + r]).abs());
                peak = peak.max(direct[3 * n + r].abs());
            }
        }
        assert!(
            worst <= 2e-3 * peak,
            "sample {s}: fields off the direct solve by {worst:.2e} m of {peak:.2e} m"
        );
    }

    // The cache file round-trips; a truncated or padded one is an error, not a panic.
    let bytes = fields.encode();
    assert_eq!(DisplayFields::decode(&bytes).unwrap(), fields);
    let cut = DisplayFields::decode(&bytes[..bytes.len() - 3]).unwrap_err();
    assert!(cut.to_string().contains("truncated"), "{cut}");
    let mut long = bytes.clone();
    long.push(0);
    assert!(DisplayFields::decode(&long).is_err());
    let mut magic = bytes;
    magic[0] = b'X';
    assert!(DisplayFields::decode(&magic).is_err());
    // A point off the bank's triangles shows no displacement.
    fields.displacement(u32::MAX, [1.0, 0.0, 0.0], force, &mut u);
    assert!(u.iter().flatten().all(|&x| x == 0.0));
}
