//! `host bank build | inspect | sweep`: firmware banks from scene files.

use anyhow::{Context, Result, bail};
use bank_format::region::BANK_LEN;
use bank_format::{AlignedBytes, Bank, LawKind, SectionKind};
use fem::compliance::{Block3, contact_forces};
use fem::mesh::{Surface, TetMesh};
use firmware::patch::tool_patch;
use firmware::solve::WeightedSolve;
use host::bank::{BuiltBank, Prepared};
use host::contact::{ContactSurface, SurfaceHit, patch_force};
use host::fsio::write_atomic;
use host::progress::Bar;
use host::scene::MeshSource;
use std::collections::HashMap;
use std::path::PathBuf;
use std::time::Instant;

/// Bank subcommands.
#[derive(clap::Subcommand, Debug)]
pub enum BankCmd {
    /// Build a bank from a scene file (atomic write: nothing is left behind on error).
    Build(BuildArgs),
    /// Validate a bank file and print what it holds; exits non-zero when it is invalid.
    Inspect(InspectArgs),
    /// Truncation radius -> couplings kept -> bank bytes -> force error against the full
    /// compliance, for presses spread over the reachable region.
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
    scene: PathBuf,
    /// Truncation radii, m, comma separated.
    #[arg(long, default_value = "0,0.004,0.008,0.012,0.016,0.02,0.03")]
    radii: String,
    /// Number of press sites spread over the reachable region.
    #[arg(long, default_value_t = 20)]
    sites: usize,
    /// Press depth along the inward normal, m.
    #[arg(long, default_value_t = 0.005)]
    depth: f64,
}

/// Runs a bank subcommand.
pub fn run(cmd: BankCmd) -> Result<()> {
    match cmd {
        BankCmd::Build(a) => build(a),
        BankCmd::Inspect(a) => inspect(a),
        BankCmd::Sweep(a) => sweep(a),
    }
}

/// `(kind name, offset, len, count)` of each entry of the bank's section table.
/// The largest candidate list of the grid's cells, and the mean over the cells of clearance
/// at most 1 (those where detection tests candidates).
fn candidate_stats(bank: &bank_format::Bank) -> (usize, f64) {
    let g = bank.grid();
    let (mut max, mut sum, mut near) = (0, 0usize, 0usize);
    for c in 0..g.cell_count() {
        let k = g.cell_triangles(c).len();
        max = max.max(k);
        if g.clearance(c) <= 1 {
            sum += k;
            near += 1;
        }
    }
    (
        max,
        if near > 0 {
            sum as f64 / near as f64
        } else {
            0.0
        },
    )
}

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
    prep.warnings.iter().for_each(|w| eprintln!("{w}"));
    let radius = prep.scene.bank.truncation_radius_m;
    let progress = Bar::new("supernodes");
    let BuiltBank { bytes, pairs } = prep.build_bank(Some(&progress))?;
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
    if let MeshSource::File(mesh) = &prep.scene.mesh {
        inputs.push(mesh);
    }
    write_atomic(&args.out, &bytes, &inputs)?;
    // Read back what was written.
    let written = std::fs::read(&args.out)?;
    let aligned = AlignedBytes::new(&written);
    let bank = Bank::parse(&aligned).map_err(|e| {
        anyhow::anyhow!("{}: written bank fails validation: {e}", args.out.display())
    })?;
    let (lo, hi) = prep.mesh.bounding_box();
    println!(
        "scene     {} ({}, {} nodes, {} surface nodes, box [{:.3}, {:.3}] x [{:.3}, {:.3}] x \
         [{:.3}, {:.3}] m)",
        args.scene.display(),
        prep.mesh_name,
        prep.mesh.nodes.len(),
        prep.surface.nodes.len(),
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
        prep.scene.tip_radius_m,
        prep.scene.bank.reach_margin_m
    );
    println!(
        "couplings {pairs} pairs kept (truncation radius {radius} m, plus every triangle edge), \
         {} neighbour entries",
        2 * pairs
    );
    let (mut most, mut dropped) = (0, 0.0f32);
    for (t, tri) in bank.triangles().iter().enumerate() {
        let p = bank.positions();
        let v = tri.map(|k| p[usize::from(k)]);
        let centroid = std::array::from_fn(|i| (v[0][i] + v[1][i] + v[2][i]) / 3.0);
        let patch = tool_patch(
            &bank,
            t as u32,
            *tri,
            [1.0 / 3.0; 3],
            centroid,
            bank.device().tip_radius_m,
        );
        most = most.max(patch.nodes().len());
        dropped = dropped.max(patch.dropped);
    }
    println!(
        "tool      tip radius {} m: patches of up to {most} nodes at the triangles' centroids; at \
         most {:.1}% of a patch's load dropped (nodes the bank does not couple, or beyond {} \
         nodes){}",
        prep.scene.tip_radius_m,
        100.0 * dropped,
        firmware::solve::MAX_CONTACT_NODES,
        if dropped > 0.01 {
            ": raise bank.truncation_radius_m (see `host bank sweep`)"
        } else {
            ""
        }
    );
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
        .map(|k| bank.neighbours(k).0.len())
        .sum::<usize>()
        / 2;
    let sections = section_table(&bank);
    let cand = candidate_stats(&bank);
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
                "max_candidates": cand.0, "mean_candidates_near_surface": cand.1,
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
                "max_joint_speed": d.max_joint_speed,
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
        cand.0,
        cand.1
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
    println!("sections  kind                  offset     bytes   count");
    for (name, off, len, count) in sections {
        println!("          {name:<20} {off:>7} {len:>9} {count:>7}");
    }
    Ok(())
}

/// Press sites spread over R: farthest-point sampling from the node nearest R's centroid.
fn spread_sites(positions: &[[f64; 3]], count: usize) -> Vec<usize> {
    let n = positions.len();
    if n == 0 || count == 0 {
        return Vec::new();
    }
    let mut c = [0.0; 3];
    for p in positions {
        for i in 0..3 {
            c[i] += p[i] / n as f64;
        }
    }
    let d2 = |a: [f64; 3], b: [f64; 3]| (0..3).map(|i| (a[i] - b[i]).powi(2)).sum::<f64>();
    let first = (0..n)
        .min_by(|&a, &b| d2(positions[a], c).total_cmp(&d2(positions[b], c)))
        .unwrap_or(0);
    let mut sites = vec![first];
    let mut near: Vec<f64> = positions.iter().map(|p| d2(*p, positions[first])).collect();
    while sites.len() < count.min(n) {
        let next = (0..n)
            .max_by(|&a, &b| near[a].total_cmp(&near[b]))
            .unwrap_or(0);
        if near[next] == 0.0 {
            break;
        }
        sites.push(next);
        for (k, p) in positions.iter().enumerate() {
            near[k] = near[k].min(d2(*p, positions[next]));
        }
    }
    sites
}

/// Outward unit vertex normals (area-weighted) of the mesh's boundary, indexed by mesh node.
fn vertex_normals(mesh: &TetMesh, surface: &Surface) -> Vec<[f64; 3]> {
    let mut n = vec![[0.0; 3]; mesh.nodes.len()];
    for t in &surface.triangles {
        let [a, b, c] = t.map(|i| mesh.nodes[i]);
        let u = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
        let v = [c[0] - a[0], c[1] - a[1], c[2] - a[2]];
        let w = [
            u[1] * v[2] - u[2] * v[1],
            u[2] * v[0] - u[0] * v[2],
            u[0] * v[1] - u[1] * v[0],
        ];
        for &i in t {
            for j in 0..3 {
                n[i][j] += w[j];
            }
        }
    }
    for v in &mut n {
        let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        if l > 0.0 {
            *v = v.map(|x| x / l);
        }
    }
    n
}

/// Relative error of the total tool force with a truncated `C_SS` (`keep(a, b)` says whether
/// the pair of contact nodes `a`, `b` is stored) against the full one; `None` when the truncated
/// `C_SS` is not positive definite.
fn force_error(
    full: &[Vec<Block3>],
    keep: impl Fn(usize, usize) -> bool,
    press: [f64; 3],
) -> Result<Option<f64>> {
    let m = full.len();
    let total = |c: &[Vec<Block3>]| -> Result<Option<[f64; 3]>> {
        match contact_forces(c, &vec![press; m]) {
            Ok(s) => Ok(Some(s.forces.iter().fold([0.0; 3], |acc, f| {
                [acc[0] + f[0], acc[1] + f[1], acc[2] + f[2]]
            }))),
            Err(_) => Ok(None),
        }
    };
    let exact = total(full)?.context("the full C_SS is not positive definite")?;
    let cut: Vec<Vec<Block3>> = (0..m)
        .map(|a| {
            (0..m)
                .map(|b| {
                    if a == b || keep(a, b) {
                        full[a][b]
                    } else {
                        [[0.0; 3]; 3]
                    }
                })
                .collect()
        })
        .collect();
    let norm = |v: [f64; 3]| (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    Ok(total(&cut)?
        .map(|t| norm([t[0] - exact[0], t[1] - exact[1], t[2] - exact[2]]) / norm(exact)))
}

#[derive(Default)]
struct Stat {
    max: f64,
    sum: f64,
    count: usize,
    not_spd: usize,
}

impl Stat {
    fn add(&mut self, e: Option<f64>) {
        match e {
            Some(e) => {
                self.max = self.max.max(e);
                self.sum += e;
                self.count += 1;
            }
            None => self.not_spd += 1,
        }
    }
    fn show(&self) -> String {
        let mean = if self.count > 0 {
            self.sum / self.count as f64
        } else {
            f64::NAN
        };
        let mut s = format!("{:>7.1}% {:>7.1}%", 100.0 * self.max, 100.0 * mean);
        if self.not_spd > 0 {
            s.push_str(&format!(" ({} not SPD)", self.not_spd));
        }
        s
    }
}

/// The tool patch on a bank against the host's f64 patch on R's surface with untruncated
/// compliance, at a press site: the firmware's `tool_patch` + `WeightedSolve` (couplings as
/// truncated in `bank`) and `host::contact` on the same anchor.
struct PatchCheck<'p> {
    prep: &'p Prepared,
    surface: ContactSurface,
}

/// One tool-patch comparison: relative tool-force error and the weight share the firmware
/// dropped (uncoupled or beyond the contact-set cap).
struct PatchError {
    error: f64,
    dropped: f64,
}

impl<'p> PatchCheck<'p> {
    fn new(prep: &'p Prepared) -> PatchCheck<'p> {
        let region = Surface {
            triangles: prep
                .triangles
                .iter()
                .map(|t| t.map(|k| prep.region[k as usize]))
                .collect(),
            nodes: prep.region.clone(),
        };
        PatchCheck {
            prep,
            surface: ContactSurface::new(&prep.mesh, &region),
        }
    }

    /// Presses triangle `t` (index into R's triangles) at its centroid by `press` (m).
    fn press(&self, bank: &Bank, t: usize, press: [f64; 3]) -> Result<PatchError> {
        let prep = self.prep;
        let tri = prep.triangles[t];
        let v = tri.map(|k| prep.positions[k as usize]);
        let centroid: [f64; 3] = std::array::from_fn(|i| (v[0][i] + v[1][i] + v[2][i]) / 3.0);
        let hit = SurfaceHit {
            triangle: t,
            nodes: tri.map(|k| prep.region[k as usize]),
            bary: [1.0 / 3.0; 3],
            point: centroid,
        };
        let radius = prep.scene.tip_radius_m;
        let full = self.surface.tool_patch(&hit, radius, |_| true);
        let exact = patch_force(&prep.compliance, &full, press)?;
        let patch = tool_patch(
            bank,
            t as u32,
            tri.map(|k| k as u16),
            [1.0 / 3.0; 3],
            centroid.map(|x| x as f32),
            radius as f32,
        );
        let got = WeightedSolve::new(bank, patch.nodes(), patch.weights())
            .and_then(|s| s.forces(press.map(|x| x as f32)))
            .map_err(|e| anyhow::anyhow!("firmware solve at triangle {t}: {e}"))?;
        let norm = |v: [f64; 3]| (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        let diff: [f64; 3] = std::array::from_fn(|i| f64::from(got.tool_force_n[i]) - exact[i]);
        Ok(PatchError {
            error: norm(diff) / norm(exact),
            dropped: f64::from(patch.dropped),
        })
    }
}

fn sweep(args: SweepArgs) -> Result<()> {
    if args.sites == 0 {
        bail!("--sites must be at least 1");
    }
    let radii = super::fixing::parse_list::<f64>(&args.radii).context("--radii")?;
    if radii.iter().any(|r| !(r.is_finite() && *r >= 0.0)) {
        bail!("--radii: every radius must be a number >= 0");
    }
    let rmax = radii.iter().copied().fold(0.0, f64::max);
    let prep = Prepared::load(&args.scene)?;
    let progress = Bar::new("supernodes");
    let rows = prep.blocks(rmax, Some(&progress))?;
    progress.finish();
    let normals = vertex_normals(&prep.mesh, &prep.surface);

    // Contact sets per site: one node; one triangle; the tool patch at the triangle's
    // centroid (firmware on the bank, against the host's f64 patch).
    let sites = spread_sites(&prep.positions, args.sites);
    let mut presses: Vec<([f64; 3], Vec<usize>, usize)> = Vec::new();
    for &k in &sites {
        let nrm = normals[prep.region[k]];
        let press = nrm.map(|x| -args.depth * x);
        let Some(t) = prep.triangles.iter().position(|t| t.contains(&(k as u32))) else {
            continue;
        };
        let tri: Vec<usize> = prep.triangles[t].iter().map(|&v| v as usize).collect();
        presses.push((press, tri, t));
    }
    let check = PatchCheck::new(&prep);
    // Full (untruncated) blocks among every contact node.
    let mut union: Vec<usize> = presses
        .iter()
        .flat_map(|(_, t, _)| t.iter().copied())
        .collect();
    union.sort_unstable();
    union.dedup();
    let mesh_ids: Vec<usize> = union.iter().map(|&a| prep.region[a]).collect();
    let full = prep.compliance.blocks(&mesh_ids, None)?;
    let at: HashMap<usize, usize> = union.iter().enumerate().map(|(i, &a)| (a, i)).collect();
    let sub = |set: &[usize]| -> Vec<Vec<Block3>> {
        set.iter()
            .map(|a| set.iter().map(|b| full[at[a]][at[b]]).collect())
            .collect()
    };

    println!(
        "scene {}: |R| = {}, {} press sites, {:.1} mm along the inward normal; relative error \
         of the total tool force against the full C_SS (max, mean)",
        args.scene.display(),
        prep.region.len(),
        presses.len(),
        args.depth * 1e3
    );
    println!(
        "| radius (mm) | pairs kept | bank bytes | fits 768 KiB | 1 node | triangle, pairs <= r only | tool patch r = {:.1} mm, firmware on the bank | patch weight dropped (max) |",
        prep.scene.tip_radius_m * 1e3
    );
    println!("| ---: | ---: | ---: | :---: | --- | --- | --- | ---: |");
    for &r in &radii {
        let BuiltBank { bytes, pairs } = prep.bank(&rows, r)?;
        let aligned = AlignedBytes::new(&bytes);
        let bank = Bank::parse(&aligned).map_err(|e| anyhow::anyhow!("swept bank: {e}"))?;
        let (mut one, mut tri, mut patch) = (Stat::default(), Stat::default(), Stat::default());
        let mut dropped: f64 = 0.0;
        for (press, t, ti) in &presses {
            one.add(force_error(&sub(&t[..1]), |_, _| false, *press)?);
            tri.add(force_error(
                &sub(t),
                |a, b| prep.dist(t[a], t[b]) <= r,
                *press,
            )?);
            let e = check.press(&bank, *ti, *press)?;
            patch.add(Some(e.error));
            dropped = dropped.max(e.dropped);
        }
        println!(
            "| {:.1} | {pairs} | {} | {} | {} | {} | {} | {:.1}% |",
            r * 1e3,
            bytes.len(),
            if bytes.len() <= BANK_LEN { "yes" } else { "no" },
            one.show(),
            tri.show(),
            patch.show(),
            100.0 * dropped
        );
    }
    Ok(())
}
