//! PC2 and MDD point caches (`madder::io::point_cache`): byte-level fixtures written out by
//! hand (independent of the writers), round trips, endianness, and the errors that name the
//! file, frame and vertex.

use std::path::{Path, PathBuf};

use madder::io::point_cache::{
    Format, Pc2Writer, PointCache, PointCacheError, Timing, write_mdd, write_pc2,
};

fn tmpdir(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("madder-pc-test-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Two frames of two points, every coordinate exactly representable and distinct.
const FRAMES: [[[f32; 3]; 2]; 2] = [
    [[1.0, -2.0, 0.5], [0.25, 3.0, 10.0]],
    [[-1.5, 100.0, 0.125], [1.5, 0.0, -2.0]],
];

/// Their IEEE-754 bit patterns, most significant byte first.
const BITS: [[[u32; 3]; 2]; 2] = [
    [
        [0x3F80_0000, 0xC000_0000, 0x3F00_0000],
        [0x3E80_0000, 0x4040_0000, 0x4120_0000],
    ],
    [
        [0xBFC0_0000, 0x42C8_0000, 0x3E00_0000],
        [0x3FC0_0000, 0x0000_0000, 0xC000_0000],
    ],
];

/// PC2 fixture, every byte spelled out little-endian: 2 points, start 10.0, rate 0.5,
/// 2 frames, then [`FRAMES`].
fn pc2_fixture() -> Vec<u8> {
    let mut b: Vec<u8> = Vec::new();
    b.extend_from_slice(b"POINTCACHE2\0");
    b.extend_from_slice(&[0x01, 0x00, 0x00, 0x00]); // version 1
    b.extend_from_slice(&[0x02, 0x00, 0x00, 0x00]); // 2 points
    b.extend_from_slice(&[0x00, 0x00, 0x20, 0x41]); // start 10.0
    b.extend_from_slice(&[0x00, 0x00, 0x00, 0x3F]); // rate 0.5
    b.extend_from_slice(&[0x02, 0x00, 0x00, 0x00]); // 2 frames
    // frame 0: (1, -2, 0.5), (0.25, 3, 10)
    b.extend_from_slice(&[
        0x00, 0x00, 0x80, 0x3F, 0x00, 0x00, 0x00, 0xC0, 0x00, 0x00, 0x00, 0x3F,
    ]);
    b.extend_from_slice(&[
        0x00, 0x00, 0x80, 0x3E, 0x00, 0x00, 0x40, 0x40, 0x00, 0x00, 0x20, 0x41,
    ]);
    // frame 1: (-1.5, 100, 0.125), (1.5, 0, -2)
    b.extend_from_slice(&[
        0x00, 0x00, 0xC0, 0xBF, 0x00, 0x00, 0xC8, 0x42, 0x00, 0x00, 0x00, 0x3E,
    ]);
    b.extend_from_slice(&[
        0x00, 0x00, 0xC0, 0x3F, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0xC0,
    ]);
    assert_eq!(b.len(), 32 + 2 * 2 * 12);
    b
}

/// MDD fixture, every byte spelled out big-endian: 2 frames, 2 points, times 0.0 s and
/// 0.5 s, then [`FRAMES`].
fn mdd_fixture() -> Vec<u8> {
    let mut b: Vec<u8> = Vec::new();
    b.extend_from_slice(&[0x00, 0x00, 0x00, 0x02]); // 2 frames
    b.extend_from_slice(&[0x00, 0x00, 0x00, 0x02]); // 2 points
    b.extend_from_slice(&[0x00, 0x00, 0x00, 0x00]); // t0 = 0.0 s
    b.extend_from_slice(&[0x3F, 0x00, 0x00, 0x00]); // t1 = 0.5 s
    // frame 0: (1, -2, 0.5), (0.25, 3, 10)
    b.extend_from_slice(&[
        0x3F, 0x80, 0x00, 0x00, 0xC0, 0x00, 0x00, 0x00, 0x3F, 0x00, 0x00, 0x00,
    ]);
    b.extend_from_slice(&[
        0x3E, 0x80, 0x00, 0x00, 0x40, 0x40, 0x00, 0x00, 0x41, 0x20, 0x00, 0x00,
    ]);
    // frame 1: (-1.5, 100, 0.125), (1.5, 0, -2)
    b.extend_from_slice(&[
        0xBF, 0xC0, 0x00, 0x00, 0x42, 0xC8, 0x00, 0x00, 0x3E, 0x00, 0x00, 0x00,
    ]);
    b.extend_from_slice(&[
        0x3F, 0xC0, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0xC0, 0x00, 0x00, 0x00,
    ]);
    assert_eq!(b.len(), 8 + 2 * 4 + 2 * 2 * 12);
    b
}

fn write_bytes(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, bytes).unwrap();
    p
}

/// Bit-exact comparison (also distinguishes -0.0 and NaN payloads).
fn bits(frame: &[[f32; 3]]) -> Vec<[u32; 3]> {
    frame.iter().map(|p| p.map(f32::to_bits)).collect()
}

#[test]
fn the_constants_match_their_bit_patterns() {
    for (f, b) in FRAMES.iter().zip(BITS.iter()) {
        assert_eq!(bits(f), b.to_vec());
    }
}

#[test]
fn pc2_hand_built_fixture_reads_back() {
    let d = tmpdir("pc2-fixture");
    let p = write_bytes(&d, "cloth.pc2", &pc2_fixture());
    let mut c = PointCache::open(&p).unwrap();
    assert_eq!(c.format(), Format::Pc2);
    assert_eq!((c.n_points(), c.n_frames()), (2, 2));
    assert_eq!(
        c.timing(),
        &Timing::Frames {
            start: 10.0,
            rate: 0.5
        }
    );
    assert_eq!(c.frame_times(), vec![10.0, 10.5]);
    assert_eq!(c.trailing_bytes(), 0);
    c.check_times().unwrap();
    // random access, in reverse order
    assert_eq!(bits(&c.read_frame(1).unwrap()), BITS[1].to_vec());
    assert_eq!(bits(&c.read_frame(0).unwrap()), BITS[0].to_vec());
}

#[test]
fn mdd_hand_built_fixture_reads_back() {
    let d = tmpdir("mdd-fixture");
    let p = write_bytes(&d, "cloth.mdd", &mdd_fixture());
    let mut c = PointCache::open(&p).unwrap();
    assert_eq!(c.format(), Format::Mdd);
    assert_eq!((c.n_points(), c.n_frames()), (2, 2));
    assert_eq!(c.timing(), &Timing::Seconds(vec![0.0, 0.5]));
    assert_eq!(c.frame_times(), vec![0.0, 0.5]);
    c.check_times().unwrap();
    assert_eq!(bits(&c.read_frame(1).unwrap()), BITS[1].to_vec());
    assert_eq!(bits(&c.read_frame(0).unwrap()), BITS[0].to_vec());
}

#[test]
fn writers_produce_the_fixtures_byte_for_byte() {
    // Endianness both ways: the readers decode the hand-written bytes (tests above), and the
    // writers reproduce them exactly — PC2 little-endian, MDD big-endian.
    let d = tmpdir("endian");
    let pc2 = d.join("w.pc2");
    write_pc2(&pc2, 10.0, 0.5, &FRAMES).unwrap();
    assert_eq!(std::fs::read(&pc2).unwrap(), pc2_fixture());
    let mdd = d.join("w.mdd");
    write_mdd(&mdd, &[0.0, 0.5], &FRAMES).unwrap();
    assert_eq!(std::fs::read(&mdd).unwrap(), mdd_fixture());

    // Swapping the payloads: PC2's little-endian coordinates behind an MDD header read as
    // the byte-swapped values, and vice versa.
    let mut swapped = mdd_fixture()[..16].to_vec();
    swapped.extend_from_slice(&pc2_fixture()[32..]);
    let p = d.join("swapped.mdd");
    std::fs::write(&p, &swapped).unwrap();
    let got = PointCache::open(&p).unwrap().read_frame(0);
    let want: Vec<[u32; 3]> = BITS[0].iter().map(|p| p.map(u32::swap_bytes)).collect();
    // frame 0 swapped holds no NaN/Inf: the largest exponent byte there is 0x41
    assert_eq!(bits(&got.unwrap()), want);
    let mut swapped = pc2_fixture()[..32].to_vec();
    swapped.extend_from_slice(&mdd_fixture()[16..]);
    let p = d.join("swapped.pc2");
    std::fs::write(&p, &swapped).unwrap();
    let got = PointCache::open(&p).unwrap().read_frame(0).unwrap();
    assert_eq!(bits(&got), want);
}

/// A deterministic cloth: `n_frames` frames of `n_points` points with values that exercise
/// signs, magnitudes and subnormals.
fn cloth(n_frames: usize, n_points: usize) -> Vec<Vec<[f32; 3]>> {
    (0..n_frames)
        .map(|f| {
            (0..n_points)
                .map(|v| {
                    let t = (f * 131 + v * 17) as f32;
                    [
                        (t * 0.37).sin() * 3.0,
                        -(t * 1.0e-3) + v as f32,
                        if v == 1 {
                            f32::MIN_POSITIVE / 4.0
                        } else {
                            t * 1.0e4
                        },
                    ]
                })
                .collect()
        })
        .collect()
}

#[test]
fn pc2_round_trip() {
    let d = tmpdir("pc2-rt");
    let p = d.join("a.pc2");
    let frames = cloth(7, 50);
    write_pc2(&p, -3.0, 0.25, &frames).unwrap();
    assert_eq!(std::fs::metadata(&p).unwrap().len(), 32 + 7 * 50 * 12);
    let mut c = PointCache::open(&p).unwrap();
    assert_eq!((c.n_points(), c.n_frames()), (50, 7));
    assert_eq!(
        c.frame_times(),
        vec![-3.0, -2.75, -2.5, -2.25, -2.0, -1.75, -1.5]
    );
    for k in (0..7).rev() {
        assert_eq!(
            bits(&c.read_frame(k).unwrap()),
            bits(&frames[k]),
            "frame {k}"
        );
    }
}

#[test]
fn mdd_round_trip() {
    let d = tmpdir("mdd-rt");
    let p = d.join("a.mdd");
    let frames = cloth(5, 33);
    let times: Vec<f32> = (0..5).map(|k| k as f32 / 24.0).collect();
    write_mdd(&p, &times, &frames).unwrap();
    assert_eq!(
        std::fs::metadata(&p).unwrap().len(),
        8 + 5 * 4 + 5 * 33 * 12
    );
    let mut c = PointCache::open(&p).unwrap();
    assert_eq!((c.n_points(), c.n_frames()), (33, 5));
    assert_eq!(c.timing(), &Timing::Seconds(times.clone()));
    for k in [3, 0, 4, 1, 2] {
        assert_eq!(
            bits(&c.read_frame(k).unwrap()),
            bits(&frames[k]),
            "frame {k}"
        );
    }
    assert!(matches!(
        c.read_frame(5),
        Err(PointCacheError::FrameOutOfRange {
            frame: 5,
            n_frames: 5,
            ..
        })
    ));
}

fn truncated_frame(p: &Path) -> usize {
    match PointCache::open(p) {
        Err(e @ PointCacheError::Truncated { frame, .. }) => {
            let msg = e.to_string();
            assert!(msg.contains(&p.display().to_string()), "{msg}");
            assert!(
                msg.contains(&format!("frame {frame} is incomplete")),
                "{msg}"
            );
            frame
        }
        other => panic!("expected Truncated, got {other:?}"),
    }
}

#[test]
fn truncated_files_name_the_first_incomplete_frame() {
    let d = tmpdir("trunc");
    // PC2: 3 frames of 2 points, 24 bytes each, after a 32-byte header.
    let p = d.join("t.pc2");
    write_pc2(&p, 1.0, 1.0, &cloth(3, 2)).unwrap();
    let full = std::fs::read(&p).unwrap();
    for (len, frame) in [(32, 0), (40, 0), (56, 1), (79, 1), (80, 2), (103, 2)] {
        std::fs::write(&p, &full[..len]).unwrap();
        assert_eq!(truncated_frame(&p), frame, "cut at {len} bytes");
    }
    std::fs::write(&p, &full[..20]).unwrap();
    let e = PointCache::open(&p).unwrap_err();
    assert!(matches!(e, PointCacheError::Header { .. }), "{e}");
    assert!(e.to_string().contains("20 bytes"), "{e}");

    // MDD: 3 frames of 2 points; time table bytes 8..20, data from 20.
    let p = d.join("t.mdd");
    write_mdd(&p, &[0.0, 1.0, 2.0], &cloth(3, 2)).unwrap();
    let full = std::fs::read(&p).unwrap();
    // cut in the time table: the first frame without a time is incomplete
    for (len, frame) in [(8, 0), (13, 1), (19, 2), (20, 0), (44, 1), (91, 2)] {
        std::fs::write(&p, &full[..len]).unwrap();
        assert_eq!(truncated_frame(&p), frame, "cut at {len} bytes");
    }
}

#[test]
fn a_file_cut_after_open_names_the_frame_at_read_time() {
    let d = tmpdir("shrink");
    let p = d.join("s.pc2");
    write_pc2(&p, 1.0, 1.0, &cloth(3, 4)).unwrap();
    let mut c = PointCache::open(&p).unwrap();
    let f = std::fs::OpenOptions::new().write(true).open(&p).unwrap();
    f.set_len(32 + 2 * 48 + 10).unwrap();
    assert!(c.read_frame(1).is_ok());
    assert!(matches!(
        c.read_frame(2),
        Err(PointCacheError::Truncated { frame: 2, .. })
    ));
}

#[test]
fn corrupt_headers_are_named() {
    let d = tmpdir("header");
    let good = pc2_fixture();
    let open = |name: &str, bytes: &[u8]| PointCache::open(write_bytes(&d, name, bytes));

    let mut bad = good.clone();
    bad[3] = b'X';
    let e = open("sig.pc2", &bad).unwrap_err();
    assert!(matches!(e, PointCacheError::BadSignature { .. }), "{e}");
    assert!(e.to_string().contains("sig.pc2"), "{e}");
    assert!(matches!(
        open("text.pc2", b"hello").unwrap_err(),
        PointCacheError::BadSignature { .. }
    ));

    let mut bad = good.clone();
    bad[12] = 2;
    let e = open("version.pc2", &bad).unwrap_err();
    assert!(
        matches!(e, PointCacheError::Version { found: 2, .. }),
        "{e}"
    );
    assert!(e.to_string().contains("version.pc2"), "{e}");

    let header_reason = |name: &str, bytes: &[u8]| match open(name, bytes) {
        Err(e @ PointCacheError::Header { .. }) => {
            assert!(e.to_string().contains(name), "{e}");
            e.to_string()
        }
        other => panic!("{name}: expected a header error, got {other:?}"),
    };
    let with = |at: usize, word: [u8; 4]| {
        let mut b = good.clone();
        b[at..at + 4].copy_from_slice(&word);
        b
    };
    assert!(header_reason("neg.pc2", &with(16, (-5i32).to_le_bytes())).contains("-5 points"));
    assert!(header_reason("zero.pc2", &with(28, 0i32.to_le_bytes())).contains("0 frames"));
    let mut huge = with(16, i32::MAX.to_le_bytes());
    huge[28..32].copy_from_slice(&i32::MAX.to_le_bytes());
    assert!(header_reason("huge.pc2", &huge).contains("overflows 64 bits"));

    let mdd = |frames: i32, points: i32| {
        let mut b = frames.to_be_bytes().to_vec();
        b.extend_from_slice(&points.to_be_bytes());
        b.extend_from_slice(&[0; 40]);
        b
    };
    assert!(header_reason("neg.mdd", &mdd(-1, 2)).contains("-1 frames"));
    assert!(header_reason("zero.mdd", &mdd(2, 0)).contains("0 points"));
    assert!(header_reason("huge.mdd", &mdd(i32::MAX, i32::MAX)).contains("overflows 64 bits"));
    assert!(header_reason("short.mdd", &[0, 0, 0, 1, 0]).contains("5 bytes"));
    assert!(header_reason("empty.pc2", &[]).contains("0 bytes"));
}

#[test]
fn huge_declared_counts_within_u64_are_truncation_without_allocating() {
    // 2³¹−1 frames declared in a 48-byte file: reported from the length, before the reader
    // would allocate the 8 GiB time table (or a frame buffer) the header asks for.
    let d = tmpdir("huge");
    let mut b = i32::MAX.to_be_bytes().to_vec();
    b.extend_from_slice(&1i32.to_be_bytes());
    b.extend_from_slice(&[0; 40]);
    let p = write_bytes(&d, "h.mdd", &b);
    assert_eq!(truncated_frame(&p), 10);

    let mut b = pc2_fixture();
    b[16..20].copy_from_slice(&(1i32 << 30).to_le_bytes()); // 2³⁰ points per frame
    let p = write_bytes(&d, "h.pc2", &b);
    assert_eq!(truncated_frame(&p), 0);
}

#[test]
fn mdd_times_that_do_not_increase_are_accepted_and_reported_on_demand() {
    // Decision: open accepts them (Blender's Mesh Cache plays such files in its default
    // Frame mode, and exporters exist that write constant times); check_times names the
    // first frame out of order.
    let d = tmpdir("times");
    let mut b = mdd_fixture();
    // three frames: times 0.0, 0.5, 0.25 — the last goes backwards
    b[3] = 3;
    b.splice(16..16, [0x3E, 0x80, 0x00, 0x00]); // t2 = 0.25
    b.extend_from_slice(&mdd_fixture()[16..40]); // frame 2 = frame 0
    let p = write_bytes(&d, "back.mdd", &b);
    let mut c = PointCache::open(&p).unwrap();
    assert_eq!(c.frame_times(), vec![0.0, 0.5, 0.25]);
    assert_eq!(bits(&c.read_frame(2).unwrap()), BITS[0].to_vec());
    let e = c.check_times().unwrap_err();
    assert!(matches!(e, PointCacheError::Time { frame: 2, .. }), "{e}");
    assert!(e.to_string().contains("back.mdd"), "{e}");

    // equal times: frame 1 is not after frame 0
    let mut b = mdd_fixture();
    b[12..16].copy_from_slice(&[0; 4]);
    let c = PointCache::open(write_bytes(&d, "flat.mdd", &b)).unwrap();
    assert!(matches!(
        c.check_times(),
        Err(PointCacheError::Time { frame: 1, .. })
    ));
    // NaN time
    let mut b = mdd_fixture();
    b[8..12].copy_from_slice(&f32::NAN.to_be_bytes());
    let c = PointCache::open(write_bytes(&d, "nan.mdd", &b)).unwrap();
    assert!(matches!(
        c.check_times(),
        Err(PointCacheError::Time { frame: 0, .. })
    ));
    // PC2: rate 0 makes frame 1 coincide with frame 0; a NaN start breaks frame 0
    let mut b = pc2_fixture();
    b[24..28].copy_from_slice(&0f32.to_le_bytes());
    let c = PointCache::open(write_bytes(&d, "rate0.pc2", &b)).unwrap();
    assert!(matches!(
        c.check_times(),
        Err(PointCacheError::Time { frame: 1, .. })
    ));
    // ... also in a one-frame file, where the rate places nothing (found by fuzz/pc2: the
    // writer refused what check_times accepted); frame 0 is named
    let mut b = pc2_fixture()[..32 + 24].to_vec();
    b[28] = 1;
    b[24..28].copy_from_slice(&0f32.to_le_bytes());
    let c = PointCache::open(write_bytes(&d, "one.pc2", &b)).unwrap();
    assert!(matches!(
        c.check_times(),
        Err(PointCacheError::Time { frame: 0, .. })
    ));
    let mut b = pc2_fixture();
    b[20..24].copy_from_slice(&f32::INFINITY.to_le_bytes());
    let c = PointCache::open(write_bytes(&d, "start.pc2", &b)).unwrap();
    assert!(matches!(
        c.check_times(),
        Err(PointCacheError::Time { frame: 0, .. })
    ));
}

#[test]
fn non_finite_positions_name_frame_and_vertex() {
    let d = tmpdir("nan");
    let mut b = pc2_fixture();
    // frame 1, vertex 1, y
    let at = 32 + 24 + 12 + 4;
    b[at..at + 4].copy_from_slice(&f32::NAN.to_le_bytes());
    let p = write_bytes(&d, "nan.pc2", &b);
    let mut c = PointCache::open(&p).unwrap();
    assert!(c.read_frame(0).is_ok());
    let e = c.read_frame(1).unwrap_err();
    assert!(
        matches!(
            e,
            PointCacheError::NonFinite {
                frame: 1,
                vertex: 1,
                ..
            }
        ),
        "{e}"
    );
    let msg = e.to_string();
    assert!(
        msg.contains("nan.pc2") && msg.contains("frame 1, vertex 1"),
        "{msg}"
    );

    let mut b = mdd_fixture();
    b[16 + 8..16 + 12].copy_from_slice(&f32::NEG_INFINITY.to_be_bytes()); // frame 0, vertex 0, z
    let mut c = PointCache::open(write_bytes(&d, "inf.mdd", &b)).unwrap();
    assert!(matches!(
        c.read_frame(0),
        Err(PointCacheError::NonFinite {
            frame: 0,
            vertex: 0,
            ..
        })
    ));
}

#[test]
fn trailing_bytes_are_accepted_and_counted() {
    // Blender's 2.6x–2.7x MDD exporter wrote one frame more than its header declares.
    let d = tmpdir("trailing");
    let mut b = mdd_fixture();
    b.extend_from_slice(&mdd_fixture()[16..40]);
    let mut c = PointCache::open(write_bytes(&d, "old.mdd", &b)).unwrap();
    assert_eq!((c.n_frames(), c.trailing_bytes()), (2, 24));
    assert_eq!(bits(&c.read_frame(1).unwrap()), BITS[1].to_vec());
}

#[test]
fn format_is_told_by_signature_then_name() {
    let d = tmpdir("sniff");
    // PC2 content wins over the name
    let c = PointCache::open(write_bytes(&d, "renamed.mdd", &pc2_fixture())).unwrap();
    assert_eq!(c.format(), Format::Pc2);
    let c = PointCache::open(write_bytes(&d, "cloth.cache", &pc2_fixture())).unwrap();
    assert_eq!(c.format(), Format::Pc2);
    // MDD content needs the name (any case), or open_as
    let c = PointCache::open(write_bytes(&d, "cloth.MDD", &mdd_fixture())).unwrap();
    assert_eq!(c.format(), Format::Mdd);
    let p = write_bytes(&d, "cloth.bin", &mdd_fixture());
    let e = PointCache::open(&p).unwrap_err();
    assert!(matches!(e, PointCacheError::UnknownFormat { .. }), "{e}");
    assert_eq!(
        PointCache::open_as(&p, Format::Mdd).unwrap().format(),
        Format::Mdd
    );
    assert!(matches!(
        PointCache::open(write_bytes(&d, "cloth.pc2", &mdd_fixture())),
        Err(PointCacheError::BadSignature { .. })
    ));
    assert!(matches!(
        PointCache::open(d.join("missing.pc2")),
        Err(PointCacheError::Io { .. })
    ));
}

#[test]
fn writers_refuse_what_they_could_not_read_back_and_keep_the_old_file() {
    let d = tmpdir("refuse");
    let p = d.join("keep.pc2");
    write_pc2(&p, 1.0, 1.0, &FRAMES).unwrap();
    let before = std::fs::read(&p).unwrap();

    let mut nan = FRAMES;
    nan[1][0][2] = f32::NAN;
    let e = write_pc2(&p, 1.0, 1.0, &nan).unwrap_err();
    assert!(
        matches!(
            e,
            PointCacheError::NonFinite {
                frame: 1,
                vertex: 0,
                ..
            }
        ),
        "{e}"
    );
    let ragged = vec![vec![[0.0f32; 3]; 2], vec![[0.0; 3]; 3]];
    let e = write_pc2(&p, 1.0, 1.0, &ragged).unwrap_err();
    assert!(e.to_string().contains("frame 1 has 3 points"), "{e}");
    let none: [Vec<[f32; 3]>; 0] = [];
    assert!(matches!(
        write_pc2(&p, 1.0, 1.0, &none),
        Err(PointCacheError::Usage { .. })
    ));
    assert!(matches!(
        write_pc2(&p, 1.0, 0.0, &FRAMES),
        Err(PointCacheError::Usage { .. })
    ));
    assert!(matches!(
        write_pc2(&p, f32::NAN, 1.0, &FRAMES),
        Err(PointCacheError::Usage { .. })
    ));
    let m = d.join("keep.mdd");
    let e = write_mdd(&m, &[0.0], &FRAMES).unwrap_err();
    assert!(e.to_string().contains("1 times for 2 frames"), "{e}");
    let e = write_mdd(&m, &[0.5, 0.5], &FRAMES).unwrap_err();
    assert!(e.to_string().contains("frame 1"), "{e}");
    assert!(!m.exists());

    // a write that fails on I/O (no such directory) leaves nothing behind
    let e = write_pc2(d.join("no/such/dir.pc2"), 1.0, 1.0, &FRAMES).unwrap_err();
    assert!(matches!(e, PointCacheError::Io { .. }), "{e}");

    assert_eq!(std::fs::read(&p).unwrap(), before);
    let names: Vec<_> = std::fs::read_dir(&d)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(names, vec!["keep.pc2"], "no temporary file is left");
}

/// The files in `d`, sorted.
fn names(d: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(d)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

#[test]
fn the_streaming_writer_writes_the_fixture_and_keeps_the_old_file_until_finish() {
    let d = tmpdir("stream");
    let p = d.join("s.pc2");
    std::fs::write(&p, b"previous").unwrap();

    // frame by frame: the hand-built fixture, byte for byte, once finished
    let mut w = Pc2Writer::create(&p, 2, 10.0, 0.5).unwrap();
    w.add_frame(&FRAMES[0]).unwrap();
    assert_eq!(std::fs::read(&p).unwrap(), b"previous", "not before finish");
    assert_eq!(names(&d).len(), 2, "a temporary file beside the target");
    w.add_frame(&FRAMES[1]).unwrap();
    assert_eq!(w.n_frames(), 2);
    w.finish().unwrap();
    assert_eq!(std::fs::read(&p).unwrap(), pc2_fixture());
    assert_eq!(names(&d), vec!["s.pc2"]);

    // dropped or aborted unfinished, or failing on bad input: the target is untouched and
    // nothing is left beside it
    let before = std::fs::read(&p).unwrap();
    let mut w = Pc2Writer::create(&p, 2, 1.0, 1.0).unwrap();
    w.add_frame(&FRAMES[1]).unwrap();
    drop(w);
    let mut w = Pc2Writer::create(&p, 2, 1.0, 1.0).unwrap();
    w.add_frame(&FRAMES[0]).unwrap();
    w.abort();
    let mut w = Pc2Writer::create(&p, 2, 1.0, 1.0).unwrap();
    w.add_frame(&FRAMES[0]).unwrap();
    let mut nan = FRAMES[1];
    nan[1][2] = f32::INFINITY;
    let e = w.add_frame(&nan).unwrap_err();
    assert!(
        matches!(
            e,
            PointCacheError::NonFinite {
                frame: 1,
                vertex: 1,
                ..
            }
        ),
        "{e}"
    );
    let e = w.add_frame(&FRAMES[0][..1]).unwrap_err();
    assert!(e.to_string().contains("frame 1 has 1 points"), "{e}");
    drop(w);
    let e = Pc2Writer::create(&p, 2, 1.0, 1.0)
        .unwrap()
        .finish()
        .unwrap_err();
    assert!(e.to_string().contains("at least one frame"), "{e}");
    for (n, start, rate) in [(0, 1.0, 1.0), (2, f32::NAN, 1.0), (2, 1.0, -1.0)] {
        assert!(matches!(
            Pc2Writer::create(&p, n, start, rate),
            Err(PointCacheError::Usage { .. })
        ));
    }
    assert_eq!(std::fs::read(&p).unwrap(), before);
    assert_eq!(names(&d), vec!["s.pc2"], "no temporary file is left");

    // a long sequence streamed reads back frame for frame
    let frames = cloth(40, 33);
    let mut w = Pc2Writer::create(&p, 33, 1.0, 1.0).unwrap();
    for f in &frames {
        w.add_frame(f).unwrap();
    }
    w.finish().unwrap();
    let mut back = PointCache::open(&p).unwrap();
    for (k, f) in frames.iter().enumerate() {
        assert_eq!(bits(&back.read_frame(k).unwrap()), bits(f), "frame {k}");
    }
}
