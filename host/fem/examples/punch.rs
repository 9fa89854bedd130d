//! The locking measurement: a frictionless flat punch pressed into the top of the liver,
//! P1 and the ANP element against 10-node tetrahedra (P2, the reference) on the same mesh,
//! plus the assembly / factorisation cost of each.
//!
//! ```sh
//! cargo run -p fem --profile checked --example punch                 # liver-1k4, liver-10k
//! cargo run -p fem --profile checked --example punch -- --refine      # + each mesh split 1:8
//! ```
//!
//! Setup: [`fem::reference::Punch`] (bed `z <= z_min + 10 mm` fixed, a 10 mm flat punch
//! pressed 5 mm into the top, frictionless), E = 3 kPa (the force is linear in E). `--refine` adds each mesh split 1:8 (same geometry);
//! P2 runs where it has at most [`P2_MAX_NODES`] nodes (liver-10k split would have 0.55 M).

use fem::compliance::Compliance;
use fem::elasticity::quadratic::QuadraticBody;
use fem::elasticity::{DofMap, Elasticity, Element, FixedSet, Material, Stiffness};
use fem::ordering::{Ordering, permutation};
use fem::reference::{Punch, split_1_to_8};
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
        let surface = fem::mesh::boundary(mesh)?;
        let setup = Punch::on_vertices(mesh, &surface)?;
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
            let setup = Punch::on_quadratic(mesh, &surface, &body)?;
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
    let setup = Punch::on_vertices(mesh, &fem::mesh::boundary(mesh)?)?;
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
