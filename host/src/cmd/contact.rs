//! `host contact`: what a scene's bank renders at a point of the organ (`probe`), and the
//! convergence study of the patch compliance (`study`).

use crate::progress::Bar;
use anyhow::{Context, Result, bail};
use bank_format::{AlignedBytes, Bank};
use haptic::bank::Prepared;
use haptic::organ::Organ;
use haptic::reach::Region;
use haptic::scene::Scene;
use std::path::PathBuf;

/// `host contact ...`.
#[derive(clap::Subcommand, Debug)]
pub enum ContactCmd {
    /// The collision-surface point closest to a point, its normal, the patch compliance W the
    /// firmware reads there and, with --depth, the force its tick renders for a normal press.
    Probe(ProbeArgs),
    /// Convergence study of W: the normal stiffness 1 / (n.W.n) at the study's sites on a
    /// sequence of FEM meshes, and its Richardson extrapolation with the error it estimates.
    Study(StudyArgs),
}

/// Arguments of `host contact study`.
#[derive(clap::Args, Debug)]
pub struct StudyArgs {
    /// Scene file (default: the embedded default liver scene): material, supports, tool,
    /// collision surface.
    #[arg(long)]
    scene: Option<PathBuf>,
    /// A FEM mesh and its fine-zone size in m, coarse to fine (at least three for the
    /// extrapolation, the last three sizes in one constant ratio).
    #[arg(long = "mesh", value_name = "FILE:H", required = true)]
    meshes: Vec<String>,
    /// Element: p1, anp or p2.
    #[arg(long, default_value = "p2")]
    element: String,
    /// Write the study (sites, every level's W, the reference) as JSON to this file.
    #[arg(long)]
    out: Option<PathBuf>,
}

/// Arguments of `host contact probe`.
#[derive(clap::Args, Debug)]
#[command(allow_negative_numbers = true)]
pub struct ProbeArgs {
    /// Scene file (default: the embedded default liver scene).
    #[arg(long)]
    scene: Option<PathBuf>,
    /// Probe this bank file instead of the scene's own bank (the scene still gives the organ's
    /// surface, to tell an unreachable point).
    #[arg(long)]
    bank: Option<PathBuf>,
    /// The query point, m.
    #[arg(long, value_name = "X,Y,Z", allow_hyphen_values = true)]
    at: String,
    /// Press depth along the inward normal, m: prints the force the firmware's tick renders.
    #[arg(long, value_name = "M")]
    depth: Option<f64>,
    /// Render the force through the scene's tissue law Q (default: the linear model's force).
    #[arg(long)]
    law: bool,
    /// One JSON object on stdout: point, normal, W (rows, m/N), nWn (m/N), force_n (N).
    #[arg(long)]
    json: bool,
}

/// Runs a `host contact` command.
pub fn run(cmd: ContactCmd) -> Result<()> {
    match cmd {
        ContactCmd::Probe(args) => probe(args),
        ContactCmd::Study(args) => study(args),
    }
}

fn parse_point(s: &str) -> Result<[f64; 3]> {
    let v: Vec<f64> = s
        .split(',')
        .map(|x| x.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .with_context(|| format!("--at {s:?}: expected three numbers X,Y,Z (m)"))?;
    match v[..] {
        [x, y, z] if v.iter().all(|c| c.is_finite()) => Ok([x, y, z]),
        _ => bail!("--at {s:?}: expected three finite numbers X,Y,Z (m)"),
    }
}

fn probe(args: ProbeArgs) -> Result<()> {
    let at = parse_point(&args.at)?;
    let scene = Scene::load_or_default(args.scene.as_deref())?;
    let prep = Prepared::from_scene(scene)?;
    let bytes = match &args.bank {
        Some(file) => std::fs::read(file).with_context(|| format!("--bank {}", file.display()))?,
        None => {
            let progress = Bar::new("patch compliance chunks");
            let (built, _) = haptic::bank::cache::scene_bank_cached(&prep, Some(&progress))?;
            progress.finish();
            built.bytes
        }
    };
    let aligned = AlignedBytes::new(&bytes);
    let bank = Bank::parse(&aligned).map_err(|e| anyhow::anyhow!("built bank invalid: {e}"))?;
    let p = haptic::probe::probe(
        &bank,
        (&prep.organ.mesh.nodes, &prep.organ.surface.triangles),
        at,
        args.depth,
        args.law,
    )?;
    if args.json {
        let mut o = serde_json::json!({
            "point": p.point,
            "normal": p.normal,
            "W": p.w,
            "nWn": p.nwn,
            "triangle": p.triangle,
            "model": if bank.samples().is_some() { "sampled" } else { "nodal" },
        });
        if let Some(f) = p.force_n {
            o["force_n"] = serde_json::json!(f);
        }
        println!("{o}");
        return Ok(());
    }
    let model = if bank.samples().is_some() {
        "sampled patch compliance"
    } else {
        "tool patch on the nodes"
    };
    println!(
        "point     [{:.5}, {:.5}, {:.5}] m on collision triangle {} ({model})",
        p.point[0], p.point[1], p.point[2], p.triangle
    );
    println!(
        "normal    [{:.4}, {:.4}, {:.4}]",
        p.normal[0], p.normal[1], p.normal[2]
    );
    for (i, row) in p.w.iter().enumerate() {
        println!(
            "{}[{:+.4e}, {:+.4e}, {:+.4e}] m/N",
            if i == 0 { "W         " } else { "          " },
            row[0],
            row[1],
            row[2]
        );
    }
    println!("n.W.n     {:.4e} m/N", p.nwn);
    if let (Some(f), Some(d)) = (p.force_n, args.depth) {
        let mag = (f[0] * f[0] + f[1] * f[1] + f[2] * f[2]).sqrt();
        println!(
            "force     [{:+.4}, {:+.4}, {:+.4}] N, |F| = {mag:.4} N on the tool for a {:.2} mm \
             press ({})",
            f[0],
            f[1],
            f[2],
            1e3 * d,
            if args.law { "law Q" } else { "linear model" }
        );
    }
    Ok(())
}

fn study(args: StudyArgs) -> Result<()> {
    use haptic::linalg::normal_compliance;
    use haptic::scene::FemElement;
    use haptic::study::{self, DEFAULT_SITES};
    let element: FemElement = args
        .element
        .parse()
        .map_err(|why: String| anyhow::anyhow!("--element: {why}"))?;
    let meshes = args
        .meshes
        .iter()
        .map(|m| {
            let (f, h) = m
                .rsplit_once(':')
                .with_context(|| format!("--mesh {m:?}: expected FILE:H"))?;
            let h: f64 = h
                .parse()
                .ok()
                .filter(|h: &f64| *h > 0.0 && h.is_finite())
                .with_context(|| format!("--mesh {m:?}: H must be a size in m, > 0"))?;
            Ok((PathBuf::from(f), h))
        })
        .collect::<Result<Vec<_>>>()?;
    let scene = Scene::load_or_default(args.scene.as_deref())?;
    let organ = Organ::from_scene(scene)?;
    let region = Region::of(&organ)?;
    let given: Vec<(String, [f64; 3])> = DEFAULT_SITES
        .iter()
        .map(|(n, p)| (n.to_string(), *p))
        .collect();
    let sites = study::sites(&organ, &region, &given)?;
    let mut levels = Vec::new();
    for (mesh, h) in &meshes {
        eprintln!(
            "level {} ({}, h {} mm) ...",
            mesh.display(),
            args.element,
            1e3 * h
        );
        let l = study::level(&organ.scene, &sites, mesh, *h, element)?;
        eprintln!(
            "  {} vertices, {} nodes, {} free dofs, nnz(L) {:.1} M, {:.1} s",
            l.vertices,
            l.nodes,
            l.free_dofs,
            l.nnz_l as f64 / 1e6,
            l.seconds
        );
        levels.push(l);
    }
    let (reference_w, order, reference_error) = if levels.len() >= 3 {
        study::extrapolate(&sites, &levels)?
    } else {
        eprintln!("note: fewer than three levels, no extrapolation");
        (Vec::new(), Vec::new(), Vec::new())
    };
    print!("{:<28}", "normal stiffness (N/m)");
    for l in &levels {
        print!(" {:>9}", format!("{:.2}mm", 1e3 * l.h_m));
    }
    println!(" {:>9} {:>8}", "limit", "ref err");
    for (s, site) in sites.iter().enumerate() {
        print!("{:<28}", site.name);
        for l in &levels {
            print!(" {:>9.3}", 1.0 / normal_compliance(&l.w[s], site.normal));
        }
        if let Some(w) = reference_w.get(s) {
            print!(
                " {:>9.3} {:>7.2}%",
                1.0 / normal_compliance(w, site.normal),
                100.0 * reference_error[s]
            );
        }
        println!();
    }
    if let Some(q) = order.first() {
        println!(
            "order {q:.2}, pooled over the {} sites (straight-sided P2 or P1 on a curved surface: 2 \
             expected); reference error: grid convergence index, safety factor {}",
            sites.len(),
            study::GCI_SAFETY
        );
    }
    if let Some(out) = &args.out {
        let st = study::Study {
            scene: organ.scene.path.display().to_string(),
            tip_radius_m: organ.scene.tip_radius_m,
            sites,
            levels,
            reference_w,
            order,
            reference_error,
        };
        let text = serde_json::to_string_pretty(&st)?;
        haptic::fsio::write_atomic(out, text.as_bytes(), &[])?;
        eprintln!("wrote {}", out.display());
    }
    Ok(())
}
