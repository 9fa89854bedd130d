//! Fuzz the streaming frame decoder (both message directions, small and default buffers) and
//! `decode_frame`. Any message that decodes must re-encode to a frame that decodes to a message
//! with the same encoding.
#![no_main]

use bank_format::{
    DeviceToHost, FrameDecoder, HostToDevice, MAX_FRAME, decode_frame, encode_frame,
};
use libfuzzer_sys::fuzz_target;

fn reencode<M: serde::Serialize + serde::de::DeserializeOwned>(msg: &M) {
    let mut buf = [0u8; MAX_FRAME];
    let frame = encode_frame(msg, &mut buf)
        .expect("a decoded message re-encodes")
        .to_vec();
    let mut copy = frame.clone();
    let again: M = decode_frame(&mut copy).expect("a re-encoded message decodes");
    let mut buf2 = [0u8; MAX_FRAME];
    assert_eq!(encode_frame(&again, &mut buf2).unwrap(), &frame[..]);
}

fuzz_target!(|data: &[u8]| {
    let mut d1 = FrameDecoder::<DeviceToHost>::new();
    let mut results = 0u32;
    for r in d1.feed_slice(data) {
        results += 1;
        if let Ok(m) = r {
            reencode(&m);
        }
    }
    let s = d1.stats();
    assert_eq!(results, s.ok + s.errors());

    let mut d2 = FrameDecoder::<HostToDevice, 48>::new();
    for r in d2.feed_slice(data) {
        if let Ok(m) = r {
            reencode(&m);
        }
    }
    let mut copy = data.to_vec();
    let _ = decode_frame::<HostToDevice>(&mut copy);
});
