//! Closed triangulated surfaces (an organ's segmented boundary) before volume meshing: reading
//! (STL, OBJ, PLY, legacy VTK polydata, [`read_surface`]) and the checks a surface must pass to
//! bound a volume ([`check`]), with opt-in safe repairs.
//!
//! Vertex and face ids are 0-based positions in the file's order (STL: vertices in order of
//! first appearance, bit-identical coordinates merged; polygons are split into fans, so a face
//! id counts triangles).

use crate::vec3::{add, cross, dot, norm, scale, sub};
use predicates::{orient2d, orient3d};
use std::cmp::Ordering;
use std::collections::{HashMap, HashSet};
use std::fmt;

mod predicates;
mod read;

pub use read::{SurfaceFormat, read_surface, read_surface_bytes};

/// A triangulated surface, in the file's units until scaled.
#[derive(Debug, Clone, PartialEq)]
pub struct TriSurface {
    /// Vertex coordinates.
    pub vertices: Vec<[f64; 3]>,
    /// Three vertex ids per face; outward faces are counter-clockwise seen from outside.
    pub triangles: Vec<[usize; 3]>,
}

impl TriSurface {
    /// Axis-aligned bounding box `(min, max)` of the vertices used by a face.
    pub fn bounding_box(&self) -> ([f64; 3], [f64; 3]) {
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for t in &self.triangles {
            for &v in t {
                let p = self.vertices[v];
                for a in 0..3 {
                    lo[a] = lo[a].min(p[a]);
                    hi[a] = hi[a].max(p[a]);
                }
            }
        }
        (lo, hi)
    }

    /// The surface with every coordinate multiplied by `s`.
    pub fn scaled(&self, s: f64) -> TriSurface {
        TriSurface {
            vertices: self.vertices.iter().map(|&p| scale(p, s)).collect(),
            triangles: self.triangles.clone(),
        }
    }

    /// Enclosed volume (positive when the faces point outward); meaningful for closed surfaces.
    pub fn signed_volume(&self) -> f64 {
        self.triangles
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|v| self.vertices[v]);
                dot(a, cross(b, c)) / 6.0
            })
            .sum()
    }

    fn area(&self, f: usize) -> f64 {
        let [a, b, c] = self.triangles[f].map(|v| self.vertices[v]);
        0.5 * norm(cross(sub(b, a), sub(c, a)))
    }

    fn centroid(&self, f: usize) -> [f64; 3] {
        let [a, b, c] = self.triangles[f].map(|v| self.vertices[v]);
        scale(add(add(a, b), c), 1.0 / 3.0)
    }

    fn diagonal(&self) -> f64 {
        let (lo, hi) = self.bounding_box();
        norm(sub(hi, lo))
    }

    /// Binary STL bytes (f32 coordinates, zero normals and attributes).
    pub fn to_stl_binary(&self) -> Vec<u8> {
        let mut b = Vec::with_capacity(84 + 50 * self.triangles.len());
        b.extend_from_slice(&[0u8; 80]);
        b.extend_from_slice(&(self.triangles.len() as u32).to_le_bytes());
        for t in &self.triangles {
            b.extend_from_slice(&[0u8; 12]);
            for &v in t {
                for x in self.vertices[v] {
                    b.extend_from_slice(&(x as f32).to_le_bytes());
                }
            }
            b.extend_from_slice(&[0u8; 2]);
        }
        b
    }
}

/// A point for messages: three coordinates, 4 decimals (file units).
struct At([f64; 3]);

impl fmt::Display for At {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "({:.4}, {:.4}, {:.4})",
            self.0[0] + 0.0,
            self.0[1] + 0.0,
            self.0[2] + 0.0
        )
    }
}

fn at(p: [f64; 3]) -> String {
    At(p).to_string()
}

/// What makes a surface unfit to bound a volume. Every message names the faces or vertices,
/// counts and a location (file units).
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum SurfaceError {
    /// A face refers to a vertex that does not exist.
    #[error("face {face} refers to vertex {vertex}, but there are {count} vertices")]
    VertexOutOfRange {
        /// The face.
        face: usize,
        /// The missing vertex.
        vertex: usize,
        /// Vertices in all.
        count: usize,
    },
    /// A vertex used by a face has a NaN or infinite coordinate.
    #[error("vertex {vertex} has a non-finite coordinate {coords:?}")]
    NonFinite {
        /// The vertex.
        vertex: usize,
        /// Its coordinates.
        coords: [f64; 3],
    },
    /// Vertices closer than the merge tolerance.
    #[error(
        "{count} duplicate vertices (closer than {tolerance:.2e}): first vertices {first} and \
         {second} at {location}; --repair merges them"
    )]
    DuplicateVertices {
        /// Vertices that would be merged into another one.
        count: usize,
        /// The first pair found.
        first: usize,
        /// Its partner.
        second: usize,
        /// Where.
        location: String,
        /// The tolerance (file units).
        tolerance: f64,
    },
    /// A face of zero area.
    #[error("{count} degenerate faces: face {face} {why} at {location}{hint}")]
    DegenerateFace {
        /// Degenerate faces in all.
        count: usize,
        /// The first.
        face: usize,
        /// "uses vertex 3 twice" or "has zero area (collinear vertices)".
        why: String,
        /// Where.
        location: String,
        /// What --repair can do about it.
        hint: &'static str,
    },
    /// An edge with more than two faces.
    #[error(
        "{count} non-manifold edges: the edge between vertices {} and {} has {faces} faces \
         (a closed surface has 2) at {location}",
        edge[0], edge[1]
    )]
    NonManifoldEdge {
        /// Such edges in all.
        count: usize,
        /// The first.
        edge: [usize; 2],
        /// Its number of faces.
        faces: usize,
        /// Where.
        location: String,
    },
    /// Boundary edges: the surface has holes.
    #[error(
        "not closed: {} holes, boundary loops of {} edges; the first starts at vertex {first_vertex} \
         at {location}{hint}",
        loops.len(),
        loops.iter().map(|n| n.to_string()).collect::<Vec<_>>().join(", ")
    )]
    NotClosed {
        /// Edge count of each boundary loop.
        loops: Vec<usize>,
        /// A vertex of the first loop.
        first_vertex: usize,
        /// Where.
        location: String,
        /// What --repair can do about it.
        hint: String,
    },
    /// A vertex where the surface touches itself (its faces form several fans).
    #[error(
        "{count} non-manifold vertices: at vertex {vertex} the faces form {fans} separate fans \
         (the surface touches itself) at {location}"
    )]
    NonManifoldVertex {
        /// Such vertices in all.
        count: usize,
        /// The first.
        vertex: usize,
        /// Its number of fans.
        fans: usize,
        /// Where.
        location: String,
    },
    /// Disconnected pieces.
    #[error(
        "{} disconnected shells ({}); --largest keeps the largest",
        shells.len(),
        shells.iter().map(|s| s.to_string()).collect::<Vec<_>>().join("; ")
    )]
    SeveralShells {
        /// Every shell.
        shells: Vec<Shell>,
    },
    /// Neighbouring faces that disagree on which side is outside.
    #[error(
        "inconsistent orientation: {count} of {total} faces point the other way from their \
         neighbours, first face {face} (shares edge {} - {} with face {neighbour} in the same \
         direction) at {location}{hint}",
        edge[0], edge[1]
    )]
    InconsistentOrientation {
        /// Faces to flip.
        count: usize,
        /// Faces in all.
        total: usize,
        /// The first face to flip.
        face: usize,
        /// A neighbour it disagrees with.
        neighbour: usize,
        /// Their common edge.
        edge: [usize; 2],
        /// Where.
        location: String,
        /// What --repair can do about it.
        hint: &'static str,
    },
    /// The orientation cannot be made consistent (a Moebius-like surface).
    #[error("non-orientable surface: face {face} cannot agree with all its neighbours")]
    NonOrientable {
        /// A face on the conflict.
        face: usize,
    },
    /// Faces crossing each other.
    #[error(
        "self-intersecting: {count} pairs of faces cross, first faces {} and {} at {location}",
        faces[0], faces[1]
    )]
    SelfIntersection {
        /// Crossing pairs found.
        count: usize,
        /// The first pair.
        faces: [usize; 2],
        /// Where.
        location: String,
    },
}

/// One connected piece of a surface.
#[derive(Debug, Clone, PartialEq)]
pub struct Shell {
    /// Its faces.
    pub faces: usize,
    /// Its area (file units squared).
    pub area: f64,
    /// The centre of its bounding box.
    pub centre: [f64; 3],
}

impl fmt::Display for Shell {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{} faces, area {:.3e}, centred at {}",
            self.faces,
            self.area,
            at(self.centre)
        )
    }
}

/// What [`check`] may change.
#[derive(Debug, Clone, Copy)]
pub struct CheckOptions {
    /// Safe repairs: merge duplicate vertices, drop faces that use a vertex twice, make the
    /// orientation consistent, fill holes of at most `fill_holes` edges (O(n^3) time and
    /// O(n^2) memory in a hole's edges).
    pub repair: bool,
    /// Vertices closer than this fraction of the bounding-box diagonal are duplicates.
    pub merge_tolerance: f64,
    /// Largest hole (boundary loop edges) `repair` fills.
    pub fill_holes: usize,
    /// Keep the largest shell (by area) when there are several, instead of refusing.
    pub largest: bool,
}

impl Default for CheckOptions {
    fn default() -> Self {
        CheckOptions {
            repair: false,
            merge_tolerance: 1e-9,
            fill_holes: 32,
            largest: false,
        }
    }
}

/// Union-find over `0..n`.
struct Sets(Vec<usize>);

impl Sets {
    fn new(n: usize) -> Self {
        Sets((0..n).collect())
    }
    fn find(&mut self, mut i: usize) -> usize {
        while self.0[i] != i {
            self.0[i] = self.0[self.0[i]];
            i = self.0[i];
        }
        i
    }
    fn union(&mut self, a: usize, b: usize) {
        let (a, b) = (self.find(a), self.find(b));
        // The lower id represents the set.
        if a < b {
            self.0[b] = a;
        } else {
            self.0[a] = b;
        }
    }
}

/// Check that `s` bounds a volume, repairing what `opts` allows; returns the surface (faces
/// outward, unused vertices dropped) and one line per change made. The checks run in this
/// order: vertex ids and finite coordinates, duplicate vertices, degenerate faces,
/// non-manifold edges, non-manifold vertices, shells, holes (filled by the least-area
/// triangulation of each boundary loop), orientation, self-intersections (every pair of faces
/// whose boxes overlap, with exact orientation predicates: faces that share a vertex or an
/// edge and coplanar overlaps included). A surface whose faces all point inward is flipped
/// whatever `opts` say (that is a convention, not a defect), and said.
pub fn check(
    s: &TriSurface,
    opts: CheckOptions,
) -> Result<(TriSurface, Vec<String>), SurfaceError> {
    let mut s = s.clone();
    let mut notes = Vec::new();
    for (face, t) in s.triangles.iter().enumerate() {
        for &v in t {
            let Some(&p) = s.vertices.get(v) else {
                return Err(SurfaceError::VertexOutOfRange {
                    face,
                    vertex: v,
                    count: s.vertices.len(),
                });
            };
            if !p.iter().all(|x| x.is_finite()) {
                return Err(SurfaceError::NonFinite {
                    vertex: v,
                    coords: p,
                });
            }
        }
    }
    merge_duplicates(&mut s, &opts, &mut notes)?;
    degenerate_faces(&mut s, &opts, &mut notes)?;
    let edges = edge_faces(&s);
    non_manifold_edges(&s, &edges)?;
    non_manifold_vertices(&s)?;
    shells(&mut s, &edges, &opts, &mut notes)?;
    holes(&mut s, &opts, &mut notes)?;
    orient(&mut s, &opts, &mut notes)?;
    if s.signed_volume() < 0.0 {
        for t in &mut s.triangles {
            t.swap(1, 2);
        }
        notes.push("the faces pointed inward (inside out): all flipped".into());
    }
    self_intersections(&s)?;
    drop_unused(&mut s, &mut notes);
    Ok((s, notes))
}

fn merge_duplicates(
    s: &mut TriSurface,
    opts: &CheckOptions,
    notes: &mut Vec<String>,
) -> Result<(), SurfaceError> {
    let tol = opts.merge_tolerance * s.diagonal();
    let n = s.vertices.len();
    let mut sets = Sets::new(n);
    let mut pairs = 0usize;
    let mut first = None;
    // Buckets of side tol (at least a tiny positive size): neighbours are in the 27 around.
    let cell = tol.max(f64::MIN_POSITIVE);
    let key = |p: [f64; 3]| p.map(|x| (x / cell).floor() as i64);
    let mut grid: HashMap<[i64; 3], Vec<usize>> = HashMap::new();
    let mut used = vec![false; n];
    for t in &s.triangles {
        for &v in t {
            used[v] = true;
        }
    }
    for (i, &p) in s.vertices.iter().enumerate() {
        if !used[i] {
            continue;
        }
        let k = key(p);
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    let Some(list) = grid.get(&[k[0] + dx, k[1] + dy, k[2] + dz]) else {
                        continue;
                    };
                    for &j in list {
                        if norm(sub(s.vertices[j], p)) <= tol && sets.find(i) != sets.find(j) {
                            sets.union(i, j);
                            pairs += 1;
                            first.get_or_insert((j, i));
                        }
                    }
                }
            }
        }
        grid.entry(k).or_default().push(i);
    }
    let Some((a, b)) = first else {
        return Ok(());
    };
    if !opts.repair {
        return Err(SurfaceError::DuplicateVertices {
            count: pairs,
            first: a,
            second: b,
            location: at(s.vertices[a]),
            tolerance: tol,
        });
    }
    for t in &mut s.triangles {
        for v in t.iter_mut() {
            *v = sets.find(*v);
        }
    }
    notes.push(format!(
        "merged {pairs} duplicate vertices (closer than {tol:.2e}; first {b} into {a})"
    ));
    Ok(())
}

fn degenerate_faces(
    s: &mut TriSurface,
    opts: &CheckOptions,
    notes: &mut Vec<String>,
) -> Result<(), SurfaceError> {
    let repeated = |t: &[usize; 3]| t[0] == t[1] || t[1] == t[2] || t[0] == t[2];
    let min_area = 1e-14 * s.diagonal().powi(2);
    let collinear: Vec<usize> = (0..s.triangles.len())
        .filter(|&f| !repeated(&s.triangles[f]) && s.area(f) <= min_area)
        .collect();
    let twice: Vec<usize> = (0..s.triangles.len())
        .filter(|&f| repeated(&s.triangles[f]))
        .collect();
    if let Some(&f) = collinear.first() {
        return Err(SurfaceError::DegenerateFace {
            count: collinear.len() + twice.len(),
            face: f,
            why: format!("has zero area ({:.2e}, collinear vertices)", s.area(f)),
            location: at(s.centroid(f)),
            hint: "",
        });
    }
    if let Some(&f) = twice.first() {
        if !opts.repair {
            let t = s.triangles[f];
            let v = if t[0] == t[1] || t[0] == t[2] {
                t[0]
            } else {
                t[1]
            };
            return Err(SurfaceError::DegenerateFace {
                count: twice.len(),
                face: f,
                why: format!("uses vertex {v} twice"),
                location: at(s.vertices[v]),
                hint: "; --repair drops such faces",
            });
        }
        let drop: HashSet<usize> = twice.iter().copied().collect();
        let mut f = 0;
        s.triangles.retain(|_| {
            f += 1;
            !drop.contains(&(f - 1))
        });
        notes.push(format!(
            "dropped {} faces that used a vertex twice",
            drop.len()
        ));
    }
    Ok(())
}

/// Faces of each undirected edge `(low, high)`.
fn edge_faces(s: &TriSurface) -> HashMap<[usize; 2], Vec<usize>> {
    let mut m: HashMap<[usize; 2], Vec<usize>> = HashMap::new();
    for (f, t) in s.triangles.iter().enumerate() {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            m.entry([a.min(b), a.max(b)]).or_default().push(f);
        }
    }
    m
}

fn non_manifold_edges(
    s: &TriSurface,
    edges: &HashMap<[usize; 2], Vec<usize>>,
) -> Result<(), SurfaceError> {
    let mut bad: Vec<(&[usize; 2], usize)> = edges
        .iter()
        .filter(|(_, f)| f.len() > 2)
        .map(|(e, f)| (e, f.len()))
        .collect();
    bad.sort();
    if let Some(&(e, faces)) = bad.first() {
        return Err(SurfaceError::NonManifoldEdge {
            count: bad.len(),
            edge: *e,
            faces,
            location: at(s.vertices[e[0]]),
        });
    }
    Ok(())
}

fn shells(
    s: &mut TriSurface,
    edges: &HashMap<[usize; 2], Vec<usize>>,
    opts: &CheckOptions,
    notes: &mut Vec<String>,
) -> Result<(), SurfaceError> {
    let mut sets = Sets::new(s.triangles.len());
    for f in edges.values() {
        for w in f.windows(2) {
            sets.union(w[0], w[1]);
        }
    }
    let mut ids: Vec<usize> = Vec::new();
    let mut of_face = vec![0; s.triangles.len()];
    for (f, slot) in of_face.iter_mut().enumerate() {
        let r = sets.find(f);
        *slot = match ids.iter().position(|&x| x == r) {
            Some(i) => i,
            None => {
                ids.push(r);
                ids.len() - 1
            }
        };
    }
    if ids.len() < 2 {
        return Ok(());
    }
    let list: Vec<Shell> = (0..ids.len())
        .map(|k| {
            let part = TriSurface {
                vertices: s.vertices.clone(),
                triangles: (0..s.triangles.len())
                    .filter(|&f| of_face[f] == k)
                    .map(|f| s.triangles[f])
                    .collect(),
            };
            let (lo, hi) = part.bounding_box();
            Shell {
                faces: part.triangles.len(),
                area: (0..part.triangles.len()).map(|f| part.area(f)).sum(),
                centre: scale(add(lo, hi), 0.5),
            }
        })
        .collect();
    if !opts.largest {
        return Err(SurfaceError::SeveralShells { shells: list });
    }
    let keep = (0..list.len())
        .max_by(|&a, &b| list[a].area.total_cmp(&list[b].area))
        .unwrap_or(0);
    let mut f = 0;
    s.triangles.retain(|_| {
        f += 1;
        of_face[f - 1] == keep
    });
    notes.push(format!(
        "kept the largest of {} shells ({}); dropped {}",
        list.len(),
        list[keep],
        list.iter()
            .enumerate()
            .filter(|&(k, _)| k != keep)
            .map(|(_, x)| x.to_string())
            .collect::<Vec<_>>()
            .join("; ")
    ));
    Ok(())
}

/// Boundary loops: each a cycle of boundary edges (edges of one face), in their face's
/// direction.
fn boundary_loops(s: &TriSurface) -> Vec<Vec<[usize; 2]>> {
    let edges = edge_faces(s);
    let mut boundary: Vec<[usize; 2]> = Vec::new();
    for (e, faces) in &edges {
        if let [f] = faces[..] {
            let t = s.triangles[f];
            let forward = (0..3).any(|k| [t[k], t[(k + 1) % 3]] == *e);
            boundary.push(if forward { *e } else { [e[1], e[0]] });
        }
    }
    boundary.sort();
    let mut from: HashMap<usize, Vec<[usize; 2]>> = HashMap::new();
    for &e in &boundary {
        from.entry(e[0]).or_default().push(e);
    }
    let mut used: HashSet<[usize; 2]> = HashSet::new();
    let mut loops = Vec::new();
    for &start in &boundary {
        if used.contains(&start) {
            continue;
        }
        let mut lp = vec![start];
        used.insert(start);
        let mut cur = start;
        while cur[1] != start[0] {
            let Some(next) = from
                .get(&cur[1])
                .and_then(|v| v.iter().find(|e| !used.contains(*e)))
                .copied()
            else {
                break;
            };
            used.insert(next);
            lp.push(next);
            cur = next;
        }
        loops.push(lp);
    }
    loops
}

fn holes(
    s: &mut TriSurface,
    opts: &CheckOptions,
    notes: &mut Vec<String>,
) -> Result<(), SurfaceError> {
    let loops = boundary_loops(s);
    if loops.is_empty() {
        return Ok(());
    }
    let sizes: Vec<usize> = loops.iter().map(Vec::len).collect();
    let fillable = opts.repair && sizes.iter().all(|&n| n <= opts.fill_holes);
    if !fillable {
        let first_vertex = loops[0][0][0];
        let hint = if opts.repair {
            format!(
                "; --repair fills holes of at most {} edges (--fill-holes)",
                opts.fill_holes
            )
        } else {
            format!(
                "; --repair fills holes of at most {} edges",
                opts.fill_holes
            )
        };
        return Err(SurfaceError::NotClosed {
            loops: sizes,
            first_vertex,
            location: at(s.vertices[first_vertex]),
            hint,
        });
    }
    let mut existing: HashSet<[usize; 2]> = edge_faces(s).into_keys().collect();
    for lp in &loops {
        let ring: Vec<usize> = lp.iter().map(|e| e[0]).collect();
        let Some(faces) = fill_loop(&s.vertices, &ring, &existing) else {
            return Err(SurfaceError::NotClosed {
                loops: sizes.clone(),
                first_vertex: ring[0],
                location: at(s.vertices[ring[0]]),
                hint: format!(
                    "; the hole of {} edges at vertex {} cannot be filled without an edge the \
                     surface already has (its boundary touches itself): fill it by hand",
                    ring.len(),
                    ring[0]
                ),
            });
        };
        for t in faces {
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                existing.insert([a.min(b), a.max(b)]);
            }
            s.triangles.push(t);
        }
    }
    notes.push(format!(
        "filled {} holes (boundary loops of {} edges) with the least-area triangulation of each \
         loop",
        loops.len(),
        sizes
            .iter()
            .map(|n| n.to_string())
            .collect::<Vec<_>>()
            .join(", ")
    ));
    Ok(())
}

/// The triangulation of the boundary loop `ring` (vertex ids in the direction of its faces'
/// boundary edges: edge `ring[i] -> ring[i + 1]`) of least total area, by dynamic programming
/// over its sub-polygons (Barequet and Sharir 1995; Liepa 2003 without the dihedral term),
/// O(n^3) time and O(n^2) memory; no vertex is added. The faces run against the loop, so they
/// agree with the faces around the hole. A triangle that would use a vertex twice, or a
/// diagonal that is an edge of `existing` or of the ring itself (it would be non-manifold), is
/// not allowed; `None` when no triangulation avoids them.
fn fill_loop(
    v: &[[f64; 3]],
    ring: &[usize],
    existing: &HashSet<[usize; 2]>,
) -> Option<Vec<[usize; 3]>> {
    let n = ring.len();
    if n < 3 {
        return None;
    }
    let key = |a: usize, b: usize| [a.min(b), a.max(b)];
    // A diagonal i - j (not a side of the loop) is allowed when it is no edge yet.
    let allowed = |i: usize, j: usize| {
        j == i + 1
            || (i == 0 && j == n - 1)
            || (ring[i] != ring[j] && !existing.contains(&key(ring[i], ring[j])))
    };
    let area = |i: usize, m: usize, j: usize| {
        let [a, b, c] = [ring[i], ring[m], ring[j]].map(|x| v[x]);
        0.5 * norm(cross(sub(b, a), sub(c, a)))
    };
    // best[i][j]: least area of the polygon ring[i..=j] closed by the diagonal i - j, with
    // the middle vertex of its triangle on i - j in split[i][j].
    let mut best = vec![vec![f64::INFINITY; n]; n];
    let mut split = vec![vec![usize::MAX; n]; n];
    for i in 0..n - 1 {
        best[i][i + 1] = 0.0;
    }
    for len in 2..n {
        for i in 0..n - len {
            let j = i + len;
            if !allowed(i, j) {
                continue;
            }
            for m in i + 1..j {
                let (ri, rm, rj) = (ring[i], ring[m], ring[j]);
                if ri == rm || rm == rj {
                    continue;
                }
                let w = best[i][m] + best[m][j] + area(i, m, j);
                if w < best[i][j] {
                    best[i][j] = w;
                    split[i][j] = m;
                }
            }
        }
    }
    if !best[0][n - 1].is_finite() {
        return None;
    }
    let mut faces = Vec::with_capacity(n - 2);
    let mut stack = vec![(0, n - 1)];
    while let Some((i, j)) = stack.pop() {
        if j <= i + 1 {
            continue;
        }
        let m = split[i][j];
        faces.push([ring[j], ring[m], ring[i]]);
        stack.push((i, m));
        stack.push((m, j));
    }
    Some(faces)
}

fn non_manifold_vertices(s: &TriSurface) -> Result<(), SurfaceError> {
    let mut faces_of: Vec<Vec<usize>> = vec![Vec::new(); s.vertices.len()];
    for (f, t) in s.triangles.iter().enumerate() {
        for &v in t {
            faces_of[v].push(f);
        }
    }
    let mut bad = Vec::new();
    for (v, faces) in faces_of.iter().enumerate() {
        if faces.len() < 2 {
            continue;
        }
        // Faces around v joined when they share an edge through v.
        let mut sets = Sets::new(faces.len());
        let mut by_other: HashMap<usize, usize> = HashMap::new();
        for (i, &f) in faces.iter().enumerate() {
            for &w in &s.triangles[f] {
                if w == v {
                    continue;
                }
                if let Some(&j) = by_other.get(&w) {
                    sets.union(i, j);
                } else {
                    by_other.insert(w, i);
                }
            }
        }
        let fans = (0..faces.len()).filter(|&i| sets.find(i) == i).count();
        if fans > 1 {
            bad.push((v, fans));
        }
    }
    if let Some(&(vertex, fans)) = bad.first() {
        return Err(SurfaceError::NonManifoldVertex {
            count: bad.len(),
            vertex,
            fans,
            location: at(s.vertices[vertex]),
        });
    }
    Ok(())
}

fn orient(
    s: &mut TriSurface,
    opts: &CheckOptions,
    notes: &mut Vec<String>,
) -> Result<(), SurfaceError> {
    let edges = edge_faces(s);
    let n = s.triangles.len();
    // flip[f]: whether f must be reversed to agree with the first face of its shell.
    let mut flip: Vec<Option<bool>> = vec![None; n];
    let mut first_conflict: Option<(usize, usize, [usize; 2])> = None;
    let same_direction = |f: usize, g: usize, e: [usize; 2], tris: &[[usize; 3]]| {
        let dir = |t: [usize; 3]| (0..3).any(|k| [t[k], t[(k + 1) % 3]] == e);
        dir(tris[f]) == dir(tris[g])
    };
    for seed in 0..n {
        if flip[seed].is_some() {
            continue;
        }
        flip[seed] = Some(false);
        let mut stack = vec![seed];
        while let Some(f) = stack.pop() {
            let t = s.triangles[f];
            for k in 0..3 {
                let e = [t[k], t[(k + 1) % 3]];
                let key = [e[0].min(e[1]), e[0].max(e[1])];
                for &g in edges.get(&key).map_or(&[][..], Vec::as_slice) {
                    if g == f {
                        continue;
                    }
                    // After the flips, f and g must run along e in opposite directions.
                    let same = same_direction(f, g, e, &s.triangles);
                    let want = same != (flip[f] == Some(true));
                    match flip[g] {
                        None => {
                            flip[g] = Some(want);
                            stack.push(g);
                        }
                        Some(x) if x != want => {
                            return Err(SurfaceError::NonOrientable { face: g });
                        }
                        Some(_) => {}
                    }
                    if same && first_conflict.is_none() {
                        first_conflict = Some((g, f, e));
                    }
                }
            }
        }
    }
    let to_flip: Vec<usize> = (0..n).filter(|&f| flip[f] == Some(true)).collect();
    let Some((face, neighbour, edge)) = first_conflict else {
        return Ok(());
    };
    // Flip the minority: the fewer faces that disagree with the rest.
    let flip_set: Vec<usize> = if to_flip.len() * 2 > n {
        (0..n).filter(|&f| flip[f] == Some(false)).collect()
    } else {
        to_flip
    };
    if !opts.repair {
        return Err(SurfaceError::InconsistentOrientation {
            count: flip_set.len(),
            total: n,
            face,
            neighbour,
            edge,
            location: at(s.centroid(face)),
            hint: "; --repair flips them",
        });
    }
    for &f in &flip_set {
        s.triangles[f].swap(1, 2);
    }
    notes.push(format!(
        "flipped {} of {n} faces to agree with their neighbours (first face {face})",
        flip_set.len()
    ));
    Ok(())
}

/// Signs as -1, 0, 1.
fn sgn(o: Ordering) -> i8 {
    o as i8
}

/// Whether the convex polygons `p` and `q` (a triangle, or a segment given as two points) in
/// one plane overlap: they do unless a line through an edge of one (a segment's own line
/// counts, with either side) leaves the other on its far side. With `touch`, sharing only
/// boundary points counts as overlapping (the far side is then strict), else it does not.
/// Exact ([`orient2d`]).
fn overlap_2d(p: &[[f64; 2]], q: &[[f64; 2]], touch: bool) -> bool {
    let separated_by = |a: &[[f64; 2]], b: &[[f64; 2]]| {
        (0..a.len()).any(|i| {
            let (u, v) = (a[i], a[(i + 1) % a.len()]);
            // The side of the edge's line that `a` occupies (a segment: both).
            let sides: Vec<i8> = match a.len() {
                2 => vec![1, -1],
                _ => vec![sgn(orient2d(u, v, a[(i + 2) % a.len()]))],
            };
            sides.iter().any(|&side| {
                b.iter().all(|&w| {
                    let o = sgn(orient2d(u, v, w)) * side;
                    if touch { o < 0 } else { o <= 0 }
                })
            })
        })
    };
    !separated_by(p, q) && !separated_by(q, p)
}

/// `x` with the coordinate `drop` left out.
fn project(x: [f64; 3], drop: usize) -> [f64; 2] {
    match drop {
        0 => [x[1], x[2]],
        1 => [x[2], x[0]],
        _ => [x[0], x[1]],
    }
}

/// The axis to drop to see the plane of `t` without collapsing it: its normal's largest
/// component.
fn drop_axis(t: &[[f64; 3]; 3]) -> usize {
    let n = cross(sub(t[1], t[0]), sub(t[2], t[0])).map(f64::abs);
    if n[0] >= n[1] && n[0] >= n[2] {
        0
    } else if n[1] >= n[2] {
        1
    } else {
        2
    }
}

/// Whether the faces `tf` and `tg` (vertex ids into `v`, each of positive area) intersect
/// anywhere but where their shared vertices or shared edge make them meet. Exact in its
/// decisions ([`orient3d`], [`orient2d`]): coplanar faces overlap when their interiors do
/// (or, sharing no vertex, when they touch); faces sharing an edge can meet elsewhere only
/// when coplanar and folded onto each other; faces sharing one vertex `s` meet elsewhere
/// when each crosses the other's plane along the rays from `s` in the same direction;
/// faces sharing nothing meet when an edge of one meets the other (closed) face.
fn faces_intersect(v: &[[f64; 3]], tf: [usize; 3], tg: [usize; 3]) -> bool {
    let pf = tf.map(|i| v[i]);
    let pg = tg.map(|i| v[i]);
    // Signs of g's vertices against f's plane, and of f's against g's.
    let sg = pg.map(|x| sgn(orient3d(pf[0], pf[1], pf[2], x)));
    let sf = pf.map(|x| sgn(orient3d(pg[0], pg[1], pg[2], x)));
    let shared = tf.iter().filter(|i| tg.contains(i)).count();
    if sg == [0; 3] {
        let k = drop_axis(&pf);
        let qf = pf.map(|x| project(x, k));
        let qg = pg.map(|x| project(x, k));
        return overlap_2d(&qf, &qg, shared == 0);
    }
    match shared {
        // Not coplanar: they meet on the shared edge's line only.
        2 => false,
        1 => {
            // f = (c, a, b) and g = (c, d, e) with c the shared vertex. Each face meets the
            // other's plane along a ray from c (or at c only, when its other two vertices lie
            // strictly on one side), towards the point of its opposite edge on that plane; the
            // faces meet beyond c when both rays exist and point the same way (they lie on
            // the line where the planes cross: the dot product's sign is well conditioned).
            let c = tf.iter().copied().find(|i| tg.contains(i)).unwrap_or(tf[0]);
            let rot = |t: [usize; 3], s: [i8; 3]| {
                let k = t.iter().position(|&x| x == c).unwrap_or(0);
                let (i, j) = ((k + 1) % 3, (k + 2) % 3);
                ([t[k], t[i], t[j]], [s[i], s[j]])
            };
            let (f, sf) = rot(tf, sf);
            let (g, sg) = rot(tg, sg);
            let ray = |t: [usize; 3], s: [i8; 2], other: [usize; 3]| {
                let (a, b) = (sub(v[t[1]], v[t[0]]), sub(v[t[2]], v[t[0]]));
                match s {
                    [0, _] => Some(a),
                    [_, 0] => Some(b),
                    [x, y] if x == y => None,
                    _ => {
                        // The zero of the signed distance along a -> b.
                        let n = cross(sub(v[other[1]], v[other[0]]), sub(v[other[2]], v[other[0]]));
                        let (da, db) = (dot(n, a), dot(n, b));
                        Some(add(scale(a, db.abs()), scale(b, da.abs())))
                    }
                }
            };
            match (ray(f, sf, g), ray(g, sg, f)) {
                (Some(rf), Some(rg)) => dot(rf, rg) > 0.0,
                _ => false,
            }
        }
        _ => {
            // One face wholly on one side of the other's plane: they do not meet.
            let one_side = |s: [i8; 3]| s.iter().all(|&x| x > 0) || s.iter().all(|&x| x < 0);
            if one_side(sf) || one_side(sg) {
                return false;
            }
            let edge_hits = |e: [[f64; 3]; 3], se: [i8; 3], t: [[f64; 3]; 3]| {
                (0..3).any(|k| {
                    let (p, q) = (e[k], e[(k + 1) % 3]);
                    let (sp, sq) = (se[k], se[(k + 1) % 3]);
                    if sp == 0 && sq == 0 {
                        let d = drop_axis(&t);
                        let seg = [project(p, d), project(q, d)];
                        return overlap_2d(&seg, &t.map(|x| project(x, d)), true);
                    }
                    if sp * sq > 0 {
                        return false;
                    }
                    let o = [0, 1, 2].map(|i| sgn(orient3d(p, q, t[i], t[(i + 1) % 3])));
                    o.iter().all(|&x| x >= 0) || o.iter().all(|&x| x <= 0)
                })
            };
            edge_hits(pf, sf, pg) || edge_hits(pg, sg, pf)
        }
    }
}

fn self_intersections(s: &TriSurface) -> Result<(), SurfaceError> {
    let n = s.triangles.len();
    if n == 0 {
        return Ok(());
    }
    let mut boxes = Vec::with_capacity(n);
    let mut mean_edge = 0.0;
    for t in &s.triangles {
        let p = t.map(|v| s.vertices[v]);
        let mut lo = p[0];
        let mut hi = p[0];
        for q in &p[1..] {
            for a in 0..3 {
                lo[a] = lo[a].min(q[a]);
                hi[a] = hi[a].max(q[a]);
            }
        }
        mean_edge += norm(sub(p[1], p[0]));
        boxes.push((lo, hi));
    }
    // Buckets of about two mean edges, but at least 1/64 of the bounding box's diagonal so
    // that a stray far vertex (a huge triangle) cannot ask for billions of buckets.
    let cell = (2.0 * mean_edge / n as f64)
        .max(s.diagonal() / 64.0)
        .max(f64::MIN_POSITIVE);
    let key = |x: [f64; 3]| x.map(|c| (c / cell).floor() as i64);
    let mut grid: HashMap<[i64; 3], Vec<usize>> = HashMap::new();
    for (f, (lo, hi)) in boxes.iter().enumerate() {
        let (a, b) = (key(*lo), key(*hi));
        for i in a[0]..=b[0] {
            for j in a[1]..=b[1] {
                for k in a[2]..=b[2] {
                    grid.entry([i, j, k]).or_default().push(f);
                }
            }
        }
    }
    let mut seen: HashSet<(usize, usize)> = HashSet::new();
    let mut hits: Vec<(usize, usize)> = Vec::new();
    for list in grid.values() {
        for (x, &f) in list.iter().enumerate() {
            for &g in &list[x + 1..] {
                let (f, g) = (f.min(g), f.max(g));
                if !seen.insert((f, g)) {
                    continue;
                }
                let (lf, hf) = boxes[f];
                let (lg, hg) = boxes[g];
                if (0..3).any(|a| lf[a] > hg[a] || lg[a] > hf[a]) {
                    continue;
                }
                if faces_intersect(&s.vertices, s.triangles[f], s.triangles[g]) {
                    hits.push((f, g));
                }
            }
        }
    }
    hits.sort();
    if let Some(&(f, g)) = hits.first() {
        return Err(SurfaceError::SelfIntersection {
            count: hits.len(),
            faces: [f, g],
            location: at(s.centroid(f)),
        });
    }
    Ok(())
}

fn drop_unused(s: &mut TriSurface, notes: &mut Vec<String>) {
    let mut used = vec![false; s.vertices.len()];
    for t in &s.triangles {
        for &v in t {
            used[v] = true;
        }
    }
    // The used vertices keep their order.
    let mut new_id = vec![usize::MAX; s.vertices.len()];
    let mut vertices = Vec::new();
    for (v, &u) in used.iter().enumerate() {
        if u {
            new_id[v] = vertices.len();
            vertices.push(s.vertices[v]);
        }
    }
    for t in &mut s.triangles {
        for v in t.iter_mut() {
            *v = new_id[*v];
        }
    }
    let dropped = s.vertices.len() - vertices.len();
    if dropped > 0 {
        notes.push(format!("dropped {dropped} vertices that no face uses"));
    }
    s.vertices = vertices;
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `faces_intersect` on faces 0 1 2 and `g` of `v`.
    fn meet(v: &[[f64; 3]], g: [usize; 3]) -> bool {
        let a = faces_intersect(v, [0, 1, 2], g);
        // The answer does not depend on the order of the faces nor on their orientation.
        assert_eq!(a, faces_intersect(v, g, [0, 1, 2]));
        assert_eq!(a, faces_intersect(v, [0, 2, 1], [g[0], g[2], g[1]]));
        a
    }

    #[test]
    fn faces_sharing_one_vertex() {
        // f in z = 0 around +x from the origin; g's wedge in y = 0.
        let f = [[0.0, 0.0, 0.0], [2.0, -1.0, 0.0], [2.0, 1.0, 0.0]];
        let case = |d: [f64; 3], e: [f64; 3]| {
            let v = [f[0], f[1], f[2], d, e];
            meet(&v, [0, 3, 4])
        };
        // g around +x too: they cross along the x axis from the origin to x = 1.
        assert!(case([1.0, 0.0, -1.0], [1.0, 0.0, 1.0]));
        // g around -x: they touch at the shared vertex only.
        assert!(!case([-1.0, 0.0, -1.0], [-1.0, 0.0, 1.0]));
        // g wholly above f's plane.
        assert!(!case([1.0, 0.0, 1.0], [1.0, 1.0, 1.0]));
        // g's edge from the origin lies in f's plane inside f's wedge.
        assert!(case([1.0, 0.0, 0.0], [1.0, 0.0, 1.0]));
        // ... or outside it.
        assert!(!case([-1.0, 0.5, 0.0], [1.0, 0.0, 1.0]));
        // Nearly coplanar and crossing: g tilted by 1e-12 about the x axis, wedge inside f's.
        assert!(case([1.0, -0.1, -1e-12], [1.0, 0.1, 1e-12]));
    }

    #[test]
    fn coplanar_faces() {
        let base = [[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [0.0, 2.0, 0.0]];
        let with = |extra: &[[f64; 3]]| {
            let mut v = base.to_vec();
            v.extend_from_slice(extra);
            v
        };
        // Sharing nothing: overlapping, apart, touching at a point.
        let v = with(&[[0.5, 0.5, 0.0], [3.0, 0.5, 0.0], [0.5, 3.0, 0.0]]);
        assert!(meet(&v, [3, 4, 5]));
        let v = with(&[[3.0, 3.0, 0.0], [5.0, 3.0, 0.0], [3.0, 5.0, 0.0]]);
        assert!(!meet(&v, [3, 4, 5]));
        let v = with(&[[1.0, 1.0, 0.0], [3.0, 1.0, 0.0], [3.0, 3.0, 0.0]]);
        assert!(meet(&v, [3, 4, 5]));
        // Sharing an edge: folded onto f, or unfolded.
        let v = with(&[[1.0, 0.5, 0.0]]);
        assert!(meet(&v, [1, 0, 3]));
        let v = with(&[[1.0, -0.5, 0.0]]);
        assert!(!meet(&v, [1, 0, 3]));
        // Sharing a vertex: wedges overlapping, or apart.
        let v = with(&[[3.0, 0.5, 0.0], [0.5, 3.0, 0.0]]);
        assert!(meet(&v, [0, 3, 4]));
        let v = with(&[[-1.0, 0.0, 0.0], [-1.0, -1.0, 0.0]]);
        assert!(!meet(&v, [0, 3, 4]));
        // Off the axis planes: a tilted plane through exactly representable points.
        let p = |x: f64, y: f64| [x, y, 0.5 * x + 0.25 * y];
        let v = vec![
            p(0.0, 0.0),
            p(2.0, 0.0),
            p(0.0, 2.0),
            p(0.5, 0.5),
            p(3.0, 0.5),
            p(0.5, 3.0),
        ];
        assert!(meet(&v, [3, 4, 5]));
    }

    #[test]
    fn faces_sharing_nothing_or_an_edge() {
        let f = [[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [0.0, 2.0, 0.0]];
        let with = |extra: &[[f64; 3]]| {
            let mut v = f.to_vec();
            v.extend_from_slice(extra);
            v
        };
        // A face piercing f, one passing beside it, one touching it with a vertex.
        let v = with(&[[0.5, 0.5, -1.0], [0.5, 0.5, 1.0], [0.6, 0.4, 1.0]]);
        assert!(meet(&v, [3, 4, 5]));
        let v = with(&[[3.0, 3.0, -1.0], [3.0, 3.0, 1.0], [3.1, 2.9, 1.0]]);
        assert!(!meet(&v, [3, 4, 5]));
        let v = with(&[[0.5, 0.5, 0.0], [0.5, 0.5, 1.0], [0.6, 0.4, 1.0]]);
        assert!(meet(&v, [3, 4, 5]));
        // An edge of g lying in f's plane across f.
        let v = with(&[[-1.0, 0.5, 0.0], [3.0, 0.5, 0.0], [1.0, 0.5, 1.0]]);
        assert!(meet(&v, [3, 4, 5]));
        // Sharing an edge at a dihedral angle: they meet on the edge only.
        let v = with(&[[1.0, -0.5, 1.0]]);
        assert!(!meet(&v, [1, 0, 3]));
    }
}
