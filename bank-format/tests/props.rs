//! Property tests: the reader and the frame decoder never panic (and so never read out of
//! bounds: every access is checked) on arbitrary input; banks and frames round trip.
#![allow(clippy::needless_range_loop)] // index loops read best for 3x3 blocks

mod common;

use bank_format::{
    AlignedBytes, Bank, BankBuilder, Contact, ContactPoint, Counters, DeviceToHost, FaultReason,
    FrameDecoder, HostToDevice, MAGIC, MAX_CONTACTS, MAX_FRAME, Mode, ResetCause, State, Telemetry,
    decode_frame, encode_frame, reseal,
};
use common::*;
use proptest::prelude::*;

/// Touch everything a firmware could touch, including out-of-range indices.
fn exercise(bank: &Bank<'_>, probe: [f32; 3]) {
    let n = bank.node_count();
    assert!((1..=65535).contains(&n));
    assert_eq!(bank.positions().len(), n);
    assert_eq!(bank.mesh_ids().len(), n);
    for tri in bank.triangles() {
        for &v in tri {
            assert!(usize::from(v) < n);
        }
    }
    for k in 0..=n {
        let _ = bank.c_kk(k);
        let _ = bank.c_kk_matrix(k);
        for &t in bank.node_triangles(k) {
            assert!(bank.triangles()[t as usize].contains(&(k as u16)));
        }
        let ls = bank.neighbours(k);
        for &l in ls {
            assert!(usize::from(l) < n);
            assert!(bank.coupling(usize::from(l), k).is_some());
            assert!(bank.coupling(k, usize::from(l)).is_some());
        }
        let _ = bank.coupling(k, (k + 1) % (n + 1));
    }
    let g = bank.grid();
    for c in 0..=g.cell_count() {
        for &i in g.cell_items(c) {
            assert!(usize::from(i) < n);
        }
    }
    let _ = bank.nearest_node(probe);
    let _ = g.cell_of(probe);
    let law = bank.tissue_law();
    let _ = (law.eval(probe[0]), law.slope(probe[1]));
    let _ = bank.device();
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 2000, ..ProptestConfig::default() })]

    #[test]
    fn parse_never_panics_on_arbitrary_bytes(bytes in proptest::collection::vec(any::<u8>(), 0..2048)) {
        let aligned = AlignedBytes::new(&bytes);
        if let Ok(bank) = Bank::parse(&aligned) {
            exercise(&bank, [0.0; 3]);
        }
    }

    #[test]
    fn parse_never_panics_on_arbitrary_bytes_behind_a_header(
        tail in proptest::collection::vec(any::<u8>(), 0..2048),
        sections in 0u16..40,
        seal in any::<bool>(),
    ) {
        let mut bytes = MAGIC.to_vec();
        bytes.extend_from_slice(&1u16.to_le_bytes());
        bytes.extend_from_slice(&0u16.to_le_bytes());
        bytes.extend_from_slice(&32u16.to_le_bytes());
        bytes.extend_from_slice(&sections.to_le_bytes());
        let total = (32 + tail.len()) / 8 * 8;
        bytes.extend_from_slice(&(total as u32).to_le_bytes());
        bytes.extend_from_slice(&[0; 12]);
        bytes.extend_from_slice(&tail);
        if seal {
            reseal(&mut bytes);
        }
        let aligned = AlignedBytes::new(&bytes);
        if let Ok(bank) = Bank::parse(&aligned) {
            exercise(&bank, [0.0; 3]);
        }
    }

    #[test]
    fn mutated_valid_banks_never_panic(
        edits in proptest::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 1..8),
        seal in any::<bool>(),
        cut in proptest::option::of(any::<prop::sample::Index>()),
        probe in proptest::array::uniform3(-0.05f32..0.05),
    ) {
        let mut bytes = valid_bytes();
        for (i, v) in &edits {
            let at = i.index(bytes.len());
            bytes[at] = *v;
        }
        if seal {
            reseal(&mut bytes);
        }
        if let Some(c) = cut {
            let keep = c.index(bytes.len() + 1);
            bytes.truncate(keep);
        }
        let aligned = AlignedBytes::new(&bytes);
        if let Ok(bank) = Bank::parse(&aligned) {
            exercise(&bank, probe);
        }
    }

    #[test]
    fn mutated_f32_fields_never_panic(
        edits in proptest::collection::vec((any::<prop::sample::Index>(), any::<f32>()), 1..4),
    ) {
        // Whole f32 words replaced (NaN, infinities, denormals, huge values) behind a valid CRC.
        let mut bytes = valid_bytes();
        for (i, v) in &edits {
            let at = (i.index(bytes.len() - 32) + 32) / 4 * 4;
            put_f32(&mut bytes, at, *v);
        }
        reseal(&mut bytes);
        let aligned = AlignedBytes::new(&bytes);
        if let Ok(bank) = Bank::parse(&aligned) {
            exercise(&bank, [*edits[0].1.to_bits().to_le_bytes().first().unwrap() as f32 * 1e-3; 3]);
        }
    }
}

#[test]
fn huge_truncation_radius_does_not_overflow() {
    // Regression (cargo-fuzz): a radius of f32::MAX made the grid search's floor overflow.
    for r in [f32::MAX, 1.0e30, 3.0e38] {
        let mut bytes = valid_bytes();
        let (_, off, ..) = section(&bytes, bank_format::SectionKind::Meta);
        put_f32(&mut bytes, off + 8, r);
        reseal(&mut bytes);
        assert_eq!(
            parse(&bytes),
            Err(bank_format::BankError::MissingNeighbour {
                node: 1,
                neighbour: 3
            })
        );
    }
}

/// Random well-formed banks: jittered lattice points (never closer than 3 mm), a positive
/// definite kernel compliance, every pair within the radius and every triangle edge coupled.
fn random_builder(
    sites: Vec<(u8, u8, u8)>,
    jitter: Vec<[f64; 3]>,
    tris: Vec<(usize, usize, usize)>,
    radius: f64,
    cell: f64,
) -> Option<BankBuilder> {
    let mut seen = std::collections::BTreeSet::new();
    let mut pos = Vec::new();
    for (s, j) in sites.iter().zip(&jitter) {
        if seen.insert(*s) {
            pos.push([
                0.005 * f64::from(s.0) + j[0],
                0.005 * f64::from(s.1) + j[1],
                0.005 * f64::from(s.2) + j[2],
            ]);
        }
    }
    let n = pos.len();
    let dist = |a: usize, b: usize| -> f64 {
        (0..3)
            .map(|i| (pos[a][i] - pos[b][i]).powi(2))
            .sum::<f64>()
            .sqrt()
    };
    let m = [
        [1.0e-3, 0.2e-3, 0.1e-3],
        [0.2e-3, 1.5e-3, 0.0],
        [0.1e-3, 0.0, 0.8e-3],
    ];
    let blk = |a: usize, b: usize| -> [[f64; 3]; 3] {
        let k = (-dist(a, b) / 0.01).exp();
        m.map(|row| row.map(|v| k * v))
    };
    let mut triangles = Vec::new();
    let mut pairs = std::collections::BTreeSet::new();
    for &(a, b, c) in &tris {
        let (a, b, c) = (a % n, b % n, c % n);
        if a != b && b != c && a != c {
            triangles.push([a as u32, b as u32, c as u32]);
            for (x, y) in [(a, b), (b, c), (a, c)] {
                pairs.insert((x.min(y), x.max(y)));
            }
        }
    }
    for a in 0..n {
        for b in a + 1..n {
            if dist(a, b) <= radius {
                pairs.insert((a, b));
            }
        }
    }
    if n == 0 {
        return None;
    }
    Some(BankBuilder {
        positions_m: pos.clone(),
        mesh_ids: (0..n as u32).map(|i| i * 3 + 1).collect(),
        triangles,
        c_kk: (0..n).map(|k| blk(k, k)).collect(),
        couplings: pairs
            .iter()
            .map(|&(a, b)| (a as u32, b as u32, blk(a, b)))
            .collect(),
        grid_cell_size_m: cell,
        truncation_radius_m: radius,
        scene_id: n as u64,
        law: law(),
        gravity: None,
        relaxation: None,
        samples: None,
        device: device(),
    })
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 200, ..ProptestConfig::default() })]

    #[test]
    fn random_banks_round_trip(
        sites in proptest::collection::vec((0u8..8, 0u8..8, 0u8..4), 1..60),
        jitter in proptest::collection::vec(proptest::array::uniform3(-0.001f64..0.001), 60),
        tris in proptest::collection::vec((0usize..60, 0usize..60, 0usize..60), 0..40),
        radius in 0.0f64..0.012,
        cell in 0.002f64..0.05,
    ) {
        let Some(b) = random_builder(sites, jitter, tris, radius, cell) else { return Ok(()); };
        // Random banks may exceed the tick's limits (candidates per cell, triangles per
        // node): round-trip without them, and check that the bounded builder and reader agree
        // on which banks those are.
        let bytes = b
            .build_unbounded(bank_format::Precision::F32)
            .expect("a well-formed random bank builds");
        let aligned = AlignedBytes::new(&bytes);
        let bank = Bank::parse_unbounded(&aligned).unwrap();
        prop_assert_eq!(b.build().is_ok(), Bank::parse(&aligned).is_ok());
        prop_assert_eq!(bank.node_count(), b.positions_m.len());
        for (k, p) in b.positions_m.iter().enumerate() {
            prop_assert_eq!(bank.positions()[k], p.map(|v| v as f32));
            // Its own position finds the node (or one at distance zero).
            let (_, d2) = bank.nearest_node(bank.positions()[k]).unwrap();
            prop_assert_eq!(d2, 0.0);
        }
        for &(k, l, c) in &b.couplings {
            let got = bank.coupling(k as usize, l as usize).unwrap();
            let back = bank.coupling(l as usize, k as usize).unwrap();
            for i in 0..3 {
                for j in 0..3 {
                    prop_assert_eq!(got[i][j], c[i][j] as f32);
                    prop_assert_eq!(back[j][i], got[i][j]);
                }
            }
        }
        let edges: usize = (0..bank.node_count()).map(|k| bank.neighbours(k).len()).sum();
        prop_assert_eq!(edges, 2 * b.couplings.len());
        // Each triangle's plane is the writer's rule on its stored vertices, and SPEC.md's
        // identities hold (in f64 from the stored plane): at x = 0.2 a + 0.3 b + 0.5 c + h n / |n|
        // the plane value is h / |n| and the division-free coordinates are (0.2, 0.3, 0.5).
        prop_assert_eq!(bank.triangle_planes().len(), bank.triangles().len());
        for (plane, tri) in bank.triangle_planes().iter().zip(bank.triangles()) {
            let [a, b, c] = tri.map(|k| bank.positions()[usize::from(k)]);
            prop_assert_eq!(*plane, bank_format::triangle_plane(a, b, c));
            let [a, b, c] = [a, b, c].map(|v| v.map(f64::from));
            let n = cross(sub(b, a), sub(c, a));
            let len = dot(n, n).sqrt();
            let h = 0.001;
            let x: [f64; 3] =
                std::array::from_fn(|i| 0.2 * a[i] + 0.3 * b[i] + 0.5 * c[i] + h * n[i] / len);
            let m = plane.m.map(f64::from);
            let s = dot(m, x) - f64::from(plane.off);
            prop_assert!((s * len - h).abs() <= 1e-5 * h, "plane value {} for {}", s * len, h);
            let k1 = dot(cross(sub(x, a), sub(c, a)), m);
            let k2 = dot(cross(sub(b, a), sub(x, a)), m);
            let k0 = dot(cross(sub(c, b), sub(x, b)), m);
            for (got, want) in [(k0, 0.2), (k1, 0.3), (k2, 0.5)] {
                prop_assert!((got - want).abs() <= 1e-5, "{:?}", (k0, k1, k2));
            }
        }
        exercise(&bank, [0.01, 0.01, 0.01]);
    }
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    std::array::from_fn(|i| a[i] - b[i])
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    (0..3).map(|i| a[i] * b[i]).sum()
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn f32_finite() -> impl Strategy<Value = f32> {
    -1.0e3f32..1.0e3
}

fn mode() -> impl Strategy<Value = Mode> {
    prop_oneof![
        Just(Mode::Render),
        Just(Mode::LinearLaw),
        Just(Mode::Transparent),
        proptest::array::uniform3(f32_finite())
            .prop_map(|c| Mode::ConstantCurrent { currents_a: c }),
    ]
}

fn fault() -> impl Strategy<Value = FaultReason> {
    prop_oneof![
        Just(FaultReason::Nan),
        Just(FaultReason::InvalidBank),
        Just(FaultReason::LinkSilent),
        Just(FaultReason::Overrun),
        Just(FaultReason::EncoderJump),
        Just(FaultReason::CurrentLimit),
        Just(FaultReason::JointLimit),
        Just(FaultReason::SolveFailed),
        Just(FaultReason::EStop),
        Just(FaultReason::AmplifierFault),
        Just(FaultReason::Overspeed),
        Just(FaultReason::BadCommand),
        Just(FaultReason::WatchdogReset),
        Just(FaultReason::NotReferenced),
        Just(FaultReason::AmplifierRange),
        Just(FaultReason::BrownOutLevel),
    ]
}

fn device_msg() -> impl Strategy<Value = DeviceToHost> {
    let state = prop_oneof![
        Just(State::Disarmed),
        Just(State::Armed),
        Just(State::Fault)
    ];
    let contacts = proptest::collection::vec(
        (any::<u16>(), proptest::array::uniform3(f32_finite())),
        0..=MAX_CONTACTS,
    );
    let telemetry = (
        any::<u32>(),
        state,
        mode(),
        proptest::option::of(fault()),
        proptest::array::uniform3(f32_finite()),
        contacts,
        proptest::option::of((any::<u32>(), proptest::array::uniform3(f32_finite()))),
        proptest::array::uniform3(f32_finite()),
        proptest::array::uniform3(f32_finite()),
        f32_finite(),
        proptest::array::uniform8(any::<u32>()),
    )
        .prop_map(
            |(
                tick,
                state,
                mode,
                fault,
                tip_m,
                contacts,
                point,
                currents_a,
                tool_force_n,
                dropped_load,
                c,
            )| {
                DeviceToHost::Telemetry(Telemetry {
                    tick,
                    state,
                    mode,
                    fault,
                    tip_m,
                    contacts: contacts
                        .into_iter()
                        .map(|(node, force_n)| Contact { node, force_n })
                        .collect(),
                    contact_point: point.map(|(triangle, bary)| ContactPoint { triangle, bary }),
                    currents_a,
                    tool_force_n,
                    dropped_load,
                    counters: Counters {
                        rx_frames: c[0],
                        rx_errors: c[1],
                        overruns: c[2],
                        max_tick_cycles: c[3],
                        tx_dropped: c[4],
                        rx_dropped: c[5],
                        capped_ticks: c[6],
                        rebuilds_failed: c[7],
                    },
                })
            },
        );
    prop_oneof![
        (
            any::<u16>(),
            any::<Option<u32>>(),
            any::<u64>(),
            any::<u16>()
        )
            .prop_map(
                |(protocol, bank_crc, scene_id, node_count)| DeviceToHost::Hello {
                    protocol,
                    bank_crc,
                    scene_id,
                    node_count
                }
            ),
        telemetry,
        (
            any::<u32>(),
            proptest::array::uniform3(f32_finite()),
            proptest::array::uniform3(f32_finite()),
            prop_oneof![
                Just(State::Disarmed),
                Just(State::Armed),
                Just(State::Fault)
            ],
            any::<u8>(),
            (any::<(u32, u32)>(), any::<[u32; 6]>())
        )
            .prop_map(
                |(
                    tick,
                    currents_a,
                    force_n,
                    state,
                    contact_nodes,
                    ((body_cycles, tick_cycles), p),
                )| {
                    DeviceToHost::Plant {
                        tick,
                        currents_a,
                        force_n,
                        state,
                        contact_nodes,
                        body_cycles,
                        tick_cycles,
                        phase_cycles: bank_format::PhaseCycles {
                            kinematics: p[0],
                            detection: p[1],
                            patch: p[2],
                            solve: p[3],
                            law: p[4],
                            supervisor: p[5],
                        },
                    }
                }
            ),
        (any::<u32>(), fault(), any::<u32>()).prop_map(|(tick, reason, detail)| {
            DeviceToHost::Fault {
                tick,
                reason,
                detail,
            }
        }),
        prop_oneof![
            Just(ResetCause::PowerOn),
            Just(ResetCause::Pin),
            Just(ResetCause::BrownOut),
            Just(ResetCause::Software),
            Just(ResetCause::IndependentWatchdog),
            Just(ResetCause::WindowWatchdog),
            Just(ResetCause::LowPower),
            Just(ResetCause::Unknown),
        ]
        .prop_map(|cause| DeviceToHost::Reset { cause }),
    ]
}

fn host_msg() -> impl Strategy<Value = HostToDevice> {
    prop_oneof![
        Just(HostToDevice::Hello),
        Just(HostToDevice::Heartbeat),
        Just(HostToDevice::Arm),
        Just(HostToDevice::Disarm),
        mode().prop_map(HostToDevice::SetMode),
        Just(HostToDevice::ZeroEncoders),
        Just(HostToDevice::ClearFault),
        (any::<u32>(), proptest::array::uniform3(any::<i32>())).prop_map(
            |(tick, encoder_counts)| HostToDevice::Plant {
                tick,
                encoder_counts
            }
        ),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 2000, ..ProptestConfig::default() })]

    #[test]
    fn decoder_never_panics_on_arbitrary_streams(
        stream in proptest::collection::vec(
            prop_oneof![3 => Just(0u8), 20 => any::<u8>()], 0..4096),
    ) {
        let mut d1 = FrameDecoder::<DeviceToHost>::new();
        let mut d2 = FrameDecoder::<HostToDevice, 64>::new();
        let n1 = d1.feed_slice(&stream).count() as u32;
        let n2 = d2.feed_slice(&stream).count() as u32;
        prop_assert_eq!(n1, d1.stats().ok + d1.stats().errors());
        prop_assert_eq!(n2, d2.stats().ok + d2.stats().errors());
        let mut copy = stream.clone();
        let _ = decode_frame::<DeviceToHost>(&mut copy);
    }

    #[test]
    fn device_messages_round_trip(msg in device_msg()) {
        let mut buf = [0u8; MAX_FRAME];
        let frame = encode_frame(&msg, &mut buf).unwrap().to_vec();
        let mut dec = FrameDecoder::<DeviceToHost>::new();
        let got: Vec<_> = dec.feed_slice(&frame).collect();
        prop_assert_eq!(got, vec![Ok(msg)]);
    }

    #[test]
    fn host_messages_round_trip(msg in host_msg()) {
        let mut buf = [0u8; MAX_FRAME];
        let frame = encode_frame(&msg, &mut buf).unwrap().to_vec();
        let mut dec = FrameDecoder::<HostToDevice>::new();
        let got: Vec<_> = dec.feed_slice(&frame).collect();
        prop_assert_eq!(got, vec![Ok(msg)]);
    }

    #[test]
    fn a_corrupted_frame_never_yields_a_wrong_message(
        msg in device_msg(),
        at in any::<prop::sample::Index>(),
        flip in 1u8..=255,
        next in host_msg(),
    ) {
        let mut buf = [0u8; MAX_FRAME];
        let mut frame = encode_frame(&msg, &mut buf).unwrap().to_vec();
        let i = at.index(frame.len() - 1);
        frame[i] ^= flip;
        let mut dec = FrameDecoder::<DeviceToHost>::new();
        for r in dec.feed_slice(&frame) {
            // A flipped byte can split the frame; no piece may decode as a message at all
            // (CRC-32 catches every error burst of up to 32 bits).
            prop_assert!(r.is_err(), "corruption at {} accepted: {:?}", i, r);
        }
        // And the decoder is in sync for what follows.
        let mut d2 = FrameDecoder::<HostToDevice>::new();
        frame.extend_from_slice(encode_frame(&next, &mut buf).unwrap());
        let got: Vec<_> = d2.feed_slice(&frame).collect();
        prop_assert_eq!(got.last().cloned(), Some(Ok(next)));
    }
}
