//! The angle codec's motion-file reader (`angles::MotionDecoder`) on arbitrary bytes: open,
//! read every frame forwards, then backwards (the replay path), then one past the end.
//! Must never panic, abort or allocate beyond the input; a file that opened never reports
//! `Truncated` afterwards (open checks every block), and reads the same bits twice.
//!
//! The first byte picks a mode, as for `cache_reader`: odd = repair the header checksum
//! and every frame block's checksum first (so mutations reach the entropy decoder and the
//! reconstruction), even = the rest as is.
#![no_main]

use libfuzzer_sys::fuzz_target;
use madder::CodecError;
use madder::angles::MotionDecoder;

mod common;

fn repair_checksums(b: &mut [u8]) {
    if b.len() < 48 {
        return;
    }
    let word = |b: &[u8], i: usize| u32::from_le_bytes(b[i..i + 4].try_into().unwrap()) as usize;
    let n_faces = word(b, 16).min(b.len() / 12);
    let header = 48 + 12 * n_faces;
    if b.len() < header {
        return;
    }
    let mut h = crc32fast::Hasher::new();
    h.update(&b[..44]);
    h.update(&b[48..header]);
    let crc = h.finalize();
    b[44..48].copy_from_slice(&crc.to_le_bytes());
    let mut at = header;
    while at + 8 <= b.len() {
        let size = word(b, at);
        if at + 8 + size > b.len() {
            break;
        }
        let crc = crc32fast::hash(&b[at + 8..at + 8 + size]);
        b[at + 4..at + 8].copy_from_slice(&crc.to_le_bytes());
        at += 8 + size;
    }
}

fuzz_target!(|data: &[u8]| {
    let Some((&mode, rest)) = data.split_first() else {
        return;
    };
    let mut bytes = rest.to_vec();
    if mode & 1 == 1 {
        repair_checksums(&mut bytes);
    }
    common::with_file(&bytes, "madm", |path| match MotionDecoder::open(path) {
        Ok(mut d) => {
            let n = d.n_frames();
            assert_eq!(d.frame_times().len(), n);
            let forward: Vec<_> = (0..n).map(|k| d.read_frame(k)).collect();
            for (k, r) in forward.iter().enumerate().rev() {
                let again = d.read_frame(k);
                match (r, &again) {
                    (Ok(a), Ok(b)) => assert_eq!(a, b, "frame {k} read twice differs"),
                    (Err(CodecError::Truncated { .. }), _)
                    | (_, Err(CodecError::Truncated { .. })) => {
                        panic!("a file that opened reported a truncated frame {k}")
                    }
                    _ => {}
                }
                if let Err(e) = again {
                    let _ = e.to_string();
                }
            }
            assert!(matches!(
                d.read_frame(n),
                Err(CodecError::FrameOutOfRange { .. })
            ));
        }
        Err(e) => {
            let _ = e.to_string();
        }
    });
});
