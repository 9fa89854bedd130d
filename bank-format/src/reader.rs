//! The zero-copy reader: [`Bank::parse`] validates a bank in place and hands out typed slices
//! of it. Nothing is copied and nothing is allocated; every access is bounds-checked.

use crate::error::{BankError, DeviceField};
use crate::law::TissueLaw;
use crate::layout::{
    BANK_ALIGN, BankHeader, BankMeta, CANDIDATE_WIDEN_CELLS, CKL16_EXP_MAX, CKL16_EXP_MIN, Ckl16,
    DeviceCalibration, GRAVITY_COEFF_MAX, GravityCompensation, GridHeader, HEADER_LEN, MAGIC,
    MAX_CELL_CANDIDATES, MAX_NODE_NEIGHBOURS, MAX_NODE_TRIANGLES, MAX_NODES, MAX_PRONY_TERMS,
    MAX_SAMPLE_LEVEL, MAX_SECTIONS, MAX_TRIANGLES, OCCUPIED_WIDEN_CELLS, PLANE_TOL, Precision,
    RELAXATION_TAU_MAX_S, RELAXATION_TAU_MIN_S, Relaxation, SECTION_ALIGN, SECTION_ENTRY_LEN,
    SampleHeader, SectionEntry, SectionKind, TrianglePlane, VERSION_MAJOR, bank_crc,
};
use crate::samples::{Samples, ill_conditioned_sample, lattice_index, lattice_len};
use bytemuck::Pod;
use core::ops::Range;

/// Smallest Cholesky pivot accepted, relative to the largest diagonal entry, when checking that
/// a `C_kk` or a pair's 6x6 compliance is positive definite (below it the block is singular at
/// f32 precision).
pub const SPD_PIVOT_REL: f64 = 1.0e-7;
/// Pairs closer than `truncation_radius_m * (1 - TRUNCATION_SLACK)` must be coupled; the slack
/// absorbs the rounding of positions to f32.
pub const TRUNCATION_SLACK: f64 = 1.0e-4;

/// A validated bank, borrowing the bytes it was parsed from.
#[derive(Clone, Copy, Debug)]
pub struct Bank<'a> {
    bytes: &'a [u8],
    header: &'a BankHeader,
    sections: &'a [SectionEntry],
    meta: &'a BankMeta,
    positions: &'a [[f32; 3]],
    mesh_ids: &'a [u32],
    triangles: &'a [[u16; 3]],
    planes: &'a [TrianglePlane],
    node_tri_starts: &'a [u32],
    node_tri_items: &'a [u16],
    grid: Grid<'a>,
    ckk: &'a [[f32; 6]],
    nb_starts: &'a [u32],
    nb_index: &'a [u16],
    nb_ckl: Blocks<'a>,
    coupling_starts: &'a [u32],
    law: TissueLaw,
    device: &'a DeviceCalibration,
    gravity: Option<&'a GravityCompensation>,
    relaxation: Option<&'a Relaxation>,
    samples: Option<Samples<'a>>,
}

/// The coupling blocks, one per pair, in the bank's storage precision.
#[derive(Clone, Copy, Debug)]
enum Blocks<'a> {
    /// [`SectionKind::NeighbourCkl`].
    F32(&'a [[f32; 9]]),
    /// [`SectionKind::NeighbourCkl16`].
    Bfp16(&'a [Ckl16]),
}

impl<'a> Blocks<'a> {
    fn len(&self) -> usize {
        match self {
            Blocks::F32(b) => b.len(),
            Blocks::Bfp16(b) => b.len(),
        }
    }

    /// Block `i`, row-major f32 (16-bit blocks decoded, exactly).
    fn get(&self, i: usize) -> Option<[f32; 9]> {
        match self {
            Blocks::F32(b) => b.get(i).copied(),
            Blocks::Bfp16(b) => b.get(i).map(Ckl16::decode),
        }
    }

    /// Blocks `range` (empty when out of bounds).
    fn slice(&self, range: Range<usize>) -> Blocks<'a> {
        match self {
            Blocks::F32(b) => Blocks::F32(b.get(range).unwrap_or(&[])),
            Blocks::Bfp16(b) => Blocks::Bfp16(b.get(range).unwrap_or(&[])),
        }
    }
}

/// The couplings stored in one node k's row ([`Bank::upper_couplings`]): its neighbours
/// `l > k`, ascending, and their blocks `C_kl` in the same order (`SPEC.md`, "Pairs stored
/// once (4.0)"). Walking it beside an ascending list of nodes finds all their blocks with no
/// search.
#[derive(Clone, Copy, Debug)]
pub struct UpperCouplings<'a> {
    nodes: &'a [u16],
    blocks: Blocks<'a>,
}

impl<'a> UpperCouplings<'a> {
    /// The neighbours `l > k`, strictly ascending.
    pub fn nodes(&self) -> &'a [u16] {
        self.nodes
    }

    /// Adds `w (C_kl + C_kl^T)` for entry `i` (the coupling of k with `nodes()[i]`) to the
    /// upper triangle `m = [xx, xy, xz, yy, yz, zz]` of a symmetric 3x3; `false` (nothing
    /// added) for `i` out of range. A 16-bit block adds its mantissa pairs as integers and
    /// scales once by `w 2^e`: the same f32 result as adding the decoded entries (both sums
    /// are exact, and so is `w 2^e` unless it is subnormal, for a weight below `2^(-126 - e)`).
    pub fn add_symmetric_part(&self, i: usize, w: f32, m: &mut [f32; 6]) -> bool {
        let (c, scale) = match self.blocks {
            Blocks::F32(b) => match b.get(i) {
                Some(c) => (
                    [
                        c[0] + c[0],
                        c[1] + c[3],
                        c[2] + c[6],
                        c[4] + c[4],
                        c[5] + c[7],
                        c[8] + c[8],
                    ],
                    w,
                ),
                None => return false,
            },
            Blocks::Bfp16(b) => match b.get(i) {
                Some(b) => {
                    let q = b.mantissa.map(i32::from);
                    (
                        [
                            q[0] + q[0],
                            q[1] + q[3],
                            q[2] + q[6],
                            q[4] + q[4],
                            q[5] + q[7],
                            q[8] + q[8],
                        ]
                        .map(|v| v as f32),
                        w * b.scale(),
                    )
                }
                None => return false,
            },
        };
        for (acc, v) in m.iter_mut().zip(c) {
            *acc += scale * v;
        }
        true
    }
}

/// The collision grid: buckets of node indices over R (CSR: the nodes of cell `c` are
/// `items[starts[c]..starts[c + 1]]`, ascending), and per cell the contact certificates: a
/// clearance (lower bound, in cells, of the distance to the surface) and the candidate
/// triangles a short path piece starting in the cell can cross (`SPEC.md`, "cell clearance"
/// and "cell candidates").
#[derive(Clone, Copy, Debug)]
pub struct Grid<'a> {
    header: &'a GridHeader,
    starts: &'a [u16],
    items: &'a [u16],
    clearance: &'a [u8],
    tri_starts: &'a [u32],
    tri_items: &'a [u16],
}

impl<'a> Grid<'a> {
    /// Corner of cell (0, 0, 0), m.
    pub fn origin_m(&self) -> [f32; 3] {
        self.header.origin_m
    }

    /// Cell edge length, m.
    pub fn cell_size_m(&self) -> f32 {
        self.header.cell_size_m
    }

    /// Cells along x, y, z.
    pub fn dims(&self) -> [u16; 3] {
        self.header.dims
    }

    /// Total number of cells.
    pub fn cell_count(&self) -> usize {
        let [x, y, z] = self.header.dims;
        usize::from(x) * usize::from(y) * usize::from(z)
    }

    /// CSR starts, `cell_count() + 1` entries.
    pub fn starts(&self) -> &'a [u16] {
        self.starts
    }

    /// CSR items: node indices, one per node of R.
    pub fn items(&self) -> &'a [u16] {
        self.items
    }

    /// The cell containing `p`, by the spec's rule `i = floor((p - origin) / cell_size)` in f32
    /// per axis, or `None` outside the grid (or for NaN).
    pub fn cell_of(&self, p: [f32; 3]) -> Option<[u16; 3]> {
        cell_of(self.header, p)
    }

    /// Linear index of cell `(i, j, k)`: `i + dims[0] * (j + dims[1] * k)`.
    pub fn cell_index(&self, cell: [u16; 3]) -> Option<usize> {
        let [nx, ny, nz] = self.header.dims;
        let [i, j, k] = cell;
        if i >= nx || j >= ny || k >= nz {
            return None;
        }
        Some(usize::from(i) + usize::from(nx) * (usize::from(j) + usize::from(ny) * usize::from(k)))
    }

    /// Node indices in the cell with linear index `index` (empty if out of range).
    pub fn cell_items(&self, index: usize) -> &'a [u16] {
        csr_row(self.starts, index)
            .and_then(|r| self.items.get(r))
            .unwrap_or(&[])
    }

    /// Clearance of the cell with linear index `index`: every cell a triangle occupies is at
    /// least this many cells away (Chebyshev distance of cell coordinates); 0 out of range.
    pub fn clearance(&self, index: usize) -> u8 {
        self.clearance.get(index).copied().unwrap_or(0)
    }

    /// Candidate triangles of the cell with linear index `index`, ascending: every triangle
    /// whose bounding box widened by [`CANDIDATE_WIDEN_CELLS`] cells meets the cell (empty if
    /// out of range).
    pub fn cell_triangles(&self, index: usize) -> &'a [u16] {
        csr_row(self.tri_starts, index)
            .and_then(|r| self.tri_items.get(r))
            .unwrap_or(&[])
    }

    /// The cell containing `p` with each coordinate clamped to `0..dims` (the cell of `p`
    /// moved into the grid box), or `None` for NaN (or an infinity).
    ///
    /// `floor((p - origin) / cell_size)` clamped to `0..=dims - 1`, computed by clamping the
    /// quotient in f32 first (where truncation toward zero is the floor): the same cell as the
    /// 64-bit floor then clamp, without the 64-bit conversions and `f32::max`/`min`, which are
    /// library calls on the MCU (this runs for every piece of the detection's path; the
    /// quotient is never NaN: `p`, the origin and the cell size are finite).
    pub fn clamped_cell(&self, p: [f32; 3]) -> Option<[u16; 3]> {
        let g = self.header;
        let mut out = [0u16; 3];
        for axis in 0..3 {
            if !p[axis].is_finite() {
                return None;
            }
            let t = (p[axis] - g.origin_m[axis]) / g.cell_size_m;
            let top = f32::from(g.dims[axis].saturating_sub(1));
            let clamped = if t > 0.0 {
                if t < top { t } else { top }
            } else {
                0.0
            };
            out[axis] = clamped as u16;
        }
        Some(out)
    }
}

/// The cells `lo..=hi` (per axis, clamped to the grid) that the bounding box of `tri`, widened
/// by `widen` cells on every side, meets (`SPEC.md`, "cell clearance"): per axis
/// `floor((min - widen h - origin) / h)` to `floor((max + widen h - origin) / h)` in f32.
/// `None` if a vertex is out of range.
pub fn triangle_cells(
    g: &GridHeader,
    positions: &[[f32; 3]],
    tri: [u16; 3],
    widen: f32,
) -> Option<([u16; 3], [u16; 3])> {
    let [a, b, c] = [
        positions.get(usize::from(tri[0]))?,
        positions.get(usize::from(tri[1]))?,
        positions.get(usize::from(tri[2]))?,
    ];
    let h = g.cell_size_m;
    let e = widen * h;
    let mut lo = [0u16; 3];
    let mut hi = [0u16; 3];
    for axis in 0..3 {
        let min = a[axis].min(b[axis]).min(c[axis]);
        let max = a[axis].max(b[axis]).max(c[axis]);
        let top = i64::from(g.dims[axis]) - 1;
        lo[axis] = signed_cell(min - e, g.origin_m[axis], h).clamp(0, top) as u16;
        hi[axis] = signed_cell(max + e, g.origin_m[axis], h).clamp(0, top) as u16;
    }
    Some((lo, hi))
}

/// `floor((p - origin) / cell_size)` per axis in f32, if inside `0..dims`.
pub(crate) fn cell_of(g: &GridHeader, p: [f32; 3]) -> Option<[u16; 3]> {
    let mut out = [0u16; 3];
    for axis in 0..3 {
        let t = (p[axis] - g.origin_m[axis]) / g.cell_size_m;
        // Negative and NaN fail; for t >= 0 truncation is floor.
        if !(t >= 0.0) {
            return None;
        }
        let i = t as u32;
        if i >= u32::from(g.dims[axis]) {
            return None;
        }
        out[axis] = i as u16;
    }
    Some(out)
}

/// Signed cell coordinate `floor((x - origin) / h)` without libm (saturating at the `i32`
/// range, far beyond any grid's 65535 cells). Converted through `i32`, which the MCU's FPU does
/// in one instruction (an `i64` conversion is a library call of about a hundred).
fn signed_cell(x: f32, origin: f32, h: f32) -> i64 {
    let t = (x - origin) / h;
    let i = t as i32;
    i64::from(if (i as f32) > t {
        i.saturating_sub(1)
    } else {
        i
    })
}

/// The index range of CSR row `i` (starts of any unsigned width up to `u32`).
fn csr_row<S: Copy + Into<u32>>(starts: &[S], i: usize) -> Option<Range<usize>> {
    let a = (*starts.get(i)?).into() as usize;
    let b = (*starts.get(i.checked_add(1)?)?).into() as usize;
    (a <= b).then_some(a..b)
}

fn read_header(bytes: &[u8]) -> Result<&BankHeader, BankError> {
    let head = bytes.get(..HEADER_LEN).ok_or(BankError::TooShort {
        needed: HEADER_LEN,
        got: bytes.len(),
    })?;
    bytemuck::try_from_bytes(head).map_err(|_| BankError::Misaligned)
}

/// Cast a byte range to elements, mapping a failure (it cannot happen once offsets and the base
/// are aligned and sizes checked) to a section error.
fn cast<T: Pod>(bytes: &[u8], section: SectionKind) -> Result<&[T], BankError> {
    bytemuck::try_cast_slice(bytes).map_err(|_| BankError::SectionMisaligned { section })
}

fn all_finite(values: &[f32]) -> bool {
    values.iter().all(|v| v.is_finite())
}

/// End of the section table: the header plus `section_count` entries.
fn table_end(header: &BankHeader) -> usize {
    HEADER_LEN + SECTION_ENTRY_LEN * usize::from(header.section_count)
}

/// `SPEC.md` "Validation" rule 1, the header: at least 32 bytes, 4-byte aligned start, magic,
/// major version, header_len, section_count, total_len, and the input holding total_len bytes.
/// Returns the header and the bank's bytes (exactly `total_len` of them).
fn check_header(bytes: &[u8]) -> Result<(&BankHeader, &[u8]), BankError> {
    let header = read_header(bytes)?;
    if bytes.as_ptr().align_offset(BANK_ALIGN) != 0 {
        return Err(BankError::Misaligned);
    }
    if header.magic != MAGIC {
        return Err(BankError::BadMagic);
    }
    if header.version_major != VERSION_MAJOR {
        return Err(BankError::UnsupportedVersion {
            major: header.version_major,
            minor: header.version_minor,
        });
    }
    if usize::from(header.header_len) != HEADER_LEN {
        return Err(BankError::BadHeaderLength {
            header_len: header.header_len,
        });
    }
    if usize::from(header.section_count) > MAX_SECTIONS {
        return Err(BankError::TooManySections {
            count: header.section_count,
        });
    }
    let total = header.total_len as usize;
    if !total.is_multiple_of(SECTION_ALIGN) || total < table_end(header) {
        return Err(BankError::BadTotalLength {
            total_len: header.total_len,
        });
    }
    let bank = bytes.get(..total).ok_or(BankError::TooShort {
        needed: total,
        got: bytes.len(),
    })?;
    Ok((header, bank))
}

/// `SPEC.md` "Validation" rule 2: the stored CRC matches the bank's (see "CRC").
fn check_crc(header: &BankHeader, bank: &[u8]) -> Result<(), BankError> {
    let computed = bank_crc(bank);
    if computed != header.crc32 {
        return Err(BankError::CrcMismatch {
            stored: header.crc32,
            computed,
        });
    }
    Ok(())
}

/// `SPEC.md` "Validation" rule 3: the header's flags and reserved word are zero.
fn check_header_reserved(header: &BankHeader) -> Result<(), BankError> {
    if header.flags != 0 || header.reserved != 0 {
        return Err(BankError::ReservedNotZero {
            section: SectionKind::Header,
        });
    }
    Ok(())
}

/// `SPEC.md` "Validation" rule 4: the section table, entry by entry, then every required kind
/// present ([`check_table`]). `bank` is the whole bank, `total_len` bytes.
fn read_table<'a>(header: &BankHeader, bank: &'a [u8]) -> Result<&'a [SectionEntry], BankError> {
    let end = table_end(header);
    let table: &[SectionEntry] = cast(
        bank.get(HEADER_LEN..end).unwrap_or(&[]),
        SectionKind::Header,
    )?;
    check_table(table, end, bank.len())?;
    Ok(table)
}

/// `SPEC.md` "Validation" rule 5, meta: one element, reserved zero, truncation radius finite
/// and >= 0.
fn parse_meta<'a>(sections: &Sections<'a>) -> Result<&'a BankMeta, BankError> {
    let meta: &BankMeta = sections.single(SectionKind::Meta)?;
    if meta.reserved != 0 {
        return Err(BankError::ReservedNotZero {
            section: SectionKind::Meta,
        });
    }
    if !meta.truncation_radius_m.is_finite() {
        return Err(BankError::NonFinite {
            section: SectionKind::Meta,
            entry: 0,
        });
    }
    if !(meta.truncation_radius_m >= 0.0) {
        return Err(BankError::BadTruncationRadius);
    }
    Ok(meta)
}

/// `SPEC.md` "Validation" rule 6, tissue law: one element, then [`TissueLaw::from_record`]'s
/// rules (kind, coefficient count, finite, unused coefficients zero, domain, monotone).
fn parse_law(sections: &Sections<'_>) -> Result<TissueLaw, BankError> {
    TissueLaw::from_record(sections.single(SectionKind::TissueLaw)?)
}

/// `SPEC.md` "Validation" rule 7, device: one element, all finite, then the device table's
/// rules in table order ([`check_device`]).
fn parse_device<'a>(sections: &Sections<'a>) -> Result<&'a DeviceCalibration, BankError> {
    let device: &DeviceCalibration = sections.single(SectionKind::Device)?;
    check_device(device)?;
    Ok(device)
}

/// `SPEC.md` "Validation" rule 7, gravity (optional section): absent is `None`; else one
/// element, all finite, each coefficient within [`GRAVITY_COEFF_MAX`].
fn parse_gravity<'a>(
    sections: &Sections<'a>,
) -> Result<Option<&'a GravityCompensation>, BankError> {
    let section = SectionKind::Gravity;
    if !sections.table.iter().any(|e| e.kind == section.code()) {
        return Ok(None);
    }
    let gravity: &GravityCompensation = sections.single(section)?;
    if !all_finite(&gravity.coeffs) {
        return Err(BankError::NonFinite { section, entry: 0 });
    }
    if let Some(i) = gravity
        .coeffs
        .iter()
        .position(|c| !(c.abs() <= GRAVITY_COEFF_MAX))
    {
        return Err(BankError::GravityOutOfRange {
            coefficient: i as u32,
        });
    }
    Ok(Some(gravity))
}

/// `SPEC.md` "Validation" rule 7, viscoelastic relaxation (optional section): absent is
/// `None`; else one element, all finite, reserved zero, count in `1..=MAX_PRONY_TERMS`,
/// entries past it zero, each `g_k >= 0` and `tau_k` within
/// `[RELAXATION_TAU_MIN_S, RELAXATION_TAU_MAX_S]`, and `sum g_k < 1` (in f64).
fn parse_relaxation<'a>(sections: &Sections<'a>) -> Result<Option<&'a Relaxation>, BankError> {
    let section = SectionKind::Relaxation;
    if !sections.table.iter().any(|e| e.kind == section.code()) {
        return Ok(None);
    }
    let r: &Relaxation = sections.single(section)?;
    if !all_finite(&r.g) || !all_finite(&r.tau_s) {
        return Err(BankError::NonFinite { section, entry: 0 });
    }
    if r.reserved != 0 {
        return Err(BankError::ReservedNotZero { section });
    }
    let n = r.count as usize;
    if !(1..=MAX_PRONY_TERMS).contains(&n) {
        return Err(BankError::RelaxationCount { count: r.count });
    }
    if r.g[n..].iter().chain(&r.tau_s[n..]).any(|&v| v != 0.0) {
        return Err(BankError::ReservedNotZero { section });
    }
    let tau_range = RELAXATION_TAU_MIN_S..=RELAXATION_TAU_MAX_S;
    if let Some(k) = (0..n).find(|&k| !(r.g[k] >= 0.0 && tau_range.contains(&r.tau_s[k]))) {
        return Err(BankError::RelaxationTerm { term: k as u32 });
    }
    if !(r.g[..n].iter().map(|&g| f64::from(g)).sum::<f64>() < 1.0) {
        return Err(BankError::RelaxationSum);
    }
    Ok(Some(r))
}

/// `SPEC.md` "Validation" rule 15, contact samples: all three sections or none; the header
/// (level, tip radius, reserved words); `t * lattice_len(level)` indices, each below the
/// sample count; every sample finite and SPD (the `C_kk` test); every triangle's samples
/// well enough conditioned for the tick's solve everywhere between them
/// ([`ill_conditioned_sample`]); and continuity: the triangles
/// around a node name one sample for it, and the two triangles of an edge name the same samples
/// along it.
fn parse_samples<'a>(
    sections: &Sections<'a>,
    triangles: &'a [[u16; 3]],
    node_tri_starts: &'a [u32],
    node_tri_items: &'a [u16],
) -> Result<Option<Samples<'a>>, BankError> {
    let kinds = [
        SectionKind::SampleHeader,
        SectionKind::TriangleSamples,
        SectionKind::PatchCompliance,
    ];
    if !kinds.iter().any(|&k| sections.has(k)) {
        return Ok(None);
    }
    let header: &SampleHeader = sections.single(SectionKind::SampleHeader)?;
    let ids: &[u16] = sections.slice(SectionKind::TriangleSamples)?;
    let w: &[[f32; 6]] = sections.slice(SectionKind::PatchCompliance)?;
    let level = header.level;
    let radius_ok = header.tip_radius_m >= 0.0 && header.tip_radius_m.is_finite();
    if !((1..=MAX_SAMPLE_LEVEL).contains(&level) && radius_ok) || header.reserved != [0; 2] {
        return Err(BankError::SampleHeader { level });
    }
    let len = lattice_len(level);
    expect_count(
        ids.len(),
        triangles.len() * len,
        SectionKind::TriangleSamples,
    )?;
    if let Some(e) = ids.iter().position(|&s| usize::from(s) >= w.len()) {
        return Err(BankError::IndexOutOfRange {
            section: SectionKind::TriangleSamples,
            entry: e as u32,
        });
    }
    for (s, c) in w.iter().enumerate() {
        if !all_finite(c) {
            return Err(BankError::NonFinite {
                section: SectionKind::PatchCompliance,
                entry: s as u32,
            });
        }
        if !is_spd::<3>(&sym3(c)) {
            return Err(BankError::SampleNotSpd { sample: s as u32 });
        }
    }
    let samples = Samples { header, ids, w };
    for t in 0..triangles.len() {
        if let Some(sample) = ill_conditioned_sample(w, samples.triangle_samples(t)) {
            return Err(BankError::SampleIllConditioned {
                triangle: t as u32,
                sample: u32::from(sample),
            });
        }
    }
    // Lattice point k steps from corner a towards corner b of a triangle (corners at lattice
    // (0, 0), (level, 0), (0, level)).
    let corner = |c: usize| match c {
        1 => (level, 0),
        2 => (0, level),
        _ => (0, 0),
    };
    let along = |tri: &[u16], a: usize, b: usize, k: u32| -> Option<u16> {
        let ((ia, ja), (ib, jb)) = (corner(a), corner(b));
        let at = |x: u32, y: u32| (x * (level - k) + y * k) / level;
        tri.get(lattice_index(at(ia, ib), at(ja, jb), level))
            .copied()
    };
    for (t, tri) in triangles.iter().enumerate() {
        let mine = samples.triangle_samples(t);
        for a in 0..3 {
            let b = (a + 1) % 3;
            let (Some(&va), Some(&vb)) = (tri.get(a), tri.get(b)) else {
                continue;
            };
            let row = csr_row(node_tri_starts, usize::from(va))
                .and_then(|r| node_tri_items.get(r))
                .unwrap_or(&[]);
            for &u in row {
                let Some(other) = triangles.get(usize::from(u)) else {
                    continue;
                };
                if usize::from(u) == t {
                    continue;
                }
                let (Some(oa), ob) = (
                    other.iter().position(|&v| v == va),
                    other.iter().position(|&v| v == vb),
                ) else {
                    continue;
                };
                let theirs = samples.triangle_samples(usize::from(u));
                // The shared vertex, then the shared edge's points, if any.
                let steps = if ob.is_some() { level } else { 0 };
                for k in 0..=steps {
                    let there = match ob {
                        Some(ob) => along(theirs, oa, ob, k),
                        None => along(theirs, oa, oa, 0),
                    };
                    if along(mine, a, b, k) != there {
                        return Err(BankError::SampleDiscontinuous { triangle: t as u32 });
                    }
                }
            }
        }
    }
    Ok(Some(samples))
}

/// `SPEC.md` "Validation" rule 8, positions: 1 <= n <= 65535 nodes, all finite.
fn parse_positions<'a>(sections: &Sections<'a>) -> Result<&'a [[f32; 3]], BankError> {
    let positions: &[[f32; 3]] = sections.slice(SectionKind::Positions)?;
    let n = positions.len();
    if n == 0 || n > MAX_NODES {
        return Err(BankError::NodeCount { count: n as u32 });
    }
    if let Some(k) = positions.iter().position(|p| !all_finite(p)) {
        return Err(BankError::NonFinite {
            section: SectionKind::Positions,
            entry: k as u32,
        });
    }
    Ok(positions)
}

/// `SPEC.md` "Validation" rule 8, mesh ids: one per node.
fn parse_mesh_ids<'a>(sections: &Sections<'a>, n: usize) -> Result<&'a [u32], BankError> {
    let mesh_ids: &[u32] = sections.slice(SectionKind::MeshIds)?;
    expect_count(mesh_ids.len(), n, SectionKind::MeshIds)?;
    Ok(mesh_ids)
}

/// `SPEC.md` "Validation" rule 9, triangles: at most 65535, vertices < n and three distinct.
fn parse_triangles<'a>(sections: &Sections<'a>, n: usize) -> Result<&'a [[u16; 3]], BankError> {
    let triangles: &[[u16; 3]] = sections.slice(SectionKind::Triangles)?;
    if triangles.len() > MAX_TRIANGLES {
        return Err(BankError::TriangleCount {
            count: u32::try_from(triangles.len()).unwrap_or(u32::MAX),
        });
    }
    for (t, tri) in triangles.iter().enumerate() {
        if tri.iter().any(|&v| usize::from(v) >= n) {
            return Err(BankError::IndexOutOfRange {
                section: SectionKind::Triangles,
                entry: t as u32,
            });
        }
        if tri[0] == tri[1] || tri[1] == tri[2] || tri[0] == tri[2] {
            return Err(BankError::DegenerateTriangle { triangle: t as u32 });
        }
    }
    Ok(triangles)
}

/// `SPEC.md` "Validation" rule 9, node-triangle adjacency: n + 1 starts and 3 t items, CSR
/// starts, items < t, each node's list strictly ascending and naming only triangles that
/// contain the node. Returns `(starts, items)`.
fn parse_node_triangles<'a>(
    sections: &Sections<'a>,
    triangles: &[[u16; 3]],
    n: usize,
    tick_limits: bool,
) -> Result<(&'a [u32], &'a [u16]), BankError> {
    let starts: &[u32] = sections.slice(SectionKind::NodeTriStarts)?;
    let items: &[u16] = sections.slice(SectionKind::NodeTriItems)?;
    expect_count(starts.len(), n + 1, SectionKind::NodeTriStarts)?;
    expect_count(
        items.len(),
        triangles.len().saturating_mul(3),
        SectionKind::NodeTriItems,
    )?;
    check_starts(starts, items.len(), SectionKind::NodeTriStarts)?;
    for k in 0..n {
        let found = csr_row(starts, k).and_then(|r| items.get(r.clone()).map(|row| (r, row)));
        let Some((range, row)) = found else {
            return Err(BankError::BadCsrStarts {
                section: SectionKind::NodeTriStarts,
                entry: k as u32,
            });
        };
        if tick_limits && row.len() > MAX_NODE_TRIANGLES {
            return Err(BankError::TooManyTriangles {
                node: k as u32,
                count: row.len() as u32,
            });
        }
        let mut prev: Option<u16> = None;
        for (offset, &t) in row.iter().enumerate() {
            let Some(tri) = triangles.get(usize::from(t)) else {
                return Err(BankError::IndexOutOfRange {
                    section: SectionKind::NodeTriItems,
                    entry: (range.start + offset) as u32,
                });
            };
            let ascending = prev.is_none_or(|p| t > p);
            if !ascending || !tri.iter().any(|&v| usize::from(v) == k) {
                return Err(BankError::NodeTriangleMismatch { node: k as u32 });
            }
            prev = Some(t);
        }
    }
    Ok((starts, items))
}

/// `SPEC.md` "Validation" rule 9, triangle planes: one per triangle, finite, and each the plane
/// of its triangle's stored positions within [`PLANE_TOL`] ([`check_plane`]).
fn parse_planes<'a>(
    sections: &Sections<'a>,
    positions: &[[f32; 3]],
    triangles: &[[u16; 3]],
) -> Result<&'a [TrianglePlane], BankError> {
    let section = SectionKind::TrianglePlanes;
    let planes: &[TrianglePlane] = sections.slice(section)?;
    expect_count(planes.len(), triangles.len(), section)?;
    if let Some(t) = planes
        .iter()
        .position(|q| !all_finite(&q.m) || !q.off.is_finite())
    {
        return Err(BankError::NonFinite {
            section,
            entry: t as u32,
        });
    }
    for (t, (plane, tri)) in planes.iter().zip(triangles).enumerate() {
        let v = tri.map(|k| positions.get(usize::from(k)).map(|p| p.map(f64::from)));
        let ok = match v {
            [Some(a), Some(b), Some(c)] => check_plane(plane, a, b, c),
            _ => false,
        };
        if !ok {
            return Err(BankError::TrianglePlane { triangle: t as u32 });
        }
    }
    Ok(planes)
}

/// Whether `plane` is the plane of the triangle `abc` (`SPEC.md`, check 9): with `n = (b - a) x
/// (c - a)` in f64, `n != 0`, `|m - n / |n|^2| <= PLANE_TOL |n / |n|^2|`, and every vertex v
/// with `|m . v - off| <= PLANE_TOL |m| max |v|`.
pub(crate) fn check_plane(plane: &TrianglePlane, a: [f64; 3], b: [f64; 3], c: [f64; 3]) -> bool {
    let n = cross64(sub64(b, a), sub64(c, a));
    let nn = dot64(n, n);
    if !(nn > 0.0) {
        return false;
    }
    let want = n.map(|x| x / nn);
    let m = plane.m.map(f64::from);
    let dm = sub64(m, want);
    if !(dot64(dm, dm) <= PLANE_TOL * PLANE_TOL * dot64(want, want)) {
        return false;
    }
    // Squared, so no square root (core has none): (m . v - off)^2 <= TOL^2 |m|^2 max |v|^2.
    let r2 = [a, b, c].iter().fold(0.0f64, |r, v| r.max(dot64(*v, *v)));
    let limit2 = PLANE_TOL * PLANE_TOL * dot64(m, m) * r2;
    let off = f64::from(plane.off);
    [a, b, c].iter().all(|&v| {
        let s = dot64(m, v) - off;
        s * s <= limit2
    })
}

fn sub64(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn dot64(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn cross64(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// `SPEC.md` "Validation" rule 10, the collision grid: the geometry
/// ([`check_grid_geometry`]), cells + 1 starts and n items, CSR starts, then the buckets
/// ([`check_grid_buckets`]).
fn parse_grid<'a>(
    sections: &Sections<'a>,
    positions: &[[f32; 3]],
    triangles: &[[u16; 3]],
    tick_limits: bool,
) -> Result<Grid<'a>, BankError> {
    let header: &GridHeader = sections.single(SectionKind::Grid)?;
    let cells = check_grid_geometry(header)?;
    let starts: &[u16] = sections.slice(SectionKind::GridStarts)?;
    let items: &[u16] = sections.slice(SectionKind::GridItems)?;
    expect_count(starts.len(), cells + 1, SectionKind::GridStarts)?;
    expect_count(items.len(), positions.len(), SectionKind::GridItems)?;
    check_starts(starts, items.len(), SectionKind::GridStarts)?;
    let clearance: &[u8] = sections.slice(SectionKind::CellClearance)?;
    let tri_starts: &[u32] = sections.slice(SectionKind::CellTriStarts)?;
    let tri_items: &[u16] = sections.slice(SectionKind::CellTriItems)?;
    expect_count(clearance.len(), cells, SectionKind::CellClearance)?;
    expect_count(tri_starts.len(), cells + 1, SectionKind::CellTriStarts)?;
    check_starts(tri_starts, tri_items.len(), SectionKind::CellTriStarts)?;
    let grid = Grid {
        header,
        starts,
        items,
        clearance,
        tri_starts,
        tri_items,
    };
    check_grid_buckets(&grid, positions, cells)?;
    check_cell_candidates(&grid, positions, triangles, cells, tick_limits)?;
    check_cell_clearance(&grid, positions, triangles)?;
    Ok(grid)
}

/// `SPEC.md` "Validation" rule 10, candidates: per cell, items < t and strictly ascending,
/// each naming a triangle whose widened box meets the cell; and every such (triangle, cell)
/// present. Together: each list is exactly the rule's set.
fn check_cell_candidates(
    grid: &Grid<'_>,
    positions: &[[f32; 3]],
    triangles: &[[u16; 3]],
    cells: usize,
    tick_limits: bool,
) -> Result<(), BankError> {
    let g = grid.header;
    for c in 0..cells {
        let Some(range) = csr_row(grid.tri_starts, c) else {
            return Err(BankError::BadCsrStarts {
                section: SectionKind::CellTriStarts,
                entry: c as u32,
            });
        };
        if tick_limits && range.len() > MAX_CELL_CANDIDATES {
            return Err(BankError::TooManyCandidates {
                cell: c as u32,
                count: range.len() as u32,
            });
        }
        let cell = cell_coords(g, c);
        let mut prev: Option<u16> = None;
        for e in range {
            let t = grid.tri_items.get(e).copied().unwrap_or(u16::MAX);
            let Some(&tri) = triangles.get(usize::from(t)) else {
                return Err(BankError::IndexOutOfRange {
                    section: SectionKind::CellTriItems,
                    entry: e as u32,
                });
            };
            let meets = triangle_cells(g, positions, tri, CANDIDATE_WIDEN_CELLS)
                .is_some_and(|(lo, hi)| (0..3).all(|a| lo[a] <= cell[a] && cell[a] <= hi[a]));
            if prev.is_some_and(|q| t <= q) || !meets {
                return Err(BankError::CellCandidates { cell: c as u32 });
            }
            prev = Some(t);
        }
    }
    for (t, &tri) in triangles.iter().enumerate() {
        let Some((lo, hi)) = triangle_cells(g, positions, tri, CANDIDATE_WIDEN_CELLS) else {
            continue;
        };
        for_cells(grid, lo, hi, |c| {
            if grid.cell_triangles(c).binary_search(&(t as u16)).is_ok() {
                Ok(())
            } else {
                Err(BankError::CellCandidates { cell: c as u32 })
            }
        })?;
    }
    Ok(())
}

/// `SPEC.md` "Validation" rule 10, clearance: zero in every cell a triangle occupies, and at
/// most one more than each of the (up to 26) neighbouring cells', so that it never exceeds the
/// Chebyshev cell distance to an occupied cell.
fn check_cell_clearance(
    grid: &Grid<'_>,
    positions: &[[f32; 3]],
    triangles: &[[u16; 3]],
) -> Result<(), BankError> {
    let g = grid.header;
    for &tri in triangles {
        let Some((lo, hi)) = triangle_cells(g, positions, tri, OCCUPIED_WIDEN_CELLS) else {
            continue;
        };
        for_cells(grid, lo, hi, |c| {
            if grid.clearance(c) == 0 {
                Ok(())
            } else {
                Err(BankError::CellClearance { cell: c as u32 })
            }
        })?;
    }
    let [nx, ny, nz] = g.dims;
    for cz in 0..nz {
        for cy in 0..ny {
            for cx in 0..nx {
                let Some(c) = grid.cell_index([cx, cy, cz]) else {
                    continue;
                };
                let here = u16::from(grid.clearance(c));
                let lo = [cx, cy, cz].map(|v| v.saturating_sub(1));
                let hi = [
                    cx.saturating_add(1).min(nx - 1),
                    cy.saturating_add(1).min(ny - 1),
                    cz.saturating_add(1).min(nz - 1),
                ];
                for_cells(grid, lo, hi, |n| {
                    if here <= u16::from(grid.clearance(n)) + 1 {
                        Ok(())
                    } else {
                        Err(BankError::CellClearance { cell: c as u32 })
                    }
                })?;
            }
        }
    }
    Ok(())
}

/// Calls `f` with the linear index of every cell in `lo..=hi`, stopping at the first error.
fn for_cells(
    grid: &Grid<'_>,
    lo: [u16; 3],
    hi: [u16; 3],
    mut f: impl FnMut(usize) -> Result<(), BankError>,
) -> Result<(), BankError> {
    for cz in lo[2]..=hi[2] {
        for cy in lo[1]..=hi[1] {
            for cx in lo[0]..=hi[0] {
                if let Some(c) = grid.cell_index([cx, cy, cz]) {
                    f(c)?;
                }
            }
        }
    }
    Ok(())
}

/// The coordinates of the cell with linear index `c` (`c < cells`).
fn cell_coords(g: &GridHeader, c: usize) -> [u16; 3] {
    let [nx, ny, _] = g.dims.map(usize::from);
    let (nx, ny) = (nx.max(1), ny.max(1));
    [
        (c % nx) as u16,
        ((c / nx) % ny) as u16,
        (c / (nx * ny)) as u16,
    ]
}

/// `SPEC.md` "Validation" rule 10, grid geometry: finite, reserved zero, cell size > 0,
/// dims >= 1 and cells < 2^32 - 1. Returns the number of cells.
fn check_grid_geometry(header: &GridHeader) -> Result<usize, BankError> {
    if !all_finite(&header.origin_m) || !header.cell_size_m.is_finite() {
        return Err(BankError::NonFinite {
            section: SectionKind::Grid,
            entry: 0,
        });
    }
    if header.reserved != 0 {
        return Err(BankError::ReservedNotZero {
            section: SectionKind::Grid,
        });
    }
    let cells = header.dims.iter().map(|&d| u64::from(d)).product::<u64>();
    if !(header.cell_size_m > 0.0) || cells == 0 || cells >= u64::from(u32::MAX) {
        return Err(BankError::GridGeometry);
    }
    Ok(cells as usize)
}

/// `SPEC.md` "Validation" rule 10, per cell: items < n, strictly ascending, each in the cell
/// its position maps to.
fn check_grid_buckets(
    grid: &Grid<'_>,
    positions: &[[f32; 3]],
    cells: usize,
) -> Result<(), BankError> {
    for c in 0..cells {
        let Some(range) = csr_row(grid.starts, c) else {
            return Err(BankError::BadCsrStarts {
                section: SectionKind::GridStarts,
                entry: c as u32,
            });
        };
        let mut prev: Option<u16> = None;
        for e in range {
            let item = grid.items.get(e).copied().unwrap_or(u16::MAX);
            let Some(p) = positions.get(usize::from(item)) else {
                return Err(BankError::IndexOutOfRange {
                    section: SectionKind::GridItems,
                    entry: e as u32,
                });
            };
            if prev.is_some_and(|q| item <= q) {
                return Err(BankError::GridItemsNotSorted { cell: c as u32 });
            }
            prev = Some(item);
            if grid.cell_of(*p).and_then(|cell| grid.cell_index(cell)) != Some(c) {
                return Err(BankError::GridItemWrongCell {
                    cell: c as u32,
                    entry: e as u32,
                });
            }
        }
    }
    Ok(())
}

/// `SPEC.md` "Validation" rule 11, C_kk: one per node, finite, symmetric positive definite
/// ([`is_spd`]).
fn parse_ckk<'a>(sections: &Sections<'a>, n: usize) -> Result<&'a [[f32; 6]], BankError> {
    let ckk: &[[f32; 6]] = sections.slice(SectionKind::Ckk)?;
    expect_count(ckk.len(), n, SectionKind::Ckk)?;
    for (k, c) in ckk.iter().enumerate() {
        if !all_finite(c) {
            return Err(BankError::NonFinite {
                section: SectionKind::Ckk,
                entry: k as u32,
            });
        }
        if !is_spd::<3>(&sym3(c)) {
            return Err(BankError::CkkNotSpd { node: k as u32 });
        }
    }
    Ok(ckk)
}

/// The neighbour sections `(starts, index, C_kl blocks, coupling starts)`, as
/// [`parse_neighbours`] returns them.
type NeighbourLists<'a> = (&'a [u32], &'a [u16], Blocks<'a>, &'a [u32]);

/// `SPEC.md` "Validation" rule 12, neighbours: n + 1 neighbour and coupling starts, both CSR
/// (the coupling starts over the C_kl blocks), blocks finite; per row, indices < n, != k,
/// strictly ascending, and as many blocks as entries `l > k`. Returns
/// `(starts, index, blocks, coupling starts)`.
fn parse_neighbours<'a>(
    sections: &Sections<'a>,
    n: usize,
    tick_limits: bool,
) -> Result<NeighbourLists<'a>, BankError> {
    let starts: &[u32] = sections.slice(SectionKind::NeighbourStarts)?;
    let index: &[u16] = sections.slice(SectionKind::NeighbourIndex)?;
    let ckl = if sections.has(SectionKind::NeighbourCkl16) {
        Blocks::Bfp16(sections.slice(SectionKind::NeighbourCkl16)?)
    } else {
        Blocks::F32(sections.slice(SectionKind::NeighbourCkl)?)
    };
    let cstarts: &[u32] = sections.slice(SectionKind::CouplingStarts)?;
    expect_count(starts.len(), n + 1, SectionKind::NeighbourStarts)?;
    expect_count(cstarts.len(), n + 1, SectionKind::CouplingStarts)?;
    check_starts(starts, index.len(), SectionKind::NeighbourStarts)?;
    check_starts(cstarts, ckl.len(), SectionKind::CouplingStarts)?;
    match ckl {
        Blocks::F32(b) => {
            if let Some(e) = b.iter().position(|c| !all_finite(c)) {
                return Err(BankError::NonFinite {
                    section: SectionKind::NeighbourCkl,
                    entry: e as u32,
                });
            }
        }
        Blocks::Bfp16(b) => {
            if let Some(e) = b
                .iter()
                .position(|c| !(CKL16_EXP_MIN..=CKL16_EXP_MAX).contains(&c.exponent))
            {
                return Err(BankError::CklExponent { entry: e as u32 });
            }
        }
    }
    for k in 0..n {
        let range = csr_row(starts, k).unwrap_or(0..0);
        if tick_limits && range.len() > MAX_NODE_NEIGHBOURS {
            return Err(BankError::TooManyNeighbours {
                node: k as u32,
                count: range.len() as u32,
            });
        }
        let mut prev: Option<u16> = None;
        for e in range {
            let l = index.get(e).copied().unwrap_or(u16::MAX);
            if usize::from(l) >= n {
                return Err(BankError::IndexOutOfRange {
                    section: SectionKind::NeighbourIndex,
                    entry: e as u32,
                });
            }
            if usize::from(l) == k {
                return Err(BankError::NeighbourSelf { node: k as u32 });
            }
            if prev.is_some_and(|q| l <= q) {
                return Err(BankError::NeighbourNotSorted { node: k as u32 });
            }
            prev = Some(l);
        }
        let row = csr_row(starts, k).and_then(|r| index.get(r)).unwrap_or(&[]);
        let upper = row.iter().filter(|&&l| usize::from(l) > k).count();
        if csr_row(cstarts, k).map(|r| r.len()) != Some(upper) {
            return Err(BankError::BadCsrStarts {
                section: SectionKind::CouplingStarts,
                entry: (k + 1) as u32,
            });
        }
    }
    Ok((starts, index, ckl, cstarts))
}

impl<'a> Bank<'a> {
    /// Validate `bytes` and borrow it as a bank. `bytes` must start on a 4-byte boundary and
    /// hold at least the header's `total_len` bytes; anything after that is ignored (a flash
    /// region may be larger than the bank). See `SPEC.md` for every rule and its order: the
    /// stages below run its "Validation" rules 1 to 14 in turn, each reporting its first failure.
    /// The limits the firmware's tick budget rests on ([`crate::MAX_CELL_CANDIDATES`],
    /// [`crate::MAX_NODE_NEIGHBOURS`], [`crate::MAX_NODE_TRIANGLES`]) are part of them.
    pub fn parse(bytes: &'a [u8]) -> Result<Bank<'a>, BankError> {
        Bank::parse_with(bytes, true)
    }

    /// [`Bank::parse`] without the tick's limits (rules 9, 10 and 12's counts): for banks the
    /// firmware never reads, built by the host as a means to an end (the tool-coupling probe,
    /// which couples every pair one patch can load, however many). Everything else is checked,
    /// so every accessor is as safe as on a parsed bank.
    pub fn parse_unbounded(bytes: &'a [u8]) -> Result<Bank<'a>, BankError> {
        Bank::parse_with(bytes, false)
    }

    fn parse_with(bytes: &'a [u8], tick_limits: bool) -> Result<Bank<'a>, BankError> {
        let (header, bank) = check_header(bytes)?;
        check_crc(header, bank)?;
        check_header_reserved(header)?;
        let table = read_table(header, bank)?;
        let sections = Sections { bank, table };
        let meta = parse_meta(&sections)?;
        let law = parse_law(&sections)?;
        let device = parse_device(&sections)?;
        let gravity = parse_gravity(&sections)?;
        let relaxation = parse_relaxation(&sections)?;
        let positions = parse_positions(&sections)?;
        let n = positions.len();
        let mesh_ids = parse_mesh_ids(&sections, n)?;
        let triangles = parse_triangles(&sections, n)?;
        let (node_tri_starts, node_tri_items) =
            parse_node_triangles(&sections, triangles, n, tick_limits)?;
        let planes = parse_planes(&sections, positions, triangles)?;
        let grid = parse_grid(&sections, positions, triangles, tick_limits)?;
        let ckk = parse_ckk(&sections, n)?;
        let (nb_starts, nb_index, nb_ckl, coupling_starts) =
            parse_neighbours(&sections, n, tick_limits)?;
        let bank = Bank {
            bytes: bank,
            header,
            sections: table,
            meta,
            positions,
            mesh_ids,
            triangles,
            planes,
            node_tri_starts,
            node_tri_items,
            grid,
            ckk,
            nb_starts,
            nb_index,
            nb_ckl,
            coupling_starts,
            law,
            device,
            gravity,
            relaxation,
            samples: None,
        };
        bank.check_couplings()?;
        bank.check_coverage()?;
        let samples = parse_samples(&sections, triangles, node_tri_starts, node_tri_items)?;
        Ok(Bank { samples, ..bank })
    }

    /// `SPEC.md` "Validation" rule 13: reciprocity and pairwise positive definiteness of the
    /// couplings, then every triangle edge coupled.
    fn check_couplings(&self) -> Result<(), BankError> {
        let n = self.node_count();
        for k in 0..n {
            for &l in self.neighbours(k) {
                let l = usize::from(l);
                let err_node = k as u32;
                let err_nb = l as u32;
                if self.neighbours(l).binary_search(&(k as u16)).is_err() {
                    return Err(BankError::NeighbourNotReciprocal {
                        node: err_node,
                        neighbour: err_nb,
                    });
                }
                if l < k {
                    continue; // the pair was checked from its smaller node
                }
                let (Some(ckk), Some(cll), Some(c_kl)) =
                    (self.ckk.get(k), self.ckk.get(l), self.find_coupling(k, l))
                else {
                    continue;
                };
                let a = sym3(ckk);
                let b = sym3(cll);
                let mut m = [[0.0f64; 6]; 6];
                for i in 0..3 {
                    for j in 0..3 {
                        m[i][j] = a[i][j];
                        m[i + 3][j + 3] = b[i][j];
                        m[i][j + 3] = f64::from(c_kl[3 * i + j]);
                        m[j + 3][i] = f64::from(c_kl[3 * i + j]);
                    }
                }
                if !is_spd::<6>(&m) {
                    return Err(BankError::PairNotSpd {
                        node: err_node,
                        neighbour: err_nb,
                    });
                }
            }
        }
        for (t, tri) in self.triangles.iter().enumerate() {
            let [a, b, c] = tri.map(usize::from);
            if self.find_coupling(a, b).is_none()
                || self.find_coupling(b, c).is_none()
                || self.find_coupling(a, c).is_none()
            {
                return Err(BankError::TriangleEdgeNotCoupled { triangle: t as u32 });
            }
        }
        Ok(())
    }

    /// `SPEC.md` "Validation" rule 14: every pair closer than the truncation radius is coupled.
    fn check_coverage(&self) -> Result<(), BankError> {
        let r = self.meta.truncation_radius_m;
        if r <= 0.0 {
            return Ok(());
        }
        let limit = f64::from(r) * (1.0 - TRUNCATION_SLACK);
        let limit2 = limit * limit;
        let g = self.grid.header;
        let h = g.cell_size_m;
        for (k, p) in self.positions.iter().enumerate() {
            let mut lo = [0u16; 3];
            let mut hi = [0u16; 3];
            for axis in 0..3 {
                let top = i64::from(g.dims[axis]) - 1;
                lo[axis] = signed_cell(p[axis] - r, g.origin_m[axis], h).clamp(0, top) as u16;
                hi[axis] = signed_cell(p[axis] + r, g.origin_m[axis], h).clamp(0, top) as u16;
            }
            for cz in lo[2]..=hi[2] {
                for cy in lo[1]..=hi[1] {
                    for cx in lo[0]..=hi[0] {
                        let Some(c) = self.grid.cell_index([cx, cy, cz]) else {
                            continue;
                        };
                        for &l in self.grid.cell_items(c) {
                            let l = usize::from(l);
                            if l <= k {
                                continue;
                            }
                            let Some(q) = self.positions.get(l) else {
                                continue;
                            };
                            let d2: f64 = (0..3)
                                .map(|i| {
                                    let d = f64::from(p[i]) - f64::from(q[i]);
                                    d * d
                                })
                                .sum();
                            if d2 < limit2 && self.find_coupling(k, l).is_none() {
                                return Err(BankError::MissingNeighbour {
                                    node: k as u32,
                                    neighbour: l as u32,
                                });
                            }
                        }
                    }
                }
            }
        }
        Ok(())
    }

    /// `C_kl` row-major for `k != l`: the stored block of the pair, from the row of the smaller
    /// node (`SPEC.md`, "Pairs stored once (4.0)"), transposed when `k > l`.
    fn find_coupling(&self, k: usize, l: usize) -> Option<[f32; 9]> {
        let (a, b) = if k < l { (k, l) } else { (l, k) };
        let row = self.neighbours(a);
        let i = row.binary_search(&u16::try_from(b).ok()?).ok()?;
        let blocks = csr_row(self.coupling_starts, a)?;
        // The row's last `blocks.len()` entries are its l > a, in block order.
        let first_upper = row.len().checked_sub(blocks.len())?;
        let c = self
            .nb_ckl
            .get(blocks.start + i.checked_sub(first_upper)?)?;
        Some(if k < l {
            c
        } else {
            [c[0], c[3], c[6], c[1], c[4], c[7], c[2], c[5], c[8]]
        })
    }

    /// The bank's bytes (exactly `total_len` of them).
    pub fn bytes(&self) -> &'a [u8] {
        self.bytes
    }

    /// The validated section table, in file order (see `SPEC.md`).
    pub fn sections(&self) -> &'a [SectionEntry] {
        self.sections
    }

    /// The bank's CRC-32, which also serves as its identity on the link.
    pub fn crc(&self) -> u32 {
        self.header.crc32
    }

    /// `(major, minor)` version of the writer.
    pub fn version(&self) -> (u16, u16) {
        (self.header.version_major, self.header.version_minor)
    }

    /// Bank-wide metadata.
    pub fn meta(&self) -> &'a BankMeta {
        self.meta
    }

    /// The host's scene identity.
    pub fn scene_id(&self) -> u64 {
        self.meta.scene_id()
    }

    /// Truncation radius, m.
    pub fn truncation_radius_m(&self) -> f32 {
        self.meta.truncation_radius_m
    }

    /// Number of nodes in R (1..=65535).
    pub fn node_count(&self) -> usize {
        self.positions.len()
    }

    /// Node positions, m.
    pub fn positions(&self) -> &'a [[f32; 3]] {
        self.positions
    }

    /// Each node's id in the host mesh (for the display).
    pub fn mesh_ids(&self) -> &'a [u32] {
        self.mesh_ids
    }

    /// R's surface triangles (node indices, counter-clockwise seen from outside).
    pub fn triangles(&self) -> &'a [[u16; 3]] {
        self.triangles
    }

    /// The triangles' planes, one per triangle in [`Bank::triangles`]' order (`SPEC.md`,
    /// "triangle planes"): the plane test `m . p - off` and the barycentric coordinates without
    /// loading the vertices or dividing.
    pub fn triangle_planes(&self) -> &'a [TrianglePlane] {
        self.planes
    }

    /// Indices of the triangles that contain node `k`, ascending (empty for `k` out of range).
    pub fn node_triangles(&self, k: usize) -> &'a [u16] {
        csr_row(self.node_tri_starts, k)
            .and_then(|r| self.node_tri_items.get(r))
            .unwrap_or(&[])
    }

    /// The collision grid.
    pub fn grid(&self) -> Grid<'a> {
        self.grid
    }

    /// `C_kk` as stored: xx, xy, xz, yy, yz, zz in m/N.
    pub fn c_kk(&self, k: usize) -> Option<[f32; 6]> {
        self.ckk.get(k).copied()
    }

    /// `C_kk` as a full symmetric 3x3 matrix, m/N.
    pub fn c_kk_matrix(&self, k: usize) -> Option<[[f32; 3]; 3]> {
        self.ckk
            .get(k)
            .map(|c| [[c[0], c[1], c[2]], [c[1], c[3], c[4]], [c[2], c[4], c[5]]])
    }

    /// Node `k`'s neighbours `l`: every node coupled with it, ascending, `l != k` (the blocks are
    /// read with [`Bank::coupling`]). Empty for `k` out of range.
    pub fn neighbours(&self, k: usize) -> &'a [u16] {
        csr_row(self.nb_starts, k)
            .and_then(|r| self.nb_index.get(r))
            .unwrap_or(&[])
    }

    /// The couplings stored in node `k`'s row: its neighbours `l > k` and their blocks
    /// ([`UpperCouplings`]; empty for `k` out of range).
    pub fn upper_couplings(&self, k: usize) -> UpperCouplings<'a> {
        let row = self.neighbours(k);
        let blocks = csr_row(self.coupling_starts, k).unwrap_or(0..0);
        let first = row.len().saturating_sub(blocks.len());
        UpperCouplings {
            nodes: row.get(first..).unwrap_or(&[]),
            blocks: self.nb_ckl.slice(blocks),
        }
    }

    /// Number of coupled pairs (blocks stored, one per pair).
    pub fn pair_count(&self) -> usize {
        self.nb_ckl.len()
    }

    /// The storage precision of the coupling blocks.
    pub fn precision(&self) -> Precision {
        match self.nb_ckl {
            Blocks::F32(_) => Precision::F32,
            Blocks::Bfp16(_) => Precision::Bfp16,
        }
    }

    /// The 3x3 compliance block `C_kl` (m/N: displacement of `k` per unit force at `l`) for any
    /// two nodes: `C_kk` when `k == l`, the stored coupling (`C_lk^T` when `k > l`) when `l` is
    /// a neighbour of `k`, `None` otherwise (truncated or out of range). No allocation: one
    /// binary search in the smaller node's row.
    pub fn coupling(&self, k: usize, l: usize) -> Option<[[f32; 3]; 3]> {
        if k == l {
            return self.c_kk_matrix(k);
        }
        self.find_coupling(k, l)
            .map(|c| [[c[0], c[1], c[2]], [c[3], c[4], c[5]], [c[6], c[7], c[8]]])
    }

    /// The tissue force law Q.
    pub fn tissue_law(&self) -> &TissueLaw {
        &self.law
    }

    /// The device calibration.
    pub fn device(&self) -> &'a DeviceCalibration {
        self.device
    }

    /// The gravity compensation, `None` when the bank has no gravity section (then nothing is
    /// compensated).
    pub fn gravity(&self) -> Option<&'a GravityCompensation> {
        self.gravity
    }

    /// The viscoelastic relaxation (`SPEC.md`, "viscoelastic relaxation"), `None` when the bank
    /// has none (the firmware then renders the elastic force, as before 7.0).
    pub fn relaxation(&self) -> Option<&'a Relaxation> {
        self.relaxation
    }

    /// The contact samples (`SPEC.md`, "contact samples"): the tool's patch compliance over the
    /// reachable surface; `None` when the bank has none (the firmware then renders a contact
    /// from the nodal compliance, the tool patch on the nodes).
    pub fn samples(&self) -> Option<Samples<'a>> {
        self.samples
    }

    /// The node nearest to `p` among the 27 buckets around `p`'s cell (clipped to the grid),
    /// with its squared distance in m^2; `None` if those buckets are empty or `p` is more than
    /// one cell outside the grid (or not finite).
    pub fn nearest_node(&self, p: [f32; 3]) -> Option<(u16, f32)> {
        if !all_finite(&p) {
            return None;
        }
        let g = self.grid.header;
        let mut lo = [0u16; 3];
        let mut hi = [0u16; 3];
        for axis in 0..3 {
            let c = signed_cell(p[axis], g.origin_m[axis], g.cell_size_m);
            let top = i64::from(g.dims[axis]) - 1;
            let (a, b) = (c.saturating_sub(1).max(0), c.saturating_add(1).min(top));
            if a > b {
                return None;
            }
            lo[axis] = a as u16;
            hi[axis] = b as u16;
        }
        let mut best: Option<(u16, f32)> = None;
        for cz in lo[2]..=hi[2] {
            for cy in lo[1]..=hi[1] {
                for cx in lo[0]..=hi[0] {
                    let Some(c) = self.grid.cell_index([cx, cy, cz]) else {
                        continue;
                    };
                    for &l in self.grid.cell_items(c) {
                        let Some(q) = self.positions.get(usize::from(l)) else {
                            continue;
                        };
                        let d2 = (p[0] - q[0]) * (p[0] - q[0])
                            + (p[1] - q[1]) * (p[1] - q[1])
                            + (p[2] - q[2]) * (p[2] - q[2]);
                        if best.is_none_or(|(_, b)| d2 < b) {
                            best = Some((l, d2));
                        }
                    }
                }
            }
        }
        best
    }
}

struct Sections<'a> {
    bank: &'a [u8],
    table: &'a [SectionEntry],
}

impl<'a> Sections<'a> {
    fn bytes(&self, kind: SectionKind) -> Result<(&'a [u8], u32), BankError> {
        let entry = self
            .table
            .iter()
            .find(|e| e.kind == kind.code())
            .ok_or(BankError::MissingSection { section: kind })?;
        let start = entry.offset as usize;
        let end = start
            .checked_add(entry.len as usize)
            .ok_or(BankError::SectionOutOfBounds { section: kind })?;
        let bytes = self
            .bank
            .get(start..end)
            .ok_or(BankError::SectionOutOfBounds { section: kind })?;
        Ok((bytes, entry.count))
    }

    fn has(&self, kind: SectionKind) -> bool {
        self.table.iter().any(|e| e.kind == kind.code())
    }

    fn slice<T: Pod>(&self, kind: SectionKind) -> Result<&'a [T], BankError> {
        let (bytes, _) = self.bytes(kind)?;
        cast(bytes, kind)
    }

    fn single<T: Pod>(&self, kind: SectionKind) -> Result<&'a T, BankError> {
        let (bytes, count) = self.bytes(kind)?;
        let items: &[T] = cast(bytes, kind)?;
        match (count, items) {
            (1, [one]) => Ok(one),
            _ => Err(BankError::CountMismatch { section: kind }),
        }
    }
}

fn expect_count(got: usize, want: usize, section: SectionKind) -> Result<(), BankError> {
    if got == want {
        Ok(())
    } else {
        Err(BankError::CountMismatch { section })
    }
}

fn check_starts<S: Copy + Into<u32>>(
    starts: &[S],
    items: usize,
    section: SectionKind,
) -> Result<(), BankError> {
    let mut prev = 0u32;
    for (i, s) in starts.iter().enumerate() {
        let s: u32 = (*s).into();
        let bad = if i == 0 { s != 0 } else { s < prev };
        if bad {
            return Err(BankError::BadCsrStarts {
                section,
                entry: i as u32,
            });
        }
        prev = s;
    }
    if prev as usize != items {
        return Err(BankError::BadCsrStarts {
            section,
            entry: starts.len().saturating_sub(1) as u32,
        });
    }
    Ok(())
}

fn check_table(table: &[SectionEntry], table_end: usize, total: usize) -> Result<(), BankError> {
    for (i, e) in table.iter().enumerate() {
        let section = SectionKind::from_code(e.kind);
        if section == SectionKind::Header {
            return Err(BankError::ReservedSectionKind { entry: i as u32 });
        }
        let start = e.offset as usize;
        if !start.is_multiple_of(SECTION_ALIGN) {
            return Err(BankError::SectionMisaligned { section });
        }
        let end = start
            .checked_add(e.len as usize)
            .filter(|&end| end <= total)
            .ok_or(BankError::SectionOutOfBounds { section })?;
        if start < table_end && end > start {
            return Err(BankError::SectionOverlap { section });
        }
        let earlier = table.get(..i).unwrap_or(&[]);
        if earlier.iter().any(|p| p.kind == e.kind) {
            return Err(BankError::DuplicateSection { section });
        }
        let overlaps = earlier.iter().any(|p| {
            let (ps, pe) = (p.offset as usize, p.offset as usize + p.len as usize);
            start < pe && ps < end
        });
        if overlaps {
            return Err(BankError::SectionOverlap { section });
        }
        let size_ok = section
            .element_size()
            .is_none_or(|size| (e.count as usize).checked_mul(size) == Some(e.len as usize));
        if !size_ok {
            return Err(BankError::SizeMismatch { section });
        }
    }
    for section in SectionKind::REQUIRED {
        if !table.iter().any(|e| e.kind == section.code()) {
            return Err(BankError::MissingSection { section });
        }
    }
    let has = |k: SectionKind| table.iter().any(|e| e.kind == k.code());
    match (
        has(SectionKind::NeighbourCkl),
        has(SectionKind::NeighbourCkl16),
    ) {
        (false, false) => Err(BankError::MissingSection {
            section: SectionKind::NeighbourCkl,
        }),
        (true, true) => Err(BankError::DuplicateSection {
            section: SectionKind::NeighbourCkl16,
        }),
        _ => Ok(()),
    }
}

fn sym3(c: &[f32; 6]) -> [[f64; 3]; 3] {
    let c = c.map(f64::from);
    [[c[0], c[1], c[2]], [c[1], c[3], c[4]], [c[2], c[4], c[5]]]
}

/// LDL^T in f64: every pivot must exceed [`SPD_PIVOT_REL`] times the largest diagonal entry
/// (equivalent to a Cholesky factorisation succeeding with that margin; no square roots).
fn is_spd<const N: usize>(m: &[[f64; N]; N]) -> bool {
    let mut max_diag = 0.0f64;
    for (i, row) in m.iter().enumerate() {
        max_diag = max_diag.max(row[i]);
    }
    if !(max_diag > 0.0) {
        return false;
    }
    let tol = SPD_PIVOT_REL * max_diag;
    let mut l = [[0.0f64; N]; N];
    let mut d = [0.0f64; N];
    for j in 0..N {
        let mut dj = m[j][j];
        for k in 0..j {
            dj -= l[j][k] * l[j][k] * d[k];
        }
        if !(dj > tol) {
            return false;
        }
        d[j] = dj;
        for i in j + 1..N {
            let mut v = m[i][j];
            for k in 0..j {
                v -= l[i][k] * l[j][k] * d[k];
            }
            l[i][j] = v / dj;
        }
    }
    true
}

fn check_device(d: &DeviceCalibration) -> Result<(), BankError> {
    let floats = [
        &d.fulcrum_m[..],
        &d.shaft_axis,
        &d.pitch_axis,
        &d.yaw_axis,
        &d.joint_min,
        &d.joint_max,
        &d.home_joint,
        &d.transmission,
        &d.torque_constant_nm_per_a,
        &d.current_limit_a,
        &[d.max_force_n, d.tip_radius_m, d.max_tip_speed_m_s],
        &d.max_joint_speed,
    ];
    if !floats.iter().all(|v| all_finite(v)) {
        return Err(BankError::NonFinite {
            section: SectionKind::Device,
            entry: 0,
        });
    }
    let dot = |a: &[f32; 3], b: &[f32; 3]| -> f64 {
        (0..3).map(|i| f64::from(a[i]) * f64::from(b[i])).sum()
    };
    let unit = |a: &[f32; 3]| (dot(a, a) - 1.0).abs() <= 2.0e-3;
    let fail = |field| Err(BankError::Device { field });
    if !unit(&d.shaft_axis) {
        return fail(DeviceField::ShaftAxis);
    }
    if !unit(&d.pitch_axis) {
        return fail(DeviceField::PitchAxis);
    }
    if !unit(&d.yaw_axis) {
        return fail(DeviceField::YawAxis);
    }
    if dot(&d.shaft_axis, &d.pitch_axis).abs() > 1.0e-3
        || dot(&d.shaft_axis, &d.yaw_axis).abs() > 1.0e-3
        || dot(&d.pitch_axis, &d.yaw_axis).abs() > 1.0e-3
    {
        return fail(DeviceField::AxesNotOrthogonal);
    }
    let pi = core::f32::consts::PI;
    for axis in 0..3u8 {
        let i = usize::from(axis);
        let (lo, hi) = (d.joint_min[i], d.joint_max[i]);
        let bounded = if i < 2 {
            lo >= -pi && hi <= pi
        } else {
            lo >= 0.0
        };
        if !(lo < hi) || !bounded {
            return fail(DeviceField::JointRange { axis });
        }
        if !(lo <= d.home_joint[i] && d.home_joint[i] <= hi) {
            return fail(DeviceField::HomeJoint { axis });
        }
    }
    for axis in 0..3u8 {
        let i = usize::from(axis);
        if d.counts_per_rev[i] == 0 {
            return fail(DeviceField::CountsPerRev { axis });
        }
        if !(d.transmission[i].abs() >= 1.0e-6) {
            return fail(DeviceField::Transmission { axis });
        }
        if !(d.torque_constant_nm_per_a[i] > 0.0) {
            return fail(DeviceField::TorqueConstant { axis });
        }
        let limit = d.current_limit_a[i];
        if !(limit > 0.0 && limit <= 20.0) {
            return fail(DeviceField::CurrentLimit { axis });
        }
    }
    if !(d.max_force_n > 0.0 && d.max_force_n <= 50.0) {
        return fail(DeviceField::MaxForce);
    }
    if !(d.tip_radius_m >= 0.0 && d.tip_radius_m <= 0.05) {
        return fail(DeviceField::TipRadius);
    }
    if !(d.max_tip_speed_m_s > 0.0) {
        return fail(DeviceField::MaxTipSpeed);
    }
    for (axis, &v) in (0..3u8).zip(&d.max_joint_speed) {
        if !(v > 0.0) {
            return fail(DeviceField::MaxJointSpeed { axis });
        }
    }
    if !(crate::LINK_TIMEOUT_MS_MIN..=crate::LINK_TIMEOUT_MS_MAX).contains(&d.link_timeout_ms) {
        return fail(DeviceField::LinkTimeout);
    }
    Ok(())
}

/// Validate a device calibration on its own (the same rules [`Bank::parse`] applies).
pub fn validate_device(d: &DeviceCalibration) -> Result<(), BankError> {
    check_device(d)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `Grid::clamped_cell` (f32 clamp, then truncation) is the 64-bit floor clamped to the
    /// grid, on random points, on every cell boundary and one ulp either side, and far outside.
    #[test]
    fn clamped_cell_is_the_clamped_floor() {
        let header = GridHeader {
            origin_m: [-0.0713, -0.0482, -0.003],
            cell_size_m: 0.006,
            dims: [18, 16, 9],
            reserved: 0,
        };
        let grid = Grid {
            header: &header,
            starts: &[],
            items: &[],
            clearance: &[],
            tri_starts: &[],
            tri_items: &[],
        };
        let want = |p: [f32; 3]| {
            let mut out = [0u16; 3];
            for a in 0..3 {
                let top = i64::from(header.dims[a]) - 1;
                let c = signed_cell(p[a], header.origin_m[a], header.cell_size_m);
                out[a] = c.clamp(0, top) as u16;
            }
            out
        };
        let mut rng = crate::fixtures::SplitMix64::new(0x2545_f491_4f6c_dd1d);
        let mut next = move || rng.unit_f32();
        let mut values = [0.0f32, 1.0e30, -1.0e30, f32::MAX, f32::MIN].to_vec();
        for k in -3..25 {
            let x = header.origin_m[0] + k as f32 * header.cell_size_m;
            values.extend([
                x,
                f32::from_bits(x.to_bits() + 1),
                f32::from_bits(x.to_bits() - 1),
            ]);
        }
        for _ in 0..20_000 {
            values.push(0.4 * next() - 0.2);
        }
        for (i, &x) in values.iter().enumerate() {
            let p = [
                x,
                values[(i * 7) % values.len()],
                values[(i * 13) % values.len()],
            ];
            assert_eq!(grid.clamped_cell(p), Some(want(p)), "{p:?}");
        }
        assert_eq!(grid.clamped_cell([0.0, f32::NAN, 0.0]), None);
        assert_eq!(grid.clamped_cell([0.0, 0.0, f32::INFINITY]), None);
    }

    #[test]
    fn signed_cell_floors() {
        assert_eq!(signed_cell(-0.5, 0.0, 1.0), -1);
        assert_eq!(signed_cell(-1.0, 0.0, 1.0), -1);
        assert_eq!(signed_cell(0.0, 0.0, 1.0), 0);
        assert_eq!(signed_cell(2.5, 0.0, 1.0), 2);
        // Saturates instead of overflowing (found by fuzzing), at the i32 range.
        assert_eq!(
            signed_cell(f32::NEG_INFINITY, 0.0, 1.0),
            i64::from(i32::MIN)
        );
        assert_eq!(signed_cell(-3.0e38, 0.0, 1.0e-30), i64::from(i32::MIN));
        assert_eq!(signed_cell(f32::INFINITY, 0.0, 1.0), i64::from(i32::MAX));
        assert_eq!(signed_cell(-65_536.5, 0.0, 1.0), -65_537);
    }

    #[test]
    fn spd_check() {
        assert!(is_spd::<3>(&[
            [2.0, 1.0, 0.0],
            [1.0, 2.0, 0.0],
            [0.0, 0.0, 1.0]
        ]));
        assert!(!is_spd::<3>(&[
            [1.0, 2.0, 0.0],
            [2.0, 1.0, 0.0],
            [0.0, 0.0, 1.0]
        ]));
        assert!(!is_spd::<3>(&[
            [f64::NAN, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0]
        ]));
    }
}
