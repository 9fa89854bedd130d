//! The FEM engine of the haptic soft-tissue simulator (Cotin, Delingette & Ayache, *Real-time
//! elastic deformations of soft tissues for surgery simulation*, IEEE TVCG 1999): everything the
//! offline precompute needs, and nothing of the device, the display or the command line.
//!
//! The pipeline, in module order:
//!
//! 1. [`mesh`]: read a tetrahedral organ (Gmsh `.msh`, VTK `.vtu` / `.vtk`), validate it (every
//!    error names the file and the element or node id) and find its boundary surface;
//! 2. [`elasticity`]: linear elasticity, the paper's section 3 (eq. 1, `K u = f`), with fixed
//!    nodes or single fixed components, on the paper's P1 tetrahedron or the locking-free
//!    average nodal pressure tetrahedron ([`elasticity::Element`]);
//! 3. [`ordering`]: fill-reducing orderings of `K_ff` (METIS nested dissection, AMD);
//! 4. [`compliance`]: one sparse Cholesky factorisation of `K_ff`, then the compliance blocks
//!    `C_nk = (K_ff^-1)_nk` (the paper's "elementary deformations", section 4-1, in compliance
//!    form) for the nodes a scene needs, and the imposed-displacement solve of eq. 2 /
//!    appendix A (`f_S = C_SS^-1 u*_S`);
//! 5. [`tool`]: the load of a rigid tool tip on the surface (a parabolic pressure spread over the
//!    nodes by the surface shape functions, P1 or P2), the nodal weights of
//!    [`compliance::Compliance::patch_compliances`];
//! 6. [`reference`](mod@reference): the reference problems of the locking study (a flat punch
//!    on the liver, uniform refinement), solved with any element or the 10-node
//!    [`elasticity::quadratic::QuadraticBody`];
//! 7. [`hyperelastic`]: the large-deformation reference, a compressible neo-Hookean body on
//!    the same 10-node tetrahedra, loaded by prescribed displacements and solved by Newton's
//!    method with load stepping.
//!
//! ```
//! use fem::compliance::Compliance;
//! use fem::elasticity::{Elasticity, FixedSet, Material};
//! use fem::mesh::structured::box_mesh;
//!
//! // A 10 cm cube of soft tissue standing on its bottom face.
//! let mesh = box_mesh([0.1, 0.1, 0.1], [4, 4, 4]);
//! let body = Elasticity::new(&mesh, Material::new(3000.0, 0.45)?)?;
//! let mut fixed = FixedSet::none(mesh.nodes.len());
//! fixed.fix_box(&mesh, [-1.0, -1.0, -1.0, 1.0, 1.0, 1e-9], [true; 3])?;
//! let c = Compliance::factorize(&body, &fixed)?;
//! let top = mesh.nodes.iter().position(|p| p[2] >= 0.1 - 1e-9).unwrap();
//! let block = c.blocks(&[top], None)?[0][0];
//! assert!(block[2][2] > 0.0); // pushing a top node down moves it down
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! Units are SI throughout: metres, newtons, pascals; compliance blocks are in m/N.

pub mod compliance;
pub mod elasticity;
pub mod hyperelastic;
pub mod mesh;
pub mod ordering;
pub mod progress;
pub mod reference;
pub mod surface;
pub mod tool;
pub mod vec3;
