//! Tool contact on the host, in f64: where a tool press lands on the organ's surface, the
//! weighted contact patch of a tip of finite radius, and the force of the energy-minimal solve.
//!
//! This is the f64 reference for the firmware's `patch` and `solve::WeightedSolve` (the model is
//! documented there), computed on the whole mesh surface with untruncated compliance and no cap
//! on the number of contact nodes, and the tool of the refinement series
//! (`host bench refinement`): a point force has unbounded displacement (Boussinesq), so a
//! point contact's force for a given press falls as the mesh is refined, while the finite tip's
//! converges.

use fem::compliance::{Block3, Compliance, ComplianceError};
use fem::mesh::{Surface, TetMesh};
use fem::vec3::{add, cross, dist2, dot, norm, scale, sub};

/// A mesh's boundary surface with what contact needs: positions, triangles, lumped areas.
#[derive(Debug, Clone)]
pub struct ContactSurface {
    positions: Vec<[f64; 3]>,
    triangles: Vec<[usize; 3]>,
    /// A third of the area of each node's boundary triangles (0 off the surface), m^2.
    lumped_area: Vec<f64>,
}

/// Where a ray first enters the surface.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SurfaceHit {
    /// Index into the surface's triangles.
    pub triangle: usize,
    /// The triangle's nodes (mesh ids).
    pub nodes: [usize; 3],
    /// Barycentric coordinates of `point`.
    pub bary: [f64; 3],
    /// The entry point, m.
    pub point: [f64; 3],
}

impl ContactSurface {
    /// The contact surface of `mesh` with boundary `surface`.
    pub fn new(mesh: &TetMesh, surface: &Surface) -> ContactSurface {
        let mut lumped_area = vec![0.0; mesh.nodes.len()];
        for t in &surface.triangles {
            let v = t.map(|i| mesh.nodes[i]);
            let a = norm(cross(sub(v[1], v[0]), sub(v[2], v[0]))) / 2.0;
            for &i in t {
                lumped_area[i] += a / 3.0;
            }
        }
        ContactSurface {
            positions: mesh.nodes.clone(),
            triangles: surface.triangles.clone(),
            lumped_area,
        }
    }

    /// Mean boundary edge length, m (the mesh size at the surface).
    pub fn mean_edge(&self) -> f64 {
        let total: f64 = self
            .triangles
            .iter()
            .map(|t| {
                let v = t.map(|i| self.positions[i]);
                norm(sub(v[1], v[0])) + norm(sub(v[2], v[1])) + norm(sub(v[0], v[2]))
            })
            .sum();
        total / (3 * self.triangles.len().max(1)) as f64
    }

    /// The first point where the ray `origin + s dir` (`s >= 0`) enters the surface (crossing a
    /// triangle against its outward normal).
    pub fn ray_entry(&self, origin: [f64; 3], dir: [f64; 3]) -> Option<SurfaceHit> {
        let mut best: Option<(f64, SurfaceHit)> = None;
        for (ti, t) in self.triangles.iter().enumerate() {
            let v = t.map(|i| self.positions[i]);
            let (e1, e2) = (sub(v[1], v[0]), sub(v[2], v[0]));
            let n = cross(e1, e2);
            let den = dot(dir, n);
            if den >= 0.0 {
                continue; // leaving or parallel
            }
            let s = dot(sub(v[0], origin), n) / den;
            if s < 0.0 || best.is_some_and(|(b, _)| s >= b) {
                continue;
            }
            let p = add(origin, scale(dir, s));
            let Some(bary) = barycentric(v, p) else {
                continue;
            };
            if bary.iter().all(|&b| b >= -1e-12) {
                let bary = bary.map(|b| b.max(0.0));
                let sum: f64 = bary.iter().sum();
                best = Some((
                    s,
                    SurfaceHit {
                        triangle: ti,
                        nodes: *t,
                        bary: bary.map(|b| b / sum),
                        point: p,
                    },
                ));
            }
        }
        best.map(|(_, h)| h)
    }

    /// The contact patch of a tip of radius `radius` (m) at `hit`, with no cap on its size:
    /// `(node, weight)` with weights summing to 1, heaviest first. Same model as the firmware's
    /// `patch::tool_patch`: the parabolic pressure's consistent load by the 12-point disk
    /// quadrature `firmware::patch::QUADRATURE` in the contact triangle's plane, each point
    /// moved to the closest surface point (here by a search over the triangles near the
    /// anchor). Nodes for which `keep` is false (fixed ones) are left out.
    pub fn tool_patch(
        &self,
        hit: &SurfaceHit,
        radius: f64,
        keep: impl Fn(usize) -> bool,
    ) -> Vec<(usize, f64)> {
        let mut loads: Vec<(usize, f64)> = Vec::new();
        let mut load = |nodes: [usize; 3], bary: [f64; 3], w: f64| {
            for (&k, &b) in nodes.iter().zip(&bary) {
                if b > 0.0 && keep(k) {
                    match loads.iter_mut().find(|l| l.0 == k) {
                        Some(l) => l.1 += w * b,
                        None => loads.push((k, w * b)),
                    }
                }
            }
        };
        let v = hit.nodes.map(|i| self.positions[i]);
        let n = unit(cross(sub(v[1], v[0]), sub(v[2], v[0])));
        if radius > 0.0 {
            // Same orientation rule as the firmware: e1 from the x axis (y near x-normals).
            let axis = if n[0].abs() < 0.9 {
                [1.0, 0.0, 0.0]
            } else {
                [0.0, 1.0, 0.0]
            };
            let e1 = unit(sub(axis, scale(n, dot(axis, n))));
            let e2 = cross(n, e1);
            let reach = radius + self.max_edge_near(hit.point, 2.0 * radius);
            let near: Vec<usize> = (0..self.triangles.len())
                .filter(|&t| {
                    self.triangles[t]
                        .iter()
                        .any(|&i| dist2(self.positions[i], hit.point) <= reach * reach)
                })
                .collect();
            for &(s, w, angle) in &firmware::patch::QUADRATURE {
                let (s, w, angle) = (f64::from(s), f64::from(w), f64::from(angle));
                let q = add(
                    hit.point,
                    add(
                        scale(e1, radius * s * angle.cos()),
                        scale(e2, radius * s * angle.sin()),
                    ),
                );
                let best = near
                    .iter()
                    .map(|&t| {
                        let tri = self.triangles[t];
                        let (p, k) = closest_on_triangle(q, tri.map(|i| self.positions[i]));
                        (dist2(p, q), tri, k)
                    })
                    .min_by(|a, b| a.0.total_cmp(&b.0));
                match best {
                    Some((_, tri, k)) => load(tri, k, w),
                    None => load(hit.nodes, hit.bary, w),
                }
            }
        } else {
            load(hit.nodes, hit.bary, 1.0);
        }
        normalise(&mut loads);
        // Resolved tips: blend in the nodal quadrature (see `firmware::patch`).
        let r2 = radius * radius;
        let mut nodal: Vec<(usize, f64)> = Vec::new();
        let mut n_eff = 0.0;
        if r2 > 0.0 {
            for (k, &a) in self.lumped_area.iter().enumerate() {
                let rho2 = dist2(self.positions[k], hit.point);
                if a > 0.0 && rho2 < r2 {
                    let p = 1.0 - rho2 / r2;
                    n_eff += p;
                    if keep(k) {
                        nodal.push((k, a * p));
                    }
                }
            }
        }
        let theta = firmware::patch::resolution(n_eff as f32) as f64;
        if theta > 0.0 && normalise(&mut nodal) {
            for l in &mut loads {
                l.1 *= 1.0 - theta;
            }
            for (k, w) in nodal {
                match loads.iter_mut().find(|l| l.0 == k) {
                    Some(l) => l.1 += theta * w,
                    None => loads.push((k, theta * w)),
                }
            }
        }
        loads.retain(|l| l.1 > 0.0);
        loads.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
        loads
    }

    /// The longest edge of the triangles with a vertex within `within` of `p` (0 if none).
    fn max_edge_near(&self, p: [f64; 3], within: f64) -> f64 {
        self.triangles
            .iter()
            .filter(|t| {
                t.iter()
                    .any(|&i| dist2(self.positions[i], p) <= within * within)
            })
            .map(|t| {
                let v = t.map(|i| self.positions[i]);
                norm(sub(v[1], v[0]))
                    .max(norm(sub(v[2], v[1])))
                    .max(norm(sub(v[0], v[2])))
            })
            .fold(0.0, f64::max)
    }
}

/// The firmware's cap on a patch (`firmware::patch`, with every pair coupled, as on the
/// untruncated compliance): the `max_nodes` heaviest of `patch` (heaviest first, as
/// [`ContactSurface::tool_patch`] returns it), renormalised to sum 1, and the share of the load
/// dropped (`Patch::dropped`, telemetry's `dropped_load`).
pub fn capped_patch(patch: &[(usize, f64)], max_nodes: usize) -> (Vec<(usize, f64)>, f64) {
    let mut kept: Vec<(usize, f64)> = patch.iter().take(max_nodes).copied().collect();
    let total: f64 = patch.iter().map(|p| p.1).sum();
    let sum: f64 = kept.iter().map(|p| p.1).sum();
    if !(sum > 0.0 && total > 0.0) {
        return (Vec::new(), if total > 0.0 { 1.0 } else { 0.0 });
    }
    for p in &mut kept {
        p.1 /= sum;
    }
    (kept, (1.0 - sum / total).max(0.0))
}

/// Scales the weights to sum 1 after dropping non-positive ones; `false` if none is left.
fn normalise(loads: &mut Vec<(usize, f64)>) -> bool {
    loads.retain(|l| l.1 > 0.0);
    let total: f64 = loads.iter().map(|l| l.1).sum();
    for l in loads.iter_mut() {
        l.1 /= total;
    }
    total > 0.0
}

/// The energy-minimal weighted solve (firmware `solve::WeightedSolve`) in f64: `M = sum_ab w_a
/// w_b C_ab` from the blocks `c[a][b]`, `f_tool = M^-1 d` (N, on the tissue) for the press `d`
/// (m) of the weighted mean displacement.
pub fn weighted_tool_force(
    c: &[Vec<Block3>],
    weights: &[f64],
    d: [f64; 3],
) -> Result<[f64; 3], ComplianceError> {
    let mut m = [[0.0; 3]; 3];
    for (a, &wa) in weights.iter().enumerate() {
        for (b, &wb) in weights.iter().enumerate() {
            for (i, row) in m.iter_mut().enumerate() {
                for (j, e) in row.iter_mut().enumerate() {
                    *e += wa * wb * c[a][b][i][j];
                }
            }
        }
    }
    let solved = fem::compliance::contact_forces(&[vec![m]], &[d])?;
    Ok(solved.forces[0])
}

/// The tool force (N, on the tissue) for pressing the patch `patch` by `d` (m), with the blocks
/// computed from `compliance`.
pub fn patch_force(
    compliance: &Compliance,
    patch: &[(usize, f64)],
    d: [f64; 3],
) -> Result<[f64; 3], ComplianceError> {
    let nodes: Vec<usize> = patch.iter().map(|p| p.0).collect();
    let weights: Vec<f64> = patch.iter().map(|p| p.1).collect();
    let c = compliance.blocks(&nodes, None)?;
    weighted_tool_force(&c, &weights, d)
}

/// The point of triangle `v` closest to `q` and its barycentric coordinates: the projection
/// onto the plane when it lies inside, else the closest point of the nearest edge.
fn closest_on_triangle(q: [f64; 3], v: [[f64; 3]; 3]) -> ([f64; 3], [f64; 3]) {
    let n = cross(sub(v[1], v[0]), sub(v[2], v[0]));
    let nn = dot(n, n);
    if nn > 0.0 {
        let p = sub(q, scale(n, dot(sub(q, v[0]), n) / nn));
        if let Some(k) = barycentric(v, p).filter(|k| k.iter().all(|&b| b >= 0.0)) {
            return (p, k);
        }
    }
    let mut best = (f64::INFINITY, v[0], [1.0, 0.0, 0.0]);
    for (a, b) in [(0, 1), (1, 2), (2, 0)] {
        let e = sub(v[b], v[a]);
        let ee = dot(e, e);
        let t = if ee > 0.0 {
            (dot(sub(q, v[a]), e) / ee).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let p = add(v[a], scale(e, t));
        let d = dist2(p, q);
        if d < best.0 {
            let mut k = [0.0; 3];
            k[a] = 1.0 - t;
            k[b] = t;
            best = (d, p, k);
        }
    }
    (best.1, best.2)
}

/// Barycentric coordinates of `p` (assumed in the triangle's plane) in triangle `v`.
fn barycentric(v: [[f64; 3]; 3], p: [f64; 3]) -> Option<[f64; 3]> {
    let (e1, e2, e) = (sub(v[1], v[0]), sub(v[2], v[0]), sub(p, v[0]));
    let (d11, d12, d22) = (dot(e1, e1), dot(e1, e2), dot(e2, e2));
    let (d1, d2) = (dot(e, e1), dot(e, e2));
    let den = d11 * d22 - d12 * d12;
    if den <= 0.0 {
        return None;
    }
    let b1 = (d22 * d1 - d12 * d2) / den;
    let b2 = (d11 * d2 - d12 * d1) / den;
    Some([1.0 - b1 - b2, b1, b2])
}

fn unit(a: [f64; 3]) -> [f64; 3] {
    scale(a, 1.0 / norm(a))
}
