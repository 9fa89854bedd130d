//! Length units of mesh files (`--units`, a scene's `mesh_units`), and the guess of a file's
//! units from the size of an organ. A leaf module: it imports nothing from the crate.

use fem::mesh::TetMesh;

/// Length units of a surface or tetrahedral mesh file (`--units`, a scene's `mesh_units`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Units {
    /// Metres.
    M,
    /// Centimetres.
    Cm,
    /// Millimetres.
    Mm,
}

impl Units {
    /// Metres per unit.
    pub fn to_metres(self) -> f64 {
        match self {
            Units::M => 1.0,
            Units::Cm => 0.01,
            Units::Mm => 0.001,
        }
    }

    /// The unit's symbol.
    pub fn name(self) -> &'static str {
        match self {
            Units::M => "m",
            Units::Cm => "cm",
            Units::Mm => "mm",
        }
    }
}

impl std::str::FromStr for Units {
    type Err = String;

    /// "m", "cm" or "mm".
    fn from_str(s: &str) -> Result<Self, String> {
        [Units::M, Units::Cm, Units::Mm]
            .into_iter()
            .find(|u| u.name() == s)
            .ok_or_else(|| format!("must be \"m\", \"cm\" or \"mm\", got {s:?}"))
    }
}

/// Largest side of a whole organ's bounding box, m: 4 cm (a small kidney is 10 cm, a
/// specimen is not an organ) to 40 cm (a large liver is about 25 cm).
pub const ORGAN_SIDE_M: (f64, f64) = (0.04, 0.4);

/// The largest side of the box `(lo, hi)`.
pub fn largest_side((lo, hi): ([f64; 3], [f64; 3])) -> f64 {
    (0..3).map(|k| hi[k] - lo[k]).fold(0.0, f64::max)
}

/// The units in which a bounding box whose largest side is `side` (file units) is an organ's,
/// [`ORGAN_SIDE_M`]: the three ranges do not overlap, so the guess is unique; `Err` says why
/// none fits.
pub fn guess_units(side: f64) -> Result<Units, String> {
    for u in [Units::M, Units::Cm, Units::Mm] {
        let m = side * u.to_metres();
        if (ORGAN_SIDE_M.0..=ORGAN_SIDE_M.1).contains(&m) {
            return Ok(u);
        }
    }
    Err(format!(
        "the largest side of the bounding box is {side:.4} file units: no unit makes that an \
         organ's {} to {} m (in m: {side:.3} m, in cm: {:.3} m, in mm: {:.4} m)",
        ORGAN_SIDE_M.0,
        ORGAN_SIDE_M.1,
        side * 0.01,
        side * 0.001
    ))
}

/// Multiplies every node of `mesh` by the metres per unit of `units`.
pub fn scale_mesh(mesh: &mut TetMesh, units: Units) {
    let s = units.to_metres();
    if s != 1.0 {
        mesh.nodes.iter_mut().flatten().for_each(|x| *x *= s);
    }
}
