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
/// magic + 5 words + the frame time (f64, version 2) + one 32-byte name per field + the
/// header CRC
const HEADER: usize = 8 + 5 * 4 + 8 + 32 * FIELDS.len() + 4;
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

/// The fields a bake with Bake Flow on writes (the add-on's `bridge.FLOW_FIELDS`): the
/// stain's three, then the liquid's velocity and the cloth's positions per vertex.
const FLOW_FIELDS: [&str; 9] = [
    "solute",
    "wetness",
    "deposit",
    "velocity_x",
    "velocity_y",
    "velocity_z",
    "position_x",
    "position_y",
    "position_z",
];

#[test]
fn velocity_and_frame_time_round_trip() {
    let d = tmpdir("flow");
    let p = d.join("flow.madder");
    let n = 4;
    // f32 values whose bits must survive: negatives, subnormal, tiny and large
    let value = |i: usize, k: usize, v: usize| -> f32 {
        let base = [-3.5e-7f32, 1.0e-40, 2.75, -1.0e6][v];
        base * (1.0 + i as f32) + (k as f32) * 0.125
    };
    let dt = 1.0 / 24.0;
    let mut w = CacheWriter::create_timed(&p, n, &FLOW_FIELDS, 7, 3, dt).unwrap();
    for i in 0..3 {
        let fields: Vec<Vec<f32>> = (0..FLOW_FIELDS.len())
            .map(|k| (0..n).map(|v| value(i, k, v)).collect())
            .collect();
        let refs: Vec<&[f32]> = fields.iter().map(Vec::as_slice).collect();
        w.push_frame(&refs).unwrap();
    }
    w.finish().unwrap();
    let bytes = std::fs::read(&p).unwrap();
    assert_eq!(
        bytes.len(),
        8 + 5 * 4 + 8 + 32 * 9 + 4 + 3 * (4 + 4 * 9 * n + 4),
        "version-2 layout"
    );
    let mut r = CacheReader::open(&p).unwrap();
    assert_eq!(r.version(), 2);
    assert_eq!(r.frame_time(), Some(dt));
    assert_eq!(r.field_names(), FLOW_FIELDS);
    for i in 0..3 {
        for (k, name) in FLOW_FIELDS.iter().enumerate() {
            let got = r.read(7 + i as i32, name).unwrap();
            let want: Vec<f32> = (0..n).map(|v| value(i, k, v)).collect();
            assert_eq!(
                got.iter().map(|x| x.to_bits()).collect::<Vec<_>>(),
                want.iter().map(|x| x.to_bits()).collect::<Vec<_>>(),
                "frame {} field {name}",
                7 + i
            );
        }
    }
    // no frame time recorded: None, and a bad one is refused before anything is written
    let q = d.join("untimed.madder");
    let mut w = CacheWriter::create(&q, 1, &["solute"], 0, 1).unwrap();
    w.push_frame(&[&[1.0]]).unwrap();
    w.finish().unwrap();
    assert_eq!(CacheReader::open(&q).unwrap().frame_time(), None);
    for bad in [f64::NAN, -0.5, f64::INFINITY] {
        let e = CacheWriter::create_timed(d.join("bad.madder"), 1, &["s"], 0, 1, bad)
            .err()
            .unwrap_or_else(|| panic!("frame time {bad} accepted"));
        assert!(e.to_string().contains("frame time"), "{e}");
    }
}

/// A version-1 file (Madder before the LCS tools), built byte by byte from the layout
/// version 1 had: the same header without `frame_time`. It still opens and reads; it has
/// no frame time and no velocity field, and asking for one names the field and the file.
#[test]
fn a_version_1_cache_still_reads() {
    let d = tmpdir("v1");
    let p = d.join("old.madder");
    let names = ["solute", "wetness", "deposit"];
    let (n, first, frames) = (2usize, 3i32, 2u32);
    let mut h = b"MADDERC\0".to_vec();
    for w in [1u32, n as u32, names.len() as u32, first as u32, frames] {
        h.extend_from_slice(&w.to_le_bytes());
    }
    for name in names {
        let mut field = [0u8; 32];
        field[..name.len()].copy_from_slice(name.as_bytes());
        h.extend_from_slice(&field);
    }
    let crc = crc32fast::hash(&h);
    h.extend_from_slice(&crc.to_le_bytes());
    let value = |i: usize, k: usize, v: usize| (10 * i + 3 * k + v) as f32 * 0.5;
    for i in 0..frames as usize {
        let mut block = (first + i as i32).to_le_bytes().to_vec();
        for k in 0..names.len() {
            for v in 0..n {
                block.extend_from_slice(&value(i, k, v).to_le_bytes());
            }
        }
        let crc = crc32fast::hash(&block);
        block.extend_from_slice(&crc.to_le_bytes());
        h.extend_from_slice(&block);
    }
    std::fs::write(&p, &h).unwrap();
    let mut r = CacheReader::open(&p).unwrap();
    assert_eq!(r.version(), 1);
    assert_eq!(r.frame_time(), None);
    assert_eq!(r.field_names(), names);
    assert_eq!((r.first_frame(), r.last_frame()), (3, 4));
    for i in 0..2 {
        for (k, name) in names.iter().enumerate() {
            let want: Vec<f32> = (0..n).map(|v| value(i, k, v)).collect();
            assert_eq!(r.read(3 + i as i32, name).unwrap(), want);
        }
    }
    let e = r.read(3, "velocity_x").unwrap_err();
    assert!(matches!(e, CacheError::FieldMissing { .. }), "{e}");
    assert!(
        e.to_string().contains("velocity_x") && e.to_string().contains("old.madder"),
        "{e}"
    );
    // the playback read-out works on it as before
    let (mut rgba, mut wet, mut dep) = (vec![0.0; 4 * n], vec![0.0; n], vec![0.0; n]);
    r.read_stain(
        4, [100.0; 3], [1.0; 3], true, &mut rgba, &mut wet, &mut dep, None,
    )
    .unwrap();
    assert_eq!(wet, vec![value(1, 1, 0) / 100.0, value(1, 1, 1) / 100.0]);
}
