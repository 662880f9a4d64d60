//! Shared by the fuzz targets: the readers take a path, so each input goes through a file.
#![allow(dead_code)] // each target uses a part

use std::path::{Path, PathBuf};

use madder::io::point_cache::{Format, PointCache, PointCacheError, Timing, write_mdd, write_pc2};

/// A per-process scratch directory, in memory when `/dev/shm` exists.
fn scratch() -> &'static Path {
    static DIR: std::sync::OnceLock<PathBuf> = std::sync::OnceLock::new();
    DIR.get_or_init(|| {
        let shm = Path::new("/dev/shm");
        let base = if shm.is_dir() {
            shm.to_path_buf()
        } else {
            std::env::temp_dir()
        };
        let d = base.join(format!("madder-fuzz-{}", std::process::id()));
        std::fs::create_dir_all(&d).expect("scratch directory");
        d
    })
}

/// Writes `data` to `input.<ext>` in the scratch directory and hands over its path.
pub fn with_file(data: &[u8], ext: &str, f: impl FnOnce(&Path)) {
    let path = scratch().join(format!("input.{ext}"));
    std::fs::write(&path, data).expect("write fuzz input");
    f(&path);
}

/// Everything a caller can do with a point cache that opened. It must never panic, a file
/// that opened must never turn out truncated, and a clean file must survive a rewrite
/// byte for byte (reader and writer agree on the format).
pub fn exercise(mut c: PointCache, data: &[u8]) {
    let (n_points, n_frames) = (c.n_points(), c.n_frames());
    assert!(n_points >= 1 && n_frames >= 1);
    let data_offset = match c.format() {
        Format::Pc2 => 32,
        Format::Mdd => 8 + 4 * n_frames,
    };
    let expected = data_offset + n_frames * n_points * 12;
    assert_eq!(expected as u64 + c.trailing_bytes(), data.len() as u64);
    assert_eq!(c.frame_times().len(), n_frames);
    let times_ok = c.check_times().map_err(|e| e.to_string()).is_ok();
    let mut frames = Vec::with_capacity(n_frames);
    for k in 0..n_frames {
        match c.read_frame(k) {
            Ok(f) => {
                assert_eq!(f.len(), n_points);
                frames.push(f);
            }
            Err(PointCacheError::NonFinite { frame, vertex, .. }) => {
                assert!(frame == k && vertex < n_points)
            }
            Err(e) => panic!("frame {k} of a file that opened: {e}"),
        }
    }
    assert!(matches!(
        c.read_frame(n_frames),
        Err(PointCacheError::FrameOutOfRange { .. })
    ));
    if !times_ok || frames.len() != n_frames {
        return;
    }
    let out = scratch().join("rewrite");
    match c.timing().clone() {
        Timing::Frames { start, rate } => write_pc2(&out, start, rate, &frames),
        Timing::Seconds(times) => write_mdd(&out, &times, &frames),
    }
    .expect("a clean file can be rewritten");
    assert_eq!(
        std::fs::read(&out).expect("rewritten file"),
        data[..expected]
    );
}
