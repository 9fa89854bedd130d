//! `Compliance::blocks` (sparse forward substitution and Gram product) against columns of
//! `C = K_ff^-1` computed one by one with full solves (`Compliance::displacement` of unit
//! forces), for both orderings, partly fixed nodes and bad requests.

use fem::compliance::{Block3, Compliance, ComplianceError};
use fem::elasticity::{Elasticity, FemError, FixedSet, Material};
use fem::mesh::TetMesh;
use fem::mesh::structured::box_mesh;
use fem::ordering::Ordering;
use std::path::Path;

fn liver() -> TetMesh {
    fem::mesh::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("../meshes/liver-1k4.msh")).unwrap()
}

fn bedded(mesh: &TetMesh) -> (Elasticity, FixedSet) {
    let body = Elasticity::new(mesh, Material::new(3.0e3, 0.45).unwrap()).unwrap();
    let mut fixed = FixedSet::none(mesh.nodes.len());
    fixed
        .fix_box(mesh, [-1.0, -1.0, -1.0, 1.0, 1.0, 0.01], [true; 3])
        .unwrap();
    (body, fixed)
}

/// `C(nodes[a], nodes[b])` from one full solve per unit force.
fn by_columns(c: &Compliance, nodes: &[usize]) -> Vec<Vec<Block3>> {
    let n = c.dofs().nodes();
    let mut out = vec![vec![[[0.0; 3]; 3]; nodes.len()]; nodes.len()];
    for (b, &l) in nodes.iter().enumerate() {
        for col in 0..3 {
            if c.dofs().free_dof(l, col).is_none() {
                continue;
            }
            let mut f = vec![0.0; 3 * n];
            f[3 * l + col] = 1.0;
            let u = c.displacement(&f);
            for (a, &k) in nodes.iter().enumerate() {
                for row in 0..3 {
                    out[a][b][row][col] = u[3 * k + row];
                }
            }
        }
    }
    out
}

fn assert_agree(got: &[Vec<Block3>], want: &[Vec<Block3>], what: &str) {
    let flat = |b: &[Vec<Block3>]| -> Vec<f64> {
        b.iter().flatten().flatten().flatten().copied().collect()
    };
    let (g, w) = (flat(got), flat(want));
    assert_eq!(g.len(), w.len(), "{what}");
    let scale = w.iter().fold(0.0f64, |s, v| s.max(v.abs()));
    let diff = g
        .iter()
        .zip(&w)
        .fold(0.0f64, |s, (a, b)| s.max((a - b).abs()));
    eprintln!("{what}: max |difference| / max |C| = {:.1e}", diff / scale);
    assert!(diff <= 1e-10 * scale, "{what}: {diff:e} vs {scale:e}");
}

fn free_surface(mesh: &TetMesh, fixed: &FixedSet) -> Vec<usize> {
    fem::mesh::boundary(mesh)
        .unwrap()
        .nodes
        .into_iter()
        .filter(|&i| (0..3).all(|c| !fixed.is_fixed(i, c)))
        .collect()
}

#[test]
fn liver_free_surface_matches_column_solves_for_both_orderings() {
    let mesh = liver();
    let (body, fixed) = bedded(&mesh);
    let nodes = free_surface(&mesh, &fixed);
    assert_eq!(nodes.len(), 470);
    for ordering in [Ordering::NestedDissection, Ordering::Amd] {
        let c = Compliance::factorize_ordered(&body, &fixed, ordering).unwrap();
        // Every third node for the (slow) reference, in a scrambled order.
        let sample: Vec<usize> = nodes.iter().rev().step_by(3).copied().collect();
        assert_agree(
            &c.blocks(&sample, None).unwrap(),
            &by_columns(&c, &sample),
            &format!("liver-1k4 {ordering:?}"),
        );
    }
}

#[test]
fn partly_fixed_nodes_get_zero_rows_and_columns() {
    let mesh = liver();
    let (body, mut fixed) = bedded(&mesh);
    // A slide-only wall: the nodes with the smallest x may only move in y and z.
    let (lo, hi) = mesh.bounding_box();
    let wall = lo[0] + 0.1 * (hi[0] - lo[0]);
    fixed
        .fix_box(
            &mesh,
            [-1.0, -1.0, -1.0, wall, 1.0, 1.0],
            [true, false, false],
        )
        .unwrap();
    let surface = fem::mesh::boundary(&mesh).unwrap().nodes;
    let partial = surface
        .iter()
        .copied()
        .filter(|&i| fixed.is_fixed(i, 0) && !fixed.is_fixed(i, 1));
    let full = surface.iter().copied().filter(|&i| fixed.is_fixed(i, 2));
    let free = free_surface(&mesh, &fixed);
    let mut nodes: Vec<usize> = partial.take(15).chain(full.take(5)).collect();
    nodes.extend(free.iter().rev().take(40));
    let c = Compliance::factorize(&body, &fixed).unwrap();
    let blocks = c.blocks(&nodes, None).unwrap();
    assert_agree(
        &blocks,
        &by_columns(&c, &nodes),
        "liver-1k4 with a slide-only wall",
    );
    for (&k, row) in nodes.iter().zip(&blocks) {
        for (&l, block) in nodes.iter().zip(row) {
            for (r, block_row) in block.iter().enumerate() {
                for (col, &v) in block_row.iter().enumerate() {
                    let fixed_entry = fixed.is_fixed(k, r) || fixed.is_fixed(l, col);
                    assert_eq!(v == 0.0, fixed_entry, "C({k},{l})[{r}][{col}] = {v}");
                }
            }
        }
    }
}

#[test]
fn every_node_of_a_box_matches_column_solves() {
    let mesh = box_mesh([0.06, 0.04, 0.03], [6, 4, 3]);
    let body = Elasticity::new(&mesh, Material::new(3.0e3, 0.45).unwrap()).unwrap();
    let mut fixed = FixedSet::none(mesh.nodes.len());
    fixed
        .fix_box(&mesh, [-1.0, -1.0, -1.0, 1.0, 1.0, 1e-9], [true; 3])
        .unwrap();
    let c = Compliance::factorize(&body, &fixed).unwrap();
    let all: Vec<usize> = (0..mesh.nodes.len()).collect();
    assert_agree(
        &c.blocks(&all, None).unwrap(),
        &by_columns(&c, &all),
        "box, every node",
    );
    assert_agree(
        &c.blocks(&[40], None).unwrap(),
        &by_columns(&c, &[40]),
        "box, one node",
    );
    assert!(c.blocks(&[], None).unwrap().is_empty());
}

#[test]
fn bad_requests_are_refused() {
    let mesh = box_mesh([0.03, 0.02, 0.02], [3, 2, 2]);
    let n = mesh.nodes.len();
    let body = Elasticity::new(&mesh, Material::new(3.0e3, 0.45).unwrap()).unwrap();
    let mut fixed = FixedSet::none(n);
    fixed
        .fix_box(&mesh, [-1.0, -1.0, -1.0, 1.0, 1.0, 1e-9], [true; 3])
        .unwrap();
    let c = Compliance::factorize(&body, &fixed).unwrap();
    assert!(matches!(
        c.blocks(&[n - 1, n], None),
        Err(ComplianceError::NoSuchNode { node, nodes }) if node == n && nodes == n
    ));
    assert!(matches!(
        c.blocks(&[n - 1, 4, n - 1], None),
        Err(ComplianceError::DegenerateContact(_))
    ));
    assert!(matches!(
        Compliance::factorize(&body, &FixedSet::none(n + 3)),
        Err(ComplianceError::Fem(FemError::FixedSetMismatch { .. }))
    ));
}

#[test]
fn blocks_within_a_radius_are_the_near_pairs_of_all_blocks() {
    let mesh = liver();
    let (body, fixed) = bedded(&mesh);
    let nodes = free_surface(&mesh, &fixed);
    let positions: Vec<[f64; 3]> = nodes.iter().map(|&k| mesh.nodes[k]).collect();
    let c = Compliance::factorize(&body, &fixed).unwrap();
    let all = c.blocks(&nodes, None).unwrap();
    let radius = 0.012;
    let near = c.blocks_within(&nodes, &positions, radius, None).unwrap();
    let scale = all
        .iter()
        .flatten()
        .flatten()
        .flatten()
        .fold(0.0f64, |s, v| s.max(v.abs()));
    let mut kept = 0;
    for (a, row) in near.iter().enumerate() {
        let expected: Vec<usize> = (0..nodes.len())
            .filter(|&b| {
                (0..3)
                    .map(|i| (positions[a][i] - positions[b][i]).powi(2))
                    .sum::<f64>()
                    <= radius * radius
            })
            .collect();
        let got: Vec<usize> = row.iter().map(|e| e.0).collect();
        assert_eq!(got, expected, "pairs of node {}", nodes[a]);
        for (b, block) in row {
            for i in 0..3 {
                for j in 0..3 {
                    assert!((block[i][j] - all[a][*b][i][j]).abs() <= 1e-14 * scale);
                }
            }
        }
        kept += row.len();
    }
    eprintln!(
        "{} nodes, {kept} ordered pairs within {radius} m",
        nodes.len()
    );
    assert!(kept > nodes.len() && kept < nodes.len() * nodes.len() / 4);
}
