//! The surface checks and repairs of `fem::surface::check`, on hand-made surfaces with known
//! answers: a subdivided octahedron on the unit sphere (closed, outward, 4^k * 8 faces), and
//! what each defect does to it.

use fem::surface::{CheckOptions, SurfaceError, TriSurface, check};

/// The octahedron with each face split into 4^`level` faces, projected on the unit sphere,
/// centred at `c`, outward.
fn sphere(level: u32, c: [f64; 3]) -> TriSurface {
    let mut v: Vec<[f64; 3]> = vec![
        [1.0, 0.0, 0.0],
        [-1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.0, -1.0, 0.0],
        [0.0, 0.0, 1.0],
        [0.0, 0.0, -1.0],
    ];
    let mut t: Vec<[usize; 3]> = vec![
        [0, 2, 4],
        [2, 1, 4],
        [1, 3, 4],
        [3, 0, 4],
        [2, 0, 5],
        [1, 2, 5],
        [3, 1, 5],
        [0, 3, 5],
    ];
    for _ in 0..level {
        let mut mid = std::collections::HashMap::new();
        let mut next = Vec::new();
        let mut m = |a: usize, b: usize, v: &mut Vec<[f64; 3]>| {
            *mid.entry((a.min(b), a.max(b))).or_insert_with(|| {
                let p = [0, 1, 2].map(|k| (v[a][k] + v[b][k]) / 2.0);
                let n = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
                v.push(p.map(|x| x / n));
                v.len() - 1
            })
        };
        for &[a, b, c] in &t {
            let (ab, bc, ca) = (m(a, b, &mut v), m(b, c, &mut v), m(c, a, &mut v));
            next.extend([[a, ab, ca], [ab, b, bc], [ca, bc, c], [ab, bc, ca]]);
        }
        t = next;
    }
    TriSurface {
        vertices: v.iter().map(|p| [0, 1, 2].map(|k| p[k] + c[k])).collect(),
        triangles: t,
    }
}

fn repair() -> CheckOptions {
    CheckOptions {
        repair: true,
        ..CheckOptions::default()
    }
}

#[test]
fn a_closed_sphere_passes_unchanged() {
    let s = sphere(2, [0.0; 3]);
    assert_eq!(s.triangles.len(), 128);
    let (out, notes) = check(&s, CheckOptions::default()).unwrap();
    assert!(notes.is_empty(), "{notes:?}");
    assert_eq!(out, s);
    // The inscribed polyhedron's volume is below the ball's 4.19.
    let v = out.signed_volume();
    assert!(v > 3.5 && v < 4.0 * std::f64::consts::PI / 3.0, "{v}");
}

#[test]
fn inside_out_is_flipped_and_said() {
    let mut s = sphere(1, [0.0; 3]);
    for t in &mut s.triangles {
        t.swap(1, 2);
    }
    let (out, notes) = check(&s, CheckOptions::default()).unwrap();
    assert!(out.signed_volume() > 0.0);
    assert_eq!(
        notes,
        ["the faces pointed inward (inside out): all flipped"]
    );
}

#[test]
fn holes_are_refused_with_their_loop_sizes_or_filled() {
    let mut s = sphere(2, [0.0; 3]);
    // Remove the fan of vertex 4 (the north pole: valence 4) and one face far from it.
    let pole = 4;
    s.triangles.retain(|t| !t.contains(&pole));
    let south = s
        .triangles
        .iter()
        .position(|t| t.iter().all(|&v| s.vertices[v][2] < -0.5))
        .unwrap();
    s.triangles.remove(south);
    let e = check(&s, CheckOptions::default()).unwrap_err();
    match &e {
        SurfaceError::NotClosed { loops, .. } => {
            let mut l = loops.clone();
            l.sort();
            assert_eq!(l, [3, 4]);
        }
        other => panic!("{other}"),
    }
    assert!(
        e.to_string()
            .starts_with("not closed: 2 holes, boundary loops of "),
        "{e}"
    );
    // Too small a fill limit: still refused.
    let small = CheckOptions {
        fill_holes: 3,
        ..repair()
    };
    assert!(matches!(
        check(&s, small),
        Err(SurfaceError::NotClosed { .. })
    ));
    let (out, notes) = check(&s, repair()).unwrap();
    // No vertex added: a 4-edge loop takes 2 faces, a 3-edge loop 1.
    assert_eq!(out.triangles.len(), 128 - 4 - 1 + 2 + 1);
    assert_eq!(out.vertices.len(), s.vertices.len() - 1);
    assert!(notes[0].starts_with("filled 2 holes"), "{notes:?}");
    // The filled surface is closed: checking it again changes nothing.
    assert!(check(&out, CheckOptions::default()).unwrap().1.is_empty());
}

#[test]
fn a_flipped_patch_is_refused_or_flipped_back() {
    let s = sphere(2, [0.0; 3]);
    let mut bad = s.clone();
    let patch: Vec<usize> = (0..bad.triangles.len())
        .filter(|&f| bad.triangles[f].iter().all(|&v| bad.vertices[v][0] > 0.6))
        .collect();
    assert!(!patch.is_empty() && patch.len() < 20);
    for &f in &patch {
        bad.triangles[f].swap(1, 2);
    }
    match check(&bad, CheckOptions::default()).unwrap_err() {
        SurfaceError::InconsistentOrientation { count, total, .. } => {
            assert_eq!((count, total), (patch.len(), 128));
        }
        other => panic!("{other}"),
    }
    let (out, notes) = check(&bad, repair()).unwrap();
    assert_eq!(out, s);
    assert_eq!(notes.len(), 1);
    let want = format!(
        "flipped {} of 128 faces to agree with their neighbours",
        patch.len()
    );
    assert!(notes[0].starts_with(&want), "{notes:?}");
}

#[test]
fn two_shells_are_refused_or_the_largest_kept() {
    let big = sphere(2, [0.0; 3]);
    let mut small = sphere(1, [5.0, 0.0, 0.0]);
    // Half the radius.
    for v in &mut small.vertices {
        *v = [5.0 + (v[0] - 5.0) * 0.5, v[1] * 0.5, v[2] * 0.5];
    }
    let n = big.vertices.len();
    let both = TriSurface {
        vertices: [big.vertices.clone(), small.vertices.clone()].concat(),
        triangles: big
            .triangles
            .iter()
            .copied()
            .chain(small.triangles.iter().map(|t| t.map(|v| v + n)))
            .collect(),
    };
    let e = check(&both, CheckOptions::default()).unwrap_err();
    assert!(
        e.to_string()
            .starts_with("2 disconnected shells (128 faces, area "),
        "{e}"
    );
    let (out, notes) = check(
        &both,
        CheckOptions {
            largest: true,
            ..CheckOptions::default()
        },
    )
    .unwrap();
    assert_eq!(out, big);
    assert!(
        notes[0].starts_with("kept the largest of 2 shells (128 faces"),
        "{notes:?}"
    );
}

#[test]
fn duplicate_vertices_are_refused_or_merged() {
    let s = sphere(1, [0.0; 3]);
    // Give the faces around vertex 0 their own copy of it, 1e-12 away.
    let mut bad = s.clone();
    bad.vertices.push([1.0 + 1e-12, 0.0, 0.0]);
    let copy = bad.vertices.len() - 1;
    let mut changed = 0;
    for t in &mut bad.triangles {
        if let Some(k) = t.iter().position(|&v| v == 0)
            && changed < 2
        {
            t[k] = copy;
            changed += 1;
        }
    }
    let e = check(&bad, CheckOptions::default()).unwrap_err();
    match &e {
        SurfaceError::DuplicateVertices {
            count: 1,
            first: 0,
            second,
            ..
        } => assert_eq!(*second, copy),
        other => panic!("{other}"),
    }
    let (out, notes) = check(&bad, repair()).unwrap();
    assert_eq!(out, s);
    assert_eq!(notes.len(), 2, "{notes:?}"); // merged, then the unused copy dropped
}

#[test]
fn degenerate_and_non_manifold_are_refused() {
    let s = sphere(1, [0.0; 3]);
    let mut bad = s.clone();
    bad.triangles.push([0, 0, 2]);
    let e = check(&bad, CheckOptions::default())
        .unwrap_err()
        .to_string();
    assert!(
        e.starts_with("1 degenerate faces: face 32 uses vertex 0 twice"),
        "{e}"
    );
    // With --repair the face is dropped.
    assert_eq!(check(&bad, repair()).unwrap().0, s);
    // A third face on an edge.
    let mut bad = s.clone();
    bad.vertices.push([2.0, 2.0, 2.0]);
    let t = bad.triangles[0];
    bad.triangles.push([t[0], t[1], bad.vertices.len() - 1]);
    let e = check(&bad, CheckOptions::default())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("non-manifold edges") && e.contains("has 3 faces"),
        "{e}"
    );
    // Two spheres touching at one vertex: a non-manifold vertex.
    let a = sphere(1, [0.0; 3]);
    let b = sphere(1, [2.0, 0.0, 0.0]);
    // b's vertex 1 is at (1, 0, 0), a's vertex 0: share it.
    let n = a.vertices.len();
    let map = |v: usize| if v == 1 { 0 } else { v + n };
    let touching = TriSurface {
        vertices: [a.vertices.clone(), b.vertices.clone()].concat(),
        triangles: a
            .triangles
            .iter()
            .copied()
            .chain(b.triangles.iter().map(|t| t.map(map)))
            .collect(),
    };
    let e = check(&touching, CheckOptions::default())
        .unwrap_err()
        .to_string();
    assert!(
        e.starts_with("1 non-manifold vertices: at vertex 0 the faces form 2"),
        "{e}"
    );
}

#[test]
fn a_vertex_pushed_through_is_a_self_intersection() {
    let mut s = sphere(2, [0.0; 3]);
    // The north pole through the south side (off the axis planes, where the octahedron's
    // edges lie, so that no crossing falls exactly on an edge).
    s.vertices[4] = [0.05, 0.03, -1.5];
    let e = check(&s, CheckOptions::default()).unwrap_err();
    match &e {
        SurfaceError::SelfIntersection { count, .. } => assert!(*count >= 4, "{e}"),
        other => panic!("{other}"),
    }
    assert!(e.to_string().starts_with("self-intersecting: "), "{e}");
}

/// Whether `s` is closed and manifold with consistently oriented faces: every directed edge
/// once, its reverse once.
fn closed_oriented(s: &TriSurface) -> bool {
    let mut directed = std::collections::HashMap::new();
    for t in &s.triangles {
        for k in 0..3 {
            *directed.entry((t[k], t[(k + 1) % 3])).or_insert(0) += 1;
        }
    }
    directed
        .iter()
        .all(|(&(a, b), &n)| n == 1 && directed.get(&(b, a)) == Some(&1))
}

#[test]
fn a_cap_cut_from_a_sphere_is_filled_by_least_area() {
    let s = sphere(4, [0.0; 3]);
    let whole = s.signed_volume();
    for (z, loop_edges) in [(0.93, 20), (0.8, 32)] {
        let mut cut = s.clone();
        cut.triangles
            .retain(|t| t.iter().any(|&v| cut.vertices[v][2] < z));
        let e = check(&cut, CheckOptions::default()).unwrap_err();
        match &e {
            SurfaceError::NotClosed { loops, .. } => assert_eq!(loops, &[loop_edges], "{e}"),
            other => panic!("{other}"),
        }
        let (out, notes) = check(&cut, repair()).unwrap();
        assert_eq!(
            notes[0],
            format!(
                "filled 1 holes (boundary loops of {loop_edges} edges) with the least-area \
                 triangulation of each loop"
            )
        );
        assert!(closed_oriented(&out));
        assert_eq!(out.triangles.len(), cut.triangles.len() + loop_edges - 2);
        // Passes every check unchanged (closed, manifold, oriented, no self-intersection).
        let (again, none) = check(&out, CheckOptions::default()).unwrap();
        assert!(none.is_empty(), "{none:?}");
        assert_eq!(again, out);
        // The volume lost is about the cap above the loop (of the ball: an upper bound).
        let removed = whole - out.signed_volume();
        let h = 1.0 - z;
        let cap = std::f64::consts::PI * h * h * (3.0 - h) / 3.0;
        eprintln!(
            "cap above z = {z}: loop of {loop_edges} edges, volume {:.5} of {whole:.5} \
             ({:+.3}%), the ball's cap {cap:.5}",
            out.signed_volume(),
            100.0 * (out.signed_volume() / whole - 1.0)
        );
        assert!(removed > 0.0 && removed < 1.3 * cap, "{removed} {cap}");
    }
}

#[test]
fn a_pyramid_flattened_onto_its_base_overlaps_itself() {
    // A closed square pyramid whose apex is pushed into the base plane: its side faces lie
    // on the base's, folded over it (coplanar faces sharing an edge or a vertex).
    let s = TriSurface {
        vertices: vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.0, 1.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.3, 0.4, 0.0],
        ],
        triangles: vec![
            [0, 2, 1],
            [0, 3, 2],
            [0, 1, 4],
            [1, 2, 4],
            [2, 3, 4],
            [3, 0, 4],
        ],
    };
    let e = check(&s, CheckOptions::default()).unwrap_err();
    match &e {
        SurfaceError::SelfIntersection { count, .. } => assert!(*count >= 4, "{e}"),
        other => panic!("{other}"),
    }
    // With the apex above the base, it passes.
    let mut ok = s.clone();
    ok.vertices[4][2] = 0.5;
    assert!(check(&ok, CheckOptions::default()).is_ok());
}

#[test]
fn faces_sharing_a_vertex_cross() {
    // A triangular bipyramid (every two faces share a vertex) whose north apex is pulled below
    // the equator, beside the south half: the north faces through a pass through the south
    // half, crossing south faces they share a vertex with.
    let mut s = TriSurface {
        vertices: vec![
            [1.0, 0.0, 0.0],
            [-0.5, 0.875, 0.0],
            [-0.5, -0.875, 0.0],
            [0.0, 0.0, 1.0],
            [0.0, 0.0, -1.0],
        ],
        triangles: vec![
            [0, 1, 3],
            [1, 2, 3],
            [2, 0, 3],
            [1, 0, 4],
            [2, 1, 4],
            [0, 2, 4],
        ],
    };
    assert!(check(&s, CheckOptions::default()).unwrap().1.is_empty());
    s.vertices[3] = [-0.5, 0.0, -0.5];
    let e = check(&s, CheckOptions::default()).unwrap_err();
    assert_eq!(
        e.to_string(),
        "self-intersecting: 2 pairs of faces cross, first faces 0 and 4 at \
         (0.0000, 0.2917, -0.1667)"
    );
    // Above the equator again (beside the axis): no crossing.
    s.vertices[3] = [-0.5, 0.0, 0.5];
    assert!(check(&s, CheckOptions::default()).is_ok());
}

#[test]
fn bad_ids_and_coordinates_are_errors() {
    let mut s = sphere(1, [0.0; 3]);
    s.triangles[3][1] = 99;
    let e = check(&s, CheckOptions::default()).unwrap_err().to_string();
    assert_eq!(e, "face 3 refers to vertex 99, but there are 18 vertices");
    let mut s = sphere(1, [0.0; 3]);
    s.vertices[5][2] = f64::NAN;
    let e = check(&s, CheckOptions::default()).unwrap_err().to_string();
    assert!(e.starts_with("vertex 5 has a non-finite coordinate"), "{e}");
    // A far stray vertex (a huge face) is checked in bounded time.
    let mut s = sphere(3, [0.0; 3]);
    s.vertices[4] = [1e11, 0.0, 0.0];
    let t = std::time::Instant::now();
    let _ = check(&s, CheckOptions::default());
    assert!(t.elapsed().as_secs_f64() < 5.0);
}
