//! Scene files: everything a bank is built from, in TOML.
//!
//! A scene names the organ mesh, its material and supports, the tool, the laparoscopic device
//! (trocar pose, joint ranges, motors), the tissue force law and the bank options. The shipped
//! example `host/scenes/liver.toml` documents every key with a comment. Rules:
//!
//! - Unknown keys are errors; so are missing required keys and out-of-range values. Every error
//!   names the file, the line and the key.
//! - `mesh` is a path relative to the scene file, or `"builtin:liver-1k4"` for the 1.4k-node
//!   liver embedded in the binary. Optional `mesh_units` ("m", "cm" or "mm") names the units of
//!   the organ's mesh files (`mesh`, and a sampled `[contact]`'s `fem_mesh` and
//!   `richardson_mesh`); they are scaled to metres on loading. Without it the files are in
//!   metres, and a mesh that is no organ in metres but one in cm or mm is refused (set
//!   `mesh_units`).
//! - SI units everywhere (m, rad, Pa, N, A, N m/A); angles in radians.
//! - The device maps onto [`bank_format::DeviceCalibration`]: joints are 0 = pitch, 1 = yaw,
//!   2 = insertion, and `tip = fulcrum + insertion * Rot(yaw_axis, yaw) Rot(pitch_axis, pitch)
//!   shaft_axis`.

use crate::meshing::Units;
use bank_format::{DeviceCalibration, TissueLaw};
use fem::elasticity::{Element, FixedSet, Material};
use fem::mesh::TetMesh;
use serde::Deserialize;
use std::ops::Range;
use std::path::{Path, PathBuf};
use toml::Spanned;

/// The embedded 1.4k-node liver (`mesh = "builtin:liver-1k4"`).
pub const BUILTIN_LIVER: &[u8] = include_bytes!("../../meshes/liver-1k4.msh");
/// The default scene (`host/scenes/liver.toml`, embedded): what `demo` and `report` use
/// without `--scene`.
pub const DEFAULT_SCENE: &str = include_str!("../../scenes/liver.toml");
/// The scene value that selects [`BUILTIN_LIVER`].
pub const BUILTIN_LIVER_NAME: &str = "builtin:liver-1k4";

/// Default `[device] max_tip_speed_m_s`, m/s: above it the armed device disables its forces
/// (`Overspeed`). Twice the demo's virtual hand at its fastest along the shaft (0.5 m/s; 0.78 m/s
/// with pitch, yaw and insertion all at their top rates at full insertion), so normal use never
/// trips it; a 5 cm strike in one tick (50 m/s) and the SIL plant's scripted strike (1.4 m/s
/// peak, 18 mm in 20 ms) do: an impact that fast is not rendered, the forces are cut.
pub const DEFAULT_MAX_TIP_SPEED_M_S: f64 = 1.0;
/// Lever of the default pitch and yaw thresholds, m: `max_joint_speed` defaults to
/// `[v / lever, v / lever, v]` for the tip threshold `v`. The shipped liver's surface is 0.09 m
/// below the trocar and the insertion reaches 0.14 m, so where the tool touches tissue the
/// default 10 rad/s is 0.9 to 1.4 m/s at the tip, about where the tip check trips anyway: in
/// normal use the joint check does not trip before the tip check (it guards the motors near the
/// fulcrum, where a fast swing moves the tip little). Insertion defaults to `v` itself: the tip
/// moves at least as fast as the insertion (the gimbal's motion is orthogonal to the shaft), so
/// it never trips first. At the defaults, 10 rad/s and 1 m/s are 3.3 and 2 times the demo
/// hand's 3 rad/s and 0.5 m/s, and half the firmware's encoder-jump speeds
/// ([`firmware::safety::DEFAULT_JUMP_SPEED`]).
pub const DEFAULT_SPEED_LEVER_M: f64 = 0.1;

/// A scene-file error: file, 1-based line (when known), key and what is wrong.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{file}:{}: {key}: {message}", line.map_or("?".to_string(), |l| l.to_string()))]
pub struct SceneError {
    /// The scene file.
    pub file: String,
    /// 1-based line of the offending key or value.
    pub line: Option<usize>,
    /// Dotted key path, e.g. `material.young_pa`.
    pub key: String,
    /// What is wrong.
    pub message: String,
}

/// The scene file as written (fields carry their source spans for error lines).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawScene {
    mesh: Spanned<String>,
    #[serde(default)]
    mesh_units: Option<Spanned<String>>,
    material: RawMaterial,
    fixed: RawFixed,
    tool: RawTool,
    device: RawDevice,
    law: RawLaw,
    #[serde(default)]
    display_law: Option<RawDisplayLaw>,
    #[serde(default)]
    gravity: Option<RawGravity>,
    #[serde(default)]
    viscoelastic: Option<RawViscoelastic>,
    bank: RawBank,
    #[serde(default)]
    contact: Option<RawContact>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawContact {
    #[serde(default)]
    model: Option<Spanned<String>>,
    #[serde(default)]
    fem_mesh: Option<Spanned<String>>,
    #[serde(default)]
    fem_element: Option<Spanned<String>>,
    #[serde(default)]
    sample_level: Option<Spanned<u32>>,
    #[serde(default)]
    richardson_mesh: Option<Spanned<String>>,
    #[serde(default)]
    richardson_ratio: Option<Spanned<f64>>,
    #[serde(default)]
    richardson_order: Option<Spanned<f64>>,
}

/// `[gravity]`: the coefficients of the instrument's weight feed-forward (`bank-format`
/// `SPEC.md`, "gravity"), written by `host calibrate gravity`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawGravity {
    coeffs: Spanned<[f64; bank_format::GRAVITY_COEFFS]>,
}

/// `[viscoelastic]`: the Prony terms of the reduced relaxation function (`bank-format`
/// `SPEC.md`, "viscoelastic relaxation"), written by `host calibrate relaxation`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawViscoelastic {
    g: Spanned<Vec<f64>>,
    tau_s: Spanned<Vec<f64>>,
}

/// Fung's quasi-linear viscoelasticity of the tissue (`[viscoelastic]`): the reduced relaxation
/// function `G(t) = g_inf + sum_k g_k exp(-t / tau_k)`, `G(0) = 1`, applied by the firmware to
/// the elastic force (`firmware::relax`). Validated: 1 to [`bank_format::MAX_PRONY_TERMS`]
/// terms, `g_k >= 0`, `sum g_k < 1`, each `tau_k` in [`bank_format::RELAXATION_TAU_MIN_S`] (two
/// ticks) ..= [`bank_format::RELAXATION_TAU_MAX_S`] (an hour).
#[derive(Clone, Debug, PartialEq)]
pub struct Viscoelastic {
    /// `g_k`, dimensionless.
    pub g: Vec<f64>,
    /// `tau_k`, s.
    pub tau_s: Vec<f64>,
}

impl Viscoelastic {
    /// `g_inf = 1 - sum_k g_k`, the share of the elastic force left after full relaxation.
    pub fn g_inf(&self) -> f64 {
        1.0 - self.g.iter().sum::<f64>()
    }

    /// The bank's record (f32), or why the terms do not make a valid one: the scene's own
    /// rules, also for a fit before it is written (`host calibrate relaxation`).
    pub fn record(&self) -> Result<bank_format::Relaxation, String> {
        let n = self.g.len();
        if n != self.tau_s.len() {
            return Err(format!(
                "g has {n} terms, tau_s {}: one time constant per term",
                self.tau_s.len()
            ));
        }
        if !(1..=bank_format::MAX_PRONY_TERMS).contains(&n) {
            return Err(format!(
                "{n} terms: the firmware renders 1 to {} (delete the table for an elastic tissue)",
                bank_format::MAX_PRONY_TERMS
            ));
        }
        let mut r = bank_format::Relaxation {
            count: n as u32,
            reserved: 0,
            g: [0.0; bank_format::MAX_PRONY_TERMS],
            tau_s: [0.0; bank_format::MAX_PRONY_TERMS],
        };
        let (lo, hi) = (
            bank_format::RELAXATION_TAU_MIN_S,
            bank_format::RELAXATION_TAU_MAX_S,
        );
        for (k, (&g, &tau)) in self.g.iter().zip(&self.tau_s).enumerate() {
            if !g.is_finite() || !tau.is_finite() {
                return Err(format!("term {k}: values must be finite"));
            }
            if g < 0.0 {
                return Err(format!(
                    "term {k}: g = {g} < 0 (a negative share would make the force grow in a hold)"
                ));
            }
            let (gf, tf) = (g as f32, tau as f32);
            if tf < lo {
                return Err(format!(
                    "term {k}: tau = {tau} s is under two ticks of the 1 kHz loop ({lo} s): it                      relaxes before the loop can render it; fold it into the elastic law"
                ));
            }
            if tf > hi {
                return Err(format!(
                    "term {k}: tau = {tau} s is over an hour ({hi} s): it does not relax within                      a session (it is elasticity), and its decay per tick is below f32 precision"
                ));
            }
            r.g[k] = gf;
            r.tau_s[k] = tf;
        }
        let sum: f64 = r.g.iter().map(|&g| f64::from(g)).sum();
        if sum >= 1.0 {
            return Err(format!(
                "the g sum to {sum} >= 1: g_inf = 1 - sum must stay > 0 (a solid keeps a force                  in a hold)"
            ));
        }
        Ok(r)
    }
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawMaterial {
    young_pa: Spanned<f64>,
    poisson: Spanned<f64>,
    #[serde(default)]
    element: Option<Spanned<String>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawFixed {
    #[serde(default)]
    boxes: Vec<Spanned<RawBox>>,
    #[serde(default)]
    nodes: Option<Spanned<Vec<usize>>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawBox {
    min: [f64; 3],
    max: [f64; 3],
    #[serde(default)]
    axes: Option<String>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawTool {
    tip_radius_m: Spanned<f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawDevice {
    fulcrum_m: Spanned<[f64; 3]>,
    shaft_axis: Spanned<[f64; 3]>,
    pitch_axis: Spanned<[f64; 3]>,
    yaw_axis: Spanned<[f64; 3]>,
    pitch_range_rad: Spanned<[f64; 2]>,
    yaw_range_rad: Spanned<[f64; 2]>,
    insertion_range_m: Spanned<[f64; 2]>,
    #[serde(default)]
    home: Option<Spanned<[f64; 3]>>,
    counts_per_rev: Spanned<[u32; 3]>,
    gear_ratio: Spanned<[f64; 3]>,
    torque_constant_nm_per_a: Spanned<[f64; 3]>,
    current_limit_a: Spanned<[f64; 3]>,
    max_force_n: Spanned<f64>,
    #[serde(default)]
    max_tip_speed_m_s: Option<Spanned<f64>>,
    #[serde(default)]
    max_joint_speed: Option<Spanned<[f64; 3]>>,
    #[serde(default)]
    link_timeout_ms: Option<Spanned<f64>>,
    #[serde(default)]
    friction_offset: Option<Spanned<[f64; 3]>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawLaw {
    kind: Spanned<String>,
    #[serde(default)]
    gain: Option<Spanned<f64>>,
    #[serde(default)]
    offset_n: Option<Spanned<f64>>,
    #[serde(default)]
    coeffs: Option<Spanned<Vec<f64>>>,
    #[serde(default)]
    domain_n: Option<Spanned<[f64; 2]>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawDisplayLaw {
    kind: Spanned<String>,
    coeffs: Spanned<Vec<f64>>,
    domain_m: Spanned<[f64; 2]>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawBank {
    #[serde(default)]
    couplings: Option<Spanned<String>>,
    #[serde(default)]
    truncation_radius_m: Option<Spanned<f64>>,
    #[serde(default)]
    precision: Option<Spanned<String>>,
    #[serde(default)]
    max_contact_nodes: Option<Spanned<u32>>,
    #[serde(default)]
    grid_cell_m: Option<Spanned<f64>>,
    #[serde(default)]
    reach_margin_m: Option<Spanned<f64>>,
}

/// Where the organ mesh comes from.
#[derive(Debug, Clone, PartialEq)]
pub enum MeshSource {
    /// The embedded 1.4k-node liver.
    BuiltinLiver,
    /// A file (already resolved against the scene file's directory).
    File(PathBuf),
}

/// One fixed box: the nodes inside the closed box get the selected components fixed.
#[derive(Debug, Clone, PartialEq)]
pub struct FixBox {
    /// `[xmin, ymin, zmin, xmax, ymax, zmax]`, m.
    pub bounds: [f64; 6],
    /// Components fixed (x, y, z).
    pub axes: [bool; 3],
    line: usize,
}

/// The tissue force law as given in the scene.
#[derive(Debug, Clone, PartialEq)]
pub enum LawSpec {
    /// `Q(f) = offset + gain f`.
    Linear {
        /// Offset, N.
        offset_n: f64,
        /// Gain (dimensionless).
        gain: f64,
        /// Range the gain was measured on, N.
        domain_n: [f64; 2],
    },
    /// Chebyshev series on `domain_n`.
    Chebyshev {
        /// Coefficients, N.
        coeffs: Vec<f64>,
        /// Fitted range, N.
        domain_n: [f64; 2],
    },
}

/// Which pairs of R the bank couples (besides every triangle edge).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Couplings {
    /// Every pair closer than `truncation_radius_m`.
    Radius,
    /// Every pair the scene's tool can put into one contact set (found by sampling R with the
    /// firmware's patch rule, see [`crate::bank::ToolPairs`]), and every pair closer than
    /// `truncation_radius_m` (default 0).
    Tool,
}

/// How the firmware renders a contact (`[contact] model`).
#[derive(Debug, Clone, PartialEq)]
pub enum ContactModel {
    /// The tool patch on the nodes of the scene's `mesh` (the bank's compliance blocks; the
    /// force depends on that mesh's resolution): for comparison.
    Nodal,
    /// The patch compliance `W(p)` of the scene's tool computed on a separate FEM mesh and
    /// sampled over the reachable surface (bank format 6, "contact samples"): the scene's
    /// `mesh` is then only the collision surface.
    Sampled(SampledContact),
}

/// The three resolutions of a sampled contact (`[contact]`): the FEM mesh and element the
/// patch compliance is computed on, and the sample lattice over the collision surface (the
/// scene's `mesh`).
#[derive(Debug, Clone, PartialEq)]
pub struct SampledContact {
    /// The FEM mesh (`fem_mesh`, resolved against the scene file's directory).
    pub fem_mesh: PathBuf,
    /// The element the patch compliance is computed with (`fem_element`, default `p2`).
    pub element: FemElement,
    /// Lattice steps per collision triangle side (`sample_level`, 1..=8, default 2).
    pub level: u32,
    /// Richardson extrapolation of the samples, if any (`richardson_mesh`,
    /// `richardson_ratio`, `richardson_order`).
    pub richardson: Option<Richardson>,
}

/// Richardson extrapolation of the sampled `W` towards the continuum: `W = W_f + (W_f - W_c)
/// / (ratio^order - 1)` from `W_f` on `fem_mesh` and `W_c` on a coarser mesh of the same organ
/// whose size is `ratio` times `fem_mesh`'s where the tool reaches.
#[derive(Debug, Clone, PartialEq)]
pub struct Richardson {
    /// The coarser FEM mesh (resolved against the scene file's directory).
    pub mesh: PathBuf,
    /// Its mesh size over `fem_mesh`'s, > 1.
    pub ratio: f64,
    /// The assumed order of convergence, in [0.5, 4].
    pub order: f64,
}

impl Richardson {
    /// The factor of `W_f - W_c`: `1 / (ratio^order - 1)`.
    pub fn factor(&self) -> f64 {
        1.0 / (self.ratio.powf(self.order) - 1.0)
    }
}

/// The element of a sampled contact's FEM mesh.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FemElement {
    /// A linear-displacement element on the mesh's vertices (P1 or ANP).
    Linear(Element),
    /// The 10-node quadratic tetrahedron ([`fem::elasticity::quadratic::QuadraticBody`]).
    Quadratic,
}

impl std::str::FromStr for FemElement {
    type Err = String;

    /// "p2", or a linear element's name ([`Element`]).
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "p2" => Ok(FemElement::Quadratic),
            e => e
                .parse::<Element>()
                .map(FemElement::Linear)
                .map_err(|why| format!("{why}, or \"p2\" (the 10-node tetrahedron)")),
        }
    }
}

impl FemElement {
    /// The name a scene uses: "p1", "anp" or "p2".
    pub fn name(self) -> &'static str {
        match self {
            FemElement::Linear(e) => e.name(),
            FemElement::Quadratic => "p2",
        }
    }
}

/// Default `[contact] sample_level`.
pub const DEFAULT_SAMPLE_LEVEL: u32 = 2;

/// Bank options.
#[derive(Debug, Clone, PartialEq)]
pub struct BankOptions {
    /// The coupling rule.
    pub couplings: Couplings,
    /// Every pair of R closer than this is coupled, m.
    pub truncation_radius_m: f64,
    /// Largest contact set the firmware solves (informative; checked against the link's limit).
    pub max_contact_nodes: u32,
    /// Collision-grid cell edge, m (`None`: chosen by the builder).
    pub grid_cell_m: Option<f64>,
    /// Extra distance beyond the tip radius at which a surface node still counts as reachable.
    pub reach_margin_m: f64,
    /// Storage precision of the coupling blocks `C_kl` (`bank.precision`, default f32).
    pub precision: bank_format::Precision,
}

/// A validated scene.
#[derive(Debug, Clone)]
pub struct Scene {
    /// The scene file.
    pub path: PathBuf,
    /// Organ mesh.
    pub mesh: MeshSource,
    /// Units of the mesh file's coordinates (`mesh_units`), scaled to metres on loading;
    /// `None`: the key is absent, the file is in metres unless it is implausible in metres and
    /// organ-sized in cm or mm ([`crate::meshing::guess_units`]), which [`Scene::load_mesh`]
    /// refuses.
    pub mesh_units: Option<Units>,
    /// Material.
    pub material: Material,
    /// Element formulation (`[material] element`, default the paper's P1).
    pub element: Element,
    /// Fixed boxes.
    pub fix_boxes: Vec<FixBox>,
    /// Fully fixed nodes.
    pub fix_nodes: Vec<usize>,
    fix_nodes_line: usize,
    /// Tool tip radius, m.
    pub tip_radius_m: f64,
    /// Device calibration (includes the tip radius).
    pub device: DeviceCalibration,
    /// Tissue law, validated.
    pub law: TissueLaw,
    /// The law as written.
    pub law_spec: LawSpec,
    /// Display law P (paper, eq. 4; m -> m), from the optional `[display_law]` table; `None`:
    /// the display shows the linear displacements.
    pub display_law: Option<TissueLaw>,
    /// Friction offsets measured by `host calibrate motor` (pitch, yaw: N m; insertion: N);
    /// recorded for the operator, default 0.
    pub friction_offset: [f64; 3],
    /// Gravity compensation of the instrument's weight from the optional `[gravity]` table:
    /// `[a_c, a_s, a_p, b_c, b_s, b_p, d_c, d_s]` (N m, N m, N m, N, N, N, N m, N m; `bank-format`
    /// `SPEC.md`, "gravity"). `None`: no compensation (the bank has no gravity section).
    pub gravity: Option<[f64; bank_format::GRAVITY_COEFFS]>,
    /// Viscoelastic relaxation from the optional `[viscoelastic]` table; `None`: elastic (the
    /// bank has no relaxation section).
    pub viscoelastic: Option<Viscoelastic>,
    /// Bank options.
    pub bank: BankOptions,
    /// The contact model (`[contact]`; absent: [`ContactModel::Nodal`]).
    pub contact: ContactModel,
    /// Identity of the scene: FNV-1a 64 of the scene file's bytes (the mesh is hashed in when
    /// the bank is built, see [`Scene::scene_id`]).
    pub text_hash: u64,
}

/// 1-based line of byte `offset` in `text`.
pub fn line_of(text: &str, offset: usize) -> usize {
    let end = offset.min(text.len());
    text.as_bytes()[..end]
        .iter()
        .filter(|&&b| b == b'\n')
        .count()
        + 1
}

/// FNV-1a, 64 bit.
pub fn fnv1a(seed: u64, bytes: &[u8]) -> u64 {
    bytes.iter().fold(seed, |h, &b| {
        (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3)
    })
}

/// FNV-1a 64 offset basis.
pub const FNV_OFFSET: u64 = 0xcbf2_9ce4_8422_2325;

struct Ctx<'a> {
    file: String,
    text: &'a str,
}

impl Ctx<'_> {
    fn err(&self, span: Range<usize>, key: &str, message: impl Into<String>) -> SceneError {
        SceneError {
            file: self.file.clone(),
            line: Some(line_of(self.text, span.start)),
            key: key.to_string(),
            message: message.into(),
        }
    }
}

fn finite<const N: usize>(ctx: &Ctx, v: &Spanned<[f64; N]>, key: &str) -> Result<(), SceneError> {
    if v.get_ref().iter().all(|x| x.is_finite()) {
        Ok(())
    } else {
        Err(ctx.err(v.span(), key, "values must be finite"))
    }
}

fn range(ctx: &Ctx, v: &Spanned<[f64; 2]>, key: &str) -> Result<[f64; 2], SceneError> {
    finite(ctx, v, key)?;
    let [a, b] = *v.get_ref();
    if a >= b {
        return Err(ctx.err(
            v.span(),
            key,
            format!("empty range [{a}, {b}]: need min < max"),
        ));
    }
    Ok([a, b])
}

fn unit(ctx: &Ctx, v: &Spanned<[f64; 3]>, key: &str) -> Result<[f64; 3], SceneError> {
    finite(ctx, v, key)?;
    let a = *v.get_ref();
    let n = (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt();
    if (n - 1.0).abs() > 1e-3 {
        return Err(ctx.err(
            v.span(),
            key,
            format!("must be a unit vector, has length {n}"),
        ));
    }
    Ok(a.map(|x| x / n))
}

fn positive3(
    ctx: &Ctx,
    v: &Spanned<[f64; 3]>,
    key: &str,
    max: f64,
) -> Result<[f32; 3], SceneError> {
    finite(ctx, v, key)?;
    for &x in v.get_ref() {
        if !(x > 0.0 && x <= max) {
            return Err(ctx.err(
                v.span(),
                key,
                format!("every value must lie in (0, {max}], got {x}"),
            ));
        }
    }
    Ok(v.get_ref().map(|x| x as f32))
}

impl Scene {
    /// Warnings about the scene that do not stop it (P1 locking above
    /// [`P1_LOCKING_WARN`]), for the commands to print.
    pub fn warnings(&self) -> Vec<String> {
        if self.element != Element::P1 {
            return Vec::new();
        }
        match p1_locking(self.material.poisson) {
            Locking::Stiffens(w) => vec![format!(
                "{}: {w} (or set [material] element = \"anp\", free of locking)",
                self.path.display()
            )],
            _ => Vec::new(),
        }
    }

    /// The scene file at `path`, or the embedded default liver scene ([`DEFAULT_SCENE`]).
    pub fn load_or_default(path: Option<&Path>) -> Result<Scene, SceneError> {
        match path {
            Some(p) => Scene::load(p),
            // Named in the source tree, so that its relative FEM meshes resolve from any
            // working directory.
            None => Scene::parse(
                Path::new(concat!(
                    env!("CARGO_MANIFEST_DIR"),
                    "/../scenes/liver.toml (embedded)"
                )),
                DEFAULT_SCENE,
            ),
        }
    }

    /// Reads and validates a scene file.
    pub fn load(path: &Path) -> Result<Scene, SceneError> {
        let text = std::fs::read_to_string(path).map_err(|e| SceneError {
            file: path.display().to_string(),
            line: None,
            key: "(file)".into(),
            message: format!("cannot read: {e}"),
        })?;
        Scene::parse(path, &text)
    }

    /// Parses and validates scene text; `path` names it in errors and anchors a relative mesh
    /// path.
    pub fn parse(path: &Path, text: &str) -> Result<Scene, SceneError> {
        let ctx = Ctx {
            file: path.display().to_string(),
            text,
        };
        let raw = parse_toml(&ctx)?;
        let mesh = parse_mesh(&ctx, path, &raw.mesh)?;
        let mesh_units = parse_mesh_units(&ctx, &raw, &mesh)?;
        let (material, element) = parse_material(&ctx, &raw.material)?;
        let (fix_boxes, fix_nodes, fix_nodes_line) = parse_fixed(&ctx, &raw.fixed)?;
        let tip_radius_m = parse_tool(&ctx, &raw.tool)?;
        let device = parse_device(&ctx, &raw.device, tip_radius_m)?;
        // Checked by `parse_device`; the linear law's default domain is [0, max_force_n].
        let max_force_n = *raw.device.max_force_n.get_ref();
        let (law_spec, law) = parse_law(&ctx, &raw.law, max_force_n)?;
        let display_law = raw
            .display_law
            .as_ref()
            .map(|p| parse_display_law(&ctx, p))
            .transpose()?;
        let friction_offset = parse_friction_offset(&ctx, &raw.device)?;
        let gravity = raw
            .gravity
            .as_ref()
            .map(|g| parse_gravity(&ctx, g))
            .transpose()?;
        let viscoelastic = raw
            .viscoelastic
            .as_ref()
            .map(|v| parse_viscoelastic(&ctx, v))
            .transpose()?;
        let bank = parse_bank(&ctx, &raw.bank)?;
        let contact = match &raw.contact {
            Some(c) => parse_contact(&ctx, path, c)?,
            None => ContactModel::Nodal,
        };
        if matches!(contact, ContactModel::Sampled(_)) && !fix_nodes.is_empty() {
            let at = ctx.text.find("nodes").unwrap_or(0);
            return Err(ctx.err(
                at..at,
                "fixed.nodes",
                "node ids name nodes of `mesh`, not of [contact] fem_mesh: a sampled contact \
                 takes its supports from fixed.boxes only",
            ));
        }
        Ok(Scene {
            path: path.to_path_buf(),
            mesh,
            mesh_units,
            material,
            element,
            fix_boxes,
            fix_nodes,
            fix_nodes_line,
            tip_radius_m,
            device,
            law,
            law_spec,
            display_law,
            friction_offset,
            gravity,
            viscoelastic,
            bank,
            contact,
            text_hash: fnv1a(FNV_OFFSET, text.as_bytes()),
        })
    }

    /// Loads the scene's mesh; returns it with a display name and its bytes' hash.
    pub fn load_mesh(&self) -> anyhow::Result<(TetMesh, String, u64)> {
        use anyhow::Context;
        match &self.mesh {
            MeshSource::BuiltinLiver => Ok((
                fem::mesh::parse_msh(BUILTIN_LIVER).context("embedded liver-1k4")?,
                "embedded liver-1k4.msh".into(),
                fnv1a(FNV_OFFSET, BUILTIN_LIVER),
            )),
            MeshSource::File(p) => {
                let (mesh, hash) = self.read_organ_mesh(p, "mesh")?;
                Ok((mesh, p.display().to_string(), hash))
            }
        }
    }

    /// Reads a tetrahedral mesh file of the scene's organ (`mesh`, or a sampled `[contact]`'s
    /// `fem_mesh` and `richardson_mesh`; `key` names it in errors) in the scene's `mesh_units`,
    /// scaled to metres and validated. Without `mesh_units` a mesh too small or too large to be
    /// an organ in metres is refused with the unit that fits. Returns the mesh and the hash of
    /// its bytes (and of its units, when not metres: they are part of its identity, a bank is
    /// cached by it).
    pub fn read_organ_mesh(&self, p: &Path, key: &str) -> anyhow::Result<(TetMesh, u64)> {
        use anyhow::Context;
        let bytes = std::fs::read(p)
            .with_context(|| format!("{}: {key} {}", self.path.display(), p.display()))?;
        let mut mesh = fem::mesh::read(p)?;
        let side = crate::meshing::largest_side(mesh.bounding_box());
        let units = match self.mesh_units {
            Some(u) => u,
            None => match crate::meshing::guess_units(side) {
                Ok(u) if u != Units::M => anyhow::bail!(
                    "{}: {key} {}: its largest side is {side:.4}, no organ in metres; in {} it \
                     is {:.3} m: set mesh_units = \"{}\" (or \"m\" to keep metres)",
                    self.path.display(),
                    p.display(),
                    u.name(),
                    side * u.to_metres(),
                    u.name()
                ),
                _ => Units::M,
            },
        };
        crate::meshing::scale_mesh(&mut mesh, units);
        fem::mesh::validate(&mesh).map_err(|e| e.with_path(p))?;
        let mut hash = fnv1a(FNV_OFFSET, &bytes);
        if units != Units::M {
            hash = fnv1a(hash, units.name().as_bytes());
        }
        Ok((mesh, hash))
    }

    /// The fixed set on `mesh`; errors name the scene line of the box or node list.
    pub fn fixed_set(&self, mesh: &TetMesh) -> Result<FixedSet, SceneError> {
        let mut fixed = FixedSet::none(mesh.nodes.len());
        let err = |line: usize, key: &str, message: String| SceneError {
            file: self.path.display().to_string(),
            line: Some(line),
            key: key.into(),
            message,
        };
        for b in &self.fix_boxes {
            fixed
                .fix_box(mesh, b.bounds, b.axes)
                .map_err(|e| err(b.line, "fixed.boxes", e.to_string()))?;
        }
        for &n in &self.fix_nodes {
            fixed
                .fix_node(n)
                .map_err(|e| err(self.fix_nodes_line, "fixed.nodes", e.to_string()))?;
        }
        Ok(fixed)
    }

    /// The files the scene reads besides itself (already resolved against its directory): the
    /// organ mesh unless it is the embedded one, and a sampled contact's FEM and Richardson
    /// meshes. A cache of anything built from the scene keys on their bytes too.
    pub fn input_files(&self) -> Vec<&Path> {
        let mesh = match &self.mesh {
            MeshSource::File(p) => Some(p.as_path()),
            MeshSource::BuiltinLiver => None,
        };
        let (fem, richardson) = match &self.contact {
            ContactModel::Sampled(s) => (
                Some(s.fem_mesh.as_path()),
                s.richardson.as_ref().map(|r| r.mesh.as_path()),
            ),
            _ => (None, None),
        };
        [mesh, fem, richardson].into_iter().flatten().collect()
    }

    /// The paths of [`Scene::input_files`], to edit.
    fn input_files_mut(&mut self) -> Vec<&mut PathBuf> {
        let mesh = match &mut self.mesh {
            MeshSource::File(p) => Some(p),
            MeshSource::BuiltinLiver => None,
        };
        let (fem, richardson) = match &mut self.contact {
            ContactModel::Sampled(s) => (
                Some(&mut s.fem_mesh),
                s.richardson.as_mut().map(|r| &mut r.mesh),
            ),
            _ => (None, None),
        };
        [mesh, fem, richardson].into_iter().flatten().collect()
    }

    /// FNV-1a 64 of the bytes of `file`, one the scene names (the error says so).
    pub fn file_hash(&self, file: &Path) -> anyhow::Result<u64> {
        use anyhow::Context;
        let bytes = std::fs::read(file).with_context(|| {
            format!(
                "cannot read {}, named by {}",
                file.display(),
                self.path.display()
            )
        })?;
        Ok(fnv1a(FNV_OFFSET, &bytes))
    }

    /// FNV-1a 64 over everything a bank is built from: the scene file's text, the validated
    /// scene (its `Debug` text without its path and its files' directories: a scene edited in
    /// memory after loading is not
    /// its file's), the bytes of every file it reads ([`Scene::input_files`]) or of the
    /// embedded liver, and the bank format version. The bank caches key on it
    /// ([`crate::bank::cache`] and [`crate::sil::bank`], each adding the code that builds).
    pub fn inputs_hash(&self) -> anyhow::Result<u64> {
        let mut h = self.text_hash;
        if self.mesh == MeshSource::BuiltinLiver {
            h = fnv1a(h, BUILTIN_LIVER);
        }
        for file in self.input_files() {
            h = fnv1a(h, &self.file_hash(file)?.to_le_bytes());
        }
        // Where the files lie is no input, their bytes are (above): the same scene reached as
        // `host/scenes/liver.toml` and as `tests/../host/scenes/liver.toml` has one key.
        let mut scene = self.clone();
        scene.path = PathBuf::new();
        for p in scene.input_files_mut() {
            *p = p.file_name().map(PathBuf::from).unwrap_or_default();
        }
        h = fnv1a(h, format!("{scene:?}").as_bytes());
        h = fnv1a(h, &bank_format::VERSION_MAJOR.to_le_bytes());
        Ok(fnv1a(h, &bank_format::VERSION_MINOR.to_le_bytes()))
    }

    /// The bank's scene id: FNV-1a 64 over the scene file's bytes, then the mesh bytes' hash.
    pub fn scene_id(&self, mesh_hash: u64) -> u64 {
        fnv1a(self.text_hash, &mesh_hash.to_le_bytes())
    }
}

/// The whole file: TOML syntax, missing and unknown keys, value types. The error's key is the
/// field the TOML error names (`(syntax)` when it names none).
fn parse_toml(ctx: &Ctx) -> Result<RawScene, SceneError> {
    toml::from_str(ctx.text).map_err(|e| {
        let message = e.message().trim().to_string();
        let key = message
            .split('`')
            .nth(1)
            .filter(|_| message.contains("field"))
            .unwrap_or("(syntax)")
            .to_string();
        SceneError {
            file: ctx.file.clone(),
            line: e.span().map(|s| line_of(ctx.text, s.start)),
            key,
            message,
        }
    })
}

/// `mesh`: [`BUILTIN_LIVER_NAME`], no other `builtin:` name, or a file path resolved against
/// the scene file's directory.
fn parse_mesh(ctx: &Ctx, path: &Path, mesh: &Spanned<String>) -> Result<MeshSource, SceneError> {
    if mesh.get_ref() == BUILTIN_LIVER_NAME {
        Ok(MeshSource::BuiltinLiver)
    } else if mesh.get_ref().starts_with("builtin:") {
        Err(ctx.err(
            mesh.span(),
            "mesh",
            format!(
                "unknown built-in mesh {:?} (available: {BUILTIN_LIVER_NAME:?})",
                mesh.get_ref()
            ),
        ))
    } else {
        let dir = path.parent().unwrap_or(Path::new("."));
        Ok(MeshSource::File(dir.join(mesh.get_ref())))
    }
}

/// `mesh_units`: "m", "cm" or "mm", only for a mesh file (the embedded liver is in metres). It
/// holds for every mesh of the organ: `mesh` and a sampled `[contact]`'s `fem_mesh` and
/// `richardson_mesh` ([`Scene::read_organ_mesh`]).
fn parse_mesh_units(
    ctx: &Ctx,
    raw: &RawScene,
    mesh: &MeshSource,
) -> Result<Option<Units>, SceneError> {
    let Some(u) = &raw.mesh_units else {
        return Ok(None);
    };
    let units: Units = u
        .get_ref()
        .parse()
        .map_err(|e| ctx.err(u.span(), "mesh_units", e))?;
    if units == Units::M {
        return Ok(Some(units));
    }
    if *mesh == MeshSource::BuiltinLiver {
        return Err(ctx.err(
            u.span(),
            "mesh_units",
            format!(
                "the embedded liver is in metres: mesh_units must be \"m\", got {:?}",
                units.name()
            ),
        ));
    }
    Ok(Some(units))
}

/// `[contact]`: `model` "sampled" (default) or "nodal"; with "sampled", `fem_mesh` (required: a
/// path relative to the scene file), `fem_element` "p1", "anp" or "p2" (default), `sample_level`
/// in `1..=`[`bank_format::MAX_SAMPLE_LEVEL`] (default [`DEFAULT_SAMPLE_LEVEL`]); with "nodal",
/// none of them.
fn parse_contact(ctx: &Ctx, path: &Path, c: &RawContact) -> Result<ContactModel, SceneError> {
    let sampled = match &c.model {
        None => true,
        Some(m) => match m.get_ref().as_str() {
            "sampled" => true,
            "nodal" => false,
            other => {
                return Err(ctx.err(
                    m.span(),
                    "contact.model",
                    format!("must be \"sampled\" or \"nodal\", got {other:?}"),
                ));
            }
        },
    };
    if !sampled {
        let extra = [
            c.fem_mesh.as_ref().map(|v| (v.span(), "contact.fem_mesh")),
            c.fem_element
                .as_ref()
                .map(|v| (v.span(), "contact.fem_element")),
            c.sample_level
                .as_ref()
                .map(|v| (v.span(), "contact.sample_level")),
        ];
        if let Some((span, key)) = extra.into_iter().flatten().next() {
            return Err(ctx.err(span, key, "only a sampled contact model takes this key"));
        }
        return Ok(ContactModel::Nodal);
    }
    let Some(mesh) = &c.fem_mesh else {
        let at = ctx.text.find("[contact]").unwrap_or(0);
        return Err(ctx.err(
            at..at,
            "contact.fem_mesh",
            "missing: the sampled contact model needs the FEM mesh its patch compliance is \
             computed on",
        ));
    };
    if mesh.get_ref().starts_with("builtin:") {
        return Err(ctx.err(
            mesh.span(),
            "contact.fem_mesh",
            "must be a mesh file (a path relative to the scene file)",
        ));
    }
    let dir = path.parent().unwrap_or(Path::new("."));
    let element = match &c.fem_element {
        None => FemElement::Quadratic,
        Some(e) => e
            .get_ref()
            .parse::<FemElement>()
            .map_err(|why| ctx.err(e.span(), "contact.fem_element", why))?,
    };
    let level = match &c.sample_level {
        None => DEFAULT_SAMPLE_LEVEL,
        Some(l) => {
            let v = *l.get_ref();
            if !(1..=bank_format::MAX_SAMPLE_LEVEL).contains(&v) {
                return Err(ctx.err(
                    l.span(),
                    "contact.sample_level",
                    format!(
                        "must lie in 1..={} (lattice steps per collision triangle side), got {v}",
                        bank_format::MAX_SAMPLE_LEVEL
                    ),
                ));
            }
            v
        }
    };
    let richardson = match (&c.richardson_mesh, &c.richardson_ratio, &c.richardson_order) {
        (None, None, None) => None,
        (Some(m), Some(r), order) => {
            let ratio = *r.get_ref();
            if !(ratio > 1.01 && ratio <= 4.0) {
                return Err(ctx.err(
                    r.span(),
                    "contact.richardson_ratio",
                    format!("must lie in (1.01, 4] (coarse mesh size / fine), got {ratio}"),
                ));
            }
            let order = match order {
                None => 2.0,
                Some(o) => {
                    let v = *o.get_ref();
                    if !(0.5..=4.0).contains(&v) {
                        return Err(ctx.err(
                            o.span(),
                            "contact.richardson_order",
                            format!("must lie in [0.5, 4], got {v}"),
                        ));
                    }
                    v
                }
            };
            Some(Richardson {
                mesh: dir.join(m.get_ref()),
                ratio,
                order,
            })
        }
        _ => {
            let at = ctx.text.find("richardson").unwrap_or(0);
            return Err(ctx.err(
                at..at,
                "contact.richardson_mesh",
                "richardson_mesh and richardson_ratio go together (richardson_order is \
                 optional, default 2)",
            ));
        }
    };
    Ok(ContactModel::Sampled(SampledContact {
        fem_mesh: dir.join(mesh.get_ref()),
        element,
        level,
        richardson,
    }))
}

/// `[material]`: `young_pa` in [`YOUNG_RANGE_PA`], `poisson` in (-1, 0.5) (for P1 at most
/// [`P1_LOCKING_REFUSE`]), `element` one of [`Element::ALL`] (default `p1`), then whatever
/// [`Material::new`] rejects.
fn parse_material(ctx: &Ctx, m: &RawMaterial) -> Result<(Material, Element), SceneError> {
    let (e, nu) = (*m.young_pa.get_ref(), *m.poisson.get_ref());
    if !(e.is_finite() && e > 0.0) {
        return Err(ctx.err(
            m.young_pa.span(),
            "material.young_pa",
            format!("Young's modulus must be > 0 Pa, got {e}"),
        ));
    }
    if !(YOUNG_RANGE_PA.0..=YOUNG_RANGE_PA.1).contains(&e) {
        return Err(ctx.err(
            m.young_pa.span(),
            "material.young_pa",
            format!(
                "{e} Pa is outside [{:e}, {:e}] Pa, the range this product models (soft tissue is \
                 1e2-1e6 Pa); outside it the bank's f32 compliance under- or overflows",
                YOUNG_RANGE_PA.0, YOUNG_RANGE_PA.1
            ),
        ));
    }
    if !(nu > -1.0 && nu < 0.5) {
        return Err(ctx.err(
            m.poisson.span(),
            "material.poisson",
            format!("Poisson's ratio must lie in (-1, 0.5), got {nu}"),
        ));
    }
    let element = match &m.element {
        Some(name) => name
            .get_ref()
            .parse::<Element>()
            .map_err(|why| ctx.err(name.span(), "material.element", why))?,
        None => Element::P1,
    };
    if element == Element::P1
        && let Locking::Meaningless(why) = p1_locking(nu)
    {
        return Err(ctx.err(
            m.poisson.span(),
            "material.poisson",
            format!("{why} (or use element = \"anp\", free of locking)"),
        ));
    }
    let material = Material::new(e, nu)
        .map_err(|err| ctx.err(m.young_pa.span(), "material", err.to_string()))?;
    Ok((material, element))
}

/// Collision grid cells a scene may ask for, m.
pub const GRID_CELL_RANGE_M: (f64, f64) = (1e-4, 1.0);

/// Young's moduli a scene may have, Pa: from a gel to hard plastics. The bank stores compliance
/// in f32, and a 10 cm organ's node compliance is about 1 / (E x 0.01 m): these bounds keep it
/// within 1e-12..1e2 m/N, far inside f32's range and its SPD checks' resolution.
pub const YOUNG_RANGE_PA: (f64, f64) = (1.0, 1.0e10);

/// Poisson's ratio above which P1 tetrahedra are warned about: at 0.45 the locking excess on the
/// shipped livers is 3 % (10k nodes) to 21 % (1.4k); it grows like 1 / (1 - 2 nu) beyond.
pub const P1_LOCKING_WARN: f64 = 0.45;
/// Poisson's ratio above which P1 results are refused as meaningless: at 0.499 P1 answers 1.8x
/// (10k liver) to 2.9x (1.4k liver) too stiff; at 0.4999 a node's compliance is a twentieth of its
/// value at 0.45, a locked answer, not tissue.
pub const P1_LOCKING_REFUSE: f64 = 0.499;

/// What P1 locking does to a result at Poisson's ratio `nu`.
#[derive(Debug, Clone, PartialEq)]
pub enum Locking {
    /// Negligible.
    Fine,
    /// Stiffer than the tissue by the stated amount: warn.
    Stiffens(String),
    /// Locked: refuse, saying why and what to do.
    Meaningless(String),
}

/// P1 locking at Poisson's ratio `nu`, with the stiffening measured against quadratic
/// elements on the shipped livers (bed fixed, a 10 mm flat punch pressed 5 mm; issue 18's
/// table: P1 / P2 force 1.21 / 1.03 at 0.45, 1.49 / 1.16 at 0.49, 2.85 / 1.80 at 0.499 on the
/// 1.4k / 10k liver).
pub fn p1_locking(nu: f64) -> Locking {
    if nu > P1_LOCKING_REFUSE {
        Locking::Meaningless(format!(
            "Poisson's ratio {nu} > {P1_LOCKING_REFUSE}: linear tetrahedra lock (at 0.499 they \
             already answer 1.8-2.9x too stiff on the shipped livers, and worse beyond), so the \
             result would describe the element, not the tissue; use at most \
             {P1_LOCKING_REFUSE} and fit the remaining stiffness into the tissue law Q"
        ))
    } else if nu > P1_LOCKING_WARN {
        let (coarse, fine) = if nu <= 0.49 {
            ("1.2-1.5x", "1.03-1.16x")
        } else {
            ("1.5-2.9x", "1.16-1.8x")
        };
        Locking::Stiffens(format!(
            "warning: Poisson's ratio {nu} > {P1_LOCKING_WARN}: linear tetrahedra lock, answering \
             about {coarse} too stiff on a 1.4k-node liver and {fine} on a 10k-node one (P1 \
             against quadratic elements); a finer mesh lessens it"
        ))
    } else {
        Locking::Fine
    }
}

/// `[fixed]`: every box finite with min <= max, `axes` default "xyz"; `nodes` default none (line
/// 0); at least one box or node. Returns the boxes, the nodes and the line of the node list.
fn parse_fixed(
    ctx: &Ctx,
    fixed: &RawFixed,
) -> Result<(Vec<FixBox>, Vec<usize>, usize), SceneError> {
    let mut fix_boxes = Vec::new();
    for b in &fixed.boxes {
        let key = "fixed.boxes";
        let r = b.get_ref();
        let mut bounds = [0.0; 6];
        bounds[..3].copy_from_slice(&r.min);
        bounds[3..].copy_from_slice(&r.max);
        if bounds.iter().any(|v| !v.is_finite()) || (0..3).any(|a| r.min[a] > r.max[a]) {
            return Err(ctx.err(
                b.span(),
                key,
                "box bounds must be finite with min <= max on every axis",
            ));
        }
        let axes = match &r.axes {
            None => [true; 3],
            Some(s) => {
                FixedSet::parse_axes(s).map_err(|msg| ctx.err(b.span(), "fixed.boxes.axes", msg))?
            }
        };
        fix_boxes.push(FixBox {
            bounds,
            axes,
            line: line_of(ctx.text, b.span().start),
        });
    }
    let (fix_nodes, fix_nodes_line) = match &fixed.nodes {
        Some(n) => (n.get_ref().clone(), line_of(ctx.text, n.span().start)),
        None => (Vec::new(), 0),
    };
    if fix_boxes.is_empty() && fix_nodes.is_empty() {
        return Err(SceneError {
            file: ctx.file.clone(),
            line: Some(line_of(ctx.text, ctx.text.find("[fixed]").unwrap_or(0))),
            key: "fixed".into(),
            message: "nothing is fixed: give boxes and/or nodes (the body would float)".into(),
        });
    }
    Ok((fix_boxes, fix_nodes, fix_nodes_line))
}

/// `[tool]`: `tip_radius_m` in [0, 0.05]; returns it.
fn parse_tool(ctx: &Ctx, tool: &RawTool) -> Result<f64, SceneError> {
    let tip = *tool.tip_radius_m.get_ref();
    if !(0.0..=0.05).contains(&tip) {
        return Err(ctx.err(
            tool.tip_radius_m.span(),
            "tool.tip_radius_m",
            format!("must lie in [0, 0.05] m, got {tip}"),
        ));
    }
    Ok(tip)
}

/// `[device]` (all but `friction_offset`, see [`parse_friction_offset`]): finite fulcrum,
/// orthonormal unit axes, non-empty joint ranges (pitch inside (-pi/2, pi/2), yaw inside
/// [-pi, pi], insertion >= 0), `home` inside the ranges (default: 0 clamped into the pitch and yaw
/// ranges, minimum insertion), counts > 0, non-zero finite gear ratios, torque constants > 0,
/// current limits in (0, 20], `max_force_n` in (0, 50], the speed thresholds
/// ([`parse_speed_limits`]); then [`bank_format::validate_device`]. `tip` is the tool's tip
/// radius, m.
fn parse_device(ctx: &Ctx, d: &RawDevice, tip: f64) -> Result<DeviceCalibration, SceneError> {
    finite(ctx, &d.fulcrum_m, "device.fulcrum_m")?;
    let shaft = unit(ctx, &d.shaft_axis, "device.shaft_axis")?;
    let pitch_axis = unit(ctx, &d.pitch_axis, "device.pitch_axis")?;
    let yaw_axis = unit(ctx, &d.yaw_axis, "device.yaw_axis")?;
    let dot = |a: [f64; 3], b: [f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    for (a, b, key, span) in [
        (shaft, pitch_axis, "device.pitch_axis", d.pitch_axis.span()),
        (shaft, yaw_axis, "device.yaw_axis", d.yaw_axis.span()),
        (pitch_axis, yaw_axis, "device.yaw_axis", d.yaw_axis.span()),
    ] {
        if dot(a, b).abs() > 1e-3 {
            return Err(ctx.err(
                span,
                key,
                "shaft_axis, pitch_axis and yaw_axis must be pairwise orthogonal",
            ));
        }
    }
    let pitch = range(ctx, &d.pitch_range_rad, "device.pitch_range_rad")?;
    let yaw = range(ctx, &d.yaw_range_rad, "device.yaw_range_rad")?;
    let ins = range(ctx, &d.insertion_range_m, "device.insertion_range_m")?;
    let half_pi = std::f64::consts::FRAC_PI_2;
    if pitch[0] <= -half_pi || pitch[1] >= half_pi {
        return Err(ctx.err(
            d.pitch_range_rad.span(),
            "device.pitch_range_rad",
            "pitch must stay inside (-pi/2, pi/2)",
        ));
    }
    if yaw[0] < -std::f64::consts::PI || yaw[1] > std::f64::consts::PI {
        return Err(ctx.err(
            d.yaw_range_rad.span(),
            "device.yaw_range_rad",
            "yaw must stay inside [-pi, pi]",
        ));
    }
    if ins[0] < 0.0 {
        return Err(ctx.err(
            d.insertion_range_m.span(),
            "device.insertion_range_m",
            "insertion must be >= 0 m",
        ));
    }
    let home = match &d.home {
        Some(h) => {
            finite(ctx, h, "device.home")?;
            let h3 = *h.get_ref();
            for (j, r) in [pitch, yaw, ins].iter().enumerate() {
                if !(r[0] <= h3[j] && h3[j] <= r[1]) {
                    return Err(ctx.err(
                        h.span(),
                        "device.home",
                        format!("joint {j} home {} is outside [{}, {}]", h3[j], r[0], r[1]),
                    ));
                }
            }
            h3
        }
        None => [
            0.0f64.clamp(pitch[0], pitch[1]),
            0.0f64.clamp(yaw[0], yaw[1]),
            ins[0],
        ],
    };
    if d.counts_per_rev.get_ref().contains(&0) {
        return Err(ctx.err(
            d.counts_per_rev.span(),
            "device.counts_per_rev",
            "counts per revolution must be > 0",
        ));
    }
    finite(ctx, &d.gear_ratio, "device.gear_ratio")?;
    if d.gear_ratio.get_ref().iter().any(|g| g.abs() < 1e-6) {
        return Err(ctx.err(
            d.gear_ratio.span(),
            "device.gear_ratio",
            "gear ratios must be non-zero (|ratio| >= 1e-6; the sign is the motor direction)",
        ));
    }
    let kt = positive3(
        ctx,
        &d.torque_constant_nm_per_a,
        "device.torque_constant_nm_per_a",
        // The largest DC motors of haptic devices have a few tenths of N m/A.
        10.0,
    )?;
    let imax = positive3(ctx, &d.current_limit_a, "device.current_limit_a", 20.0)?;
    let fmax = *d.max_force_n.get_ref();
    if !(fmax > 0.0 && fmax <= 50.0) {
        return Err(ctx.err(
            d.max_force_n.span(),
            "device.max_force_n",
            format!("must lie in (0, 50] N, got {fmax}"),
        ));
    }
    let (tip_speed, joint_speed) = parse_speed_limits(ctx, d)?;
    let link_timeout_ms = parse_link_timeout(ctx, d)?;
    let f32s = |a: [f64; 3]| a.map(|x| x as f32);
    let device = DeviceCalibration {
        fulcrum_m: f32s(*d.fulcrum_m.get_ref()),
        shaft_axis: f32s(shaft),
        pitch_axis: f32s(pitch_axis),
        yaw_axis: f32s(yaw_axis),
        joint_min: f32s([pitch[0], yaw[0], ins[0]]),
        joint_max: f32s([pitch[1], yaw[1], ins[1]]),
        home_joint: f32s(home),
        counts_per_rev: *d.counts_per_rev.get_ref(),
        transmission: f32s(*d.gear_ratio.get_ref()),
        torque_constant_nm_per_a: kt,
        current_limit_a: imax,
        max_force_n: fmax as f32,
        tip_radius_m: tip as f32,
        max_tip_speed_m_s: tip_speed as f32,
        max_joint_speed: f32s(joint_speed),
        link_timeout_ms,
    };
    bank_format::validate_device(&device)
        .map_err(|e| ctx.err(d.fulcrum_m.span(), "device", e.to_string()))?;
    Ok(device)
}

/// `device.link_timeout_ms` (optional, default [`bank_format::DEFAULT_LINK_TIMEOUT_MS`]): a whole
/// number of ms in [`bank_format::LINK_TIMEOUT_MS_MIN`]`..=`[`bank_format::LINK_TIMEOUT_MS_MAX`]
/// (`bank-format` `SPEC.md`, "Link timeout").
fn parse_link_timeout(ctx: &Ctx, d: &RawDevice) -> Result<u32, SceneError> {
    let Some(v) = &d.link_timeout_ms else {
        return Ok(bank_format::DEFAULT_LINK_TIMEOUT_MS);
    };
    let (lo, hi) = (
        bank_format::LINK_TIMEOUT_MS_MIN,
        bank_format::LINK_TIMEOUT_MS_MAX,
    );
    let ms = *v.get_ref();
    if ms.fract() == 0.0 && ms >= f64::from(lo) && ms <= f64::from(hi) {
        // Whole and within [5, 100]: exact as u32.
        return Ok(ms as u32);
    }
    Err(ctx.err(
        v.span(),
        "device.link_timeout_ms",
        format!(
            "must be a whole number of ms in [{lo}, {hi}], got {ms} (the host's heartbeat comes \
             every 2 ms; `host bench heartbeat` measures how late it can be)"
        ),
    ))
}

/// `device.max_tip_speed_m_s` (optional, default [`DEFAULT_MAX_TIP_SPEED_M_S`]) finite and > 0;
/// `device.max_joint_speed` (optional, default derived from the tip's, see
/// [`DEFAULT_SPEED_LEVER_M`]) finite, > 0 and below the firmware's encoder-jump speeds
/// ([`firmware::safety::DEFAULT_JUMP_SPEED`]): a move faster than those counts as an encoder
/// glitch, so a threshold at or above them would never report an overspeed. Returns the tip's
/// (m/s) and the joints' (rad/s, rad/s, m/s).
fn parse_speed_limits(ctx: &Ctx, d: &RawDevice) -> Result<(f64, [f64; 3]), SceneError> {
    let jump = firmware::safety::DEFAULT_JUMP_SPEED.map(f64::from);
    let tip = match &d.max_tip_speed_m_s {
        Some(v) => {
            let x = *v.get_ref();
            if !(x.is_finite() && x > 0.0) {
                return Err(ctx.err(
                    v.span(),
                    "device.max_tip_speed_m_s",
                    format!("must be > 0 m/s, got {x}"),
                ));
            }
            x
        }
        None => DEFAULT_MAX_TIP_SPEED_M_S,
    };
    let below_jump = |v: [f64; 3]| (0..3).all(|j| v[j] < jump[j]);
    let joints = match &d.max_joint_speed {
        Some(v) => {
            finite(ctx, v, "device.max_joint_speed")?;
            let x = *v.get_ref();
            if !x.iter().all(|&s| s > 0.0) {
                return Err(ctx.err(
                    v.span(),
                    "device.max_joint_speed",
                    format!("every value must be > 0 (rad/s, rad/s, m/s), got {x:?}"),
                ));
            }
            if !below_jump(x) {
                return Err(ctx.err(
                    v.span(),
                    "device.max_joint_speed",
                    format!(
                        "{x:?} must stay below the firmware's encoder-jump speeds {jump:?} \
                         (rad/s, rad/s, m/s), above which a move counts as an encoder glitch"
                    ),
                ));
            }
            x
        }
        None => {
            let derived = [
                tip / DEFAULT_SPEED_LEVER_M,
                tip / DEFAULT_SPEED_LEVER_M,
                tip,
            ];
            if !below_jump(derived) {
                let span = d.max_tip_speed_m_s.as_ref().map_or(0..0, |v| v.span());
                return Err(ctx.err(
                    span,
                    "device.max_tip_speed_m_s",
                    format!(
                        "the default device.max_joint_speed derived from it, {derived:?}, is not \
                         below the firmware's encoder-jump speeds {jump:?}: give \
                         device.max_joint_speed"
                    ),
                ));
            }
            derived
        }
    };
    Ok((tip, joints))
}

/// `[law]`: `domain_n` a non-empty range when given; `kind` "linear" (no `coeffs`; `gain` > 0,
/// default 1; `offset_n` default 0; `domain_n` default [0, `fmax`]) or "chebyshev" (no `gain` or
/// `offset_n`; `coeffs` and `domain_n` required); then what [`TissueLaw`] rejects. `fmax` is
/// `device.max_force_n`, N.
fn parse_law(ctx: &Ctx, l: &RawLaw, fmax: f64) -> Result<(LawSpec, TissueLaw), SceneError> {
    let law_key_span = l.kind.span();
    let domain = match &l.domain_n {
        Some(dn) => Some(range(ctx, dn, "law.domain_n")?),
        None => None,
    };
    match l.kind.get_ref().as_str() {
        "linear" => {
            if let Some(c) = &l.coeffs {
                return Err(ctx.err(c.span(), "law.coeffs", "only for kind = \"chebyshev\""));
            }
            let gain = l.gain.as_ref().map_or(1.0, |g| *g.get_ref());
            let offset = l.offset_n.as_ref().map_or(0.0, |o| *o.get_ref());
            if !(gain > 0.0 && gain.is_finite()) {
                let span = l.gain.as_ref().map_or(law_key_span.clone(), |g| g.span());
                return Err(ctx.err(span, "law.gain", format!("must be > 0, got {gain}")));
            }
            if !offset.is_finite() || offset < 0.0 {
                let span = l
                    .offset_n
                    .as_ref()
                    .map_or(law_key_span.clone(), |o| o.span());
                return Err(ctx.err(
                    span,
                    "law.offset_n",
                    format!(
                        "must be >= 0, got {offset}: Q(0) < 0 would pull the tool into the \
                         tissue at first contact"
                    ),
                ));
            }
            let domain_n = domain.unwrap_or([0.0, fmax]);
            let law = TissueLaw::linear(offset as f32, gain as f32, domain_n.map(|v| v as f32))
                .map_err(|e| ctx.err(law_key_span.clone(), "law", e.to_string()))?;
            Ok((
                LawSpec::Linear {
                    offset_n: offset,
                    gain,
                    domain_n,
                },
                law,
            ))
        }
        "chebyshev" => {
            for (present, key) in [
                (l.gain.as_ref().map(|g| g.span()), "law.gain"),
                (l.offset_n.as_ref().map(|g| g.span()), "law.offset_n"),
            ] {
                if let Some(span) = present {
                    return Err(ctx.err(span, key, "only for kind = \"linear\""));
                }
            }
            let Some(c) = &l.coeffs else {
                return Err(ctx.err(law_key_span, "law.coeffs", "required for chebyshev"));
            };
            let Some(domain_n) = domain else {
                return Err(ctx.err(law_key_span, "law.domain_n", "required for chebyshev"));
            };
            let coeffs: Vec<f32> = c.get_ref().iter().map(|&v| v as f32).collect();
            let law = TissueLaw::chebyshev(&coeffs, domain_n.map(|v| v as f32))
                .map_err(|e| ctx.err(c.span(), "law.coeffs", e.to_string()))?;
            if let Some(q0) = pull_at_first_contact(&law) {
                return Err(ctx.err(
                    c.span(),
                    "law.coeffs",
                    format!(
                        "the law gives Q(0) = {q0} N: it would pull the tool into the tissue at \
                         first contact"
                    ),
                ));
            }
            Ok((
                LawSpec::Chebyshev {
                    coeffs: c.get_ref().clone(),
                    domain_n,
                },
                law,
            ))
        }
        other => Err(ctx.err(
            law_key_span,
            "law.kind",
            format!("unknown law {other:?} (use \"linear\" or \"chebyshev\")"),
        )),
    }
}

/// How far below zero Q(0) may be, relative to Q at the end of its domain (the largest force
/// it renders): a fit to measured data leaves residuals of that order (the shipped brain data's
/// fits: up to 0.5 % of full scale at their worst point), and a pull that small is below what
/// the device resolves.
pub const PULL_TOLERANCE: f32 = 0.005;

/// `Some(Q(0))` when a tissue law would pull the tool in at first contact: Q(0) below
/// `-PULL_TOLERANCE` times Q at the end of its domain, or not a number.
pub fn pull_at_first_contact(law: &TissueLaw) -> Option<f32> {
    let q0 = law.eval(0.0);
    let full = law.eval(law.domain()[1]).abs();
    (q0.is_nan() || q0 < -PULL_TOLERANCE * full).then_some(q0)
}

/// `[display_law]` (optional table): `kind` "chebyshev", `domain_m` a non-empty range, then what
/// [`TissueLaw::chebyshev`] rejects in `coeffs`.
fn parse_display_law(ctx: &Ctx, p: &RawDisplayLaw) -> Result<TissueLaw, SceneError> {
    if p.kind.get_ref() != "chebyshev" {
        return Err(ctx.err(
            p.kind.span(),
            "display_law.kind",
            format!("unknown law {:?} (use \"chebyshev\")", p.kind.get_ref()),
        ));
    }
    let domain = range(ctx, &p.domain_m, "display_law.domain_m")?;
    let coeffs: Vec<f32> = p.coeffs.get_ref().iter().map(|&v| v as f32).collect();
    TissueLaw::chebyshev(&coeffs, domain.map(|v| v as f32))
        .map_err(|e| ctx.err(p.coeffs.span(), "display_law.coeffs", e.to_string()))
}

/// `device.friction_offset` (optional): finite, default 0. Checked after `[law]` and
/// `[display_law]`, as it always was, so a file with several errors reports the same one.
fn parse_friction_offset(ctx: &Ctx, d: &RawDevice) -> Result<[f64; 3], SceneError> {
    match &d.friction_offset {
        Some(f) => {
            finite(ctx, f, "device.friction_offset")?;
            Ok(*f.get_ref())
        }
        None => Ok([0.0; 3]),
    }
}

/// `[gravity]`: eight finite coefficients, each within the bank's
/// [`bank_format::GRAVITY_COEFF_MAX`] (N m or N).
fn parse_gravity(
    ctx: &Ctx,
    g: &RawGravity,
) -> Result<[f64; bank_format::GRAVITY_COEFFS], SceneError> {
    finite(ctx, &g.coeffs, "gravity.coeffs")?;
    let c = *g.coeffs.get_ref();
    let max = f64::from(bank_format::GRAVITY_COEFF_MAX);
    if let Some(i) = c.iter().position(|v| v.abs() > max) {
        return Err(ctx.err(
            g.coeffs.span(),
            "gravity.coeffs",
            format!(
                "coefficient {i} is {}: beyond +-{max} (N m or N), a unit or sign error",
                c[i]
            ),
        ));
    }
    Ok(c)
}

/// `[viscoelastic]`: [`Viscoelastic::record`]'s rules, the error on the table's `g` line
/// (`tau_s`'s for a time constant).
fn parse_viscoelastic(ctx: &Ctx, v: &RawViscoelastic) -> Result<Viscoelastic, SceneError> {
    let out = Viscoelastic {
        g: v.g.get_ref().clone(),
        tau_s: v.tau_s.get_ref().clone(),
    };
    match out.record() {
        Ok(_) => Ok(out),
        Err(m) if m.contains("tau =") => Err(ctx.err(v.tau_s.span(), "viscoelastic.tau_s", m)),
        Err(m) => Err(ctx.err(v.g.span(), "viscoelastic.g", m)),
    }
}

/// `[bank]`: `couplings` "radius" (default) or "tool"; `truncation_radius_m` finite and >= 0
/// (required with "radius", default 0 with "tool"); `precision` "f32" (default);
/// `max_contact_nodes` in 1..=[`bank_format::MAX_CONTACTS`] (default the maximum);
/// `grid_cell_m` > 0 (default `None`, the builder's choice); `reach_margin_m` >= 0 (default
/// 0.002 m).
fn parse_bank(ctx: &Ctx, b: &RawBank) -> Result<BankOptions, SceneError> {
    let couplings = match &b.couplings {
        None => Couplings::Radius,
        Some(c) => match c.get_ref().as_str() {
            "radius" => Couplings::Radius,
            "tool" => Couplings::Tool,
            other => {
                return Err(ctx.err(
                    c.span(),
                    "bank.couplings",
                    format!("must be \"radius\" or \"tool\", got {other:?}"),
                ));
            }
        },
    };
    let r = match (&b.truncation_radius_m, couplings) {
        (Some(r), _) => {
            let v = *r.get_ref();
            if !(v.is_finite() && v >= 0.0) {
                return Err(ctx.err(
                    r.span(),
                    "bank.truncation_radius_m",
                    format!("must be >= 0 m, got {v}"),
                ));
            }
            v
        }
        (None, Couplings::Tool) => 0.0,
        (None, Couplings::Radius) => {
            let at = ctx.text.find("[bank]").unwrap_or(0);
            return Err(ctx.err(
                at..at,
                "bank.truncation_radius_m",
                "missing: required unless bank.couplings = \"tool\"".to_string(),
            ));
        }
    };
    let precision = match &b.precision {
        None => bank_format::Precision::F32,
        Some(p) => bank_format::Precision::from_name(p.get_ref()).ok_or_else(|| {
            ctx.err(
                p.span(),
                "bank.precision",
                format!(
                    "storage precision {:?} is not one of bank format 5.0's: \"f32\" or \"bfp16\" \
                     (16-bit mantissas, one exponent per block)",
                    p.get_ref()
                ),
            )
        })?,
    };
    let max_contact_nodes = match &b.max_contact_nodes {
        Some(m) => {
            let v = *m.get_ref();
            if v == 0 || v as usize > bank_format::MAX_CONTACTS {
                return Err(ctx.err(
                    m.span(),
                    "bank.max_contact_nodes",
                    format!(
                        "must lie in 1..={} (the link's contact list), got {v}",
                        bank_format::MAX_CONTACTS
                    ),
                ));
            }
            v
        }
        None => bank_format::MAX_CONTACTS as u32,
    };
    let grid_cell_m = match &b.grid_cell_m {
        Some(g) => {
            let v = *g.get_ref();
            if !(GRID_CELL_RANGE_M.0..=GRID_CELL_RANGE_M.1).contains(&v) {
                return Err(ctx.err(
                    g.span(),
                    "bank.grid_cell_m",
                    format!(
                        "{v} m is outside [{}, {}] m: smaller cells than a tenth of a millimetre \
                         make a grid too large for the bank, larger ones hold the whole organ",
                        GRID_CELL_RANGE_M.0, GRID_CELL_RANGE_M.1
                    ),
                ));
            }
            Some(v)
        }
        None => None,
    };
    let reach_margin_m = match &b.reach_margin_m {
        Some(g) => {
            let v = *g.get_ref();
            if !(v.is_finite() && v >= 0.0) {
                return Err(ctx.err(
                    g.span(),
                    "bank.reach_margin_m",
                    format!("must be >= 0 m, got {v}"),
                ));
            }
            v
        }
        None => 0.002,
    };
    Ok(BankOptions {
        couplings,
        truncation_radius_m: r,
        max_contact_nodes,
        grid_cell_m,
        reach_margin_m,
        precision,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn shipped() -> (PathBuf, String) {
        let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/liver.toml");
        let t = std::fs::read_to_string(&p).unwrap();
        (p, t)
    }

    #[test]
    fn shipped_scene_loads() {
        let (p, _) = shipped();
        let s = Scene::load(&p).unwrap();
        assert_eq!(s.mesh, MeshSource::BuiltinLiver);
        assert_eq!(s.material.young, 3000.0);
        assert_eq!(s.material.poisson, 0.45);
        assert!(!s.fix_boxes.is_empty());
        assert!(bank_format::validate_device(&s.device).is_ok());
        let (mesh, _, _) = s.load_mesh().unwrap();
        assert!(s.fixed_set(&mesh).unwrap().count() > 0);
    }

    /// `[viscoelastic]`: parsed into the bank's record; absent, none; each rule refused with
    /// its reason, at the file's line of the offending key.
    #[test]
    fn viscoelastic_terms_are_validated_with_their_reasons() {
        let (_, t) = shipped();
        let s = Scene::parse(Path::new("scene.toml"), &t).unwrap();
        assert_eq!(s.viscoelastic, None);
        let with = |g: &str, tau: &str| format!("{t}\n[viscoelastic]\ng = {g}\ntau_s = {tau}\n");
        let line_g = t.lines().count() + 3;
        let s = Scene::parse(Path::new("scene.toml"), &with("[0.5, 0.2]", "[0.05, 5.0]")).unwrap();
        let v = s.viscoelastic.unwrap();
        assert!((v.g_inf() - 0.3).abs() < 1e-12);
        let r = v.record().unwrap();
        assert_eq!((r.count, r.g[1], r.tau_s[1], r.g[2]), (2, 0.2, 5.0, 0.0));
        for (g, tau, key, line, words) in [
            (
                "[0.5, 0.5]",
                "[0.05, 5.0]",
                "viscoelastic.g",
                line_g,
                "g_inf",
            ),
            ("[-0.1]", "[1.0]", "viscoelastic.g", line_g, "< 0"),
            (
                "[0.1, 0.1]",
                "[1.0]",
                "viscoelastic.g",
                line_g,
                "one time constant",
            ),
            ("[]", "[]", "viscoelastic.g", line_g, "0 terms"),
            (
                "[0.1, 0.1, 0.1, 0.1, 0.1]",
                "[1, 2, 3, 4, 5]",
                "viscoelastic.g",
                line_g,
                "1 to 4",
            ),
            (
                "[0.1]",
                "[0.001]",
                "viscoelastic.tau_s",
                line_g + 1,
                "two ticks",
            ),
            (
                "[0.1]",
                "[7200.0]",
                "viscoelastic.tau_s",
                line_g + 1,
                "an hour",
            ),
            ("[0.1]", "[nan]", "viscoelastic.g", line_g, "finite"),
        ] {
            let e = err_of(&with(g, tau));
            assert_eq!(
                (e.key.as_str(), e.line),
                (key, Some(line)),
                "{g} {tau}: {e}"
            );
            assert!(e.message.contains(words), "{g} {tau}: {e}");
        }
    }

    /// Replaces the first line starting with `key =` and returns the text and its line number.
    fn with_line(text: &str, key: &str, new: &str) -> (String, usize) {
        let mut line = 0;
        let out: Vec<String> = text
            .lines()
            .enumerate()
            .map(|(i, l)| {
                if line == 0 && l.trim_start().starts_with(&format!("{key} =")) {
                    line = i + 1;
                    new.to_string()
                } else {
                    l.to_string()
                }
            })
            .collect();
        assert!(line > 0, "{key} not in the shipped scene");
        (out.join("\n"), line)
    }

    fn err_of(text: &str) -> SceneError {
        Scene::parse(Path::new("scene.toml"), text).unwrap_err()
    }

    #[test]
    fn mesh_units_are_checked() {
        let (_, t) = shipped();
        // The shipped scene: the embedded liver (metres) and a sampled [contact].
        let (ok, _) = with_line(
            &t,
            "mesh",
            "mesh = \"builtin:liver-1k4\"\nmesh_units = \"m\"",
        );
        let s = Scene::parse(Path::new("scene.toml"), &ok).unwrap();
        assert_eq!(s.mesh_units, Some(Units::M));
        for (mesh, units, why) in [
            ("builtin:liver-1k4", "mm", "the embedded liver is in metres"),
            (
                "organ.msh",
                "inch",
                "must be \"m\", \"cm\" or \"mm\", got \"inch\"",
            ),
        ] {
            let (bad, line) = with_line(
                &t,
                "mesh",
                &format!("mesh = \"{mesh}\"\nmesh_units = \"{units}\""),
            );
            let e = err_of(&bad);
            assert_eq!(
                (e.key.as_str(), e.line),
                ("mesh_units", Some(line + 1)),
                "{e}"
            );
            assert!(e.to_string().contains(why), "{e}");
        }
    }

    #[test]
    fn unknown_key_names_key_and_line() {
        let (_, t) = shipped();
        let (t, line) = with_line(&t, "poisson", "poisson = 0.45\nstiffness = 2");
        let e = err_of(&t);
        assert_eq!(e.line, Some(line + 1), "{e}");
        assert_eq!(e.key, "stiffness", "{e}");
        assert!(
            e.to_string().contains(&format!("scene.toml:{}:", line + 1)),
            "{e}"
        );
    }

    #[test]
    fn out_of_range_values_name_key_and_line() {
        let (_, t) = shipped();
        for (key, bad, name) in [
            ("young_pa", "young_pa = -3000.0", "material.young_pa"),
            ("poisson", "poisson = 0.5", "material.poisson"),
            (
                "insertion_range_m",
                "insertion_range_m = [0.1, 0.1]",
                "device.insertion_range_m",
            ),
            (
                "pitch_range_rad",
                "pitch_range_rad = [0.3, -0.3]",
                "device.pitch_range_rad",
            ),
            ("precision", "precision = \"f16\"", "bank.precision"),
            (
                "max_tip_speed_m_s",
                "max_tip_speed_m_s = 0.0",
                "device.max_tip_speed_m_s",
            ),
            (
                "max_tip_speed_m_s",
                "max_tip_speed_m_s = -1.0",
                "device.max_tip_speed_m_s",
            ),
            (
                "max_tip_speed_m_s",
                "max_tip_speed_m_s = nan",
                "device.max_tip_speed_m_s",
            ),
            (
                "max_joint_speed",
                "max_joint_speed = [10.0, 0.0, 1.0]",
                "device.max_joint_speed",
            ),
            (
                "max_joint_speed",
                "max_joint_speed = [inf, 10.0, 1.0]",
                "device.max_joint_speed",
            ),
            (
                "max_joint_speed",
                "max_joint_speed = [10.0, 10.0, 2.5]",
                "device.max_joint_speed",
            ),
            (
                "truncation_radius_m",
                "truncation_radius_m = -1.0",
                "bank.truncation_radius_m",
            ),
            ("couplings", "couplings = \"knn\"", "bank.couplings"),
            (
                "link_timeout_ms",
                "link_timeout_ms = 4",
                "device.link_timeout_ms",
            ),
            (
                "link_timeout_ms",
                "link_timeout_ms = 101",
                "device.link_timeout_ms",
            ),
            (
                "link_timeout_ms",
                "link_timeout_ms = -20",
                "device.link_timeout_ms",
            ),
        ] {
            let (text, line) = with_line(&t, key, bad);
            let e = err_of(&text);
            assert_eq!(e.line, Some(line), "{bad}: {e}");
            assert_eq!(e.key, name, "{bad}: {e}");
            assert!(
                e.to_string()
                    .starts_with(&format!("scene.toml:{line}: {name}:")),
                "{e}"
            );
        }
    }

    /// The overspeed thresholds: the shipped scene's, the defaults when the keys are absent
    /// (the joints' derived from the tip's), and a derived default the encoder-jump check would
    /// shadow refused with the tip key's line.
    #[test]
    fn speed_thresholds_have_defaults_and_reach_the_calibration() {
        let (_, t) = shipped();
        let parse = |text: &str| Scene::parse(Path::new("scene.toml"), text).unwrap().device;
        let d = parse(&t);
        assert_eq!(
            (d.max_tip_speed_m_s, d.max_joint_speed),
            (1.0, [10.0, 10.0, 1.0])
        );
        let (no_tip, _) = with_line(&t, "max_tip_speed_m_s", "");
        let (neither, _) = with_line(&no_tip, "max_joint_speed", "");
        let d = parse(&neither);
        assert_eq!(f64::from(d.max_tip_speed_m_s), DEFAULT_MAX_TIP_SPEED_M_S);
        assert_eq!(d.max_joint_speed, [10.0, 10.0, 1.0]);
        let (slow, _) = with_line(
            &neither,
            "max_force_n",
            "max_force_n = 5.0\nmax_tip_speed_m_s = 0.5",
        );
        let d = parse(&slow);
        assert_eq!(
            (d.max_tip_speed_m_s, d.max_joint_speed),
            (0.5, [5.0, 5.0, 0.5])
        );
        let (given, _) = with_line(&t, "max_joint_speed", "max_joint_speed = [4.0, 5.0, 0.6]");
        assert_eq!(parse(&given).max_joint_speed, [4.0, 5.0, 0.6]);
        // 3 m/s at the tip would derive 30 rad/s and 3 m/s: beyond the encoder-jump check.
        let (fast, line) = with_line(
            &neither,
            "max_force_n",
            "max_force_n = 5.0\nmax_tip_speed_m_s = 3.0",
        );
        let e = err_of(&fast);
        assert_eq!(
            (e.line, e.key.as_str()),
            (Some(line + 1), "device.max_tip_speed_m_s"),
            "{e}"
        );
        assert!(e.message.contains("device.max_joint_speed"), "{e}");
        // Given explicitly below the jump speeds, a fast tip threshold is fine.
        let (fast, _) = with_line(&t, "max_tip_speed_m_s", "max_tip_speed_m_s = 3.0");
        assert_eq!(parse(&fast).max_tip_speed_m_s, 3.0);
    }

    /// The link timeout: the shipped scene's, the default when the key is absent, both ends of
    /// the range accepted and carried into the calibration; a fraction is refused naming the
    /// key and line.
    #[test]
    fn link_timeout_has_a_default_and_reaches_the_calibration() {
        let (_, t) = shipped();
        let parse = |text: &str| Scene::parse(Path::new("scene.toml"), text).unwrap().device;
        assert_eq!(parse(&t).link_timeout_ms, 50);
        let (absent, _) = with_line(&t, "link_timeout_ms", "");
        assert_eq!(
            parse(&absent).link_timeout_ms,
            bank_format::DEFAULT_LINK_TIMEOUT_MS
        );
        for ms in [5, 100] {
            let (given, _) = with_line(&t, "link_timeout_ms", &format!("link_timeout_ms = {ms}"));
            assert_eq!(parse(&given).link_timeout_ms, ms);
        }
        let (fraction, line) = with_line(&t, "link_timeout_ms", "link_timeout_ms = 50.5");
        let e = err_of(&fraction);
        assert_eq!(
            (e.line, e.key.as_str()),
            (Some(line), "device.link_timeout_ms"),
            "{e}"
        );
        assert!(e.message.contains("whole number of ms in [5, 100]"), "{e}");
    }

    #[test]
    fn display_law_is_optional_and_validated() {
        let (_, t) = shipped();
        let s = Scene::parse(Path::new("scene.toml"), &t).unwrap();
        assert!(s.display_law.is_none());
        assert_eq!(s.friction_offset, [0.0; 3]);
        let ok = format!(
            "{t}\n[display_law]\nkind = \"chebyshev\"\ncoeffs = [1e-3, 1e-3]\ndomain_m = [0.0, 0.002]\n"
        );
        let p = Scene::parse(Path::new("scene.toml"), &ok)
            .unwrap()
            .display_law
            .unwrap();
        assert!((p.eval(0.002) - 2e-3).abs() < 1e-9);
        let lines = t.lines().count();
        for (table, line, key) in [
            (
                "kind = \"linear\"\ncoeffs = [0.0, 1.0]\ndomain_m = [0.0, 1.0]",
                lines + 3,
                "display_law.kind",
            ),
            (
                "kind = \"chebyshev\"\ncoeffs = [0.0, -1.0]\ndomain_m = [0.0, 1.0]",
                lines + 4,
                "display_law.coeffs",
            ),
            (
                "kind = \"chebyshev\"\ncoeffs = [0.0, 1.0]\ndomain_m = [1.0, 0.0]",
                lines + 5,
                "display_law.domain_m",
            ),
        ] {
            let e = err_of(&format!("{t}\n[display_law]\n{table}\n"));
            assert_eq!((e.line, e.key.as_str()), (Some(line), key), "{e}");
        }
    }

    #[test]
    fn syntax_errors_and_missing_keys_have_lines() {
        let e = err_of("mesh = \"x.msh\"\n[material\n");
        assert_eq!(e.line, Some(2), "{e}");
        let e = err_of("mesh = \"x.msh\"\n");
        assert!(e.message.contains("missing field"), "{e}");
    }

    /// One scene reached by two spellings of its path has one key (the caches share its bank);
    /// a different FEM mesh file gives another.
    #[test]
    fn inputs_hash_ignores_the_path_spelling_not_the_files() {
        let dir = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/.."));
        let a = Scene::load(&dir.join("scenes/liver.toml")).unwrap();
        let b = Scene::load(&dir.join("../tests/../host/scenes/liver.toml")).unwrap();
        assert_ne!(a.input_files(), b.input_files());
        assert_eq!(a.inputs_hash().unwrap(), b.inputs_hash().unwrap());
        let mut c = a.clone();
        let ContactModel::Sampled(spec) = &mut c.contact else {
            panic!("the shipped scene is sampled")
        };
        spec.fem_mesh = dir.join("meshes/liver-1k4.msh");
        assert_ne!(a.inputs_hash().unwrap(), c.inputs_hash().unwrap());
    }
}
