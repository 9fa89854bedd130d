//! Compliance blocks by the Schur complement (`host::schur`) against the column solves of
//! `Compliance::blocks`, with timings of both (printed, never asserted).
//!
//! Run with `cargo test --release -p host --test schur -- --nocapture` to see the figures.

use host::compliance::{Block3, Compliance, ComplianceError};
use host::fem::{Elasticity, FemError, FixedSet, Material};
use host::mesh::TetMesh;
use host::mesh::structured::box_mesh;
use host::schur::compliance_blocks;
use std::path::Path;
use std::sync::Mutex;
use std::time::Instant;

type TestResult = Result<(), Box<dyn std::error::Error>>;

/// The tests run one at a time so that timings and peak memory are not disturbed.
static SERIAL: Mutex<()> = Mutex::new(());

fn serial() -> std::sync::MutexGuard<'static, ()> {
    SERIAL.lock().unwrap_or_else(|e| e.into_inner())
}

fn liver(name: &str) -> Result<TetMesh, Box<dyn std::error::Error>> {
    Ok(host::mesh::load(
        &Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("meshes")
            .join(name),
    )?)
}

/// The organ on a bed: every node less than 1 cm high fixed.
fn bedded(mesh: &TetMesh) -> Result<(Elasticity, FixedSet), FemError> {
    let body = Elasticity::new(mesh, Material::new(3.0e3, 0.45)?)?;
    let mut fixed = FixedSet::none(mesh.nodes.len());
    fixed.fix_box(mesh, [-1.0, -1.0, -1.0, 1.0, 1.0, 0.01], [true; 3])?;
    Ok((body, fixed))
}

/// Free boundary nodes (no fixed component).
fn free_surface(
    mesh: &TetMesh,
    fixed: &FixedSet,
) -> Result<Vec<usize>, Box<dyn std::error::Error>> {
    Ok(host::mesh::boundary(mesh)?
        .nodes
        .into_iter()
        .filter(|&i| (0..3).all(|c| !fixed.is_fixed(i, c)))
        .collect())
}

/// `(max |a - b|, max |b|)` over all entries.
fn max_difference(a: &[Vec<Block3>], b: &[Vec<Block3>]) -> (f64, f64) {
    assert_eq!(a.len(), b.len());
    let mut diff = 0.0f64;
    let mut scale = 0.0f64;
    for (ra, rb) in a.iter().zip(b) {
        assert_eq!(ra.len(), rb.len());
        for (x, y) in ra
            .iter()
            .flatten()
            .flatten()
            .zip(rb.iter().flatten().flatten())
        {
            diff = diff.max((x - y).abs());
            scale = scale.max(y.abs());
        }
    }
    (diff, scale)
}

fn assert_agree(new: &[Vec<Block3>], old: &[Vec<Block3>], what: &str) {
    let (diff, scale) = max_difference(new, old);
    eprintln!(
        "{what}: max |difference| {diff:.3e}, max |C| {scale:.3e}, relative {:.3e}",
        diff / scale
    );
    assert!(scale > 0.0, "{what}: all blocks zero");
    assert!(
        diff <= 1e-10 * scale,
        "{what}: relative difference {:e}",
        diff / scale
    );
}

/// Peak resident set size since the last reset, in MiB (Linux; 0 elsewhere).
fn peak_rss_mib() -> f64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmHWM:"))
                .and_then(|l| l.split_whitespace().nth(1)?.parse::<f64>().ok())
        })
        .map_or(0.0, |kib| kib / 1024.0)
}

/// CPU time (user + system, all threads) of this process in seconds (Linux; 0 elsewhere).
fn cpu_seconds() -> f64 {
    // Fields 14 and 15 of /proc/self/stat, after the parenthesised command name, in clock
    // ticks (100 per second on Linux).
    std::fs::read_to_string("/proc/self/stat")
        .ok()
        .and_then(|s| {
            let rest = &s[s.rfind(')')? + 1..];
            let f: Vec<&str> = rest.split_whitespace().collect();
            Some((f.get(11)?.parse::<f64>().ok()? + f.get(12)?.parse::<f64>().ok()?) / 100.0)
        })
        .unwrap_or(0.0)
}

fn reset_peak_rss() {
    let _ = std::fs::write("/proc/self/clear_refs", "5");
}

/// Both methods on a liver with all free surface nodes requested; prints time and peak memory.
fn compare_on_liver(name: &str) -> TestResult {
    let mesh = liver(name)?;
    let (body, fixed) = bedded(&mesh)?;
    let nodes = free_surface(&mesh, &fixed)?;

    reset_peak_rss();
    let (t, cpu) = (Instant::now(), cpu_seconds());
    let c = Compliance::factorize(&body, &fixed)?;
    let factor_s = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let old = c.blocks(&nodes, None)?;
    let columns_s = t.elapsed().as_secs_f64();
    let old_cpu = cpu_seconds() - cpu;
    drop(c);
    let old_peak = peak_rss_mib();

    reset_peak_rss();
    let (t, cpu) = (Instant::now(), cpu_seconds());
    let new = compliance_blocks(&body, &fixed, &nodes)?;
    let schur_s = t.elapsed().as_secs_f64();
    let new_cpu = cpu_seconds() - cpu;
    let new_peak = peak_rss_mib();

    eprintln!(
        "{name}: {} requested nodes, {} threads; columns: factor {factor_s:.3} s + solves \
         {columns_s:.3} s = {:.3} s wall, {old_cpu:.2} s CPU, peak {old_peak:.0} MiB; \
         schur: {schur_s:.3} s wall, {new_cpu:.2} s CPU, peak {new_peak:.0} MiB",
        nodes.len(),
        rayon::current_num_threads(),
        factor_s + columns_s,
    );
    assert_agree(&new, &old, name);
    Ok(())
}

#[test]
fn liver_free_surface_matches_column_solves() -> TestResult {
    let _guard = serial();
    compare_on_liver("liver-1k4.msh")
}

#[test]
fn liver_10k_timings() -> TestResult {
    let _guard = serial();
    compare_on_liver("liver-10k.msh")
}

#[test]
fn partially_fixed_nodes_get_zero_rows() -> TestResult {
    let _guard = serial();
    let mesh = liver("liver-1k4.msh")?;
    let (body, mut fixed) = bedded(&mesh)?;
    // A slide-only wall: the nodes with the smallest x may only move in y and z.
    let (lo, hi) = mesh.bounding_box();
    let wall = lo[0] + 0.1 * (hi[0] - lo[0]);
    fixed.fix_box(
        &mesh,
        [-1.0, -1.0, -1.0, wall, 1.0, 1.0],
        [true, false, false],
    )?;
    let surface = host::mesh::boundary(&mesh)?.nodes;
    let partial: Vec<usize> = surface
        .iter()
        .copied()
        .filter(|&i| fixed.is_fixed(i, 0) && !fixed.is_fixed(i, 1))
        .take(20)
        .collect();
    let full: Vec<usize> = surface
        .iter()
        .copied()
        .filter(|&i| fixed.is_fixed(i, 2))
        .take(5)
        .collect();
    let free = free_surface(&mesh, &fixed)?;
    assert!(!partial.is_empty() && !full.is_empty());
    // Interleave the kinds, in no particular order.
    let mut nodes: Vec<usize> = Vec::new();
    for (i, &k) in free.iter().rev().take(60).enumerate() {
        nodes.push(k);
        if let Some(&p) = partial.get(i) {
            nodes.push(p);
        }
        if let Some(&f) = full.get(i) {
            nodes.push(f);
        }
    }
    let old = Compliance::factorize(&body, &fixed)?.blocks(&nodes, None)?;
    let new = compliance_blocks(&body, &fixed, &nodes)?;
    assert_agree(&new, &old, "liver-1k4 with a slide-only wall");
    for (a, &k) in nodes.iter().enumerate() {
        for (b, &l) in nodes.iter().enumerate() {
            for r in 0..3 {
                for c in 0..3 {
                    if fixed.is_fixed(k, r) || fixed.is_fixed(l, c) {
                        assert_eq!(new[a][b][r][c], 0.0, "C({k},{l})[{r}][{c}]");
                    }
                }
            }
        }
    }
    Ok(())
}

#[test]
fn structured_box_matches_column_solves() -> TestResult {
    let _guard = serial();
    let size = [0.06, 0.04, 0.03];
    let mesh = box_mesh(size, [8, 6, 5]);
    let body = Elasticity::new(&mesh, Material::new(3.0e3, 0.45)?)?;
    let mut fixed = FixedSet::none(mesh.nodes.len());
    fixed.fix_box(&mesh, [-1.0, -1.0, -1.0, 1.0, 1.0, 1e-9], [true; 3])?;
    // Top face, plus a few interior and bed nodes.
    let mut nodes: Vec<usize> = (0..mesh.nodes.len())
        .filter(|&i| mesh.nodes[i][2] > size[2] - 1e-9)
        .collect();
    nodes.extend([7, 100, 200, 3]);
    let old = Compliance::factorize(&body, &fixed)?.blocks(&nodes, None)?;
    let new = compliance_blocks(&body, &fixed, &nodes)?;
    assert_agree(&new, &old, "box 8x6x5, top face");
    // A single node, and every node of the mesh.
    for nodes in [vec![150], (0..mesh.nodes.len()).collect::<Vec<_>>()] {
        let old = Compliance::factorize(&body, &fixed)?.blocks(&nodes, None)?;
        let new = compliance_blocks(&body, &fixed, &nodes)?;
        assert_agree(&new, &old, &format!("box 8x6x5, {} nodes", nodes.len()));
    }
    assert!(compliance_blocks(&body, &fixed, &[])?.is_empty());
    Ok(())
}

#[test]
fn bad_requests_are_refused() -> TestResult {
    let _guard = serial();
    let mesh = box_mesh([0.03, 0.02, 0.02], [3, 2, 2]);
    let body = Elasticity::new(&mesh, Material::new(3.0e3, 0.45)?)?;
    let mut fixed = FixedSet::none(mesh.nodes.len());
    let n = mesh.nodes.len();
    assert!(matches!(
        compliance_blocks(&body, &fixed, &[n - 1]),
        Err(ComplianceError::Fem(FemError::RigidMotion(_)))
    ));
    fixed.fix_box(&mesh, [-1.0, -1.0, -1.0, 1.0, 1.0, 1e-9], [true; 3])?;
    assert!(matches!(
        compliance_blocks(&body, &fixed, &[n - 1, n]),
        Err(ComplianceError::NoSuchNode { node, nodes }) if node == n && nodes == n
    ));
    assert!(matches!(
        compliance_blocks(&body, &fixed, &[n - 1, 4, n - 1]),
        Err(ComplianceError::DegenerateContact(_))
    ));
    let other = FixedSet::none(n + 3);
    assert!(compliance_blocks(&body, &other, &[0]).is_err());
    Ok(())
}
