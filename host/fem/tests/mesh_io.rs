//! Integration tests of `fem::mesh`: reading every supported format, validation errors, robustness
//! against malformed input, and the boundary surface. Test data: `host/fem/tests/data/`, made by
//! `scripts/gen_test_meshes.py`.

use fem::mesh::{self, Format, MeshError, TetMesh};
use std::path::{Path, PathBuf};

fn data(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data")
        .join(name)
}

/// Edge of the test cube, metres.
const L: f64 = 0.05;

const CUBE_FILES: [&str; 16] = [
    "cube_v1.msh",
    "cube_v1_sparse.msh",
    "cube.mesh",
    "cube_v2.msh",
    "cube_v41.msh",
    "cube_v41_bin.msh",
    "cube_v41_sparse.msh",
    "noncontiguous_tags_v2.msh",
    "cube.vtu",
    "cube_raw.vtu",
    "cube_ascii.vtu",
    "cube_appended.vtu",
    "cube.vtk",
    "cube_v51.vtk",
    "cube_bin.vtk",
    "cube_v51_bin.vtk",
];

fn total_volume(m: &TetMesh) -> f64 {
    (0..m.tets.len()).map(|t| m.signed_volume(t)).sum()
}

#[test]
fn all_formats_load_to_the_same_mesh() {
    let reference = mesh::load(&data("cube_v2.msh")).unwrap();
    assert!(reference.tets.len() >= 24, "{} tets", reference.tets.len());
    assert!((total_volume(&reference) - L * L * L).abs() < 1e-15);
    for name in CUBE_FILES {
        let m = mesh::load(&data(name)).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(m.nodes.len(), reference.nodes.len(), "{name}");
        assert_eq!(m.tets, reference.tets, "{name}");
        for (p, q) in m.nodes.iter().zip(&reference.nodes) {
            for a in 0..3 {
                // Text formats print 12 (meshio ASCII .vtu) to 17 significant digits.
                assert!((p[a] - q[a]).abs() <= 1e-13, "{name}: {p:?} vs {q:?}");
            }
        }
        assert!((total_volume(&m) - L * L * L).abs() < 1e-15, "{name}");
    }
}

/// The boundary triangles, lines and points in the files are skipped and counted: 84 boundary
/// triangles (as `scripts/gen_test_meshes.py` prints for the cube), in every file that has them.
#[test]
fn lower_dimensional_elements_are_counted() {
    let cases = [
        ("cube_v1.msh", "3-node triangle"),
        ("cube_v1_sparse.msh", "3-node triangle"),
        ("cube_v2.msh", "3-node triangle"),
        ("cube_v41.msh", "3-node triangle"),
        ("cube_v41_bin.msh", "3-node triangle"),
        ("cube.vtk", "VTK_TRIANGLE"),
        ("cube_bin.vtk", "VTK_TRIANGLE"),
        ("cube.vtu", "VTK_TRIANGLE"),
        ("cube.mesh", "triangle"),
    ];
    for (name, kind) in cases {
        let (m, ignored) = mesh::read_counted(&data(name)).unwrap();
        assert_eq!(m.tets.len(), 100, "{name}");
        let triangles = ignored.0.iter().find(|(k, _)| k == kind);
        assert_eq!(triangles.map(|t| t.1), Some(84), "{name}: {ignored}");
    }
    // Gmsh's MSH files also hold the cube's 8 corner points and the lines along its 12 edges
    // (2 segments each at the 25 mm size).
    let (_, ignored) = mesh::read_counted(&data("cube_v2.msh")).unwrap();
    assert_eq!(
        ignored.to_string(),
        "8 point, 24 2-node line, 84 3-node triangle"
    );
    let (_, ignored) = mesh::read_counted(&data("noncontiguous_tags_v2.msh")).unwrap();
    assert_eq!(ignored.total(), 0);
}

#[test]
fn read_does_not_validate_but_load_does() {
    let m = mesh::read(&data("bad/inverted.msh")).unwrap();
    assert_eq!(m.tets.len(), 5);
    assert!(mesh::load(&data("bad/inverted.msh")).is_err());
}

#[test]
fn inverted_message_reads_well() {
    let path = data("bad/inverted.msh");
    let e = mesh::load(&path).unwrap_err();
    assert_eq!(
        e.to_string(),
        format!(
            "{}: tetrahedron 3 is inverted (signed volume -1.67e-7 m^3)",
            path.display()
        )
    );
    assert_eq!(e.path(), Some(path.as_path()));
}

/// Every bad file, the error variant it must produce and text its message must contain.
#[test]
fn every_problem_is_reported_with_its_ids() {
    type Check = fn(&MeshError) -> bool;
    let cases: &[(&str, Check, &[&str])] = &[
        // Validation, in `validate`'s order.
        (
            "no_tets.msh",
            |e| matches!(e, MeshError::NoTetrahedra { nodes: 3, .. }),
            &["no tetrahedra"],
        ),
        (
            "index_out_of_range.vtk",
            |e| {
                matches!(
                    e,
                    MeshError::NodeIndexOutOfRange {
                        tet: 1,
                        node: 9,
                        num_nodes: 5,
                        ..
                    }
                )
            },
            &["tetrahedron 1 refers to node 9", "only 5 nodes"],
        ),
        (
            "repeated_node.msh",
            |e| {
                matches!(
                    e,
                    MeshError::RepeatedNode {
                        tet: 2,
                        node: 2,
                        ..
                    }
                )
            },
            &["tetrahedron 2 uses node 2 more than once"],
        ),
        (
            "non_finite.msh",
            |e| matches!(e, MeshError::NonFiniteCoordinate { node: 2, .. }),
            &["node 2 has a non-finite coordinate", "NaN"],
        ),
        (
            "duplicate_nodes.msh",
            |e| {
                matches!(
                    e,
                    MeshError::DuplicateNodes {
                        first: 1,
                        second: 8,
                        ..
                    }
                )
            },
            &["nodes 1 and 8 coincide"],
        ),
        (
            "unreferenced.msh",
            |e| matches!(e, MeshError::UnreferencedNode { node: 8, .. }),
            &["node 8 is not used by any tetrahedron"],
        ),
        (
            "degenerate.msh",
            |e| matches!(e, MeshError::DegenerateTet { tet: 1, quality, .. } if *quality < 1e-6),
            &["tetrahedron 1 is degenerate (quality "],
        ),
        (
            "inverted.msh",
            |e| matches!(e, MeshError::InvertedTet { tet: 3, volume, .. } if *volume < 0.0),
            &["tetrahedron 3 is inverted"],
        ),
        (
            "duplicate_tet.msh",
            |e| {
                matches!(
                    e,
                    MeshError::DuplicateTet {
                        first: 2,
                        second: 5,
                        ..
                    }
                )
            },
            &["tetrahedra 2 and 5 have the same nodes"],
        ),
        (
            "nonmanifold_face.msh",
            |e| {
                matches!(e, MeshError::NonManifoldFace { face: [0, 1, 2], tets, .. }
                    if tets == &[0, 1, 2])
            },
            &["face with nodes [0, 1, 2] is shared by 3 tetrahedra [0, 1, 2]"],
        ),
        (
            "overlapping.msh",
            |e| {
                matches!(
                    e,
                    MeshError::OverlappingTets {
                        face: [0, 1, 2],
                        tets: [0, 1],
                        ..
                    }
                )
            },
            &["tetrahedra 0 and 1 overlap", "[0, 1, 2]"],
        ),
        (
            "nonmanifold_edge.msh",
            |e| {
                matches!(
                    e,
                    MeshError::NonManifoldEdge {
                        edge: [0, 1],
                        triangles: 4,
                        ..
                    }
                )
            },
            &["edge between nodes 0 and 1 is shared by 4 boundary triangles"],
        ),
        (
            "nonmanifold_vertex.msh",
            |e| {
                matches!(
                    e,
                    MeshError::NonManifoldVertex {
                        node: 0,
                        fans: 2,
                        ..
                    }
                )
            },
            &["at node 0 the boundary triangles form 2 separate fans"],
        ),
        // Reading.
        (
            "truncated.msh",
            |e| matches!(e, MeshError::Parse { line: 49, .. }),
            &["line 49: unexpected end of file in $Nodes: got 44 of 45 nodes (file truncated?)"],
        ),
        (
            "bad_number.msh",
            |e| matches!(e, MeshError::Parse { line: 7, .. }),
            &["line 7: invalid y coordinate \"0.0O\" of node tag 2"],
        ),
        (
            "tet10.msh",
            |e| matches!(e, MeshError::UnsupportedElement { element: 2, .. }),
            &["element 2 is of unsupported type 10-node tetrahedron"],
        ),
        (
            "hex.msh",
            |e| matches!(e, MeshError::UnsupportedElement { element: 1, .. }),
            &["element 1 is of unsupported type 8-node hexahedron"],
        ),
        (
            "hex.vtk",
            |e| matches!(e, MeshError::UnsupportedElement { element: 1, .. }),
            &["element 1 is of unsupported type VTK_HEXAHEDRON"],
        ),
        (
            "unknown_node_tag.msh",
            |e| {
                matches!(
                    e,
                    MeshError::UnknownNodeTag {
                        element: 1,
                        node_tag: 99,
                        ..
                    }
                )
            },
            &["element 1 refers to node tag 99"],
        ),
        (
            "version40.msh",
            |e| matches!(e, MeshError::UnsupportedVersion { .. }),
            &["unsupported Gmsh MSH format version 4 "],
        ),
        (
            "version1.msh",
            |e| matches!(e, MeshError::NoTetrahedra { nodes: 1, .. }),
            &["no tetrahedra (1 nodes"],
        ),
        (
            "binary_v2.msh",
            |e| matches!(e, MeshError::UnsupportedVersion { .. }),
            &["version 2.2 binary"],
        ),
        (
            "cube.stl",
            |e| matches!(e, MeshError::UnknownExtension { .. }),
            &["unknown mesh file extension \"stl\""],
        ),
    ];
    for (name, check, texts) in cases {
        let path = data(&format!("bad/{name}"));
        let e = mesh::load(&path).expect_err(name);
        let msg = e.to_string();
        assert!(check(&e), "{name}: wrong error: {msg}");
        let prefix = format!("{}: ", path.display());
        assert!(
            msg.starts_with(&prefix),
            "{name}: message lacks the file: {msg}"
        );
        for t in *texts {
            assert!(msg.contains(t), "{name}: {msg:?} does not contain {t:?}");
        }
    }
    // A missing file.
    let e = mesh::load(&data("bad/does_not_exist.msh")).unwrap_err();
    assert!(matches!(e, MeshError::Io { .. }), "{e}");
    assert!(
        e.to_string()
            .contains("does_not_exist.msh: cannot read mesh file"),
        "{e}"
    );
}

/// Parse `bytes`; whatever parses is also validated and has its boundary taken. Nothing may panic.
fn exercise(bytes: &[u8], format: Format) -> Result<(), MeshError> {
    let m = mesh::read_bytes(bytes, format)?;
    let _ = mesh::boundary(&m);
    mesh::validate(&m)
}

fn internal_failure(e: &MeshError) -> bool {
    e.to_string().contains("gave up")
}

#[test]
fn truncated_inputs_are_errors_not_panics() {
    for name in CUBE_FILES {
        let bytes = std::fs::read(data(name)).unwrap();
        let format = Format::from_path(Path::new(name)).unwrap();
        let mut guarded = 0;
        for len in 0..bytes.len() {
            // Prefixes that end in the trailing whitespace or in skipped trailing sections
            // may still be complete files; everything else must be an error.
            match exercise(&bytes[..len], format) {
                Ok(()) => assert!(
                    len + 64 > bytes.len(),
                    "{name}: prefix of {len} of {} bytes accepted",
                    bytes.len()
                ),
                Err(e) => guarded += internal_failure(&e) as usize,
            }
        }
        println!(
            "{name}: {} prefixes, {guarded} caught parser panics",
            bytes.len()
        );
    }
}

#[test]
fn garbage_and_corrupted_inputs_are_errors_not_panics() {
    let mut rng = splitmix::SplitMix64::new(0x9e37_79b9_7f4a_7c15);
    let formats = [Format::Msh, Format::Vtu, Format::Vtk];
    // Pure garbage, with and without a plausible header.
    let headers: [&[u8]; 6] = [
        b"",
        b"$MeshFormat\n2.2 0 8\n$EndMeshFormat\n",
        b"$MeshFormat\n4.1 0 8\n$EndMeshFormat\n",
        b"$MeshFormat\n4.1 1 8\n\x01\x00\x00\x00\n$EndMeshFormat\n",
        b"# vtk DataFile Version 4.2\nt\nASCII\nDATASET UNSTRUCTURED_GRID\n",
        b"<?xml version=\"1.0\"?>\n<VTKFile type=\"UnstructuredGrid\" version=\"0.1\">",
    ];
    for _ in 0..300 {
        let mut bytes = headers[rng.below(headers.len())].to_vec();
        let n = rng.below(200);
        let alphabet = b"0123456789 .-e\n$NodesElements";
        for _ in 0..n {
            bytes.push(if rng.below(2) == 0 {
                rng.next_u64() as u8
            } else {
                alphabet[rng.below(alphabet.len())]
            });
        }
        for f in formats {
            let _ = exercise(&bytes, f);
        }
    }
    // Valid files with random bytes changed: the parsers see plausible structure with bad
    // numbers, counts and ids.
    let mut guarded = 0;
    for name in CUBE_FILES {
        let orig = std::fs::read(data(name)).unwrap();
        let format = Format::from_path(Path::new(name)).unwrap();
        for _ in 0..300 {
            let mut bytes = orig.clone();
            for _ in 0..1 + rng.below(4) {
                let i = rng.below(bytes.len());
                bytes[i] = match rng.below(3) {
                    0 => rng.next_u64() as u8,
                    1 => b"0123456789"[rng.below(10)],
                    _ => b"\n -9"[rng.below(4)],
                };
            }
            if let Err(e) = exercise(&bytes, format) {
                guarded += internal_failure(&e) as usize;
            }
        }
    }
    println!("corrupted files: {guarded} caught parser panics");
}

#[test]
fn cube_boundary_is_closed_outward_and_has_the_right_area() {
    let m = mesh::load(&data("cube_v41.msh")).unwrap();
    let s = mesh::boundary(&m).unwrap();
    let c = [L / 2.0; 3];
    let mut area = 0.0;
    for &[a, b, d] in &s.triangles {
        let (pa, pb, pd) = (m.nodes[a], m.nodes[b], m.nodes[d]);
        let u = [pb[0] - pa[0], pb[1] - pa[1], pb[2] - pa[2]];
        let v = [pd[0] - pa[0], pd[1] - pa[1], pd[2] - pa[2]];
        let n = [
            u[1] * v[2] - u[2] * v[1],
            u[2] * v[0] - u[0] * v[2],
            u[0] * v[1] - u[1] * v[0],
        ];
        let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
        area += len / 2.0;
        // The cube is convex: the normal points away from its centre.
        let g = [
            (pa[0] + pb[0] + pd[0]) / 3.0 - c[0],
            (pa[1] + pb[1] + pd[1]) / 3.0 - c[1],
            (pa[2] + pb[2] + pd[2]) / 3.0 - c[2],
        ];
        assert!(
            g[0] * n[0] + g[1] * n[1] + g[2] * n[2] > 0.0,
            "inward triangle {a} {b} {d}"
        );
    }
    assert!((area - 6.0 * L * L).abs() < 1e-15, "area {area}");
    // Every edge in exactly two triangles, once in each direction (consistent orientation).
    let mut directed: Vec<(usize, usize)> = s
        .triangles
        .iter()
        .flat_map(|&[a, b, c]| [(a, b), (b, c), (c, a)])
        .collect();
    directed.sort_unstable();
    assert!(
        directed.windows(2).all(|w| w[0] != w[1]),
        "a directed edge repeats"
    );
    for &(a, b) in &directed {
        assert!(
            directed.binary_search(&(b, a)).is_ok(),
            "edge {a}-{b} has no twin"
        );
    }
    // Boundary nodes: sorted, unique, exactly the nodes of the triangles, and all on the faces.
    assert!(s.nodes.windows(2).all(|w| w[0] < w[1]));
    let mut tri_nodes: Vec<usize> = s.triangles.iter().flatten().copied().collect();
    tri_nodes.sort_unstable();
    tri_nodes.dedup();
    assert_eq!(tri_nodes, s.nodes);
    for &i in &s.nodes {
        let p = m.nodes[i];
        assert!(
            p.iter().any(|&x| x.abs() < 1e-12 || (x - L).abs() < 1e-12),
            "{p:?}"
        );
    }
    // Euler characteristic of a sphere: V - E + F = 2.
    let v = s.nodes.len() as i64;
    let f = s.triangles.len() as i64;
    assert_eq!(v - 3 * f / 2 + f, 2);
}

#[test]
fn structured_box_boundary_nodes() {
    let m = mesh::structured::box_mesh([1., 1., 1.], [3, 3, 3]);
    mesh::validate(&m).unwrap();
    let s = mesh::boundary(&m).unwrap();
    assert_eq!(s.nodes.len(), 4 * 4 * 4 - 2 * 2 * 2);
    assert_eq!(s.triangles.len(), 6 * 9 * 2);
}

#[test]
fn writer_round_trips() {
    for name in ["cube_v2.msh", "cube.vtu"] {
        let m = mesh::load(&data(name)).unwrap();
        let mut buf = Vec::new();
        m.write_msh4_ascii(&mut buf).unwrap();
        let back = mesh::read_bytes(&buf, Format::Msh).unwrap();
        assert_eq!(back, m, "{name}");
        assert_eq!(mesh::parse_msh(&buf).unwrap(), m);
    }
}

/// Every mesh shipped in `host/meshes/` is valid and has a boundary.
#[test]
fn shipped_meshes_are_valid() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../meshes");
    let entries = std::fs::read_dir(&dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display()));
    let mut checked = 0;
    for entry in entries {
        let path = entry.unwrap().path();
        if Format::from_path(&path).is_err() {
            continue;
        }
        let m = mesh::load(&path).unwrap_or_else(|e| panic!("{e}"));
        let s = mesh::boundary(&m).unwrap();
        assert!(!s.triangles.is_empty(), "{}", path.display());
        checked += 1;
    }
    // liver-1k4, liver-10k, cylinder-2k, cylinder-10k, beam, brain-specimen.
    assert!(checked >= 6, "only {checked} meshes in {}", dir.display());
}

/// Validation and boundary of a ~100k-node, ~600k-tet mesh (their speed is measured by
/// `host bench compliance` as its load time; this checks the result at that size).
#[test]
fn large_mesh_validates_and_has_its_boundary() {
    let m = mesh::structured::box_mesh([0.1, 0.1, 0.1], [46, 46, 46]);
    assert!(m.nodes.len() > 100_000 && m.tets.len() > 580_000);
    mesh::validate(&m).unwrap();
    let s = mesh::boundary(&m).unwrap();
    assert_eq!(s.triangles.len(), 6 * 46 * 46 * 2);
}

/// One tetrahedron in MSH 4.1 ASCII whose `$Nodes` block lists `tags` for the corners
/// `(0,0,0), (1,0,0), (0,1,0), (0,0,1)` cm given in `order`; the element names tags 1 2 3 4.
fn msh41_one_tet(tags: [u64; 4], order: [usize; 4]) -> String {
    let corners = [
        [0.0, 0.0, 0.0],
        [0.01, 0.0, 0.0],
        [0.0, 0.01, 0.0],
        [0.0, 0.0, 0.01],
    ];
    let mut s = String::from("$MeshFormat\n4.1 0 8\n$EndMeshFormat\n$Nodes\n1 4 1 4\n3 1 0 4\n");
    for t in tags {
        s.push_str(&format!("{t}\n"));
    }
    for i in order {
        let [x, y, z] = corners[i];
        s.push_str(&format!("{x} {y} {z}\n"));
    }
    s.push_str("$EndNodes\n$Elements\n1 1 1 1\n3 1 4 1\n1 1 2 3 4\n$EndElements\n");
    s
}

/// MSH 4.1 node tags are read as the file gives them: permuted tags map to the right
/// coordinates (`mshio` drops dense tags and file order would make this tetrahedron inverted),
/// a repeated tag (with another missing) is refused, and node counts the file cannot hold are
/// refused before anything is allocated.
#[test]
fn msh41_node_tags_are_what_the_file_says() {
    // Tags 3, 1, 4, 2 listed with the coordinates of corners 2, 0, 3, 1.
    let permuted = msh41_one_tet([3, 1, 4, 2], [2, 0, 3, 1]);
    let m = mesh::parse_msh(permuted.as_bytes()).unwrap();
    mesh::validate(&m).unwrap();
    assert!(m.signed_volume(0) > 0.0);
    let corner = |tag: usize| m.nodes[m.tets[0][tag - 1]];
    assert_eq!(corner(1), [0.0, 0.0, 0.0]);
    assert_eq!(corner(4), [0.0, 0.0, 0.01]);
    // Tag 3 twice, tag 4 absent: the count still matches the header's dense range.
    let repeated = msh41_one_tet([1, 2, 3, 3], [0, 1, 2, 3]);
    let e = mesh::parse_msh(repeated.as_bytes())
        .unwrap_err()
        .to_string();
    assert!(e.contains("node tag 3 is defined twice"), "{e}");
    let huge = permuted.replace("$Nodes\n1 4 1 4\n", "$Nodes\n1 18446744073709551615 1 4\n");
    let e = mesh::parse_msh(huge.as_bytes()).unwrap_err().to_string();
    assert!(
        e.contains("nodes declared, more than the file holds"),
        "{e}"
    );
}

/// A file with no nodes says so (not "node tag 0 is reserved").
#[test]
fn an_empty_msh41_says_it_has_no_nodes() {
    let text = "$MeshFormat\n4.1 0 8\n$EndMeshFormat\n$Nodes\n0 0 0 0\n$EndNodes\n\
                $Elements\n0 0 0 0\n$EndElements\n";
    let e = mesh::parse_msh(text.as_bytes()).unwrap_err().to_string();
    assert!(e.contains("the mesh has no nodes"), "{e}");
}

/// Nodes but an empty `$Elements` section: that is what the error says.
#[test]
fn an_msh41_without_elements_says_so() {
    let text = msh41_one_tet([1, 2, 3, 4], [0, 1, 2, 3]).replace(
        "$Elements\n1 1 1 1\n3 1 4 1\n1 1 2 3 4\n$EndElements",
        "$Elements\n0 0 0 0\n$EndElements",
    );
    let e = mesh::parse_msh(text.as_bytes()).unwrap_err().to_string();
    assert!(e.contains("the mesh has no elements"), "{e}");
}

/// A device or FIFO is not read (it would never end).
#[test]
fn special_files_are_not_read() {
    let e = mesh::load(Path::new("/dev/zero.msh"));
    assert!(e.is_err());
    let dir = tempfile::tempdir().unwrap();
    let link = dir.path().join("zero.msh");
    std::os::unix::fs::symlink("/dev/zero", &link).unwrap();
    let e = mesh::load(&link).unwrap_err().to_string();
    assert!(e.contains("not a regular file"), "{e}");
}
