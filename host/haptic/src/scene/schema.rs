//! The scene file as written: the TOML tables as serde reads them, every value with its source
//! span (for the line of an error). Unknown keys are refused here; values are checked by
//! [`super::checks`].

use serde::Deserialize;
use toml::Spanned;

/// The whole file.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawScene {
    pub(super) mesh: Spanned<String>,
    #[serde(default)]
    pub(super) mesh_units: Option<Spanned<String>>,
    pub(super) material: RawMaterial,
    pub(super) fixed: RawFixed,
    pub(super) tool: RawTool,
    pub(super) device: RawDevice,
    pub(super) law: RawLaw,
    #[serde(default)]
    pub(super) display_law: Option<RawDisplayLaw>,
    #[serde(default)]
    pub(super) gravity: Option<RawGravity>,
    #[serde(default)]
    pub(super) viscoelastic: Option<RawViscoelastic>,
    pub(super) bank: RawBank,
    #[serde(default)]
    pub(super) contact: Option<RawContact>,
}

/// `[contact]`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawContact {
    #[serde(default)]
    pub(super) model: Option<Spanned<String>>,
    #[serde(default)]
    pub(super) fem_mesh: Option<Spanned<String>>,
    #[serde(default)]
    pub(super) fem_element: Option<Spanned<String>>,
    #[serde(default)]
    pub(super) sample_level: Option<Spanned<u32>>,
    #[serde(default)]
    pub(super) richardson_mesh: Option<Spanned<String>>,
    #[serde(default)]
    pub(super) richardson_ratio: Option<Spanned<f64>>,
    #[serde(default)]
    pub(super) richardson_order: Option<Spanned<f64>>,
}

/// `[gravity]`: the coefficients of the instrument's weight feed-forward (`bank-format`
/// `SPEC.md`, "gravity"), written by `host calibrate gravity`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawGravity {
    pub(super) coeffs: Spanned<[f64; bank_format::GRAVITY_COEFFS]>,
}

/// `[viscoelastic]`: the Prony terms of the reduced relaxation function (`bank-format`
/// `SPEC.md`, "viscoelastic relaxation"), written by `host calibrate relaxation`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawViscoelastic {
    pub(super) g: Spanned<Vec<f64>>,
    pub(super) tau_s: Spanned<Vec<f64>>,
}

/// `[material]`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawMaterial {
    pub(super) young_pa: Spanned<f64>,
    pub(super) poisson: Spanned<f64>,
    #[serde(default)]
    pub(super) element: Option<Spanned<String>>,
}

/// `[fixed]`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawFixed {
    #[serde(default)]
    pub(super) boxes: Vec<Spanned<RawBox>>,
    #[serde(default)]
    pub(super) nodes: Option<Spanned<Vec<usize>>>,
}

/// One of `[fixed]`'s `boxes`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawBox {
    pub(super) min: [f64; 3],
    pub(super) max: [f64; 3],
    #[serde(default)]
    pub(super) axes: Option<String>,
}

/// `[tool]`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawTool {
    pub(super) tip_radius_m: Spanned<f64>,
}

/// `[device]`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawDevice {
    pub(super) fulcrum_m: Spanned<[f64; 3]>,
    pub(super) shaft_axis: Spanned<[f64; 3]>,
    pub(super) pitch_axis: Spanned<[f64; 3]>,
    pub(super) yaw_axis: Spanned<[f64; 3]>,
    pub(super) pitch_range_rad: Spanned<[f64; 2]>,
    pub(super) yaw_range_rad: Spanned<[f64; 2]>,
    pub(super) insertion_range_m: Spanned<[f64; 2]>,
    #[serde(default)]
    pub(super) home: Option<Spanned<[f64; 3]>>,
    pub(super) counts_per_rev: Spanned<[u32; 3]>,
    pub(super) gear_ratio: Spanned<[f64; 3]>,
    pub(super) torque_constant_nm_per_a: Spanned<[f64; 3]>,
    pub(super) current_limit_a: Spanned<[f64; 3]>,
    pub(super) max_force_n: Spanned<f64>,
    #[serde(default)]
    pub(super) max_tip_speed_m_s: Option<Spanned<f64>>,
    #[serde(default)]
    pub(super) max_joint_speed: Option<Spanned<[f64; 3]>>,
    #[serde(default)]
    pub(super) link_timeout_ms: Option<Spanned<f64>>,
    #[serde(default)]
    pub(super) friction_offset: Option<Spanned<[f64; 3]>>,
}

/// `[law]`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawLaw {
    pub(super) kind: Spanned<String>,
    #[serde(default)]
    pub(super) gain: Option<Spanned<f64>>,
    #[serde(default)]
    pub(super) offset_n: Option<Spanned<f64>>,
    #[serde(default)]
    pub(super) coeffs: Option<Spanned<Vec<f64>>>,
    #[serde(default)]
    pub(super) domain_n: Option<Spanned<[f64; 2]>>,
}

/// `[display_law]`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawDisplayLaw {
    pub(super) kind: Spanned<String>,
    pub(super) coeffs: Spanned<Vec<f64>>,
    pub(super) domain_m: Spanned<[f64; 2]>,
}

/// `[bank]`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawBank {
    #[serde(default)]
    pub(super) couplings: Option<Spanned<String>>,
    #[serde(default)]
    pub(super) truncation_radius_m: Option<Spanned<f64>>,
    #[serde(default)]
    pub(super) precision: Option<Spanned<String>>,
    #[serde(default)]
    pub(super) max_contact_nodes: Option<Spanned<u32>>,
    #[serde(default)]
    pub(super) grid_cell_m: Option<Spanned<f64>>,
    #[serde(default)]
    pub(super) reach_margin_m: Option<Spanned<f64>>,
}
