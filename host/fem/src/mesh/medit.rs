//! Medit `.mesh` files, ASCII (the format of Medit, MMG, TetGen's `-g` output and Gmsh's
//! `.mesh` export): free-format keywords, each followed by a count and that many items.
//!
//! Read: `MeshVersionFormatted` (1 or 2: single or double precision, the same in ASCII),
//! `Dimension 3`, `Vertices` (x y z ref), `Tetrahedra` (four 1-based vertex numbers and a
//! reference), `End`. Skipped and counted: `Edges`, `Triangles`, `Quadrilaterals`. Skipped:
//! the corner, ridge, required-entity and normal/tangent lists. Other 3D elements
//! (`Hexahedra`, `Prisms`, `Pyramids`) are an error; so is any keyword not listed here. Lines
//! starting with `#` are comments. The binary `.meshb` variant is not read.

use super::error::{MeshError, nofile};
use super::text::{Cursor, parse_num, show};
use super::{Ignored, TetMesh};

/// What follows a keyword.
enum Section {
    Vertices,
    Tetrahedra,
    /// Lower-dimensional elements: their name and tokens per item (vertices + reference).
    Counted(&'static str, usize),
    /// 3D elements that are not tetrahedra.
    Unsupported(&'static str),
    /// Lists that say nothing about the volume: tokens per item.
    Skipped(usize),
}

fn section(keyword: &[u8]) -> Option<Section> {
    let k = keyword.to_ascii_lowercase();
    Some(match k.as_slice() {
        b"vertices" => Section::Vertices,
        b"tetrahedra" => Section::Tetrahedra,
        b"edges" => Section::Counted("edge", 3),
        b"triangles" => Section::Counted("triangle", 4),
        b"quadrilaterals" => Section::Counted("quadrilateral", 5),
        b"hexahedra" => Section::Unsupported("hexahedron (Medit Hexahedra)"),
        b"prisms" => Section::Unsupported("prism (Medit Prisms)"),
        b"pyramids" => Section::Unsupported("pyramid (Medit Pyramids)"),
        b"corners"
        | b"requiredvertices"
        | b"ridges"
        | b"requirededges"
        | b"requiredtriangles"
        | b"requiredquadrilaterals"
        | b"requiredtetrahedra" => Section::Skipped(1),
        b"normalatvertices" | b"tangentatvertices" => Section::Skipped(2),
        b"normals" | b"tangents" | b"normalattrianglevertices" => Section::Skipped(3),
        _ => return None,
    })
}

/// The next token that is not in a `#` comment.
fn token<'a>(c: &mut Cursor<'a>) -> Option<&'a [u8]> {
    loop {
        let t = c.token()?;
        if t.starts_with(b"#") {
            c.drop_rest_of_line();
        } else {
            return Some(t);
        }
    }
}

fn number<T: std::str::FromStr>(c: &mut Cursor<'_>, what: &str) -> Result<T, MeshError> {
    let t = token(c).ok_or_else(|| {
        c.err(format!(
            "unexpected end of file while reading {what} (file truncated?)"
        ))
    })?;
    parse_num(t).ok_or_else(|| c.err(format!("invalid {what} {}", show(t))))
}

/// Read a Medit `.mesh` file.
pub(crate) fn read_medit(bytes: &[u8]) -> Result<(TetMesh, Ignored), MeshError> {
    let mut c = Cursor::new(bytes);
    // Capacity hints bounded by the file size, so a bogus count cannot exhaust memory.
    let cap = |n: usize| n.min(bytes.len() / 8);
    let first = token(&mut c).ok_or_else(|| c.err("empty file"))?;
    if !first.eq_ignore_ascii_case(b"MeshVersionFormatted") {
        return Err(c.err(format!(
            "expected \"MeshVersionFormatted\" at the start of a Medit .mesh file, found {}",
            show(first)
        )));
    }
    let version: u32 = number(&mut c, "MeshVersionFormatted version")?;
    if !(1..=2).contains(&version) {
        return Err(c.err(format!(
            "unsupported MeshVersionFormatted {version} (expected 1 or 2)"
        )));
    }
    let mut nodes: Vec<[f64; 3]> = Vec::new();
    let mut tets: Vec<[usize; 4]> = Vec::new();
    let mut ignored = Ignored::default();
    let mut dimension = None;
    let mut seen_vertices = false;
    while let Some(kw) = token(&mut c) {
        if kw.eq_ignore_ascii_case(b"End") {
            break;
        }
        if kw.eq_ignore_ascii_case(b"Dimension") {
            let d: u32 = number(&mut c, "dimension")?;
            if d != 3 {
                return Err(c.err(format!("Dimension {d}: only 3D meshes hold tetrahedra")));
            }
            dimension = Some(d);
            continue;
        }
        let Some(sec) = section(kw) else {
            return Err(c.err(format!(
                "unknown or unsupported Medit keyword {} (expected Vertices, Tetrahedra, \
                 Triangles, Edges, ... or End)",
                show(kw)
            )));
        };
        let kw_line = c.line();
        let name = String::from_utf8_lossy(kw).into_owned();
        let n: usize = number(&mut c, &format!("number of {name}"))?;
        match sec {
            Section::Vertices => {
                if dimension.is_none() {
                    return Err(c.err("Vertices before \"Dimension 3\""));
                }
                if seen_vertices {
                    return Err(c.err("second Vertices section (only one is supported)"));
                }
                seen_vertices = true;
                nodes.reserve(cap(n));
                for i in 0..n {
                    let mut p = [0.0; 3];
                    for (k, axis) in ["x", "y", "z"].into_iter().enumerate() {
                        p[k] = number(&mut c, &format!("{axis} coordinate of vertex {}", i + 1))?;
                    }
                    number::<i64>(&mut c, &format!("reference of vertex {}", i + 1))?;
                    nodes.push(p);
                }
            }
            Section::Tetrahedra => {
                if !seen_vertices {
                    return Err(c.err("Tetrahedra before Vertices"));
                }
                tets.reserve(cap(n));
                for i in 0..n {
                    let mut tet = [0usize; 4];
                    for slot in &mut tet {
                        let v: u64 =
                            number(&mut c, &format!("vertex number of tetrahedron {}", i + 1))?;
                        *slot = usize::try_from(v)
                            .ok()
                            .filter(|&v| (1..=nodes.len()).contains(&v))
                            .ok_or_else(|| {
                                c.err(format!(
                                    "tetrahedron {} refers to vertex {v}, but Vertices has {} \
                                     (numbered from 1)",
                                    i + 1,
                                    nodes.len()
                                ))
                            })?
                            - 1;
                    }
                    number::<i64>(&mut c, &format!("reference of tetrahedron {}", i + 1))?;
                    tets.push(tet);
                }
            }
            Section::Counted(kind, per_item) => {
                for i in 0..n {
                    for _ in 0..per_item {
                        number::<i64>(&mut c, &format!("{name} item {}", i + 1))?;
                    }
                }
                ignored.add_many(kind, n);
            }
            Section::Unsupported(kind) => {
                if n > 0 {
                    return Err(MeshError::UnsupportedElement {
                        file: nofile(),
                        element: 0,
                        kind: format!("{kind}, {n} of them from line {kw_line}"),
                    });
                }
            }
            Section::Skipped(per_item) => {
                for i in 0..n {
                    for _ in 0..per_item {
                        number::<f64>(&mut c, &format!("{name} item {}", i + 1))?;
                    }
                }
            }
        }
    }
    if !seen_vertices {
        return Err(c.err("no Vertices section"));
    }
    Ok((TetMesh { nodes, tets }, ignored))
}

#[cfg(test)]
mod tests {
    use super::*;

    const ONE_TET: &str = "MeshVersionFormatted 2\n# a comment\nDimension\n3\nVertices\n4\n\
        0 0 0 1\n1 0 0 1\n0 1 0 1\n0 0 1 1\nTriangles\n2\n1 2 3 5\n1 2 4 5\n\
        Corners 1 1\nTetrahedra\n1\n1 2 3 4 7\nEnd\n";

    #[test]
    fn one_tetrahedron_with_triangles_and_comments() {
        let (m, ignored) = read_medit(ONE_TET.as_bytes()).unwrap();
        assert_eq!(m.nodes[1], [1.0, 0.0, 0.0]);
        assert_eq!(m.tets, vec![[0, 1, 2, 3]]);
        assert_eq!(ignored.to_string(), "2 triangle");
    }

    #[test]
    fn errors_name_the_line_and_the_item() {
        let e = |text: String| read_medit(text.as_bytes()).unwrap_err().to_string();
        assert_eq!(
            e(ONE_TET.replace("1 2 3 4 7", "1 2 3 5 7")),
            "line 18: tetrahedron 1 refers to vertex 5, but Vertices has 4 (numbered from 1)"
        );
        assert_eq!(
            e(ONE_TET.replace("0 1 0 1\n", "0 y 0 1\n")),
            "line 9: invalid y coordinate of vertex 3 \"y\""
        );
        assert_eq!(
            e(ONE_TET.replace("Dimension\n3", "Dimension\n2")),
            "line 4: Dimension 2: only 3D meshes hold tetrahedra"
        );
        assert!(
            e(ONE_TET.replace("Tetrahedra\n1", "Hexahedra\n1"))
                .contains("unsupported type hexahedron")
        );
        assert!(e(ONE_TET.replace("Corners", "Blobs")).contains("unknown or unsupported"));
        let cut = &ONE_TET[..ONE_TET.find("2 3 4 7").unwrap()];
        assert!(e(cut.to_string()).contains("file truncated?"));
    }
}
