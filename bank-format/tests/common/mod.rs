//! A small hand-made bank and byte-patching helpers shared by the integration tests.
#![allow(dead_code, clippy::needless_range_loop)]

use bank_format::{
    AlignedBytes, Bank, BankBuilder, BankError, DeviceCalibration, HEADER_LEN, SECTION_ENTRY_LEN,
    SectionKind, TissueLaw, fixtures::bench_device, reseal,
};

/// Side of the square the four nodes sit on, m.
pub const SIDE: f64 = 0.01;

/// Node positions: a 10 mm square in the z = 0 plane (0-1-2-3 counter-clockwise from +z).
pub fn positions() -> Vec<[f64; 3]> {
    vec![
        [0.0, 0.0, 0.0],
        [SIDE, 0.0, 0.0],
        [SIDE, SIDE, 0.0],
        [0.0, SIDE, 0.0],
    ]
}

/// A genuine SPD 12x12 compliance: `K (x) M + s A A^T` with `K_kl = exp(-d_kl / L)` (a
/// positive definite kernel), so every principal block is SPD and `C_kl` is not symmetric.
pub fn compliance() -> Vec<Vec<f64>> {
    let p = positions();
    let m = [
        [1.0e-3, 0.1e-3, 0.0],
        [0.1e-3, 1.2e-3, 0.05e-3],
        [0.0, 0.05e-3, 2.0e-3],
    ];
    let a: Vec<[f64; 3]> = (0..12)
        .map(|i| {
            let x = i as f64;
            [(0.7 * x).sin(), (1.3 * x + 0.5).cos(), (0.4 * x * x).sin()]
        })
        .collect();
    let mut c = vec![vec![0.0; 12]; 12];
    for k in 0..4 {
        for l in 0..4 {
            let d: f64 = (0..3)
                .map(|i| (p[k][i] - p[l][i]).powi(2))
                .sum::<f64>()
                .sqrt();
            let kern = (-d / 0.02).exp();
            for i in 0..3 {
                for j in 0..3 {
                    let (r, s) = (3 * k + i, 3 * l + j);
                    let aat: f64 = (0..3).map(|q| a[r][q] * a[s][q]).sum();
                    c[r][s] = kern * m[i][j] + 0.2e-3 * aat;
                }
            }
        }
    }
    c
}

/// Block `C_kl` of [`compliance`].
pub fn block(k: usize, l: usize) -> [[f64; 3]; 3] {
    let c = compliance();
    let mut b = [[0.0; 3]; 3];
    for (i, row) in b.iter_mut().enumerate() {
        for (j, v) in row.iter_mut().enumerate() {
            *v = c[3 * k + i][3 * l + j];
        }
    }
    b
}

/// The pairs the valid bank couples: the square's edges and the diagonal 0-2 (a triangle
/// edge); 1-3 (14.1 mm apart, beyond the 12 mm truncation radius) is left out.
pub const PAIRS: [(usize, usize); 5] = [(0, 1), (0, 2), (0, 3), (1, 2), (2, 3)];

pub fn law() -> TissueLaw {
    TissueLaw::chebyshev(&[2.6, 2.5, 0.1], [0.0, 5.0]).unwrap()
}

/// The bench gimbal ([`bench_device`]) over the square, with a distinct joint speed per axis
/// and a 20 ms link timeout.
pub fn device() -> DeviceCalibration {
    DeviceCalibration {
        max_joint_speed: [10.0, 12.0, 1.5],
        link_timeout_ms: 20,
        ..bench_device([0.005, 0.005, 0.1])
    }
}

/// The valid 4-node, 2-triangle bank's input. Cell size 8 mm puts each node in its own cell
/// of a 2 x 2 x 1 grid.
pub fn builder() -> BankBuilder {
    BankBuilder {
        positions_m: positions(),
        mesh_ids: vec![700, 701, 1000, 42],
        triangles: vec![[0, 1, 2], [0, 2, 3]],
        c_kk: (0..4).map(|k| block(k, k)).collect(),
        couplings: PAIRS
            .iter()
            .map(|&(k, l)| (k as u32, l as u32, block(k, l)))
            .collect(),
        grid_cell_size_m: 0.008,
        truncation_radius_m: 0.012,
        scene_id: 0x0123_4567_89ab_cdef,
        law: law(),
        gravity: None,
        relaxation: None,
        samples: None,
        device: device(),
    }
}

/// The valid bank with contact samples at lattice level 2 (`SPEC.md`, "contact samples"):
/// each sample's `W` the barycentric mix of its triangle's vertices' `C_kk` (SPD), points of the
/// shared edge 0-2 stored once.
pub fn sampled_builder() -> BankBuilder {
    let mut b = builder();
    let lattice = bank_format::SharedLattice::new(&b.triangles, 2);
    let w = lattice
        .points
        .iter()
        .map(|&(t, bary)| {
            let tri = b.triangles[t];
            let mut m = [[0.0; 3]; 3];
            for (v, wv) in tri.iter().zip(bary) {
                let c = block(*v as usize, *v as usize);
                for i in 0..3 {
                    for j in 0..3 {
                        m[i][j] += wv * c[i][j];
                    }
                }
            }
            m
        })
        .collect();
    b.samples = Some(bank_format::ContactSamples {
        level: 2,
        tip_radius_m: 0.002,
        triangle_samples: lattice.triangle_points,
        w,
    });
    b
}

pub fn valid_bytes() -> Vec<u8> {
    builder().build().expect("the hand-made bank is valid")
}

/// Parse from aligned storage.
pub fn parse(bytes: &[u8]) -> Result<(), BankError> {
    let aligned = AlignedBytes::new(bytes);
    Bank::parse(&aligned).map(|_| ())
}

/// (table index, offset, len, count) of a section.
pub fn section(bytes: &[u8], kind: SectionKind) -> (usize, usize, usize, usize) {
    let count = u16::from_le_bytes([bytes[14], bytes[15]]) as usize;
    for i in 0..count {
        let e = HEADER_LEN + SECTION_ENTRY_LEN * i;
        let w = |o: usize| u32::from_le_bytes(bytes[e + o..e + o + 4].try_into().unwrap()) as usize;
        if w(0) == kind.code() as usize {
            return (i, w(4), w(8), w(12));
        }
    }
    panic!("no section {kind:?}");
}

pub fn put_u16(bytes: &mut [u8], at: usize, v: u16) {
    bytes[at..at + 2].copy_from_slice(&v.to_le_bytes());
}

pub fn put_u32(bytes: &mut [u8], at: usize, v: u32) {
    bytes[at..at + 4].copy_from_slice(&v.to_le_bytes());
}

pub fn put_f32(bytes: &mut [u8], at: usize, v: f32) {
    bytes[at..at + 4].copy_from_slice(&v.to_le_bytes());
}

pub fn get_f32(bytes: &[u8], at: usize) -> f32 {
    f32::from_le_bytes(bytes[at..at + 4].try_into().unwrap())
}

/// Byte offset of field `field` (0..4 = kind, offset, len, count) of table entry `i`.
pub fn entry_field(i: usize, field: usize) -> usize {
    HEADER_LEN + SECTION_ENTRY_LEN * i + 4 * field
}

/// Apply `f` to a valid bank, fix its CRC, and parse it.
pub fn corrupt(f: impl FnOnce(&mut Vec<u8>)) -> Result<(), BankError> {
    let mut bytes = valid_bytes();
    f(&mut bytes);
    assert!(reseal(&mut bytes));
    parse(&bytes)
}

/// Apply `f` to the section `kind` of a valid bank, fix its CRC, and parse it.
pub fn corrupt_section(kind: SectionKind, f: impl FnOnce(&mut [u8])) -> Result<(), BankError> {
    corrupt(|bytes| {
        let (_, off, len, _) = section(bytes, kind);
        f(&mut bytes[off..off + len]);
    })
}
