//! The host-side writer (feature `alloc`): turns plain Rust data into a bank, then validates its
//! own output with the reader, so it never hands out a bank the firmware would reject.

use crate::error::BankError;
use crate::law::TissueLaw;
use crate::layout::{
    BankHeader, BankMeta, CANDIDATE_WIDEN_CELLS, CKL16_EXP_MAX, CKL16_EXP_MIN, Ckl16,
    DeviceCalibration, GravityCompensation, GridHeader, HEADER_LEN, MAGIC, MAX_NODES,
    MAX_TRIANGLES, OCCUPIED_WIDEN_CELLS, Precision, Relaxation, SECTION_ALIGN, SECTION_ENTRY_LEN,
    SampleHeader, SectionEntry, SectionKind, TrianglePlane, VERSION_MAJOR, VERSION_MINOR, reseal,
};
use crate::reader::{Bank, cell_of, triangle_cells};
use alloc::collections::BTreeMap;
use alloc::vec;
use alloc::vec::Vec;
use core::fmt;

/// Relative tolerance for the input's own symmetry: `C_kk` against its transpose, and the two
/// directions of a coupling given twice.
pub const INPUT_SYMMETRY_REL: f64 = 1.0e-6;

/// Everything a bank holds, as plain host data. Node `k` of R is entry `k` of every per-node
/// vector. All quantities SI (m, N, m/N).
#[derive(Clone, Debug)]
pub struct BankBuilder {
    /// Node positions, m.
    pub positions_m: Vec<[f64; 3]>,
    /// Node id in the host mesh, per node.
    pub mesh_ids: Vec<u32>,
    /// R's surface triangles as node indices, counter-clockwise seen from outside.
    pub triangles: Vec<[u32; 3]>,
    /// `C_kk` per node, m/N (symmetric; stored symmetrised).
    pub c_kk: Vec<[[f64; 3]; 3]>,
    /// Couplings `(k, l, C_kl)`, `k != l`, m/N. Each unordered pair once or in both directions
    /// (then `C_lk` must equal `C_kl^T`); the bank stores one block per pair.
    pub couplings: Vec<(u32, u32, [[f64; 3]; 3])>,
    /// Edge of the collision grid's cubic cells, m (e.g. the mean surface edge length). Any size
    /// finds every contact (the cell certificates are structural); flash cost: 9 bytes per cell
    /// of the bounding box plus 2 per candidate entry, which grow as cells shrink, while larger
    /// cells give longer candidate lists to test per tick.
    pub grid_cell_size_m: f64,
    /// Truncation radius, m: every pair of nodes closer than this must be in `couplings`.
    pub truncation_radius_m: f64,
    /// Opaque scene identity (e.g. a hash of the scene file).
    pub scene_id: u64,
    /// The tissue force law Q.
    pub law: TissueLaw,
    /// Device calibration.
    pub device: DeviceCalibration,
    /// Gravity compensation of the instrument's weight; `None` writes no gravity section (no
    /// compensation).
    pub gravity: Option<GravityCompensation>,
    /// The viscoelastic relaxation (`SPEC.md`, "viscoelastic relaxation"); `None` writes none
    /// (the firmware renders the elastic force).
    pub relaxation: Option<Relaxation>,
    /// The tool's patch compliance sampled over R (`SPEC.md`, "contact samples"); `None`
    /// writes none (the firmware then renders contacts from the nodal compliance).
    pub samples: Option<ContactSamples>,
}

/// The contact samples a [`BankBuilder`] writes: per triangle a lattice of `level` steps per
/// side ([`crate::lattice_index`] order), each point naming one of `w`; triangles that share
/// an edge must name the same samples along it (the reader checks it).
#[derive(Clone, Debug, PartialEq)]
pub struct ContactSamples {
    /// Lattice steps per triangle side, `1..=`[`crate::MAX_SAMPLE_LEVEL`].
    pub level: u32,
    /// The tool radius the samples were computed for, m.
    pub tip_radius_m: f64,
    /// Per triangle, in [`BankBuilder::triangles`]' order, [`crate::lattice_len`]`(level)`
    /// indices into `w`.
    pub triangle_samples: Vec<Vec<u32>>,
    /// The patch compliance `W` of each sample, m/N, symmetric (stored symmetrised).
    pub w: Vec<[[f64; 3]; 3]>,
}

/// Why [`BankBuilder::build`] refused its input.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum BuildError {
    /// A per-node vector's length differs from `positions_m`'s.
    LengthMismatch {
        /// `"mesh_ids"` or `"c_kk"`.
        field: &'static str,
    },
    /// A triangle or coupling names a node that does not exist.
    IndexOutOfRange {
        /// `"triangles"` or `"couplings"`.
        field: &'static str,
        /// Entry of that vector.
        entry: usize,
    },
    /// A coupling with `k == l`.
    SelfCoupling {
        /// Entry of `couplings`.
        entry: usize,
    },
    /// `C_kk` of this node is not symmetric.
    AsymmetricCkk {
        /// Node.
        node: usize,
    },
    /// A pair given in both directions with `C_lk != C_kl^T` (or twice with different values).
    InconsistentCoupling {
        /// Entry of `couplings`.
        entry: usize,
    },
    /// Grid cell size not positive, or the grid would exceed 65535 cells along an axis or
    /// `u32::MAX` cells in all.
    Grid,
    /// The bank would exceed 4 GiB.
    TooLarge,
    /// A coupling block too large (or not finite) for the 16-bit storage's exponent.
    BlockRange {
        /// Smaller node of the pair.
        k: u16,
        /// Larger node.
        l: u16,
    },
    /// A CSR section has more items than its `u16` starts can count (65535; only the grid
    /// starts are `u16`, and they count at most the 65535 nodes).
    TooManyItems {
        /// The section whose items overflow.
        section: SectionKind,
        /// Items it would hold.
        count: usize,
    },
    /// The contact samples do not fit the triangles (`what` says how).
    Samples {
        /// What is wrong.
        what: &'static str,
    },
    /// The output fails the reader's validation (the input breaks a format rule).
    Rejected(BankError),
}

impl fmt::Display for BuildError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            BuildError::LengthMismatch { field } => {
                write!(f, "{field} must have one entry per node")
            }
            BuildError::IndexOutOfRange { field, entry } => {
                write!(f, "{field}[{entry}] names a node that does not exist")
            }
            BuildError::SelfCoupling { entry } => write!(f, "couplings[{entry}] has k == l"),
            BuildError::AsymmetricCkk { node } => write!(f, "C_kk of node {node} not symmetric"),
            BuildError::InconsistentCoupling { entry } => {
                write!(
                    f,
                    "couplings[{entry}] disagrees with the same pair given before"
                )
            }
            BuildError::Grid => f.write_str("grid cell size invalid or grid too large"),
            BuildError::TooLarge => f.write_str("bank larger than 4 GiB"),
            BuildError::BlockRange { k, l } => {
                write!(
                    f,
                    "C_kl of pair ({k}, {l}) out of the 16-bit storage's range"
                )
            }
            BuildError::TooManyItems { section, count } => write!(
                f,
                "{section}: {count} items, more than the 65535 its u16 starts can count"
            ),
            BuildError::Samples { what } => write!(f, "contact samples: {what}"),
            BuildError::Rejected(e) => write!(f, "bank rejected by the reader: {e}"),
        }
    }
}

impl core::error::Error for BuildError {}

impl From<BankError> for BuildError {
    fn from(e: BankError) -> Self {
        BuildError::Rejected(e)
    }
}

/// Bytes stored with 8-byte alignment (a `Vec<u8>` promises only 1), so a bank read from a file
/// or built in memory can be handed to [`Bank::parse`].
#[derive(Clone, Debug, Default)]
pub struct AlignedBytes {
    words: Vec<u64>,
    len: usize,
}

impl AlignedBytes {
    /// Copy `bytes` into aligned storage.
    pub fn new(bytes: &[u8]) -> AlignedBytes {
        let mut words = vec![0u64; bytes.len().div_ceil(8)];
        let dst: &mut [u8] = bytemuck::cast_slice_mut(&mut words);
        if let Some(d) = dst.get_mut(..bytes.len()) {
            d.copy_from_slice(bytes);
        }
        AlignedBytes {
            words,
            len: bytes.len(),
        }
    }

    /// The bytes.
    pub fn as_slice(&self) -> &[u8] {
        let all: &[u8] = bytemuck::cast_slice(&self.words);
        all.get(..self.len).unwrap_or(&[])
    }

    /// The bytes, mutable (for tools that patch a bank; see [`crate::reseal`]).
    pub fn as_mut_slice(&mut self) -> &mut [u8] {
        let all: &mut [u8] = bytemuck::cast_slice_mut(&mut self.words);
        all.get_mut(..self.len).unwrap_or(&mut [])
    }
}

impl core::ops::Deref for AlignedBytes {
    type Target = [u8];
    fn deref(&self) -> &[u8] {
        self.as_slice()
    }
}

fn f32s<const N: usize>(a: [f64; N]) -> [f32; N] {
    a.map(|v| v as f32)
}

fn transpose(m: &[[f64; 3]; 3]) -> [[f64; 3]; 3] {
    let mut t = [[0.0; 3]; 3];
    for (i, row) in m.iter().enumerate() {
        for (j, v) in row.iter().enumerate() {
            t[j][i] = *v;
        }
    }
    t
}

fn max_abs(m: &[[f64; 3]; 3]) -> f64 {
    m.iter().flatten().fold(0.0f64, |a, v| a.max(v.abs()))
}

fn close(a: &[[f64; 3]; 3], b: &[[f64; 3]; 3]) -> bool {
    let tol = INPUT_SYMMETRY_REL * max_abs(a).max(max_abs(b));
    a.iter()
        .flatten()
        .zip(b.iter().flatten())
        .all(|(x, y)| (x - y).abs() <= tol)
}

/// `2^e` in f64 (`e` within the normal range).
fn pow2(e: i32) -> f64 {
    f64::from_bits(((e + 1023) as u64) << 52)
}

/// `x` rounded to the nearest integer, halves away from zero (`|x| < 2^52`; no libm).
fn round_i(x: f64) -> i64 {
    if x >= 0.0 {
        (x + 0.5) as i64
    } else {
        -((-x + 0.5) as i64)
    }
}

/// Block floating point (`SPEC.md`, "16-bit blocks"): the smallest exponent e >=
/// [`CKL16_EXP_MIN`] with `round(max |c| / 2^e) <= 32767`, and the mantissas `round(c / 2^e)`,
/// so each entry is off by at most `2^(e-1) <= max |c| / 32767`. `None` for a block too large
/// for [`CKL16_EXP_MAX`] or not finite.
pub fn encode_ckl16(c: &[[f64; 3]; 3]) -> Option<Ckl16> {
    if !c.iter().flatten().all(|v| v.is_finite()) {
        return None;
    }
    let max = max_abs(c);
    let limit = f64::from(i16::MAX);
    let mut e = i32::from(CKL16_EXP_MIN);
    if max > 0.0 {
        // max < 2^(x + 1) for its binary exponent x, so e = x - 14 gives max / 2^e < 2^15;
        // x - 15 would give >= 2^15: e = x - 14 is the smallest unless rounding reaches 32768.
        let x = ((max.to_bits() >> 52) & 0x7ff) as i32 - 1023;
        e = e.max(x - 14);
        while round_i(max / pow2(e)) > i64::from(i16::MAX) {
            e += 1;
        }
    }
    if e > i32::from(CKL16_EXP_MAX) || max / pow2(e) > limit + 0.5 {
        return None;
    }
    let scale = pow2(e);
    let mut mantissa = [0i16; 9];
    for (m, v) in mantissa.iter_mut().zip(c.iter().flatten()) {
        *m = i16::try_from(round_i(v / scale)).ok()?;
    }
    Some(Ckl16 {
        mantissa,
        exponent: e as i16,
    })
}

/// The plane of the triangle with stored (f32) vertices `a`, `b`, `c` as the writer stores it
/// (`SPEC.md`, "triangle planes"): in f64 `n = (b - a) x (c - a)` and `m = n / (n . n)`, rounded
/// to f32; then `off = m . a` in f64 from the rounded `m`, rounded. A zero-area triangle has no
/// plane: it gets all zeros, which the reader rejects (`BankError::TrianglePlane`).
pub fn triangle_plane(a: [f32; 3], b: [f32; 3], c: [f32; 3]) -> TrianglePlane {
    let [a, b, c] = [a, b, c].map(|v| v.map(f64::from));
    let (u, v) = (
        [b[0] - a[0], b[1] - a[1], b[2] - a[2]],
        [c[0] - a[0], c[1] - a[1], c[2] - a[2]],
    );
    let n = [
        u[1] * v[2] - u[2] * v[1],
        u[2] * v[0] - u[0] * v[2],
        u[0] * v[1] - u[1] * v[0],
    ];
    let nn = n[0] * n[0] + n[1] * n[1] + n[2] * n[2];
    if !(nn > 0.0) {
        return TrianglePlane {
            m: [0.0; 3],
            off: 0.0,
        };
    }
    let m = n.map(|x| (x / nn) as f32);
    let off = (0..3).map(|i| f64::from(m[i]) * a[i]).sum::<f64>() as f32;
    TrianglePlane { m, off }
}

impl BankBuilder {
    /// Write the bank with `C_kl` in f32 ([`BankBuilder::build_with_precision`]).
    pub fn build(&self) -> Result<Vec<u8>, BuildError> {
        self.build_with_precision(Precision::F32)
    }

    /// Write the bank, its coupling blocks in `precision` (`C_kk` is always f32). Fails on
    /// malformed input, and on any input the reader rejects.
    pub fn build_with_precision(&self, precision: Precision) -> Result<Vec<u8>, BuildError> {
        self.build_checked(precision, true)
    }

    /// [`BankBuilder::build_with_precision`] checked by [`Bank::parse_unbounded`]: a bank for
    /// the host's own use that may exceed the firmware's tick limits (the tool-coupling probe).
    pub fn build_unbounded(&self, precision: Precision) -> Result<Vec<u8>, BuildError> {
        self.build_checked(precision, false)
    }

    fn build_checked(
        &self,
        precision: Precision,
        tick_limits: bool,
    ) -> Result<Vec<u8>, BuildError> {
        let n = self.positions_m.len();
        if self.mesh_ids.len() != n {
            return Err(BuildError::LengthMismatch { field: "mesh_ids" });
        }
        if self.c_kk.len() != n {
            return Err(BuildError::LengthMismatch { field: "c_kk" });
        }
        if n == 0 || n > MAX_NODES {
            return Err(BankError::NodeCount {
                count: u32::try_from(n).unwrap_or(u32::MAX),
            }
            .into());
        }
        let positions: Vec<[f32; 3]> = self.positions_m.iter().map(|p| f32s(*p)).collect();

        // Triangles and node -> triangle adjacency (ascending by construction).
        let mut triangles = Vec::with_capacity(self.triangles.len());
        if self.triangles.len() > MAX_TRIANGLES {
            return Err(BankError::TriangleCount {
                count: u32::try_from(self.triangles.len()).unwrap_or(u32::MAX),
            }
            .into());
        }
        let mut node_tris: Vec<Vec<u16>> = vec![Vec::new(); n];
        for (t, tri) in self.triangles.iter().enumerate() {
            let mut out = [0u16; 3];
            for (o, &v) in out.iter_mut().zip(tri) {
                *o = u16::try_from(v)
                    .ok()
                    .filter(|&v| usize::from(v) < n)
                    .ok_or(BuildError::IndexOutOfRange {
                        field: "triangles",
                        entry: t,
                    })?;
            }
            triangles.push(out);
            let t = u16::try_from(t).map_err(|_| BuildError::TooLarge)?;
            for v in out {
                match node_tris.get_mut(usize::from(v)) {
                    Some(list) if list.last() != Some(&t) => list.push(t),
                    _ => {}
                }
            }
        }
        let (node_tri_starts, node_tri_items) = csr(&node_tris)?;
        let planes: Vec<TrianglePlane> = triangles
            .iter()
            .map(|tri| {
                let [a, b, c] = tri.map(|k| positions[usize::from(k)]);
                triangle_plane(a, b, c)
            })
            .collect();

        // Grid: origin half a cell below the smallest coordinate, dims from the largest.
        let h = self.grid_cell_size_m as f32;
        if !(h > 0.0 && h.is_finite()) {
            return Err(BuildError::Grid);
        }
        let mut grid = GridHeader {
            origin_m: [0.0; 3],
            cell_size_m: h,
            dims: [0; 3],
            reserved: 0,
        };
        for axis in 0..3 {
            let lo = positions
                .iter()
                .map(|p| p[axis])
                .fold(f32::INFINITY, f32::min);
            let hi = positions
                .iter()
                .map(|p| p[axis])
                .fold(f32::NEG_INFINITY, f32::max);
            let origin = lo - 0.5 * h;
            let top = (hi - origin) / h;
            if !(0.0..65534.0).contains(&top) {
                return Err(BuildError::Grid);
            }
            grid.origin_m[axis] = origin;
            grid.dims[axis] = top as u16 + 1;
        }
        let cells: u64 = grid.dims.iter().map(|&d| u64::from(d)).product();
        if cells >= u64::from(u32::MAX) {
            return Err(BuildError::Grid);
        }
        let mut buckets: Vec<Vec<u16>> = vec![Vec::new(); cells as usize];
        for (k, p) in positions.iter().enumerate() {
            let [i, j, l] = cell_of(&grid, *p).ok_or(BuildError::Grid)?;
            let [nx, ny, _] = grid.dims.map(usize::from);
            let c = usize::from(i) + nx * (usize::from(j) + ny * usize::from(l));
            buckets.get_mut(c).ok_or(BuildError::Grid)?.push(k as u16);
        }
        let (grid_starts, grid_items) = csr16(&buckets, SectionKind::GridItems)?;
        let (clearance, cell_tri_starts, cell_tri_items) =
            cell_certificates(&grid, &positions, &triangles, cells as usize)?;

        // Self-compliance, symmetrised.
        let mut ckk = Vec::with_capacity(n);
        for (k, c) in self.c_kk.iter().enumerate() {
            if !close(c, &transpose(c)) {
                return Err(BuildError::AsymmetricCkk { node: k });
            }
            let s = |i: usize, j: usize| (0.5 * (c[i][j] + c[j][i])) as f32;
            ckk.push([s(0, 0), s(0, 1), s(0, 2), s(1, 1), s(1, 2), s(2, 2)]);
        }

        // Couplings: one canonical block per unordered pair (k < l), stored once in k's row;
        // the index lists both directions.
        let mut pairs: BTreeMap<(u16, u16), [[f64; 3]; 3]> = BTreeMap::new();
        for (e, (k, l, c)) in self.couplings.iter().enumerate() {
            let idx = |v: u32| {
                u16::try_from(v).ok().filter(|&v| usize::from(v) < n).ok_or(
                    BuildError::IndexOutOfRange {
                        field: "couplings",
                        entry: e,
                    },
                )
            };
            let (k, l) = (idx(*k)?, idx(*l)?);
            if k == l {
                return Err(BuildError::SelfCoupling { entry: e });
            }
            let (key, block) = if k < l {
                ((k, l), *c)
            } else {
                ((l, k), transpose(c))
            };
            match pairs.get(&key) {
                Some(prev) if !close(prev, &block) => {
                    return Err(BuildError::InconsistentCoupling { entry: e });
                }
                Some(_) => {}
                None => {
                    pairs.insert(key, block);
                }
            }
        }
        let mut nb_lists: Vec<Vec<u16>> = vec![Vec::new(); n];
        let mut blocks: Vec<Vec<[f32; 9]>> = vec![Vec::new(); n];
        let mut blocks16: Vec<Vec<Ckl16>> = vec![Vec::new(); n];
        // BTreeMap order: by k, then l ascending, so each row's blocks come in index order.
        for (&(a, b), c) in &pairs {
            let m: [f32; 9] = [
                c[0][0], c[0][1], c[0][2], c[1][0], c[1][1], c[1][2], c[2][0], c[2][1], c[2][2],
            ]
            .map(|v| v as f32);
            match precision {
                Precision::F32 => {
                    if let Some(r) = blocks.get_mut(usize::from(a)) {
                        r.push(m);
                    }
                }
                Precision::Bfp16 => {
                    let q = encode_ckl16(c).ok_or(BuildError::BlockRange { k: a, l: b })?;
                    if let Some(r) = blocks16.get_mut(usize::from(a)) {
                        r.push(q);
                    }
                }
            }
            for (row, other) in [(a, b), (b, a)] {
                if let Some(r) = nb_lists.get_mut(usize::from(row)) {
                    r.push(other);
                }
            }
        }
        for r in &mut nb_lists {
            r.sort_unstable();
        }
        let (nb_starts, nb_index) = csr(&nb_lists)?;
        let (coupling_starts, nb_ckl) = csr(&blocks)?;
        let (coupling_starts16, nb_ckl16) = csr(&blocks16)?;

        let meta = BankMeta {
            scene_id: [self.scene_id as u32, (self.scene_id >> 32) as u32],
            truncation_radius_m: self.truncation_radius_m as f32,
            reserved: 0,
        };
        let law = self.law.to_record();

        // Lay out: header, table, then the sections in REQUIRED order, 8-aligned.
        let mut body = Sink::default();
        body.push(SectionKind::Meta, bytemuck::bytes_of(&meta), 1)?;
        body.push_slice(SectionKind::Positions, &positions)?;
        body.push_slice(SectionKind::MeshIds, &self.mesh_ids)?;
        body.push_slice(SectionKind::Triangles, &triangles)?;
        body.push_slice(SectionKind::TrianglePlanes, &planes)?;
        body.push_slice(SectionKind::NodeTriStarts, &node_tri_starts)?;
        body.push_slice(SectionKind::NodeTriItems, &node_tri_items)?;
        body.push(SectionKind::Grid, bytemuck::bytes_of(&grid), 1)?;
        body.push_slice(SectionKind::GridStarts, &grid_starts)?;
        body.push_slice(SectionKind::GridItems, &grid_items)?;
        body.push_slice(SectionKind::CellClearance, &clearance)?;
        body.push_slice(SectionKind::CellTriStarts, &cell_tri_starts)?;
        body.push_slice(SectionKind::CellTriItems, &cell_tri_items)?;
        body.push_slice(SectionKind::Ckk, &ckk)?;
        body.push_slice(SectionKind::NeighbourStarts, &nb_starts)?;
        body.push_slice(SectionKind::NeighbourIndex, &nb_index)?;
        match precision {
            Precision::F32 => {
                body.push_slice(SectionKind::NeighbourCkl, &nb_ckl)?;
                body.push_slice(SectionKind::CouplingStarts, &coupling_starts)?;
            }
            Precision::Bfp16 => {
                body.push_slice(SectionKind::NeighbourCkl16, &nb_ckl16)?;
                body.push_slice(SectionKind::CouplingStarts, &coupling_starts16)?;
            }
        }
        body.push(SectionKind::TissueLaw, bytemuck::bytes_of(&law), 1)?;
        body.push(SectionKind::Device, bytemuck::bytes_of(&self.device), 1)?;
        if let Some(gravity) = &self.gravity {
            body.push(SectionKind::Gravity, bytemuck::bytes_of(gravity), 1)?;
        }
        if let Some(relaxation) = &self.relaxation {
            body.push(SectionKind::Relaxation, bytemuck::bytes_of(relaxation), 1)?;
        }
        if let Some(samples) = &self.samples {
            let (header, ids, w) = samples.sections(triangles.len())?;
            body.push(SectionKind::SampleHeader, bytemuck::bytes_of(&header), 1)?;
            body.push_slice(SectionKind::TriangleSamples, &ids)?;
            body.push_slice(SectionKind::PatchCompliance, &w)?;
        }

        let table_len = SECTION_ENTRY_LEN * body.table.len();
        let data_start = HEADER_LEN + table_len;
        let total = data_start + body.data.len();
        let total_u32 = u32::try_from(total).map_err(|_| BuildError::TooLarge)?;
        let header = BankHeader {
            magic: MAGIC,
            version_major: VERSION_MAJOR,
            version_minor: VERSION_MINOR,
            header_len: HEADER_LEN as u16,
            section_count: body.table.len() as u16,
            total_len: total_u32,
            crc32: 0,
            flags: 0,
            reserved: 0,
        };
        let mut out = Vec::with_capacity(total);
        out.extend_from_slice(bytemuck::bytes_of(&header));
        for e in &body.table {
            let shifted = SectionEntry {
                offset: e
                    .offset
                    .checked_add(data_start as u32)
                    .ok_or(BuildError::TooLarge)?,
                ..*e
            };
            out.extend_from_slice(bytemuck::bytes_of(&shifted));
        }
        out.extend_from_slice(&body.data);
        reseal(&mut out);

        // The writer's output must satisfy the reader.
        let aligned = AlignedBytes::new(&out);
        if tick_limits {
            Bank::parse(&aligned)?;
        } else {
            Bank::parse_unbounded(&aligned)?;
        }
        Ok(out)
    }
}

/// The lattice points of a triangle mesh at `level` steps per side, each point once: a point
/// on an edge or a vertex that several triangles share gets one sample, so that the samples
/// are continuous across edges (`SPEC.md`, "contact samples").
#[derive(Clone, Debug, PartialEq)]
pub struct SharedLattice {
    /// Per triangle, [`crate::lattice_len`]`(level)` point indices, [`crate::lattice_index`]
    /// order ([`ContactSamples::triangle_samples`]).
    pub triangle_points: Vec<Vec<u32>>,
    /// Per point, one triangle holding it and its barycentric coordinates there.
    pub points: Vec<(usize, [f64; 3])>,
}

impl SharedLattice {
    /// The shared lattice of `triangles` (node indices) at `level` steps per side.
    pub fn new(triangles: &[[u32; 3]], level: u32) -> SharedLattice {
        let level = level.max(1);
        let mut ids: BTreeMap<[(u32, u32); 3], u32> = BTreeMap::new();
        let mut points = Vec::new();
        let mut triangle_points = Vec::with_capacity(triangles.len());
        for (t, tri) in triangles.iter().enumerate() {
            let mut mine = Vec::with_capacity(crate::lattice_len(level));
            for j in 0..=level {
                for i in 0..=level - j {
                    // The point as integer weights on the mesh's vertices, sorted: the same
                    // key from every triangle that holds it.
                    let mut key = [(tri[0], level - i - j), (tri[1], i), (tri[2], j)]
                        .map(|(v, w)| if w == 0 { (u32::MAX, 0) } else { (v, w) });
                    key.sort_unstable();
                    let next = ids.len() as u32;
                    let id = *ids.entry(key).or_insert_with(|| {
                        points.push((t, crate::lattice_bary(i, j, level)));
                        next
                    });
                    mine.push(id);
                }
            }
            triangle_points.push(mine);
        }
        SharedLattice {
            triangle_points,
            points,
        }
    }
}

/// The contact samples' three sections: header, flat sample indices, samples.
type SampleSections = (SampleHeader, Vec<u16>, Vec<[f32; 6]>);

impl ContactSamples {
    /// The three sections' contents for `triangles` triangles: header, flat `u16` indices,
    /// symmetrised f32 samples.
    fn sections(&self, triangles: usize) -> Result<SampleSections, BuildError> {
        let bad = |what| Err(BuildError::Samples { what });
        if !(1..=crate::MAX_SAMPLE_LEVEL).contains(&self.level) {
            return bad("level not in 1..=MAX_SAMPLE_LEVEL");
        }
        if self.triangle_samples.len() != triangles {
            return bad("one lattice per triangle is needed");
        }
        if self.w.len() > usize::from(u16::MAX) + 1 {
            return bad("more than 65536 samples");
        }
        let len = crate::lattice_len(self.level);
        let mut ids = Vec::with_capacity(triangles * len);
        for tri in &self.triangle_samples {
            if tri.len() != len {
                return bad("a triangle's lattice has the wrong number of points");
            }
            for &s in tri {
                match u16::try_from(s) {
                    Ok(s) if usize::from(s) < self.w.len() => ids.push(s),
                    _ => return bad("a lattice point names a sample that does not exist"),
                }
            }
        }
        let mut w = Vec::with_capacity(self.w.len());
        for c in &self.w {
            if !close(c, &transpose(c)) {
                return bad("a sample is not symmetric");
            }
            let s = |i: usize, j: usize| (0.5 * (c[i][j] + c[j][i])) as f32;
            w.push([s(0, 0), s(0, 1), s(0, 2), s(1, 1), s(1, 2), s(2, 2)]);
        }
        let header = SampleHeader {
            level: self.level,
            tip_radius_m: self.tip_radius_m as f32,
            reserved: [0; 2],
        };
        Ok((header, ids, w))
    }
}

/// Clearance per cell, and the CSR (starts, items) of the candidate triangles.
type CellCertificates = (Vec<u8>, Vec<u32>, Vec<u16>);

/// The per-cell contact certificates (`SPEC.md`, "cell clearance" and "cell candidates"): the
/// clearance (the exact Chebyshev distance, in cells, to the nearest occupied cell, by a
/// two-pass chamfer transform, capped at 255) and the CSR candidate lists.
fn cell_certificates(
    grid: &GridHeader,
    positions: &[[f32; 3]],
    triangles: &[[u16; 3]],
    cells: usize,
) -> Result<CellCertificates, BuildError> {
    let [nx, ny, nz] = grid.dims.map(usize::from);
    let index = |x: usize, y: usize, z: usize| x + nx * (y + ny * z);
    let mut lists: Vec<Vec<u16>> = vec![Vec::new(); cells];
    let mut dist: Vec<u16> = vec![u16::MAX; cells];
    for (t, &tri) in triangles.iter().enumerate() {
        let (lo, hi) = triangle_cells(grid, positions, tri, CANDIDATE_WIDEN_CELLS).ok_or(
            BuildError::IndexOutOfRange {
                field: "triangles",
                entry: t,
            },
        )?;
        for z in lo[2]..=hi[2] {
            for y in lo[1]..=hi[1] {
                for x in lo[0]..=hi[0] {
                    let c = index(usize::from(x), usize::from(y), usize::from(z));
                    lists.get_mut(c).ok_or(BuildError::Grid)?.push(t as u16);
                }
            }
        }
        let (lo, hi) =
            triangle_cells(grid, positions, tri, OCCUPIED_WIDEN_CELLS).ok_or(BuildError::Grid)?;
        for z in lo[2]..=hi[2] {
            for y in lo[1]..=hi[1] {
                for x in lo[0]..=hi[0] {
                    let c = index(usize::from(x), usize::from(y), usize::from(z));
                    *dist.get_mut(c).ok_or(BuildError::Grid)? = 0;
                }
            }
        }
    }
    // Chamfer transform for the Chebyshev distance: a forward pass over the 13 neighbours that
    // precede a cell, a backward pass over the 13 that follow it.
    for pass in 0..2 {
        for i in 0..cells {
            let c = if pass == 0 { i } else { cells - 1 - i };
            let (x, y, z) = (c % nx, (c / nx) % ny, c / (nx * ny));
            let mut best = dist[c];
            for dz in -1i64..=1 {
                for dy in -1i64..=1 {
                    for dx in -1i64..=1 {
                        let d = dx + 3 * (dy + 3 * dz);
                        if (pass == 0 && d >= 0) || (pass == 1 && d <= 0) {
                            continue;
                        }
                        let (qx, qy, qz) = (x as i64 + dx, y as i64 + dy, z as i64 + dz);
                        if qx < 0 || qy < 0 || qz < 0 {
                            continue;
                        }
                        let (qx, qy, qz) = (qx as usize, qy as usize, qz as usize);
                        if qx >= nx || qy >= ny || qz >= nz {
                            continue;
                        }
                        best = best.min(dist[index(qx, qy, qz)].saturating_add(1));
                    }
                }
            }
            dist[c] = best;
        }
    }
    let clearance = dist.iter().map(|&d| d.min(255) as u8).collect();
    let (starts, items) = csr(&lists)?;
    Ok((clearance, starts, items))
}

/// CSR (starts, items) of per-row lists.
fn csr<T: Copy>(rows: &[Vec<T>]) -> Result<(Vec<u32>, Vec<T>), BuildError> {
    let mut starts = Vec::with_capacity(rows.len() + 1);
    let mut items = Vec::new();
    starts.push(0u32);
    for r in rows {
        items.extend_from_slice(r);
        starts.push(u32::try_from(items.len()).map_err(|_| BuildError::TooLarge)?);
    }
    Ok((starts, items))
}

/// CSR (starts, items) of per-row lists with `u16` starts; `section` names the items in the
/// error when they are more than 65535.
fn csr16<T: Copy>(rows: &[Vec<T>], section: SectionKind) -> Result<(Vec<u16>, Vec<T>), BuildError> {
    let (starts, items) = csr(rows)?;
    let count = items.len();
    let starts = starts
        .into_iter()
        .map(u16::try_from)
        .collect::<Result<Vec<u16>, _>>()
        .map_err(|_| BuildError::TooManyItems { section, count })?;
    Ok((starts, items))
}

/// Section data being laid out (offsets relative to the end of the section table).
#[derive(Default)]
struct Sink {
    data: Vec<u8>,
    table: Vec<SectionEntry>,
}

impl Sink {
    fn push(&mut self, kind: SectionKind, bytes: &[u8], count: usize) -> Result<(), BuildError> {
        let offset = u32::try_from(self.data.len()).map_err(|_| BuildError::TooLarge)?;
        let len = u32::try_from(bytes.len()).map_err(|_| BuildError::TooLarge)?;
        let count = u32::try_from(count).map_err(|_| BuildError::TooLarge)?;
        self.data.extend_from_slice(bytes);
        self.data
            .resize(self.data.len().next_multiple_of(SECTION_ALIGN), 0);
        self.table.push(SectionEntry {
            kind: kind.code(),
            offset,
            len,
            count,
        });
        Ok(())
    }

    fn push_slice<T: bytemuck::Pod>(
        &mut self,
        kind: SectionKind,
        items: &[T],
    ) -> Result<(), BuildError> {
        self.push(kind, bytemuck::cast_slice(items), items.len())
    }
}
