//! `host bank build | inspect | sweep`: firmware banks from scene files.

use crate::progress::Bar;
use anyhow::{Context, Result, bail};
use bank_format::region::BANK_LEN;
use bank_format::{AlignedBytes, Bank, LawKind, SectionKind};
use haptic::bank::stats;
use haptic::bank::sweep::{self, SweepConfig};
use haptic::bank::{BankSpec, BuiltBank, Prepared};
use haptic::fsio::write_atomic;
use haptic::scene::{ContactModel, Couplings, MeshSource};
use std::path::PathBuf;
use std::time::Instant;

/// Bank subcommands.
#[derive(clap::Subcommand, Debug)]
pub enum BankCmd {
    /// Build a bank from a scene file (atomic write: nothing is left behind on error).
    Build(BuildArgs),
    /// Validate a bank file and print what it holds; exits non-zero when it is invalid.
    Inspect(InspectArgs),
    /// Coupling rule (truncation radius, or the tool's pairs) -> pairs kept -> bank bytes ->
    /// the firmware's force error against the f64 solve on untruncated compliance, over contact
    /// sites spread over the reachable region (point contact and tool patch).
    Sweep(SweepArgs),
}

/// Arguments of `host bank build`.
#[derive(clap::Args, Debug)]
pub struct BuildArgs {
    /// Scene file (TOML; see host/scenes/liver.toml).
    scene: PathBuf,
    /// Output bank file.
    #[arg(short, long)]
    out: PathBuf,
    /// Refuse banks larger than this many bytes (default: the 768 KiB bank region of memory.x).
    #[arg(long, default_value_t = BANK_LEN)]
    region_bytes: usize,
}

/// Arguments of `host bank inspect`.
#[derive(clap::Args, Debug)]
pub struct InspectArgs {
    /// Bank file.
    bank: PathBuf,
    /// Print one JSON object instead of text.
    #[arg(long)]
    json: bool,
}

/// Arguments of `host bank sweep`.
#[derive(clap::Args, Debug)]
pub struct SweepArgs {
    /// Scene file.
    scene: Option<PathBuf>,
    /// Scene file (the same as the positional argument).
    #[arg(long = "scene")]
    scene_flag: Option<PathBuf>,
    /// Truncation radii of the "radius" rule, m, comma separated.
    #[arg(long, default_value = "0,0.008,0.012,0.016,0.02,0.03")]
    radii: String,
    /// Leave out the "tool" rule's row (the pairs the scene's tool can put in one contact set).
    #[arg(long)]
    no_tool: bool,
    /// Number of contact sites spread over the reachable region (area-uniform).
    #[arg(long, default_value_t = 1000)]
    sites: usize,
    /// Seed of the sites' placement.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Press depth along the inward normal, m.
    #[arg(long, default_value_t = 0.005)]
    depth: f64,
    /// Storage precisions of C_kl, comma separated: "f32" and/or "bfp16" (16-bit mantissas,
    /// one exponent per 3x3 block); every rule and radius is built in each.
    #[arg(long, default_value = "f32,bfp16")]
    precision: String,
    /// Print one JSON object instead of the table.
    #[arg(long)]
    json: bool,
}

/// Runs a bank subcommand.
pub fn run(cmd: BankCmd) -> Result<()> {
    match cmd {
        BankCmd::Build(a) => build(a),
        BankCmd::Inspect(a) => inspect(a),
        BankCmd::Sweep(a) => sweep(a),
    }
}

/// What `bank build` prints of a nodal bank: its coupling rule and the tool patches it holds.
fn print_nodal(prep: &Prepared, bank: &Bank, pairs: usize) {
    let radius = prep.organ.scene.bank.truncation_radius_m;
    let rule = match prep.organ.scene.bank.couplings {
        Couplings::Radius => format!("truncation radius {radius} m, plus every triangle edge"),
        Couplings::Tool => format!(
            "every pair the {} m tool can put into one contact set (firmware patch rule at {} \
             anchors per triangle), every triangle edge, pairs within {radius} m; all pairs \
             within {:.4} m are kept",
            prep.organ.scene.tip_radius_m,
            (haptic::bank::TOOL_DIVISIONS + 1) * (haptic::bank::TOOL_DIVISIONS + 2) / 2,
            bank.truncation_radius_m()
        ),
    };
    println!(
        "couplings {pairs} pairs kept ({rule}), {} neighbour entries",
        2 * pairs
    );
    let patches = stats::tool_patches(bank);
    println!(
        "tool      tip radius {} m: patches of up to {} nodes at the triangles' centroids; at \
         most {:.1}% of a patch's load dropped (nodes the bank does not couple, or beyond {} \
         nodes){}",
        prep.organ.scene.tip_radius_m,
        patches.max_nodes,
        100.0 * patches.max_dropped,
        firmware::solve::MAX_CONTACT_NODES,
        if patches.max_dropped > 0.01 {
            ": raise bank.truncation_radius_m (see `host bank sweep`)"
        } else {
            ""
        }
    );
}

/// `(kind name, offset, len, count)` of each entry of the bank's section table.
fn section_table(bank: &Bank) -> Vec<(&'static str, u32, u32, u32)> {
    bank.sections()
        .iter()
        .map(|e| {
            (
                SectionKind::from_code(e.kind).name(),
                e.offset,
                e.len,
                e.count,
            )
        })
        .collect()
}

fn build(args: BuildArgs) -> Result<()> {
    let t = Instant::now();
    let prep = Prepared::load(&args.scene)?;
    prep.organ.warnings.iter().for_each(|w| eprintln!("{w}"));
    let progress = Bar::new(match prep.organ.scene.contact {
        ContactModel::Nodal => "supernodes",
        ContactModel::Sampled(_) => "patch compliance chunks",
    });
    if let ContactModel::Sampled(spec) = &prep.organ.scene.contact {
        eprintln!(
            "sampling the tool's patch compliance on {} ({}) ...",
            spec.fem_mesh.display(),
            spec.element.name()
        );
    }
    let BuiltBank {
        bytes,
        pairs,
        sampled,
    } = prep.bank(&BankSpec::Scene {
        progress: Some(&progress),
    })?;
    progress.finish();
    if bytes.len() > args.region_bytes {
        bail!(
            "the bank would be {} bytes, more than the {} bytes of the bank region ({} nodes in \
             R, {pairs} coupled pairs): lower bank.truncation_radius_m or narrow the device's \
             ranges; nothing was written",
            bytes.len(),
            args.region_bytes,
            prep.region.len()
        );
    }
    let mut inputs = vec![args.scene.as_path()];
    if let MeshSource::File(mesh) = &prep.organ.scene.mesh {
        inputs.push(mesh);
    }
    if let ContactModel::Sampled(spec) = &prep.organ.scene.contact {
        inputs.push(&spec.fem_mesh);
    }
    write_atomic(&args.out, &bytes, &inputs)?;
    // Read back what was written.
    let written = std::fs::read(&args.out)?;
    let aligned = AlignedBytes::new(&written);
    let bank = Bank::parse(&aligned).map_err(|e| {
        anyhow::anyhow!("{}: written bank fails validation: {e}", args.out.display())
    })?;
    let (lo, hi) = prep.organ.mesh.bounding_box();
    println!(
        "scene     {} ({}, {} nodes, {} surface nodes, box [{:.3}, {:.3}] x [{:.3}, {:.3}] x \
         [{:.3}, {:.3}] m)",
        args.scene.display(),
        prep.organ.mesh_name,
        prep.organ.mesh.nodes.len(),
        prep.organ.surface.nodes.len(),
        lo[0],
        hi[0],
        lo[1],
        hi[1],
        lo[2],
        hi[2]
    );
    println!(
        "region R  {} reachable surface nodes, {} triangles (tip radius {} m, margin {} m)",
        bank.node_count(),
        bank.triangles().len(),
        prep.organ.scene.tip_radius_m,
        prep.organ.scene.bank.reach_margin_m
    );
    match (&prep.organ.scene.contact, sampled) {
        (ContactModel::Sampled(spec), Some(st)) => {
            println!(
                "couplings {pairs} pairs kept (the triangle edges, for the nodal contact models; \
                 the firmware renders from the samples)"
            );
            println!(
                "contact   sampled patch compliance: {} samples (lattice level {}) computed on {} \
                 ({}, {} vertices, {} nodes, nnz(L) {:.1} M; factor {:.1} s, W {:.1} s); \
                 largest patch {} FEM nodes",
                st.samples,
                spec.level,
                spec.fem_mesh.display(),
                spec.element.name(),
                st.fem_vertices,
                st.fem_nodes,
                st.factor.nnz_l as f64 / 1e6,
                st.factor_s,
                st.w_s,
                st.max_patch_nodes,
            );
            println!(
                "depth     the collision surface lies within {:.2} mm of the FEM surface at the \
                 samples (mean {:.2} mm): a depth error of the rendered press",
                1e3 * st.gap_max_m,
                1e3 * st.gap_mean_m
            );
        }
        _ => print_nodal(&prep, &bank, pairs),
    }
    println!("sections  kind                  bytes   count");
    for (name, _, len, count) in section_table(&bank) {
        println!("          {name:<20} {len:>7} {count:>7}");
    }
    let region = BANK_LEN;
    println!(
        "total     {} bytes = {:.1} KiB of the {} KiB bank region ({:.1}%), crc32 {:08x}, \
         scene id {:016x}",
        bytes.len(),
        bytes.len() as f64 / 1024.0,
        region / 1024,
        100.0 * bytes.len() as f64 / region as f64,
        bank.crc(),
        bank.scene_id()
    );
    println!(
        "written   {} in {:.2} s",
        args.out.display(),
        t.elapsed().as_secs_f64()
    );
    Ok(())
}

fn inspect(args: InspectArgs) -> Result<()> {
    let raw = std::fs::read(&args.bank)
        .with_context(|| format!("cannot read {}", args.bank.display()))?;
    let aligned = AlignedBytes::new(&raw);
    let bank = match Bank::parse(&aligned) {
        Ok(b) => b,
        Err(e) => bail!(
            "{}: invalid bank: {e} (validation code {})",
            args.bank.display(),
            e.code()
        ),
    };
    let (major, minor) = bank.version();
    let law = bank.tissue_law();
    let law_kind = match law.kind() {
        LawKind::Linear => "linear",
        LawKind::Chebyshev => "chebyshev",
    };
    let d = bank.device();
    let pairs = (0..bank.node_count())
        .map(|k| bank.neighbours(k).len())
        .sum::<usize>()
        / 2;
    let sections = section_table(&bank);
    let cand = stats::grid_candidates(&bank);
    if args.json {
        let v = serde_json::json!({
            "file": args.bank.display().to_string(),
            "version": [major, minor],
            "crc32": format!("{:08x}", bank.crc()),
            "scene_id": format!("{:016x}", bank.scene_id()),
            "bytes": bank.bytes().len(),
            "nodes": bank.node_count(),
            "triangles": bank.triangles().len(),
            "coupled_pairs": pairs,
            "truncation_radius_m": bank.truncation_radius_m(),
            "grid": {
                "cell_size_m": bank.grid().cell_size_m(), "dims": bank.grid().dims(),
                "max_candidates": cand.max, "mean_candidates_near_surface": cand.mean_near_surface,
            },
            "law": { "kind": law_kind, "coeffs": law.coeffs(), "domain_n": law.domain() },
            "device": {
                "fulcrum_m": d.fulcrum_m, "shaft_axis": d.shaft_axis,
                "pitch_axis": d.pitch_axis, "yaw_axis": d.yaw_axis,
                "joint_min": d.joint_min, "joint_max": d.joint_max, "home_joint": d.home_joint,
                "counts_per_rev": d.counts_per_rev, "transmission": d.transmission,
                "torque_constant_nm_per_a": d.torque_constant_nm_per_a,
                "current_limit_a": d.current_limit_a, "max_force_n": d.max_force_n,
                "tip_radius_m": d.tip_radius_m, "max_tip_speed_m_s": d.max_tip_speed_m_s,
                "max_joint_speed": d.max_joint_speed, "link_timeout_ms": d.link_timeout_ms,
            },
            "sections": sections.iter().map(|(n, o, l, c)| serde_json::json!(
                { "kind": n, "offset": o, "len": l, "count": c })).collect::<Vec<_>>(),
        });
        println!("{v}");
        return Ok(());
    }
    println!(
        "bank      {} ({} bytes)",
        args.bank.display(),
        bank.bytes().len()
    );
    println!(
        "format    {major}.{minor}, crc32 {:08x}, scene id {:016x}",
        bank.crc(),
        bank.scene_id()
    );
    println!(
        "region    {} nodes, {} triangles, {pairs} coupled pairs, truncation radius {} m",
        bank.node_count(),
        bank.triangles().len(),
        bank.truncation_radius_m()
    );
    println!(
        "grid      cell {} m, {:?} cells; candidate triangles per cell: max {}, mean {:.1} \
         where the surface is near (clearance <= 1)",
        bank.grid().cell_size_m(),
        bank.grid().dims(),
        cand.max,
        cand.mean_near_surface
    );
    println!(
        "law       {law_kind}, coefficients {:?}, domain {:?} N",
        law.coeffs(),
        law.domain()
    );
    println!(
        "device    fulcrum {:?} m, shaft {:?}; pitch [{}, {}] rad, yaw [{}, {}] rad, insertion \
         [{}, {}] m",
        d.fulcrum_m,
        d.shaft_axis,
        d.joint_min[0],
        d.joint_max[0],
        d.joint_min[1],
        d.joint_max[1],
        d.joint_min[2],
        d.joint_max[2]
    );
    println!(
        "motors    counts/rev {:?}, transmission {:?}, Kt {:?} N m/A, limits {:?} A; max force \
         {} N, tip radius {} m",
        d.counts_per_rev,
        d.transmission,
        d.torque_constant_nm_per_a,
        d.current_limit_a,
        d.max_force_n,
        d.tip_radius_m
    );
    println!(
        "overspeed tip {} m/s; joints {} rad/s, {} rad/s, {} m/s",
        d.max_tip_speed_m_s, d.max_joint_speed[0], d.max_joint_speed[1], d.max_joint_speed[2]
    );
    println!("link      timeout {} ms", d.link_timeout_ms);
    println!("sections  kind                  offset     bytes   count");
    for (name, off, len, count) in sections {
        println!("          {name:<20} {off:>7} {len:>9} {count:>7}");
    }
    Ok(())
}

fn sweep(args: SweepArgs) -> Result<()> {
    let scene = match (&args.scene, &args.scene_flag) {
        (Some(s), None) | (None, Some(s)) => s.clone(),
        (Some(_), Some(_)) => bail!("give the scene once (positional or --scene)"),
        (None, None) => bail!("no scene: give a scene file (e.g. host/scenes/liver.toml)"),
    };
    let radii = super::fixing::parse_list::<f64>(&args.radii).context("--radii")?;
    if radii.iter().any(|r| !(r.is_finite() && *r >= 0.0)) {
        bail!("--radii: every radius must be a number >= 0");
    }
    if args.sites == 0 {
        bail!("--sites must be at least 1");
    }
    if !(args.depth.is_finite() && args.depth > 0.0) {
        bail!("--depth must be > 0 m, got {}", args.depth);
    }
    let precisions = args
        .precision
        .split(',')
        .map(|p| {
            bank_format::Precision::from_name(p.trim())
                .with_context(|| format!("--precision: {p:?} is not \"f32\" or \"bfp16\""))
        })
        .collect::<Result<Vec<_>>>()?;
    let prep = Prepared::load(&scene)?;
    prep.organ.warnings.iter().for_each(|w| eprintln!("{w}"));
    let config = SweepConfig {
        precisions,
        radii,
        tool_radii: if args.no_tool { vec![] } else { vec![0.0] },
        sites: args.sites,
        depth_m: args.depth,
        seed: args.seed,
    };
    let progress = Bar::new("supernodes, then banks");
    let rows = sweep::run(&prep, &config, Some(&progress))?;
    progress.finish();
    if args.json {
        let v = serde_json::json!({
            "scene": scene.display().to_string(),
            "region_nodes": prep.region.len(),
            "tip_radius_m": prep.organ.scene.tip_radius_m,
            "depth_m": args.depth,
            "rows": rows,
        });
        println!("{v}");
        return Ok(());
    }
    println!(
        "scene {}: |R| = {}, {} contact sites (area-uniform on R, seed {}), {:.1} mm along the \
         inward normal; relative error of the firmware's tool force (f32, on the bank) against \
         the f64 solve on untruncated compliance (max / mean)",
        scene.display(),
        prep.region.len(),
        args.sites,
        args.seed,
        args.depth * 1e3
    );
    println!(
        "| rule | radius (mm) | precision | pairs kept | bank bytes | fits 768 KiB | point contact | tool patch r = {:.1} mm | patch load dropped (max) |",
        prep.organ.scene.tip_radius_m * 1e3
    );
    println!("| --- | ---: | --- | ---: | ---: | :---: | --- | --- | ---: |");
    for r in &rows {
        println!(
            "| {} | {:.1} | {} | {} | {} | {} | {:.1e} / {:.1e} | {:.1e} / {:.1e} | {:.1}%{} |",
            r.rule,
            r.radius_m * 1e3,
            r.precision,
            r.pairs,
            r.bank_bytes,
            if r.fits_region { "yes" } else { "no" },
            r.errors.point_max,
            r.errors.point_mean,
            r.errors.patch_max,
            r.errors.patch_mean,
            100.0 * r.errors.dropped_max,
            if r.errors.failed > 0 {
                format!(" ({} solves failed)", r.errors.failed)
            } else {
                String::new()
            }
        );
    }
    Ok(())
}
