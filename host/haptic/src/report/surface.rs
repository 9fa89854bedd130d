//! The contact against the organ's own surface: a sampled scene's firmware presses on the
//! collision surface (the scene's `mesh`), while the organ is the FEM mesh's surface
//! (`[contact] fem_mesh`). This section presses where the organ is: random sites drawn
//! area-uniformly over the FEM surface's reachable part, each pressed 5 mm along the FEM
//! surface's inward normal from the FEM surface point (the firmware's own tick on the scene's
//! bank, [`crate::probe::press`], linear model), against the continuum's force there.
//!
//! **Sites** ([`draw`]): FEM boundary triangles with no fixed vertex, drawn by area, a point
//! uniform in the triangle; kept when its outward normal faces the trocar (the shaft comes
//! from there) and the device can make the whole press ([`crate::probe::press_fits`]). A fixed
//! seed: the same sites every run.
//!
//! **Reference** ([`reference_w`]): the patch compliance `W` of the scene's tool computed
//! directly at each site on the scene's FEM mesh and on its Richardson partner, extrapolated
//! with the scene's Richardson factor (what the bank's samples hold, but at the site itself,
//! not interpolated, and at the organ's surface point, not at a collision-surface point's
//! closest one); the force of the press is `W_ref^-1 d`, `d` 5 mm along the FEM normal. Its own
//! error against the converged continuum is that of the scene's extrapolation, measured at the
//! study's 14 sites against `host/tests/data/patch-study-p2.json` and stored with the sites.
//!
//! **Per site** ([`check`]): the angle between the collision triangle's normal (the triangle
//! whose point is closest to the site) and the FEM normal; whether the reachable region R
//! (cut on the collision surface) holds the site, and if not by how much it falls short (the
//! distance from the organ's closest collision point to R); and the rendered force's relative
//! error.

use super::{HardCase, Verdict};
use crate::bank::sampled::{SampledFem, extrapolated};
use crate::linalg::solve3;
use crate::organ::Organ;
use crate::probe::{PressPath, closest_point, closest_reachable, press, press_fits};
use crate::reach::Region;
use crate::rng::SplitMix64;
use crate::scene::{ContactModel, Scene};
use anyhow::{Context, Result, bail};
use bank_format::Bank;
use fem::compliance::Block3;
use fem::vec3::{cross, dist2, dot, norm, scale, sub};
use serde::{Deserialize, Serialize};

/// The press depth of the check, m.
pub const DEPTH_M: f64 = 0.005;

/// The sites and their reference committed with the tests (module notes).
const COMMITTED: &str = include_str!("../../../tests/data/surface-sites.json");

/// A point of the organ's (FEM mesh's) surface.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq)]
pub struct SurfaceSite {
    /// The point, m.
    pub point: [f64; 3],
    /// The FEM surface's outward unit normal there.
    pub normal: [f64; 3],
}

/// Random sites with their reference, as committed (`host/tests/data/surface-sites.json`).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct SurfaceSites {
    /// The file name of the FEM mesh the sites lie on.
    pub fem_mesh: String,
    /// FNV-1a 64 of the FEM mesh file's bytes.
    pub fem_mesh_hash: u64,
    /// The Richardson partner `W` was extrapolated with, if any.
    pub richardson_mesh: Option<String>,
    /// The seed of the draw.
    pub seed: u64,
    /// The sites.
    pub sites: Vec<SurfaceSite>,
    /// `W_ref` per site, m/N.
    pub reference_w: Vec<Block3>,
    /// The same extrapolation's normal stiffness against the converged continuum at the
    /// study's 14 sites: its largest relative difference (the reference's own error).
    pub reference_error: f64,
}

/// The committed sites.
pub fn committed() -> Result<SurfaceSites> {
    serde_json::from_str(COMMITTED).context("the committed surface sites do not parse")
}

/// Which FEM surface points [`draw`] keeps.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Reach {
    /// The device can make the whole 5 mm press there ([`crate::probe::press_fits`]).
    Press,
    /// Within the scene's tip radius and reach margin of the tip's workspace, the test R
    /// applies to the collision surface's nodes ([`crate::kinematics::Workspace::reaches`]).
    Region,
}

/// `count` sites over the reachable part (`reach`) of the sampled `scene`'s FEM surface
/// (module notes), from `seed`.
pub fn draw(scene: &Scene, count: usize, seed: u64, reach: Reach) -> Result<Vec<SurfaceSite>> {
    let ContactModel::Sampled(spec) = &scene.contact else {
        bail!("the surface sites need a scene with [contact] model = \"sampled\"");
    };
    let (mesh, _) = scene.read_organ_mesh(&spec.fem_mesh, "[contact] fem_mesh")?;
    let boundary = fem::mesh::boundary(&mesh)?;
    let fixed = scene.fixed_set(&mesh)?;
    let free = |k: usize| (0..3).all(|c| !fixed.is_fixed(k, c));
    let triangles: Vec<[[f64; 3]; 3]> = boundary
        .triangles
        .iter()
        .filter(|t| t.iter().all(|&k| free(k)))
        .map(|t| t.map(|k| mesh.nodes[k]))
        .collect();
    let mut cumulative = Vec::with_capacity(triangles.len());
    let mut total = 0.0;
    for t in &triangles {
        total += 0.5 * norm(cross(sub(t[1], t[0]), sub(t[2], t[0])));
        cumulative.push(total);
    }
    if total.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
        bail!("the FEM surface has no free triangle");
    }
    let fulcrum = scene.device.fulcrum_m.map(f64::from);
    let workspace = crate::kinematics::Workspace::from_device(&scene.device);
    let mut rng = SplitMix64::new(seed);
    let mut sites = Vec::with_capacity(count);
    let attempts = 1000 * count.max(1);
    for _ in 0..attempts {
        if sites.len() == count {
            break;
        }
        let a = rng.unit() * total;
        let i = cumulative
            .partition_point(|&c| c < a)
            .min(triangles.len() - 1);
        let t = triangles[i];
        let (r1, r2) = (rng.unit().sqrt(), rng.unit());
        let b = [1.0 - r1, r1 * (1.0 - r2), r1 * r2];
        let point: [f64; 3] = std::array::from_fn(|c| (0..3).map(|k| b[k] * t[k][c]).sum());
        let n = cross(sub(t[1], t[0]), sub(t[2], t[0]));
        let normal = scale(n, 1.0 / norm(n));
        let reached = match reach {
            Reach::Press => press_fits(&scene.device, point, scale(normal, -1.0), DEPTH_M),
            Reach::Region => {
                workspace.reaches(point, scene.tip_radius_m + scene.bank.reach_margin_m)
            }
        };
        if dot(normal, sub(fulcrum, point)) <= 0.0 || !reached {
            continue;
        }
        sites.push(SurfaceSite { point, normal });
    }
    if sites.len() < count {
        bail!(
            "only {} of {count} sites found in {attempts} draws: the tool reaches little of \
             the FEM surface",
            sites.len()
        );
    }
    Ok(sites)
}

/// `W` of the scene's tool at `points` on the sampled `scene`'s FEM mesh, Richardson-
/// extrapolated with its partner when it has one (module notes).
pub fn reference_w(scene: &Scene, points: &[[f64; 3]]) -> Result<Vec<Block3>> {
    let ContactModel::Sampled(spec) = &scene.contact else {
        bail!("the reference needs a scene with [contact] model = \"sampled\"");
    };
    let r = scene.tip_radius_m;
    let fine = SampledFem::new(scene, spec)?;
    let (w, ..) = fine.patch_compliance(points, r, None)?;
    drop(fine);
    let Some(rich) = &spec.richardson else {
        return Ok(w);
    };
    let coarse = SampledFem::load(scene, &rich.mesh, spec.element)?;
    let (w_c, ..) = coarse.patch_compliance(points, r, None)?;
    Ok(extrapolated(&w, &w_c, rich.factor()))
}

/// How far R (cut on the collision surface) falls short of each of `sites`, m: the distance
/// from the organ's collision-surface point closest to the site to R's nearest point, 0 where
/// R holds the site ([`crate::probe::closest_reachable`] accepts it).
pub fn shortfalls(organ: &Organ, region: &Region, sites: &[SurfaceSite]) -> Vec<f64> {
    let triangles: Vec<[usize; 3]> = region
        .triangles
        .iter()
        .map(|t| t.map(|k| k as usize))
        .collect();
    let surface = (&organ.mesh.nodes[..], &organ.surface.triangles[..]);
    sites
        .iter()
        .map(
            |site| match closest_reachable(&region.positions, &triangles, surface, site.point) {
                Ok(_) => 0.0,
                Err(_) => closest_point(surface.0, surface.1, site.point).map_or(
                    f64::INFINITY,
                    |(_, o, ..)| {
                        closest_point(&region.positions, &triangles, o)
                            .map_or(f64::INFINITY, |(.., d2)| d2.sqrt())
                    },
                ),
            },
        )
        .collect()
}

/// What one site shows.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SiteCheck {
    /// Angle between the closest collision triangle's normal and the FEM normal, rad.
    pub angle_rad: f64,
    /// Where the press line crosses the collision surface (the plane of the collision triangle
    /// closest to the site), m along the FEM outward normal from the site: positive when the
    /// collision surface lies outside the organ there (the contact starts early and the
    /// firmware's depth is that much too large), negative when inside.
    pub offset_m: f64,
    /// How far R falls short of the site, m: the distance from the organ's collision-surface
    /// point closest to it to R's nearest point (0 when R holds it).
    pub shortfall_m: f64,
    /// The force the firmware's tick renders for the press, N (`None`: refused or failed).
    pub rendered: Option<[f64; 3]>,
    /// `W_ref^-1 d`, N.
    pub reference: [f64; 3],
    /// `|rendered - reference| / |reference|` (1 when nothing was rendered).
    pub error: f64,
}

/// Each of `sites` (with `reference_w`) checked on `bank`, the scene's `organ` and `region`
/// (module notes).
pub fn check(
    organ: &Organ,
    region: &Region,
    bank: &Bank<'_>,
    sites: &[SurfaceSite],
    reference_w: &[Block3],
) -> Vec<SiteCheck> {
    let surface = (&organ.mesh.nodes[..], &organ.surface.triangles[..]);
    let short = shortfalls(organ, region, sites);
    sites
        .iter()
        .zip(reference_w)
        .zip(short)
        .map(|((site, w), shortfall_m)| {
            let closest = closest_point(surface.0, surface.1, site.point);
            let (angle_rad, offset_m) = closest.map_or((std::f64::consts::PI, 0.0), |(t, ..)| {
                let v = surface.1[t].map(|k| surface.0[k]);
                let n = cross(sub(v[1], v[0]), sub(v[2], v[0]));
                let n = scale(n, 1.0 / norm(n));
                let cos = dot(n, site.normal).clamp(-1.0, 1.0);
                (cos.acos(), dot(sub(v[0], site.point), n) / cos)
            });
            let reference = solve3(w, scale(site.normal, DEPTH_M));
            let rendered = press(
                bank,
                site.point,
                scale(site.normal, -1.0),
                DEPTH_M,
                PressPath::PROBE,
                false,
            )
            .ok();
            let error = rendered.map_or(1.0, |f| {
                (dist2(f, reference) / dot(reference, reference)).sqrt()
            });
            SiteCheck {
                angle_rad,
                offset_m,
                shortfall_m,
                rendered,
                reference,
                error,
            }
        })
        .collect()
}

/// The summary of [`check`] over its sites.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Summary {
    /// Sites checked.
    pub sites: usize,
    /// Largest and mean normal angle, rad.
    pub angle_max_rad: f64,
    /// Mean normal angle, rad.
    pub angle_mean_rad: f64,
    /// Sites R refuses, and the largest shortfall, m.
    pub refused: usize,
    /// Largest shortfall, m.
    pub shortfall_max_m: f64,
    /// Mean and worst force error, and the worst site's index.
    pub error_mean: f64,
    /// Worst force error.
    pub error_max: f64,
    /// Index of the worst site.
    pub worst: usize,
}

/// [`Summary`] of `checks` (at least one).
pub fn summary(checks: &[SiteCheck]) -> Summary {
    let n = checks.len().max(1) as f64;
    let worst = (0..checks.len())
        .max_by(|&a, &b| checks[a].error.total_cmp(&checks[b].error))
        .unwrap_or(0);
    Summary {
        sites: checks.len(),
        angle_max_rad: checks.iter().map(|c| c.angle_rad).fold(0.0, f64::max),
        angle_mean_rad: checks.iter().map(|c| c.angle_rad).sum::<f64>() / n,
        refused: checks.iter().filter(|c| c.shortfall_m > 0.0).count(),
        shortfall_max_m: checks.iter().map(|c| c.shortfall_m).fold(0.0, f64::max),
        error_mean: checks.iter().map(|c| c.error).sum::<f64>() / n,
        error_max: checks.get(worst).map_or(0.0, |c| c.error),
        worst,
    }
}

/// A site's position for messages, mm.
pub fn name(site: &SurfaceSite) -> String {
    let p = site.point;
    format!(
        "[{:.1}, {:.1}, {:.1}] mm",
        1e3 * p[0],
        1e3 * p[1],
        1e3 * p[2]
    )
}

/// FEM surface points [`section`] draws for the reach row ([`Reach::Region`]).
pub const REACH_SITES: usize = 2000;

/// The report's rows for the sampled `scene` and its `bank`, from the committed sites (module
/// notes): the presses' force error (the worst site named), the collision normal's angle to the
/// organ's and the sites beyond the stick cone, and R's shortfall on the organ's surface
/// ([`REACH_SITES`] sites drawn by R's own reach test). Refuses a scene whose FEM mesh is not
/// the one the sites were drawn on.
pub fn section(scene: &Scene, bank: &[u8]) -> Result<Vec<HardCase>> {
    let ContactModel::Sampled(spec) = &scene.contact else {
        bail!("the surface check needs a scene with [contact] model = \"sampled\"");
    };
    let data = committed()?;
    if crate::bank::cache::file_hash(scene, &spec.fem_mesh)? != data.fem_mesh_hash {
        bail!(
            "the committed sites lie on {}, not on the scene's fem_mesh {}",
            data.fem_mesh,
            spec.fem_mesh.display()
        );
    }
    let organ = Organ::from_scene(scene.clone())?;
    let region = Region::of(&organ)?;
    let aligned = bank_format::AlignedBytes::new(bank);
    let bank = Bank::parse(&aligned).map_err(|e| anyhow::anyhow!("the scene's bank: {e}"))?;
    let checks = check(&organ, &region, &bank, &data.sites, &data.reference_w);
    let s = summary(&checks);
    let cone = f64::from(firmware::contact::STICK_SLOPE).atan();
    let inside: Vec<&SiteCheck> = checks.iter().filter(|c| c.angle_rad <= cone).collect();
    let beyond: Vec<&SiteCheck> = checks.iter().filter(|c| c.angle_rad > cone).collect();
    let worst_of = |v: &[&SiteCheck]| v.iter().map(|c| c.error).fold(0.0, f64::max);
    let offset_max = inside.iter().map(|c| c.offset_m.abs()).fold(0.0, f64::max);
    let within = checks.iter().filter(|c| c.error <= 0.05).count();
    let reach = draw(scene, REACH_SITES, data.seed, Reach::Region)?;
    let short = shortfalls(&organ, &region, &reach);
    let refused = short.iter().filter(|&&x| x > 0.0).count();
    let short_max = short.iter().copied().fold(0.0, f64::max);
    let reference = format!(
        "W of the scene's FEM and Richardson step computed at each site (not interpolated), \
         W^-1 d for d 5 mm along the FEM normal; within {:.1} % of the converged study at its \
         14 sites",
        100.0 * data.reference_error
    );
    Ok(vec![
        HardCase {
            case: format!(
                "5 mm presses along the organ's normal at {} random sites of its FEM surface",
                s.sites
            ),
            measurement: format!(
                "firmware force on the scene's bank: mean {:.1} %, worst {:.1} % at {}; {} of \
                 {} within 5 %",
                100.0 * s.error_mean,
                100.0 * s.error_max,
                data.sites.get(s.worst).map_or_else(String::new, name),
                within,
                s.sites
            ),
            reference,
            verdict: if s.error_max <= 0.05 {
                Verdict::MatchesReference
            } else {
                Verdict::Weakness
            },
            value: Some(s.error_max),
            reference_value: Some(0.05),
        },
        HardCase {
            case: "collision normal against the organ's (FEM surface) normal".into(),
            measurement: format!(
                "over {} sites: max {:.1} deg, mean {:.1} deg; {} sites beyond the stick cone \
                 ({:.1} deg), where the press slides on the collision triangle (force error up \
                 to {:.1} %); within it up to {:.1} %, all of it the collision surface's offset \
                 from the organ along the press (up to {:.2} mm), which shifts where contact \
                 starts",
                s.sites,
                s.angle_max_rad.to_degrees(),
                s.angle_mean_rad.to_degrees(),
                beyond.len(),
                cone.to_degrees(),
                100.0 * worst_of(&beyond),
                100.0 * worst_of(&inside),
                1e3 * offset_max
            ),
            reference: format!(
                "the stick cone's half-angle, atan {}",
                firmware::contact::STICK_SLOPE
            ),
            verdict: if beyond.is_empty() {
                Verdict::Bounded
            } else {
                Verdict::Weakness
            },
            value: Some(s.angle_max_rad),
            reference_value: Some(cone),
        },
        HardCase {
            case: "reach on the organ's surface: R cut on the collision surface".into(),
            measurement: format!(
                "{refused} of {} FEM surface points within R's reach test (tip radius and \
                 margin of the workspace) refused by R, up to {:.2} mm short (R keeps a \
                 collision triangle only when its three vertices pass the test); {} of the {} \
                 press sites (where the device can make the whole press)",
                reach.len(),
                1e3 * short_max,
                s.refused,
                s.sites
            ),
            reference: "every point within the reach test held".into(),
            verdict: if refused == 0 {
                Verdict::MatchesReference
            } else {
                Verdict::Weakness
            },
            value: Some(short_max),
            reference_value: Some(0.0),
        },
    ])
}
