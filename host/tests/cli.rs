//! The `host` command line: the stable `compliance` JSON interface and its errors.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn host(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_host"))
        .args(args)
        .output()
        .expect("run host")
}

fn liver() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("meshes/liver-1k4.msh")
}

const BED: &str = "-1,-1,-1,1,1,0.01";

#[test]
fn compliance_prints_one_json_object_matching_the_library() {
    let mesh = liver();
    let out = host(&[
        "compliance",
        "--mesh",
        mesh.to_str().unwrap(),
        "--young",
        "3000",
        "--poisson",
        "0.45",
        "--fix-box",
        BED,
        "--nodes",
        "700,701,1000",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).expect("stdout is JSON only");
    assert_eq!(v["nodes"], serde_json::json!([700, 701, 1000]));
    let blocks = v["blocks"].as_array().unwrap();
    assert_eq!(blocks.len(), 3);
    let get = |a: usize, b: usize, i: usize| blocks[a][b][i].as_f64().unwrap();
    // Same numbers as the library, and C_kn = C_nk^T.
    let m = fem::mesh::load(&mesh).unwrap();
    let body =
        fem::elasticity::Elasticity::new(&m, fem::elasticity::Material::new(3000.0, 0.45).unwrap())
            .unwrap();
    let mut fixed = fem::elasticity::FixedSet::none(m.nodes.len());
    fixed
        .fix_box(&m, [-1.0, -1.0, -1.0, 1.0, 1.0, 0.01], [true; 3])
        .unwrap();
    let c = fem::compliance::Compliance::factorize(&body, &fixed).unwrap();
    let lib = c.blocks(&[700, 701, 1000], None).unwrap();
    for a in 0..3 {
        for b in 0..3 {
            assert_eq!(blocks[a][b].as_array().unwrap().len(), 9);
            for i in 0..9 {
                // Not bit-equal: the parallel assembly and factorisation may sum in another
                // order from one run to the next (one suite run under load differed by more
                // than 1e-15 of the diagonal); 1e-12 still tells the library's numbers from any
                // other solve.
                assert!(
                    (get(a, b, i) - lib[a][b][i / 3][i % 3]).abs() <= 1e-12 * get(a, a, 0).abs()
                );
                assert!(
                    (get(a, b, i) - get(b, a, (i % 3) * 3 + i / 3)).abs() <= 1e-12 * get(a, a, 0)
                );
            }
        }
    }
}

#[test]
fn compliance_element_anp_matches_the_library_and_unknown_elements_are_refused() {
    let mesh = liver();
    let run = |element: &str| {
        host(&[
            "compliance",
            "--mesh",
            mesh.to_str().unwrap(),
            "--young",
            "3000",
            "--poisson",
            "0.499",
            "--fix-box",
            BED,
            "--nodes",
            "700",
            "--element",
            element,
        ])
    };
    let out = run("anp");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).expect("stdout is JSON only");
    let m = fem::mesh::load(&mesh).unwrap();
    let material = fem::elasticity::Material::new(3000.0, 0.499).unwrap();
    let mut fixed = fem::elasticity::FixedSet::none(m.nodes.len());
    fixed
        .fix_box(&m, [-1.0, -1.0, -1.0, 1.0, 1.0, 0.01], [true; 3])
        .unwrap();
    let block = |element| {
        let body = fem::elasticity::Elasticity::with_element(&m, material, element).unwrap();
        let c = fem::compliance::Compliance::factorize(&body, &fixed).unwrap();
        c.blocks(&[700], None).unwrap()[0][0]
    };
    let anp = block(fem::elasticity::Element::Anp);
    let p1 = block(fem::elasticity::Element::P1);
    // The same solve in another process: equal up to rounding (the factorisation's parallel sums
    // may add in another order; a 1e-15 bound failed once), far tighter than P1's 20 % gap.
    for i in 0..9 {
        let got = v["blocks"][0][0][i].as_f64().unwrap();
        assert!(
            (got - anp[i / 3][i % 3]).abs() <= 1e-12 * anp[0][0].abs(),
            "block entry {i}: {got} from the CLI, {} from the library",
            anp[i / 3][i % 3]
        );
    }
    // P1 locks at nu = 0.499: its compliance is smaller.
    assert!(anp[2][2] > 1.2 * p1[2][2], "{anp:?} vs {p1:?}");
    let bad = run("p2");
    assert!(!bad.status.success());
    let err = String::from_utf8_lossy(&bad.stderr);
    assert!(err.contains("p1 or anp"), "{err}");
}

#[test]
fn fix_nodes_file_is_equivalent_to_the_box() {
    let mesh = liver();
    let m = fem::mesh::load(&mesh).unwrap();
    let dir = std::env::temp_dir().join(format!("host-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let list = dir.join("bed.txt");
    let ids: String = (0..m.nodes.len())
        .filter(|&i| m.nodes[i][2] <= 0.01)
        .map(|i| format!("{i}\n"))
        .collect();
    std::fs::write(&list, format!("# bed nodes\n{ids}")).unwrap();
    let common = [
        "compliance",
        "--mesh",
        mesh.to_str().unwrap(),
        "--young",
        "3000",
        "--poisson",
        "0.45",
        "--nodes",
        "700",
    ];
    let by_box = host(&[&common[..], &["--fix-box", BED]].concat());
    let by_file = host(&[&common[..], &["--fix-nodes", list.to_str().unwrap()]].concat());
    assert!(by_box.status.success() && by_file.status.success());
    assert_eq!(by_box.stdout, by_file.stdout);
    std::fs::remove_dir_all(&dir).unwrap();
}

fn fails_with(args: &[&str], needle: &str) {
    let out = host(args);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "expected failure for {args:?}");
    assert!(out.stdout.is_empty(), "nothing on stdout on failure");
    assert!(
        stderr.contains(needle),
        "stderr {stderr:?} should mention {needle:?}"
    );
    assert!(!stderr.contains("panicked"), "{stderr}");
}

#[test]
fn bad_input_is_reported_on_stderr_with_a_nonzero_exit() {
    let mesh = liver();
    let m = mesh.to_str().unwrap();
    let base = |extra: &[&'static str]| -> Vec<String> {
        let mut v: Vec<String> = [
            "compliance",
            "--mesh",
            m,
            "--young",
            "3000",
            "--poisson",
            "0.45",
        ]
        .iter()
        .map(|s| s.to_string())
        .collect();
        v.extend(extra.iter().map(|s| s.to_string()));
        v
    };
    let run = |extra: &[&'static str], needle: &str| {
        let v = base(extra);
        let refs: Vec<&str> = v.iter().map(String::as_str).collect();
        fails_with(&refs, needle);
    };
    run(&["--nodes", "1"], "nothing is fixed");
    run(
        &["--fix-box", "-1,-1,-1,1,1,1", "--nodes", "1"],
        "holds every node",
    );
    run(&["--fix-box", BED, "--nodes", "1,x"], "\"x\"");
    run(&["--fix-box", BED, "--nodes", "999999"], "node 999999");
    run(
        &["--fix-box", "5,5,5,6,6,6", "--nodes", "1"],
        "contains no node",
    );
    run(
        &["--fix-box", "0,0,0,1,1", "--nodes", "1"],
        "expected 6 numbers",
    );
    run(
        &["--fix-box", "-1,-1,-1,1,1,0.01:z", "--nodes", "700"],
        "rigid motions",
    );
    run(
        &[
            "--fix-box",
            BED,
            "--nodes",
            "700",
            "--fix-nodes",
            "/nonexistent/list",
        ],
        "/nonexistent/list",
    );
    fails_with(
        &[
            "compliance",
            "--mesh",
            "/nonexistent.msh",
            "--young",
            "1",
            "--poisson",
            "0.3",
            "--fix-box",
            BED,
            "--nodes",
            "0",
        ],
        "/nonexistent.msh",
    );
    fails_with(
        &[
            "compliance",
            "--mesh",
            m,
            "--young",
            "-3",
            "--poisson",
            "0.3",
            "--fix-box",
            BED,
            "--nodes",
            "0",
        ],
        "Young",
    );
    fails_with(
        &[
            "compliance",
            "--mesh",
            m,
            "--young",
            "3000",
            "--poisson",
            "0.5",
            "--fix-box",
            BED,
            "--nodes",
            "0",
        ],
        "Poisson",
    );
}

/// A malformed MSH 4.1 file on which the `mshio` parser panics (it subtracts 1 from a node
/// count of zero): the user sees one clean error, no panic message.
#[test]
fn malformed_msh41_prints_only_the_error() {
    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("bad.msh");
    std::fs::write(
        &bad,
        "$MeshFormat\n4.1 0 8\n$EndMeshFormat\n$Nodes\n1 0 1 1\n$EndNodes\n",
    )
    .unwrap();
    let out = host(&[
        "compliance",
        "--mesh",
        bad.to_str().unwrap(),
        "--young",
        "3000",
        "--poisson",
        "0.45",
        "--fix-box",
        BED,
        "--nodes",
        "0",
    ]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(stderr.contains("bad.msh"), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert_eq!(stderr.trim().lines().count(), 1, "{stderr}");
}

/// A little-endian ELF32 file with the given sections `(type, flags, address, size)`: the file
/// holds the headers, and then the word `first_word`, the contents of every section (`bench
/// image` reads the headers and the vector table's first word, the initial stack pointer).
fn elf32(sections: &[(u32, u32, u32, u32)], first_word: u32) -> Vec<u8> {
    let contents = 52 + 40 * (sections.len() as u32 + 1);
    let mut b = vec![0u8; 52];
    b[..7].copy_from_slice(&[0x7f, b'E', b'L', b'F', 1, 1, 1]); // ELF32, little-endian, version 1
    b[0x20..0x24].copy_from_slice(&52u32.to_le_bytes()); // e_shoff
    b[0x2e..0x30].copy_from_slice(&40u16.to_le_bytes()); // e_shentsize
    let shnum = sections.len() as u16 + 1;
    b[0x30..0x32].copy_from_slice(&shnum.to_le_bytes());
    b.extend_from_slice(&[0u8; 40]); // the null section
    for &(kind, flags, addr, size) in sections {
        let mut h = [0u8; 40];
        h[4..8].copy_from_slice(&kind.to_le_bytes());
        h[8..12].copy_from_slice(&flags.to_le_bytes());
        h[12..16].copy_from_slice(&addr.to_le_bytes());
        h[16..20].copy_from_slice(&contents.to_le_bytes());
        h[20..24].copy_from_slice(&size.to_le_bytes());
        b.extend_from_slice(&h);
    }
    b.extend_from_slice(&first_word.to_le_bytes());
    b
}

#[test]
fn bench_image_prints_flash_and_static_ram_against_memory_x() {
    use bank_format::region::{FIRMWARE_LEN, RAM_LEN, RAM_ORIGIN};
    const PROGBITS: u32 = 1;
    const NOBITS: u32 = 8;
    const ALLOC: u32 = 2;
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("image.elf");
    // .text 65,536 B in flash, starting with the initial stack pointer; .data 256 B (in RAM,
    // its initial values in flash); .bss 1,792 B; a debug section (not allocated) counts for
    // neither.
    let elf = elf32(
        &[
            (PROGBITS, ALLOC | 4, 0x0800_0000, 65_536),
            (PROGBITS, ALLOC | 1, RAM_ORIGIN, 256),
            (NOBITS, ALLOC | 1, RAM_ORIGIN + 256, 1_792),
            (PROGBITS, 0, 0, 99_999),
        ],
        0x1001_0000,
    );
    std::fs::write(&path, elf).unwrap();
    let out = host(&["bench", "image", path.to_str().unwrap()]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let ram_pct = 100.0 * 2_048.0 / RAM_LEN as f64;
    let flash_pct = 100.0 * 65_792.0 / FIRMWARE_LEN as f64;
    assert_eq!(
        String::from_utf8_lossy(&out.stdout),
        format!(
            "flash 65792 B of {FIRMWARE_LEN} B ({flash_pct:.1}%), static RAM 2048 B of \
             {RAM_LEN} B ({ram_pct:.1}%)\ninitial stack pointer 0x10010000\n"
        )
    );
    // No section at the flash origin: no vector table, an error saying so.
    std::fs::write(&path, elf32(&[(PROGBITS, ALLOC | 4, 0x0800_0100, 64)], 0)).unwrap();
    fails_with(
        &["bench", "image", path.to_str().unwrap()],
        "no vector table",
    );
    // Not an ELF file, and no file: an error naming it.
    std::fs::write(&path, b"not an elf").unwrap();
    fails_with(
        &["bench", "image", path.to_str().unwrap()],
        "not an ELF32 file",
    );
    fails_with(&["bench", "image", "/nonexistent/image.elf"], "cannot read");
}

/// Near-incompressible material: P1 locks. Above 0.499 the command refuses (saying why); above
/// 0.45 it warns with the expected stiffening; a Young's modulus that leaves no finite
/// compliance fails instead of printing `null`.
#[test]
fn locking_and_unrepresentable_materials_are_refused_or_warned() {
    let mesh = liver();
    let m = mesh.to_str().unwrap();
    let args = |young: &'static str, poisson: &'static str| {
        [
            "compliance",
            "--mesh",
            m,
            "--young",
            young,
            "--poisson",
            poisson,
            "--fix-box",
            BED,
            "--nodes",
            "700",
        ]
        .map(String::from)
    };
    let run = |young, poisson| {
        let a = args(young, poisson);
        host(&a.iter().map(String::as_str).collect::<Vec<_>>())
    };
    for nu in ["0.4999", "0.49999999"] {
        let out = run("3000", nu);
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success() && out.stdout.is_empty(), "{nu}");
        assert!(err.contains("lock") && err.contains("0.499"), "{err}");
    }
    let out = run("3000", "0.47");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    assert!(
        err.contains("warning") && err.contains("too stiff"),
        "{err}"
    );
    let out = run("3000", "0.45");
    assert!(out.status.success() && out.stderr.is_empty());
    let out = run("1e-310", "0.45");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && out.stdout.is_empty(), "{err}");
    assert!(err.contains("not finite"), "{err}");
}

/// A mesh in millimetres is computed (it may be what the user wants) but warned about.
#[test]
fn a_mesh_in_millimetres_is_warned_about() {
    let dir = tempfile::tempdir().unwrap();
    let mut mesh = fem::mesh::load(&liver()).unwrap();
    mesh.nodes.iter_mut().flatten().for_each(|x| *x *= 1000.0);
    let path = dir.path().join("liver-mm.msh");
    let mut f = std::fs::File::create(&path).unwrap();
    mesh.write_msh4_ascii(&mut f).unwrap();
    drop(f);
    let out = host(&[
        "compliance",
        "--mesh",
        path.to_str().unwrap(),
        "--young",
        "3000",
        "--poisson",
        "0.45",
        "--fix-box",
        "-1000,-1000,-1000,1000,1000,10",
        "--nodes",
        "700",
    ]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    assert!(err.contains("are its coordinates in metres"), "{err}");
    let out = host(&[
        "compliance",
        "--mesh",
        liver().to_str().unwrap(),
        "--young",
        "3000",
        "--poisson",
        "0.45",
        "--fix-box",
        BED,
        "--nodes",
        "700",
    ]);
    assert!(out.status.success() && out.stderr.is_empty());
}

/// `host sil --trajectory` with a bad file fails before QEMU starts, naming the file's line.
#[test]
fn sil_trajectory_file_errors_name_the_line() {
    let dir = tempfile::tempdir().unwrap();
    let bank = dir.path().join("patch.bank");
    std::fs::write(&bank, firmware::fixtures::flat_patch().as_slice()).unwrap();
    let csv = dir.path().join("hand.csv");
    std::fs::write(
        &csv,
        "t_s,pitch_rad,yaw_rad,insertion_m\n0,0,0,0.09\n0.5,0.1,0,0.09\n0.4,0,0,0.09\n",
    )
    .unwrap();
    let (b, c) = (bank.to_str().unwrap(), csv.to_str().unwrap());
    let args = [
        "sil",
        "--bank",
        b,
        "--image",
        "/nonexistent",
        "--trajectory",
        c,
    ];
    fails_with(&args, &format!("{c}:4: column \"t_s\" must increase"));
    fails_with(
        &[
            "sil",
            "--bank",
            b,
            "--image",
            "/nonexistent",
            "--trajectory",
            "/nonexistent.csv",
        ],
        "/nonexistent.csv: cannot read",
    );
}
