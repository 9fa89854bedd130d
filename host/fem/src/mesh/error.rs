//! The error type of mesh reading, validation and boundary extraction.

use std::fmt;
use std::path::{Path, PathBuf};

/// The file an error is about, if any; displays as `"path: "` or as nothing for in-memory meshes.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Origin(pub Option<PathBuf>);

impl fmt::Display for Origin {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match &self.0 {
            Some(p) => write!(f, "{}: ", p.display()),
            None => Ok(()),
        }
    }
}

/// Everything that can go wrong when reading, validating or taking the boundary of a mesh.
///
/// Node and tetrahedron ids are 0-based positions (see the [module docs](super)); Gmsh element
/// *tags* (as written in the file) are named "tag". The `file` field names the file when known;
/// [`MeshError::with_path`] fills it in.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum MeshError {
    /// The file could not be read from disk.
    #[error("{file}cannot read mesh file: {source}")]
    Io {
        /// The file.
        file: Origin,
        /// The operating system's error.
        source: std::io::Error,
    },
    /// The file name has no extension this module can read.
    #[error(
        "{file}unknown mesh file extension {extension:?} (expected .msh, .vtu, .vtk or .mesh){}",
        surface_hint(extension)
    )]
    UnknownExtension {
        /// The file.
        file: Origin,
        /// The extension found (empty when there is none).
        extension: String,
    },
    /// A Gmsh MSH file of a version (or encoding) that is not supported.
    #[error(
        "{file}unsupported Gmsh MSH format version {version} (supported: 2.x ASCII, 4.1 ASCII \
         and 4.1 binary; re-save the mesh with Gmsh as version 4.1 or 2.2 ASCII)"
    )]
    UnsupportedVersion {
        /// The file.
        file: Origin,
        /// The version (and encoding) found.
        version: String,
    },
    /// A syntax error in a text file, located by line.
    #[error("{file}line {line}: {message}")]
    Parse {
        /// The file.
        file: Origin,
        /// 1-based line number.
        line: usize,
        /// What is wrong.
        message: String,
    },
    /// A syntax error in a binary file, located by byte offset.
    #[error("{file}byte {offset}: {message}")]
    ParseBinary {
        /// The file.
        file: Origin,
        /// 0-based byte offset from the start of the file.
        offset: usize,
        /// What is wrong, including the section being read.
        message: String,
    },
    /// A structural problem in the file that cannot be tied to a line or byte.
    #[error("{file}{message}")]
    Format {
        /// The file.
        file: Origin,
        /// What is wrong.
        message: String,
    },
    /// A 3D element that is not a 4-node linear tetrahedron.
    #[error(
        "{file}element {element} is of unsupported type {kind}: only 4-node linear tetrahedra \
         are supported (re-mesh with first-order tetrahedra)"
    )]
    UnsupportedElement {
        /// The file.
        file: Origin,
        /// Gmsh element tag, or 0-based VTK cell index.
        element: u64,
        /// Human-readable element type.
        kind: String,
    },
    /// A Gmsh element refers to a node tag that the `$Nodes` section does not define.
    #[error(
        "{file}element {element} refers to node tag {node_tag}, which is not defined in $Nodes"
    )]
    UnknownNodeTag {
        /// The file.
        file: Origin,
        /// Gmsh element tag.
        element: u64,
        /// The undefined node tag.
        node_tag: u64,
    },
    /// The mesh has no tetrahedra at all.
    #[error("{file}the mesh has no tetrahedra ({nodes} nodes, no 3D elements)")]
    NoTetrahedra {
        /// The file.
        file: Origin,
        /// Number of nodes read.
        nodes: usize,
    },
    /// A tetrahedron refers to a node id that does not exist.
    #[error(
        "{file}tetrahedron {tet} refers to node {node}, but the mesh has only {num_nodes} nodes"
    )]
    NodeIndexOutOfRange {
        /// The file.
        file: Origin,
        /// Tetrahedron id.
        tet: usize,
        /// The out-of-range node id.
        node: usize,
        /// Number of nodes in the mesh.
        num_nodes: usize,
    },
    /// A tetrahedron uses the same node more than once.
    #[error("{file}tetrahedron {tet} uses node {node} more than once (nodes {nodes:?})")]
    RepeatedNode {
        /// The file.
        file: Origin,
        /// Tetrahedron id.
        tet: usize,
        /// The repeated node id.
        node: usize,
        /// The tetrahedron's four node ids.
        nodes: [usize; 4],
    },
    /// A node coordinate is NaN or infinite.
    #[error("{file}node {node} has a non-finite coordinate {coords:?}")]
    NonFiniteCoordinate {
        /// The file.
        file: Origin,
        /// Node id.
        node: usize,
        /// Its coordinates.
        coords: [f64; 3],
    },
    /// A tetrahedron has negative signed volume (wrong node order, or a folded mesh).
    #[error("{file}tetrahedron {tet} is inverted (signed volume {volume:.2e} m^3)")]
    InvertedTet {
        /// The file.
        file: Origin,
        /// Tetrahedron id.
        tet: usize,
        /// Its signed volume.
        volume: f64,
    },
    /// A tetrahedron is (nearly) flat: `6*sqrt(2)*|V| / l_rms^3` below [`super::DEGENERATE_QUALITY`].
    #[error(
        "{file}tetrahedron {tet} is degenerate (quality {quality:.2e}, signed volume {volume:.2e} \
         m^3; quality = 6*sqrt(2)*|V|/l_rms^3 is 1 for a regular tetrahedron)"
    )]
    DegenerateTet {
        /// The file.
        file: Origin,
        /// Tetrahedron id.
        tet: usize,
        /// Its shape quality.
        quality: f64,
        /// Its signed volume.
        volume: f64,
    },
    /// A node that no tetrahedron uses.
    #[error("{file}node {node} is not used by any tetrahedron")]
    UnreferencedNode {
        /// The file.
        file: Origin,
        /// Node id.
        node: usize,
    },
    /// Two nodes at the same position (within `1e-12` of the bounding-box diagonal).
    #[error(
        "{file}nodes {first} and {second} coincide (both at {coords:?}, distance {distance:.2e} m)"
    )]
    DuplicateNodes {
        /// The file.
        file: Origin,
        /// The lower node id.
        first: usize,
        /// The higher node id.
        second: usize,
        /// Coordinates of `first`.
        coords: [f64; 3],
        /// Distance between the two.
        distance: f64,
    },
    /// Two tetrahedra with the same four nodes.
    #[error("{file}tetrahedra {first} and {second} have the same nodes {nodes:?}")]
    DuplicateTet {
        /// The file.
        file: Origin,
        /// The lower tetrahedron id.
        first: usize,
        /// The higher tetrahedron id.
        second: usize,
        /// The common nodes (sorted).
        nodes: [usize; 4],
    },
    /// A triangular face shared by more than two tetrahedra.
    #[error(
        "{file}non-manifold mesh: the face with nodes {face:?} is shared by {} tetrahedra {tets:?} \
         (at most 2 allowed)",
        tets.len()
    )]
    NonManifoldFace {
        /// The file.
        file: Origin,
        /// The face's nodes (sorted).
        face: [usize; 3],
        /// All tetrahedra that have this face.
        tets: Vec<usize>,
    },
    /// Two tetrahedra that share a face lie on the same side of it, so they overlap.
    #[error(
        "{file}tetrahedra {} and {} overlap: both lie on the same side of their common face {face:?}",
        tets[0], tets[1]
    )]
    OverlappingTets {
        /// The file.
        file: Origin,
        /// The common face's nodes (sorted).
        face: [usize; 3],
        /// The two tetrahedra.
        tets: [usize; 2],
    },
    /// A boundary edge that does not have exactly two boundary triangles.
    #[error(
        "{file}non-manifold boundary: the edge between nodes {} and {} is shared by {triangles} \
         boundary triangles (expected 2)",
        edge[0], edge[1]
    )]
    NonManifoldEdge {
        /// The file.
        file: Origin,
        /// The edge's nodes (sorted).
        edge: [usize; 2],
        /// Number of boundary triangles using it.
        triangles: usize,
    },
    /// A boundary vertex whose boundary triangles do not form a single disc.
    #[error(
        "{file}non-manifold boundary: at node {node} the boundary triangles form {fans} separate \
         fans (the body touches itself at this point)"
    )]
    NonManifoldVertex {
        /// The file.
        file: Origin,
        /// Node id.
        node: usize,
        /// Number of separate fans of boundary triangles around it.
        fans: usize,
    },
    /// The mesh is too large for the 32-bit ids used internally.
    #[error(
        "{file}mesh too large ({nodes} nodes, {tets} tetrahedra; at most 2^32 - 1 and 2^30 - 1)"
    )]
    TooLarge {
        /// The file.
        file: Origin,
        /// Number of nodes.
        nodes: usize,
        /// Number of tetrahedra.
        tets: usize,
    },
}

/// Expands to a match on every variant, binding its `file` field.
macro_rules! with_origin {
    ($e:expr, $file:ident => $body:expr) => {{
        use MeshError::*;
        match $e {
            Io { $file, .. }
            | UnknownExtension { $file, .. }
            | UnsupportedVersion { $file, .. }
            | Parse { $file, .. }
            | ParseBinary { $file, .. }
            | Format { $file, .. }
            | UnsupportedElement { $file, .. }
            | UnknownNodeTag { $file, .. }
            | NoTetrahedra { $file, .. }
            | NodeIndexOutOfRange { $file, .. }
            | RepeatedNode { $file, .. }
            | NonFiniteCoordinate { $file, .. }
            | InvertedTet { $file, .. }
            | DegenerateTet { $file, .. }
            | UnreferencedNode { $file, .. }
            | DuplicateNodes { $file, .. }
            | DuplicateTet { $file, .. }
            | NonManifoldFace { $file, .. }
            | OverlappingTets { $file, .. }
            | NonManifoldEdge { $file, .. }
            | NonManifoldVertex { $file, .. }
            | TooLarge { $file, .. } => $body,
        }
    }};
}

impl MeshError {
    /// The file this error is about, if known.
    pub fn path(&self) -> Option<&Path> {
        with_origin!(self, file => file.0.as_deref())
    }

    /// Attach `path` as the file this error is about, unless one is already set.
    pub fn with_path(mut self, path: &Path) -> Self {
        with_origin!(&mut self, file => {
            if file.0.is_none() {
                file.0 = Some(path.to_path_buf());
            }
        });
        self
    }
}

/// For a surface file given where a tetrahedral mesh is wanted: how to get one.
fn surface_hint(extension: &str) -> &'static str {
    match extension {
        "stl" | "obj" | "ply" | "vtp" => {
            "; that is a surface: make a tetrahedral mesh of it with `host mesh`"
        }
        _ => "",
    }
}

/// Shorthand for an error without a file (filled in later by [`MeshError::with_path`]).
pub(crate) fn nofile() -> Origin {
    Origin(None)
}
