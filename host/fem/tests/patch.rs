//! `Compliance::patch_compliances` against the compliance blocks of `Compliance::blocks`
//! (`W = sum_a sum_b w_a w_b C_ab`), on the liver with P1 and P2 bodies and tool loads from
//! [`fem::tool::ToolSurface`], and its errors.

use fem::compliance::{Block3, Compliance, ComplianceError};
use fem::elasticity::quadratic::QuadraticBody;
use fem::elasticity::{Elasticity, FixedSet, Material, Stiffness};
use fem::mesh::TetMesh;
use fem::tool::ToolSurface;
use std::path::Path;

fn liver() -> TetMesh {
    fem::mesh::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("../meshes/liver-1k4.msh")).unwrap()
}

/// The bed `z <= 0.01` fixed.
fn bed(positions: &[[f64; 3]]) -> FixedSet {
    let mut fixed = FixedSet::none(positions.len());
    for (i, p) in positions.iter().enumerate() {
        if p[2] <= 0.01 {
            fixed.fix_node(i).unwrap();
        }
    }
    fixed
}

/// `sum_a sum_b w_a w_b C_ab` from the blocks of the load's nodes.
fn from_blocks(c: &Compliance, load: &[(usize, f64)]) -> Block3 {
    let mut nodes: Vec<usize> = load.iter().map(|e| e.0).collect();
    nodes.sort_unstable();
    nodes.dedup();
    let blocks = c.blocks(&nodes, None).unwrap();
    let at = |n: usize| nodes.binary_search(&n).unwrap();
    let mut w = [[0.0; 3]; 3];
    for &(a, wa) in load {
        for &(b, wb) in load {
            let block = blocks[at(a)][at(b)];
            for i in 0..3 {
                for j in 0..3 {
                    w[i][j] += wa * wb * block[i][j];
                }
            }
        }
    }
    w
}

fn relative_difference(got: &Block3, want: &Block3) -> f64 {
    let scale = want.iter().flatten().fold(0.0f64, |m, v| m.max(v.abs()));
    got.iter()
        .flatten()
        .zip(want.iter().flatten())
        .map(|(g, w)| (g - w).abs() / scale)
        .fold(0.0, f64::max)
}

/// Symmetric, and positive definite by its leading minors, unless the load lies wholly on
/// fixed nodes (then zero).
fn assert_spd(w: &Block3, load: &[(usize, f64)], fixed: &FixedSet) {
    if load.iter().all(|e| fixed.is_fixed(e.0, 0)) {
        assert_eq!(*w, [[0.0; 3]; 3]);
        return;
    }
    let transposed: Block3 = std::array::from_fn(|i| std::array::from_fn(|j| w[j][i]));
    assert_eq!(*w, transposed);
    let m1 = w[0][0];
    let m2 = w[0][0] * w[1][1] - w[0][1] * w[1][0];
    let m3 = w[0][0] * (w[1][1] * w[2][2] - w[1][2] * w[2][1])
        - w[0][1] * (w[1][0] * w[2][2] - w[1][2] * w[2][0])
        + w[0][2] * (w[1][0] * w[2][1] - w[1][1] * w[2][0]);
    assert!(m1 > 0.0 && m2 > 0.0 && m3 > 0.0, "{w:?}");
}

/// Tool loads at a spread of surface points, radii 0 to 1 cm, some reaching the bed.
fn tool_loads(mesh: &TetMesh, tool: &ToolSurface) -> Vec<Vec<(usize, f64)>> {
    let surface = fem::mesh::boundary(mesh).unwrap();
    let mut loads = Vec::new();
    for (k, &v) in surface.nodes.iter().step_by(37).enumerate() {
        let radius = [0.0, 0.002, 0.004, 0.01][k % 4];
        loads.push(tool.tool_weights(mesh.nodes[v], radius).unwrap());
    }
    // Near the bed: some weights fall on fixed nodes.
    let low = surface
        .nodes
        .iter()
        .copied()
        .find(|&v| (0.009..0.011).contains(&mesh.nodes[v][2]))
        .unwrap();
    loads.push(tool.tool_weights(mesh.nodes[low], 0.006).unwrap());
    loads
}

#[test]
fn single_node_loads_give_the_diagonal_blocks() {
    let mesh = liver();
    let body = Elasticity::new(&mesh, Material::new(3.0e3, 0.45).unwrap()).unwrap();
    let c = Compliance::factorize(&body, &bed(&mesh.nodes)).unwrap();
    let nodes: Vec<usize> = fem::mesh::boundary(&mesh)
        .unwrap()
        .nodes
        .into_iter()
        .step_by(5)
        .collect();
    let loads: Vec<Vec<(usize, f64)>> = nodes.iter().map(|&n| vec![(n, 1.0)]).collect();
    let w = c.patch_compliances(&loads, None).unwrap();
    for (k, &n) in nodes.iter().enumerate() {
        let block = c.blocks(&[n], None).unwrap()[0][0];
        if block == [[0.0; 3]; 3] {
            assert_eq!(w[k], block, "fixed node {n}");
            continue;
        }
        let err = relative_difference(&w[k], &block);
        assert!(err < 1e-12, "node {n}: {err:e}");
        assert_spd(&w[k], &loads[k], &bed(&mesh.nodes));
    }
}

#[test]
fn tool_loads_match_the_blocks_p1() {
    let mesh = liver();
    let body = Elasticity::new(&mesh, Material::new(3.0e3, 0.45).unwrap()).unwrap();
    let c = Compliance::factorize(&body, &bed(&mesh.nodes)).unwrap();
    let tool = ToolSurface::linear(&mesh, &fem::mesh::boundary(&mesh).unwrap()).unwrap();
    let loads = tool_loads(&mesh, &tool);
    let fixed = bed(&mesh.nodes);
    assert!(
        loads
            .iter()
            .any(|l| l.iter().any(|e| fixed.is_fixed(e.0, 0))
                && l.iter().any(|e| !fixed.is_fixed(e.0, 0)))
    );
    check_against_blocks("p1", &c, &loads, &fixed);
}

#[test]
fn tool_loads_match_the_blocks_p2() {
    let mesh = liver();
    let body = QuadraticBody::new(&mesh, Material::new(3.0e3, 0.45).unwrap()).unwrap();
    let fixed = bed(body.positions());
    let c = Compliance::factorize(&body, &fixed).unwrap();
    assert_eq!(c.dofs().nodes(), body.nodes());
    let tool = ToolSurface::quadratic(&mesh, &fem::mesh::boundary(&mesh).unwrap(), &body).unwrap();
    let loads = tool_loads(&mesh, &tool);
    assert!(loads.iter().any(|l| l.iter().any(|e| e.1 < 0.0)));
    check_against_blocks("p2", &c, &loads, &fixed);
}

/// Every load's `W` from [`Compliance::patch_compliances`] equals `sum w_a w_b C_ab` from the
/// blocks (1e-12 relative) and is symmetric positive definite (zero when wholly on `fixed`).
fn check_against_blocks(name: &str, c: &Compliance, loads: &[Vec<(usize, f64)>], fixed: &FixedSet) {
    let w = c.patch_compliances(loads, None).unwrap();
    let mut worst = 0.0f64;
    for (load, w) in loads.iter().zip(&w) {
        let err = relative_difference(w, &from_blocks(c, load));
        worst = worst.max(err);
        assert!(err < 1e-12, "{err:e}");
        assert_spd(w, load, fixed);
    }
    eprintln!(
        "{name}: {} loads, worst relative difference {worst:.1e}",
        loads.len()
    );
}

#[test]
fn repeated_nodes_add_up_and_bad_loads_are_errors() {
    let mesh = liver();
    let body = Elasticity::new(&mesh, Material::new(3.0e3, 0.45).unwrap()).unwrap();
    let c = Compliance::factorize(&body, &bed(&mesh.nodes)).unwrap();
    let top = (0..mesh.nodes.len())
        .max_by(|&a, &b| mesh.nodes[a][2].total_cmp(&mesh.nodes[b][2]))
        .unwrap();
    let other = top + 1;
    let split = vec![(top, 0.25), (other, 0.5), (top, 0.25)];
    let merged = vec![(top, 0.5), (other, 0.5)];
    let w = c.patch_compliances(&[split, merged], None).unwrap();
    assert!(relative_difference(&w[0], &w[1]) < 1e-14);
    assert!(c.patch_compliances(&[], None).unwrap().is_empty());

    let n = mesh.nodes.len();
    let e = c
        .patch_compliances(&[vec![(top, 1.0)], vec![(n, 1.0)]], None)
        .unwrap_err();
    assert!(matches!(e, ComplianceError::NoSuchNode { node, nodes } if node == n && nodes == n));
    let e = c
        .patch_compliances(&[vec![(top, 1.0)], vec![]], None)
        .unwrap_err();
    assert_eq!(e.to_string(), "patch load 1 is invalid: it has no node");
    let e = c
        .patch_compliances(&[vec![(top, f64::NAN)]], None)
        .unwrap_err();
    assert_eq!(
        e.to_string(),
        format!("patch load 0 is invalid: node {top} has the weight NaN")
    );
}
