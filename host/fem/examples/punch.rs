//! Issue 18's locking measurement: a frictionless flat punch pressed into the top of the liver,
//! P1 and the ANP element against 10-node tetrahedra (P2, the reference) on the same mesh,
//! plus the assembly / factorisation cost of each.
//!
//! ```sh
//! cargo run -p fem --profile checked --example punch                 # liver-1k4, liver-10k
//! cargo run -p fem --profile checked --example punch -- --refine      # + each mesh split 1:8
//! ```
//!
//! Setup: the bed `z <= z_min + 10 mm` is fixed; the boundary nodes of the upper surface
//! (`z > z_mid`; for P2 the vertices and edge nodes of the boundary triangles) within 10 mm
//! (horizontally) of the top centre (the highest vertex) take a uniform `u_z = -5 mm`, with
//! `x`, `y` free (frictionless); the punch force is minus the sum of their `z` reactions.
//! E = 3 kPa (the force is linear in E). `--refine` adds each mesh split 1:8 (same geometry);
//! P2 runs where it has at most [`P2_MAX_NODES`] nodes (liver-10k split would have 0.55 M).

use fem::compliance::{Compliance, solve_prescribed};
use fem::elasticity::quadratic::QuadraticBody;
use fem::elasticity::{DofMap, Elasticity, Element, FixedSet, Material, Stiffness};
use fem::mesh::TetMesh;
use fem::ordering::{Ordering, permutation};
use std::collections::HashMap;
use std::path::Path;
use std::time::Instant;

const POISSON: [f64; 3] = [0.45, 0.49, 0.499];
const ALPHAS: [f64; 5] = [0.0, 0.001, 0.003, 0.01, 0.1];
/// Largest P2 body solved (about 40 s and 2.5 GiB at 72k nodes on 2 cores).
const P2_MAX_NODES: usize = 200_000;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let refine = std::env::args().any(|a| a == "--refine");
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../meshes");
    let mut meshes = Vec::new();
    for name in ["liver-1k4", "liver-10k"] {
        let mesh = fem::mesh::load(&dir.join(format!("{name}.msh")))?;
        if refine {
            meshes.push((name.to_string(), mesh.clone()));
            meshes.push((format!("{name} split 1:8"), split_1_to_8(&mesh)));
        } else {
            meshes.push((name.to_string(), mesh));
        }
    }
    for (name, mesh) in &meshes {
        let setup = Punch::new(mesh, mesh.nodes.clone(), |_, _| None)?;
        println!(
            "{name}: {} nodes, {} tets, {} bed nodes, {} punch nodes",
            mesh.nodes.len(),
            mesh.tets.len(),
            setup.bed.count() / 3,
            setup.contact.len()
        );
        for element in Element::ALL {
            let body = Elasticity::with_element(mesh, Material::new(3.0e3, 0.49)?, element)?;
            cost(&body, &setup.bed, element.name())?;
        }
        let body = QuadraticBody::new(mesh, Material::new(3.0e3, 0.49)?)?;
        let p2 = if body.nodes() <= P2_MAX_NODES {
            let setup = Punch::new(mesh, body.positions().to_vec(), |a, b| body.edge_node(a, b))?;
            println!(
                "  p2: {} nodes, {} bed nodes, {} punch nodes",
                body.nodes(),
                setup.bed.count() / 3,
                setup.contact.len()
            );
            cost(&body, &setup.bed, "p2")?;
            Some(setup)
        } else {
            println!("  p2: skipped ({} nodes > {P2_MAX_NODES})", body.nodes());
            None
        };
        for nu in POISSON {
            let material = Material::new(3.0e3, nu)?;
            let mut line = format!("  nu={nu:<6}");
            let mut forces = Vec::new();
            for element in Element::ALL {
                let f = setup.force(&Elasticity::with_element(mesh, material, element)?)?;
                line += &format!(" {element} {f:.4e} N");
                forces.push(f);
            }
            if let Some(p2) = &p2 {
                let f = p2.force(&QuadraticBody::new(mesh, material)?)?;
                line += &format!(
                    " p2 {f:.4e} N  p1/p2 {:.3}  anp/p2 {:.3}",
                    forces[0] / f,
                    forces[1] / f
                );
            }
            println!("{line}");
        }
    }
    // The stabilisation's price: it re-introduces P1's element constraint with penalty
    // alpha kappa, so the force creeps back towards P1's as alpha grows.
    let (name, mesh) = &meshes[0];
    let setup = Punch::new(mesh, mesh.nodes.clone(), |_, _| None)?;
    for nu in [0.49, 0.499] {
        let mut line = format!("{name} nu={nu} anp force vs alpha:");
        for alpha in ALPHAS {
            let body = Elasticity::with_anp_stabilisation(mesh, Material::new(3.0e3, nu)?, alpha)?;
            line += &format!("  {alpha}: {:.4e} N", setup.force(&body)?);
        }
        println!("{line}");
    }
    Ok(())
}

/// The fixed bed and the punch nodes of a liver mesh, for a body whose nodes are `positions`
/// (the mesh's vertices first, then any edge nodes: `edge_node(a, b)`).
struct Punch {
    bed: FixedSet,
    contact: Vec<usize>,
}

impl Punch {
    fn new(
        mesh: &TetMesh,
        positions: Vec<[f64; 3]>,
        edge_node: impl Fn(usize, usize) -> Option<usize>,
    ) -> Result<Self, Box<dyn std::error::Error>> {
        let (lo, hi) = mesh.bounding_box();
        let mut bed = FixedSet::none(positions.len());
        for (i, p) in positions.iter().enumerate() {
            if p[2] <= lo[2] + 0.01 {
                bed.fix_node(i)?;
            }
        }
        let surface = fem::mesh::boundary(mesh)?;
        let mut on_surface = vec![false; positions.len()];
        for t in &surface.triangles {
            for k in 0..3 {
                on_surface[t[k]] = true;
                if let Some(m) = edge_node(t[k], t[(k + 1) % 3]) {
                    on_surface[m] = true;
                }
            }
        }
        let apex = (0..mesh.nodes.len())
            .max_by(|&a, &b| mesh.nodes[a][2].total_cmp(&mesh.nodes[b][2]))
            .ok_or("empty mesh")?;
        let c = mesh.nodes[apex];
        let mid = 0.5 * (lo[2] + hi[2]);
        let contact: Vec<usize> = (0..positions.len())
            .filter(|&i| {
                let p = positions[i];
                on_surface[i] && p[2] > mid && (p[0] - c[0]).hypot(p[1] - c[1]) <= 0.01
            })
            .collect();
        Ok(Self { bed, contact })
    }

    /// Punch force (N) for a 5 mm indentation.
    fn force(&self, body: &impl Stiffness) -> Result<f64, Box<dyn std::error::Error>> {
        let mut held = self.bed.clone();
        let mut u_held = vec![0.0; 3 * body.nodes()];
        for &i in &self.contact {
            held.fix_component(i, 2)?;
            u_held[3 * i + 2] = -0.005;
        }
        let (_, f) = solve_prescribed(body, &held, &u_held)?;
        Ok(-self.contact.iter().map(|&i| f[3 * i + 2]).sum::<f64>())
    }
}

/// Times assembly and ordering + factorisation of `K_ff` for the bed.
fn cost(
    body: &impl Stiffness,
    bed: &FixedSet,
    name: &str,
) -> Result<(), Box<dyn std::error::Error>> {
    let start = Instant::now();
    let dofs = DofMap::new(bed);
    let k = body.stiffness(&dofs);
    let assembly = start.elapsed();
    let start = Instant::now();
    let perm = permutation(Ordering::default(), body, &dofs)?;
    let c = Compliance::factorize_matrix(dofs, &k, perm.as_ref())?;
    let factor = start.elapsed();
    let s = c.stats();
    println!(
        "  {name:<3}: {} free dofs, nnz(K) {}, nnz(L) {}, assembly {:.3} s, \
         ordering+factorisation {:.3} s",
        s.free_dofs,
        s.nnz_k,
        s.nnz_l,
        assembly.as_secs_f64(),
        factor.as_secs_f64()
    );
    Ok(())
}

/// Uniform refinement, each tetrahedron into 8: four corner tetrahedra at the edge midpoints
/// and the inner octahedron cut along the diagonal between the midpoints of edges 0-2 and
/// 1-3. The geometry stays the coarse mesh's, so this is a discretisation reference for
/// that shape.
fn split_1_to_8(mesh: &TetMesh) -> TetMesh {
    let mut nodes = mesh.nodes.clone();
    let mut mids: HashMap<(usize, usize), usize> = HashMap::new();
    let mut mid = |a: usize, b: usize, nodes: &mut Vec<[f64; 3]>| {
        let key = (a.min(b), a.max(b));
        *mids.entry(key).or_insert_with(|| {
            let (p, q) = (nodes[a], nodes[b]);
            nodes.push(std::array::from_fn(|c| 0.5 * (p[c] + q[c])));
            nodes.len() - 1
        })
    };
    let mut tets = Vec::with_capacity(8 * mesh.tets.len());
    for &[v0, v1, v2, v3] in &mesh.tets {
        let m01 = mid(v0, v1, &mut nodes);
        let m02 = mid(v0, v2, &mut nodes);
        let m03 = mid(v0, v3, &mut nodes);
        let m12 = mid(v1, v2, &mut nodes);
        let m13 = mid(v1, v3, &mut nodes);
        let m23 = mid(v2, v3, &mut nodes);
        tets.extend([
            [v0, m01, m02, m03],
            [m01, v1, m12, m13],
            [m02, m12, v2, m23],
            [m03, m13, m23, v3],
            [m01, m02, m03, m13],
            [m01, m02, m13, m12],
            [m02, m03, m13, m23],
            [m02, m12, m23, m13],
        ]);
    }
    let mut fine = TetMesh { nodes, tets };
    // Orient every child positively.
    for t in 0..fine.tets.len() {
        if fine.signed_volume(t) < 0.0 {
            fine.tets[t].swap(2, 3);
        }
    }
    fine
}
