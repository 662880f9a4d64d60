//! The bake cache (`madder::io::cache`) when the file is damaged: cut at every byte offset,
//! or with one byte of any block flipped. The expected outcome of every case comes from
//! the layout documented in the module (header and block sizes), not from the reader: a
//! file cut anywhere after its header opens, each frame whose whole block is in the file
//! reads back exactly what was written, and every later frame is `Truncated`, naming the
//! frame read and the first frame cut. A flipped byte fails that frame's checksum only.

use std::path::{Path, PathBuf};

use madder::error::CacheError;
use madder::io::cache::{CacheReader, CacheWriter};

const N_VERTICES: usize = 3;
const FIELDS: [&str; 2] = ["solute", "wetness"];
const FIRST: i32 = -2; // negative on purpose: frame numbers are signed
const N_FRAMES: u32 = 5;
/// magic + 5 words + one 32-byte name per field + the header CRC
const HEADER: usize = 8 + 5 * 4 + 32 * FIELDS.len() + 4;
/// frame number + the fields' values + the block CRC
const BLOCK: usize = 4 + 4 * FIELDS.len() * N_VERTICES + 4;

fn tmpdir(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("madder-cache-it-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Field `k` of frame index `i` (distinct, exactly representable values).
fn values(i: usize, k: usize) -> Vec<f32> {
    (0..N_VERTICES)
        .map(|v| (100 * i + 10 * k + v) as f32 + 0.25)
        .collect()
}

fn write(path: &Path) -> Vec<u8> {
    let mut w = CacheWriter::create(path, N_VERTICES, &FIELDS, FIRST, N_FRAMES).unwrap();
    for i in 0..N_FRAMES as usize {
        let (a, b) = (values(i, 0), values(i, 1));
        w.push_frame(&[&a, &b]).unwrap();
    }
    w.finish().unwrap();
    let bytes = std::fs::read(path).unwrap();
    assert_eq!(bytes.len(), HEADER + N_FRAMES as usize * BLOCK, "layout");
    bytes
}

#[test]
fn a_cache_cut_at_any_byte_keeps_every_whole_frame() {
    let d = tmpdir("cut");
    let p = d.join("cut.madder");
    let bytes = write(&p);
    for len in 0..bytes.len() {
        std::fs::write(&p, &bytes[..len]).unwrap();
        let opened = CacheReader::open(&p);
        if len < HEADER {
            match opened {
                Err(e @ CacheError::Header { .. }) => assert!(e.to_string().contains("cut.madder")),
                other => panic!("cut at {len}: expected a header error, got {other:?}"),
            }
            continue;
        }
        let mut r = opened.unwrap_or_else(|e| panic!("cut at {len}: {e}"));
        let whole = (len - HEADER) / BLOCK;
        let first_cut = FIRST + whole as i32;
        assert_eq!(r.complete_frames() as usize, whole, "cut at {len}");
        assert_eq!(r.truncated_at(), Some(first_cut), "cut at {len}");
        assert_eq!((r.first_frame(), r.n_frames()), (FIRST, N_FRAMES));
        for i in 0..N_FRAMES as usize {
            let frame = FIRST + i as i32;
            if i < whole {
                assert_eq!(r.read(frame, "solute").unwrap(), values(i, 0));
                assert_eq!(
                    r.read_frame(frame).unwrap(),
                    [values(i, 0), values(i, 1)].concat()
                );
            } else {
                let e = r.read_frame(frame).unwrap_err();
                match &e {
                    CacheError::Truncated {
                        frame: f,
                        first_cut: c,
                        ..
                    } => {
                        assert_eq!((*f, *c), (frame, first_cut), "cut at {len}");
                    }
                    other => panic!("cut at {len}, frame {frame}: {other:?}"),
                }
                let msg = e.to_string();
                assert!(msg.contains("cut.madder"), "{msg}");
                assert!(
                    msg.contains(&format!("truncated at frame {first_cut}")),
                    "{msg}"
                );
            }
        }
    }
    // the whole file: nothing is cut
    std::fs::write(&p, &bytes).unwrap();
    let r = CacheReader::open(&p).unwrap();
    assert_eq!((r.truncated_at(), r.complete_frames()), (None, N_FRAMES));
    // one byte too many is not a file this writer made
    std::fs::write(&p, [&bytes[..], &[0u8]].concat()).unwrap();
    assert!(matches!(
        CacheReader::open(&p),
        Err(CacheError::Header { .. })
    ));
}

#[test]
fn a_flipped_byte_fails_only_its_own_frame() {
    let d = tmpdir("flip");
    let p = d.join("flip.madder");
    let bytes = write(&p);
    for at in HEADER..bytes.len() {
        let mut bad = bytes.clone();
        bad[at] ^= 0x10;
        std::fs::write(&p, &bad).unwrap();
        let mut r = CacheReader::open(&p).unwrap();
        assert_eq!(r.truncated_at(), None);
        let damaged = FIRST + ((at - HEADER) / BLOCK) as i32;
        for i in 0..N_FRAMES as usize {
            let frame = FIRST + i as i32;
            if frame == damaged {
                let e = r.read_frame(frame).unwrap_err();
                assert!(
                    matches!(e, CacheError::Checksum { frame: f, .. } if f == frame),
                    "byte {at}: {e}"
                );
                assert!(e.to_string().contains(&format!("frame {frame}")));
            } else {
                assert_eq!(r.read(frame, "wetness").unwrap(), values(i, 1), "byte {at}");
            }
        }
    }
}
