//! Large presses and pulls of the scene's tool on the organ: the large-deformation reference
//! ([`fem::hyperelastic`], compressible neo-Hookean on 10-node tetrahedra) against the linear
//! model on the same mesh, for a study site ([`crate::study::Site`]).
//!
//! **The operation** ([`LargeFem::press`]): the scene's FEM mesh with its material and its
//! supports (`[fixed]`: every node of the 10-node body in a fixed box is held); at the site,
//! the point of the FEM mesh's surface closest to the site's contact point (as the study and
//! the sampled bank place the tool); the tool is the rigid disc of the scene's tip radius
//! bonded to the surface there ([`fem::hyperelastic::indent`]: every surface node within the
//! radius moves by the same vector); it moves by `d` along the site's inward normal (a press)
//! or its outward normal (a pull), and the force on it is the sum of the reactions at those
//! nodes, neo-Hookean and linear (same mesh, same supports, same disc), so their ratio is the
//! nonlinearity alone. Several depths are stops of one load path.
//!
//! **Against the bank's tool**: a sampled bank loads the surface with the tip's parabolic
//! pressure and renders `W^-1 d` with `d` the pressure-weighted displacement of a patch that
//! deforms; the bonded disc is rigid and holds the tissue sideways too. Their linear forces
//! differ (the disc is the stiffer), which is why the reference is used through the ratio
//! `|F_large| / |F_linear|` of the same tool, not by its absolute force.

use crate::scene::Scene;
use crate::study::Site;
use anyhow::{Context, Result, bail};
use fem::hyperelastic::indent::{IndentForce, Indenter, indent};
use fem::hyperelastic::{HyperelasticBody, NewtonOptions, Prescribed};
use fem::mesh::{Surface, TetMesh};
use fem::tool::ToolSurface;
use std::path::Path;

/// The solver's options: the defaults, with tolerances for forces good to about 1e-6
/// (the defaults' 1e-10 residual costs a Newton iteration or two more per load step, on a
/// solve of dozens of iterations).
pub const OPTIONS: NewtonOptions = NewtonOptions {
    initial_steps: 4,
    min_step: 1e-4,
    max_iterations: 25,
    residual_tolerance: 1e-7,
    increment_tolerance: 1e-6,
    line_search_halvings: 10,
};

/// The scene's organ on one FEM mesh as a neo-Hookean body with its supports.
pub struct LargeFem {
    /// The mesh file's name for messages.
    pub mesh_name: String,
    /// Vertices of the mesh.
    pub vertices: usize,
    body: HyperelasticBody,
    supports: Prescribed,
    boundary: Surface,
    surface: ToolSurface,
    radius: f64,
}

/// A press (`depth_m > 0`, into the organ along `-n`) or a pull (`depth_m < 0`, along `+n`).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Press {
    /// Tool displacement along the inward normal, m (negative: a pull).
    pub depth_m: f64,
    /// Force of the tool on the organ, neo-Hookean, N.
    pub large: [f64; 3],
    /// The same in the linear model, N.
    pub linear: [f64; 3],
    /// Newton iterations of the path up to this depth.
    pub iterations: usize,
}

fn norm(v: [f64; 3]) -> f64 {
    v.iter().map(|x| x * x).sum::<f64>().sqrt()
}

impl Press {
    /// `|F_large| / |F_linear|`: the nonlinearity on the same mesh and tool.
    pub fn ratio(&self) -> f64 {
        norm(self.large) / norm(self.linear)
    }

    /// The linear model's error `|F_linear - F_large| / |F_large|`.
    pub fn linear_error(&self) -> f64 {
        norm(std::array::from_fn(|a| self.linear[a] - self.large[a])) / norm(self.large)
    }
}

impl LargeFem {
    /// Reads `mesh` (a mesh of the scene's organ, the scene's mesh units) and builds the body
    /// with the scene's material and supports; the tool is the scene's tip radius.
    pub fn load(scene: &Scene, mesh: &Path) -> Result<Self> {
        let (m, _) = scene.read_organ_mesh(mesh, "large-deformation mesh")?;
        Self::new(scene, &m, &mesh.display().to_string())
    }

    /// [`LargeFem::load`] on a mesh already read, named `name` in messages.
    pub fn new(scene: &Scene, mesh: &TetMesh, name: &str) -> Result<Self> {
        let body = HyperelasticBody::new(mesh, scene.material)?;
        let all = TetMesh {
            nodes: body.positions().to_vec(),
            tets: Vec::new(),
        };
        let fixed = scene.fixed_set(&all)?;
        let mut supports = Prescribed::none(body.nodes());
        for n in 0..body.nodes() {
            for a in 0..3 {
                if fixed.is_fixed(n, a) {
                    supports.set(n, a, 0.0)?;
                }
            }
        }
        let boundary = fem::mesh::boundary(mesh)?;
        let surface = ToolSurface::linear(mesh, &boundary)?;
        Ok(Self {
            mesh_name: name.to_string(),
            vertices: mesh.nodes.len(),
            body,
            supports,
            boundary,
            surface,
            radius: scene.tip_radius_m,
        })
    }

    /// Nodes of the 10-node body.
    pub fn nodes(&self) -> usize {
        self.body.nodes()
    }

    /// Presses the bonded tool at `site` to each of `depths_m` (m along the inward normal, all
    /// of one sign: presses, or pulls when negative; increasing in size) on one load path.
    /// Errors say the site and what failed (an inverted element, Newton without convergence
    /// and the depth it reached, too few surface nodes under the tool).
    pub fn press(&self, site: &Site, depths_m: &[f64]) -> Result<Vec<Press>> {
        let Some(&deepest) = depths_m.last() else {
            bail!("site {:?}: no depth asked", site.name);
        };
        if !(deepest != 0.0 && deepest.is_finite())
            || depths_m
                .iter()
                .any(|&d| !(d / deepest > 0.0 && d.is_finite()))
        {
            bail!(
                "site {:?}: depths {depths_m:?} m must be finite, non-zero and of one sign",
                site.name
            );
        }
        let stops: Vec<f64> = depths_m.iter().map(|d| d / deepest).collect();
        let at = self.surface.closest_point(site.point);
        let tool = Indenter::disc(&self.body, &self.boundary, at.point, self.radius)
            .with_context(|| format!("site {:?} on {}", site.name, self.mesh_name))?;
        let n = site.normal;
        let displacement = n.map(|x| -deepest * x);
        let forces = indent(
            &self.body,
            &self.supports,
            &tool,
            displacement,
            &stops,
            &OPTIONS,
        )
        .with_context(|| {
            format!(
                "site {:?} on {}: {} of {:.1} mm",
                site.name,
                self.mesh_name,
                if deepest > 0.0 { "press" } else { "pull" },
                1e3 * deepest.abs()
            )
        })?;
        Ok(forces
            .iter()
            .map(|f: &IndentForce| Press {
                depth_m: f.load * deepest,
                large: f.large,
                linear: f.linear,
                iterations: f.iterations,
            })
            .collect())
    }
}
