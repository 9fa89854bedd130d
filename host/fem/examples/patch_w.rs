//! Patch compliances of a tool pressed on an organ: for each requested point, the closest
//! surface point, its outward normal, the tool's nodal weights ([`fem::tool`]) and the 3x3
//! patch compliance `W = B K_ff^-1 B^T` ([`Compliance::patch_compliances`]), with its normal
//! part `n . W n`.
//!
//! ```sh
//! cargo run -p fem --release --example patch_w -- host/meshes/liver-1k4.msh
//! cargo run -p fem --release --example patch_w -- host/meshes/liver-10k.msh --p2 \
//!     --radius 0.003 --at 0,0,0.07 --at 0.03,0,0.07
//! ```
//!
//! Setup: E = 3000 Pa, nu = 0.45, every node of the bed `z <= 0.01` fixed; P1 on the mesh's
//! vertices, or `--p2` 10-node tetrahedra on the same mesh. Default points: (0, 0, 0.07)
//! straight above the top, (0.03, 0, 0.07) and (-0.03, 0.01, 0.07). Default radius 3 mm.

use fem::compliance::{Block3, Compliance};
use fem::elasticity::quadratic::QuadraticBody;
use fem::elasticity::{Elasticity, FixedSet, Material, Stiffness};
use fem::mesh::TetMesh;
use fem::tool::ToolSurface;
use std::path::PathBuf;
use std::time::Instant;

const YOUNG_PA: f64 = 3000.0;
const POISSON: f64 = 0.45;
const BED_M: f64 = 0.01;

struct Args {
    mesh: PathBuf,
    p2: bool,
    radius: f64,
    points: Vec<[f64; 3]>,
}

fn parse() -> Result<Args, String> {
    let usage = "usage: patch_w MESH.msh [--p2] [--radius METRES] [--at x,y,z ...]";
    let mut mesh = None;
    let mut p2 = false;
    let mut radius = 0.003;
    let mut points = Vec::new();
    let mut args = std::env::args().skip(1);
    while let Some(arg) = args.next() {
        match arg.as_str() {
            "--p2" => p2 = true,
            "--radius" => {
                let v = args.next().ok_or(usage)?;
                radius = v.parse().map_err(|e| format!("--radius {v}: {e}"))?;
            }
            "--at" => {
                let v = args.next().ok_or(usage)?;
                let xyz: Vec<f64> = v
                    .split(',')
                    .map(|s| s.trim().parse::<f64>())
                    .collect::<Result<_, _>>()
                    .map_err(|e| format!("--at {v}: {e}"))?;
                let p: [f64; 3] = xyz
                    .try_into()
                    .map_err(|_| format!("--at {v}: expected x,y,z"))?;
                if !p.iter().all(|x| x.is_finite()) {
                    return Err(format!("--at {v}: not finite"));
                }
                points.push(p);
            }
            other if other.starts_with("--") => return Err(format!("{other}?\n{usage}")),
            other if mesh.is_none() => mesh = Some(PathBuf::from(other)),
            other => return Err(format!("unexpected argument {other}\n{usage}")),
        }
    }
    if points.is_empty() {
        points = vec![[0.0, 0.0, 0.07], [0.03, 0.0, 0.07], [-0.03, 0.01, 0.07]];
    }
    Ok(Args {
        mesh: mesh.ok_or(usage)?,
        p2,
        radius,
        points,
    })
}

/// The bed `z <= 0.01` fixed (all components) on the given node positions.
fn bed(positions: &[[f64; 3]]) -> Result<FixedSet, Box<dyn std::error::Error>> {
    let mut fixed = FixedSet::none(positions.len());
    for (i, p) in positions.iter().enumerate() {
        if p[2] <= BED_M {
            fixed.fix_node(i)?;
        }
    }
    Ok(fixed)
}

fn factorize(
    body: &impl Stiffness,
    positions: &[[f64; 3]],
) -> Result<Compliance, Box<dyn std::error::Error>> {
    Ok(Compliance::factorize(body, &bed(positions)?)?)
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args = parse()?;
    let mesh: TetMesh = fem::mesh::load(&args.mesh)?;
    let surface = fem::mesh::boundary(&mesh)?;
    let material = Material::new(YOUNG_PA, POISSON)?;

    let start = Instant::now();
    let (compliance, tool, nodes) = if args.p2 {
        let body = QuadraticBody::new(&mesh, material)?;
        let c = factorize(&body, body.positions())?;
        let tool = ToolSurface::quadratic(&mesh, &surface, &body)?;
        (c, tool, body.nodes())
    } else {
        let body = Elasticity::new(&mesh, material)?;
        let c = factorize(&body, &mesh.nodes)?;
        (c, ToolSurface::linear(&mesh, &surface)?, mesh.nodes.len())
    };
    let factor_s = start.elapsed().as_secs_f64();
    let stats = compliance.stats();
    println!(
        "{}: {} ({} nodes, {} surface triangles), E = {YOUNG_PA} Pa, nu = {POISSON}, \
         bed z <= {BED_M} m fixed, tool radius {} m",
        args.mesh.display(),
        if args.p2 { "P2" } else { "P1" },
        nodes,
        tool.len(),
        args.radius
    );
    println!(
        "factor: {} free dofs, nnz(K) {}, nnz(L) {}",
        stats.free_dofs, stats.nnz_k, stats.nnz_l
    );

    let start = Instant::now();
    let mut found = Vec::new();
    let mut loads = Vec::new();
    for &q in &args.points {
        let at = tool.closest_point(q);
        loads.push(tool.tool_weights(at.point, args.radius)?);
        found.push(at);
    }
    let weights_s = start.elapsed().as_secs_f64();

    let start = Instant::now();
    let w = compliance.patch_compliances(&loads, None)?;
    let w_s = start.elapsed().as_secs_f64();

    for (((q, at), load), w) in args.points.iter().zip(&found).zip(&loads).zip(&w) {
        let n = at.normal;
        let wn: f64 = (0..3)
            .map(|i| n[i] * (0..3).map(|j| w[i][j] * n[j]).sum::<f64>())
            .sum();
        println!(
            "at {}: surface point {} ({:.2e} m away), normal {}, {} weighted nodes",
            fmt3(*q, 4),
            fmt3(at.point, 5),
            at.distance,
            fmt3(n, 3),
            load.len()
        );
        println!("  W (m/N) = {}", fmt_block(w));
        println!(
            "  n.W.n = {wn:.4e} m/N (normal stiffness {:.2} N/m)",
            1.0 / wn
        );
    }
    println!(
        "timings: assembly + factor {factor_s:.3} s, weights {:.3} ms, W {:.3} s",
        1e3 * weights_s,
        w_s
    );
    Ok(())
}

fn fmt3(p: [f64; 3], digits: usize) -> String {
    format!("({:.digits$}, {:.digits$}, {:.digits$})", p[0], p[1], p[2])
}

fn fmt_block(w: &Block3) -> String {
    let rows: Vec<String> = w
        .iter()
        .map(|r| format!("[{:+.3e} {:+.3e} {:+.3e}]", r[0], r[1], r[2]))
        .collect();
    rows.join(" ")
}
