//! `host bench …`: parses a benchmark's arguments, runs it ([`haptic::bench`],
//! [`haptic::bench::precompute`]) and prints its figures (speed is measured, never asserted by
//! tests; tests check behaviour).

use super::organ::{OrganArgs, default_meshes};
use anyhow::{Context, Result};
use fem::elasticity::{Element, Material};
use fem::ordering::Ordering;
use std::path::PathBuf;

/// Benchmarks.
#[derive(clap::Subcommand, Debug)]
pub enum Bench {
    /// Assembly, factorisation and column-solve times and peak memory of the compliance
    /// precompute, on the shipped livers (and the 100k one if generated).
    Compliance(ComplianceArgs),
    /// Nanoseconds per tick of the firmware's portable loop run natively on a bank, along a
    /// scripted press-slide-release trajectory.
    Tick(TickArgs),
    /// The same tool press on one organ meshed at several sizes: point contact against the
    /// finite tool tip (the point contact's force falls under refinement, the tip's converges).
    Refinement(super::refinement::Args),
    /// Instructions per tick of the firmware image under QEMU (idle and per contact-set size,
    /// loop body and whole tick) along the press, slide and strike scripts, the worst loop
    /// body over them and over seeded wander paths, and the image's flash and RAM use against
    /// memory.x.
    Sil(SilArgs),
    /// Instructions one evaluation of the tissue law costs on the MCU (thumbv7em), per degree,
    /// counted on the disassembly of `TissueLaw::eval`.
    Law(super::bench_law::LawArgs),
    /// The host link's heartbeat intervals as a device sees them (median, p99, p99.9, max),
    /// optionally under a CPU load: what the device's link timeout must tolerate.
    Heartbeat(super::bench_heartbeat::HeartbeatArgs),
    /// Flash and static RAM of an MCU image (ELF) against the firmware and RAM regions of
    /// memory.x (e.g. the board image,
    /// firmware/board/target/thumbv7em-none-eabihf/release/firmware-board).
    Image(ImageArgs),
    /// A sampled scene's precompute without the cache (bank: FEM factors and the patch
    /// compliance at every sample; the display fields) with its peak memory, and the start of
    /// a run that finds both in the cache.
    Precompute(PrecomputeArgs),
    /// The patch compliance W = B K^-1 B^T of tool loads on a sampled scene's FEM by the
    /// sparse forward substitution banks use, against full solves: times and their largest
    /// difference.
    Patch(PatchArgs),
}

/// The sampled scene and FEM of the precompute benchmarks.
#[derive(clap::Args, Debug)]
pub struct SampledFemArgs {
    /// Scene file; default: the embedded default scene.
    #[arg(long)]
    scene: Option<PathBuf>,
    /// Compute on this FEM mesh instead of the scene's `fem_mesh`
    /// (e.g. host/meshes/generated/liver-100k.msh).
    #[arg(long)]
    fem_mesh: Option<PathBuf>,
    /// The element: p1, anp or p2 (default: the scene's).
    #[arg(long)]
    element: Option<String>,
}

impl SampledFemArgs {
    /// The scene and its overrides.
    fn resolve(
        self,
        no_richardson: bool,
    ) -> Result<(haptic::scene::Scene, haptic::bench::precompute::Overrides)> {
        let scene = haptic::scene::Scene::load_or_default(self.scene.as_deref())?;
        let element = self
            .element
            .as_deref()
            .map(str::parse::<haptic::scene::FemElement>)
            .transpose()
            .map_err(|why| anyhow::anyhow!("--element: {why}"))?;
        let overrides = haptic::bench::precompute::Overrides {
            fem_mesh: self.fem_mesh,
            element,
            no_richardson,
        };
        Ok((scene, overrides))
    }
}

/// Arguments of `host bench patch`.
#[derive(clap::Args, Debug)]
pub struct PatchArgs {
    #[command(flatten)]
    fem: SampledFemArgs,
    /// Tool loads, evenly spread over the scene's samples (0: all of them; full solves take
    /// about 0.3 s a load on the default scene's P2 FEM).
    #[arg(long, default_value_t = 100)]
    loads: usize,
    /// Print one JSON object instead of text.
    #[arg(long)]
    json: bool,
}

/// Arguments of `host bench precompute`.
#[derive(clap::Args, Debug)]
pub struct PrecomputeArgs {
    #[command(flatten)]
    fem: SampledFemArgs,
    /// Drop the scene's Richardson extrapolation.
    #[arg(long)]
    no_richardson: bool,
    /// Print one JSON object instead of text.
    #[arg(long)]
    json: bool,
}

/// Arguments of `host bench image`.
#[derive(clap::Args, Debug)]
pub struct ImageArgs {
    /// The image (ELF32, linked against memory.x).
    elf: PathBuf,
}

/// Arguments of `host bench sil`.
#[derive(clap::Args, Debug)]
pub struct SilArgs {
    /// Virtual seconds per script and per wander seed.
    #[arg(long, default_value_t = 3.0)]
    seconds: f64,
    /// Wander paths (`host sil --script wander`) of seeds 0 to this less one, run side by side
    /// after the scripts.
    #[arg(long, default_value_t = 20)]
    seeds: u64,
    /// Print one JSON object instead of a table.
    #[arg(long)]
    json: bool,
    #[command(flatten)]
    setup: super::sil::SetupArgs,
}

/// Arguments of `host bench tick`.
#[derive(clap::Args, Debug)]
pub struct TickArgs {
    /// A bank file (`host bank build <scene> -o <file>`).
    bank: PathBuf,
    /// Number of ticks to run.
    #[arg(long, default_value_t = 20_000)]
    ticks: usize,
    /// Press depth beyond first contact, in metres.
    #[arg(long, default_value_t = 0.005)]
    depth: f64,
}

/// Arguments of `host bench compliance`.
#[derive(clap::Args, Debug)]
pub struct ComplianceArgs {
    /// Meshes to measure; default: host/meshes/liver-1k4.msh, liver-10k.msh and
    /// host/meshes/generated/liver-100k.msh when present.
    #[arg(long)]
    mesh: Vec<PathBuf>,
    #[command(flatten)]
    organ: OrganArgs,
    /// At most this many contact-candidate nodes (the free surface nodes nearest the top
    /// centre, a stand-in for a scene's reachable region).
    #[arg(long, default_value_t = 5000)]
    max_nodes: usize,
    /// Keep only the blocks of node pairs at most this far apart (metres), as a bank's
    /// truncated couplings do; default: every pair (memory grows with the square).
    #[arg(long)]
    radius: Option<f64>,
    /// Fill-reducing ordering: amd or nested-dissection.
    #[arg(long, default_value_t = Ordering::default())]
    ordering: Ordering,
    /// Element formulation: p1 (the paper's) or anp (average nodal pressure, locking-free).
    #[arg(long, default_value_t = Element::P1, value_name = "p1|anp")]
    element: Element,
    /// Print one JSON object per mesh instead of a table.
    #[arg(long)]
    json: bool,
}

/// Runs a benchmark.
pub fn run(bench: Bench) -> Result<()> {
    match bench {
        Bench::Compliance(args) => compliance(args),
        Bench::Tick(args) => tick(args),
        Bench::Refinement(args) => super::refinement::run(args),
        Bench::Sil(args) => sil(args),
        Bench::Law(args) => super::bench_law::run(args),
        Bench::Heartbeat(args) => super::bench_heartbeat::run(args),
        Bench::Image(args) => image(args),
        Bench::Precompute(args) => precompute(args),
        Bench::Patch(args) => patch(args),
    }
}

fn patch(args: PatchArgs) -> Result<()> {
    let (scene, overrides) = args.fem.resolve(true)?;
    eprintln!("factorising the FEM, then W of the loads twice ...");
    let m = haptic::bench::precompute::patch_methods(scene, &overrides, args.loads)?;
    if args.json {
        println!("{}", serde_json::to_string(&m)?);
        return Ok(());
    }
    println!(
        "fem       {} ({}): {} free dofs, nnz(L) {:.1} M, factor {:.1} s",
        m.fem_mesh,
        m.element,
        m.free_dofs,
        m.nnz_l as f64 / 1e6,
        m.factor_s
    );
    println!(
        "loads     {} tool loads, up to {} nodes each",
        m.loads, m.widest
    );
    println!(
        "forward   {:.2} s ({:.1} ms a load): sparse forward substitution, W = Y^T Y",
        m.forward_s,
        1e3 * m.forward_s / m.loads.max(1) as f64
    );
    println!(
        "full      {:.2} s ({:.1} ms a load): full solves, W = B K^-1 B^T; {:.1} x the forward \
         method",
        m.full_s,
        1e3 * m.full_s / m.loads.max(1) as f64,
        m.full_s / m.forward_s.max(1e-9)
    );
    println!(
        "agree     largest difference {:.1e} of W's largest diagonal entry",
        m.max_difference
    );
    Ok(())
}

fn precompute(args: PrecomputeArgs) -> Result<()> {
    let larger_fem = args.fem.fem_mesh.is_some();
    let (scene, overrides) = args.fem.resolve(args.no_richardson)?;
    let progress = crate::progress::Bar::new("chunks (patch compliance, then display fields)");
    let f = haptic::bench::precompute::measure(scene, &overrides, Some(&progress))?;
    progress.finish();
    if args.json {
        println!("{}", serde_json::to_string(&f)?);
        return Ok(());
    }
    let total = f.prepare_s + f.bank_s + f.fields_s;
    println!(
        "fem       {} ({}, {} vertices, {} nodes){}",
        f.fem_mesh,
        f.element,
        f.fem_vertices,
        f.fem_nodes,
        f.richardson_mesh
            .as_ref()
            .map_or(String::new(), |m| format!(", Richardson with {m}"))
    );
    println!(
        "bank      {} samples, {} B, {:.1} s (scene prepared in {:.1} s)",
        f.samples, f.bank_bytes, f.bank_s, f.prepare_s
    );
    println!(
        "display   {} surface nodes, fields {:.1} MiB (f16), {:.1} s",
        f.display_nodes,
        f.fields_bytes as f64 / f64::from(1 << 20),
        f.fields_s
    );
    println!(
        "total     {total:.1} s, peak memory {:.2} GiB; cached start {:.2} s",
        f.peak_rss_mib / 1024.0,
        f.cached_start_s
    );
    let verdict = |met: bool| if met { "met" } else { "not met" };
    if larger_fem {
        println!(
            "goal      a larger FEM (liver-100k): samples and display fields <= 300 s: {}",
            verdict(f.bank_s + f.fields_s <= 300.0)
        );
    } else {
        println!(
            "goal      default scene: precompute <= 60 s and <= 4 GiB, cached start <= 3 s: {}",
            verdict(total <= 60.0 && f.peak_rss_mib <= 4096.0 && f.cached_start_s <= 3.0)
        );
    }
    Ok(())
}

fn compliance(args: ComplianceArgs) -> Result<()> {
    let meshes = if args.mesh.is_empty() {
        default_meshes()
    } else {
        args.mesh.clone()
    };
    let config = haptic::bench::compliance::Config {
        material: Material::new(args.organ.young, args.organ.poisson)?,
        bed_m: args.organ.bed,
        max_nodes: args.max_nodes,
        radius_m: args.radius,
        ordering: args.ordering,
        element: args.element,
    };
    if !args.json {
        println!(
            "{:<22} {:>7} {:>8} {:>7} {:>6} {:>8} {:>8} {:>8} {:>9} {:>10} {:>9}",
            "mesh",
            "nodes",
            "tets",
            "dofs",
            "cols",
            "assem s",
            "factor s",
            "cols s",
            "nnz(L) M",
            "peak MiB",
            "factor MiB"
        );
    }
    for path in meshes {
        let bar = crate::progress::Bar::new("supernodes");
        let r = haptic::bench::compliance::run(&path, &config, &bar)
            .with_context(|| format!("benchmark on {}", path.display()));
        bar.finish();
        let r = r?;
        if args.json {
            println!("{}", serde_json::to_string(&r)?);
        } else {
            println!(
                "{:<22} {:>7} {:>8} {:>7} {:>6} {:>9} {:>8.3} {:>8.3} {:>8.3} {:>9.2} {:>10.0} {:>9.0}",
                r.mesh,
                r.nodes,
                r.tets,
                r.free_dofs,
                r.columns,
                r.pairs,
                r.assemble_s,
                r.factor_s,
                r.columns_s,
                r.nnz_l as f64 / 1e6,
                r.peak_rss_mib,
                r.factor_peak_rss_mib
            );
        }
    }
    Ok(())
}

fn tick(args: TickArgs) -> Result<()> {
    let bytes = std::fs::read(&args.bank)
        .with_context(|| format!("cannot read {}", args.bank.display()))?;
    let aligned = bank_format::AlignedBytes::new(&bytes);
    let bank = bank_format::Bank::parse(&aligned)
        .map_err(|e| anyhow::anyhow!("{}: invalid bank: {e}", args.bank.display()))?;
    let r = haptic::bench::tick::run(&bank, args.ticks, args.depth)?;
    println!(
        "ticks {} ({} in contact, up to {} contact nodes), peak force {:.3} N, faults {}",
        r.ticks, r.touching, r.max_contact_nodes, r.peak_force_n, r.faults
    );
    println!(
        "ns per tick (native, {}): mean {:.0}, median {}, p99 {}, max {}",
        std::env::consts::ARCH,
        r.ns_mean,
        r.ns_median,
        r.ns_p99,
        r.ns_max
    );
    Ok(())
}

fn sil(args: SilArgs) -> Result<()> {
    use bank_format::region::{FIRMWARE_LEN, RAM_LEN};
    use haptic::sil::cost::{BODY_GOAL, TICK_GOAL};
    use haptic::sil::harness;
    let (setup, bytes) = args.setup.resolve()?;
    let bank = bank_format::Bank::parse(&bytes)
        .map_err(|e| anyhow::anyhow!("{}: invalid bank: {e}", setup.bank.display()))?;
    let haptic::bench::sil::Figures {
        by_contact_nodes: groups,
        code_phases: code,
        worst_body: worst,
        worst_tick,
        goal_body,
        goal_tick,
        met,
        size,
        runs,
        wander,
    } = haptic::bench::sil::run(&setup, &bank, args.seconds, 0..args.seeds)?;
    let seeds = match args.seeds {
        0 => "no seeds".to_string(),
        1 => "seed 0".to_string(),
        n => format!("seeds 0-{}", n - 1),
    };
    let worst_wander = wander.iter().max_by_key(|w| w.max_body_instructions);
    if args.json {
        let by: serde_json::Map<String, serde_json::Value> = groups
            .iter()
            .map(|(k, g)| (k.to_string(), serde_json::json!(g)))
            .collect();
        let out = serde_json::json!({
            "instructions_per_period": harness::INSTRUCTIONS_PER_TICK,
            "by_contact_nodes": by,
            "code_phases": code.iter().map(|(n, c)| ((*n).to_string(), serde_json::json!(c))).collect::<serde_json::Map<_, _>>(),
            "worst_body_instructions": worst,
            "worst_tick_instructions": worst_tick,
            "goal": {
                "body_instructions": BODY_GOAL,
                "tick_instructions": TICK_GOAL,
                "max_body_instructions": goal_body,
                "max_tick_instructions": goal_tick,
                "met": met,
            },
            "flash_bytes": size.flash,
            "flash_region_bytes": FIRMWARE_LEN,
            "ram_static_bytes": size.ram,
            "ram_region_bytes": RAM_LEN,
            "runs": runs.iter().map(|r| serde_json::json!({
                "script": r.script,
                "ticks": r.ticks,
                "overruns": r.overruns,
                "faults": r.faults,
                "wall_s": r.wall_s,
            })).collect::<Vec<_>>(),
            "wander": wander,
        });
        println!("{out}");
        return Ok(());
    }
    println!(
        "instructions per armed tick under QEMU (-icount shift=3: {} per 1 ms period), {} s of \
         press, slide and strike",
        harness::INSTRUCTIONS_PER_TICK,
        args.seconds
    );
    println!(
        "{:<16} {:>7} {:>10} {:>9} {:>9} {:>9} {:>10} {:>9}",
        "contact nodes",
        "ticks",
        "body mean",
        "body p50",
        "body p99",
        "body max",
        "tick mean",
        "tick max"
    );
    for (k, g) in &groups {
        let name = if *k == 0 {
            "0 (idle)".to_string()
        } else {
            k.to_string()
        };
        println!(
            "{:<16} {:>7} {:>10.0} {:>9} {:>9} {:>9} {:>10.0} {:>9}",
            name, g.ticks, g.body_mean, g.body_p50, g.body_p99, g.body_max, g.tick_mean, g.tick_max
        );
    }
    println!("worst case       body {worst}, whole tick {worst_tick}");
    if let Some(w) = worst_wander {
        let worst_tick = wander.iter().map(|w| w.max_tick_instructions).max();
        println!(
            "wander           {seeds}, {} s each: worst body {} (seed {}), whole tick {}; \
             faults {}, overruns {}",
            args.seconds,
            w.max_body_instructions,
            w.seed,
            worst_tick.unwrap_or(0),
            wander.iter().map(|w| w.faults).sum::<usize>(),
            wander.iter().map(|w| w.overruns).sum::<u32>()
        );
    }
    println!(
        "worst body over press, slide, strike and wander {seeds}: {goal_body} instructions (goal \
         {BODY_GOAL})"
    );
    println!(
        "goal             every tick (armed or not): body {goal_body} <= {BODY_GOAL}, whole tick \
         {goal_tick} <= {TICK_GOAL}: {}",
        if met { "met" } else { "NOT met" }
    );
    println!(
        "instructions per tick by code phase, every tick (armed or not); link = whole tick less body"
    );
    println!(
        "{:<16} {:>7} {:>10} {:>9} {:>9} {:>9}",
        "code phase", "ticks", "mean", "p50", "p99", "max"
    );
    for (n, c) in &code {
        println!(
            "{:<16} {:>7} {:>10.0} {:>9} {:>9} {:>9}",
            n, c.ticks, c.mean, c.p50, c.p99, c.max
        );
    }
    println!("image            {}", size_line(&size));
    Ok(())
}

fn image(args: ImageArgs) -> Result<()> {
    use bank_format::region::{RAM_LEN, RAM_ORIGIN};
    let size = haptic::mcu::image_size(&args.elf, RAM_ORIGIN, RAM_LEN as u32)?;
    let sp = haptic::mcu::initial_stack_pointer(&args.elf, bank_format::region::FIRMWARE_ORIGIN)?;
    println!("{}", size_line(&size));
    println!("initial stack pointer {sp:#010x}");
    Ok(())
}

/// An image's flash and static RAM against the firmware and RAM regions of memory.x, as
/// `bench sil` and `bench image` print it.
fn size_line(size: &haptic::mcu::ImageSize) -> String {
    use bank_format::region::{FIRMWARE_LEN, RAM_LEN};
    format!(
        "flash {} B of {} B ({:.1}%), static RAM {} B of {} B ({:.1}%)",
        size.flash,
        FIRMWARE_LEN,
        100.0 * size.flash as f64 / FIRMWARE_LEN as f64,
        size.ram,
        RAM_LEN,
        100.0 * size.ram as f64 / RAM_LEN as f64
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn size_line_against_the_regions() {
        use bank_format::region::{FIRMWARE_LEN, RAM_LEN};
        let size = haptic::mcu::ImageSize {
            flash: FIRMWARE_LEN as u64 / 4,
            ram: 1_000,
        };
        let ram_pct = 100.0 * 1_000.0 / RAM_LEN as f64;
        assert_eq!(
            size_line(&size),
            format!(
                "flash {} B of {FIRMWARE_LEN} B (25.0%), static RAM 1000 B of {RAM_LEN} B \
                 ({ram_pct:.1}%)",
                FIRMWARE_LEN / 4
            )
        );
    }
}
