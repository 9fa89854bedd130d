//! The reachable region R: the surface nodes the tool tip can touch.
//!
//! The tip moves on `p = fulcrum + insertion * d(pitch, yaw)` with
//! `d = Rot(yaw_axis, yaw) Rot(pitch_axis, pitch) shaft_axis` (the bank's forward kinematics),
//! pitch, yaw and insertion within their ranges: a spherical-shell sector around the fulcrum.
//! A surface node `x` is in R when it is within `tip_radius + margin` of that sector and none of
//! its components is fixed (a fixed component makes `C_kk` singular: no force can be rendered
//! there, and the bank requires SPD blocks).
//!
//! Approximation (a slight over-estimate, never an under-estimate of the exact distance test):
//! with `rho = |x - fulcrum|` and `(pitch, yaw)` the joint angles that point the shaft at `x`
//! (inverse kinematics, exact for `|pitch| < pi/2`), `x` is kept when
//!
//! - `rho` lies in `[ins_min - m, ins_max + m]` (radial test), and
//! - the angular excess `sqrt(dp^2 + (cos(pitch) dy)^2) <= asin(min(1, m / rho))`, where `dp`,
//!   `dy` are how far pitch and yaw fall outside their ranges (0 inside); `cos(pitch)` turns a
//!   yaw step into an arc on the unit sphere.
//!
//! Radial and angular excesses are tested separately, so a node near a corner of the sector
//! (both slightly outside) may be kept although its true distance is up to `sqrt(2) m`.
//!
//! Not modelled: whether the shaft can get to the node without passing through the organ (or
//! other tissue). Nodes on the far side of the organ, seen from the trocar, are therefore kept
//! when they lie in the sector; the scene's insertion range is what keeps R to the near surface.

use crate::kinematics::Workspace;
use crate::organ::Organ;
use anyhow::{Result, bail};
use fem::vec3::{dot, sub};
use std::collections::{BTreeSet, HashMap};

impl Workspace {
    /// Whether point `x` lies within (approximately, see the module notes) `margin` of the
    /// tip's workspace.
    pub fn reaches(&self, x: [f64; 3], margin: f64) -> bool {
        let v = sub(x, self.fulcrum);
        let rho = dot(v, v).sqrt();
        if rho < self.insertion[0] - margin || rho > self.insertion[1] + margin {
            return false;
        }
        if rho <= margin {
            return true;
        }
        let (pitch, yaw) = self.angles(v);
        let outside = |t: f64, r: [f64; 2]| (r[0] - t).max(t - r[1]).max(0.0);
        let dp = outside(pitch, self.pitch);
        let dy = outside(yaw, self.yaw) * pitch.cos();
        (dp * dp + dy * dy).sqrt() <= (margin / rho).min(1.0).asin()
    }
}

/// The reachable region: the `candidates` (surface nodes) within `tip_radius + margin` of the
/// workspace whose components are all free (`fixed(node)` is true when any component is
/// fixed). Sorted as `candidates` is.
pub fn reachable(
    workspace: &Workspace,
    positions: &[[f64; 3]],
    candidates: &[usize],
    fixed: impl Fn(usize) -> bool,
    tip_radius: f64,
    margin: f64,
) -> Vec<usize> {
    candidates
        .iter()
        .copied()
        .filter(|&k| !fixed(k) && workspace.reaches(positions[k], tip_radius + margin))
        .collect()
}

/// The reach stage of the pipeline: R, the free surface nodes of an organ the scene's tool can
/// touch, with the boundary triangles among them. The bank models only these.
pub struct Region {
    /// R: mesh node ids, ascending.
    pub nodes: Vec<usize>,
    /// R's positions, m.
    pub positions: Vec<[f64; 3]>,
    /// Boundary triangles with all three vertices in R, as indices into `nodes`.
    pub triangles: Vec<[u32; 3]>,
}

impl Region {
    /// [`reachable`] on the organ's surface with the scene's device, tip radius and
    /// `bank.reach_margin_m`; refuses an empty R and one larger than a bank holds.
    pub fn of(organ: &Organ) -> Result<Region> {
        let scene = &organ.scene;
        let path = scene.path.display();
        let nodes = reachable(
            &Workspace::from_device(&scene.device),
            &organ.mesh.nodes,
            &organ.surface.nodes,
            |k| (0..3).any(|c| organ.fixed.is_fixed(k, c)),
            scene.tip_radius_m,
            scene.bank.reach_margin_m,
        );
        if nodes.is_empty() {
            bail!(
                "{path}: the tool reaches no free surface node (check device.fulcrum_m, the \
                 ranges and bank.reach_margin_m)"
            );
        }
        if nodes.len() > bank_format::MAX_NODES {
            bail!(
                "{path}: the reachable region has {} nodes; a bank holds at most {} (u16 \
                 indices): narrow the device's ranges",
                nodes.len(),
                bank_format::MAX_NODES
            );
        }
        let local: HashMap<usize, u32> = nodes
            .iter()
            .enumerate()
            .map(|(i, &k)| (k, i as u32))
            .collect();
        let triangles = organ
            .surface
            .triangles
            .iter()
            .filter_map(|t| Some([*local.get(&t[0])?, *local.get(&t[1])?, *local.get(&t[2])?]))
            .collect();
        let positions = nodes.iter().map(|&k| organ.mesh.nodes[k]).collect();
        Ok(Region {
            nodes,
            positions,
            triangles,
        })
    }

    /// Nodes in R.
    pub fn len(&self) -> usize {
        self.nodes.len()
    }

    /// Whether R is empty (never, for a region from [`Region::of`]).
    pub fn is_empty(&self) -> bool {
        self.nodes.is_empty()
    }

    /// R's triangle edges `(a, b)`, `a < b`, as indices into [`Region::nodes`].
    pub fn edges(&self) -> BTreeSet<(usize, usize)> {
        let mut e = BTreeSet::new();
        for t in &self.triangles {
            for i in 0..3 {
                let (a, b) = (t[i] as usize, t[(i + 1) % 3] as usize);
                e.insert((a.min(b), a.max(b)));
            }
        }
        e
    }

    /// Distance between R's nodes `a` and `b` at rest, m.
    pub fn dist(&self, a: usize, b: usize) -> f64 {
        let (p, q) = (self.positions[a], self.positions[b]);
        (0..3).map(|i| (p[i] - q[i]).powi(2)).sum::<f64>().sqrt()
    }

    /// Mean length of R's triangle edges, m (0 without triangles).
    pub fn mean_edge(&self) -> f64 {
        let e = self.edges();
        if e.is_empty() {
            return 0.0;
        }
        e.iter().map(|&(a, b)| self.dist(a, b)).sum::<f64>() / e.len() as f64
    }

    /// Length of R's longest triangle edge, m (0 without triangles).
    pub fn longest_edge(&self) -> f64 {
        self.edges()
            .iter()
            .map(|&(a, b)| self.dist(a, b))
            .fold(0.0, f64::max)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flat_box_under_a_vertical_trocar() {
        // Top face of a box, z = 0, nodes every 10 mm from -80 to 80 mm.
        let mut positions = Vec::new();
        for j in -8..=8 {
            for i in -8..=8 {
                positions.push([0.01 * f64::from(i), 0.01 * f64::from(j), 0.0]);
            }
        }
        let at = |x: i32, y: i32| ((y + 8) * 17 + (x + 8)) as usize;
        let all: Vec<usize> = (0..positions.len()).collect();
        let w = Workspace::straight_down();
        // Margin 1 um (0 would put the nodes exactly on the bounds at the mercy of rounding).
        // By hand: yaw = atan2(-x, 0.1), so |x| <= 50 mm; pitch = asin(y / |p - f|) <=
        // asin(1 / sqrt 5) needs 4 y^2 <= x^2 + 0.01: every |y| <= 50 mm passes, y = 60 mm
        // needs |x| >= 66 mm (excluded by yaw). |p - f| <= 0.1225 m is inside the insertion
        // range. So the 11 x 11 nodes with |x|, |y| <= 50 mm.
        let r0 = reachable(&w, &positions, &all, |_| false, 0.0, 1e-6);
        assert_eq!(r0.len(), 121, "{r0:?}");
        assert!(r0.contains(&at(5, 5)) && r0.contains(&at(-5, 5)));
        assert!(!r0.contains(&at(6, 0)) && !r0.contains(&at(0, 6)) && !r0.contains(&at(6, 6)));
        // Tip 1 mm + margin 2 mm: the nodes at 60 mm on the axes are 0.0768 rad * 0.1166 m =
        // 9 mm outside the sector, still out.
        let r3 = reachable(&w, &positions, &all, |_| false, 0.001, 0.002);
        assert_eq!(r3, r0);
        // A node 1 mm outside the yaw bound comes in with the margin: put one at x = 51 mm.
        let mut more = positions.clone();
        more.push([0.051, 0.0, 0.0]);
        let ids: Vec<usize> = (0..more.len()).collect();
        assert!(reachable(&w, &more, &ids, |_| false, 0.001, 0.002).contains(&(more.len() - 1)));
        assert!(!reachable(&w, &more, &ids, |_| false, 0.0, 1e-6).contains(&(more.len() - 1)));
        // Fixed nodes are never reachable.
        let r = reachable(&w, &positions, &all, |k| k == at(0, 0), 0.001, 0.002);
        assert!(!r.contains(&at(0, 0)) && r.len() + 1 == r3.len());
        // Insertion too short: the plane 0.1 m below is out of reach (radial test).
        let short = Workspace {
            insertion: [0.02, 0.09],
            ..w
        };
        assert!(reachable(&short, &positions, &all, |_| false, 0.001, 0.002).is_empty());
        // Within 3 mm of a shell of radius 0.0971 m: only |p - f| <= 0.1001 m, the centre.
        let just = Workspace {
            insertion: [0.02, 0.0971],
            ..w
        };
        assert_eq!(
            reachable(&just, &positions, &all, |_| false, 0.001, 0.002),
            vec![at(0, 0)]
        );
    }
}
