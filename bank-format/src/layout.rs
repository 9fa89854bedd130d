//! The bank's on-flash records: header, section table and the fixed-size section records.
//!
//! Every record is `#[repr(C)]`, [`Pod`], built only from 4-byte fields (so its alignment is 4
//! and it has no padding), and stored little-endian. The byte layout is specified in `SPEC.md`
//! beside this crate; the constants here are the single source of truth that the spec quotes.

use bytemuck::{Pod, Zeroable};

/// The eight bytes a bank starts with.
pub const MAGIC: [u8; 8] = *b"HAPTBANK";
/// Major version this crate reads and writes. A reader rejects any other major version. 2: the
/// device record gained the speed thresholds; 3: the per-cell contact certificates (clearance
/// and candidate triangles) became required sections; 4: each coupled pair's block stored once
/// ([`SectionKind::CouplingStarts`]), narrower index arrays; 5: the per-triangle planes
/// ([`SectionKind::TrianglePlanes`]) became a required section; 6: the contact samples
/// ([`SampleHeader`]: the tool's patch compliance `W(p)` sampled over the reachable surface), whose
/// presence changes how the firmware renders a contact (`SPEC.md`, "Versioning"); 7: the
/// optional viscoelastic relaxation ([`Relaxation`]), whose presence changes the force the
/// firmware renders for the same penetration (a 6.x reader would skip it and render the
/// instantaneous elastic response for ever, up to `1 / g_inf` times too stiff in a hold); 8: the
/// device record gained the host link timeout ([`DeviceCalibration::link_timeout_ms`]).
pub const VERSION_MAJOR: u16 = 8;
/// Minor version this crate writes. Readers accept any minor version of their major version
/// (minor versions only add optional sections, which older readers skip). 8.0 has the optional
/// gravity section ([`SectionKind::Gravity`], added in 3.1).
pub const VERSION_MINOR: u16 = 0;
/// Size of [`BankHeader`] in bytes; the section table follows it.
pub const HEADER_LEN: usize = 32;
/// Size of one [`SectionEntry`] in bytes.
pub const SECTION_ENTRY_LEN: usize = 16;
/// Upper bound on the number of section table entries.
pub const MAX_SECTIONS: usize = 32;
/// Every section offset, and the bank's total length, is a multiple of this.
pub const SECTION_ALIGN: usize = 8;
/// The input slice must start at an address that is a multiple of this (the largest alignment
/// of any element type in the bank).
pub const BANK_ALIGN: usize = 4;
/// Byte offset of the CRC field in the header.
pub const CRC_OFFSET: usize = 20;
/// Largest number of nodes in the reachable region R (node indices are `u16`).
pub const MAX_NODES: usize = u16::MAX as usize;
/// Largest number of triangles (the cells' candidate lists and the node-triangle items hold
/// `u16` triangle indices).
pub const MAX_TRIANGLES: usize = u16::MAX as usize;
/// A cell's candidate triangles are those whose bounding box, widened by this many cells on
/// every side, meets the cell (`SPEC.md`, "cell candidates"): a path piece of Chebyshev length
/// at most [`PIECE_CELLS`] cells can only cross them.
pub const CANDIDATE_WIDEN_CELLS: f32 = 33.0 / 64.0;
/// A triangle occupies the cells its bounding box, widened by this many cells on every side,
/// meets (the margin absorbs the rounding of the cell rule; `SPEC.md`, "cell clearance").
pub const OCCUPIED_WIDEN_CELLS: f32 = 1.0 / 64.0;
/// Longest path piece, Chebyshev norm, in cells, that the candidate lists cover (with margin
/// for rounding and the clipping pad: [`CANDIDATE_WIDEN_CELLS`] is 0.516).
pub const PIECE_CELLS: f32 = 0.45;
/// Most candidate triangles one grid cell may list (`SPEC.md`, check 10, `TooManyCandidates`).
/// The firmware's detection tests a path piece's cell's candidates, and a tick cuts its path
/// into at most `firmware::contact::MAX_DETECT_PIECES` pieces, so this bounds the detection
/// of any tick; the firmware's tick budget is derived from it (`SPEC.md`, "Limits the tick's
/// cost rests on"). The shipped liver's 6 mm cells list at most 28.
pub const MAX_CELL_CANDIDATES: usize = 128;
/// Most neighbour entries (coupled nodes) of one node (`SPEC.md`, check 12,
/// `TooManyNeighbours`): the nodal patch's quadrature scans the nearest node's row, the
/// assembly of `B C_SS B^T` walks each patch node's stored row. The shipped nodal liver's
/// "tool" couplings reach 34.
pub const MAX_NODE_NEIGHBOURS: usize = 128;
/// Most triangles one node belongs to (`SPEC.md`, check 9, `TooManyTriangles`): each step of a
/// surface walk (the contact's slide, the patch's quadrature points) finds the triangle across
/// an edge in a vertex's list. A surface mesh's vertices have about 6; the shipped liver at
/// most 10.
pub const MAX_NODE_TRIANGLES: usize = 16;
/// Largest lattice level of the contact samples ([`SampleHeader::level`]): a triangle holds
/// `(level + 1) (level + 2) / 2` samples.
pub const MAX_SAMPLE_LEVEL: u32 = 8;
/// Most coefficients a tissue law may have (Chebyshev degree <= 15).
pub const MAX_LAW_COEFFS: usize = 16;

/// The CRC the bank (and the link frames) use: CRC-32/ISO-HDLC, the "IEEE" CRC-32 of zlib,
/// Ethernet and PNG (poly 0x04C11DB7 reflected, init and final XOR 0xFFFFFFFF; check value of
/// `"123456789"` is 0xCBF43926).
pub const CRC32: crc::Crc<u32> = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC);

/// The fixed 32-byte header at offset 0.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Eq, Pod, Zeroable)]
pub struct BankHeader {
    /// [`MAGIC`].
    pub magic: [u8; 8],
    /// [`VERSION_MAJOR`] of the writer.
    pub version_major: u16,
    /// [`VERSION_MINOR`] of the writer.
    pub version_minor: u16,
    /// Bytes before the section table: [`HEADER_LEN`].
    pub header_len: u16,
    /// Number of [`SectionEntry`] records that follow the header (at most [`MAX_SECTIONS`]).
    pub section_count: u16,
    /// Length of the whole bank in bytes, a multiple of [`SECTION_ALIGN`]. The input slice may be
    /// longer (a flash region is erased to 0xFF past the bank); bytes past it are ignored.
    pub total_len: u32,
    /// CRC-32 ([`CRC32`]) of the first `total_len` bytes with this field read as zero.
    pub crc32: u32,
    /// Reserved, zero.
    pub flags: u32,
    /// Reserved, zero.
    pub reserved: u32,
}

/// One entry of the section table.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Eq, Pod, Zeroable)]
pub struct SectionEntry {
    /// [`SectionKind::code`].
    pub kind: u32,
    /// Offset of the section's first byte from the bank's start; a multiple of
    /// [`SECTION_ALIGN`].
    pub offset: u32,
    /// Length of the section in bytes: exactly `count` times the element size.
    pub len: u32,
    /// Number of elements.
    pub count: u32,
}

/// What a section holds. The numeric codes are part of the format (see `SPEC.md`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum SectionKind {
    /// Pseudo-kind naming the header and section table in errors; code 0 must not appear in the
    /// section table.
    Header,
    /// [`BankMeta`], one element.
    Meta,
    /// Node positions `[f32; 3]` in m, one per node of R.
    Positions,
    /// Node id in the host mesh (`u32`), one per node of R.
    MeshIds,
    /// Triangles of R's surface, `[u16; 3]` node indices, counter-clockwise seen from outside.
    Triangles,
    /// [`TrianglePlane`] per triangle, in [`SectionKind::Triangles`]' order (5.0).
    TrianglePlanes,
    /// CSR row starts (`u32`, n + 1) of the node-to-triangle adjacency.
    NodeTriStarts,
    /// CSR items (`u16` triangle indices) of the node-to-triangle adjacency.
    NodeTriItems,
    /// [`GridHeader`], one element.
    Grid,
    /// CSR bucket starts (`u16`, cells + 1) of the collision grid.
    GridStarts,
    /// CSR bucket items (`u16` node indices) of the collision grid.
    GridItems,
    /// Per grid cell (`u8`, cells): a lower bound, in cells (Chebyshev), of the distance from
    /// the cell to every cell a triangle occupies.
    CellClearance,
    /// CSR starts (`u32`, cells + 1) of the cells' candidate triangles.
    CellTriStarts,
    /// CSR items (`u16` triangle indices, ascending per cell) of the cells' candidate triangles.
    CellTriItems,
    /// Self-compliance `C_kk` per node, `[f32; 6]` = xx, xy, xz, yy, yz, zz, in m/N.
    Ckk,
    /// CSR row starts (`u32`, n + 1) of the neighbour lists.
    NeighbourStarts,
    /// Neighbour node indices (`u16`), each row strictly ascending, both directions.
    NeighbourIndex,
    /// Coupling blocks `C_kl`, `[f32; 9]` row-major, m/N, one per coupled pair `k < l`, in node
    /// `k`'s row order (`C_lk = C_kl^T` is not stored).
    NeighbourCkl,
    /// CSR starts (`u32`, n + 1) of each node's blocks in [`SectionKind::NeighbourCkl`] (or
    /// [`SectionKind::NeighbourCkl16`]): those of its row's entries `l > k` (4.0).
    CouplingStarts,
    /// The same blocks as [`SectionKind::NeighbourCkl`], stored as [`Ckl16`] (16-bit mantissas
    /// and one exponent per block); a bank holds exactly one of the two (4.0).
    NeighbourCkl16,
    /// [`LawRecord`], one element: the tissue force law Q.
    TissueLaw,
    /// [`DeviceCalibration`], one element.
    Device,
    /// [`GravityCompensation`], one element; optional (2.1): absent means no compensation.
    Gravity,
    /// [`SampleHeader`], one element; optional (6.0), together with
    /// [`SectionKind::TriangleSamples`] and [`SectionKind::PatchCompliance`]: present means the
    /// firmware renders a contact from the sampled patch compliance.
    SampleHeader,
    /// Per triangle (in [`SectionKind::Triangles`]' order), the `u16` indices into
    /// [`SectionKind::PatchCompliance`] of its lattice points (`SPEC.md`, "contact samples").
    TriangleSamples,
    /// Patch compliance samples `W`, `[f32; 6]` = xx, xy, xz, yy, yz, zz, m/N, each symmetric
    /// positive definite.
    PatchCompliance,
    /// [`Relaxation`], one element; optional (7.0): present means the firmware renders the
    /// quasi-linear viscoelastic force (`SPEC.md`, "viscoelastic relaxation"), absent the
    /// elastic one.
    Relaxation,
    /// A section of a later minor version that this reader does not know; skipped.
    Unknown(u32),
}

impl SectionKind {
    /// The sections a valid bank of this major version must contain, in the order the writer
    /// lays them out; besides these, exactly one of [`SectionKind::NeighbourCkl`] and
    /// [`SectionKind::NeighbourCkl16`] (the storage precision, [`Precision`]).
    pub const REQUIRED: [SectionKind; 19] = [
        SectionKind::Meta,
        SectionKind::Positions,
        SectionKind::MeshIds,
        SectionKind::Triangles,
        SectionKind::TrianglePlanes,
        SectionKind::NodeTriStarts,
        SectionKind::NodeTriItems,
        SectionKind::Grid,
        SectionKind::GridStarts,
        SectionKind::GridItems,
        SectionKind::CellClearance,
        SectionKind::CellTriStarts,
        SectionKind::CellTriItems,
        SectionKind::Ckk,
        SectionKind::NeighbourStarts,
        SectionKind::NeighbourIndex,
        SectionKind::CouplingStarts,
        SectionKind::TissueLaw,
        SectionKind::Device,
    ];

    /// The kind with numeric code `code`.
    pub const fn from_code(code: u32) -> SectionKind {
        match code {
            0 => SectionKind::Header,
            1 => SectionKind::Meta,
            2 => SectionKind::Positions,
            3 => SectionKind::MeshIds,
            4 => SectionKind::Triangles,
            5 => SectionKind::NodeTriStarts,
            6 => SectionKind::NodeTriItems,
            7 => SectionKind::Grid,
            8 => SectionKind::GridStarts,
            9 => SectionKind::GridItems,
            10 => SectionKind::Ckk,
            11 => SectionKind::NeighbourStarts,
            12 => SectionKind::NeighbourIndex,
            13 => SectionKind::NeighbourCkl,
            14 => SectionKind::TissueLaw,
            15 => SectionKind::Device,
            16 => SectionKind::CellClearance,
            17 => SectionKind::CellTriStarts,
            18 => SectionKind::CellTriItems,
            19 => SectionKind::CouplingStarts,
            20 => SectionKind::NeighbourCkl16,
            21 => SectionKind::TrianglePlanes,
            22 => SectionKind::SampleHeader,
            23 => SectionKind::TriangleSamples,
            24 => SectionKind::Gravity,
            25 => SectionKind::PatchCompliance,
            26 => SectionKind::Relaxation,
            other => SectionKind::Unknown(other),
        }
    }

    /// The numeric code stored in [`SectionEntry::kind`].
    pub const fn code(self) -> u32 {
        match self {
            SectionKind::Header => 0,
            SectionKind::Meta => 1,
            SectionKind::Positions => 2,
            SectionKind::MeshIds => 3,
            SectionKind::Triangles => 4,
            SectionKind::NodeTriStarts => 5,
            SectionKind::NodeTriItems => 6,
            SectionKind::Grid => 7,
            SectionKind::GridStarts => 8,
            SectionKind::GridItems => 9,
            SectionKind::Ckk => 10,
            SectionKind::NeighbourStarts => 11,
            SectionKind::NeighbourIndex => 12,
            SectionKind::NeighbourCkl => 13,
            SectionKind::TissueLaw => 14,
            SectionKind::Device => 15,
            SectionKind::CellClearance => 16,
            SectionKind::CellTriStarts => 17,
            SectionKind::CellTriItems => 18,
            SectionKind::CouplingStarts => 19,
            SectionKind::NeighbourCkl16 => 20,
            SectionKind::TrianglePlanes => 21,
            SectionKind::SampleHeader => 22,
            SectionKind::TriangleSamples => 23,
            SectionKind::Gravity => 24,
            SectionKind::PatchCompliance => 25,
            SectionKind::Relaxation => 26,
            SectionKind::Unknown(code) => code,
        }
    }

    /// Size in bytes of one element of this section (`None` for unknown kinds, whose elements
    /// this reader does not interpret, and for the header pseudo-kind).
    pub const fn element_size(self) -> Option<usize> {
        Some(match self {
            SectionKind::Header | SectionKind::Unknown(_) => return None,
            SectionKind::Meta => core::mem::size_of::<BankMeta>(),
            SectionKind::Positions => 12,
            SectionKind::MeshIds => 4,
            SectionKind::Triangles => 6,
            SectionKind::TrianglePlanes => core::mem::size_of::<TrianglePlane>(),
            SectionKind::NodeTriStarts => 4,
            SectionKind::NodeTriItems => 2,
            SectionKind::Grid => core::mem::size_of::<GridHeader>(),
            SectionKind::GridStarts => 2,
            SectionKind::GridItems => 2,
            SectionKind::CellClearance => 1,
            SectionKind::CellTriStarts => 4,
            SectionKind::CellTriItems => 2,
            SectionKind::Ckk => 24,
            SectionKind::NeighbourStarts => 4,
            SectionKind::NeighbourIndex => 2,
            SectionKind::NeighbourCkl => 36,
            SectionKind::CouplingStarts => 4,
            SectionKind::NeighbourCkl16 => core::mem::size_of::<Ckl16>(),
            SectionKind::TissueLaw => core::mem::size_of::<LawRecord>(),
            SectionKind::Device => core::mem::size_of::<DeviceCalibration>(),
            SectionKind::Gravity => core::mem::size_of::<GravityCompensation>(),
            SectionKind::SampleHeader => core::mem::size_of::<SampleHeader>(),
            SectionKind::TriangleSamples => 2,
            SectionKind::PatchCompliance => 24,
            SectionKind::Relaxation => core::mem::size_of::<Relaxation>(),
        })
    }

    /// A short lower-case name, used by `Display`.
    pub const fn name(self) -> &'static str {
        match self {
            SectionKind::Header => "header",
            SectionKind::Meta => "meta",
            SectionKind::Positions => "positions",
            SectionKind::MeshIds => "mesh ids",
            SectionKind::Triangles => "triangles",
            SectionKind::TrianglePlanes => "triangle planes",
            SectionKind::NodeTriStarts => "node-triangle starts",
            SectionKind::NodeTriItems => "node-triangle items",
            SectionKind::Grid => "grid",
            SectionKind::GridStarts => "grid starts",
            SectionKind::GridItems => "grid items",
            SectionKind::CellClearance => "cell clearance",
            SectionKind::CellTriStarts => "cell candidate starts",
            SectionKind::CellTriItems => "cell candidate items",
            SectionKind::Ckk => "C_kk",
            SectionKind::NeighbourStarts => "neighbour starts",
            SectionKind::NeighbourIndex => "neighbour index",
            SectionKind::NeighbourCkl => "C_kl",
            SectionKind::CouplingStarts => "coupling starts",
            SectionKind::NeighbourCkl16 => "C_kl, 16-bit",
            SectionKind::TissueLaw => "tissue law",
            SectionKind::Device => "device",
            SectionKind::Gravity => "gravity",
            SectionKind::SampleHeader => "sample header",
            SectionKind::TriangleSamples => "triangle samples",
            SectionKind::PatchCompliance => "patch compliance",
            SectionKind::Relaxation => "viscoelastic relaxation",
            SectionKind::Unknown(_) => "unknown",
        }
    }
}

impl core::fmt::Display for SectionKind {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            SectionKind::Unknown(code) => write!(f, "unknown section {code}"),
            other => f.write_str(other.name()),
        }
    }
}

/// The contact samples' header (section [`SectionKind::SampleHeader`], `SPEC.md` "contact
/// samples"): each triangle of R carries a lattice of `level` steps per side, whose points hold
/// the patch compliance `W` of the scene's tool centred there.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct SampleHeader {
    /// Lattice steps per triangle side, `1..=`[`MAX_SAMPLE_LEVEL`].
    pub level: u32,
    /// The tool radius the samples were computed for, m (finite, `>= 0`; informative: the
    /// firmware renders from the samples whatever the device record's radius).
    pub tip_radius_m: f32,
    /// Reserved, zero.
    pub reserved: [u32; 2],
}

/// Bank-wide metadata (section [`SectionKind::Meta`]).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct BankMeta {
    /// Opaque 64-bit scene identity chosen by the host (e.g. a hash of the scene file), low word
    /// first, so the host can check that a device runs the bank of the scene it displays.
    pub scene_id: [u32; 2],
    /// Truncation radius in m: every pair of nodes of R closer than this (see `SPEC.md` for the
    /// exact rule) has its `C_kl` in the neighbour lists. Finite, `>= 0`.
    pub truncation_radius_m: f32,
    /// Reserved, zero.
    pub reserved: u32,
}

impl BankMeta {
    /// [`BankMeta::scene_id`] as one `u64`.
    pub const fn scene_id(&self) -> u64 {
        (self.scene_id[0] as u64) | ((self.scene_id[1] as u64) << 32)
    }
}

/// The collision grid's geometry (section [`SectionKind::Grid`]).
///
/// Cell `(i, j, k)` covers `origin + cell_size * [i, i+1) x [j, j+1) x [k, k+1)` and has linear
/// index `i + dims[0] * (j + dims[1] * k)`.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct GridHeader {
    /// Corner of cell (0, 0, 0), m.
    pub origin_m: [f32; 3],
    /// Edge length of the cubic cells, m, finite and `> 0`.
    pub cell_size_m: f32,
    /// Number of cells along x, y, z; each `>= 1`.
    pub dims: [u16; 3],
    /// Reserved, zero.
    pub reserved: u16,
}

/// Relative tolerance of the reader's check of a [`TrianglePlane`] against its triangle's
/// positions (`SPEC.md`, "triangle planes" and check 9): 16 times the writer's f32 rounding.
pub const PLANE_TOL: f64 = 1.0e-6;

/// A triangle's plane (section [`SectionKind::TrianglePlanes`], `SPEC.md` "triangle planes"):
/// with `n = (b - a) x (c - a)` from the triangle's stored positions, `m = n / |n|^2` and `off =
/// m . a`. The plane value `s(p) = m . p - off = (p - a) . n / |n|^2` has the sign of `(p - a)
/// . n` (>= 0 outside), and the barycentric coordinates of the projection of `x` are `k1 = ((x -
/// a) x (c - a)) . m`, `k2 = ((b - a) x (x - a)) . m`, `k0 = 1 - k1 - k2`: no division, and no
/// vertex needed for the plane test.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct TrianglePlane {
    /// `n / |n|^2`, 1/m: the outward unit normal divided by `|n|`, twice the triangle's area.
    pub m: [f32; 3],
    /// `m . a` (dimensionless).
    pub off: f32,
}

impl TrianglePlane {
    /// The plane value `s(p) = m . p - off` in f32 (`(m0 p0 + m1 p1) + m2 p2`, then `- off`).
    #[inline]
    pub fn value(&self, p: [f32; 3]) -> f32 {
        self.m[0] * p[0] + self.m[1] * p[1] + self.m[2] * p[2] - self.off
    }
}

/// Storage precision of the coupling blocks `C_kl` (`SPEC.md`, "16-bit blocks").
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Default)]
pub enum Precision {
    /// IEEE-754 single precision, [`SectionKind::NeighbourCkl`], 36 bytes a block.
    #[default]
    F32,
    /// Block floating point, [`SectionKind::NeighbourCkl16`], 20 bytes a block: each entry off
    /// by at most `max |C_kl| / 32767`.
    Bfp16,
}

impl Precision {
    /// Every precision.
    pub const ALL: [Precision; 2] = [Precision::F32, Precision::Bfp16];

    /// The name a scene file uses: "f32" or "bfp16".
    pub const fn name(self) -> &'static str {
        match self {
            Precision::F32 => "f32",
            Precision::Bfp16 => "bfp16",
        }
    }

    /// The precision named `name` ([`Precision::name`]).
    pub fn from_name(name: &str) -> Option<Precision> {
        Precision::ALL.into_iter().find(|p| p.name() == name)
    }
}

/// Smallest exponent of a [`Ckl16`] (its `2^e` is then the smallest normal f32 power of two).
pub const CKL16_EXP_MIN: i16 = -126;
/// Largest exponent of a [`Ckl16`] (`32767 * 2^112` is below `f32::MAX`).
pub const CKL16_EXP_MAX: i16 = 112;

/// A coupling block in block floating point (section [`SectionKind::NeighbourCkl16`]):
/// `C_kl[i] = mantissa[i] * 2^exponent`, row-major, m/N. 2-byte fields, 20 bytes.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Eq, Pod, Zeroable)]
pub struct Ckl16 {
    /// Row-major mantissas.
    pub mantissa: [i16; 9],
    /// The block's exponent, in [`CKL16_EXP_MIN`]`..=`[`CKL16_EXP_MAX`] in a valid bank.
    pub exponent: i16,
}

impl Ckl16 {
    /// The block in f32, row-major: exact for an exponent in range (at most 16 significant
    /// bits, a normal number or 0). `2^e` is built from its exponent bits (no libm); an
    /// exponent out of range is clamped (the reader rejects such banks).
    pub fn decode(&self) -> [f32; 9] {
        let scale = self.scale();
        self.mantissa.map(|m| f32::from(m) * scale)
    }

    /// The block's `2^e`, built from its exponent bits (clamped like [`Ckl16::decode`]).
    pub fn scale(&self) -> f32 {
        let e = self.exponent.clamp(CKL16_EXP_MIN, CKL16_EXP_MAX);
        f32::from_bits(((i32::from(e) + 127) as u32) << 23)
    }
}

/// Law kind code: `Q(f) = c0 + c1 f` (two coefficients, `c1 > 0`).
pub const LAW_LINEAR: u32 = 1;
/// Law kind code: `Q(f) = sum_i c_i T_i(x)` with `x = (2 f - (f_min + f_max)) / (f_max - f_min)`
/// on the domain, continued linearly outside it.
pub const LAW_CHEBYSHEV: u32 = 2;

/// The tissue force law Q as stored (section [`SectionKind::TissueLaw`]); see
/// [`crate::TissueLaw`] for the validated, evaluable form.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct LawRecord {
    /// [`LAW_LINEAR`] or [`LAW_CHEBYSHEV`].
    pub kind: u32,
    /// Number of coefficients used, `1..=16` (exactly 2 for a linear law).
    pub coeff_count: u32,
    /// Fitted domain `[f_min, f_max]` of the linear force magnitude, N; `0 <= f_min < f_max`.
    pub domain_n: [f32; 2],
    /// Coefficients; entries past `coeff_count` are zero. Linear: `[c0 (N), c1 (1)]`.
    /// Chebyshev: `c_i` in N.
    pub coeffs: [f32; MAX_LAW_COEFFS],
}

/// Calibration of the laparoscopic gimbal (section [`SectionKind::Device`]).
///
/// Joints are indexed 0 = pitch (rad), 1 = yaw (rad), 2 = insertion (m, distance from the
/// fulcrum to the tool tip along the shaft). Forward kinematics (all in the scene frame of the
/// positions):
///
/// `tip = fulcrum + insertion * Rot(yaw_axis, yaw) * Rot(pitch_axis, pitch) * shaft_axis`
///
/// where `Rot(a, t)` is the right-handed rotation by `t` about the unit axis `a` (yaw is the
/// outer, ground-fixed gimbal axis, pitch the inner one, given at rest). Encoder counts `n`
/// map to joint values `q = home + 2 pi n / (counts_per_rev * transmission)` (for insertion the
/// `2 pi n / counts_per_rev` motor radians divide by the transmission in rad/m). Motor current
/// for a joint effort `tau` (N m, or N for insertion) is
/// `i = tau / (transmission * torque_constant)`, then clamped to `current_limit`.
///
/// The speed thresholds are the scene's: while armed, the firmware faults (`Overspeed`) when the
/// tip or a joint moved faster than them over the last tick.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct DeviceCalibration {
    /// Fulcrum (trocar point) in m.
    pub fulcrum_m: [f32; 3],
    /// Unit vector along the shaft from the fulcrum towards the tip, at pitch = yaw = 0.
    pub shaft_axis: [f32; 3],
    /// Unit pitch axis at rest, orthogonal to `shaft_axis`.
    pub pitch_axis: [f32; 3],
    /// Unit yaw axis (ground-fixed), orthogonal to `shaft_axis` and `pitch_axis`.
    pub yaw_axis: [f32; 3],
    /// Lower joint limits: pitch rad, yaw rad, insertion m.
    pub joint_min: [f32; 3],
    /// Upper joint limits: pitch rad, yaw rad, insertion m. `min < max`, angles within
    /// `[-pi, pi]`, `0 <= insertion min`.
    pub joint_max: [f32; 3],
    /// Joint values at which the encoders read zero after a zero-encoders command (the rest pose
    /// on the dock), inside the limits.
    pub home_joint: [f32; 3],
    /// Encoder counts per motor revolution, per joint (quadrature edges counted), `> 0`.
    pub counts_per_rev: [u32; 3],
    /// Transmission: motor radians per joint radian (pitch, yaw) or per metre of insertion
    /// (rad/m). Its sign encodes the motor's direction; `|value| > 0`.
    pub transmission: [f32; 3],
    /// Motor torque constants, N m / A, `> 0`.
    pub torque_constant_nm_per_a: [f32; 3],
    /// Hard current limits per motor, A, in `(0, 20]`.
    pub current_limit_a: [f32; 3],
    /// Largest tip force the device renders, N, in `(0, 50]`.
    pub max_force_n: f32,
    /// Radius of the tool tip, m, in `[0, 0.05]`; contacts spread over the nodes under it.
    pub tip_radius_m: f32,
    /// Tip speed above which the armed device disables its forces (`Overspeed`), m/s, `> 0`.
    pub max_tip_speed_m_s: f32,
    /// Joint speeds above which the armed device disables its forces (`Overspeed`): pitch rad/s,
    /// yaw rad/s, insertion m/s, each `> 0`.
    pub max_joint_speed: [f32; 3],
    /// Host link timeout, ms, in [`LINK_TIMEOUT_MS_MIN`]`..=`[`LINK_TIMEOUT_MS_MAX`]: the armed
    /// device faults (`LinkSilent`) when no valid host frame arrived for longer (8.0).
    pub link_timeout_ms: u32,
}

/// Shortest [`DeviceCalibration::link_timeout_ms`]: two and a half of the host's 2 ms
/// heartbeat periods.
pub const LINK_TIMEOUT_MS_MIN: u32 = 5;
/// Longest [`DeviceCalibration::link_timeout_ms`]: beyond it a hand pushed by a force the host
/// can no longer stop moves centimetres (at the 1 m/s overspeed threshold, 10 cm in 100 ms).
pub const LINK_TIMEOUT_MS_MAX: u32 = 100;
/// The scene's default [`DeviceCalibration::link_timeout_ms`], from the host's measured
/// heartbeat jitter (`host bench heartbeat`; `docs/scenes-and-banks.md`, "link timeout").
pub const DEFAULT_LINK_TIMEOUT_MS: u32 = 50;

/// Number of coefficients of [`GravityCompensation`].
pub const GRAVITY_COEFFS: usize = 8;
/// Largest magnitude of a gravity coefficient, N m or N (`SPEC.md`, "gravity").
pub const GRAVITY_COEFF_MAX: f32 = 100.0;

/// Feed-forward for the instrument's own weight (section [`SectionKind::Gravity`], optional).
///
/// The effort that holds the instrument still is the gradient of its potential energy
/// `tau_g(q) = dV/dq` with (`cp, sp, cy, sy`: cosine and sine of pitch and yaw, `s` the
/// insertion in m)
///
/// `V = -(a_c + s b_c) cp cy - (a_s + s b_s) cp sy - (a_p + s b_p) sp - d_c cy - d_s sy`
///
/// `b` is the sliding shaft's weight vector in the device frame (N), `a` its moment about the
/// fulcrum at zero insertion plus parts that pitch without sliding (N m), `d` the parts that
/// only yaw (N m). See `SPEC.md` ("gravity") for the derivation and the three efforts.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct GravityCompensation {
    /// `[a_c, a_s, a_p, b_c, b_s, b_p, d_c, d_s]`: N m, N m, N m, N, N, N, N m, N m; each
    /// finite with magnitude at most [`GRAVITY_COEFF_MAX`].
    pub coeffs: [f32; GRAVITY_COEFFS],
}

impl GravityCompensation {
    /// The efforts `tau_g` (pitch N m, yaw N m, insertion N) given `(sin, cos)` of pitch and
    /// yaw and the insertion `s` in m: the gradient of `V` above (`SPEC.md`, "gravity").
    pub fn efforts(&self, pitch: (f32, f32), yaw: (f32, f32), s: f32) -> [f32; 3] {
        let [a_c, a_s, a_p, b_c, b_s, b_p, d_c, d_s] = self.coeffs;
        let ((sp, cp), (sy, cy)) = (pitch, yaw);
        let (mc, ms, mp) = (a_c + s * b_c, a_s + s * b_s, a_p + s * b_p);
        [
            mc * sp * cy + ms * sp * sy - mp * cp,
            mc * cp * sy - ms * cp * cy + d_c * sy - d_s * cy,
            -(b_c * cp * cy + b_s * cp * sy + b_p * sp),
        ]
    }
}

/// Most Prony terms of the reduced relaxation function ([`Relaxation`]).
pub const MAX_PRONY_TERMS: usize = 4;
/// Shortest relaxation time a bank may hold, s: two ticks of the 1 kHz loop. A faster term
/// has relaxed before the next tick can render it (its force is gone within the tick it
/// appeared in: instantaneous elasticity the scene should fold into `Q` instead).
pub const RELAXATION_TAU_MIN_S: f32 = 2.0e-3;
/// Longest relaxation time a bank may hold, s: an hour. A slower term does not relax within a
/// session (it is elasticity), and its per-tick decay `dt / tau < 2.8e-7` is a few f32 ulps
/// of 1, so the firmware could not render it faithfully anyway.
pub const RELAXATION_TAU_MAX_S: f32 = 3600.0;

/// The reduced relaxation function of Fung's quasi-linear viscoelasticity (section
/// [`SectionKind::Relaxation`], optional, 7.0; `SPEC.md`, "viscoelastic relaxation"):
///
/// `G(t) = g_inf + sum_k g_k exp(-t / tau_k)`, `G(0) = 1`, so `g_inf = 1 - sum_k g_k`,
///
/// the force on the tissue being `F(t) = integral_0^t G(t - s) dQ_e(s)`, with `Q_e` the
/// elastic law's force (the tissue law `Q` of the linear model's force) taken as the
/// instantaneous response.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct Relaxation {
    /// Number of Prony terms, `1..=`[`MAX_PRONY_TERMS`].
    pub count: u32,
    /// Reserved, zero.
    pub reserved: u32,
    /// `g_k`, dimensionless, each `>= 0`, `sum < 1`; entries past `count` zero.
    pub g: [f32; MAX_PRONY_TERMS],
    /// `tau_k`, s, from [`RELAXATION_TAU_MIN_S`] to [`RELAXATION_TAU_MAX_S`]; entries past
    /// `count` zero.
    pub tau_s: [f32; MAX_PRONY_TERMS],
}

impl Relaxation {
    /// The terms `(g_k, tau_k)` in use (the first `count`, at most [`MAX_PRONY_TERMS`]).
    pub fn terms(&self) -> impl Iterator<Item = (f32, f32)> + '_ {
        let n = (self.count as usize).min(MAX_PRONY_TERMS);
        self.g
            .iter()
            .copied()
            .zip(self.tau_s.iter().copied())
            .take(n)
    }

    /// `g_inf = 1 - sum_k g_k`: the share of the elastic force left after full relaxation
    /// (> 0 in a valid bank).
    pub fn g_inf(&self) -> f32 {
        1.0 - self.terms().map(|(g, _)| g).sum::<f32>()
    }
}

/// The CRC-32 of `bank` as the header's `crc32` field defines it: over all of `bank` with the
/// four bytes at [`CRC_OFFSET`] taken as zero. `bank` must be exactly the bank (`total_len`
/// bytes); a slice shorter than the header gives the CRC of what there is.
pub fn bank_crc(bank: &[u8]) -> u32 {
    let mut digest = CRC32.digest();
    match (bank.get(..CRC_OFFSET), bank.get(CRC_OFFSET + 4..)) {
        (Some(head), Some(tail)) => {
            digest.update(head);
            digest.update(&[0; 4]);
            digest.update(tail);
        }
        _ => digest.update(bank),
    }
    digest.finalize()
}

/// Recompute and store the CRC of a bank in place (for tools that patch a bank, e.g. new device
/// calibration, without rebuilding it). Uses the header's `total_len`; returns `false` (and
/// changes nothing) when the header is missing or `total_len` exceeds the slice.
pub fn reseal(bytes: &mut [u8]) -> bool {
    let total = match bytes.get(16..20).and_then(|b| <[u8; 4]>::try_from(b).ok()) {
        Some(b) => u32::from_le_bytes(b) as usize,
        None => return false,
    };
    if total < HEADER_LEN {
        return false;
    }
    let Some(bank) = bytes.get_mut(..total) else {
        return false;
    };
    let crc = bank_crc(bank);
    match bank.get_mut(CRC_OFFSET..CRC_OFFSET + 4) {
        Some(field) => {
            field.copy_from_slice(&crc.to_le_bytes());
            true
        }
        None => false,
    }
}

// The layout is fixed: fail the build if a record's size drifts.
const _: () = {
    assert!(core::mem::size_of::<BankHeader>() == HEADER_LEN);
    assert!(core::mem::size_of::<SectionEntry>() == SECTION_ENTRY_LEN);
    assert!(core::mem::size_of::<BankMeta>() == 16);
    assert!(core::mem::size_of::<GridHeader>() == 24);
    assert!(core::mem::size_of::<LawRecord>() == 80);
    assert!(core::mem::size_of::<DeviceCalibration>() == 160);
    assert!(core::mem::align_of::<DeviceCalibration>() == BANK_ALIGN);
    assert!(core::mem::size_of::<GravityCompensation>() == 32);
    assert!(core::mem::size_of::<Ckl16>() == 20);
    assert!(core::mem::size_of::<TrianglePlane>() == 16);
    assert!(core::mem::size_of::<Relaxation>() == 40);
};
