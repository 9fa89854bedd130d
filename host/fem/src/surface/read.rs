//! Triangulated surface files: STL (ASCII and binary), Wavefront OBJ, PLY (ASCII and binary,
//! either byte order), legacy VTK polydata (`.vtk`, ASCII and binary) and VTK XML polydata
//! (`.vtp`).
//!
//! Hand parsers, like the tetrahedral readers beside them: errors must name the line (text) or
//! byte offset (binary) and the face or vertex, and no input may panic. (`tobj`'s `LoadError`
//! carries neither a line nor an index; `vtkio` prints to stderr and panics on malformed input,
//! see `crate::mesh`.) Polygons with more than three vertices are split into fans.

use super::TriSurface;
use crate::mesh::MeshError;
use crate::mesh::text::{Cursor, parse_num, show, tokens, trim};
use std::path::Path;

/// Surface file formats that can be read.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SurfaceFormat {
    /// STL, ASCII or binary (told apart by the declared triangle count against the file size).
    Stl,
    /// Wavefront OBJ: `v` and `f` lines (`f a/b/c ...`, negative indices relative), the rest
    /// ignored.
    Obj,
    /// PLY, ASCII or binary (little- or big-endian): element `vertex` (x, y, z) and `face`
    /// (list `vertex_indices` or `vertex_index`); other elements and properties skipped.
    Ply,
    /// Legacy VTK `DATASET POLYDATA`, ASCII or binary, classic or 5.1 layout: `POLYGONS` and
    /// `TRIANGLE_STRIPS`; vertices and lines ignored.
    Vtk,
    /// VTK XML `PolyData` (`.vtp`): the `<Polys>` of every piece (ascii, base64 or raw
    /// appended data, zlib or none, as `.vtu`).
    Vtp,
}

impl SurfaceFormat {
    /// The format for a file name's extension (case-insensitive).
    pub fn from_path(path: &Path) -> Result<SurfaceFormat, MeshError> {
        let ext = path
            .extension()
            .map(|e| e.to_string_lossy().to_ascii_lowercase())
            .unwrap_or_default();
        match ext.as_str() {
            "stl" => Ok(SurfaceFormat::Stl),
            "obj" => Ok(SurfaceFormat::Obj),
            "ply" => Ok(SurfaceFormat::Ply),
            "vtk" => Ok(SurfaceFormat::Vtk),
            "vtp" => Ok(SurfaceFormat::Vtp),
            _ => Err(MeshError::Format {
                file: crate::mesh::Origin(Some(path.to_path_buf())),
                message: format!(
                    "unknown surface file extension {ext:?} (expected .stl, .obj, .ply, .vtk or .vtp)"
                ),
            }),
        }
    }
}

fn format_err(message: impl Into<String>) -> MeshError {
    MeshError::Format {
        file: crate::mesh::Origin(None),
        message: message.into(),
    }
}

fn bin_err(offset: usize, message: impl Into<String>) -> MeshError {
    MeshError::ParseBinary {
        file: crate::mesh::Origin(None),
        offset,
        message: message.into(),
    }
}

/// Parse the contents of a surface file. Never panics; errors carry no file name (add one
/// with [`MeshError::with_path`]).
pub fn read_surface_bytes(bytes: &[u8], format: SurfaceFormat) -> Result<TriSurface, MeshError> {
    let s = match format {
        SurfaceFormat::Stl => read_stl(bytes)?,
        SurfaceFormat::Obj => read_obj(bytes)?,
        SurfaceFormat::Ply => read_ply(bytes)?,
        SurfaceFormat::Vtk => crate::mesh::read_vtk_polydata(bytes)?,
        SurfaceFormat::Vtp => crate::mesh::read_vtp(bytes)?,
    };
    if s.triangles.is_empty() {
        return Err(format_err(format!(
            "the file has no triangles ({} vertices)",
            s.vertices.len()
        )));
    }
    Ok(s)
}

/// Read a surface file (format from its extension). Only regular files up to 4 GiB.
pub fn read_surface(path: &Path) -> Result<TriSurface, MeshError> {
    let format = SurfaceFormat::from_path(path)?;
    let file = || crate::mesh::Origin(Some(path.to_path_buf()));
    let meta = std::fs::metadata(path).map_err(|source| MeshError::Io {
        file: file(),
        source,
    })?;
    if !meta.is_file() || meta.len() > crate::mesh::MAX_MESH_BYTES {
        return Err(MeshError::Format {
            file: file(),
            message: "not a regular file of at most 4 GiB".into(),
        });
    }
    let bytes = std::fs::read(path).map_err(|source| MeshError::Io {
        file: file(),
        source,
    })?;
    read_surface_bytes(&bytes, format).map_err(|e| e.with_path(path))
}

/// Split polygon `poly` (vertex ids) into a fan of triangles.
fn push_fan(out: &mut Vec<[usize; 3]>, poly: &[usize]) {
    for k in 1..poly.len().saturating_sub(1) {
        out.push([poly[0], poly[k], poly[k + 1]]);
    }
}

/// STL: vertices are repeated per facet in the format, so identical coordinates are merged
/// while reading (bit-for-bit equal only; near duplicates are the checks' business).
fn read_stl(bytes: &[u8]) -> Result<TriSurface, MeshError> {
    let declared = bytes
        .get(80..84)
        .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as u64);
    let binary_size = declared.map(|n| 84 + 50 * n);
    let looks_ascii = trim(bytes).starts_with(b"solid");
    if binary_size == Some(bytes.len() as u64) || !looks_ascii {
        read_stl_binary(bytes)
    } else {
        read_stl_ascii(bytes)
    }
}

/// Merges bit-identical coordinates into one vertex id.
#[derive(Default)]
struct Welder {
    ids: std::collections::HashMap<[u64; 3], usize>,
    vertices: Vec<[f64; 3]>,
}

impl Welder {
    fn id(&mut self, p: [f64; 3]) -> usize {
        // +0.0 and -0.0 are the same point.
        let key = p.map(|x| (x + 0.0).to_bits());
        *self.ids.entry(key).or_insert_with(|| {
            self.vertices.push(p);
            self.vertices.len() - 1
        })
    }
}

fn read_stl_binary(bytes: &[u8]) -> Result<TriSurface, MeshError> {
    let Some(head) = bytes.get(80..84) else {
        return Err(bin_err(
            bytes.len(),
            "binary STL shorter than its 84-byte header (file truncated?)",
        ));
    };
    let n = u32::from_le_bytes([head[0], head[1], head[2], head[3]]) as usize;
    let need = 84 + 50 * n as u64;
    if need != bytes.len() as u64 {
        return Err(bin_err(
            80,
            format!(
                "binary STL declares {n} triangles ({need} bytes) but the file has {} bytes{}",
                bytes.len(),
                if need > bytes.len() as u64 {
                    " (file truncated?)"
                } else {
                    ""
                }
            ),
        ));
    }
    let mut w = Welder::default();
    let mut triangles = Vec::with_capacity(n);
    for (t, rec) in bytes[84..].chunks_exact(50).enumerate() {
        let f = |k: usize| {
            let b = &rec[12 + 4 * k..16 + 4 * k];
            f64::from(f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        };
        let mut tri = [0; 3];
        for (v, slot) in tri.iter_mut().enumerate() {
            let p = [f(3 * v), f(3 * v + 1), f(3 * v + 2)];
            if p.iter().any(|x| !x.is_finite()) {
                return Err(bin_err(
                    84 + 50 * t + 12 + 12 * v,
                    format!("triangle {t} has a non-finite vertex {p:?}"),
                ));
            }
            *slot = w.id(p);
        }
        triangles.push(tri);
    }
    Ok(TriSurface {
        vertices: w.vertices,
        triangles,
    })
}

fn read_stl_ascii(bytes: &[u8]) -> Result<TriSurface, MeshError> {
    let mut c = Cursor::new(bytes);
    let mut w = Welder::default();
    let mut triangles = Vec::new();
    let mut poly: Vec<usize> = Vec::new();
    let mut in_loop = false;
    let mut ended = false;
    c.expect_token("\"solid\"")?; // checked by the caller
    c.drop_rest_of_line(); // the solid's name
    while let Some(tok) = c.token() {
        match tok {
            b"facet" | b"outer" => c.drop_rest_of_line(),
            b"loop" => {}
            b"vertex" => {
                let mut p = [0.0f64; 3];
                for (k, axis) in ["x", "y", "z"].into_iter().enumerate() {
                    p[k] = c.number(&format!("vertex {axis} coordinate"))?;
                }
                if !p.iter().all(|x| x.is_finite()) {
                    return Err(c.err(format!("non-finite vertex {p:?}")));
                }
                if !in_loop {
                    in_loop = true;
                    poly.clear();
                }
                poly.push(w.id(p));
            }
            b"endloop" => {
                if poly.len() < 3 {
                    return Err(c.err(format!(
                        "facet {} has {} vertices (at least 3 needed)",
                        triangles.len(),
                        poly.len()
                    )));
                }
                push_fan(&mut triangles, &poly);
                in_loop = false;
            }
            b"endfacet" => {}
            b"endsolid" => {
                ended = true;
                break;
            }
            // A second solid in the same file.
            b"solid" => c.drop_rest_of_line(),
            other => {
                return Err(c.err(format!(
                    "unexpected {} in an ASCII STL (expected facet, vertex, endloop, endfacet \
                     or endsolid)",
                    show(other)
                )));
            }
        }
    }
    if in_loop || !ended {
        return Err(c.err("unexpected end of file: no \"endsolid\" (file truncated?)"));
    }
    Ok(TriSurface {
        vertices: w.vertices,
        triangles,
    })
}

/// OBJ: `v x y z [w | r g b]` and `f i[/t[/n]] ...` (1-based, negative = from the end).
fn read_obj(bytes: &[u8]) -> Result<TriSurface, MeshError> {
    let mut c = Cursor::new(bytes);
    let mut vertices = Vec::new();
    let mut triangles = Vec::new();
    let mut poly = Vec::new();
    while let Some(line) = c.next_line() {
        let mut t = tokens(line);
        match t.next() {
            Some(b"v") => {
                let mut p = [0.0; 3];
                for (k, axis) in ["x", "y", "z"].into_iter().enumerate() {
                    let tok = t.next().ok_or_else(|| {
                        c.err(format!(
                            "vertex {} has no {axis} coordinate",
                            vertices.len() + 1
                        ))
                    })?;
                    p[k] = parse_num::<f64>(tok)
                        .filter(|x| x.is_finite())
                        .ok_or_else(|| {
                            c.err(format!(
                                "invalid {axis} coordinate {} of vertex {}",
                                show(tok),
                                vertices.len() + 1
                            ))
                        })?;
                }
                vertices.push(p);
            }
            Some(b"f") => {
                poly.clear();
                for tok in t {
                    let idx = tok.split(|&b| b == b'/').next().unwrap_or(b"");
                    let i: i64 = parse_num(idx).ok_or_else(|| {
                        c.err(format!("invalid vertex index {} in a face", show(tok)))
                    })?;
                    let n = vertices.len() as i64;
                    let id = if i > 0 { i - 1 } else { n + i };
                    if i == 0 || id < 0 || id >= n {
                        return Err(c.err(format!(
                            "face {} refers to vertex {i}, but {n} vertices are defined so far",
                            triangles.len() + 1
                        )));
                    }
                    poly.push(id as usize);
                }
                if poly.len() < 3 {
                    return Err(c.err(format!(
                        "face with {} vertices (at least 3 needed)",
                        poly.len()
                    )));
                }
                push_fan(&mut triangles, &poly);
            }
            _ => {}
        }
    }
    Ok(TriSurface {
        vertices,
        triangles,
    })
}

/// A PLY scalar type: size in bytes, and whether it is a float.
fn ply_type(name: &[u8]) -> Option<(usize, bool, bool)> {
    // (size, float, signed)
    Some(match name {
        b"char" | b"int8" => (1, false, true),
        b"uchar" | b"uint8" => (1, false, false),
        b"short" | b"int16" => (2, false, true),
        b"ushort" | b"uint16" => (2, false, false),
        b"int" | b"int32" => (4, false, true),
        b"uint" | b"uint32" => (4, false, false),
        b"float" | b"float32" => (4, true, true),
        b"double" | b"float64" => (8, true, true),
        _ => return None,
    })
}

type PlyType = (usize, bool, bool);

struct PlyProperty {
    name: Vec<u8>,
    /// `Some(count type)` for a list property.
    list: Option<PlyType>,
    ty: PlyType,
}

struct PlyElement {
    name: Vec<u8>,
    count: usize,
    props: Vec<PlyProperty>,
}

/// PLY, ASCII or binary.
fn read_ply(bytes: &[u8]) -> Result<TriSurface, MeshError> {
    let mut c = Cursor::new(bytes);
    let first = c.next_line().map(trim).unwrap_or_default();
    if first != b"ply" {
        return Err(c.err(format!(
            "not a PLY file: expected \"ply\", found {}",
            show(first)
        )));
    }
    let mut encoding = None;
    let mut elements: Vec<PlyElement> = Vec::new();
    loop {
        let line = c
            .next_line()
            .ok_or_else(|| c.err("unexpected end of file in the header: no end_header"))?;
        let t: Vec<&[u8]> = tokens(line).collect();
        match t.first().copied() {
            Some(b"format") => {
                encoding = Some(match t.get(1).copied() {
                    Some(b"ascii") => 0,
                    Some(b"binary_little_endian") => 1,
                    Some(b"binary_big_endian") => 2,
                    _ => return Err(c.err(format!("unknown PLY format {}", show(trim(line))))),
                });
            }
            Some(b"element") => {
                let (Some(name), Some(count)) = (t.get(1), t.get(2).and_then(|n| parse_num(n)))
                else {
                    return Err(c.err(format!(
                        "expected \"element name count\", found {}",
                        show(trim(line))
                    )));
                };
                elements.push(PlyElement {
                    name: name.to_vec(),
                    count,
                    props: Vec::new(),
                });
            }
            Some(b"property") => {
                let bad = || c.err(format!("invalid property line {}", show(trim(line))));
                let el = elements.last_mut().ok_or_else(bad)?;
                let prop = if t.get(1) == Some(&&b"list"[..]) {
                    let (Some(ct), Some(it), Some(name)) = (
                        t.get(2).and_then(|x| ply_type(x)),
                        t.get(3).and_then(|x| ply_type(x)),
                        t.get(4),
                    ) else {
                        return Err(bad());
                    };
                    if ct.1 {
                        return Err(bad());
                    }
                    PlyProperty {
                        name: name.to_vec(),
                        list: Some(ct),
                        ty: it,
                    }
                } else {
                    let (Some(ty), Some(name)) = (t.get(1).and_then(|x| ply_type(x)), t.get(2))
                    else {
                        return Err(bad());
                    };
                    PlyProperty {
                        name: name.to_vec(),
                        list: None,
                        ty,
                    }
                };
                el.props.push(prop);
            }
            Some(b"end_header") => break,
            Some(b"comment" | b"obj_info") | None => {}
            Some(other) => {
                return Err(c.err(format!("unexpected {} in the PLY header", show(other))));
            }
        }
    }
    let encoding = encoding.ok_or_else(|| c.err("the PLY header has no format line"))?;
    let mut vertices = Vec::new();
    let mut triangles = Vec::new();
    let mut poly = Vec::new();
    let mut bin_pos = bytes.len() - c.rest().len();
    for el in &elements {
        let is_vertex = el.name == b"vertex";
        let is_face = el.name == b"face";
        let axis_of = |p: &PlyProperty| match p.name.as_slice() {
            b"x" => Some(0),
            b"y" => Some(1),
            b"z" => Some(2),
            _ => None,
        };
        if is_vertex && (0..3).any(|a| !el.props.iter().any(|p| axis_of(p) == Some(a))) {
            return Err(format_err("PLY element vertex lacks an x, y or z property"));
        }
        if el.props.is_empty() {
            continue; // nothing to read, however many
        }
        for i in 0..el.count {
            let mut p = [0.0; 3];
            for prop in &el.props {
                let what = || {
                    format!(
                        "property {} of {} {i}",
                        String::from_utf8_lossy(&prop.name),
                        String::from_utf8_lossy(&el.name)
                    )
                };
                let mut read_one = |ty: PlyType| -> Result<f64, MeshError> {
                    if encoding == 0 {
                        let what = what();
                        let tok = c.expect_token(&what)?;
                        parse_num::<f64>(tok)
                            .ok_or_else(|| c.err(format!("invalid {what} {}", show(tok))))
                    } else {
                        let at = bin_pos;
                        let b = bytes.get(at..at + ty.0).ok_or_else(|| {
                            bin_err(
                                at,
                                format!("unexpected end of file in {} (file truncated?)", what()),
                            )
                        })?;
                        bin_pos += ty.0;
                        let mut u = 0u64;
                        for k in 0..ty.0 {
                            let byte = if encoding == 1 { b[ty.0 - 1 - k] } else { b[k] };
                            u = (u << 8) | u64::from(byte);
                        }
                        Ok(match ty {
                            (4, true, _) => f64::from(f32::from_bits(u as u32)),
                            (_, true, _) => f64::from_bits(u),
                            (s, false, true) => {
                                let shift = 64 - 8 * s as u32;
                                (((u << shift) as i64) >> shift) as f64
                            }
                            _ => u as f64,
                        })
                    }
                };
                match prop.list {
                    None => {
                        let v = read_one(prop.ty)?;
                        if is_vertex && let Some(a) = axis_of(prop) {
                            p[a] = v;
                        }
                    }
                    Some(ct) => {
                        let n = read_one(ct)?;
                        let keep = is_face
                            && matches!(prop.name.as_slice(), b"vertex_indices" | b"vertex_index");
                        if !(0.0..=1e6).contains(&n) {
                            return Err(format_err(format!("{}: list length {n}", what())));
                        }
                        poly.clear();
                        for _ in 0..n as usize {
                            let v = read_one(prop.ty)?;
                            if keep {
                                if !(v >= 0.0 && v < vertices.len() as f64 && v.fract() == 0.0) {
                                    return Err(format_err(format!(
                                        "face {i} refers to vertex {v}, but there are {} vertices",
                                        vertices.len()
                                    )));
                                }
                                poly.push(v as usize);
                            }
                        }
                        if keep {
                            if poly.len() < 3 {
                                return Err(format_err(format!(
                                    "face {i} has {} vertices (at least 3 needed)",
                                    poly.len()
                                )));
                            }
                            push_fan(&mut triangles, &poly);
                        }
                    }
                }
            }
            if is_vertex {
                if !p.iter().all(|x| x.is_finite()) {
                    return Err(format_err(format!("vertex {i} is not finite: {p:?}")));
                }
                vertices.push(p);
            }
        }
    }
    Ok(TriSurface {
        vertices,
        triangles,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A unit tetrahedron's surface, outward.
    fn tet() -> TriSurface {
        TriSurface {
            vertices: vec![[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            triangles: vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]],
        }
    }

    /// The faces as coordinate triples, each rotated to start at its smallest vertex, sorted:
    /// equal for the same oriented surface whatever the vertex numbering.
    fn shape(s: &TriSurface) -> Vec<[[u64; 3]; 3]> {
        let mut v: Vec<[[u64; 3]; 3]> = s
            .triangles
            .iter()
            .map(|t| {
                let p = t.map(|i| s.vertices[i].map(f64::to_bits));
                let k = (0..3).min_by_key(|&k| p[k]).unwrap_or(0);
                [p[k], p[(k + 1) % 3], p[(k + 2) % 3]]
            })
            .collect();
        v.sort();
        v
    }

    #[test]
    fn every_format_reads_the_same_tetrahedron() {
        let obj = "# tet\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nvn 0 0 1\nf 1 3 2\nf 1/1 2/2 4/4\n\
                   f -4//1 -1//1 -2//1\nf 2 3 4\n";
        assert_eq!(
            read_surface_bytes(obj.as_bytes(), SurfaceFormat::Obj).unwrap(),
            tet()
        );
        let mut stl = String::from("solid t\n");
        for t in tet().triangles {
            stl.push_str(" facet normal 0 0 0\n  outer loop\n");
            for v in t {
                let p = tet().vertices[v];
                stl.push_str(&format!("   vertex {} {} {}\n", p[0], p[1], p[2]));
            }
            stl.push_str("  endloop\n endfacet\n");
        }
        stl.push_str("endsolid t\n");
        let s = read_surface_bytes(stl.as_bytes(), SurfaceFormat::Stl).unwrap();
        assert_eq!((s.vertices.len(), shape(&s)), (4, shape(&tet())));
        let mut bin = vec![0u8; 80];
        bin.extend_from_slice(&4u32.to_le_bytes());
        for t in tet().triangles {
            bin.extend_from_slice(&[0; 12]);
            for v in t {
                for x in tet().vertices[v] {
                    bin.extend_from_slice(&(x as f32).to_le_bytes());
                }
            }
            bin.extend_from_slice(&[0; 2]);
        }
        let s = read_surface_bytes(&bin, SurfaceFormat::Stl).unwrap();
        assert_eq!((s.vertices.len(), shape(&s)), (4, shape(&tet())));
        let e = read_surface_bytes(&bin[..bin.len() - 7], SurfaceFormat::Stl)
            .unwrap_err()
            .to_string();
        assert_eq!(
            e,
            "byte 80: binary STL declares 4 triangles (284 bytes) but the file has 277 bytes \
             (file truncated?)"
        );
        let ply = "ply\nformat ascii 1.0\ncomment t\nelement vertex 4\nproperty float x\n\
                   property float y\nproperty float z\nproperty uchar red\nelement face 4\n\
                   property list uchar int vertex_indices\nend_header\n0 0 0 9\n1 0 0 9\n\
                   0 1 0 9\n0 0 1 9\n3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n";
        assert_eq!(
            read_surface_bytes(ply.as_bytes(), SurfaceFormat::Ply).unwrap(),
            tet()
        );
        for (name, le) in [("binary_little_endian", true), ("binary_big_endian", false)] {
            let mut b = format!(
                "ply\nformat {name} 1.0\nelement vertex 4\nproperty double x\nproperty double y\n\
                 property double z\nelement face 4\nproperty list uchar uint vertex_indices\n\
                 end_header\n"
            )
            .into_bytes();
            for p in tet().vertices {
                for x in p {
                    b.extend_from_slice(&if le { x.to_le_bytes() } else { x.to_be_bytes() });
                }
            }
            for t in tet().triangles {
                b.push(3);
                for v in t {
                    let v = v as u32;
                    b.extend_from_slice(&if le { v.to_le_bytes() } else { v.to_be_bytes() });
                }
            }
            assert_eq!(
                read_surface_bytes(&b, SurfaceFormat::Ply).unwrap(),
                tet(),
                "{name}"
            );
            let e = read_surface_bytes(&b[..b.len() - 1], SurfaceFormat::Ply).unwrap_err();
            assert!(
                e.to_string().contains("property vertex_indices of face 3"),
                "{e}"
            );
        }
    }

    #[test]
    fn errors_name_the_line_and_the_item() {
        let e = |text: &str, f| {
            read_surface_bytes(text.as_bytes(), f)
                .unwrap_err()
                .to_string()
        };
        assert_eq!(
            e("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n", SurfaceFormat::Obj),
            "line 4: face 1 refers to vertex 4, but 3 vertices are defined so far"
        );
        assert_eq!(
            e("v 0 0 0\nv 1 nan 0\n", SurfaceFormat::Obj),
            "line 2: invalid y coordinate \"nan\" of vertex 2"
        );
        assert_eq!(
            e("v 0 0 0\n", SurfaceFormat::Obj),
            "the file has no triangles (1 vertices)"
        );
        assert_eq!(
            e(
                "solid x\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0\n",
                SurfaceFormat::Stl
            ),
            "line 5: unexpected end of file while reading vertex z coordinate (file truncated?)"
        );
        assert!(
            e(
                "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nend_header\n0\n",
                SurfaceFormat::Ply
            )
            .contains("lacks an x, y or z")
        );
    }
}
