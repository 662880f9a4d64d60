//! The Madder cache reader (`io::cache::CacheReader`) on arbitrary bytes: open, then read
//! every field of every frame, plus the frames just outside the range and a missing field.
//! Must never panic, abort or allocate beyond the input; a file that opened reports
//! `Truncated` exactly for the frames from `truncated_at()` on, and never a missing
//! in-range frame (otherwise only checksums can fail per block).
//!
//! Checksums would stop the fuzzer at the header (any mutation of a count breaks the
//! header CRC), so the first input byte picks a mode: odd = repair every checksum of the
//! rest before writing it (reaches the code behind them), even = write the rest as is.
#![no_main]

use libfuzzer_sys::fuzz_target;
use madder::error::CacheError;
use madder::io::cache::CacheReader;

mod common;

/// Rewrites the header CRC and the CRC of every complete block, as the writer would.
fn repair_checksums(b: &mut [u8]) {
    if b.len() < 28 {
        return;
    }
    let word = |b: &[u8], i: usize| u32::from_le_bytes(b[i..i + 4].try_into().unwrap()) as u64;
    let (n_vertices, n_fields) = (word(b, 12), word(b, 16));
    let header = 28 + 32 * n_fields.min(64) as usize;
    if b.len() < header + 4 {
        return;
    }
    let crc = crc32fast::hash(&b[..header]);
    b[header..header + 4].copy_from_slice(&crc.to_le_bytes());
    let block = 8 + 4 * n_fields.min(64) * n_vertices;
    let mut at = header as u64 + 4;
    while at + block <= b.len() as u64 {
        let (s, e) = (at as usize, (at + block) as usize);
        let crc = crc32fast::hash(&b[s..e - 4]);
        b[e - 4..e].copy_from_slice(&crc.to_le_bytes());
        at += block;
    }
}

fuzz_target!(|input: &[u8]| {
    let Some((&mode, rest)) = input.split_first() else {
        return;
    };
    let mut data = rest.to_vec();
    if mode & 1 == 1 {
        repair_checksums(&mut data);
    }
    common::with_file(&data, "madder", |path| {
        let mut r = match CacheReader::open(path) {
            Ok(r) => r,
            Err(e) => {
                let _ = e.to_string();
                return;
            }
        };
        let names = r.field_names().to_vec();
        assert!(!names.is_empty() && r.n_vertices() >= 1);
        let (first, last) = (r.first_frame(), r.last_frame());
        assert_eq!(last as i64 - first as i64 + 1, r.n_frames() as i64);
        let cut = r.truncated_at().map_or(i64::MAX, i64::from);
        assert_eq!(
            cut.min(last as i64 + 1) - first as i64,
            r.complete_frames() as i64
        );
        // a short file may declare billions of frames: the cut ones past the first two
        // fail alike, so stop there
        let end = (last as i64).min(first as i64 + r.complete_frames() as i64 + 1);
        for frame in first as i64..=end {
            for name in &names {
                match r.read(frame as i32, name) {
                    Ok(v) => assert!(frame < cut && v.len() == r.n_vertices()),
                    Err(CacheError::Checksum { .. }) => assert!(frame < cut),
                    Err(CacheError::Truncated { first_cut, .. }) => {
                        assert!(frame >= cut && first_cut as i64 == cut)
                    }
                    Err(e) => panic!("frame {frame} of a cache that opened: {e}"),
                }
            }
        }
        for frame in [
            first.wrapping_sub(1),
            last.wrapping_add(1),
            i32::MIN,
            i32::MAX,
        ] {
            if !(first..=last).contains(&frame) {
                assert!(matches!(
                    r.read(frame, &names[0]),
                    Err(CacheError::FrameMissing { .. })
                ));
            }
        }
        assert!(matches!(
            r.read(first, "\0not a field"),
            Err(CacheError::FieldMissing { .. })
        ));
    });
});
