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
//!
//! This module holds the model ([`Scene`] and its parts) and its loading; `schema` is the file
//! as serde reads it, `checks` the checks of its values, one module per table.

mod checks;
mod schema;

pub use checks::bank::GRID_CELL_RANGE_M;
pub use checks::law::{PULL_TOLERANCE, pull_at_first_contact};
pub use checks::material::{
    Locking, P1_LOCKING_REFUSE, P1_LOCKING_WARN, YOUNG_RANGE_PA, p1_locking,
};

use crate::cache::{FNV_OFFSET, fnv1a};
use crate::units::{Units, guess_units, largest_side, scale_mesh};
use bank_format::{DeviceCalibration, TissueLaw};
use fem::elasticity::{Element, FixedSet, Material};
use fem::mesh::TetMesh;
use std::path::{Path, PathBuf};

/// The embedded 1.4k-node liver (`mesh = "builtin:liver-1k4"`).
pub const BUILTIN_LIVER: &[u8] = include_bytes!("../../../meshes/liver-1k4.msh");
/// The default scene (`host/scenes/liver.toml`, embedded): what `demo` and `report` use
/// without `--scene`.
pub const DEFAULT_SCENE: &str = include_str!("../../../scenes/liver.toml");
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
    /// organ-sized in cm or mm ([`crate::units::guess_units`]), which [`Scene::load_mesh`]
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
        checks::scene(path, text)
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
        let side = largest_side(mesh.bounding_box());
        let units = match self.mesh_units {
            Some(u) => u,
            None => match guess_units(side) {
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
        scale_mesh(&mut mesh, units);
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
    pub(crate) fn input_files_mut(&mut self) -> Vec<&mut PathBuf> {
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

    /// The bank's scene id: FNV-1a 64 over the scene file's bytes, then the mesh bytes' hash.
    pub fn scene_id(&self, mesh_hash: u64) -> u64 {
        fnv1a(self.text_hash, &mesh_hash.to_le_bytes())
    }
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
}
