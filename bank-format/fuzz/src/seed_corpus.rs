//! Writes seed inputs for the fuzz targets: the tests' valid 4-node bank, in f32 and in bfp16
//! (plain and with the "reseal" mode byte), and one frame of each message kind. Run from `bank-format/fuzz`.

#[path = "../../tests/common/mod.rs"]
#[allow(dead_code, clippy::needless_range_loop)]
mod common;

use bank_format::{
    DeviceToHost, FaultReason, HostToDevice, MAX_FRAME, Mode, State, encode_frame,
};
use std::fs;

fn main() -> std::io::Result<()> {
    fs::create_dir_all("corpus/bank_parse")?;
    fs::create_dir_all("corpus/frame_decode")?;
    let bank = common::valid_bytes();
    for mode in [0u8, 1] {
        let mut seed = vec![mode];
        seed.extend_from_slice(&bank);
        fs::write(format!("corpus/bank_parse/seed-valid-{mode}"), seed)?;
    }
    // The same bank with 16-bit coupling blocks (section kind 20).
    let bfp16 = common::builder()
        .build_with_precision(bank_format::Precision::Bfp16)
        .map_err(std::io::Error::other)?;
    for mode in [0u8, 1] {
        let mut seed = vec![mode];
        seed.extend_from_slice(&bfp16);
        fs::write(format!("corpus/bank_parse/seed-valid-bfp16-{mode}"), seed)?;
    }
    let mut all = Vec::new();
    let mut buf = [0u8; MAX_FRAME];
    let device = [
        DeviceToHost::Hello {
            protocol: 1,
            bank_crc: Some(7),
            scene_id: 9,
            node_count: 4,
        },
        DeviceToHost::Plant {
            tick: 3,
            currents_a: [0.1, 0.2, 0.3],
            force_n: [0.0, 0.0, 1.5],
            state: State::Armed,
            contact_nodes: 3,
            body_cycles: 2500,
            tick_cycles: 9000,
            phase_cycles: bank_format::PhaseCycles {
                kinematics: 300,
                detection: 900,
                patch: 600,
                solve: 200,
                law: 250,
                supervisor: 250,
            },
        },
        DeviceToHost::Fault {
            tick: 5,
            reason: FaultReason::Overrun,
            detail: 0,
        },
    ];
    for (i, m) in device.iter().enumerate() {
        let f = encode_frame(m, &mut buf).unwrap();
        all.extend_from_slice(f);
        fs::write(format!("corpus/frame_decode/seed-dev-{i}"), &f[..])?;
    }
    let host = [
        HostToDevice::Arm,
        HostToDevice::SetMode(Mode::ConstantCurrent {
            currents_a: [0.5, 0.0, 0.0],
        }),
        HostToDevice::Plant {
            tick: 1,
            encoder_counts: [1, -1, 100],
        },
    ];
    for (i, m) in host.iter().enumerate() {
        let f = encode_frame(m, &mut buf).unwrap();
        all.extend_from_slice(f);
        fs::write(format!("corpus/frame_decode/seed-host-{i}"), &f[..])?;
    }
    fs::write("corpus/frame_decode/seed-stream", all)?;
    Ok(())
}
