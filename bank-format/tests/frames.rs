//! Link frames: round trip of every message variant, corruption, truncation, oversize, resync.

use bank_format::{
    CRC32, Contact, ContactPoint, Counters, DeviceToHost, FaultReason, FrameDecoder, FrameError,
    FrameStats, HostToDevice, MAX_CONTACTS, MAX_FRAME, MAX_MESSAGE, Mode, PROTOCOL_VERSION,
    ResetCause, State, Telemetry, decode_frame, encode_frame,
};

fn full_telemetry() -> Telemetry {
    let mut contacts = heapless::Vec::new();
    for i in 0..MAX_CONTACTS {
        contacts
            .push(Contact {
                node: u16::MAX - i as u16,
                force_n: [f32::MAX, -1.5e-3, 0.25],
            })
            .unwrap();
    }
    Telemetry {
        tick: u32::MAX,
        state: State::Fault,
        mode: Mode::ConstantCurrent {
            currents_a: [1.0, -2.0, 0.5],
        },
        fault: Some(FaultReason::SolveFailed),
        tip_m: [0.01, -0.02, 0.03],
        contacts,
        contact_point: Some(ContactPoint {
            triangle: u32::MAX,
            bary: [0.25, 0.5, 0.25],
        }),
        currents_a: [0.1, 0.2, -0.3],
        tool_force_n: [0.5, -0.25, 4.0],
        dropped_load: 0.125,
        counters: Counters {
            rx_frames: u32::MAX,
            rx_errors: u32::MAX,
            overruns: u32::MAX,
            max_tick_cycles: u32::MAX,
            tx_dropped: u32::MAX,
            rx_dropped: u32::MAX,
            capped_ticks: u32::MAX,
            rebuilds_failed: u32::MAX,
        },
    }
}

fn device_messages() -> Vec<DeviceToHost> {
    let mut small = full_telemetry();
    small.contacts.clear();
    small.fault = None;
    small.state = State::Armed;
    small.mode = Mode::Render;
    vec![
        DeviceToHost::Hello {
            protocol: PROTOCOL_VERSION,
            bank_crc: Some(0xDEAD_BEEF),
            scene_id: u64::MAX,
            node_count: 1234,
        },
        DeviceToHost::Hello {
            protocol: PROTOCOL_VERSION,
            bank_crc: None,
            scene_id: 0,
            node_count: 0,
        },
        DeviceToHost::Telemetry(full_telemetry()),
        DeviceToHost::Telemetry(small),
        DeviceToHost::Plant {
            tick: 17,
            currents_a: [0.5, -0.25, 1.0e-6],
            force_n: [-1.0, 0.0, 4.75],
            state: State::Fault,
            contact_nodes: 8,
            body_cycles: u32::MAX,
            tick_cycles: 0,
            phase_cycles: bank_format::PhaseCycles {
                kinematics: 1,
                detection: u32::MAX,
                patch: 127,
                solve: 128,
                law: 0,
                supervisor: 16_384,
            },
        },
        DeviceToHost::Fault {
            tick: 99,
            reason: FaultReason::InvalidBank,
            detail: 27,
        },
        DeviceToHost::Fault {
            tick: 100,
            reason: FaultReason::AmplifierFault,
            detail: 2,
        },
        DeviceToHost::Fault {
            tick: 101,
            reason: FaultReason::Overspeed,
            detail: 3,
        },
        DeviceToHost::Fault {
            tick: 102,
            reason: FaultReason::AmplifierRange,
            detail: 1,
        },
        DeviceToHost::Fault {
            tick: 103,
            reason: FaultReason::BrownOutLevel,
            detail: 0,
        },
        DeviceToHost::Reset {
            cause: ResetCause::BrownOut,
        },
        DeviceToHost::Reset {
            cause: ResetCause::Unknown,
        },
    ]
}

fn host_messages() -> Vec<HostToDevice> {
    vec![
        HostToDevice::Hello,
        HostToDevice::Heartbeat,
        HostToDevice::Arm,
        HostToDevice::Disarm,
        HostToDevice::SetMode(Mode::Render),
        HostToDevice::SetMode(Mode::LinearLaw),
        HostToDevice::SetMode(Mode::Transparent),
        HostToDevice::SetMode(Mode::ConstantCurrent {
            currents_a: [0.1, 0.0, -0.1],
        }),
        HostToDevice::ZeroEncoders,
        HostToDevice::ClearFault,
        HostToDevice::Plant {
            tick: 5,
            encoder_counts: [i32::MIN, -1, i32::MAX],
        },
    ]
}

#[test]
fn every_message_variant_round_trips() {
    let mut buf = [0u8; MAX_FRAME];
    let mut dec = FrameDecoder::<DeviceToHost>::new();
    for msg in device_messages() {
        let frame = encode_frame(&msg, &mut buf).unwrap();
        assert_eq!(*frame.last().unwrap(), 0);
        assert!(!frame[..frame.len() - 1].contains(&0));
        let mut got = None;
        for &b in frame.iter() {
            if let Some(r) = dec.feed(b) {
                got = Some(r);
            }
        }
        assert_eq!(got, Some(Ok(msg)));
    }
    let mut dec = FrameDecoder::<HostToDevice>::new();
    for msg in host_messages() {
        let frame = encode_frame(&msg, &mut buf).unwrap();
        let results: Vec<_> = dec.feed_slice(frame).collect();
        assert_eq!(results, vec![Ok(msg)]);
    }
    assert_eq!(dec.stats().ok, host_messages().len() as u32);
    assert_eq!(dec.stats().errors(), 0);
}

/// The variant order is the wire protocol: the reasons added in protocols 3, 4, 5 and 6 come
/// after the earlier ones, whose indices stay what a deployed host decodes.
#[test]
fn fault_reasons_keep_their_wire_indices() {
    let reasons = [
        FaultReason::Nan,
        FaultReason::InvalidBank,
        FaultReason::LinkSilent,
        FaultReason::Overrun,
        FaultReason::EncoderJump,
        FaultReason::CurrentLimit,
        FaultReason::JointLimit,
        FaultReason::SolveFailed,
        FaultReason::EStop,
        FaultReason::AmplifierFault,
        FaultReason::Overspeed,
        FaultReason::BadCommand,
        FaultReason::WatchdogReset,
        FaultReason::NotReferenced,
        FaultReason::AmplifierRange,
        FaultReason::BrownOutLevel,
    ];
    for (index, reason) in reasons.into_iter().enumerate() {
        let bytes = postcard::to_slice(&reason, &mut [0u8; 8]).unwrap().to_vec();
        assert_eq!(bytes, [index as u8], "{reason:?}");
    }
    assert_eq!(PROTOCOL_VERSION, 7);
}

#[test]
fn the_largest_message_fits_max_message_and_max_frame() {
    let msg = DeviceToHost::Telemetry(full_telemetry());
    let body = postcard::to_slice(&msg, &mut [0u8; 1024]).unwrap().len();
    assert!(
        body <= 241,
        "telemetry grew to {body} bytes: update MAX_MESSAGE docs"
    );
    assert!(body <= MAX_MESSAGE);
    let mut buf = [0u8; MAX_FRAME];
    let frame = encode_frame(&msg, &mut buf).unwrap();
    assert!(frame.len() <= MAX_FRAME);
}

#[test]
fn frame_is_cobs_of_postcard_plus_crc32() {
    let msg = HostToDevice::Arm;
    let body = postcard::to_slice(&msg, &mut [0u8; 16]).unwrap().to_vec();
    let mut payload = body.clone();
    payload.extend_from_slice(&CRC32.checksum(&body).to_le_bytes());
    let mut expected = vec![0u8; payload.len() + 2];
    let n = cobs::try_encode(&payload, &mut expected).unwrap();
    expected.truncate(n);
    expected.push(0);
    let mut buf = [0u8; MAX_FRAME];
    assert_eq!(encode_frame(&msg, &mut buf).unwrap(), &expected[..]);
    // decode_frame accepts the frame with or without its delimiter.
    let mut copy = expected.clone();
    assert_eq!(decode_frame::<HostToDevice>(&mut copy), Ok(msg.clone()));
    let mut copy = expected[..expected.len() - 1].to_vec();
    assert_eq!(decode_frame::<HostToDevice>(&mut copy), Ok(msg));
}

#[test]
fn small_buffer_is_an_error_not_a_panic() {
    let msg = DeviceToHost::Telemetry(full_telemetry());
    for len in 0..40 {
        let mut buf = vec![0u8; len];
        assert_eq!(
            encode_frame(&msg, &mut buf).map(|f| f.len()),
            Err(FrameError::BufferTooSmall)
        );
    }
}

fn encoded<M: serde::Serialize>(msg: &M) -> Vec<u8> {
    let mut buf = [0u8; MAX_FRAME];
    encode_frame(msg, &mut buf).unwrap().to_vec()
}

#[test]
fn a_corrupt_byte_is_counted_and_the_next_frame_decodes() {
    let msg = DeviceToHost::Telemetry(full_telemetry());
    let good = encoded(&msg);
    // Flip every payload byte in turn (never into 0x00, which would split the frame).
    for i in 0..good.len() - 1 {
        let mut bad = good.clone();
        bad[i] ^= if bad[i] == 0x01 { 0x03 } else { 0x01 };
        let mut dec = FrameDecoder::<DeviceToHost>::new();
        let mut stream = bad.clone();
        stream.extend_from_slice(&good);
        let results: Vec<_> = dec.feed_slice(&stream).collect();
        assert_eq!(results.len(), 2, "byte {i}");
        assert!(results[0].is_err(), "byte {i}: corrupt frame accepted");
        assert_eq!(results[1], Ok(msg.clone()), "byte {i}: no resync");
        let stats = dec.stats();
        assert_eq!(stats.ok, 1);
        assert_eq!(stats.errors(), 1);
    }
    // A payload byte flipped (not a COBS code byte): specifically a CRC error.
    let mut bad = good.clone();
    let last_data = bad.len() - 3;
    bad[last_data] ^= 0x40;
    if bad[last_data] == 0 {
        bad[last_data] = 0x41;
    }
    let mut dec = FrameDecoder::<DeviceToHost>::new();
    let results: Vec<_> = dec.feed_slice(&bad).collect();
    assert_eq!(results, vec![Err(FrameError::Crc)]);
    assert_eq!(dec.stats().crc, 1);
}

#[test]
fn a_truncated_frame_is_dropped_and_the_next_one_decodes() {
    let msg = HostToDevice::Plant {
        tick: 123_456,
        encoder_counts: [1, -2, 300_000],
    };
    let good = encoded(&msg);
    for cut in 0..good.len() - 1 {
        let mut dec = FrameDecoder::<HostToDevice>::new();
        // A sender that restarts sends a 0x00 first, which ends the partial frame.
        let mut stream = good[..cut].to_vec();
        stream.push(0);
        stream.extend_from_slice(&good);
        let results: Vec<_> = dec.feed_slice(&stream).collect();
        let last = results.last().cloned();
        assert_eq!(last, Some(Ok(msg.clone())), "cut at {cut}");
        if cut == 0 {
            assert_eq!(results.len(), 1, "an empty frame is ignored");
        } else {
            assert_eq!(results.len(), 2);
            assert!(results[0].is_err());
        }
        assert_eq!(dec.stats().errors(), u32::from(cut > 0));
    }
    // A truncated frame glued to the next one (no delimiter in between) fails as one frame,
    // and the decoder is back in sync for the frame after.
    let mut dec = FrameDecoder::<HostToDevice>::new();
    let mut stream = good[..good.len() / 2].to_vec();
    stream.extend_from_slice(&good);
    stream.extend_from_slice(&good);
    let results: Vec<_> = dec.feed_slice(&stream).collect();
    assert_eq!(results.len(), 2);
    assert!(results[0].is_err());
    assert_eq!(results[1], Ok(msg));
}

#[test]
fn short_frames_are_reported_as_too_short() {
    let mut dec = FrameDecoder::<HostToDevice>::new();
    // COBS of 3 bytes: decodes, but has no room for a message plus CRC.
    let results: Vec<_> = dec.feed_slice(&[4, 1, 2, 3, 0]).collect();
    assert_eq!(results, vec![Err(FrameError::TooShort)]);
    // Repeated delimiters are not frames.
    let results: Vec<_> = dec.feed_slice(&[0, 0, 0]).collect();
    assert!(results.is_empty());
    assert_eq!(dec.stats().short, 1);
}

#[test]
fn oversize_frames_are_dropped_and_counted() {
    let msg = HostToDevice::Heartbeat;
    let good = encoded(&msg);
    let mut dec = FrameDecoder::<HostToDevice, 32>::new();
    let mut stream = vec![0x55u8; 1000];
    stream.push(0);
    stream.extend_from_slice(&good);
    let results: Vec<_> = dec.feed_slice(&stream).collect();
    assert_eq!(results, vec![Err(FrameError::Oversize), Ok(msg)]);
    assert_eq!(
        dec.stats(),
        FrameStats {
            ok: 1,
            oversize: 1,
            ..FrameStats::default()
        }
    );
    // A frame exactly filling the buffer is fine, one byte more is not.
    let arm = encoded(&HostToDevice::Arm);
    assert_eq!(
        arm.len() - 1,
        6,
        "1 byte of postcard + 4 of CRC, plus 1 of COBS"
    );
    let mut exact = FrameDecoder::<HostToDevice, 6>::new();
    assert_eq!(
        exact.feed_slice(&arm).collect::<Vec<_>>(),
        vec![Ok(HostToDevice::Arm)]
    );
    let mut small = FrameDecoder::<HostToDevice, 5>::new();
    assert_eq!(
        small.feed_slice(&arm).collect::<Vec<_>>(),
        vec![Err(FrameError::Oversize)]
    );
}

#[test]
fn wrong_message_type_is_malformed() {
    // A valid frame of the other direction: CRC fine, postcard says otherwise.
    let frame = encoded(&DeviceToHost::Telemetry(full_telemetry()));
    let mut dec = FrameDecoder::<HostToDevice>::new();
    let results: Vec<_> = dec.feed_slice(&frame).collect();
    assert_eq!(results, vec![Err(FrameError::Malformed)]);
    assert_eq!(dec.stats().malformed, 1);
    // Trailing bytes after a complete message are malformed too.
    let body = [2u8, 0xAA]; // `Arm` followed by a stray byte
    let mut payload = body.to_vec();
    payload.extend_from_slice(&CRC32.checksum(&body).to_le_bytes());
    let mut out = vec![0u8; payload.len() + 2];
    let n = cobs::try_encode(&payload, &mut out).unwrap();
    out.truncate(n);
    out.push(0);
    assert_eq!(
        dec.feed_slice(&out).collect::<Vec<_>>(),
        vec![Err(FrameError::Malformed)]
    );
}

#[test]
fn reset_drops_a_partial_frame() {
    let good = encoded(&HostToDevice::Arm);
    let mut dec = FrameDecoder::<HostToDevice>::new();
    assert_eq!(dec.feed_slice(&good[..2]).count(), 0);
    dec.reset();
    assert_eq!(
        dec.feed_slice(&good).collect::<Vec<_>>(),
        vec![Ok(HostToDevice::Arm)]
    );
}

#[test]
fn plant_messages_are_a_length_byte_and_postcard() {
    use bank_format::{decode_plant, encode_plant};
    let msg = HostToDevice::Plant {
        tick: 300,
        encoder_counts: [-1, 0, i32::MAX],
    };
    let mut buf = [0u8; 64];
    let bytes = encode_plant(&msg, &mut buf).unwrap().to_vec();
    let body = postcard::to_slice(&msg, &mut [0u8; 64]).unwrap().to_vec();
    assert_eq!(usize::from(bytes[0]), body.len());
    assert_eq!(bytes[1..], body[..]);
    assert_eq!(decode_plant::<HostToDevice>(&bytes[1..]).unwrap(), msg);
    // Refused: empty, truncated, trailing bytes; a buffer too small to encode into.
    assert_eq!(decode_plant::<HostToDevice>(&[]), Err(FrameError::TooShort));
    assert_eq!(
        decode_plant::<HostToDevice>(&bytes[1..bytes.len() - 1]),
        Err(FrameError::Malformed)
    );
    let mut long = bytes[1..].to_vec();
    long.push(0);
    assert_eq!(
        decode_plant::<HostToDevice>(&long),
        Err(FrameError::Malformed)
    );
    assert_eq!(
        encode_plant(&msg, &mut [0u8; 4]),
        Err(FrameError::BufferTooSmall)
    );
    // The image's largest reply (every varint at its longest) is 72 bytes, within the 127
    // its plant channel allows for (firmware/qemu/src/plant.rs).
    let m = u32::MAX;
    let reply = DeviceToHost::Plant {
        tick: m,
        currents_a: [f32::MAX; 3],
        force_n: [f32::MAX; 3],
        state: State::Fault,
        contact_nodes: u8::MAX,
        body_cycles: m,
        tick_cycles: m,
        phase_cycles: bank_format::PhaseCycles {
            kinematics: m,
            detection: m,
            patch: m,
            solve: m,
            law: m,
            supervisor: m,
        },
    };
    let mut buf = [0u8; 256];
    assert_eq!(encode_plant(&reply, &mut buf).unwrap().len(), 1 + 72);
}

/// The phases' array form, names and fields agree (the host's code-phase tables index by it).
#[test]
fn phase_cycles_array_order_is_the_names_order() {
    let p = bank_format::PhaseCycles::from_array([1, 2, 3, 4, 5, 6]);
    assert_eq!(
        (
            p.kinematics,
            p.detection,
            p.patch,
            p.solve,
            p.law,
            p.supervisor
        ),
        (1, 2, 3, 4, 5, 6)
    );
    assert_eq!(p.to_array(), [1, 2, 3, 4, 5, 6]);
    assert_eq!(p.total(), 21);
    assert_eq!(
        bank_format::PhaseCycles::NAMES,
        [
            "kinematics",
            "detection",
            "patch",
            "solve",
            "law",
            "supervisor"
        ]
    );
}
