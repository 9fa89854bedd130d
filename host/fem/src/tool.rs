//! The load a rigid tool tip puts on the organ's surface, as weights on the FEM nodes.
//!
//! A spherical tip of radius `a` pressed on the surface at the point `c` is modelled by a
//! parabolic pressure
//!
//! ```text
//! p(x) = max(0, 1 - |x - c|^2 / a^2)        (x on the surface, 3-D distance)
//! ```
//!
//! scaled so that it carries the tool force `F`: the traction is `t(x) = F p(x) / P`,
//! `P = integral of p dA` (on a flat face through `c`, `P = pi a^2 / 2`, so the peak pressure
//! is `2 |F| / (pi a^2)`). Spread over the nodes by the surface shape functions `N_i`
//! (the consistent nodal load), node `i` receives `f_i = integral N_i t dA = w_i F` with
//!
//! ```text
//! w_i = (integral of N_i p dA) / P.
//! ```
//!
//! The shape functions are a partition of unity, so the weights sum to 1, and they reproduce
//! linear functions (P1, and P2 with straight sides and mid-edge nodes), so `sum w_i x_i` is the
//! pressure centroid, `c` itself on a flat face. Every node gets the same direction:
//! `f = B^T F` with `B = [w_1 I, ..., w_n I]`, and `B u` is the load-weighted mean
//! displacement that is work-conjugate to `F` (the patch compliance `B K_ff^-1 B^T` of
//! [`crate::compliance::Compliance::patch_compliances`]).
//!
//! Surfaces: the 3-node triangles of a P1 mesh ([`ToolSurface::linear`], `N_i = L_i`) or the
//! 6-node triangles of a [`QuadraticBody`] ([`ToolSurface::quadratic`], `N_i = L_i (2 L_i - 1)`
//! at the vertices, `4 L_i L_j` at the edge nodes; `L` the barycentric coordinates). The
//! consistent load of P2 is not positive: a uniform pressure gives the vertices 0 and each edge
//! node a third of the triangle's force, and the parabolic one gives some vertices small
//! negative weights. They are kept.
//!
//! Quadrature. Where `p > 0` the integrand `N_i p` is a polynomial of degree at most 4 on a
//! flat triangle, so the 7-point degree-5 rule (Dunavant / Radon) integrates it exactly. A
//! triangle entirely inside the ball `|x - c| <= a` is integrated in one go; one entirely
//! outside (exact point-triangle distance `>= a`) is skipped; one cut by the sphere is split
//! 1 -> 4 recursively until each piece is inside, outside, or has its longest edge below
//! `h = rho / 64`, where `rho = sqrt(a^2 - d^2)` is the radius of the disk the ball cuts from the
//! triangle's plane (`d` the plane's distance from `c`; `rho = a` when `c` is in the plane).
//! Such a leaf is clipped to the polygon spanned by its vertices inside the ball and the exact
//! crossings of the sphere on its edges; that polygon lies in the ball, so the rule is exact on
//! it (fan-triangulated). What is lost is the thin segment between each chord and its arc:
//! chord length `l <= h`, sagitta `s ~ l^2 / (8 rho)`, pressure there `<= 2 rho s / a^2`, so at
//! most `l^5 / (48 rho a^2)` per leaf and `pi h^4 / (24 a^2)` around the circle, against
//! `P = pi rho^4 / (2 a^2)` for that disk: a relative error of at most
//! `(h / rho)^4 / 12 = 5e-9`, always an underestimate (a leaf whose edge the circle crosses twice
//! misses a cap of the same order). The weights are ratios of such integrals, so their error is
//! of the same order relative to the largest weight. Measured on flat faces: `P` within
//! `2e-10` of `pi a^2 / 2`, `sum w_i x_i` within `5e-14` m of `c`. (A plane the ball barely
//! reaches has a tiny `rho`; the leaf size never goes below `a / (64 * 2^20)`.)
//!
//! A point tool (`a = 0`, or below [`ToolSurface::tolerance`]) gets the shape functions' values
//! at the surface point closest to `c`, the limit of the above as `a -> 0`; so does a ball that
//! only grazes the surface so that no leaf vertex falls inside it.
//!
//! Spatial index: a uniform grid over the surface's bounding box (cells of about two mean edge
//! lengths, at most four per triangle), each cell listing the triangles whose bounding box meets
//! it; closest-point queries search it in rings of cells until no unvisited cell can hold a
//! closer point, ball queries visit the cells the ball's bounding box meets.

use crate::elasticity::quadratic::QuadraticBody;
use crate::mesh::{Surface, TetMesh};
use crate::vec3::{add, cross, dist2, dot, norm, scale, sub};

/// Cut triangles are split until their longest edge is below the local disk radius over this.
const LEAF_DIVISOR: f64 = 64.0;

/// The leaf size never goes below `LEAF_FLOOR * a / LEAF_DIVISOR` (planes the ball barely
/// touches).
const LEAF_FLOOR: f64 = 1.0 / (1u64 << 20) as f64;

/// Relative tolerance of "on the surface": times the diagonal of the surface's bounding box.
const RELATIVE_TOLERANCE: f64 = 1e-9;

/// The 7-point degree-5 rule on a triangle (Dunavant 1985, Radon 1948): barycentric points
/// and weights summing to 1 (multiply by the area). `(6 +- sqrt 15) / 21`, `(155 +- sqrt 15) /
/// 1200`.
const RULE: [([f64; 3], f64); 7] = {
    const W0: f64 = 0.225;
    const A1: f64 = 0.059_715_871_789_769_82;
    const B1: f64 = 0.470_142_064_105_115_1;
    const W1: f64 = 0.132_394_152_788_506_2;
    const A2: f64 = 0.797_426_985_353_087_3;
    const B2: f64 = 0.101_286_507_323_456_34;
    const W2: f64 = 0.125_939_180_544_827_15;
    const T: f64 = 1.0 / 3.0;
    [
        ([T, T, T], W0),
        ([A1, B1, B1], W1),
        ([B1, A1, B1], W1),
        ([B1, B1, A1], W1),
        ([A2, B2, B2], W2),
        ([B2, A2, B2], W2),
        ([B2, B2, A2], W2),
    ]
};

/// Errors of building a [`ToolSurface`] and of tool loads.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ToolError {
    /// The tool radius is negative, infinite or NaN.
    #[error(
        "tool radius {radius} m at centre {} is negative or not finite",
        point(*.centre)
    )]
    BadRadius {
        /// Tool centre, m.
        centre: [f64; 3],
        /// Requested radius, m.
        radius: f64,
    },
    /// The tool centre has a non-finite coordinate.
    #[error("tool centre {} (radius {radius} m) is not finite", point(*.centre))]
    BadCentre {
        /// Tool centre, m.
        centre: [f64; 3],
        /// Requested radius, m.
        radius: f64,
    },
    /// The ball of the tool meets no surface.
    #[error(
        "no surface within {radius} m of the tool centre {}: the closest surface point is \
         {distance} m away",
        point(*.centre)
    )]
    NoSurface {
        /// Tool centre, m.
        centre: [f64; 3],
        /// Tool radius, m.
        radius: f64,
        /// Distance from the centre to the closest surface point, m.
        distance: f64,
    },
    /// The surface has no triangle.
    #[error("the surface has no triangles")]
    EmptySurface,
    /// A surface triangle refers to a node the mesh does not have.
    #[error("surface triangle {triangle} refers to node {node}, but the mesh has {nodes} nodes")]
    NoSuchNode {
        /// Triangle id.
        triangle: usize,
        /// Offending node id.
        node: usize,
        /// Number of mesh nodes.
        nodes: usize,
    },
    /// A surface triangle has zero area or non-finite coordinates.
    #[error("surface triangle {triangle} has zero area or non-finite coordinates")]
    DegenerateTriangle {
        /// Triangle id.
        triangle: usize,
    },
    /// The quadratic body was not built on this mesh.
    #[error("the quadratic body does not match the mesh: {what} (was it built on another mesh?)")]
    BodyMismatch {
        /// What does not match.
        what: String,
    },
}

/// `(x, y, z) m` for messages.
fn point(p: [f64; 3]) -> String {
    format!("({}, {}, {}) m", p[0], p[1], p[2])
}

/// A closest-point candidate: squared distance, triangle, point, barycentric coordinates.
type Nearest = (f64, usize, [f64; 3], [f64; 3]);

/// The point of a [`ToolSurface`] closest to a query point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SurfacePoint {
    /// Index of the triangle in the [`Surface`]'s list.
    pub triangle: usize,
    /// The closest point, m.
    pub point: [f64; 3],
    /// Its barycentric coordinates in the triangle (vertex order of the [`Surface`]).
    pub bary: [f64; 3],
    /// Outward unit normal of that triangle.
    pub normal: [f64; 3],
    /// Distance from the query point, m.
    pub distance: f64,
}

/// A boundary surface prepared for tool loads: its triangles' geometry and FEM nodes, and a
/// spatial index.
#[derive(Clone)]
pub struct ToolSurface {
    /// Corner positions of each triangle, m.
    corners: Vec<[[f64; 3]; 3]>,
    /// FEM nodes of each triangle: its 3 vertices, then (P2 only) the edge nodes of its edges
    /// 0-1, 1-2, 2-0.
    nodes: Vec<[usize; 6]>,
    /// Number of nodes per triangle, 3 (P1) or 6 (P2).
    per_triangle: usize,
    /// Outward unit normals.
    normals: Vec<[f64; 3]>,
    /// Areas, m^2.
    areas: Vec<f64>,
    grid: Grid,
    tolerance: f64,
}

impl std::fmt::Debug for ToolSurface {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ToolSurface")
            .field("triangles", &self.corners.len())
            .field("nodes_per_triangle", &self.per_triangle)
            .field("grid", &self.grid.dims)
            .finish()
    }
}

impl ToolSurface {
    /// The 3-node triangles of `surface` (the boundary of `mesh`); node ids are the mesh's.
    /// Errors: an empty surface, a node id out of range, a triangle of zero area or with
    /// non-finite coordinates.
    pub fn linear(mesh: &TetMesh, surface: &Surface) -> Result<Self, ToolError> {
        let nodes = surface
            .triangles
            .iter()
            .map(|&[a, b, c]| [a, b, c, 0, 0, 0])
            .collect();
        Self::build(mesh, &surface.triangles, nodes, 3)
    }

    /// The 6-node triangles of `surface` (the boundary of `mesh`) in the numbering of `body`, a
    /// [`QuadraticBody`] built on `mesh`: the 3 vertices and the 3 edge nodes. The sides are
    /// straight, so the geometry is the linear triangle's. Errors: those of
    /// [`ToolSurface::linear`], and a body not built on `mesh`.
    pub fn quadratic(
        mesh: &TetMesh,
        surface: &Surface,
        body: &QuadraticBody,
    ) -> Result<Self, ToolError> {
        if body.vertices() != mesh.nodes.len() {
            return Err(ToolError::BodyMismatch {
                what: format!(
                    "the body has {} vertices, the mesh {} nodes",
                    body.vertices(),
                    mesh.nodes.len()
                ),
            });
        }
        let mut nodes = Vec::with_capacity(surface.triangles.len());
        for &[a, b, c] in &surface.triangles {
            let mut t = [a, b, c, 0, 0, 0];
            for (k, (p, q)) in [(a, b), (b, c), (c, a)].into_iter().enumerate() {
                t[3 + k] = body
                    .edge_node(p, q)
                    .ok_or_else(|| ToolError::BodyMismatch {
                        what: format!("the body has no node on the edge {p}-{q}"),
                    })?;
            }
            nodes.push(t);
        }
        Self::build(mesh, &surface.triangles, nodes, 6)
    }

    fn build(
        mesh: &TetMesh,
        triangles: &[[usize; 3]],
        nodes: Vec<[usize; 6]>,
        per_triangle: usize,
    ) -> Result<Self, ToolError> {
        if triangles.is_empty() {
            return Err(ToolError::EmptySurface);
        }
        let n = mesh.nodes.len();
        let mut corners = Vec::with_capacity(triangles.len());
        let mut normals = Vec::with_capacity(triangles.len());
        let mut areas = Vec::with_capacity(triangles.len());
        for (t, tri) in triangles.iter().enumerate() {
            if let Some(&node) = tri.iter().find(|&&v| v >= n) {
                return Err(ToolError::NoSuchNode {
                    triangle: t,
                    node,
                    nodes: n,
                });
            }
            let p = tri.map(|v| mesh.nodes[v]);
            let m = cross(sub(p[1], p[0]), sub(p[2], p[0]));
            let twice = norm(m);
            if !(twice > 0.0 && twice.is_finite() && p.iter().flatten().all(|x| x.is_finite())) {
                return Err(ToolError::DegenerateTriangle { triangle: t });
            }
            corners.push(p);
            normals.push(scale(m, 1.0 / twice));
            areas.push(0.5 * twice);
        }
        let grid = Grid::new(&corners);
        let diagonal = norm(sub(grid.hi, grid.lo));
        Ok(Self {
            corners,
            nodes,
            per_triangle,
            normals,
            areas,
            grid,
            tolerance: RELATIVE_TOLERANCE * diagonal,
        })
    }

    /// Number of triangles.
    pub fn len(&self) -> usize {
        self.corners.len()
    }

    /// Always false: a tool surface has at least one triangle.
    pub fn is_empty(&self) -> bool {
        self.corners.is_empty()
    }

    /// Distance below which a point counts as on the surface, and a radius as a point tool:
    /// `1e-9` times the diagonal of the surface's bounding box, m.
    pub fn tolerance(&self) -> f64 {
        self.tolerance
    }

    /// The point of the surface closest to `q` (exact point-triangle distances; the grid is
    /// searched outward from `q` until no unvisited cell can hold a closer point; ties go to the
    /// lowest triangle index found). A non-finite `q` gives a NaN distance.
    pub fn closest_point(&self, q: [f64; 3]) -> SurfacePoint {
        let g = &self.grid;
        let home: [usize; 3] = std::array::from_fn(|a| g.index(q[a], a));
        let mut best: Option<Nearest> = None;
        // The triangles of a cell, unless the cell is farther than the best point so far.
        let visit = |cell: [usize; 3], best: &mut Option<Nearest>| {
            if let Some((b, ..)) = *best
                && g.box_distance2(cell, q) > b
            {
                return;
            }
            for &t in g.cell(cell) {
                let (x, bary) = closest_on_triangle(q, self.corners[t]);
                let d2 = dist2(q, x);
                let better = match *best {
                    None => true,
                    Some((b, bt, _, _)) => d2 < b || (d2 == b && t < bt),
                };
                if better {
                    *best = Some((d2, t, x, bary));
                }
            }
        };
        for ring in 0usize.. {
            let range: [(usize, usize); 3] = std::array::from_fn(|a| {
                (
                    home[a].saturating_sub(ring),
                    (home[a] + ring).min(g.dims[a] - 1),
                )
            });
            // The cells of the ring: Chebyshev distance exactly `ring` from `home`.
            let on_ring = |a: usize, i: usize| i.abs_diff(home[a]) == ring;
            for i in range[0].0..=range[0].1 {
                for j in range[1].0..=range[1].1 {
                    if on_ring(0, i) || on_ring(1, j) {
                        for k in range[2].0..=range[2].1 {
                            visit([i, j, k], &mut best);
                        }
                    } else {
                        let (lo, hi) = (home[2].checked_sub(ring), home[2] + ring);
                        if let Some(k) = lo.filter(|&k| k >= range[2].0) {
                            visit([i, j, k], &mut best);
                        }
                        if ring > 0 && hi <= range[2].1 {
                            visit([i, j, hi], &mut best);
                        }
                    }
                }
            }
            // Distance from q to the cells beyond this ring; none left: done.
            let mut gap = f64::INFINITY;
            let mut covered = true;
            for a in 0..3 {
                if range[a].0 > 0 {
                    covered = false;
                    gap = gap.min(q[a] - (g.lo[a] + range[a].0 as f64 * g.cell));
                }
                if range[a].1 + 1 < g.dims[a] {
                    covered = false;
                    gap = gap.min(g.lo[a] + (range[a].1 + 1) as f64 * g.cell - q[a]);
                }
            }
            if covered {
                break;
            }
            if let Some((d2, ..)) = best
                && gap >= 0.0
                && d2 <= gap * gap
            {
                break;
            }
        }
        // The grid has at least one cell holding a triangle, and the rings cover all cells.
        let (d2, triangle, point, bary) =
            best.unwrap_or((f64::NAN, 0, [f64::NAN; 3], [f64::NAN; 3]));
        SurfacePoint {
            triangle,
            point,
            bary,
            normal: self.normals[triangle],
            distance: d2.sqrt(),
        }
    }

    /// The nodal weights of a tool of radius `radius` (m) centred at `centre` (see the module
    /// documentation): `(node, w)` sorted by node (the body's numbering), exact zeros dropped,
    /// summing to 1. A radius at most [`ToolSurface::tolerance`] is a point tool: the shape
    /// functions at the closest surface point.
    ///
    /// Errors: a negative or non-finite radius, a non-finite centre, no surface within the radius
    /// (the closest point farther than `radius + tolerance`).
    pub fn tool_weights(
        &self,
        centre: [f64; 3],
        radius: f64,
    ) -> Result<Vec<(usize, f64)>, ToolError> {
        let (mut entries, total) = self.load(centre, radius)?;
        if !(total > 0.0 && total.is_finite()) {
            // A point tool, or a ball that only grazes the surface: the limit a -> 0.
            let at = self.closest_point(centre);
            let n = self.shape(at.bary);
            let nodes = self.nodes[at.triangle];
            entries = (0..self.per_triangle).map(|k| (nodes[k], n[k])).collect();
            entries = merge(entries);
        }
        let sum: f64 = entries.iter().map(|e| e.1).sum();
        entries.retain(|e| e.1 != 0.0);
        for e in &mut entries {
            e.1 /= sum;
        }
        Ok(entries)
    }

    /// The integral of the (unscaled) tool pressure `p` over the surface, m^2: `pi a^2 / 2` on a
    /// flat face through the centre, 0 for a point tool. A tool force `F` gives the peak
    /// pressure `|F| / P`. Errors: those of [`ToolSurface::tool_weights`].
    pub fn pressure_integral(&self, centre: [f64; 3], radius: f64) -> Result<f64, ToolError> {
        Ok(self.load(centre, radius)?.1)
    }

    /// The unnormalised loads `integral N_i p dA` (merged by node) and their sum; empty and 0 for
    /// a point tool.
    fn load(&self, centre: [f64; 3], radius: f64) -> Result<(Vec<(usize, f64)>, f64), ToolError> {
        if !(radius.is_finite() && radius >= 0.0) {
            return Err(ToolError::BadRadius { centre, radius });
        }
        if !centre.iter().all(|x| x.is_finite()) {
            return Err(ToolError::BadCentre { centre, radius });
        }
        let distance = self.closest_point(centre).distance;
        if distance > radius + self.tolerance {
            return Err(ToolError::NoSurface {
                centre,
                radius,
                distance,
            });
        }
        if radius <= self.tolerance {
            return Ok((Vec::new(), 0.0));
        }
        let ball = Ball::new(centre, radius);
        let mut candidates = self
            .grid
            .in_box(centre.map(|x| x - radius), centre.map(|x| x + radius));
        candidates.sort_unstable();
        candidates.dedup();
        let mut entries = Vec::new();
        let mut total = 0.0;
        for t in candidates {
            let mut acc = [0.0; 6];
            self.integrate(t, &ball, &mut acc);
            if acc[..self.per_triangle].iter().any(|&v| v != 0.0) {
                let nodes = self.nodes[t];
                entries.extend((0..self.per_triangle).map(|k| (nodes[k], acc[k])));
                total += acc[..self.per_triangle].iter().sum::<f64>();
            }
        }
        Ok((merge(entries), total))
    }

    /// Shape functions of a triangle at barycentric `l`: `L_i` (P1) or `L_i (2 L_i - 1)` and
    /// `4 L_i L_j` for the edges 0-1, 1-2, 2-0 (P2).
    fn shape(&self, l: [f64; 3]) -> [f64; 6] {
        if self.per_triangle == 3 {
            [l[0], l[1], l[2], 0.0, 0.0, 0.0]
        } else {
            [
                l[0] * (2.0 * l[0] - 1.0),
                l[1] * (2.0 * l[1] - 1.0),
                l[2] * (2.0 * l[2] - 1.0),
                4.0 * l[0] * l[1],
                4.0 * l[1] * l[2],
                4.0 * l[2] * l[0],
            ]
        }
    }

    /// Adds `integral N_k p dA` over triangle `t` to `acc[k]` (see the module documentation).
    fn integrate(&self, t: usize, ball: &Ball, acc: &mut [f64; 6]) {
        let p = self.corners[t];
        let d = dot(self.normals[t], sub(ball.centre, p[0]));
        let disk2 = ball.radius * ball.radius - d * d;
        if disk2 <= 0.0 {
            return;
        }
        let leaf = disk2.sqrt().max(LEAF_FLOOR * ball.radius) / LEAF_DIVISOR;
        let piece = Piece {
            corners: p,
            area: self.areas[t],
            ball,
            leaf2: leaf * leaf,
        };
        let unit = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        self.recurse(&piece, unit, self.areas[t], acc);
    }

    /// One sub-triangle of `piece` (barycentric vertices `b`, area `area`).
    fn recurse(&self, piece: &Piece<'_>, b: [[f64; 3]; 3], area: f64, acc: &mut [f64; 6]) {
        let x = b.map(|l| piece.at(l));
        let pv = x.map(|x| piece.ball.pressure(x));
        if pv.iter().all(|&v| v >= 0.0) {
            self.rule(piece, b, area, acc);
            return;
        }
        if pv.iter().all(|&v| v < 0.0) {
            let (near, _) = closest_on_triangle(piece.ball.centre, x);
            if dist2(near, piece.ball.centre) >= piece.ball.radius * piece.ball.radius {
                return;
            }
        }
        let longest = dist2(x[0], x[1])
            .max(dist2(x[1], x[2]))
            .max(dist2(x[2], x[0]));
        if longest > piece.leaf2 {
            let mid = |i: usize, j: usize| -> [f64; 3] {
                std::array::from_fn(|c| 0.5 * (b[i][c] + b[j][c]))
            };
            let (m01, m12, m20) = (mid(0, 1), mid(1, 2), mid(2, 0));
            let quarter = 0.25 * area;
            for child in [
                [b[0], m01, m20],
                [m01, b[1], m12],
                [m20, m12, b[2]],
                [m01, m12, m20],
            ] {
                self.recurse(piece, child, quarter, acc);
            }
            return;
        }
        // A leaf: the polygon of its vertices inside the ball and the sphere's crossings.
        let mut poly: Vec<[f64; 3]> = Vec::with_capacity(4);
        for i in 0..3 {
            let j = (i + 1) % 3;
            let (inside_i, inside_j) = (pv[i] >= 0.0, pv[j] >= 0.0);
            if inside_i {
                poly.push(b[i]);
            }
            if inside_i != inside_j {
                let (from, to) = if inside_i { (i, j) } else { (j, i) };
                let s = piece.ball.crossing(x[from], x[to]);
                poly.push(std::array::from_fn(|c| {
                    b[from][c] + s * (b[to][c] - b[from][c])
                }));
            }
        }
        for k in 1..poly.len().saturating_sub(1) {
            let tri = [poly[0], poly[k], poly[k + 1]];
            self.rule(piece, tri, piece.area * det3(tri).abs(), acc);
        }
    }

    /// The 7-point rule for `N_k p` on the sub-triangle `b` (barycentric vertices) of area `area`.
    fn rule(&self, piece: &Piece<'_>, b: [[f64; 3]; 3], area: f64, acc: &mut [f64; 6]) {
        for (lam, w) in RULE {
            let l: [f64; 3] =
                std::array::from_fn(|c| lam[0] * b[0][c] + lam[1] * b[1][c] + lam[2] * b[2][c]);
            let f = area * w * piece.ball.pressure(piece.at(l));
            for (a, n) in acc.iter_mut().zip(self.shape(l)) {
                *a += f * n;
            }
        }
    }
}

/// Sums entries with equal nodes; sorted by node.
fn merge(mut entries: Vec<(usize, f64)>) -> Vec<(usize, f64)> {
    entries.sort_by_key(|e| e.0);
    let mut out: Vec<(usize, f64)> = Vec::with_capacity(entries.len());
    for (node, w) in entries {
        match out.last_mut() {
            Some(last) if last.0 == node => last.1 += w,
            _ => out.push((node, w)),
        }
    }
    out
}

/// Determinant of three barycentric points (rows): the area ratio of the triangle they span.
fn det3(m: [[f64; 3]; 3]) -> f64 {
    dot(m[0], cross(m[1], m[2]))
}

/// The tool's ball.
struct Ball {
    centre: [f64; 3],
    radius: f64,
    inv_a2: f64,
}

impl Ball {
    fn new(centre: [f64; 3], radius: f64) -> Self {
        Self {
            centre,
            radius,
            inv_a2: 1.0 / (radius * radius),
        }
    }

    /// `1 - |x - c|^2 / a^2` (negative outside the ball).
    fn pressure(&self, x: [f64; 3]) -> f64 {
        1.0 - dist2(x, self.centre) * self.inv_a2
    }

    /// The parameter `s` in `[0, 1]` where the segment from `inside` to `outside` leaves the
    /// ball: the root of `|u + s e|^2 = a^2`, `u = inside - c`, `e = outside - inside`.
    fn crossing(&self, inside: [f64; 3], outside: [f64; 3]) -> f64 {
        let u = sub(inside, self.centre);
        let e = sub(outside, inside);
        let qa = dot(e, e);
        let qb = dot(u, e);
        let qc = dot(u, u) - self.radius * self.radius; // <= 0
        let root = (qb * qb - qa * qc).max(0.0).sqrt();
        let s = if qb >= 0.0 {
            if qb + root > 0.0 {
                -qc / (qb + root)
            } else {
                0.0
            }
        } else {
            (root - qb) / qa
        };
        s.clamp(0.0, 1.0)
    }
}

/// The triangle being integrated.
struct Piece<'a> {
    corners: [[f64; 3]; 3],
    area: f64,
    ball: &'a Ball,
    /// Squared leaf size.
    leaf2: f64,
}

impl Piece<'_> {
    /// The point of barycentric coordinates `l`.
    fn at(&self, l: [f64; 3]) -> [f64; 3] {
        let [a, b, c] = self.corners;
        add(add(scale(a, l[0]), scale(b, l[1])), scale(c, l[2]))
    }
}

/// The closest point of triangle `t` to `q` and its barycentric coordinates (Ericson, *Real-Time
/// Collision Detection*, 5.1.5: Voronoi regions of the vertices, then the edges, then the face).
pub fn closest_on_triangle(q: [f64; 3], t: [[f64; 3]; 3]) -> ([f64; 3], [f64; 3]) {
    let [a, b, c] = t;
    let ab = sub(b, a);
    let ac = sub(c, a);
    let ap = sub(q, a);
    let d1 = dot(ab, ap);
    let d2 = dot(ac, ap);
    if d1 <= 0.0 && d2 <= 0.0 {
        return (a, [1.0, 0.0, 0.0]);
    }
    let bp = sub(q, b);
    let d3 = dot(ab, bp);
    let d4 = dot(ac, bp);
    if d3 >= 0.0 && d4 <= d3 {
        return (b, [0.0, 1.0, 0.0]);
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = d1 / (d1 - d3);
        return (add(a, scale(ab, v)), [1.0 - v, v, 0.0]);
    }
    let cp = sub(q, c);
    let d5 = dot(ab, cp);
    let d6 = dot(ac, cp);
    if d6 >= 0.0 && d5 <= d6 {
        return (c, [0.0, 0.0, 1.0]);
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return (add(a, scale(ac, w)), [1.0 - w, 0.0, w]);
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && d4 - d3 >= 0.0 && d5 - d6 >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return (add(b, scale(sub(c, b), w)), [0.0, 1.0 - w, w]);
    }
    let denom = 1.0 / (va + vb + vc);
    let v = vb * denom;
    let w = vc * denom;
    (add(a, add(scale(ab, v), scale(ac, w))), [1.0 - v - w, v, w])
}

/// A uniform grid of cubic cells over a bounding box, each cell listing the triangles whose
/// bounding box meets it (CSR).
#[derive(Debug, Clone)]
struct Grid {
    lo: [f64; 3],
    hi: [f64; 3],
    cell: f64,
    dims: [usize; 3],
    start: Vec<usize>,
    items: Vec<usize>,
}

impl Grid {
    /// Cells of about two mean edge lengths, at most four cells per triangle.
    fn new(corners: &[[[f64; 3]; 3]]) -> Self {
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        let mut edges = 0.0;
        for t in corners {
            for (k, p) in t.iter().enumerate() {
                for a in 0..3 {
                    lo[a] = lo[a].min(p[a]);
                    hi[a] = hi[a].max(p[a]);
                }
                edges += dist2(*p, t[(k + 1) % 3]).sqrt();
            }
        }
        let extent = (0..3).map(|a| hi[a] - lo[a]).fold(0.0, f64::max);
        let mut cell = (2.0 * edges / (3 * corners.len()) as f64).max(extent * 1e-6);
        let cap = 4 * corners.len() + 64;
        let dims_for = |cell: f64| -> [usize; 3] {
            std::array::from_fn(|a| (((hi[a] - lo[a]) / cell).floor() as usize + 1).max(1))
        };
        let mut dims = dims_for(cell);
        while dims.iter().map(|&d| d as f64).product::<f64>() > cap as f64 {
            cell *= 1.25;
            dims = dims_for(cell);
        }
        let mut grid = Self {
            lo,
            hi,
            cell,
            dims,
            start: Vec::new(),
            items: Vec::new(),
        };
        let boxes: Vec<[[usize; 3]; 2]> = corners
            .iter()
            .map(|t| {
                let mut b = [[usize::MAX; 3], [0; 3]];
                for p in t {
                    for a in 0..3 {
                        let i = grid.index(p[a], a);
                        b[0][a] = b[0][a].min(i);
                        b[1][a] = b[1][a].max(i);
                    }
                }
                b
            })
            .collect();
        let cells = dims[0] * dims[1] * dims[2];
        let mut count = vec![0usize; cells + 1];
        let for_cells = |b: &[[usize; 3]; 2], f: &mut dyn FnMut(usize)| {
            for k in b[0][2]..=b[1][2] {
                for j in b[0][1]..=b[1][1] {
                    for i in b[0][0]..=b[1][0] {
                        f(i + dims[0] * (j + dims[1] * k));
                    }
                }
            }
        };
        for b in &boxes {
            for_cells(b, &mut |c| count[c + 1] += 1);
        }
        for c in 0..cells {
            count[c + 1] += count[c];
        }
        let mut items = vec![0usize; count[cells]];
        let mut fill = count.clone();
        for (t, b) in boxes.iter().enumerate() {
            for_cells(b, &mut |c| {
                items[fill[c]] = t;
                fill[c] += 1;
            });
        }
        grid.start = count;
        grid.items = items;
        grid
    }

    /// The cell index along `axis` of coordinate `x`, clamped to the grid (NaN gives 0).
    fn index(&self, x: f64, axis: usize) -> usize {
        let i = ((x - self.lo[axis]) / self.cell).floor();
        if i >= 0.0 {
            (i as usize).min(self.dims[axis] - 1)
        } else {
            0
        }
    }

    /// The triangles listed in cell `[i, j, k]`.
    fn cell(&self, [i, j, k]: [usize; 3]) -> &[usize] {
        let c = i + self.dims[0] * (j + self.dims[1] * k);
        &self.items[self.start[c]..self.start[c + 1]]
    }

    /// Squared distance from `q` to the box of cell `[i, j, k]`.
    fn box_distance2(&self, cell: [usize; 3], q: [f64; 3]) -> f64 {
        (0..3)
            .map(|a| {
                let lo = self.lo[a] + cell[a] as f64 * self.cell;
                let d = (lo - q[a]).max(q[a] - (lo + self.cell)).max(0.0);
                d * d
            })
            .sum()
    }

    /// The triangles listed in the cells that the box `[lo, hi]` meets (with repeats).
    fn in_box(&self, lo: [f64; 3], hi: [f64; 3]) -> Vec<usize> {
        if (0..3).any(|a| hi[a] < self.lo[a] || lo[a] > self.hi[a]) {
            return Vec::new();
        }
        let a: [usize; 3] = std::array::from_fn(|x| self.index(lo[x], x));
        let b: [usize; 3] = std::array::from_fn(|x| self.index(hi[x], x));
        let mut out = Vec::new();
        for k in a[2]..=b[2] {
            for j in a[1]..=b[1] {
                for i in a[0]..=b[0] {
                    out.extend_from_slice(self.cell([i, j, k]));
                }
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `integral over the unit right triangle of x^i y^j = i! j! / (i + j + 2)!`.
    #[test]
    fn rule_is_exact_to_degree_five() {
        let fact = |n: u32| (1..=n).map(f64::from).product::<f64>();
        for i in 0..=5u32 {
            for j in 0..=(5 - i) {
                let exact = fact(i) * fact(j) / fact(i + j + 2);
                let got: f64 = RULE
                    .iter()
                    .map(|(l, w)| 0.5 * w * l[1].powi(i as i32) * l[2].powi(j as i32))
                    .sum();
                assert!((got - exact).abs() <= 1e-15 * exact.max(1e-3), "{i} {j}");
            }
        }
        let sum: f64 = RULE.iter().map(|r| r.1).sum();
        assert!((sum - 1.0).abs() < 1e-15);
    }

    #[test]
    fn crossing_is_on_the_sphere() {
        let ball = Ball::new([0.1, -0.2, 0.3], 0.5);
        for (inside, outside) in [
            ([0.1, -0.2, 0.3], [1.0, 0.0, 0.0]),
            ([0.4, -0.2, 0.3], [-1.0, -0.2, 0.3]),
            ([0.1, 0.25, 0.3], [0.1, 0.4, 0.35]),
        ] {
            let s = ball.crossing(inside, outside);
            let x: [f64; 3] = std::array::from_fn(|c| inside[c] + s * (outside[c] - inside[c]));
            assert!(ball.pressure(x).abs() < 1e-14, "{s}");
        }
    }

    #[test]
    fn merge_sums_equal_nodes() {
        assert_eq!(
            merge(vec![(3, 1.0), (1, 2.0), (3, 0.5), (2, 0.0)]),
            vec![(1, 2.0), (2, 0.0), (3, 1.5)]
        );
    }
}
