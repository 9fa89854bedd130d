//! Legacy VTK files (`.vtk`), ASCII and binary (big-endian), both the classic `CELLS n size`
//! layout and the version 5.1 `OFFSETS`/`CONNECTIVITY` layout. Also the cell-type table and the
//! mesh builder shared with the `.vtu` reader.
//!
//! (`vtkio` is not used: it prints parser diagnostics to stderr on malformed binary files,
//! panics on some, and does not read the 5.1 layout.)

use super::error::{MeshError, nofile};
use super::text::{Cursor, parse_num, show, trim};
use super::{Ignored, TetMesh};
use crate::surface::TriSurface;

/// VTK cell type of the linear tetrahedron.
const VTK_TETRA: u32 = 10;

/// Dimension and name of a VTK cell type, `None` if unknown.
fn cell_kind(ty: u32) -> Option<(u8, &'static str)> {
    Some(match ty {
        0 => (0, "VTK_EMPTY_CELL"),
        1 => (0, "VTK_VERTEX"),
        2 => (0, "VTK_POLY_VERTEX"),
        3 => (1, "VTK_LINE"),
        4 => (1, "VTK_POLY_LINE"),
        5 => (2, "VTK_TRIANGLE"),
        6 => (2, "VTK_TRIANGLE_STRIP"),
        7 => (2, "VTK_POLYGON"),
        8 => (2, "VTK_PIXEL"),
        9 => (2, "VTK_QUAD"),
        10 => (3, "VTK_TETRA"),
        11 => (3, "VTK_VOXEL (voxel)"),
        12 => (3, "VTK_HEXAHEDRON (hexahedron)"),
        13 => (3, "VTK_WEDGE (wedge)"),
        14 => (3, "VTK_PYRAMID (pyramid)"),
        15 => (3, "VTK_PENTAGONAL_PRISM (pentagonal prism)"),
        16 => (3, "VTK_HEXAGONAL_PRISM (hexagonal prism)"),
        21 => (1, "VTK_QUADRATIC_EDGE"),
        22 => (2, "VTK_QUADRATIC_TRIANGLE"),
        23 => (2, "VTK_QUADRATIC_QUAD"),
        24 => (3, "VTK_QUADRATIC_TETRA (10-node tetrahedron)"),
        25 => (3, "VTK_QUADRATIC_HEXAHEDRON (20-node hexahedron)"),
        26 => (3, "VTK_QUADRATIC_WEDGE (15-node wedge)"),
        27 => (3, "VTK_QUADRATIC_PYRAMID (13-node pyramid)"),
        28 => (2, "VTK_BIQUADRATIC_QUAD"),
        29 => (3, "VTK_TRIQUADRATIC_HEXAHEDRON (27-node hexahedron)"),
        30 => (2, "VTK_QUADRATIC_LINEAR_QUAD"),
        31 => (3, "VTK_QUADRATIC_LINEAR_WEDGE (12-node wedge)"),
        32 => (3, "VTK_BIQUADRATIC_QUADRATIC_WEDGE (18-node wedge)"),
        33 => (
            3,
            "VTK_BIQUADRATIC_QUADRATIC_HEXAHEDRON (24-node hexahedron)",
        ),
        34 => (2, "VTK_BIQUADRATIC_TRIANGLE"),
        35 => (1, "VTK_CUBIC_LINE"),
        36 => (2, "VTK_QUADRATIC_POLYGON"),
        37 => (3, "VTK_TRIQUADRATIC_PYRAMID (19-node pyramid)"),
        41 => (3, "VTK_CONVEX_POINT_SET (convex point set)"),
        42 => (3, "VTK_POLYHEDRON (polyhedron)"),
        51 => (1, "VTK_PARAMETRIC_CURVE"),
        52 => (2, "VTK_PARAMETRIC_SURFACE"),
        53 => (2, "VTK_PARAMETRIC_TRI_SURFACE"),
        54 => (2, "VTK_PARAMETRIC_QUAD_SURFACE"),
        55 => (3, "VTK_PARAMETRIC_TETRA_REGION (parametric tetrahedron)"),
        56 => (3, "VTK_PARAMETRIC_HEX_REGION (parametric hexahedron)"),
        60 => (1, "VTK_HIGHER_ORDER_EDGE"),
        61 => (2, "VTK_HIGHER_ORDER_TRIANGLE"),
        62 => (2, "VTK_HIGHER_ORDER_QUAD"),
        63 => (2, "VTK_HIGHER_ORDER_POLYGON"),
        64 => (3, "VTK_HIGHER_ORDER_TETRAHEDRON (high-order tetrahedron)"),
        65 => (3, "VTK_HIGHER_ORDER_WEDGE (high-order wedge)"),
        66 => (3, "VTK_HIGHER_ORDER_PYRAMID (high-order pyramid)"),
        67 => (3, "VTK_HIGHER_ORDER_HEXAHEDRON (high-order hexahedron)"),
        68 => (1, "VTK_LAGRANGE_CURVE"),
        69 => (2, "VTK_LAGRANGE_TRIANGLE"),
        70 => (2, "VTK_LAGRANGE_QUADRILATERAL"),
        71 => (3, "VTK_LAGRANGE_TETRAHEDRON (Lagrange tetrahedron)"),
        72 => (3, "VTK_LAGRANGE_HEXAHEDRON (Lagrange hexahedron)"),
        73 => (3, "VTK_LAGRANGE_WEDGE (Lagrange wedge)"),
        74 => (3, "VTK_LAGRANGE_PYRAMID (Lagrange pyramid)"),
        75 => (1, "VTK_BEZIER_CURVE"),
        76 => (2, "VTK_BEZIER_TRIANGLE"),
        77 => (2, "VTK_BEZIER_QUADRILATERAL"),
        78 => (3, "VTK_BEZIER_TETRAHEDRON (Bezier tetrahedron)"),
        79 => (3, "VTK_BEZIER_HEXAHEDRON (Bezier hexahedron)"),
        80 => (3, "VTK_BEZIER_WEDGE (Bezier wedge)"),
        81 => (3, "VTK_BEZIER_PYRAMID (Bezier pyramid)"),
        _ => return None,
    })
}

/// Accumulates points and tetrahedra from one or more pieces.
#[derive(Default)]
pub(crate) struct Builder {
    pub(crate) nodes: Vec<[f64; 3]>,
    tets: Vec<[usize; 4]>,
    /// Cells seen so far (over all pieces), for 0-based cell indices in messages.
    pub(crate) cells: u64,
    /// Cells of dimension < 3, skipped.
    ignored: Ignored,
    /// The triangles and polygons among them (global point ids), for surface files.
    pub(crate) polygons: Vec<Vec<usize>>,
}

impl Builder {
    /// Add the points of a piece from a flat `x y z x y z ...` array.
    pub(crate) fn add_points(&mut self, flat: &[f64]) -> Result<(), MeshError> {
        if !flat.len().is_multiple_of(3) {
            return Err(format_err(format!(
                "the points array has {} values, not a multiple of 3",
                flat.len()
            )));
        }
        self.nodes
            .extend(flat.chunks_exact(3).map(|p| [p[0], p[1], p[2]]));
        Ok(())
    }

    /// Add one cell whose point ids are local to a piece whose first point is `point_offset`.
    pub(crate) fn add_cell(
        &mut self,
        ty: u32,
        verts: &[u64],
        point_offset: usize,
    ) -> Result<(), MeshError> {
        let index = self.cells;
        self.cells += 1;
        let Some((dim, kind)) = cell_kind(ty) else {
            return Err(MeshError::UnsupportedElement {
                file: nofile(),
                element: index,
                kind: format!("cell of unknown VTK type {ty}"),
            });
        };
        if dim < 3 {
            self.ignored.add(kind);
            if matches!(ty, 5 | 7) {
                let ids = verts.iter().map(|&v| {
                    usize::try_from(v)
                        .ok()
                        .and_then(|v| v.checked_add(point_offset))
                        .unwrap_or(usize::MAX)
                });
                self.polygons.push(ids.collect());
            }
            return Ok(());
        }
        if ty != VTK_TETRA {
            return Err(MeshError::UnsupportedElement {
                file: nofile(),
                element: index,
                kind: kind.to_string(),
            });
        }
        let &[a, b, c, d] = verts else {
            return Err(format_err(format!(
                "cell {index} is a VTK_TETRA with {} points (expected 4)",
                verts.len()
            )));
        };
        let mut tet = [0usize; 4];
        for (slot, v) in tet.iter_mut().zip([a, b, c, d]) {
            // Out-of-range ids are kept (saturated) for `validate` to report.
            *slot = usize::try_from(v)
                .ok()
                .and_then(|v| v.checked_add(point_offset))
                .unwrap_or(usize::MAX);
        }
        self.tets.push(tet);
        Ok(())
    }

    pub(crate) fn finish(self) -> (TetMesh, Ignored) {
        let mesh = TetMesh {
            nodes: self.nodes,
            tets: self.tets,
        };
        (mesh, self.ignored)
    }
}

fn format_err(message: String) -> MeshError {
    MeshError::Format {
        file: nofile(),
        message,
    }
}

/// What a legacy file's `DATASET` must be.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Dataset {
    /// `UNSTRUCTURED_GRID` (tetrahedra).
    Grid,
    /// `POLYDATA` (a surface).
    Poly,
}

/// The sections of a legacy file that are kept: points, cells (offsets, connectivity), cell
/// types (grids), and polygons (polydata, triangle strips already split).
#[derive(Default)]
struct Sections {
    points: Option<Vec<f64>>,
    cells: Option<(Vec<usize>, Vec<u64>)>,
    types: Option<Vec<u32>>,
    polygons: Vec<Vec<u64>>,
}

impl Sections {
    /// Keep the cells of a polydata section: `POLYGONS` as they are, `TRIANGLE_STRIPS` split
    /// into triangles (alternate ones reversed to keep the strip's orientation), `VERTICES`
    /// and `LINES` dropped.
    fn add_poly(&mut self, keyword: &[u8], offsets: &[usize], conn: &[u64]) {
        for w in offsets.windows(2) {
            let cell = &conn[w[0]..w[1]];
            match keyword {
                b"POLYGONS" => self.polygons.push(cell.to_vec()),
                b"TRIANGLE_STRIPS" => {
                    for k in 0..cell.len().saturating_sub(2) {
                        let t = if k % 2 == 0 {
                            [cell[k], cell[k + 1], cell[k + 2]]
                        } else {
                            [cell[k + 1], cell[k], cell[k + 2]]
                        };
                        self.polygons.push(t.to_vec());
                    }
                }
                _ => {}
            }
        }
    }
}

/// Read a legacy VTK file (`.vtk`).
pub(crate) fn read_legacy(bytes: &[u8]) -> Result<(TetMesh, Ignored), MeshError> {
    let s = read_sections(bytes, Dataset::Grid)?;
    let missing = |what: &str| format_err(format!("no {what} section (file truncated?)"));
    let points = s.points.ok_or_else(|| missing("POINTS"))?;
    let (offsets, conn) = s.cells.ok_or_else(|| missing("CELLS"))?;
    let types = s.types.ok_or_else(|| missing("CELL_TYPES"))?;
    assemble(&points, &offsets, &conn, &types)
}

/// Read a legacy VTK polydata file (a surface): its points and polygons, split into fans.
pub(crate) fn read_vtk_polydata(bytes: &[u8]) -> Result<TriSurface, MeshError> {
    let s = read_sections(bytes, Dataset::Poly)?;
    let flat = s
        .points
        .ok_or_else(|| format_err("no POINTS section (file truncated?)".into()))?;
    if !flat.len().is_multiple_of(3) {
        return Err(format_err("the points array is not a multiple of 3".into()));
    }
    let vertices: Vec<[f64; 3]> = flat.chunks_exact(3).map(|p| [p[0], p[1], p[2]]).collect();
    let mut triangles = Vec::new();
    for (i, poly) in s.polygons.iter().enumerate() {
        let ids: Vec<usize> = poly
            .iter()
            .map(|&v| {
                usize::try_from(v)
                    .ok()
                    .filter(|&v| v < vertices.len())
                    .ok_or_else(|| {
                        format_err(format!(
                            "polygon {i} refers to point {v}, but there are {} points",
                            vertices.len()
                        ))
                    })
            })
            .collect::<Result<_, _>>()?;
        if ids.len() < 3 {
            return Err(format_err(format!(
                "polygon {i} has {} points (at least 3 needed)",
                ids.len()
            )));
        }
        for k in 1..ids.len() - 1 {
            triangles.push([ids[0], ids[k], ids[k + 1]]);
        }
    }
    Ok(TriSurface {
        vertices,
        triangles,
    })
}

fn read_sections(bytes: &[u8], want: Dataset) -> Result<Sections, MeshError> {
    let mut c = Cursor::new(bytes);
    let first = c.next_line().ok_or_else(|| c.err("empty file"))?;
    let first = trim(first);
    if !first.to_ascii_lowercase().starts_with(b"# vtk datafile") {
        return Err(c.err(format!(
            "not a legacy VTK file: expected \"# vtk DataFile Version x.x\", found {}",
            show(first)
        )));
    }
    c.next_line()
        .ok_or_else(|| c.err("unexpected end of file: missing title line (file truncated?)"))?;
    let enc = c.next_nonblank_line().ok_or_else(|| {
        c.err("unexpected end of file: missing ASCII/BINARY line (file truncated?)")
    })?;
    match enc.to_ascii_uppercase().as_slice() {
        b"ASCII" => read_legacy_ascii(c, bytes.len(), want),
        b"BINARY" => {
            let start = bytes.len() - c.rest().len();
            read_legacy_binary(bytes, start, want)
        }
        _ => Err(c.err(format!("expected ASCII or BINARY, found {}", show(enc)))),
    }
}

fn keyword(c: &mut Cursor<'_>, what: &str) -> Result<Vec<u8>, MeshError> {
    Ok(c.expect_token(what)?.to_ascii_uppercase())
}

/// The body of a legacy ASCII file, after the `ASCII` line.
fn read_legacy_ascii(
    mut c: Cursor<'_>,
    file_len: usize,
    want: Dataset,
) -> Result<Sections, MeshError> {
    // Capacity hints are bounded by the file size so a bogus count cannot exhaust memory.
    let cap = |n: usize| n.min(file_len / 2);
    if keyword(&mut c, "DATASET")? != b"DATASET" {
        return Err(c.err("expected \"DATASET UNSTRUCTURED_GRID\""));
    }
    let kind = keyword(&mut c, "dataset type")?;
    check_dataset(&kind, want).map_err(|m| c.err(m))?;
    let mut out = Sections::default();
    let Sections {
        points,
        cells,
        types,
        ..
    } = &mut out;
    let mut poly_cells = Vec::new();

    while let Some(tok) = c.token() {
        let kw = tok.to_ascii_uppercase();
        let (section, is_poly) = section_keyword(&kw, want);
        match section {
            b"FIELD" => skip_field(&mut c)?,
            b"METADATA" => c.skip_past_blank_line(),
            b"POINTS" => {
                let n: usize = c.number("number of points")?;
                c.expect_token("points data type")?;
                let len = n.checked_mul(3).ok_or_else(|| c.err("too many points"))?;
                let mut v = Vec::with_capacity(cap(len));
                for i in 0..len {
                    let t = c.expect_token("point coordinates")?;
                    v.push(parse_num(t).ok_or_else(|| {
                        c.err(format!(
                            "invalid {} coordinate {} of point {}",
                            ["x", "y", "z"][i % 3],
                            show(t),
                            i / 3
                        ))
                    })?);
                }
                *points = Some(v);
            }
            b"CELLS" => {
                let a: usize = c.number("number of cells")?;
                let b: usize = c.number("cell list size")?;
                let is_v5 = c
                    .peek_token()
                    .is_some_and(|t| t.eq_ignore_ascii_case(b"OFFSETS"));
                let list = if is_v5 {
                    c.token();
                    c.expect_token("offsets data type")?;
                    let mut offsets = Vec::with_capacity(cap(a));
                    for _ in 0..a {
                        offsets.push(c.number::<usize>("cell offset")?);
                    }
                    if keyword(&mut c, "CONNECTIVITY")? != b"CONNECTIVITY" {
                        return Err(c.err("expected CONNECTIVITY after the cell offsets"));
                    }
                    c.expect_token("connectivity data type")?;
                    let mut conn = Vec::with_capacity(cap(b));
                    for _ in 0..b {
                        conn.push(c.number::<u64>("point index")?);
                    }
                    let bad = offsets.first().is_some_and(|&o| o != 0)
                        || offsets.windows(2).any(|w| w[0] > w[1])
                        || offsets.last().is_some_and(|&o| o != conn.len());
                    if bad {
                        return Err(c.err(
                            "cell offsets must start at 0, never decrease, and end at the \
                             connectivity length",
                        ));
                    }
                    (offsets, conn)
                } else {
                    let mut offsets = Vec::with_capacity(cap(a).saturating_add(1));
                    let mut conn = Vec::with_capacity(cap(b));
                    offsets.push(0);
                    let mut read = 0usize;
                    for i in 0..a {
                        let k: usize = c.number("number of points in a cell")?;
                        read = read.saturating_add(k).saturating_add(1);
                        if read > b {
                            return Err(c.err(format!(
                                "cell {i} overruns the CELLS size {b} given in the header"
                            )));
                        }
                        for _ in 0..k {
                            conn.push(c.number::<u64>("point index")?);
                        }
                        offsets.push(conn.len());
                    }
                    if read != b {
                        return Err(c.err(format!(
                            "CELLS header says {b} numbers, the cells use {read}"
                        )));
                    }
                    (offsets, conn)
                };
                if is_poly {
                    poly_cells.push((kw, list));
                } else {
                    *cells = Some(list);
                }
            }
            b"CELL_TYPES" => {
                let n: usize = c.number("number of cell types")?;
                let mut v = Vec::with_capacity(cap(n));
                for _ in 0..n {
                    v.push(c.number::<u32>("cell type")?);
                }
                *types = Some(v);
            }
            // Attribute data follows; nothing of it is needed.
            b"POINT_DATA" | b"CELL_DATA" => break,
            _ => {
                return Err(c.err(format!(
                    "unexpected keyword {} (expected POINTS, CELLS or CELL_TYPES)",
                    show(tok)
                )));
            }
        }
    }
    for (kw, (offsets, conn)) in poly_cells {
        out.add_poly(&kw, &offsets, &conn);
    }
    Ok(out)
}

/// Whether dataset type `kind` is the one wanted, else the message saying why not.
fn check_dataset(kind: &[u8], want: Dataset) -> Result<(), String> {
    match (want, kind) {
        (Dataset::Grid, b"UNSTRUCTURED_GRID") | (Dataset::Poly, b"POLYDATA") => Ok(()),
        (Dataset::Grid, _) => Err(format!(
            "unsupported VTK dataset type {} (only UNSTRUCTURED_GRID holds tetrahedra)",
            show(kind)
        )),
        (Dataset::Poly, _) => Err(format!(
            "VTK dataset type {} is not a surface (expected POLYDATA)",
            show(kind)
        )),
    }
}

/// Build the mesh from flat coordinates and cells as `(offsets, connectivity, types)`, cell `i`
/// being `connectivity[offsets[i]..offsets[i + 1]]`.
fn assemble(
    points: &[f64],
    offsets: &[usize],
    conn: &[u64],
    types: &[u32],
) -> Result<(TetMesh, Ignored), MeshError> {
    let ncells = offsets.len().saturating_sub(1);
    if types.len() != ncells {
        return Err(format_err(format!(
            "CELLS lists {ncells} cells but CELL_TYPES lists {}",
            types.len()
        )));
    }
    let mut out = Builder::default();
    out.add_points(points)?;
    for (ty, w) in types.iter().zip(offsets.windows(2)) {
        let verts = conn.get(w[0]..w[1]).ok_or_else(|| {
            format_err(format!(
                "cell {} has invalid offsets {}..{}",
                out.cells, w[0], w[1]
            ))
        })?;
        out.add_cell(*ty, verts, 0)?;
    }
    Ok(out.finish())
}

/// Byte-level reader for binary legacy files: ASCII keyword lines between big-endian blocks.
struct Bin<'a> {
    b: &'a [u8],
    pos: usize,
}

impl<'a> Bin<'a> {
    fn err(&self, at: usize, message: impl Into<String>) -> MeshError {
        MeshError::ParseBinary {
            file: nofile(),
            offset: at,
            message: message.into(),
        }
    }

    /// The next non-blank line's tokens (`None` at end of file).
    fn line(&mut self) -> Option<(usize, Vec<&'a [u8]>)> {
        loop {
            let rest = self.b.get(self.pos..).filter(|r| !r.is_empty())?;
            let len = rest
                .iter()
                .position(|&c| c == b'\n')
                .map_or(rest.len(), |i| i + 1);
            let at = self.pos;
            self.pos += len;
            let toks: Vec<&[u8]> = super::text::tokens(&rest[..len]).collect();
            if !toks.is_empty() {
                return Some((at, toks));
            }
        }
    }

    fn take(&mut self, n: usize, what: &str) -> Result<&'a [u8], MeshError> {
        let at = self.pos;
        let end = at
            .checked_add(n)
            .filter(|&e| e <= self.b.len())
            .ok_or_else(|| {
                self.err(
                at,
                format!(
                    "unexpected end of file in {what}: {n} bytes needed, {} left (file truncated?)",
                    self.b.len().saturating_sub(at)
                ),
            )
            })?;
        self.pos = end;
        Ok(&self.b[at..end])
    }

    /// `n` big-endian numbers of the VTK data type named `ty`, as f64 or as integers.
    fn numbers(&mut self, n: usize, ty: &[u8], what: &str) -> Result<Vec<Num>, MeshError> {
        let at = self.pos;
        let ty_l = ty.to_ascii_lowercase();
        let (size, kind) = match ty_l.as_slice() {
            b"float" => (4, 'f'),
            b"double" => (8, 'f'),
            b"char" | b"unsigned_char" | b"bit" => (1, 'u'),
            b"short" => (2, 'i'),
            b"unsigned_short" => (2, 'u'),
            b"int" | b"vtktypeint32" => (4, 'i'),
            b"unsigned_int" | b"vtktypeuint32" => (4, 'u'),
            b"long" | b"vtktypeint64" | b"vtkidtype" => (8, 'i'),
            b"unsigned_long" | b"vtktypeuint64" => (8, 'u'),
            _ => return Err(self.err(at, format!("unsupported data type {} for {what}", show(ty)))),
        };
        let bytes = self.take(n.saturating_mul(size), what)?;
        Ok(bytes
            .chunks_exact(size)
            .map(|c| {
                let mut u = 0u64;
                for &x in c {
                    u = (u << 8) | u64::from(x);
                }
                match (kind, size) {
                    ('f', 4) => Num::Float(f64::from(f32::from_bits(u as u32))),
                    ('f', _) => Num::Float(f64::from_bits(u)),
                    ('i', s) => {
                        // Sign-extend from `s` bytes.
                        let shift = 64 - 8 * s as u32;
                        Num::Int(((u << shift) as i64) >> shift)
                    }
                    _ => Num::UInt(u),
                }
            })
            .collect())
    }
}

impl Bin<'_> {
    /// `n` non-negative integers of type `ty`.
    fn indices(&mut self, n: usize, ty: &[u8], what: &str) -> Result<Vec<u64>, MeshError> {
        let at = self.pos;
        let v = self.numbers(n, ty, what)?;
        v.iter()
            .map(|x| {
                x.index()
                    .ok_or_else(|| self.err(at, format!("negative or non-integer value in {what}")))
            })
            .collect()
    }
}

/// A number read from a binary block.
enum Num {
    Float(f64),
    Int(i64),
    UInt(u64),
}

impl Num {
    fn index(&self) -> Option<u64> {
        match *self {
            Num::Int(v) => u64::try_from(v).ok(),
            Num::UInt(v) => Some(v),
            Num::Float(_) => None,
        }
    }
}

/// The body of a binary legacy file, from byte `start` (just after the `BINARY` line).
fn read_legacy_binary(bytes: &[u8], start: usize, want: Dataset) -> Result<Sections, MeshError> {
    let mut r = Bin {
        b: bytes,
        pos: start,
    };
    let parse_count =
        |r: &Bin<'_>, at: usize, tok: Option<&&[u8]>, what: &str| -> Result<usize, MeshError> {
            tok.and_then(|t| parse_num(t))
                .ok_or_else(|| r.err(at, format!("missing or invalid {what}")))
        };
    let (at, toks) = r
        .line()
        .ok_or_else(|| r.err(start, "unexpected end of file before DATASET"))?;
    let is = |t: Option<&&[u8]>, kw: &[u8]| t.is_some_and(|t| t.eq_ignore_ascii_case(kw));
    if !is(toks.first(), b"DATASET") {
        return Err(r.err(at, "expected \"DATASET\""));
    }
    let kind = toks
        .get(1)
        .map(|t| t.to_ascii_uppercase())
        .unwrap_or_default();
    check_dataset(&kind, want).map_err(|m| r.err(at, m))?;
    let mut out = Sections::default();
    let Sections {
        points,
        cells,
        types,
        ..
    } = &mut out;
    let mut poly_cells = Vec::new();
    while let Some((at, toks)) = r.line() {
        let kw = toks
            .first()
            .map(|t| t.to_ascii_uppercase())
            .unwrap_or_default();
        let (section, is_poly) = section_keyword(&kw, want);
        match section {
            b"FIELD" => {
                let arrays = parse_count(&r, at, toks.get(2), "number of field arrays")?;
                for _ in 0..arrays {
                    let (at, t) = r
                        .line()
                        .ok_or_else(|| r.err(r.pos, "unexpected end of file in FIELD"))?;
                    let comps = parse_count(&r, at, t.get(1), "number of components")?;
                    let tuples = parse_count(&r, at, t.get(2), "number of tuples")?;
                    let ty = t.get(3).copied().unwrap_or(b"");
                    r.numbers(comps.saturating_mul(tuples), ty, "field data")?;
                }
            }
            b"METADATA" => loop {
                // ASCII metadata up to a blank line.
                let rest = bytes.get(r.pos..).unwrap_or(&[]);
                let Some(i) = rest.iter().position(|&c| c == b'\n') else {
                    r.pos = bytes.len();
                    break;
                };
                let blank = trim(&rest[..i]).is_empty();
                r.pos += i + 1;
                if blank {
                    break;
                }
            },
            b"POINTS" => {
                let n = parse_count(&r, at, toks.get(1), "number of points")?;
                let ty = toks.get(2).copied().unwrap_or(b"");
                let v = r.numbers(n.saturating_mul(3), ty, "point coordinates")?;
                *points = Some(
                    v.iter()
                        .map(|x| match *x {
                            Num::Float(f) => f,
                            Num::Int(i) => i as f64,
                            Num::UInt(u) => u as f64,
                        })
                        .collect(),
                );
            }
            b"CELLS" => {
                let a = parse_count(&r, at, toks.get(1), "number of cells")?;
                let b = parse_count(&r, at, toks.get(2), "cell list size")?;
                let save = r.pos;
                match r.line() {
                    Some((at2, t)) if is(t.first(), b"OFFSETS") => {
                        let ty = t.get(1).copied().unwrap_or(b"");
                        let offsets = r.indices(a, ty, "cell offsets")?;
                        let (at3, t) = r.line().ok_or_else(|| {
                            r.err(r.pos, "unexpected end of file: missing CONNECTIVITY")
                        })?;
                        if !is(t.first(), b"CONNECTIVITY") {
                            return Err(r.err(at3, "expected CONNECTIVITY after the cell offsets"));
                        }
                        let ty = t.get(1).copied().unwrap_or(b"");
                        let conn = r.indices(b, ty, "cell connectivity")?;
                        let offsets: Vec<usize> = offsets
                            .iter()
                            .map(|&o| usize::try_from(o).unwrap_or(usize::MAX))
                            .collect();
                        let bad = offsets.first().is_some_and(|&o| o != 0)
                            || offsets.windows(2).any(|w| w[0] > w[1])
                            || offsets.last().is_some_and(|&o| o != conn.len());
                        if bad {
                            return Err(r.err(at2, "cell offsets must start at 0, never decrease, and end at the connectivity length"));
                        }
                        if is_poly {
                            poly_cells.push((kw, (offsets, conn)));
                        } else {
                            *cells = Some((offsets, conn));
                        }
                    }
                    _ => {
                        r.pos = save;
                        let flat = r.indices(b, b"int", "cells")?;
                        let mut offsets = vec![0usize];
                        let mut conn = Vec::with_capacity(flat.len());
                        let mut i = 0usize;
                        for c in 0..a {
                            let k = flat.get(i).copied().unwrap_or(0) as usize;
                            let verts = flat.get(i + 1..i.saturating_add(1).saturating_add(k)).ok_or_else(|| {
                                r.err(save, format!("cell {c} overruns the CELLS size {b} given in the header"))
                            })?;
                            conn.extend_from_slice(verts);
                            offsets.push(conn.len());
                            i += 1 + k;
                        }
                        if i != b {
                            return Err(r.err(
                                at,
                                format!("CELLS header says {b} numbers, the cells use {i}"),
                            ));
                        }
                        if is_poly {
                            poly_cells.push((kw, (offsets, conn)));
                        } else {
                            *cells = Some((offsets, conn));
                        }
                    }
                }
            }
            b"CELL_TYPES" => {
                let n = parse_count(&r, at, toks.get(1), "number of cell types")?;
                let v = r.indices(n, b"int", "cell types")?;
                *types = Some(
                    v.iter()
                        .map(|&t| u32::try_from(t).unwrap_or(u32::MAX))
                        .collect(),
                );
            }
            b"POINT_DATA" | b"CELL_DATA" => break,
            _ => {
                return Err(r.err(
                    at,
                    format!(
                        "unexpected keyword {} (expected POINTS, CELLS or CELL_TYPES)",
                        show(toks.first().copied().unwrap_or(b""))
                    ),
                ));
            }
        }
    }
    for (kw, (offsets, conn)) in poly_cells {
        out.add_poly(&kw, &offsets, &conn);
    }
    Ok(out)
}

/// Skip `FIELD name n` and its `n` arrays (`name components tuples type` then the values).
fn skip_field(c: &mut Cursor<'_>) -> Result<(), MeshError> {
    c.expect_token("field name")?;
    let arrays: usize = c.number("number of field arrays")?;
    for _ in 0..arrays {
        c.expect_token("field array name")?;
        let comps: usize = c.number("number of components")?;
        let tuples: usize = c.number("number of tuples")?;
        c.expect_token("field data type")?;
        for _ in 0..comps.saturating_mul(tuples) {
            c.expect_token("field data")?;
        }
    }
    Ok(())
}

/// The section an (upper-case) keyword opens, and whether it is a polydata cell list:
/// `VERTICES`, `LINES`, `POLYGONS` and `TRIANGLE_STRIPS` are read as `CELLS` when a polydata
/// file is wanted; any other keyword is itself.
fn section_keyword(kw: &[u8], want: Dataset) -> (&[u8], bool) {
    let poly = want == Dataset::Poly
        && matches!(
            kw,
            b"VERTICES" | b"LINES" | b"POLYGONS" | b"TRIANGLE_STRIPS"
        );
    (if poly { b"CELLS" } else { kw }, poly)
}

#[cfg(test)]
mod tests {
    use super::*;

    const TET_V4: &str = "# vtk DataFile Version 4.2\ntitle\nASCII\nDATASET UNSTRUCTURED_GRID\n\
        FIELD FieldData 1\nTIME 1 1 double\n0\n\
        POINTS 4 double\n0 0 0 1 0 0\n0 1 0 0 0 1\nMETADATA\nINFORMATION 0\n\n\
        CELLS 2 8\n2 0 1\n4 0 1 2 3\nCELL_TYPES 2\n3\n10\nCELL_DATA 2\nSCALARS a int\n";

    #[test]
    fn legacy_v4_with_field_metadata_and_lines() {
        let (m, ignored) = read_legacy(TET_V4.as_bytes()).unwrap();
        assert_eq!(m.nodes.len(), 4);
        assert_eq!(m.tets, vec![[0, 1, 2, 3]]);
        assert_eq!(ignored.to_string(), "1 VTK_LINE");
    }

    #[test]
    fn legacy_v51_offsets_connectivity() {
        let text = "# vtk DataFile Version 5.1\nt\nASCII\nDATASET UNSTRUCTURED_GRID\n\
            POINTS 4 float\n0 0 0 1 0 0 0 1 0 0 0 1\nCELLS 3 6\nOFFSETS vtktypeint64\n0 2 6\n\
            CONNECTIVITY vtktypeint64\n0 1 0 1 2 3\nCELL_TYPES 2\n3\n10\n";
        let (m, _) = read_legacy(text.as_bytes()).unwrap();
        assert_eq!(m.tets, vec![[0, 1, 2, 3]]);
    }

    #[test]
    fn legacy_errors_name_the_line() {
        let bad = TET_V4.replace("0 1 0 0 0 1", "0 1 0 0 zero 1");
        let e = read_legacy(bad.as_bytes()).unwrap_err().to_string();
        assert_eq!(e, "line 10: invalid y coordinate \"zero\" of point 3");
        let hex = TET_V4.replace("\n10\n", "\n12\n");
        let e = read_legacy(hex.as_bytes()).unwrap_err().to_string();
        assert!(
            e.contains("element 1 is of unsupported type VTK_HEXAHEDRON"),
            "{e}"
        );
    }
}
