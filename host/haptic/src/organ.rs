//! The mesh stage of the pipeline (the paper's sections 2 and 3): a scene's organ, its
//! tetrahedral mesh with its boundary and supports, checked against the device before anything
//! is computed from it.
//!
//! The stages after it: [`crate::reach::Region`] (what the tool can reach),
//! [`Organ::factorize`] (the compliance), [`crate::bank::Prepared`] (all three, and the bank).

use crate::kinematics::Workspace;
use crate::scene::Scene;
use anyhow::{Context, Result, bail};
use fem::compliance::Compliance;
use fem::elasticity::{Elasticity, FixedSet};
use fem::mesh::{Surface, TetMesh};
use std::path::Path;

/// A scene's organ: its mesh, validated, with its boundary and its supports.
pub struct Organ {
    /// The scene as read.
    pub scene: Scene,
    /// Its organ mesh, validated.
    pub mesh: TetMesh,
    /// The mesh's name for messages (file name, or the embedded mesh's name).
    pub mesh_name: String,
    /// The mesh's boundary.
    pub surface: Surface,
    /// The elastic body: the mesh with the scene's material and element (the paper's section
    /// 3, eq. 1, `K u = f`).
    pub body: Elasticity,
    /// The scene's supports on the mesh; they leave no rigid motion of `body` free.
    pub fixed: FixedSet,
    /// The scene's identity written into the bank (scene file and mesh contents).
    pub scene_id: u64,
    /// What is doubtful but not wrong (P1 locking, an implausible organ size), for the
    /// commands to print.
    pub warnings: Vec<String>,
}

/// Organ sizes (bounding-box diagonal, m) that are plausible in metres: a millimetre-sized
/// specimen up to a whole torso.
pub const ORGAN_SIZE_RANGE_M: (f64, f64) = (1e-3, 1.0);

/// A warning when `mesh`'s size is implausible in metres (a mesh in millimetres is 1000 times
/// too large, and silently 1000 times too soft per unit force).
pub fn mesh_size_warning(mesh: &TetMesh, name: &str) -> Option<String> {
    let (lo, hi) = mesh.bounding_box();
    let size = fem::vec3::norm(fem::vec3::sub(hi, lo));
    (!(ORGAN_SIZE_RANGE_M.0..=ORGAN_SIZE_RANGE_M.1).contains(&size)).then(|| {
        format!(
            "warning: {name} spans {size:.4} m, outside the [{}, {}] m an organ has: are its \
             coordinates in metres (a mesh in millimetres is 1000 times too large)?",
            ORGAN_SIZE_RANGE_M.0, ORGAN_SIZE_RANGE_M.1
        )
    })
}

impl Organ {
    /// [`Organ::from_scene`] on the scene file at `path`.
    pub fn load(path: &Path) -> Result<Organ> {
        Organ::from_scene(Scene::load(path)?)
    }

    /// Loads the scene's mesh, its boundary, elastic body and supports; refuses a trocar or a
    /// home tip inside the organ, and supports that hold every node or leave a rigid motion
    /// free.
    pub fn from_scene(scene: Scene) -> Result<Organ> {
        let path = scene.path.clone();
        let (mesh, mesh_name, mesh_hash) = scene.load_mesh()?;
        let surface = fem::mesh::boundary(&mesh)?;
        let fixed = scene.fixed_set(&mesh)?;
        let workspace = Workspace::from_device(&scene.device);
        if let Some(t) = mesh.tet_containing(workspace.fulcrum) {
            bail!(
                "{}: device.fulcrum_m lies inside the organ (tetrahedron {t}): the trocar must be \
                 outside the tissue it enters",
                path.display()
            );
        }
        let home = scene.device.home_joint.map(f64::from);
        let home_tip = workspace.tip(home[0], home[1], home[2]);
        if let Some(t) = mesh.tet_containing(home_tip) {
            bail!(
                "{}: device.home puts the tool tip inside the organ (tetrahedron {t}, tip at \
                 [{:.4}, {:.4}, {:.4}] m): the device starts with its tip outside the tissue",
                path.display(),
                home_tip[0],
                home_tip[1],
                home_tip[2]
            );
        }
        if fixed.count() == 3 * mesh.nodes.len() {
            bail!(
                "{}: [fixed] holds every node of the mesh: nothing can deform (every compliance \
                 would be zero); fix only the supports",
                path.display()
            );
        }
        let body = Elasticity::with_element(&mesh, scene.material, scene.element)?;
        body.check_rigid_motions(&fixed)
            .with_context(|| format!("{}: [fixed]", path.display()))?;
        let scene_id = scene.scene_id(mesh_hash);
        let mut warnings = scene.warnings();
        warnings.extend(mesh_size_warning(&mesh, &mesh_name));
        Ok(Organ {
            scene,
            mesh,
            mesh_name,
            surface,
            body,
            fixed,
            scene_id,
            warnings,
        })
    }

    /// The compliance stage: the body's `K_ff` factorised (eq. 1 in compliance form: the
    /// paper's elementary deformations are its columns, combined by superposition, eq. 9).
    pub fn factorize(&self) -> Result<Compliance> {
        Compliance::factorize(&self.body, &self.fixed)
            .with_context(|| format!("{}: [fixed]", self.scene.path.display()))
    }
}
