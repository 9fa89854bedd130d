//! Every way a bank can fail validation, one variant each.

use crate::layout::SectionKind;
use core::fmt;

/// Which device calibration value is out of range (see [`crate::DeviceCalibration`] for the
/// rules). `axis` is 0 = pitch, 1 = yaw, 2 = insertion.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DeviceField {
    /// `shaft_axis` is not a unit vector (|len - 1| > 1e-3).
    ShaftAxis,
    /// `pitch_axis` is not a unit vector.
    PitchAxis,
    /// `yaw_axis` is not a unit vector.
    YawAxis,
    /// The three axes are not pairwise orthogonal (|dot| > 1e-3).
    AxesNotOrthogonal,
    /// `joint_min[axis] >= joint_max[axis]`, an angle limit outside `[-pi, pi]`, or a negative
    /// insertion limit.
    JointRange {
        /// Joint index.
        axis: u8,
    },
    /// `home_joint[axis]` outside the joint's limits.
    HomeJoint {
        /// Joint index.
        axis: u8,
    },
    /// `counts_per_rev[axis] == 0`.
    CountsPerRev {
        /// Joint index.
        axis: u8,
    },
    /// `transmission[axis]` is zero (or smaller in magnitude than 1e-6).
    Transmission {
        /// Joint index.
        axis: u8,
    },
    /// `torque_constant_nm_per_a[axis] <= 0`.
    TorqueConstant {
        /// Joint index.
        axis: u8,
    },
    /// `current_limit_a[axis]` not in `(0, 20]` A.
    CurrentLimit {
        /// Joint index.
        axis: u8,
    },
    /// `max_force_n` not in `(0, 50]` N.
    MaxForce,
    /// `tip_radius_m` not in `[0, 0.05]` m.
    TipRadius,
    /// `max_tip_speed_m_s <= 0`.
    MaxTipSpeed,
    /// `max_joint_speed[axis] <= 0`.
    MaxJointSpeed {
        /// Joint index.
        axis: u8,
    },
    /// `link_timeout_ms` not in [`crate::LINK_TIMEOUT_MS_MIN`]`..=`[`crate::LINK_TIMEOUT_MS_MAX`].
    LinkTimeout,
}

impl fmt::Display for DeviceField {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            DeviceField::ShaftAxis => f.write_str("shaft axis is not a unit vector"),
            DeviceField::PitchAxis => f.write_str("pitch axis is not a unit vector"),
            DeviceField::YawAxis => f.write_str("yaw axis is not a unit vector"),
            DeviceField::AxesNotOrthogonal => {
                f.write_str("shaft, pitch and yaw axes are not orthogonal")
            }
            DeviceField::JointRange { axis } => write!(f, "joint {axis} has an invalid range"),
            DeviceField::HomeJoint { axis } => {
                write!(f, "home value of joint {axis} is outside its range")
            }
            DeviceField::CountsPerRev { axis } => {
                write!(f, "encoder counts per revolution of joint {axis} is zero")
            }
            DeviceField::Transmission { axis } => {
                write!(f, "transmission of joint {axis} is zero")
            }
            DeviceField::TorqueConstant { axis } => {
                write!(f, "torque constant of motor {axis} is not positive")
            }
            DeviceField::CurrentLimit { axis } => {
                write!(f, "current limit of motor {axis} is not in (0, 20] A")
            }
            DeviceField::MaxForce => f.write_str("maximum force is not in (0, 50] N"),
            DeviceField::TipRadius => f.write_str("tip radius is not in [0, 0.05] m"),
            DeviceField::MaxTipSpeed => f.write_str("maximum tip speed is not positive"),
            DeviceField::MaxJointSpeed { axis } => {
                write!(f, "maximum speed of joint {axis} is not positive")
            }
            DeviceField::LinkTimeout => write!(
                f,
                "link timeout is not in [{}, {}] ms",
                crate::LINK_TIMEOUT_MS_MIN,
                crate::LINK_TIMEOUT_MS_MAX
            ),
        }
    }
}

/// Why [`crate::Bank::parse`] rejected a bank. Checks run in the order `SPEC.md` lists them
/// (header, CRC, section table, then contents section by section) and the first failure is
/// reported. `entry`, `node`, `cell` and `triangle` are 0-based element indices.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BankError {
    /// The slice is shorter than the header, the section table or `total_len`.
    TooShort {
        /// Bytes needed.
        needed: usize,
        /// Bytes given.
        got: usize,
    },
    /// The slice does not start on a [`crate::BANK_ALIGN`]-byte boundary.
    Misaligned,
    /// The first eight bytes are not [`crate::MAGIC`].
    BadMagic,
    /// A major version other than [`crate::VERSION_MAJOR`].
    UnsupportedVersion {
        /// Major version found.
        major: u16,
        /// Minor version found.
        minor: u16,
    },
    /// `header_len` is not [`crate::HEADER_LEN`].
    BadHeaderLength {
        /// Value found.
        header_len: u16,
    },
    /// More than [`crate::MAX_SECTIONS`] sections.
    TooManySections {
        /// Value found.
        count: u16,
    },
    /// `total_len` is not a multiple of 8 or is smaller than header plus section table.
    BadTotalLength {
        /// Value found.
        total_len: u32,
    },
    /// A reserved field, padding or unused coefficient is not zero.
    ReservedNotZero {
        /// Where.
        section: SectionKind,
    },
    /// The stored CRC does not match the bank's bytes.
    CrcMismatch {
        /// CRC in the header.
        stored: u32,
        /// CRC of the bytes.
        computed: u32,
    },
    /// A section table entry uses the reserved kind code 0.
    ReservedSectionKind {
        /// Index in the section table.
        entry: u32,
    },
    /// A section extends past `total_len` (or its end overflows).
    SectionOutOfBounds {
        /// Which section.
        section: SectionKind,
    },
    /// A section's offset is not a multiple of 8.
    SectionMisaligned {
        /// Which section.
        section: SectionKind,
    },
    /// A section overlaps the header, the section table or another section.
    SectionOverlap {
        /// Which section (the later one in the table).
        section: SectionKind,
    },
    /// A section kind appears twice.
    DuplicateSection {
        /// Which section.
        section: SectionKind,
    },
    /// A required section is absent.
    MissingSection {
        /// Which section.
        section: SectionKind,
    },
    /// A section's byte length is not `count` times its element size.
    SizeMismatch {
        /// Which section.
        section: SectionKind,
    },
    /// A section's element count disagrees with what other sections imply (one per node,
    /// one per neighbour entry, cells + 1, exactly one record, ...).
    CountMismatch {
        /// Which section.
        section: SectionKind,
    },
    /// The node count is 0 or exceeds [`crate::MAX_NODES`].
    NodeCount {
        /// Count found.
        count: u32,
    },
    /// A NaN or infinity.
    NonFinite {
        /// Which section.
        section: SectionKind,
        /// Which element.
        entry: u32,
    },
    /// A node, triangle or cell index past the end of what it indexes.
    IndexOutOfRange {
        /// Which section holds the index.
        section: SectionKind,
        /// Which element.
        entry: u32,
    },
    /// CSR starts that do not begin at 0, decrease, or do not end at the item count.
    BadCsrStarts {
        /// Which starts section.
        section: SectionKind,
        /// First offending start.
        entry: u32,
    },
    /// A triangle with a repeated vertex.
    DegenerateTriangle {
        /// Which triangle.
        triangle: u32,
    },
    /// A node's triangle list is not strictly ascending or names a triangle without the node.
    NodeTriangleMismatch {
        /// Which node.
        node: u32,
    },
    /// Grid cell size not finite and positive, a zero dimension, or too many cells.
    GridGeometry,
    /// A grid item sits in a bucket other than the cell containing its node's position.
    GridItemWrongCell {
        /// Which cell.
        cell: u32,
        /// Which item (index into the items).
        entry: u32,
    },
    /// More than [`crate::MAX_TRIANGLES`] triangles.
    TriangleCount {
        /// Triangles found.
        count: u32,
    },
    /// A cell's candidate triangles are not exactly the triangles whose widened bounding box
    /// meets the cell (missing, extra or not strictly ascending).
    CellCandidates {
        /// Linear cell index.
        cell: u32,
    },
    /// A cell's clearance is not a valid lower bound: non-zero in a cell a triangle occupies,
    /// or more than one above a neighbouring cell's.
    CellClearance {
        /// Linear cell index.
        cell: u32,
    },
    /// A bucket's items are not strictly ascending.
    GridItemsNotSorted {
        /// Which cell.
        cell: u32,
    },
    /// A `C_kk` is not symmetric positive definite.
    CkkNotSpd {
        /// Which node.
        node: u32,
    },
    /// A node lists itself as a neighbour.
    NeighbourSelf {
        /// Which node.
        node: u32,
    },
    /// A neighbour row is not strictly ascending (unsorted or duplicate).
    NeighbourNotSorted {
        /// Which node.
        node: u32,
    },
    /// `l` is in `k`'s row but `k` is not in `l`'s.
    NeighbourNotReciprocal {
        /// k.
        node: u32,
        /// l.
        neighbour: u32,
    },
    /// The 6x6 compliance of the pair `{k, l}` is not symmetric positive definite.
    PairNotSpd {
        /// k.
        node: u32,
        /// l.
        neighbour: u32,
    },
    /// Two nodes closer than the truncation radius without a coupling block.
    MissingNeighbour {
        /// k.
        node: u32,
        /// l.
        neighbour: u32,
    },
    /// Two vertices of a triangle without a coupling block.
    TriangleEdgeNotCoupled {
        /// Which triangle.
        triangle: u32,
    },
    /// Truncation radius negative (or not finite).
    BadTruncationRadius,
    /// Unknown tissue law kind.
    LawKind {
        /// Kind found.
        kind: u32,
    },
    /// Coefficient count 0, above 16, or not 2 for a linear law.
    LawCoefficientCount {
        /// Count found.
        count: u32,
    },
    /// Law domain with `f_min < 0` or `f_max <= f_min`.
    LawDomain,
    /// Q is not strictly increasing on its domain: its derivative is not positive at a sample.
    LawNotMonotone {
        /// Sample index, 0..=LAW_SAMPLES.
        sample: u32,
    },
    /// A device calibration value is out of range.
    Device {
        /// Which value.
        field: DeviceField,
    },
    /// A gravity coefficient's magnitude exceeds [`crate::GRAVITY_COEFF_MAX`].
    GravityOutOfRange {
        /// Index of the coefficient (0..8, the order of `GravityCompensation::coeffs`).
        coefficient: u32,
    },
    /// The viscoelastic relaxation's term count is 0 or above [`crate::MAX_PRONY_TERMS`].
    RelaxationCount {
        /// Count found.
        count: u32,
    },
    /// A relaxation term with `g_k < 0`, or `tau_k` outside
    /// [`crate::RELAXATION_TAU_MIN_S`]`..=`[`crate::RELAXATION_TAU_MAX_S`].
    RelaxationTerm {
        /// Which term.
        term: u32,
    },
    /// The relaxation's `g_k` sum to 1 or more (`g_inf <= 0`: a fluid, no force left in a hold).
    RelaxationSum,
    /// A 16-bit coupling block's exponent outside [`crate::CKL16_EXP_MIN`]`..=`
    /// [`crate::CKL16_EXP_MAX`] (its values would not decode exactly to finite f32).
    CklExponent {
        /// Which block.
        entry: u32,
    },
    /// A triangle's stored plane (section [`crate::SectionKind::TrianglePlanes`]) is not the
    /// plane recomputed from its positions within [`crate::PLANE_TOL`] (`SPEC.md`, check 9),
    /// or the triangle has zero area and so no plane.
    TrianglePlane {
        /// Which triangle.
        triangle: u32,
    },
    /// The contact samples' lattice level is outside `1..=`[`crate::MAX_SAMPLE_LEVEL`], its
    /// tip radius is negative or not finite, or its reserved words are not zero.
    SampleHeader {
        /// Level found.
        level: u32,
    },
    /// A patch compliance sample is not symmetric positive definite (`SPEC.md`, check 15).
    SampleNotSpd {
        /// Which sample.
        sample: u32,
    },
    /// A triangle's samples are positive definite but some point between them would be too
    /// ill-conditioned for the tick's contact solve ([`crate::MIN_PIVOT_REL`],
    /// [`crate::ill_conditioned_sample`]), so every press there would fault.
    SampleIllConditioned {
        /// The triangle.
        triangle: u32,
        /// Its sample with the smallest eigenvalue bound.
        sample: u32,
    },
    /// Two triangles name different samples for a lattice point of their common edge or
    /// vertex, so `W` would jump as a contact crosses it.
    SampleDiscontinuous {
        /// The triangle whose point differs from its neighbour's.
        triangle: u32,
    },
    /// A grid cell lists more than [`crate::MAX_CELL_CANDIDATES`] candidate triangles: the
    /// firmware's detection cost per tick is bounded by that limit (use smaller cells).
    TooManyCandidates {
        /// Linear cell index.
        cell: u32,
        /// Candidates it lists.
        count: u32,
    },
    /// A node has more than [`crate::MAX_NODE_NEIGHBOURS`] neighbour entries: the patch's
    /// quadrature and assembly per tick are bounded by that limit (couple fewer pairs).
    TooManyNeighbours {
        /// Which node.
        node: u32,
        /// Neighbours it lists.
        count: u32,
    },
    /// A node belongs to more than [`crate::MAX_NODE_TRIANGLES`] triangles: a surface walk's
    /// step per tick is bounded by that limit (remesh the surface).
    TooManyTriangles {
        /// Which node.
        node: u32,
        /// Triangles it belongs to.
        count: u32,
    },
}

impl BankError {
    /// A stable small number per variant (1-based, in declaration order; a retired variant's
    /// code is never reused: 31), for fault reports over the link where the full error does
    /// not fit.
    pub const fn code(&self) -> u16 {
        match self {
            BankError::TooShort { .. } => 1,
            BankError::Misaligned => 2,
            BankError::BadMagic => 3,
            BankError::UnsupportedVersion { .. } => 4,
            BankError::BadHeaderLength { .. } => 5,
            BankError::TooManySections { .. } => 6,
            BankError::BadTotalLength { .. } => 7,
            BankError::ReservedNotZero { .. } => 8,
            BankError::CrcMismatch { .. } => 9,
            BankError::ReservedSectionKind { .. } => 10,
            BankError::SectionOutOfBounds { .. } => 11,
            BankError::SectionMisaligned { .. } => 12,
            BankError::SectionOverlap { .. } => 13,
            BankError::DuplicateSection { .. } => 14,
            BankError::MissingSection { .. } => 15,
            BankError::SizeMismatch { .. } => 16,
            BankError::CountMismatch { .. } => 17,
            BankError::NodeCount { .. } => 18,
            BankError::NonFinite { .. } => 19,
            BankError::IndexOutOfRange { .. } => 20,
            BankError::BadCsrStarts { .. } => 21,
            BankError::DegenerateTriangle { .. } => 22,
            BankError::NodeTriangleMismatch { .. } => 23,
            BankError::GridGeometry => 24,
            BankError::GridItemWrongCell { .. } => 25,
            BankError::GridItemsNotSorted { .. } => 26,
            BankError::CkkNotSpd { .. } => 27,
            BankError::NeighbourSelf { .. } => 28,
            BankError::NeighbourNotSorted { .. } => 29,
            BankError::NeighbourNotReciprocal { .. } => 30,
            // 31 was `CklAsymmetric` (3.x stored both directions of a pair); retired in 4.0.
            BankError::PairNotSpd { .. } => 32,
            BankError::MissingNeighbour { .. } => 33,
            BankError::TriangleEdgeNotCoupled { .. } => 34,
            BankError::BadTruncationRadius => 35,
            BankError::LawKind { .. } => 36,
            BankError::LawCoefficientCount { .. } => 37,
            BankError::LawDomain => 38,
            BankError::LawNotMonotone { .. } => 39,
            BankError::Device { .. } => 40,
            BankError::TriangleCount { .. } => 41,
            BankError::CellCandidates { .. } => 42,
            BankError::CellClearance { .. } => 43,
            BankError::GravityOutOfRange { .. } => 44,
            BankError::CklExponent { .. } => 45,
            BankError::TrianglePlane { .. } => 46,
            BankError::SampleHeader { .. } => 47,
            BankError::SampleNotSpd { .. } => 48,
            BankError::SampleDiscontinuous { .. } => 49,
            BankError::TooManyCandidates { .. } => 50,
            BankError::TooManyNeighbours { .. } => 51,
            BankError::TooManyTriangles { .. } => 52,
            BankError::RelaxationCount { .. } => 53,
            BankError::RelaxationTerm { .. } => 54,
            BankError::RelaxationSum => 55,
            BankError::SampleIllConditioned { .. } => 56,
        }
    }
}

impl fmt::Display for BankError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        use BankError as E;
        match *self {
            E::TooShort { needed, got } => {
                write!(f, "bank too short: {needed} bytes needed, {got} given")
            }
            E::Misaligned => f.write_str("bank bytes are not 4-byte aligned"),
            E::BadMagic => f.write_str("not a bank (bad magic)"),
            E::UnsupportedVersion { major, minor } => {
                write!(f, "unsupported bank version {major}.{minor}")
            }
            E::BadHeaderLength { header_len } => write!(f, "bad header length {header_len}"),
            E::TooManySections { count } => write!(f, "too many sections ({count})"),
            E::BadTotalLength { total_len } => write!(f, "bad total length {total_len}"),
            E::ReservedNotZero { section } => write!(f, "{section}: reserved field not zero"),
            E::CrcMismatch { stored, computed } => write!(
                f,
                "CRC mismatch: stored {stored:#010x}, computed {computed:#010x}"
            ),
            E::ReservedSectionKind { entry } => {
                write!(f, "section table entry {entry} uses reserved kind 0")
            }
            E::SectionOutOfBounds { section } => write!(f, "{section}: out of bounds"),
            E::SectionMisaligned { section } => write!(f, "{section}: misaligned offset"),
            E::SectionOverlap { section } => write!(f, "{section}: overlaps another region"),
            E::DuplicateSection { section } => write!(f, "{section}: duplicate section"),
            E::MissingSection { section } => write!(f, "{section}: missing section"),
            E::SizeMismatch { section } => {
                write!(f, "{section}: length is not count x element size")
            }
            E::CountMismatch { section } => write!(f, "{section}: wrong element count"),
            E::NodeCount { count } => write!(f, "node count {count} not in 1..=65535"),
            E::NonFinite { section, entry } => {
                write!(f, "{section}: non-finite value in entry {entry}")
            }
            E::IndexOutOfRange { section, entry } => {
                write!(f, "{section}: index out of range in entry {entry}")
            }
            E::BadCsrStarts { section, entry } => {
                write!(f, "{section}: invalid start offset at entry {entry}")
            }
            E::DegenerateTriangle { triangle } => {
                write!(f, "triangle {triangle} repeats a vertex")
            }
            E::NodeTriangleMismatch { node } => {
                write!(f, "triangle list of node {node} is inconsistent")
            }
            E::GridGeometry => f.write_str("grid cell size or dimensions invalid"),
            E::GridItemWrongCell { cell, entry } => {
                write!(f, "grid item {entry} is not in cell {cell}")
            }
            E::GridItemsNotSorted { cell } => write!(f, "grid cell {cell} items not ascending"),
            E::TriangleCount { count } => {
                write!(f, "{count} triangles, at most {}", crate::MAX_TRIANGLES)
            }
            E::CellCandidates { cell } => write!(
                f,
                "grid cell {cell}: candidate triangles are not those whose widened box meets it"
            ),
            E::CellClearance { cell } => write!(
                f,
                "grid cell {cell}: clearance is not a lower bound of the distance to the surface"
            ),
            E::CkkNotSpd { node } => write!(f, "C_kk of node {node} is not SPD"),
            E::NeighbourSelf { node } => write!(f, "node {node} lists itself as neighbour"),
            E::NeighbourNotSorted { node } => {
                write!(f, "neighbours of node {node} not strictly ascending")
            }
            E::NeighbourNotReciprocal { node, neighbour } => write!(
                f,
                "node {neighbour} is a neighbour of {node} but not the reverse"
            ),
            E::PairNotSpd { node, neighbour } => {
                write!(f, "compliance of pair ({node}, {neighbour}) is not SPD")
            }
            E::MissingNeighbour { node, neighbour } => write!(
                f,
                "nodes {node} and {neighbour} are within the truncation radius but not coupled"
            ),
            E::TriangleEdgeNotCoupled { triangle } => {
                write!(f, "vertices of triangle {triangle} are not coupled")
            }
            E::BadTruncationRadius => f.write_str("truncation radius is negative or not finite"),
            E::LawKind { kind } => write!(f, "unknown tissue law kind {kind}"),
            E::LawCoefficientCount { count } => {
                write!(f, "tissue law coefficient count {count} invalid")
            }
            E::LawDomain => f.write_str("tissue law domain is empty or negative"),
            E::LawNotMonotone { sample } => {
                write!(f, "tissue law not increasing at sample {sample}")
            }
            E::Device { field } => write!(f, "device calibration: {field}"),
            E::GravityOutOfRange { coefficient } => write!(
                f,
                "gravity coefficient {coefficient} beyond +-{} (N m or N)",
                crate::GRAVITY_COEFF_MAX
            ),
            E::RelaxationCount { count } => write!(
                f,
                "viscoelastic relaxation: {count} terms, not 1..={}",
                crate::MAX_PRONY_TERMS
            ),
            E::RelaxationTerm { term } => write!(
                f,
                "viscoelastic relaxation term {term}: g < 0 or tau outside {}..={} s",
                crate::RELAXATION_TAU_MIN_S,
                crate::RELAXATION_TAU_MAX_S
            ),
            E::RelaxationSum => {
                f.write_str("viscoelastic relaxation: the g_k sum to 1 or more (g_inf <= 0)")
            }
            E::CklExponent { entry } => write!(
                f,
                "16-bit C_kl block {entry}: exponent outside {}..={}",
                crate::CKL16_EXP_MIN,
                crate::CKL16_EXP_MAX
            ),
            E::TrianglePlane { triangle } => write!(
                f,
                "triangle {triangle}: its stored plane is not the one of its positions (or it has \
                 zero area)"
            ),
            E::SampleHeader { level } => write!(
                f,
                "sample header: level {level} not in 1..={}, or a bad tip radius or reserved word",
                crate::MAX_SAMPLE_LEVEL
            ),
            E::SampleNotSpd { sample } => {
                write!(f, "patch compliance sample {sample} is not SPD")
            }
            E::SampleIllConditioned { triangle, sample } => write!(
                f,
                "triangle {triangle}: patch compliance sample {sample} is too ill-conditioned \
                 for the loop's contact solve (smallest eigenvalue under twice {:e} of the \
                 largest diagonal entry of the triangle's samples)",
                crate::MIN_PIVOT_REL
            ),
            E::SampleDiscontinuous { triangle } => write!(
                f,
                "triangle {triangle}: a sample of its edge or vertex differs from its neighbour's"
            ),
            E::TooManyCandidates { cell, count } => write!(
                f,
                "grid cell {cell} lists {count} candidate triangles, more than the firmware's \
                 {} (use smaller grid cells)",
                crate::MAX_CELL_CANDIDATES
            ),
            E::TooManyNeighbours { node, count } => write!(
                f,
                "node {node} has {count} neighbours, more than the firmware's {} (couple fewer \
                 pairs)",
                crate::MAX_NODE_NEIGHBOURS
            ),
            E::TooManyTriangles { node, count } => write!(
                f,
                "node {node} belongs to {count} triangles, more than the firmware's {}",
                crate::MAX_NODE_TRIANGLES
            ),
        }
    }
}

impl core::error::Error for BankError {}
