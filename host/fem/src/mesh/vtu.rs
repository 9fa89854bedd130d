//! VTK XML unstructured grids (`.vtu`).
//!
//! A small dedicated reader (`vtkio` 0.6 cannot read compressed inline data, which is meshio's
//! default, nor meshio's 64-bit cell types). Supported: data arrays in `ascii`, inline `binary`
//! (base64) and raw `appended` format, uncompressed or zlib-compressed, either byte order,
//! 32- or 64-bit headers, any integer type for connectivity/offsets/types, several pieces.

use super::error::{MeshError, nofile};
use super::vtk::Builder;
use super::{Ignored, TetMesh};
use crate::surface::TriSurface;
use std::io::Read;

/// A problem located at a byte offset of the file (reported as a line, the XML being text).
struct At(usize, String);

type Res<T> = Result<T, At>;

/// Read a `.vtu` file.
pub(crate) fn read_vtu(bytes: &[u8]) -> Result<(TetMesh, Ignored), MeshError> {
    read(bytes, false)
        .map(Builder::finish)
        .map_err(|e| located(bytes, e))
}

/// Read a `.vtp` file (VTK XML `PolyData`): its points and polygons (`<Polys>`), split into
/// fans; vertices, lines and strips are ignored.
pub(crate) fn read_vtp(bytes: &[u8]) -> Result<TriSurface, MeshError> {
    let b = read(bytes, true).map_err(|e| located(bytes, e))?;
    let mut triangles = Vec::new();
    for p in &b.polygons {
        for k in 1..p.len().saturating_sub(1) {
            triangles.push([p[0], p[k], p[k + 1]]);
        }
    }
    for t in &triangles {
        if let Some(&v) = t.iter().find(|&&v| v >= b.nodes.len()) {
            return Err(MeshError::Format {
                file: nofile(),
                message: format!(
                    "a polygon refers to point {v}, but there are {} points",
                    b.nodes.len()
                ),
            });
        }
    }
    Ok(TriSurface {
        vertices: b.nodes,
        triangles,
    })
}

/// The byte offset of an error as a line.
fn located(bytes: &[u8], At(offset, message): At) -> MeshError {
    MeshError::Parse {
        file: nofile(),
        line: bytes
            .get(..offset)
            .map_or(0, |b| b.iter().filter(|&&c| c == b'\n').count())
            + 1,
        message,
    }
}

/// One XML tag.
struct Tag<'a> {
    name: &'a [u8],
    attrs: Vec<(&'a [u8], &'a [u8])>,
    /// `</name>`.
    closing: bool,
    /// `<name ... />`.
    empty: bool,
    /// Offset of `<`.
    start: usize,
    /// Offset just past `>`.
    end: usize,
}

impl Tag<'_> {
    fn attr(&self, name: &str) -> Option<&[u8]> {
        self.attrs
            .iter()
            .find(|(k, _)| *k == name.as_bytes())
            .map(|(_, v)| *v)
    }

    fn attr_str(&self, name: &str) -> Option<String> {
        self.attr(name)
            .map(|v| String::from_utf8_lossy(v).into_owned())
    }

    fn attr_num(&self, name: &str) -> Res<Option<u64>> {
        match self.attr(name) {
            None => Ok(None),
            Some(v) => std::str::from_utf8(v)
                .ok()
                .and_then(|s| s.trim().parse().ok())
                .map(Some)
                .ok_or_else(|| {
                    At(
                        self.start,
                        format!(
                            "invalid {name}=\"{}\" in <{}>",
                            String::from_utf8_lossy(v),
                            String::from_utf8_lossy(self.name)
                        ),
                    )
                }),
        }
    }
}

fn find(hay: &[u8], needle: &[u8], from: usize) -> Option<usize> {
    hay.get(from..)?
        .windows(needle.len())
        .position(|w| w == needle)
        .map(|i| i + from)
}

/// The next tag at or after `pos` in `xml`, skipping declarations, comments and text.
fn next_tag(xml: &[u8], mut pos: usize) -> Res<Option<Tag<'_>>> {
    loop {
        let Some(lt) = find(xml, b"<", pos) else {
            return Ok(None);
        };
        let rest = &xml[lt..];
        if rest.starts_with(b"<!--") {
            pos = find(xml, b"-->", lt).ok_or_else(|| At(lt, "unterminated comment".into()))? + 3;
            continue;
        }
        if rest.starts_with(b"<?") || rest.starts_with(b"<!") {
            pos = find(xml, b">", lt).ok_or_else(|| At(lt, "unterminated tag".into()))? + 1;
            continue;
        }
        let mut i = lt + 1;
        let closing = xml.get(i) == Some(&b'/');
        if closing {
            i += 1;
        }
        let name_start = i;
        while i < xml.len() && !xml[i].is_ascii_whitespace() && !matches!(xml[i], b'>' | b'/') {
            i += 1;
        }
        let name = &xml[name_start..i];
        let mut attrs = Vec::new();
        loop {
            while i < xml.len() && xml[i].is_ascii_whitespace() {
                i += 1;
            }
            match xml.get(i) {
                None => {
                    return Err(At(
                        lt,
                        "unexpected end of file inside a tag (file truncated?)".into(),
                    ));
                }
                Some(b'>') => {
                    return Ok(Some(Tag {
                        name,
                        attrs,
                        closing,
                        empty: false,
                        start: lt,
                        end: i + 1,
                    }));
                }
                Some(b'/') if xml.get(i + 1) == Some(&b'>') => {
                    return Ok(Some(Tag {
                        name,
                        attrs,
                        closing,
                        empty: true,
                        start: lt,
                        end: i + 2,
                    }));
                }
                Some(_) => {
                    let k0 = i;
                    while i < xml.len()
                        && !matches!(xml[i], b'=' | b'>' | b'/')
                        && !xml[i].is_ascii_whitespace()
                    {
                        i += 1;
                    }
                    let key = &xml[k0..i];
                    while i < xml.len() && xml[i].is_ascii_whitespace() {
                        i += 1;
                    }
                    if xml.get(i) != Some(&b'=') {
                        return Err(At(
                            lt,
                            format!("malformed attribute {:?}", String::from_utf8_lossy(key)),
                        ));
                    }
                    i += 1;
                    while i < xml.len() && xml[i].is_ascii_whitespace() {
                        i += 1;
                    }
                    let Some(&q) = xml.get(i).filter(|&&q| q == b'"' || q == b'\'') else {
                        return Err(At(lt, "attribute value without quotes".into()));
                    };
                    let v0 = i + 1;
                    let v1 = xml
                        .get(v0..)
                        .and_then(|r| r.iter().position(|&c| c == q))
                        .map(|p| p + v0)
                        .ok_or_else(|| {
                            At(lt, "unterminated attribute value (file truncated?)".into())
                        })?;
                    attrs.push((key, &xml[v0..v1]));
                    i = v1 + 1;
                }
            }
        }
    }
}

#[derive(Clone, Copy, PartialEq, Eq)]
enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    I64,
    U64,
    F32,
    F64,
}

impl Scalar {
    fn parse(s: &[u8]) -> Option<Scalar> {
        Some(match s {
            b"Int8" | b"Char" => Scalar::I8,
            b"UInt8" | b"UChar" => Scalar::U8,
            b"Int16" => Scalar::I16,
            b"UInt16" => Scalar::U16,
            b"Int32" => Scalar::I32,
            b"UInt32" => Scalar::U32,
            b"Int64" => Scalar::I64,
            b"UInt64" => Scalar::U64,
            b"Float32" => Scalar::F32,
            b"Float64" => Scalar::F64,
            _ => return None,
        })
    }

    fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::I64 | Scalar::U64 | Scalar::F64 => 8,
        }
    }

    fn is_float(self) -> bool {
        matches!(self, Scalar::F32 | Scalar::F64)
    }
}

/// File-wide encoding settings from `<VTKFile>`.
#[derive(Clone, Copy)]
struct Encoding {
    big_endian: bool,
    header64: bool,
    zlib: bool,
}

impl Encoding {
    fn header_size(self) -> usize {
        if self.header64 { 8 } else { 4 }
    }

    /// Decode one unsigned integer of `size` bytes.
    fn uint(self, b: &[u8]) -> u64 {
        let mut v = 0u64;
        if self.big_endian {
            for &x in b {
                v = (v << 8) | u64::from(x);
            }
        } else {
            for &x in b.iter().rev() {
                v = (v << 8) | u64::from(x);
            }
        }
        v
    }

    /// Decode a binary value of type `ty` as f64 (floats) or as an integer in f64/i128 form.
    fn value(self, ty: Scalar, b: &[u8]) -> Num {
        let mut buf = [0u8; 8];
        let n = ty.size();
        buf[..n].copy_from_slice(&b[..n]);
        if self.big_endian {
            buf[..n].reverse();
        }
        match ty {
            Scalar::I8 => Num::Int(i128::from(buf[0] as i8)),
            Scalar::U8 => Num::Int(i128::from(buf[0])),
            Scalar::I16 => Num::Int(i128::from(i16::from_le_bytes([buf[0], buf[1]]))),
            Scalar::U16 => Num::Int(i128::from(u16::from_le_bytes([buf[0], buf[1]]))),
            Scalar::I32 => Num::Int(i128::from(i32::from_le_bytes([
                buf[0], buf[1], buf[2], buf[3],
            ]))),
            Scalar::U32 => Num::Int(i128::from(u32::from_le_bytes([
                buf[0], buf[1], buf[2], buf[3],
            ]))),
            Scalar::I64 => Num::Int(i128::from(i64::from_le_bytes(buf))),
            Scalar::U64 => Num::Int(i128::from(u64::from_le_bytes(buf))),
            Scalar::F32 => Num::Float(f64::from(f32::from_le_bytes([
                buf[0], buf[1], buf[2], buf[3],
            ]))),
            Scalar::F64 => Num::Float(f64::from_le_bytes(buf)),
        }
    }
}

enum Num {
    Int(i128),
    Float(f64),
}

/// Decode standard base64, ignoring whitespace; `None` on invalid input.
fn base64(text: &[u8]) -> Option<Vec<u8>> {
    fn val(c: u8) -> Option<u32> {
        Some(match c {
            b'A'..=b'Z' => c - b'A',
            b'a'..=b'z' => c - b'a' + 26,
            b'0'..=b'9' => c - b'0' + 52,
            b'+' => 62,
            b'/' => 63,
            _ => return None,
        } as u32)
    }
    let mut out = Vec::with_capacity(text.len() / 4 * 3);
    let mut acc = 0u32;
    let mut bits = 0u32;
    let mut padding = false;
    for &c in text {
        if c.is_ascii_whitespace() {
            continue;
        }
        if c == b'=' {
            padding = true;
            continue;
        }
        if padding {
            return None;
        }
        acc = (acc << 6) | val(c)?;
        bits += 6;
        if bits >= 8 {
            bits -= 8;
            out.push((acc >> bits) as u8);
            acc &= (1 << bits) - 1;
        }
    }
    Some(out)
}

/// Number of base64 characters that encode `n` bytes.
fn b64_len(n: usize) -> usize {
    n.div_ceil(3) * 4
}

/// Decompress the zlib blocks of one array given its decoded header and block bytes.
fn inflate(enc: Encoding, header: &[u8], blocks: &[u8], at: usize) -> Res<Vec<u8>> {
    let h = enc.header_size();
    let word = |i: usize| header.get(i * h..(i + 1) * h).map(|b| enc.uint(b) as usize);
    let bad = |what: &str| At(at, format!("corrupt compressed data array ({what})"));
    let nb = word(0).ok_or_else(|| bad("short header"))?;
    let nu = word(1).ok_or_else(|| bad("short header"))?;
    let np = word(2).ok_or_else(|| bad("short header"))?;
    let mut out = Vec::new();
    let mut pos = 0usize;
    for i in 0..nb {
        let nc = word(3 + i).ok_or_else(|| bad("short header"))?;
        let block = blocks
            .get(pos..pos.saturating_add(nc))
            .ok_or_else(|| bad("block runs past the data (file truncated?)"))?;
        pos += nc;
        let want = if i + 1 == nb && np != 0 { np } else { nu };
        let before = out.len();
        flate2::read::ZlibDecoder::new(block)
            .take(want as u64)
            .read_to_end(&mut out)
            .map_err(|e| At(at, format!("corrupt zlib block: {e}")))?;
        if out.len() - before != want {
            return Err(bad("block decompresses to the wrong size"));
        }
    }
    Ok(out)
}

/// A `<DataArray>` decoded to numbers.
fn decode_array(
    tag: &Tag<'_>,
    content: &[u8],
    enc: Encoding,
    appended: Option<&[u8]>,
) -> Res<Vec<Num>> {
    let at = tag.start;
    let ty = tag.attr("type").and_then(Scalar::parse).ok_or_else(|| {
        At(
            at,
            format!(
                "missing or unsupported DataArray type {:?}",
                tag.attr_str("type").unwrap_or_default()
            ),
        )
    })?;
    let format = tag.attr("format").unwrap_or(b"ascii");
    let raw: Vec<u8> = match format {
        b"ascii" => {
            return content
                .split(|c| c.is_ascii_whitespace())
                .filter(|t| !t.is_empty())
                .map(|t| {
                    let s = std::str::from_utf8(t).ok();
                    let v = if ty.is_float() {
                        s.and_then(|s| s.parse::<f64>().ok()).map(Num::Float)
                    } else {
                        s.and_then(|s| s.parse::<i128>().ok()).map(Num::Int)
                    };
                    v.ok_or_else(|| {
                        At(
                            tag.end + (t.as_ptr() as usize - content.as_ptr() as usize),
                            format!(
                                "invalid number {:?} in a data array",
                                String::from_utf8_lossy(t)
                            ),
                        )
                    })
                })
                .collect();
        }
        b"binary" => {
            let text: Vec<u8> = content
                .iter()
                .copied()
                .filter(|c| !c.is_ascii_whitespace())
                .collect();
            let h = enc.header_size();
            let bad = || At(at, "invalid base64 data in a binary data array".into());
            if enc.zlib {
                // Header [nb][nu][np][nc_1..nc_nb] and blocks are base64-encoded separately.
                let first = base64(text.get(..b64_len(h)).ok_or_else(bad)?).ok_or_else(bad)?;
                let nb = first
                    .get(..h)
                    .map(|b| enc.uint(b) as usize)
                    .ok_or_else(bad)?;
                let hlen = b64_len(nb.saturating_add(3).saturating_mul(h));
                let header = base64(text.get(..hlen).ok_or_else(bad)?).ok_or_else(bad)?;
                let blocks = base64(text.get(hlen..).ok_or_else(bad)?).ok_or_else(bad)?;
                inflate(enc, &header, &blocks, at)?
            } else {
                let all = base64(&text).ok_or_else(bad)?;
                let n = all.get(..h).map(|b| enc.uint(b) as usize).ok_or_else(bad)?;
                all.get(h..h.saturating_add(n))
                    .ok_or_else(|| At(at, "binary data array shorter than its header says".into()))?
                    .to_vec()
            }
        }
        b"appended" => {
            let data = appended
                .ok_or_else(|| At(at, "appended data array but no raw <AppendedData>".into()))?;
            let off = tag.attr_num("offset")?.unwrap_or(0) as usize;
            let h = enc.header_size();
            let short = || {
                At(
                    at,
                    "appended data array runs past the end of the file (file truncated?)".into(),
                )
            };
            let d = data.get(off..).ok_or_else(short)?;
            if enc.zlib {
                let nb = d.get(..h).map(|b| enc.uint(b) as usize).ok_or_else(short)?;
                let hl = nb.saturating_add(3).saturating_mul(h);
                let header = d.get(..hl).ok_or_else(short)?;
                inflate(enc, header, d.get(hl..).ok_or_else(short)?, at)?
            } else {
                let n = d.get(..h).map(|b| enc.uint(b) as usize).ok_or_else(short)?;
                d.get(h..h.saturating_add(n)).ok_or_else(short)?.to_vec()
            }
        }
        other => {
            return Err(At(
                at,
                format!(
                    "unsupported DataArray format {:?}",
                    String::from_utf8_lossy(other)
                ),
            ));
        }
    };
    let size = ty.size();
    if !raw.len().is_multiple_of(size) {
        return Err(At(
            at,
            "binary data array length is not a multiple of its type size".into(),
        ));
    }
    Ok(raw.chunks_exact(size).map(|b| enc.value(ty, b)).collect())
}

/// The arrays of one `<Piece>`.
#[derive(Default)]
struct PieceArrays {
    points: Option<Vec<Num>>,
    connectivity: Option<Vec<Num>>,
    offsets: Option<Vec<Num>>,
    types: Option<Vec<Num>>,
    num_points: u64,
    num_cells: u64,
    start: usize,
}

fn int(n: &Num, at: usize, what: &str) -> Res<u64> {
    match *n {
        Num::Int(v) => u64::try_from(v).map_err(|_| At(at, format!("negative {what} {v}"))),
        Num::Float(v) => Err(At(at, format!("non-integer {what} {v}"))),
    }
}

fn finish_piece(p: PieceArrays, out: &mut Builder, poly: bool) -> Res<()> {
    let at = p.start;
    let missing = |what: &str| At(at, format!("piece without {what} data array"));
    let points = p.points.ok_or_else(|| missing("a Points"))?;
    let flat: Vec<f64> = points
        .iter()
        .map(|n| match *n {
            Num::Float(v) => v,
            Num::Int(v) => v as f64,
        })
        .collect();
    if flat.len() as u64 != p.num_points.saturating_mul(3) {
        return Err(At(
            at,
            format!(
                "{} point coordinates for NumberOfPoints=\"{}\"",
                flat.len(),
                p.num_points
            ),
        ));
    }
    let point_offset = out.nodes.len();
    out.add_points(&flat).map_err(|e| At(at, e.to_string()))?;
    if p.num_cells == 0 {
        return Ok(());
    }
    let conn = p.connectivity.ok_or_else(|| missing("a connectivity"))?;
    let offsets = p.offsets.ok_or_else(|| missing("an offsets"))?;
    // A PolyData piece's `<Polys>` are polygons, without a types array.
    let types = match p.types {
        Some(t) => t,
        None if poly => (0..offsets.len()).map(|_| Num::Int(VTK_POLYGON)).collect(),
        None => return Err(missing("a types")),
    };
    if offsets.len() as u64 != p.num_cells || types.len() as u64 != p.num_cells {
        return Err(At(
            at,
            format!(
                "NumberOfCells=\"{}\" but {} offsets and {} types",
                p.num_cells,
                offsets.len(),
                types.len()
            ),
        ));
    }
    let conn: Vec<u64> = conn
        .iter()
        .map(|n| int(n, at, "point index"))
        .collect::<Res<_>>()?;
    let mut start = 0usize;
    for (o, t) in offsets.iter().zip(&types) {
        let end = int(o, at, "cell offset")? as usize;
        let ty = u32::try_from(int(t, at, "cell type")?).unwrap_or(u32::MAX);
        let verts = conn.get(start..end).ok_or_else(|| {
            At(
                at,
                format!("cell offsets {start}..{end} outside the connectivity array"),
            )
        })?;
        out.add_cell(ty, verts, point_offset)
            .map_err(|e| At(at, e.to_string()))?;
        start = end;
    }
    Ok(())
}

/// VTK cell type of a polygon.
const VTK_POLYGON: i128 = 7;

/// The points and cells of a `.vtu` (`poly` false) or `.vtp` file (`poly`: the `<Polys>`).
fn read(bytes: &[u8], poly: bool) -> Res<Builder> {
    let (root_type, cells_section, count_attr): (&[u8], &[u8], &str) = if poly {
        (b"PolyData", b"Polys", "NumberOfPolys")
    } else {
        (b"UnstructuredGrid", b"Cells", "NumberOfCells")
    };
    // Raw appended data is binary and may contain '<': cut it off before scanning tags.
    let (xml, appended) = match find(bytes, b"<AppendedData", 0) {
        None => (bytes, None),
        Some(a) => {
            let tag =
                next_tag(bytes, a)?.ok_or_else(|| At(a, "truncated <AppendedData>".into()))?;
            if tag.attr("encoding") != Some(b"raw") {
                return Err(At(
                    a,
                    "only encoding=\"raw\" appended data is supported".into(),
                ));
            }
            let underscore = find(bytes, b"_", tag.end).ok_or_else(|| {
                At(
                    a,
                    "appended data without the '_' marker (file truncated?)".into(),
                )
            })?;
            (&bytes[..a], Some(&bytes[underscore + 1..]))
        }
    };
    let mut enc = Encoding {
        big_endian: false,
        header64: false,
        zlib: false,
    };
    let mut out = Builder::default();
    let mut piece: Option<PieceArrays> = None;
    let mut section: Option<&[u8]> = None;
    let mut seen_root = false;
    let mut pos = 0usize;
    while let Some(tag) = next_tag(xml, pos)? {
        pos = tag.end;
        match (tag.name, tag.closing) {
            (b"VTKFile", false) => {
                seen_root = true;
                if tag.attr("type") != Some(root_type) {
                    return Err(At(
                        tag.start,
                        format!(
                            "VTK XML file of type {:?}; expected {}",
                            tag.attr_str("type").unwrap_or_default(),
                            if poly {
                                "PolyData (a surface)"
                            } else {
                                "UnstructuredGrid (only it holds tetrahedra)"
                            }
                        ),
                    ));
                }
                enc.big_endian = tag.attr("byte_order") == Some(b"BigEndian");
                enc.header64 = tag.attr("header_type") == Some(b"UInt64");
                enc.zlib = match tag.attr("compressor") {
                    None | Some(b"") => false,
                    Some(b"vtkZLibDataCompressor") => true,
                    Some(other) => {
                        return Err(At(
                            tag.start,
                            format!(
                                "unsupported compressor {:?} (only vtkZLibDataCompressor)",
                                String::from_utf8_lossy(other)
                            ),
                        ));
                    }
                };
            }
            (b"Piece", false) => {
                piece = Some(PieceArrays {
                    num_points: tag.attr_num("NumberOfPoints")?.unwrap_or(0),
                    num_cells: tag.attr_num(count_attr)?.unwrap_or(0),
                    start: tag.start,
                    ..Default::default()
                });
            }
            (b"Piece", true) => {
                let p = piece
                    .take()
                    .ok_or_else(|| At(tag.start, "</Piece> without <Piece>".into()))?;
                finish_piece(p, &mut out, poly)?;
            }
            (
                b"Points" | b"Cells" | b"Polys" | b"Verts" | b"Lines" | b"Strips" | b"PointData"
                | b"CellData" | b"FieldData",
                false,
            ) if !tag.empty => {
                section = Some(tag.name);
            }
            (
                b"Points" | b"Cells" | b"Polys" | b"Verts" | b"Lines" | b"Strips" | b"PointData"
                | b"CellData" | b"FieldData",
                true,
            ) => section = None,
            (b"DataArray", false) => {
                let content_end = if tag.empty {
                    tag.end
                } else {
                    find(xml, b"</DataArray", tag.end).ok_or_else(|| {
                        At(
                            tag.start,
                            "unterminated <DataArray> (file truncated?)".into(),
                        )
                    })?
                };
                let content = &xml[tag.end..content_end];
                pos = content_end;
                let (Some(p), Some(sec)) = (piece.as_mut(), section) else {
                    continue;
                };
                let slot = match (sec, tag.attr("Name")) {
                    (b"Points", _) if p.points.is_none() => &mut p.points,
                    (s, Some(b"connectivity")) if s == cells_section => &mut p.connectivity,
                    (s, Some(b"offsets")) if s == cells_section => &mut p.offsets,
                    (s, Some(b"types")) if s == cells_section => &mut p.types,
                    _ => continue,
                };
                *slot = Some(decode_array(&tag, content, enc, appended)?);
            }
            _ => {}
        }
    }
    if !seen_root {
        return Err(At(0, "not a VTK XML file (no <VTKFile> element)".into()));
    }
    if piece.is_some() {
        return Err(At(
            xml.len(),
            "unexpected end of file inside <Piece> (file truncated?)".into(),
        ));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base64_decodes() {
        assert_eq!(base64(b"aGVsbG8=").unwrap(), b"hello");
        assert_eq!(base64(b"aGVs\nbG8h").unwrap(), b"hello!");
        assert!(base64(b"a=b").is_none());
        assert!(base64(b"a*").is_none());
    }

    #[test]
    fn ascii_vtu() {
        let text = br#"<?xml version="1.0"?>
<VTKFile type="UnstructuredGrid" version="0.1">
<!-- comment with <tags> -->
<UnstructuredGrid><Piece NumberOfPoints="4" NumberOfCells="2">
<Points><DataArray type="Float32" NumberOfComponents="3" format="ascii">
0 0 0 1 0 0 0 1 0 0 0 1</DataArray></Points>
<Cells>
<DataArray type="Int32" Name="connectivity" format="ascii">0 1 2 0 1 2 3</DataArray>
<DataArray type="Int32" Name="offsets" format="ascii">3 7</DataArray>
<DataArray type="UInt8" Name="types" format="ascii">5 10</DataArray>
</Cells></Piece></UnstructuredGrid></VTKFile>"#;
        let (m, _) = read_vtu(text).unwrap();
        assert_eq!(m.nodes.len(), 4);
        assert_eq!(m.tets, vec![[0, 1, 2, 3]]);
        let bad = String::from_utf8_lossy(text).replace("0 1 2 3<", "0 1 x 3<");
        let e = read_vtu(bad.as_bytes()).unwrap_err().to_string();
        assert_eq!(e, "line 8: invalid number \"x\" in a data array");
    }
}
