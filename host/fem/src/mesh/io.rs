//! Reading mesh files: format dispatch on the file extension.

use super::error::{MeshError, Origin};
use super::{Ignored, TetMesh, gmsh, medit, validate, vtk, vtu};
use std::path::Path;

/// Mesh file formats that can be read.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Format {
    /// Gmsh `.msh`: version 1 or 2 ASCII, version 4.1 ASCII or binary (detected from the first
    /// section: `$NOD` for version 1, else `$MeshFormat`).
    Msh,
    /// VTK XML unstructured grid `.vtu` (ascii, base64 or raw appended data; zlib or none).
    Vtu,
    /// Legacy VTK `.vtk`, ASCII or binary, classic or version 5.1 (`OFFSETS`/`CONNECTIVITY`) layout.
    Vtk,
    /// Medit `.mesh`, ASCII (`MeshVersionFormatted` 1 or 2, `Dimension 3`).
    Medit,
}

impl Format {
    /// The format for a file name's extension (case-insensitive).
    pub fn from_path(path: &Path) -> Result<Format, MeshError> {
        let ext = path
            .extension()
            .map(|e| e.to_string_lossy().to_ascii_lowercase())
            .unwrap_or_default();
        match ext.as_str() {
            "msh" => Ok(Format::Msh),
            "vtu" => Ok(Format::Vtu),
            "vtk" => Ok(Format::Vtk),
            "mesh" => Ok(Format::Medit),
            _ => Err(MeshError::UnknownExtension {
                file: Origin(Some(path.to_path_buf())),
                extension: ext,
            }),
        }
    }
}

/// Parse the contents of a mesh file without validating the mesh. Never panics; errors carry no
/// file name (add one with [`MeshError::with_path`]).
pub fn read_bytes(bytes: &[u8], format: Format) -> Result<TetMesh, MeshError> {
    read_bytes_counted(bytes, format).map(|(mesh, _)| mesh)
}

/// [`read_bytes`], also returning the elements of dimension < 3 that were skipped.
pub fn read_bytes_counted(bytes: &[u8], format: Format) -> Result<(TetMesh, Ignored), MeshError> {
    match format {
        Format::Msh => gmsh::read_msh(bytes),
        Format::Vtu => vtu::read_vtu(bytes),
        Format::Vtk => vtk::read_legacy(bytes),
        Format::Medit => medit::read_medit(bytes),
    }
}

/// Parse the contents of a Gmsh `.msh` file (e.g. one embedded with `include_bytes!`) and
/// [`validate`] the mesh: the in-memory counterpart of [`load`].
pub fn parse_msh(bytes: &[u8]) -> Result<TetMesh, MeshError> {
    let mesh = read_bytes(bytes, Format::Msh)?;
    validate(&mesh)?;
    Ok(mesh)
}

/// The largest mesh file read, bytes (4 GiB: some 30 million tetrahedra in ASCII).
pub const MAX_MESH_BYTES: u64 = 4 << 30;

/// Read a mesh file (format from its extension) without validating the mesh, for tools that
/// want to report every problem themselves.
pub fn read(path: &Path) -> Result<TetMesh, MeshError> {
    read_counted(path).map(|(mesh, _)| mesh)
}

/// [`read`], also returning the elements of dimension < 3 that were skipped.
pub fn read_counted(path: &Path) -> Result<(TetMesh, Ignored), MeshError> {
    let format = Format::from_path(path)?;
    let io = |source| MeshError::Io {
        file: Origin(Some(path.to_path_buf())),
        source,
    };
    // Only a regular file of bounded size: `/dev/zero` or a FIFO would read forever.
    let meta = std::fs::metadata(path).map_err(io)?;
    if !meta.is_file() || meta.len() > MAX_MESH_BYTES {
        return Err(MeshError::Format {
            file: Origin(Some(path.to_path_buf())),
            message: if meta.is_file() {
                format!(
                    "{} bytes, more than the {MAX_MESH_BYTES} a mesh file may have",
                    meta.len()
                )
            } else {
                "not a regular file".into()
            },
        });
    }
    let bytes = std::fs::read(path).map_err(io)?;
    read_bytes_counted(&bytes, format).map_err(|e| e.with_path(path))
}

/// Read a mesh file and [`validate`] it.
pub fn load(path: &Path) -> Result<TetMesh, MeshError> {
    let mesh = read(path)?;
    validate(&mesh).map_err(|e| e.with_path(path))?;
    Ok(mesh)
}
