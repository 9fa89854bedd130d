//! The displayed deformation: `u = C[:, S] f_S` on the display nodes (the paper's superposition,
//! eq. 9, written with the compliance: the contact forces `f_S` the device reports replace the
//! modified constraints `u~*`, since `T^u_nk u~*_k = C_nk f_k`). The display law P is applied
//! afterwards, for either contact model ([`crate::display::law`]).
//!
//! Memory: a dense `C[display, R]` is gigabytes for a 100k-node organ, so columns are produced on
//! demand from the kept factorisation: one batched solve `K_ff X = E_k` (three unit right-hand
//! sides per contact node) in a worker thread, restricted to the display rows and cached (least
//! recently used first out) while nodes stay in or near contact. The worker serves contact nodes
//! first ([`Deformer::displacement`]) and the neighbours asked for ahead of need
//! ([`Deformer::prefetch`]) only when idle, in small batches, so a prefetch never delays a
//! contact node by more than one small solve. Until a new node's columns arrive, its force is
//! carried by the nearest cached node ([`Coverage::Approximate`]): the display drops accuracy
//! for a few frames (on a 100k-node organ, about a second per batch), never frames.

use faer::{Mat, Par};
use fem::compliance::Compliance;
use std::collections::{HashMap, VecDeque};
use std::sync::Arc;
use std::sync::mpsc::{Receiver, Sender, channel};

/// Whether a displacement used every contact node's own columns.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Coverage {
    /// `u = C[:, S] f_S` exactly (to f32 rounding of the cached columns).
    Exact,
    /// Some contact node's columns were still being solved; its force was carried by the
    /// nearest cached node (or dropped when none was cached).
    Approximate,
}

/// The three columns of one contact node `k` on the display rows: `cols[9 i + 3 r + c] =
/// C(display node i, component r; k, component c)`, m/N.
struct Columns {
    cols: Arc<[f32]>,
    position: [f64; 3],
    last_used: u64,
}

/// Produces `u = C[:, S] f_S` on a fixed set of display nodes (see the module notes).
pub struct Deformer {
    display: Arc<[usize]>,
    positions: Arc<[[f64; 3]]>,
    cache: HashMap<usize, Columns>,
    capacity: usize,
    /// Requested and not yet solved, with whether the request was urgent.
    pending: HashMap<usize, bool>,
    requests: Sender<Request>,
    results: Receiver<Batch>,
    clock: u64,
    solves: SolveStats,
}

impl std::fmt::Debug for Deformer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Deformer")
            .field("display_nodes", &self.display.len())
            .field("cached", &self.cache.len())
            .field("pending", &self.pending.len())
            .finish()
    }
}

/// One batch of solved columns and the wall time it took.
struct Batch {
    columns: Vec<(usize, Arc<[f32]>)>,
    /// Prefetch requests given up.
    dropped: Vec<usize>,
    seconds: f64,
}

/// Column solves so far.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize)]
pub struct SolveStats {
    /// Batched solves run.
    pub batches: u64,
    /// Contact nodes solved (three columns each).
    pub nodes: u64,
    /// Wall time of all batches, s.
    pub seconds: f64,
    /// Longest batch, s.
    pub max_seconds: f64,
}

/// Contact nodes solved per batch at most (a contact set has at most 8 nodes).
const MAX_URGENT_BATCH: usize = 8;
/// Prefetched nodes solved per batch at most.
const MAX_PREFETCH_BATCH: usize = 2;
/// Prefetch requests kept waiting at most (the oldest are dropped: the tool has moved on).
const MAX_PREFETCH_QUEUE: usize = 32;

/// A request to the column worker.
enum Request {
    /// Needed now (contact nodes).
    Urgent(Vec<usize>),
    /// Needed soon perhaps (neighbours of the contact set).
    Prefetch(Vec<usize>),
}

/// The worker's queues: urgent first; a node asked for urgently leaves the prefetch queue.
#[derive(Default)]
struct Queues {
    urgent: VecDeque<usize>,
    prefetch: VecDeque<usize>,
    dropped: Vec<usize>,
}

impl Queues {
    fn push(&mut self, r: Request) {
        match r {
            Request::Urgent(nodes) => {
                self.prefetch.retain(|k| !nodes.contains(k));
                for k in nodes {
                    if !self.urgent.contains(&k) {
                        self.urgent.push_back(k);
                    }
                }
            }
            Request::Prefetch(nodes) => {
                self.prefetch.extend(nodes);
                while self.prefetch.len() > MAX_PREFETCH_QUEUE {
                    self.dropped.extend(self.prefetch.pop_front());
                }
            }
        }
    }

    fn is_empty(&self) -> bool {
        self.urgent.is_empty() && self.prefetch.is_empty() && self.dropped.is_empty()
    }

    /// The next batch: urgent nodes if any, else a few prefetched ones.
    fn next_batch(&mut self) -> Vec<usize> {
        let (queue, max) = if self.urgent.is_empty() {
            (&mut self.prefetch, MAX_PREFETCH_BATCH)
        } else {
            (&mut self.urgent, MAX_URGENT_BATCH)
        };
        let n = queue.len().min(max);
        queue.drain(..n).collect()
    }
}

impl Deformer {
    /// A deformer over `display` (mesh node ids) of a mesh with rest `positions`, keeping the
    /// columns of at most `capacity` contact nodes. Starts the column worker thread, which
    /// ends when the deformer is dropped.
    pub fn new(
        compliance: Arc<Compliance>,
        positions: &[[f64; 3]],
        display: Vec<usize>,
        capacity: usize,
    ) -> Deformer {
        let display: Arc<[usize]> = display.into();
        let (requests, rx) = channel::<Request>();
        let (tx, results) = channel();
        let rows = Arc::clone(&display);
        std::thread::Builder::new()
            .name("columns".into())
            .spawn(move || {
                let mut queues = Queues::default();
                loop {
                    if queues.is_empty() {
                        match rx.recv() {
                            Ok(r) => queues.push(r),
                            Err(_) => return,
                        }
                    }
                    while let Ok(r) = rx.try_recv() {
                        queues.push(r);
                    }
                    let dropped = std::mem::take(&mut queues.dropped);
                    let batch = queues.next_batch();
                    let t = std::time::Instant::now();
                    let columns = solve_columns(&compliance, &rows, &batch);
                    let seconds = t.elapsed().as_secs_f64();
                    let out = Batch {
                        columns,
                        dropped,
                        seconds,
                    };
                    if tx.send(out).is_err() {
                        return;
                    }
                }
            })
            .ok();
        Deformer {
            display,
            positions: positions.into(),
            cache: HashMap::new(),
            capacity: capacity.max(2 * MAX_URGENT_BATCH),
            pending: HashMap::new(),
            requests,
            results,
            clock: 0,
            solves: SolveStats::default(),
        }
    }

    /// Column solves so far.
    pub fn solve_stats(&self) -> SolveStats {
        self.solves
    }

    /// Number of contact nodes whose columns are cached.
    pub fn cached(&self) -> usize {
        self.cache.len()
    }

    /// Asks for the columns of `nodes` (mesh ids) ahead of need, e.g. the neighbours of the
    /// contact set while the tool slides; solved only when no contact node waits.
    pub fn prefetch(&mut self, nodes: &[usize]) {
        self.request(nodes, false);
    }

    /// Requests the columns of `nodes` not cached yet; an urgent request promotes a pending
    /// prefetch.
    fn request(&mut self, nodes: &[usize], urgent: bool) {
        self.drain();
        let missing: Vec<usize> = nodes
            .iter()
            .copied()
            .filter(|k| *k < self.positions.len() && !self.cache.contains_key(k))
            .filter(|k| match self.pending.get(k) {
                None => true,
                Some(&was_urgent) => urgent && !was_urgent,
            })
            .collect();
        if missing.is_empty() {
            return;
        }
        for &k in &missing {
            self.pending.insert(k, urgent);
        }
        // A send error means the worker is gone; the display then stays approximate.
        let _ = self.requests.send(if urgent {
            Request::Urgent(missing)
        } else {
            Request::Prefetch(missing)
        });
    }

    /// `u = C[:, S] f_S` on the display nodes, then corrected by `P` along the direction of the
    /// total force; `contacts` are (mesh node id, force on the tissue in N). Nodes out of
    /// range are ignored. Requests missing columns and does not wait for them.
    pub fn displacement(
        &mut self,
        contacts: &[(usize, [f32; 3])],
        u: &mut Vec<[f32; 3]>,
    ) -> Coverage {
        let nodes: Vec<usize> = contacts.iter().map(|c| c.0).collect();
        self.request(&nodes, true);
        self.superpose(contacts, u)
    }

    /// [`Deformer::displacement`], waiting until every contact node's columns are cached.
    pub fn displacement_exact(&mut self, contacts: &[(usize, [f32; 3])], u: &mut Vec<[f32; 3]>) {
        let nodes: Vec<usize> = contacts.iter().map(|c| c.0).collect();
        self.request(&nodes, true);
        while nodes
            .iter()
            .any(|k| *k < self.positions.len() && !self.cache.contains_key(k))
        {
            match self.results.recv() {
                Ok(batch) => self.insert(batch),
                Err(_) => break,
            }
        }
        self.superpose(contacts, u);
    }

    fn drain(&mut self) {
        while let Ok(batch) = self.results.try_recv() {
            self.insert(batch);
        }
    }

    fn insert(&mut self, batch: Batch) {
        for k in &batch.dropped {
            self.pending.remove(k);
        }
        if batch.columns.is_empty() {
            return;
        }
        self.solves.batches += 1;
        self.solves.nodes += batch.columns.len() as u64;
        self.solves.seconds += batch.seconds;
        self.solves.max_seconds = self.solves.max_seconds.max(batch.seconds);
        for (k, cols) in batch.columns {
            self.pending.remove(&k);
            self.clock += 1;
            self.cache.insert(
                k,
                Columns {
                    cols,
                    position: self.positions[k],
                    last_used: self.clock,
                },
            );
        }
        while self.cache.len() > self.capacity {
            let Some(oldest) = self
                .cache
                .iter()
                .min_by_key(|(_, c)| c.last_used)
                .map(|(&k, _)| k)
            else {
                break;
            };
            self.cache.remove(&oldest);
        }
    }

    fn superpose(&mut self, contacts: &[(usize, [f32; 3])], u: &mut Vec<[f32; 3]>) -> Coverage {
        u.clear();
        u.resize(self.display.len(), [0.0; 3]);
        let mut coverage = Coverage::Exact;
        for &(k, f) in contacts {
            if k >= self.positions.len() {
                continue;
            }
            let carrier = if self.cache.contains_key(&k) {
                Some(k)
            } else {
                coverage = Coverage::Approximate;
                self.nearest_cached(self.positions[k])
            };
            let Some(entry) = carrier.and_then(|c| self.cache.get_mut(&c)) else {
                continue;
            };
            self.clock += 1;
            entry.last_used = self.clock;
            for (v, b) in u.iter_mut().zip(entry.cols.chunks_exact(9)) {
                for r in 0..3 {
                    v[r] += b[3 * r] * f[0] + b[3 * r + 1] * f[1] + b[3 * r + 2] * f[2];
                }
            }
        }
        coverage
    }

    fn nearest_cached(&self, p: [f64; 3]) -> Option<usize> {
        let d2 = |q: [f64; 3]| (0..3).map(|i| (p[i] - q[i]).powi(2)).sum::<f64>();
        self.cache
            .iter()
            .min_by(|a, b| d2(a.1.position).total_cmp(&d2(b.1.position)))
            .map(|(&k, _)| k)
    }
}

/// Solves `K_ff X = E` for the unit loads on every free component of `nodes` in one batch and
/// keeps the display rows (fixed components give zero rows and columns).
fn solve_columns(c: &Compliance, display: &[usize], nodes: &[usize]) -> Vec<(usize, Arc<[f32]>)> {
    let dofs = c.dofs();
    let mut rhs = Mat::<f64>::zeros(dofs.free_count(), 3 * nodes.len());
    for (j, &k) in nodes.iter().enumerate() {
        for comp in 0..3 {
            if let Some(d) = dofs.free_dof(k, comp) {
                rhs[(d, 3 * j + comp)] = 1.0;
            }
        }
    }
    if dofs.free_count() > 0 {
        // Sequential: the 1 kHz loop and the display share the machine with this solve.
        c.solve_in_place(rhs.as_mut(), Par::Seq);
    }
    nodes
        .iter()
        .enumerate()
        .map(|(j, &k)| {
            let mut cols = Vec::with_capacity(9 * display.len());
            for &n in display {
                for r in 0..3 {
                    for comp in 0..3 {
                        let fixed_col = dofs.free_dof(k, comp).is_none();
                        let v = match dofs.free_dof(n, r) {
                            Some(d) if !fixed_col => rhs[(d, 3 * j + comp)] as f32,
                            _ => 0.0,
                        };
                        cols.push(v);
                    }
                }
            }
            (k, cols.into())
        })
        .collect()
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use fem::elasticity::{Elasticity, FixedSet, Material};
    use fem::mesh::structured::box_mesh;

    /// A block of soft tissue (3 kPa, nu 0.45) of `size` (m) on `cells` hexahedra of box_mesh,
    /// resting on its bottom face (z = 0 fixed): the mesh, its factorised compliance and its
    /// boundary surface. The display's tests share it.
    pub(crate) fn resting_block(
        size: [f64; 3],
        cells: [usize; 3],
    ) -> (fem::mesh::TetMesh, Arc<Compliance>, fem::mesh::Surface) {
        let mesh = box_mesh(size, cells);
        let mut fixed = FixedSet::none(mesh.nodes.len());
        fixed
            .fix_box(&mesh, [-1.0, -1.0, -1.0, 1.0, 1.0, 1e-6], [true; 3])
            .unwrap();
        let body = Elasticity::new(&mesh, Material::new(3.0e3, 0.45).unwrap()).unwrap();
        let c = Arc::new(Compliance::factorize(&body, &fixed).unwrap());
        let surface = fem::mesh::boundary(&mesh).unwrap();
        (mesh, c, surface)
    }

    /// A 40 x 20 x 20 mm block resting on its bottom face, its boundary as display nodes.
    fn block() -> (fem::mesh::TetMesh, Arc<Compliance>, Vec<usize>) {
        let (mesh, c, surface) = resting_block([0.04, 0.02, 0.02], [6, 3, 3]);
        (mesh, c, surface.nodes)
    }

    fn top_nodes(mesh: &fem::mesh::TetMesh) -> Vec<usize> {
        (0..mesh.nodes.len())
            .filter(|&i| (mesh.nodes[i][2] - 0.02).abs() < 1e-9)
            .collect()
    }

    #[test]
    fn superposed_columns_match_a_direct_solve() {
        let (mesh, c, display) = block();
        let top = top_nodes(&mesh);
        let contacts = [
            (top[5], [0.01f32, -0.02, -0.3]),
            (top[6], [0.0, 0.05, -0.2]),
            (top[12], [-0.02, 0.0, -0.1]),
        ];
        let mut d = Deformer::new(Arc::clone(&c), &mesh.nodes, display.clone(), 8);
        let mut u = Vec::new();
        d.displacement_exact(&contacts, &mut u);
        // Independent reference: one full solve K u = f with the forces as a load vector.
        let mut f = vec![0.0; 3 * mesh.nodes.len()];
        for &(k, fk) in &contacts {
            (0..3).for_each(|i| f[3 * k + i] += f64::from(fk[i]));
        }
        let reference = c.displacement(&f);
        let scale = reference.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        assert!(
            scale > 1e-4,
            "the load must visibly deform the block: {scale}"
        );
        for (i, &n) in display.iter().enumerate() {
            for r in 0..3 {
                let err = (f64::from(u[i][r]) - reference[3 * n + r]).abs();
                assert!(err <= 1e-5 * scale, "node {n} comp {r}: {err} vs {scale}");
            }
        }
        // Fixed bottom nodes do not move.
        for (i, &n) in display.iter().enumerate() {
            if mesh.nodes[n][2] < 1e-9 {
                assert_eq!(u[i], [0.0; 3]);
            }
        }
    }

    #[test]
    fn missing_columns_are_carried_by_the_nearest_cached_node_then_become_exact() {
        let (mesh, c, display) = block();
        let top = top_nodes(&mesh);
        let mut d = Deformer::new(Arc::clone(&c), &mesh.nodes, display, 16);
        let (a, b) = (top[5], top[6]);
        let f = [0.0f32, 0.0, -0.5];
        let mut ua = Vec::new();
        d.displacement_exact(&[(a, f)], &mut ua);
        // Only `a` is cached: b's force is carried by a, so the field equals a's own.
        let mut ub = Vec::new();
        let cov = d.displacement(&[(b, f)], &mut ub);
        if cov == Coverage::Approximate {
            assert_eq!(ub, ua);
        }
        d.displacement_exact(&[(b, f)], &mut ub);
        assert_eq!(d.displacement(&[(b, f)], &mut ub), Coverage::Exact);
        assert_ne!(ub, ua);
    }

    #[test]
    fn the_cache_keeps_at_most_its_capacity() {
        let (mesh, c, display) = block();
        let top = top_nodes(&mesh);
        let mut d = Deformer::new(c, &mesh.nodes, display, 16);
        let mut u = Vec::new();
        for &k in top.iter().take(20) {
            d.displacement_exact(&[(k, [0.0, 0.0, -0.1])], &mut u);
        }
        assert_eq!(d.cached(), 16);
    }

    #[test]
    fn contact_nodes_jump_the_prefetch_queue() {
        let mut q = Queues::default();
        q.push(Request::Prefetch((0..40).collect()));
        assert_eq!(
            q.dropped,
            (0..8).collect::<Vec<_>>(),
            "only the newest 32 wait"
        );
        q.push(Request::Urgent(vec![20, 100]));
        assert_eq!(q.next_batch(), vec![20, 100]);
        assert!(!q.prefetch.contains(&20));
        assert_eq!(q.next_batch(), vec![8, 9]);
    }
}
