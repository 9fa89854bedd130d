//! Gmsh MSH files: versions 1 and 2 ASCII (hand parser), version 4.1 ASCII and binary (via
//! `mshio`), and a minimal version 4.1 ASCII writer.

use super::error::{MeshError, nofile};
use super::text::{Cursor, parse_num, show, tokens, trim};
use super::{Ignored, TetMesh};
use std::borrow::Cow;
use std::cell::Cell;
use std::collections::HashMap;
use std::collections::hash_map::Entry;
use std::io::{self, Write};
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::sync::Once;

/// Gmsh element type number of the 4-node tetrahedron.
const GMSH_TET4: i64 = 4;

/// Dimension and human-readable name of a Gmsh element type, `None` if unknown.
pub(crate) fn element_kind(ty: i64) -> Option<(u8, Cow<'static, str>)> {
    let fixed = |dim: u8, name: &'static str| Some((dim, Cow::Borrowed(name)));
    let family = |dim: u8, family: &str| {
        Some((
            dim,
            Cow::Owned(format!("{family} (Gmsh element type {ty})")),
        ))
    };
    match ty {
        1 => fixed(1, "2-node line"),
        2 => fixed(2, "3-node triangle"),
        3 => fixed(2, "4-node quadrangle"),
        4 => fixed(3, "4-node tetrahedron"),
        5 => fixed(3, "8-node hexahedron"),
        6 => fixed(3, "6-node prism"),
        7 => fixed(3, "5-node pyramid"),
        8 => fixed(1, "3-node line"),
        9 => fixed(2, "6-node triangle"),
        10 => fixed(2, "9-node quadrangle"),
        11 => fixed(3, "10-node tetrahedron"),
        12 => fixed(3, "27-node hexahedron"),
        13 => fixed(3, "18-node prism"),
        14 => fixed(3, "14-node pyramid"),
        15 => fixed(0, "point"),
        16 => fixed(2, "8-node quadrangle"),
        17 => fixed(3, "20-node hexahedron"),
        18 => fixed(3, "15-node prism"),
        19 => fixed(3, "13-node pyramid"),
        20..=25 | 42..=46 | 52..=56 | 68 | 85 | 135 | 138 | 140 => family(2, "high-order triangle"),
        26..=28 | 62..=67 | 70 | 84 | 134 => family(1, "line"),
        29..=33 | 71..=75 | 79..=83 | 87 | 136 | 137 | 139 => family(3, "high-order tetrahedron"),
        34 | 69 => family(2, "polygon"),
        35 => family(3, "polyhedron"),
        36..=41 | 47..=51 | 57..=61 | 86 => family(2, "high-order quadrangle"),
        88 | 92..=105 => family(3, "hexahedron"),
        89..=91 | 106..=117 => family(3, "prism"),
        118..=132 => family(3, "pyramid"),
        133 => family(0, "point"),
        _ => None,
    }
}

/// Read a Gmsh MSH file of any supported version; elements of dimension < 3 are counted in the
/// returned [`Ignored`].
pub(crate) fn read_msh(bytes: &[u8]) -> Result<(TetMesh, Ignored), MeshError> {
    let Some(header) = read_header(bytes)? else {
        return read_msh_legacy(bytes, Version::One);
    };
    let version_num: Option<f64> = parse_num(header.version.as_bytes());
    match version_num {
        Some(v) if (2.0..3.0).contains(&v) => {
            if header.file_type != 0 {
                return Err(MeshError::UnsupportedVersion {
                    file: nofile(),
                    version: format!("{} binary", header.version),
                });
            }
            read_msh_legacy(bytes, Version::Two)
        }
        _ if header.version == "4.1" => read_msh41(bytes, &header),
        _ => Err(MeshError::UnsupportedVersion {
            file: nofile(),
            version: header.version,
        }),
    }
}

/// The `$MeshFormat` line.
struct Header {
    version: String,
    file_type: u32,
    data_size: u32,
    /// Line number of the version line.
    line: usize,
}

/// The `$MeshFormat` header, or `None` for a version 1 file (which starts with `$NOD`).
fn read_header(bytes: &[u8]) -> Result<Option<Header>, MeshError> {
    let mut c = Cursor::new(bytes);
    let first = c.next_nonblank_line().ok_or_else(|| c.err("empty file"))?;
    if first == b"$NOD" || first == b"$NOE" {
        return Ok(None);
    }
    if first != b"$MeshFormat" {
        return Err(c.err(format!(
            "expected \"$MeshFormat\" (versions 2 and 4.1) or \"$NOD\" (version 1) at the start \
             of a Gmsh MSH file, found {}",
            show(first)
        )));
    }
    let line = c
        .next_nonblank_line()
        .ok_or_else(|| c.err("unexpected end of file in $MeshFormat (file truncated?)"))?;
    let mut t = tokens(line);
    let (Some(v), Some(ft), Some(ds)) = (t.next(), t.next(), t.next()) else {
        return Err(c.err(format!(
            "expected \"version file-type data-size\" in $MeshFormat, found {}",
            show(line)
        )));
    };
    let version = String::from_utf8_lossy(v).into_owned();
    if parse_num::<f64>(v).is_none() {
        return Err(c.err(format!("invalid MSH version {}", show(v))));
    }
    let file_type = parse_num(ft).filter(|&x: &u32| x <= 1).ok_or_else(|| {
        c.err(format!(
            "invalid MSH file type {} (expected 0 or 1)",
            show(ft)
        ))
    })?;
    let data_size = parse_num(ds)
        .filter(|&x: &u32| (1..=16).contains(&x))
        .ok_or_else(|| c.err(format!("invalid MSH data size {}", show(ds))))?;
    Ok(Some(Header {
        version,
        file_type,
        data_size,
        line: c.line(),
    }))
}

/// The two line-oriented ASCII versions the hand parser reads.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Version {
    /// `$NOD`/`$ENDNOD`, `$ELM`/`$ENDELM`; an element line is `number type physical elementary
    /// number-of-nodes nodes...`.
    One,
    /// `$MeshFormat`, `$Nodes`, `$Elements`; an element line is `number type number-of-tags
    /// tags... nodes...`.
    Two,
}

/// MSH version 1 or 2 ASCII: the node and element sections (`$Nodes`/`$Elements`, or version
/// 1's `$NOD`/`$ELM`); other sections are skipped. Node numbers may be any (sparse, permuted).
fn read_msh_legacy(bytes: &[u8], version: Version) -> Result<(TetMesh, Ignored), MeshError> {
    let mut c = Cursor::new(bytes);
    let mut nodes: Vec<[f64; 3]> = Vec::new();
    let mut tag_to_id: HashMap<u64, usize> = HashMap::new();
    let mut tets: Vec<[usize; 4]> = Vec::new();
    let mut ignored = Ignored::default();
    let (nodes_end, elements_end): (&[u8], &[u8]) = match version {
        Version::One => (b"$ENDNOD", b"$ENDELM"),
        Version::Two => (b"$EndNodes", b"$EndElements"),
    };
    let mut seen_nodes = false;
    let mut seen_elements = false;
    // Capacity hint bounded by the file size, so a bogus count cannot exhaust memory.
    let cap = |n: usize, min_bytes_per_item: usize| n.min(bytes.len() / min_bytes_per_item);

    while let Some(line) = c.next_nonblank_line() {
        let Some(name) = line.strip_prefix(b"$") else {
            return Err(c.err(format!(
                "expected a section header such as \"$Nodes\", found {}",
                show(line)
            )));
        };
        let section_line = c.line();
        match (version, name) {
            (Version::Two, b"MeshFormat") => {
                // Already checked by `read_header`; skip its content.
                c.next_nonblank_line();
                expect_end(&mut c, b"$EndMeshFormat")?;
            }
            (Version::Two, b"Nodes") | (Version::One, b"NOD" | b"NOE") => {
                if seen_nodes {
                    return Err(c.err("second $Nodes section (only one is supported)"));
                }
                seen_nodes = true;
                let count_line = c.next_nonblank_line().ok_or_else(|| {
                    c.err("unexpected end of file after $Nodes (file truncated?)")
                })?;
                let n: usize = parse_num(count_line).ok_or_else(|| {
                    c.err(format!("invalid number of nodes {}", show(count_line)))
                })?;
                nodes.reserve(cap(n, 8));
                tag_to_id.reserve(cap(n, 8));
                for i in 0..n {
                    let l = c.next_line().ok_or_else(|| {
                        c.err(format!(
                            "unexpected end of file in $Nodes: got {i} of {n} nodes (file truncated?)"
                        ))
                    })?;
                    let toks: Vec<&[u8]> = tokens(l).collect();
                    let [tag, x, y, z] = toks[..] else {
                        return Err(c.err(format!(
                            "expected \"node-tag x y z\" for node {} of {n}, found {}",
                            i + 1,
                            show(trim(l))
                        )));
                    };
                    let tag: u64 = parse_num(tag)
                        .ok_or_else(|| c.err(format!("invalid node tag {}", show(tag))))?;
                    let mut p = [0.0; 3];
                    for (k, (tok, axis)) in [(x, "x"), (y, "y"), (z, "z")].into_iter().enumerate() {
                        p[k] = parse_num(tok).ok_or_else(|| {
                            c.err(format!(
                                "invalid {axis} coordinate {} of node tag {tag}",
                                show(tok)
                            ))
                        })?;
                    }
                    match tag_to_id.entry(tag) {
                        Entry::Occupied(_) => {
                            return Err(c.err(format!("node tag {tag} is defined twice")));
                        }
                        Entry::Vacant(v) => {
                            v.insert(nodes.len());
                        }
                    }
                    nodes.push(p);
                }
                expect_end(&mut c, nodes_end)?;
            }
            (Version::Two, b"Elements") | (Version::One, b"ELM") => {
                if !seen_nodes {
                    return Err(c.err("$Elements section before $Nodes"));
                }
                if seen_elements {
                    return Err(c.err("second $Elements section (only one is supported)"));
                }
                seen_elements = true;
                let count_line = c.next_nonblank_line().ok_or_else(|| {
                    c.err("unexpected end of file after $Elements (file truncated?)")
                })?;
                let m: usize = parse_num(count_line).ok_or_else(|| {
                    c.err(format!("invalid number of elements {}", show(count_line)))
                })?;
                tets.reserve(cap(m, 16));
                for i in 0..m {
                    let l = c.next_line().ok_or_else(|| {
                        c.err(format!(
                            "unexpected end of file in $Elements: got {i} of {m} elements (file truncated?)"
                        ))
                    })?;
                    read_element(&c, l, version, &tag_to_id, &mut tets, &mut ignored)?;
                }
                expect_end(&mut c, elements_end)?;
            }
            _ => {
                // Skip an unknown section up to its matching end tag.
                let mut end = match version {
                    Version::One => b"$END".to_vec(),
                    Version::Two => b"$End".to_vec(),
                };
                end.extend_from_slice(name);
                loop {
                    let Some(l) = c.next_line() else {
                        return Err(MeshError::Parse {
                            file: nofile(),
                            line: section_line,
                            message: format!(
                                "section {} is not closed by {} (file truncated?)",
                                show(line),
                                show(&end)
                            ),
                        });
                    };
                    if trim(l) == end.as_slice() {
                        break;
                    }
                }
            }
        }
    }
    if !seen_nodes {
        return Err(c.err(match version {
            Version::One => "no $NOD section",
            Version::Two => "no $Nodes section",
        }));
    }
    Ok((TetMesh { nodes, tets }, ignored))
}

/// One line of an element section: `elm-number elm-type number-of-tags <tags> node-number-list`
/// (version 2) or `elm-number elm-type reg-phys reg-elem number-of-nodes node-number-list`
/// (version 1). Elements of dimension < 3 are counted in `ignored`.
fn read_element(
    c: &Cursor<'_>,
    line: &[u8],
    version: Version,
    tag_to_id: &HashMap<u64, usize>,
    tets: &mut Vec<[usize; 4]>,
    ignored: &mut Ignored,
) -> Result<(), MeshError> {
    let toks: Vec<&[u8]> = tokens(line).collect();
    let int = |i: usize, what: &str| -> Result<u64, MeshError> {
        let tok = toks.get(i).ok_or_else(|| {
            c.err(format!(
                "element line ends early, expected {what}: {}",
                show(trim(line))
            ))
        })?;
        parse_num(tok).ok_or_else(|| c.err(format!("invalid {what} {}", show(tok))))
    };
    let tag = int(0, "element tag")?;
    let ty = int(1, "element type")?;
    let (first_node, listed) = match version {
        Version::Two => {
            let ntags = usize::try_from(int(2, "number of element tags")?).unwrap_or(usize::MAX);
            (ntags.saturating_add(3), format!("{ntags} tags and 4 nodes"))
        }
        Version::One => {
            let n = int(4, "number of nodes")?;
            if n != 4 && ty == GMSH_TET4 as u64 {
                return Err(c.err(format!(
                    "tetrahedron (element number {tag}) declares {n} nodes (expected 4)"
                )));
            }
            (5, "2 region numbers, a node count and 4 nodes".to_string())
        }
    };
    let Some((dim, kind)) = i64::try_from(ty).ok().and_then(element_kind) else {
        return Err(MeshError::UnsupportedElement {
            file: nofile(),
            element: tag,
            kind: format!("element of unknown Gmsh type {ty}"),
        });
    };
    if dim < 3 {
        ignored.add(&kind);
        return Ok(());
    }
    if ty != GMSH_TET4 as u64 {
        return Err(MeshError::UnsupportedElement {
            file: nofile(),
            element: tag,
            kind: kind.into_owned(),
        });
    }
    if toks.len() != first_node.saturating_add(4) {
        return Err(c.err(format!(
            "tetrahedron (element tag {tag}) should list {listed}, found {} numbers",
            toks.len()
        )));
    }
    let mut tet = [0usize; 4];
    for (k, slot) in tet.iter_mut().enumerate() {
        let node_tag = int(first_node + k, "node tag")?;
        *slot = *tag_to_id.get(&node_tag).ok_or(MeshError::UnknownNodeTag {
            file: nofile(),
            element: tag,
            node_tag,
        })?;
    }
    tets.push(tet);
    Ok(())
}

fn expect_end(c: &mut Cursor<'_>, end: &[u8]) -> Result<(), MeshError> {
    match c.next_nonblank_line() {
        Some(l) if l == end => Ok(()),
        Some(l) => Err(c.err(format!("expected {}, found {}", show(end), show(l)))),
        None => Err(c.err(format!(
            "unexpected end of file, expected {} (file truncated?)",
            show(end)
        ))),
    }
}

/// MSH 4.1, ASCII or binary, through `mshio`.
fn read_msh41(bytes: &[u8], header: &Header) -> Result<(TetMesh, Ignored), MeshError> {
    let binary = header.file_type == 1;
    if binary && !matches!(header.data_size, 4 | 8) {
        return Err(MeshError::Parse {
            file: nofile(),
            line: header.line,
            message: format!(
                "unsupported data size {} in $MeshFormat (expected 8)",
                header.data_size
            ),
        });
    }
    // `mshio` has a few `unwrap`s and unchecked subtractions on malformed input; a panic there
    // must not take the caller down, nor print a panic message before the clean error.
    let parsed = catch_quietly(|| {
        mshio::parse_msh_bytes(bytes).map_err(|e| convert_mshio_error(&e, bytes, binary))
    });
    let tags = || node_tags_41(bytes, binary, header.data_size as usize);
    let no_nodes = || MeshError::Format {
        file: nofile(),
        message: "$Nodes: the mesh has no nodes".into(),
    };
    let msh = match parsed {
        // `mshio` calls an empty node section a reserved tag 0; say what it is.
        Ok(Err(_)) if tags().is_ok_and(|t| t.is_empty()) => return Err(no_nodes()),
        // Likewise an empty element section.
        Ok(Err(_)) if !binary && first_count(bytes, b"\n$Elements") == Some(0) => {
            return Err(MeshError::Format {
                file: nofile(),
                message: "$Elements: the mesh has no elements (no tetrahedra)".into(),
            });
        }
        Ok(r) => r?,
        Err(_) => {
            return Err(MeshError::Format {
                file: nofile(),
                message: "malformed MSH 4.1 file (the mshio parser gave up)".into(),
            });
        }
    };
    let tags = tags()?;
    if tags.is_empty() {
        return Err(no_nodes());
    }
    msh41_to_mesh(&msh, &tags)
}

/// The bytes after the line that opens `section` (e.g. `b"\n$Nodes"`), if the file has it.
fn section_body<'b>(bytes: &'b [u8], section: &[u8]) -> Option<&'b [u8]> {
    let at = bytes.windows(section.len()).position(|w| w == section)? + section.len();
    let rest = bytes.get(at..)?;
    rest.iter()
        .position(|&b| b == b'\n')
        .and_then(|i| rest.get(i + 1..))
}

/// The first number of an ASCII section's header line (its block count), if it reads.
fn first_count(bytes: &[u8], section: &[u8]) -> Option<u64> {
    let body = section_body(bytes, section)?;
    let line = body.split(|&b| b == b'\n').next()?;
    std::str::from_utf8(line)
        .ok()?
        .split_whitespace()
        .next()?
        .parse()
        .ok()
}

/// The node tags of an MSH 4.1 `$Nodes` section, in file order, read as the format defines
/// them: `mshio` drops them when the header's tag range is dense (`max - min + 1` nodes), which
/// would silently accept permuted, repeated or missing tags. Binary files use `size_t` of
/// `data_size` bytes and 4-byte ints, little-endian (checked by `$MeshFormat`'s one).
fn node_tags_41(bytes: &[u8], binary: bool, data_size: usize) -> Result<Vec<u64>, MeshError> {
    let bad = |message: String| MeshError::Format {
        file: nofile(),
        message: format!("$Nodes: {message}"),
    };
    if !bytes.windows(7).any(|w| w == b"\n$Nodes") {
        return Err(bad("no $Nodes section".into()));
    }
    let body = section_body(bytes, b"\n$Nodes").unwrap_or(&[]);
    let truncated = || bad("truncated".into());
    let mut tags = Vec::new();
    if binary {
        let mut pos = 0usize;
        let mut take = |n: usize| -> Result<&[u8], MeshError> {
            let s = body.get(pos..pos + n).ok_or_else(truncated)?;
            pos += n;
            Ok(s)
        };
        let size_t = |b: &[u8]| -> u64 {
            let mut w = [0u8; 8];
            w[..b.len().min(8)].copy_from_slice(&b[..b.len().min(8)]);
            u64::from_le_bytes(w)
        };
        let blocks = size_t(take(data_size)?);
        let total = size_t(take(data_size)?);
        take(2 * data_size)?; // min and max tag
        // Each node needs at least its tag and three f64 coordinates.
        if total.saturating_mul(data_size as u64 + 24) > body.len() as u64 {
            return Err(bad(format!(
                "{total} nodes declared, more than the file holds"
            )));
        }
        for _ in 0..blocks {
            take(4)?; // entity dim
            take(4)?; // entity tag
            let parametric = u32::from_le_bytes(take(4)?.try_into().map_err(|_| truncated())?);
            let n = usize::try_from(size_t(take(data_size)?)).map_err(|_| truncated())?;
            for _ in 0..n {
                tags.push(size_t(take(data_size)?));
            }
            let per_node = 3 + if parametric != 0 { 3 } else { 0 };
            take(n.checked_mul(8 * per_node).ok_or_else(truncated)?)?;
        }
    } else {
        let text = std::str::from_utf8(body).map_err(|_| bad("not ASCII".into()))?;
        let mut lines = text.lines().map(str::trim).filter(|l| !l.is_empty());
        let mut numbers = |want: usize| -> Result<Vec<u64>, MeshError> {
            let line = lines.next().ok_or_else(truncated)?;
            let v: Vec<u64> = line
                .split_whitespace()
                .take(want)
                .map(|t| t.parse::<u64>())
                .collect::<Result<_, _>>()
                .map_err(|_| bad(format!("expected {want} integers, found {line:?}")))?;
            if v.len() < want {
                return Err(bad(format!("expected {want} integers, found {line:?}")));
            }
            Ok(v)
        };
        let head = numbers(4)?;
        let (blocks, total) = (head[0], head[1]);
        if total > body.len() as u64 {
            return Err(bad(format!(
                "{total} nodes declared, more than the file holds"
            )));
        }
        for _ in 0..blocks {
            let b = numbers(4)?;
            let n = b[3];
            for _ in 0..n {
                tags.push(numbers(1)?[0]);
            }
            for _ in 0..n {
                numbers(0)?; // coordinates (and parametric ones), read by mshio
            }
        }
    }
    Ok(tags)
}

thread_local! {
    /// Set while this thread runs [`catch_quietly`]'s closure.
    static QUIET: Cell<bool> = const { Cell::new(false) };
}

/// `catch_unwind(f)` without the panic message: the first call wraps the process's panic hook
/// (whatever it is then) in one that stays silent on a thread inside `catch_quietly` and
/// delegates everywhere else, so panics of other threads and later ones print as before.
fn catch_quietly<R>(f: impl FnOnce() -> R) -> std::thread::Result<R> {
    static WRAP_HOOK: Once = Once::new();
    WRAP_HOOK.call_once(|| {
        let previous = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            if !QUIET.with(Cell::get) {
                previous(info);
            }
        }));
    });
    let was = QUIET.with(|q| q.replace(true));
    let result = catch_unwind(AssertUnwindSafe(f));
    QUIET.with(|q| q.set(was));
    result
}

fn convert_mshio_error(e: &mshio::MshParserError<&[u8]>, bytes: &[u8], binary: bool) -> MeshError {
    let rest: &[u8] = e.backtrace.first().map(|(s, _)| *s).unwrap_or(&[]);
    let offset = bytes.len().saturating_sub(rest.len());
    let contexts: Vec<String> = e
        .filter_msh_errors()
        .filter_map(|(_, k)| k.context().map(str::to_owned))
        .collect();
    let what = e
        .filter_msh_errors()
        .find(|(_, k)| k.context().is_none())
        .or_else(|| e.backtrace.first())
        .map(|(_, k)| match k {
            // Bare nom errors: say what was expected.
            mshio::error::MshParserErrorKind::NomError(kind) => {
                match format!("{kind:?}").as_str() {
                    "Tag" => "expected a section tag such as \"$EndNodes\"".to_string(),
                    "Digit" => "expected an integer".to_string(),
                    "Float" | "Double" => "expected a number".to_string(),
                    "Eof" => "data ends early".to_string(),
                    other => format!("malformed data ({other})"),
                }
            }
            k => k.to_string(),
        })
        .unwrap_or_else(|| "invalid data".into());
    let at_end = if binary {
        rest.len() < 8
    } else {
        rest.iter().all(u8::is_ascii_whitespace)
    };
    let mut message = String::new();
    if at_end {
        message.push_str("unexpected end of file (file truncated?); ");
    }
    message.push_str(what.trim_end_matches('.'));
    if !contexts.is_empty() {
        let path: Vec<&str> = contexts.iter().rev().map(String::as_str).collect();
        message.push_str(&format!(" (while reading {})", path.join(" > ")));
    }
    if binary {
        MeshError::ParseBinary {
            file: nofile(),
            offset,
            message,
        }
    } else {
        let line = bytes
            .get(..offset)
            .map_or(0, |b| b.iter().filter(|&&x| x == b'\n').count())
            + 1;
        MeshError::Parse {
            file: nofile(),
            line,
            message,
        }
    }
}

fn msh41_to_mesh(
    msh: &mshio::MshFile<u64, i32, f64>,
    tags: &[u64],
) -> Result<(TetMesh, Ignored), MeshError> {
    let fmt_err = |message: String| MeshError::Format {
        file: nofile(),
        message,
    };
    let Some(sec) = &msh.data.nodes else {
        return Err(fmt_err("no $Nodes section".into()));
    };
    let total: usize = sec.node_blocks.iter().map(|b| b.nodes.len()).sum();
    if tags.len() != total {
        return Err(fmt_err(format!(
            "$Nodes lists {} node tags for {total} nodes",
            tags.len()
        )));
    }
    let nodes: Vec<[f64; 3]> = sec
        .node_blocks
        .iter()
        .flat_map(|b| b.nodes.iter().map(|n| [n.x, n.y, n.z]))
        .collect();
    let mut tag_to_id: HashMap<u64, usize> = HashMap::with_capacity(total);
    for (id, &tag) in tags.iter().enumerate() {
        if tag_to_id.insert(tag, id).is_some() {
            return Err(fmt_err(format!("node tag {tag} is defined twice")));
        }
    }
    let lookup = |tag: u64| tag_to_id.get(&tag).copied();

    let mut tets = Vec::new();
    let mut ignored = Ignored::default();
    if let Some(el) = &msh.data.elements {
        for block in &el.element_blocks {
            let ty = block.element_type as i64;
            let Some((dim, kind)) = element_kind(ty) else {
                if let Some(first) = block.elements.first() {
                    return Err(MeshError::UnsupportedElement {
                        file: nofile(),
                        element: first.element_tag,
                        kind: format!("element of unknown Gmsh type {ty}"),
                    });
                }
                continue;
            };
            if dim < 3 {
                ignored.add_many(&kind, block.elements.len());
                continue;
            }
            if ty != GMSH_TET4 {
                if let Some(first) = block.elements.first() {
                    return Err(MeshError::UnsupportedElement {
                        file: nofile(),
                        element: first.element_tag,
                        kind: kind.into_owned(),
                    });
                }
                continue;
            }
            tets.reserve(block.elements.len());
            for e in &block.elements {
                let &[a, b, c, d] = e.nodes.as_slice() else {
                    return Err(fmt_err(format!(
                        "tetrahedron (element tag {}) has {} nodes",
                        e.element_tag,
                        e.nodes.len()
                    )));
                };
                let mut tet = [0; 4];
                for (slot, node_tag) in tet.iter_mut().zip([a, b, c, d]) {
                    *slot = lookup(node_tag).ok_or(MeshError::UnknownNodeTag {
                        file: nofile(),
                        element: e.element_tag,
                        node_tag,
                    })?;
                }
                tets.push(tet);
            }
        }
    }
    Ok((TetMesh { nodes, tets }, ignored))
}

/// Format a coordinate so that it reads back exactly and stays short.
fn fmt_coord(v: f64) -> String {
    let a = v.abs();
    if v == 0.0 || (1e-4..1e15).contains(&a) || !v.is_finite() {
        format!("{v}")
    } else {
        format!("{v:e}")
    }
}

impl TetMesh {
    /// Write the mesh as a Gmsh MSH 4.1 ASCII file: one volume entity, node tags `1..=N` in node
    /// order, tetrahedron tags `1..=T` in tetrahedron order. Coordinates are written so that they
    /// read back bit-exactly.
    pub fn write_msh4_ascii(&self, w: &mut impl Write) -> io::Result<()> {
        let n = self.nodes.len();
        let t = self.tets.len();
        writeln!(w, "$MeshFormat\n4.1 0 8\n$EndMeshFormat")?;
        let (lo, hi) = if n == 0 {
            ([0.0; 3], [0.0; 3])
        } else {
            self.bounding_box()
        };
        let bbox: Vec<String> = lo.iter().chain(&hi).map(|&v| fmt_coord(v)).collect();
        writeln!(
            w,
            "$Entities\n0 0 0 1\n1 {} 0 0\n$EndEntities",
            bbox.join(" ")
        )?;
        writeln!(w, "$Nodes")?;
        if n == 0 {
            writeln!(w, "0 0 0 0")?;
        } else {
            writeln!(w, "1 {n} 1 {n}\n3 1 0 {n}")?;
            for i in 1..=n {
                writeln!(w, "{i}")?;
            }
            for p in &self.nodes {
                writeln!(
                    w,
                    "{} {} {}",
                    fmt_coord(p[0]),
                    fmt_coord(p[1]),
                    fmt_coord(p[2])
                )?;
            }
        }
        writeln!(w, "$EndNodes\n$Elements")?;
        if t == 0 {
            writeln!(w, "0 0 0 0")?;
        } else {
            writeln!(w, "1 {t} 1 {t}\n3 1 4 {t}")?;
            for (i, [a, b, c, d]) in self.tets.iter().enumerate() {
                writeln!(w, "{} {} {} {} {}", i + 1, a + 1, b + 1, c + 1, d + 1)?;
            }
        }
        writeln!(w, "$EndElements")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn element_table_dimensions() {
        assert_eq!(element_kind(4).map(|k| k.0), Some(3));
        assert_eq!(element_kind(2).map(|k| k.0), Some(2));
        assert_eq!(element_kind(15).map(|k| k.0), Some(0));
        assert_eq!(
            element_kind(11).map(|k| k.1.into_owned()).as_deref(),
            Some("10-node tetrahedron")
        );
        assert!(element_kind(141).is_none());
        assert!(element_kind(-1).is_none());
    }

    #[test]
    fn v2_minimal_with_sparse_tags_and_other_sections() {
        let text = "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$PhysicalNames\n1\n3 1 \"body\"\n\
                    $EndPhysicalNames\n$Nodes\n4\n10 0 0 0\n20 1 0 0\n30 0 1 0\n7 0 0 1\n$EndNodes\n\
                    $Elements\n3\n1 15 2 0 1 10\n2 2 2 0 1 10 20 30\n5 4 2 1 1 10 20 30 7\n\
                    $EndElements\n";
        let (m, ignored) = read_msh(text.as_bytes()).unwrap();
        assert_eq!(m.nodes.len(), 4);
        assert_eq!(m.tets, vec![[0, 1, 2, 3]]);
        assert_eq!(m.nodes[3], [0.0, 0.0, 1.0]);
        assert_eq!(ignored.to_string(), "1 point, 1 3-node triangle");
    }

    #[test]
    fn v1_with_sparse_numbers_and_lower_dimensional_elements() {
        // Node numbers 10, 20, 30, 7 (not 1..N, not sorted); a point, a line and a triangle
        // before the tetrahedron.
        let text = "$NOD\n4\n10 0 0 0\n20 1 0 0\n30 0 1 0\n7 0 0 1\n$ENDNOD\n$ELM\n4\n\
                    1 15 0 1 1 10\n2 1 0 1 2 10 20\n3 2 0 1 3 10 20 30\n9 4 1 1 4 10 20 30 7\n\
                    $ENDELM\n";
        let (m, ignored) = read_msh(text.as_bytes()).unwrap();
        assert_eq!(
            m.nodes,
            vec![[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
        );
        assert_eq!(m.tets, vec![[0, 1, 2, 3]]);
        assert_eq!(ignored.total(), 3);
        assert_eq!(
            ignored.to_string(),
            "1 point, 1 2-node line, 1 3-node triangle"
        );
        // Errors name the line.
        let bad = text.replace("9 4 1 1 4 10 20 30 7", "9 4 1 1 4 10 20 30 8");
        let e = read_msh(bad.as_bytes()).unwrap_err().to_string();
        assert_eq!(
            e,
            "element 9 refers to node tag 8, which is not defined in $Nodes"
        );
        let bad = text.replace("9 4 1 1 4 10 20 30 7", "9 4 1 1 3 10 20 30");
        let e = read_msh(bad.as_bytes()).unwrap_err().to_string();
        assert_eq!(
            e,
            "line 13: tetrahedron (element number 9) declares 3 nodes (expected 4)"
        );
        let bad = text.replace("$ENDELM\n", "");
        let e = read_msh(bad.as_bytes()).unwrap_err().to_string();
        assert!(e.contains("expected \"$ENDELM\""), "{e}");
        let bad = text.replace("7 0 0 1", "7 0 0 x");
        let e = read_msh(bad.as_bytes()).unwrap_err().to_string();
        assert_eq!(e, "line 6: invalid z coordinate \"x\" of node tag 7");
    }

    #[test]
    fn writer_round_trips_through_mshio() {
        let m = crate::mesh::structured::box_mesh([0.1, 0.2, 0.3], [2, 1, 1]);
        let mut buf = Vec::new();
        m.write_msh4_ascii(&mut buf).unwrap();
        assert_eq!(read_msh(&buf).unwrap().0, m);
        let empty = TetMesh {
            nodes: vec![],
            tets: vec![],
        };
        let mut buf = Vec::new();
        empty.write_msh4_ascii(&mut buf).unwrap();
        // Must not panic; an empty mesh either reads back empty or is rejected.
        let _ = read_msh(&buf);
    }

    #[test]
    fn malformed_v41_is_an_error_not_a_panic() {
        // Zero nodes with tags 1..1: `mshio` subtracts 1 from the count (a panic with overflow
        // checks on, caught here).
        let text = "$MeshFormat\n4.1 0 8\n$EndMeshFormat\n$Nodes\n1 0 1 1\n$EndNodes\n";
        assert!(read_msh(text.as_bytes()).is_err());
        let e = read_msh(b"$MeshFormat\n4.1 1 3\n").unwrap_err().to_string();
        assert_eq!(
            e,
            "line 2: unsupported data size 3 in $MeshFormat (expected 8)"
        );
        let e = read_msh(b"$MeshFormat\n4.1 0 99999999999999999999\n")
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("line 2: invalid MSH data size"), "{e}");
        let e = read_msh(
            b"$MeshFormat\n4.1 0 8\n$EndMeshFormat\n$Nodes\n1 2 1 2\n3 1 0 2\n1\n2\n0 0 0\n",
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.starts_with("line 10: unexpected end of file (file truncated?)"),
            "{e}"
        );
        assert!(e.contains("node section"), "{e}");
    }

    #[test]
    fn coordinates_round_trip_exactly() {
        for v in [0.0, -0.0, 0.1, 1.0 / 3.0, 1e-7, -2.5e-12, 1e300, 123456.789] {
            let s = fmt_coord(v);
            assert_eq!(s.parse::<f64>().unwrap(), v, "{s}");
        }
    }
}
