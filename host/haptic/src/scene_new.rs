//! `host scene new`: a complete, commented scene for a tetrahedral organ mesh, the device's
//! joint ranges aimed from a trocar at the organ, a tissue preset; the text is validated by
//! loading it as any scene ([`Scene::parse`]) before it is written.

use crate::kinematics::Workspace;
use crate::organ::Organ;
use crate::reach::Region;
use crate::scene::Scene;
use crate::units::Units;
use anyhow::{Result, bail};
use fem::mesh::TetMesh;
use fem::vec3::{cross, dot, norm, scale, sub};
use std::path::{Component, Path, PathBuf};

/// A tissue's linear-elastic preset, with where each figure comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Tissue {
    /// Liver parenchyma.
    Liver,
    /// Kidney.
    Kidney,
    /// Brain.
    Brain,
}

impl Tissue {
    /// Young's modulus (Pa), Poisson's ratio, and the comment giving their sources.
    fn preset(self) -> (f64, f64, String) {
        let (young, source) = match self {
            Tissue::Liver => (
                3000.0,
                "# Liver preset. young_pa = 3000: the project's default scene's figure\n\
# (host/scenes/liver.toml), within what two readable sources give. Compression-relaxation of\n\
# 19 fresh human liver samples: \"Young's modulus values at the order of several hundreds to\n\
# thousands Pascals\", rising with fibrosis (Yeh et al., \"Young's modulus measurements of\n\
# human liver and correlation with pathological findings\", IEEE Ultrasonics Symposium 2001,\n\
# abstract). Shear modulus 1.8 +- 0.4 kPa, i.e. E = 2 (1 + nu) mu = 5.2 kPa at nu = 0.45, in\n\
# the literature table of Phys. Med. Biol. 64(22):225001, 2019 (Table 1, citing Bamber and\n\
# Hill 1981, Palmeri et al. 2008 and others). Fit the law on bench data with\n\
# `host calibrate tissue`.",
            ),
            Tissue::Kidney => (
                5250.0,
                "# Kidney preset. young_pa = 5250 = 2 (1 + nu) mu with nu = 0.45 and mu = 1.81 kPa, the\n\
# shear elasticity of the renal cortex of 8 excised swine kidneys (1.81 +- 0.17 kPa, viscosity\n\
# 1.48 +- 0.49 Pa s; shear waves of 50 to 500 Hz, small strain) in \"Shearwave dispersion\n\
# ultrasound vibrometry (SDUV) on swine kidney\", as its abstract gives it\n\
# (mayoclinic.pure.elsevier.com; the authors and journal, C. Amador et al., IEEE Trans.\n\
# Ultrason. Ferroelectr. Freq. Control 58(12), 2011, are as remembered, not checked). Perfused\n\
# kidneys are stiffer: J.-L. Gennisson, N. Grenier, C. Combe, M. Tanter, Ultrasound Med. Biol.\n\
# 38(9):1559-1567, 2012 (doi:10.1016/j.ultrasmedbio.2012.04.013), abstract: mu = 6.9 to\n\
# 7.7 kPa in the cortex of in vivo pig kidneys (E about 21 kPa), more with urinary pressure.\n\
# Fit the law on bench data with `host calibrate tissue`.",
            ),
            Tissue::Brain => (
                2526.0,
                "# Brain preset. young_pa = 2526 = 3 mu0 (incompressible small-strain limit) with\n\
# mu0 = 842 Pa, the Ogden shear parameter the project attributes to K. Miller and K. Chinzei,\n\
# \"Mechanical properties of brain tissue in tension\", J. Biomech. 35(4):483-490, 2002\n\
# (doi:10.1016/S0021-9290(01)00234-2: in vitro uniaxial tension of swine brain at strain rates\n\
# 0.64 and 0.0064 /s, an Ogden-based hyper-viscoelastic model). The paper's identity is\n\
# checked; the figure 842 Pa, which scripts/gen_brain_bench.py quotes, was not found in what\n\
# could be read of it: treat it as unverified.",
            ),
        };
        let poisson = "# poisson = 0.45: nearly incompressible soft tissue held at 0.45 because the P1\n\
# element locks above it (docs/scenes-and-banks.md, \"Nearly incompressible tissue\";\n\
# `element = \"anp\"` allows more).";
        (young, 0.45, format!("{source}\n{poisson}"))
    }

    /// What the preset's Young's modulus rests on, in one line for `host scene new` to print:
    /// none of the three is a measurement this project has checked.
    pub fn caveat(self) -> &'static str {
        match self {
            Tissue::Liver => {
                "young_pa = 3000 Pa is the default scene's figure: human liver measured hundreds \
                 to thousands of Pa ex vivo, and 5.2 kPa from a shear-wave mu = 1.8 kPa"
            }
            Tissue::Kidney => {
                "young_pa = 5250 Pa is ex vivo swine renal cortex by shear-wave elastography (an \
                 abstract's mu = 1.81 kPa); in vivo cortex measured about four times stiffer"
            }
            Tissue::Brain => {
                "young_pa = 2526 Pa = 3 x 842 Pa, a shear figure attributed to Miller and \
                 Chinzei (2002), not verified against the paper"
            }
        }
    }

    /// The preset's name.
    pub fn name(self) -> &'static str {
        match self {
            Tissue::Liver => "liver",
            Tissue::Kidney => "kidney",
            Tissue::Brain => "brain",
        }
    }
}

/// The supports of a new scene.
#[derive(Debug, Clone, Copy)]
pub enum Support {
    /// Every node at or below this height is held (m).
    Below(f64),
    /// The nodes in this box are held: min x, y, z, max x, y, z (m).
    Box([f64; 6]),
}

/// What `host scene new` needs.
#[derive(Debug, Clone)]
pub struct NewScene {
    /// The mesh file, as the scene should name it (made relative to the scene's folder).
    pub mesh_path: PathBuf,
    /// The mesh file's units (the scene's `mesh_units`; the mesh given to [`scene_text`] is
    /// already scaled to metres).
    pub mesh_units: Units,
    /// The trocar (fulcrum), m.
    pub trocar: [f64; 3],
    /// Supports.
    pub support: Support,
    /// Tissue preset.
    pub tissue: Tissue,
    /// A finer mesh of the same organ in the same units, as the scene should name it: the
    /// scene's `[contact]` then samples the tool's patch compliance on it (P2), the converged
    /// force; without it the scene uses the nodal model on `mesh_path`.
    pub fem_mesh: Option<PathBuf>,
}

/// `path` relative to `dir` (both made absolute against the current directory first).
pub fn relative_to(path: &Path, dir: &Path) -> PathBuf {
    let abs = |p: &Path| {
        let p = if p.is_absolute() {
            p.to_path_buf()
        } else {
            std::env::current_dir().unwrap_or_default().join(p)
        };
        // Lexical normalisation (no symlink resolution): drop `.`, fold `..`.
        let mut out = PathBuf::new();
        for c in p.components() {
            match c {
                Component::CurDir => {}
                Component::ParentDir => {
                    out.pop();
                }
                other => out.push(other),
            }
        }
        out
    };
    let (p, d) = (abs(path), abs(dir));
    let pc: Vec<_> = p.components().collect();
    let dc: Vec<_> = d.components().collect();
    let common = pc.iter().zip(&dc).take_while(|(a, b)| a == b).count();
    let mut out = PathBuf::new();
    for _ in common..dc.len() {
        out.push("..");
    }
    for c in &pc[common..] {
        out.push(c);
    }
    out
}

/// The device's orientation and ranges aimed from `trocar` at `organ`'s boundary nodes: the
/// shaft at rest points at the centroid of the boundary nodes; pitch and yaw cover every
/// boundary node's direction (5% more, within +-1.2 rad); the insertion starts 6 cm short of
/// the nearest boundary node and goes 5 cm past it (at most half the organ's depth along the
/// line of sight), like the default scene (0.03 to 0.14 m, the liver 0.09 m away).
pub fn aim(mesh: &TetMesh, trocar: [f64; 3]) -> Result<Workspace> {
    let surface = fem::mesh::boundary(mesh)?;
    let pts: Vec<[f64; 3]> = surface.nodes.iter().map(|&n| mesh.nodes[n]).collect();
    let c = scale(
        pts.iter()
            .fold([0.0; 3], |a, p| [a[0] + p[0], a[1] + p[1], a[2] + p[2]]),
        1.0 / pts.len() as f64,
    );
    let to_c = sub(c, trocar);
    if norm(to_c) < 1e-6 {
        bail!("the trocar is at the organ's centre");
    }
    let shaft = scale(to_c, 1.0 / norm(to_c));
    let reference = if dot(shaft, [0.0, 1.0, 0.0]).abs() < 0.9 {
        [0.0, 1.0, 0.0]
    } else {
        [1.0, 0.0, 0.0]
    };
    let p = cross(shaft, reference);
    let pitch_axis = scale(p, 1.0 / norm(p));
    let yaw_axis = cross(pitch_axis, shaft);
    let mut w = Workspace {
        fulcrum: trocar,
        shaft,
        pitch_axis,
        yaw_axis,
        pitch: [0.0; 2],
        yaw: [0.0; 2],
        insertion: [0.0; 2],
    };
    let (mut pmin, mut pmax, mut ymin, mut ymax) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
    let (mut dmin, mut dmax) = (f64::INFINITY, 0.0f64);
    for &q in &pts {
        let v = sub(q, trocar);
        let (pi, yi) = w.angles(v);
        pmin = pmin.min(pi);
        pmax = pmax.max(pi);
        ymin = ymin.min(yi);
        ymax = ymax.max(yi);
        dmin = dmin.min(norm(v));
        dmax = dmax.max(norm(v));
    }
    let lim = |x: f64| (x * 1.05).clamp(-1.2, 1.2);
    w.pitch = [lim(pmin), lim(pmax)];
    w.yaw = [lim(ymin), lim(ymax)];
    w.insertion = [
        (dmin - 0.06).max(0.0),
        dmin + (0.5 * (dmax - dmin)).min(0.05),
    ];
    Ok(w)
}

fn v3(a: [f64; 3]) -> String {
    format!("[{}, {}, {}]", r(a[0]), r(a[1]), r(a[2]))
}

/// A number rounded to 6 decimals, written so that TOML reads it as a float.
fn r(x: f64) -> String {
    let s = format!("{:.6}", x);
    let s = s.trim_end_matches('0');
    let s = if s.ends_with('.') {
        format!("{s}0")
    } else {
        s.to_string()
    };
    if s == "-0.0" { "0.0".into() } else { s }
}

/// The scene's `[contact]` (with `fem_mesh`: the sampled patch compliance on it) and `[bank]`.
fn contact_text(fem_mesh: Option<&Path>) -> String {
    match fem_mesh {
        None => "[bank]
# The nodal contact model on the mesh's nodes (no [contact] table): pairs within 12 mm, 16-bit
# blocks (see host/scenes/liver-nodal.toml for the alternatives).
couplings = \"radius\"
truncation_radius_m = 0.012
precision = \"bfp16\"
reach_margin_m = 0.002
"
        .into(),
        Some(f) => format!(
            "[contact]
# The converged force: the tool's patch compliance W(p) computed on fem_mesh (a finer mesh of
# the same organ, in mesh_units) with 10-node tetrahedra at the lattice points of the collision
# triangles of `mesh` (sample_level steps per side), stored in the bank and interpolated in the
# tick (see host/scenes/liver.toml).
model = \"sampled\"
fem_mesh = \"{}\"
fem_element = \"p2\"
sample_level = 2

[bank]
# A sampled bank keeps only the collision triangles' edges as couplings.
couplings = \"radius\"
truncation_radius_m = 0.0
precision = \"bfp16\"
reach_margin_m = 0.002
",
            f.display().to_string().replace('\\', "/")
        ),
    }
}

/// The scene's text for `mesh` (already loaded, scaled to metres and validated) and `spec`, checked as any
/// scene is before a bank is built ([`Organ::from_scene`], [`Region::of`]: the trocar and the home tip
/// outside the organ, supports that hold something but not everything and leave no rigid
/// motion, a reachable region), as `out` would be read; also the reachable nodes' count and
/// the scene's warnings (a mesh implausibly sized in metres, a Poisson's ratio that locks).
pub fn scene_text(
    mesh: &TetMesh,
    spec: &NewScene,
    out: &Path,
) -> Result<(String, usize, Vec<String>)> {
    let w = aim(mesh, spec.trocar)?;
    // The axes with 9 decimals stay orthonormal well within the scene's check.
    let axis = |a: [f64; 3]| {
        let a = a.map(|x| x + 0.0); // no "-0.000000000"
        format!("[{:.9}, {:.9}, {:.9}]", a[0], a[1], a[2])
    };
    let (young, poisson, sources) = spec.tissue.preset();
    let (lo, hi) = mesh.bounding_box();
    let fixed = match spec.support {
        Support::Below(z) => format!(
            "# --fix-below {z}: every node at or below z = {z} m is held (the organ's lowest point\n\
             # is at z = {}).\nboxes = [\n    {{ min = [-1000.0, -1000.0, -1000.0], max = [1000.0, 1000.0, {}] }},\n]",
            r(lo[2]),
            r(z)
        ),
        Support::Box(b) => format!(
            "# --fix-box: the nodes in this box are held.\nboxes = [\n    {{ min = {}, max = {} }},\n]",
            v3([b[0], b[1], b[2]]),
            v3([b[3], b[4], b[5]])
        ),
    };
    let mesh_name = spec.mesh_path.display().to_string().replace('\\', "/");
    let text = format!(
        r#"# A scene made by `host scene new` for {mesh_name} (tissue preset: {tissue}).
# `host bank build <this file> -o organ.bank` turns it into a firmware bank; `host demo
# --scene <this file>` shows it. Every key is explained in host/scenes/liver.toml; units are SI
# (m, rad, Pa, N, A, N m/A). The organ's bounding box: {lo} to {hi} m.

# Organ mesh, relative to this file (.msh v1/v2/v4.1, .vtu, .vtk, .mesh), and the units of
# its coordinates (mesh_units: "m", "cm" or "mm"; scaled to metres on loading).
mesh = "{mesh_name}"
mesh_units = "{units}"

[material]
{sources}
young_pa = {young:.1}
poisson = {poisson}

[fixed]
{fixed}
nodes = []

[tool]
tip_radius_m = 0.003   # radius of the tool tip, in [0, 0.05]

[device]
# The default scene's gimbal, aimed from the trocar at the organ: the shaft at rest points at
# the centroid of the organ's boundary nodes, pitch and yaw cover every boundary node's
# direction, the insertion starts 6 cm short of the nearest boundary node and reaches 5 cm past
# it (at most half the organ's depth along the line of sight). The tool reaches what lies in
# that sector; the scene's check refuses a trocar inside the organ.
fulcrum_m = {fulcrum}
shaft_axis = {shaft}
pitch_axis = {pitch_axis}
yaw_axis = {yaw_axis}
pitch_range_rad = [{p0}, {p1}]
yaw_range_rad = [{y0}, {y1}]
insertion_range_m = [{i0}, {i1}]
counts_per_rev = [4096, 4096, 4096]
gear_ratio = [12.0, 12.0, 400.0]
torque_constant_nm_per_a = [0.025, 0.025, 0.025]
current_limit_a = [2.0, 2.0, 2.0]
max_force_n = 5.0
max_tip_speed_m_s = 1.0
link_timeout_ms = {link_timeout_ms}   # host silence before the armed device faults, in [5, 100]

[law]
kind = "linear"   # fit a Chebyshev Q on bench data with `host calibrate tissue`

{contact}"#,
        contact = contact_text(spec.fem_mesh.as_deref()),
        link_timeout_ms = bank_format::DEFAULT_LINK_TIMEOUT_MS,
        tissue = spec.tissue.name(),
        units = spec.mesh_units.name(),
        lo = v3(lo),
        hi = v3(hi),
        fulcrum = v3(w.fulcrum),
        shaft = axis(w.shaft),
        pitch_axis = axis(w.pitch_axis),
        yaw_axis = axis(w.yaw_axis),
        p0 = r(w.pitch[0]),
        p1 = r(w.pitch[1]),
        y0 = r(w.yaw[0]),
        y1 = r(w.yaw[1]),
        i0 = r(w.insertion[0]),
        i1 = r(w.insertion[1]),
    );
    let organ = Organ::from_scene(Scene::parse(out, &text)?)?;
    let region = Region::of(&organ)?;
    Ok((text, region.len(), organ.warnings))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn relative_paths() {
        assert_eq!(
            relative_to(Path::new("/a/b/m.msh"), Path::new("/a/c")),
            PathBuf::from("../b/m.msh")
        );
        assert_eq!(
            relative_to(Path::new("/a/b/m.msh"), Path::new("/a/b")),
            PathBuf::from("m.msh")
        );
    }

    #[test]
    fn aimed_like_the_default_scene() {
        // The default liver under its trocar at z = 0.16: the shaft points down at the organ;
        // the insertion starts where the default scene's does (0.03 m: the liver's top is
        // 0.091 m away) and ends 0.13 m (half the 0.077 m depth past the top; the default
        // scene's 0.14 reaches 0.05 m past it).
        let mesh = fem::mesh::parse_msh(include_bytes!("../../meshes/liver-1k4.msh")).unwrap();
        let w = aim(&mesh, [0.0, 0.0, 0.16]).unwrap();
        assert!(w.shaft[2] < -0.95, "{:?}", w.shaft);
        assert!((w.insertion[0] - 0.03).abs() < 0.005, "{:?}", w.insertion);
        assert!((w.insertion[1] - 0.13).abs() < 0.002, "{:?}", w.insertion);
        // Orthonormal, right-handed like the default (pitch x yaw = -shaft).
        let d = |a, b| dot(a, b);
        assert!(d(w.shaft, w.pitch_axis).abs() < 1e-12 && d(w.shaft, w.yaw_axis).abs() < 1e-12);
        let c = cross(w.pitch_axis, w.yaw_axis);
        assert!((d(c, w.shaft) + 1.0).abs() < 1e-12);
        // Every boundary node's direction is within the ranges.
        let s = fem::mesh::boundary(&mesh).unwrap();
        for &n in &s.nodes {
            let (p, y) = w.angles(sub(mesh.nodes[n], w.fulcrum));
            assert!(p >= w.pitch[0] && p <= w.pitch[1] && y >= w.yaw[0] && y <= w.yaw[1]);
        }
    }
}
