//! PC2 and MDD point caches: per-frame vertex positions of a mesh with fixed topology, the
//! two formats of Blender's Mesh Cache modifier. Reading them here lets a cloth simulated in
//! another tool (or exported from Blender) be baked from the file, without evaluating the
//! scene frame by frame.
//!
//! ## PC2 (Point Cache 2, from 3ds Max), little-endian
//! ```text
//! offset  size  field
//!      0    12  signature   b"POINTCACHE2\0"
//!     12     4  version     i32 = 1
//!     16     4  n_points    i32
//!     20     4  start       f32   scene frame of the first sample
//!     24     4  rate        f32   frames between samples (3ds Max's "sample rate": 1 = every
//!                                 frame, 0.5 = twice per frame)
//!     28     4  n_frames    i32   number of samples
//!     32        n_frames × n_points × (x, y, z) f32
//! ```
//! Sample `k` is at scene frame `start + k·rate` (a rate of 0.1 gives ten samples per
//! frame). This is the layout of Blender's reader
//! (`MOD_meshcache_pc2.cc`, struct `PC2Head`) and of the PC2 exporter that shipped with
//! Blender (`io_export_pc2`: `struct.pack('<12siiffi', b'POINTCACHE2\0', 1, n_verts, start,
//! sampling, n_samples)`, then `'<fff'` per vertex).
//!
//! ## MDD (LightWave Motion Designer), big-endian
//! ```text
//! offset          size  field
//!      0             4  n_frames   i32
//!      4             4  n_points   i32
//!      8    4·n_frames  times      n_frames × f32, seconds
//!      …                n_frames × n_points × (x, y, z) f32
//! ```
//! Frame `k` is at `times[k]` seconds. This is the layout of Blender's reader
//! (`MOD_meshcache_mdd.cc`, struct `MDDHead` and the time table it skips) and of the
//! `io_shape_mdd` exporter (`pack(">2i", n_frames, n_verts)`, `pack(">%df", …)` of
//! `frame / fps`, then `">%df"` per frame).
//!
//! ## How Blender plays them
//! In the Mesh Cache modifier's default *Frame* mode, scene frame `f` shows sample
//! `clamp(f·frame_scale − frame_start, 0, n_frames − 1)` — the modifier's own Frame Scale and
//! Frame Start, defaults 1 and 0 — whatever the file's `start`/`rate` or times say. Checked in
//! bpy 5.0.1 against files from [`write_pc2`]/[`write_mdd`]: sample `k` (bit-identical to
//! [`PointCache::read_frame`]`(k)`) at scene frame `k`, the last sample held after the end.
//! Only its *Time* mode uses the timing (for MDD, a scan for the first time ≥ t).
//!
//! Coordinates are returned exactly as stored. The formats fix no axes: `io_shape_mdd`
//! swaps Y and Z on export (LightWave is Y-up), `io_export_pc2` rotates by −90° about X by
//! default (its "Convert to Y-up"), and the Mesh Cache modifier undoes such conventions with its Forward/Up axis settings.
//! Converting axes (and object-to-world transforms) is the caller's business, as in Blender.
//!
//! ## What is validated, and when
//! [`PointCache::open`] validates everything needed to *locate* frames, and names the file
//! in every error:
//! - the PC2 signature ([`BadSignature`](PointCacheError::BadSignature)) and version, which
//!   must be 1 ([`Version`](PointCacheError::Version); Blender ignores the field, but every
//!   known writer stores 1, so another value means a different or damaged file);
//! - the counts: `n_points ≥ 1` and `n_frames ≥ 1` (Blender's reader rejects
//!   `n_frames ≤ 0` too), and `data_offset + n_frames·n_points·12` must fit in a `u64`
//!   ([`Header`](PointCacheError::Header));
//! - the file length: a file shorter than its header declares is
//!   [`Truncated`](PointCacheError::Truncated), naming the first incomplete frame (for MDD,
//!   a frame whose *time* is missing counts as incomplete). This check comes before any
//!   allocation sized by the header, so a forged count cannot make the reader allocate
//!   more than the file holds: the MDD time table and each frame buffer are at most the
//!   file's length.
//!
//! Two deliberate leniencies, both following Blender, whose Mesh Cache plays such files:
//! - *Trailing bytes are accepted* and reported by [`PointCache::trailing_bytes`]. Blender's
//!   readers never look past the declared frames, and the 2.7x-era `io_shape_mdd` exporter
//!   wrote one more frame than its header declares (a rest frame, then every frame of the
//!   range); rejecting them would refuse files Blender plays. A UI may
//!   warn when the count is not zero.
//! - *Times are not checked at open.* The Mesh Cache modifier's default Frame mode ignores
//!   them (sample `k` plays at scene frame `k`), and exporters exist that write constant or
//!   zero times. [`PointCache::check_times`] checks them on demand — finite and strictly
//!   increasing, naming the first bad frame — for callers that map time to samples.
//!
//! [`PointCache::read_frame`] checks each position it returns and reports a NaN or
//! infinite coordinate as [`NonFinite`](PointCacheError::NonFinite), naming the file, frame
//! and vertex. Checking at read time (rather than behind an option) is free next to the
//! read itself, and positions feed the simulator directly, where one NaN would poison every
//! solve and the core's own check could no longer say which file and frame it came from.
//!
//! Reads are random access: a frame is at a computed offset, and reading it reads
//! `n_points × 12` bytes, never the whole file.
//!
//! ## Writing
//! [`write_pc2`] and [`write_mdd`] write the whole file to a temporary file next to the
//! target, fsync it and rename it over the target, like the Madder cache writer: a failed
//! write leaves the previous file untouched. [`Pc2Writer`] does the same a frame at a time
//! (the frame count is written into the header last), for sequences too long to hold in
//! memory; [`write_pc2`] is built on it. They refuse input they could not read back:
//! non-finite positions, frames of different lengths, empty data, non-finite or
//! non-increasing times (PC2: a finite `start` and a finite `rate > 0`).
//!
//! ## Fuzzing
//! `rust/madder/fuzz` holds cargo-fuzz targets for this reader (`pc2`, `mdd`) and for the
//! Madder cache reader (`cache_reader`); see its README. Each target writes the input to a
//! file, opens it, reads every frame, and asserts that a file that opens never reports a
//! truncated frame afterwards. Record of the runs (debug assertions and overflow checks on,
//! AddressSanitizer, `-rss_limit_mb=2048`, inputs up to 4096 bytes):
//!
//! - `cache_reader`: final clean run 331 s, 5 485 011 execs. Before it, with checksum
//!   repair on, two panics within seconds each: (1) `block_len × n_frames` overflowed `u64`
//!   at open — in a release build it wraps, so a forged header could pass the length check
//!   and `read` would then allocate a block of up to ~1 TB; (2) `first_frame + complete`
//!   overflowed `i32` in the truncation report (same class: `last_frame`, `read`,
//!   `CacheWriter::push_frame`). Without checksum repair (181 s, 3.65 M execs) it found
//!   nothing: the header CRC hid both.
//! - `pc2`: final clean run 331 s, 5 570 452 execs. Before it, the rewrite oracle found that
//!   a one-frame file with rate 0 passed [`PointCache::check_times`] while [`write_pc2`]
//!   refused it; `check_times` now requires a finite rate > 0 whatever the frame count.
//! - `mdd`: 331 s, 4 128 182 execs, nothing found.
//!
//! The fixes in [`crate::io::cache`] (with a regression test there): the declared size is
//! computed with checked arithmetic (a `Header` error, "declared size overflows 64 bits"),
//! and the frame range `first_frame ..= first_frame + n_frames − 1` must fit in `i32`, at
//! open (`Header`) and in `CacheWriter::create` (`Usage`); frame arithmetic is done in
//! `i64`. Builds: stable rustc 1.95 with `RUSTC_BOOTSTRAP=1`, 2 cores (the `mdd` run shared
//! them with a wheel build).

use std::fs::File;
use std::io::{BufWriter, Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

/// Reading or writing a PC2 or MDD point cache. Frames are counted from 0 in file order
/// and vertices from 0, as the file stores them. (It lives here, not in [`crate::error`],
/// which refers to it for [`crate::Error::PointCache`]: one direction only.)
#[derive(Debug, thiserror::Error)]
pub enum PointCacheError {
    /// The operating system refused a read or a write.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The operating system's error.
        source: std::io::Error,
    },
    /// Neither a PC2 signature nor a `.pc2`/`.mdd` name.
    #[error(
        "{path}: unknown point cache format: no PC2 signature, and the name does not end in .pc2 or .mdd (MDD files carry no signature; open it as MDD explicitly)"
    )]
    UnknownFormat {
        /// The file.
        path: PathBuf,
    },
    /// A file opened as PC2 without the PC2 signature.
    #[error("{path}: not a PC2 file (it does not start with the signature \"POINTCACHE2\\0\")")]
    BadSignature {
        /// The file.
        path: PathBuf,
    },
    /// A PC2 version other than 1.
    #[error("{path}: PC2 file version {found} is not supported (this build reads version 1)")]
    Version {
        /// The file.
        path: PathBuf,
        /// The version in the file.
        found: i32,
    },
    /// A header whose counts or times are impossible.
    #[error("{path}: corrupt {format} header: {reason}")]
    Header {
        /// The file.
        path: PathBuf,
        /// The format the file was read as.
        format: Format,
        /// What is wrong.
        reason: String,
    },
    /// A file shorter than its header declares.
    #[error(
        "{path}: file is truncated: frame {frame} is incomplete (the header declares {n_frames} frames of {n_points} points, {expected} bytes; the file has {len})"
    )]
    Truncated {
        /// The file.
        path: PathBuf,
        /// The first incomplete frame.
        frame: usize,
        /// Frames the header declares.
        n_frames: usize,
        /// Points per frame the header declares.
        n_points: usize,
        /// Bytes the header implies.
        expected: u64,
        /// Bytes the file has.
        len: u64,
    },
    /// A frame the file does not hold.
    #[error("{path}: frame {frame} is not in the file (it holds frames 0..={last})", last = .n_frames.saturating_sub(1))]
    FrameOutOfRange {
        /// The file.
        path: PathBuf,
        /// The frame.
        frame: usize,
        /// Frames the header declares.
        n_frames: usize,
    },
    /// A NaN or infinite coordinate in a frame.
    #[error("{path}: frame {frame}, vertex {vertex} has a non-finite position {position:?}")]
    NonFinite {
        /// The file.
        path: PathBuf,
        /// The frame.
        frame: usize,
        /// The vertex (0-based, file order).
        vertex: usize,
        /// The coordinates read.
        position: [f32; 3],
    },
    /// A frame time that is not finite or not after the previous one.
    #[error("{path}: frame {frame}: {reason}")]
    Time {
        /// The file.
        path: PathBuf,
        /// The frame.
        frame: usize,
        /// What is wrong.
        reason: String,
    },
    /// The writer was given frames it cannot write.
    #[error("{path}: {reason}")]
    Usage {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
}

/// The 12 bytes that start every PC2 file.
pub(crate) const PC2_SIGNATURE: &[u8; 12] = b"POINTCACHE2\0";
/// The only PC2 version there is.
pub(crate) const PC2_VERSION: i32 = 1;
/// Bytes before the first PC2 frame.
pub(crate) const PC2_HEADER_LEN: u64 = 32;
/// Bytes of the fixed MDD header (before the time table).
pub(crate) const MDD_HEADER_LEN: u64 = 8;
/// Bytes per stored point: three `f32`.
const POINT_LEN: u64 = 12;

/// Which of the two formats a file is in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Format {
    /// Point Cache 2: little-endian, with a signature, frames at `start + k·rate`.
    Pc2,
    /// LightWave MDD: big-endian, no signature, a time in seconds per frame.
    Mdd,
}

impl Format {
    /// The format a file name implies: `.pc2` or `.mdd`, any case.
    pub(crate) fn from_extension(path: &Path) -> Option<Format> {
        let ext = path.extension()?.to_str()?.to_ascii_lowercase();
        match ext.as_str() {
            "pc2" => Some(Format::Pc2),
            "mdd" => Some(Format::Mdd),
            _ => None,
        }
    }

    /// `"PC2"` or `"MDD"`.
    pub(crate) fn name(self) -> &'static str {
        match self {
            Format::Pc2 => "PC2",
            Format::Mdd => "MDD",
        }
    }

    fn f32_from(self, b: &[u8]) -> f32 {
        let b: [u8; 4] = b.try_into().expect("4 bytes");
        match self {
            Format::Pc2 => f32::from_le_bytes(b),
            Format::Mdd => f32::from_be_bytes(b),
        }
    }

    fn i32_from(self, b: &[u8]) -> i32 {
        let b: [u8; 4] = b.try_into().expect("4 bytes");
        match self {
            Format::Pc2 => i32::from_le_bytes(b),
            Format::Mdd => i32::from_be_bytes(b),
        }
    }

    fn f32_to(self, x: f32) -> [u8; 4] {
        match self {
            Format::Pc2 => x.to_le_bytes(),
            Format::Mdd => x.to_be_bytes(),
        }
    }

    fn i32_to(self, x: i32) -> [u8; 4] {
        match self {
            Format::Pc2 => x.to_le_bytes(),
            Format::Mdd => x.to_be_bytes(),
        }
    }
}

impl std::fmt::Display for Format {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// When each frame of a point cache happens, as the file states it.
#[derive(Debug, Clone, PartialEq)]
pub enum Timing {
    /// PC2: frame `k` is at scene frame `start + k·rate`.
    Frames {
        /// The scene frame of the first sample.
        start: f32,
        /// Scene frames between samples.
        rate: f32,
    },
    /// MDD: frame `k` is at `times[k]` seconds.
    Seconds(Vec<f32>),
}

/// Random access to the frames of a PC2 or MDD file.
#[derive(Debug)]
pub struct PointCache {
    path: PathBuf,
    file: File,
    format: Format,
    n_points: usize,
    n_frames: usize,
    timing: Timing,
    data_offset: u64,
    expected_len: u64,
    len: u64,
}

impl PointCache {
    /// Opens a point cache, telling the format by its content and name: a file that starts
    /// with the PC2 signature is PC2; otherwise a `.mdd` name means MDD and a `.pc2` name a
    /// PC2 file with a bad signature. Any other file is
    /// [`UnknownFormat`](PointCacheError::UnknownFormat) (MDD has no signature to sniff; use
    /// [`open_as`](Self::open_as)).
    pub fn open(path: impl AsRef<Path>) -> Result<Self, PointCacheError> {
        let path = path.as_ref().to_path_buf();
        let mut file = File::open(&path).map_err(|source| io_err(&path, source))?;
        let mut head = Vec::with_capacity(PC2_SIGNATURE.len());
        (&mut file)
            .take(PC2_SIGNATURE.len() as u64)
            .read_to_end(&mut head)
            .map_err(|source| io_err(&path, source))?;
        let format = if head == PC2_SIGNATURE {
            Format::Pc2
        } else {
            Format::from_extension(&path)
                .ok_or_else(|| PointCacheError::UnknownFormat { path: path.clone() })?
        };
        Self::from_file(path, file, format)
    }

    /// Opens `path` as `format`, whatever its name.
    pub fn open_as(path: impl AsRef<Path>, format: Format) -> Result<Self, PointCacheError> {
        let path = path.as_ref().to_path_buf();
        let file = File::open(&path).map_err(|source| io_err(&path, source))?;
        Self::from_file(path, file, format)
    }

    fn from_file(path: PathBuf, mut file: File, format: Format) -> Result<Self, PointCacheError> {
        let len = file
            .metadata()
            .map_err(|source| io_err(&path, source))?
            .len();
        let header = |reason: String| PointCacheError::Header {
            path: path.clone(),
            format,
            reason,
        };
        file.seek(SeekFrom::Start(0))
            .map_err(|source| io_err(&path, source))?;
        let (n_points, n_frames, start_rate, data_offset) = match format {
            Format::Pc2 => {
                let mut h = [0u8; PC2_HEADER_LEN as usize];
                let got = read_up_to(&mut file, &mut h).map_err(|source| io_err(&path, source))?;
                // A file too short for the signature but agreeing with it so far (an empty
                // file, say) is reported by its length; one that disagrees is not PC2.
                let sig = got.min(PC2_SIGNATURE.len());
                if h[..sig] != PC2_SIGNATURE[..sig] {
                    return Err(PointCacheError::BadSignature { path });
                }
                if got < h.len() {
                    return Err(header(format!(
                        "the file has {got} bytes, fewer than the {PC2_HEADER_LEN}-byte header"
                    )));
                }
                let version = format.i32_from(&h[12..16]);
                if version != PC2_VERSION {
                    return Err(PointCacheError::Version {
                        path,
                        found: version,
                    });
                }
                let n_points = format.i32_from(&h[16..20]);
                let start = format.f32_from(&h[20..24]);
                let rate = format.f32_from(&h[24..28]);
                let n_frames = format.i32_from(&h[28..32]);
                (n_points, n_frames, Some((start, rate)), PC2_HEADER_LEN)
            }
            Format::Mdd => {
                let mut h = [0u8; MDD_HEADER_LEN as usize];
                let got = read_up_to(&mut file, &mut h).map_err(|source| io_err(&path, source))?;
                if got < h.len() {
                    return Err(header(format!(
                        "the file has {got} bytes, fewer than the {MDD_HEADER_LEN}-byte header"
                    )));
                }
                let n_frames = format.i32_from(&h[0..4]);
                let n_points = format.i32_from(&h[4..8]);
                // n_frames < 2³¹, so the time table's end fits in a u64 comfortably.
                let offset = MDD_HEADER_LEN + 4 * n_frames.max(0) as u64;
                (n_points, n_frames, None, offset)
            }
        };
        if n_points < 1 {
            return Err(header(format!(
                "it declares {n_points} points (a point cache needs at least 1)"
            )));
        }
        if n_frames < 1 {
            return Err(header(format!(
                "it declares {n_frames} frames (a point cache needs at least 1)"
            )));
        }
        let (n_points, n_frames) = (n_points as usize, n_frames as usize);
        let expected_len = (n_points as u64 * POINT_LEN)
            .checked_mul(n_frames as u64)
            .and_then(|data| data.checked_add(data_offset))
            .ok_or_else(|| {
                header(format!(
                    "{n_frames} frames of {n_points} points do not fit in a file (the size overflows 64 bits)"
                ))
            })?;
        if len < expected_len {
            let frame = if len < data_offset {
                // MDD: the time table itself is cut; the first frame without a time.
                ((len.saturating_sub(MDD_HEADER_LEN)) / 4) as usize
            } else {
                ((len - data_offset) / (n_points as u64 * POINT_LEN)) as usize
            };
            return Err(PointCacheError::Truncated {
                path,
                frame,
                n_frames,
                n_points,
                expected: expected_len,
                len,
            });
        }
        let timing = match start_rate {
            Some((start, rate)) => Timing::Frames { start, rate },
            None => {
                // Bounded by the file length, checked above.
                let mut raw = vec![0u8; 4 * n_frames];
                file.seek(SeekFrom::Start(MDD_HEADER_LEN))
                    .and_then(|_| file.read_exact(&mut raw))
                    .map_err(|source| io_err(&path, source))?;
                Timing::Seconds(raw.chunks_exact(4).map(|b| format.f32_from(b)).collect())
            }
        };
        Ok(Self {
            path,
            file,
            format,
            n_points,
            n_frames,
            timing,
            data_offset,
            expected_len,
            len,
        })
    }

    /// The file.
    pub fn path(&self) -> &Path {
        &self.path
    }
    /// The format it is read as.
    pub fn format(&self) -> Format {
        self.format
    }
    /// Points (vertices) per frame.
    pub fn n_points(&self) -> usize {
        self.n_points
    }
    /// Frames (samples) in the file.
    pub fn n_frames(&self) -> usize {
        self.n_frames
    }
    /// The file's timing, as stored.
    pub fn timing(&self) -> &Timing {
        &self.timing
    }
    /// Time of every frame, in the file's unit: scene frames for PC2 (`start + k·rate`,
    /// computed in `f64`), seconds for MDD.
    pub fn frame_times(&self) -> Vec<f64> {
        match &self.timing {
            Timing::Frames { start, rate } => (0..self.n_frames)
                .map(|k| *start as f64 + k as f64 * *rate as f64)
                .collect(),
            Timing::Seconds(t) => t.iter().map(|&x| x as f64).collect(),
        }
    }
    /// Bytes after the last declared frame (see the module doc on why they are accepted).
    pub fn trailing_bytes(&self) -> u64 {
        self.len - self.expected_len
    }

    /// Checks that the frame times are finite and strictly increasing, naming the first
    /// frame that is not ([`Time`](PointCacheError::Time)). For PC2 that means a finite
    /// `start` (else frame 0 is named) and a finite `rate > 0` (else frame 1, or frame 0 in
    /// a one-frame file): the same conditions [`write_pc2`] puts on its input.
    pub fn check_times(&self) -> Result<(), PointCacheError> {
        let err = |frame: usize, reason: String| PointCacheError::Time {
            path: self.path.clone(),
            frame,
            reason,
        };
        match &self.timing {
            Timing::Frames { start, rate } => {
                if !start.is_finite() {
                    return Err(err(0, format!("the PC2 start frame {start} is not finite")));
                }
                if !(rate.is_finite() && *rate > 0.0) {
                    return Err(err(
                        self.n_frames.min(2) - 1,
                        format!(
                            "the PC2 rate {rate} (frames between samples) must be finite and > 0"
                        ),
                    ));
                }
            }
            Timing::Seconds(times) => {
                for (frame, &t) in times.iter().enumerate() {
                    if !t.is_finite() {
                        return Err(err(frame, format!("its time {t} s is not finite")));
                    }
                    if frame > 0 && t <= times[frame - 1] {
                        return Err(err(
                            frame,
                            format!(
                                "its time {t} s is not after frame {}'s {} s",
                                frame - 1,
                                times[frame - 1]
                            ),
                        ));
                    }
                }
            }
        }
        Ok(())
    }

    /// Positions of frame `k` (0-based, file order), one `[x, y, z]` per point. Reads that
    /// frame only; a NaN or infinite coordinate is an error naming frame and vertex.
    pub fn read_frame(&mut self, k: usize) -> Result<Vec<[f32; 3]>, PointCacheError> {
        if k >= self.n_frames {
            return Err(PointCacheError::FrameOutOfRange {
                path: self.path.clone(),
                frame: k,
                n_frames: self.n_frames,
            });
        }
        let frame_len = self.n_points as u64 * POINT_LEN;
        // k < n_frames, and data_offset + n_frames·frame_len was checked not to overflow.
        let offset = self.data_offset + k as u64 * frame_len;
        // Bounded by the file length, checked at open.
        let mut buf = vec![0u8; frame_len as usize];
        self.file
            .seek(SeekFrom::Start(offset))
            .map_err(|source| io_err(&self.path, source))?;
        if let Err(source) = self.file.read_exact(&mut buf) {
            if source.kind() != std::io::ErrorKind::UnexpectedEof {
                return Err(io_err(&self.path, source));
            }
            // The file shrank after it was opened.
            return Err(PointCacheError::Truncated {
                path: self.path.clone(),
                frame: k,
                n_frames: self.n_frames,
                n_points: self.n_points,
                expected: self.expected_len,
                len: self.file.metadata().map_or(0, |m| m.len()),
            });
        }
        let f = self.format;
        let mut out = Vec::with_capacity(self.n_points);
        for (vertex, c) in buf.chunks_exact(POINT_LEN as usize).enumerate() {
            let p = [
                f.f32_from(&c[0..4]),
                f.f32_from(&c[4..8]),
                f.f32_from(&c[8..12]),
            ];
            if !p.iter().all(|x| x.is_finite()) {
                return Err(PointCacheError::NonFinite {
                    path: self.path.clone(),
                    frame: k,
                    vertex,
                    position: p,
                });
            }
            out.push(p);
        }
        Ok(out)
    }
}

/// Writes a PC2 file atomically: frame `k` at scene frame `start + k·rate`.
pub fn write_pc2<F: AsRef<[[f32; 3]]>>(
    path: impl AsRef<Path>,
    start: f32,
    rate: f32,
    frames: &[F],
) -> Result<(), PointCacheError> {
    let path = path.as_ref();
    let n_points = check_frames(path, frames)?;
    let mut writer = Pc2Writer::create(path, n_points as usize, start, rate)?;
    for frame in frames {
        writer.add_frame(frame.as_ref())?;
    }
    writer.finish()
}

/// A PC2 file written a frame at a time, for sequences too long to hold in memory: the
/// frames go to a temporary file beside the target as they come, and [`Pc2Writer::finish`]
/// writes the frame count into the header, fsyncs and renames it over the target. Until
/// then the target keeps what it held; a writer dropped or [`Pc2Writer::abort`]ed
/// unfinished removes its temporary file. The same checks as [`write_pc2`]: a finite
/// `start`, a finite `rate > 0`, at least one point and one frame, every frame with
/// `n_points` finite positions (a [`NonFinite`](PointCacheError::NonFinite) error names
/// the frame and vertex).
#[derive(Debug)]
pub struct Pc2Writer {
    path: PathBuf,
    tmp: PathBuf,
    out: Option<BufWriter<File>>,
    n_points: usize,
    n_frames: usize,
    block: Vec<u8>,
}

impl Pc2Writer {
    /// Starts a PC2 file of `n_points` points per frame, frame `k` at scene frame
    /// `start + k·rate`.
    pub fn create(
        path: impl AsRef<Path>,
        n_points: usize,
        start: f32,
        rate: f32,
    ) -> Result<Self, PointCacheError> {
        let path = path.as_ref();
        let usage = |reason: String| PointCacheError::Usage {
            path: path.to_path_buf(),
            reason,
        };
        if n_points == 0 || n_points > i32::MAX as usize {
            return Err(usage(format!(
                "{n_points} points per frame: the count must be in 1..=2³¹−1"
            )));
        }
        if !start.is_finite() {
            return Err(usage(format!("PC2 start frame {start} is not finite")));
        }
        if !(rate.is_finite() && rate > 0.0) {
            return Err(usage(format!("PC2 rate {rate} must be finite and > 0")));
        }
        let f = Format::Pc2;
        let mut header = Vec::with_capacity(PC2_HEADER_LEN as usize);
        header.extend_from_slice(PC2_SIGNATURE);
        header.extend_from_slice(&f.i32_to(PC2_VERSION));
        header.extend_from_slice(&f.i32_to(n_points as i32));
        header.extend_from_slice(&f.f32_to(start));
        header.extend_from_slice(&f.f32_to(rate));
        header.extend_from_slice(&f.i32_to(0)); // the frame count, written by `finish`
        let tmp = temporary_beside(path);
        let out = BufWriter::new(File::create(&tmp).map_err(|e| io_err(&tmp, e))?);
        // from here on, dropping the writer (on an error too) removes the file
        let mut writer = Self {
            path: path.to_path_buf(),
            tmp,
            out: Some(out),
            n_points,
            n_frames: 0,
            block: Vec::with_capacity(12 * n_points),
        };
        if let Some(out) = writer.out.as_mut() {
            out.write_all(&header).map_err(|e| io_err(&writer.tmp, e))?;
        }
        Ok(writer)
    }

    /// Appends the next frame.
    pub fn add_frame(&mut self, frame: &[[f32; 3]]) -> Result<(), PointCacheError> {
        let usage = |reason: String| PointCacheError::Usage {
            path: self.path.clone(),
            reason,
        };
        if frame.len() != self.n_points {
            return Err(usage(format!(
                "frame {} has {} points, the file has {}",
                self.n_frames,
                frame.len(),
                self.n_points
            )));
        }
        if self.n_frames >= i32::MAX as usize {
            return Err(usage("a PC2 file holds at most 2³¹−1 frames".into()));
        }
        if let Some(vertex) = frame.iter().position(|p| !p.iter().all(|x| x.is_finite())) {
            return Err(PointCacheError::NonFinite {
                path: self.path.clone(),
                frame: self.n_frames,
                vertex,
                position: frame[vertex],
            });
        }
        let Some(out) = self.out.as_mut() else {
            return Err(usage("the writer was finished or aborted".into()));
        };
        self.block.clear();
        for &x in frame.iter().flatten() {
            self.block.extend_from_slice(&Format::Pc2.f32_to(x));
        }
        // each frame goes to the file now: memory holds one frame, whatever the length
        out.write_all(&self.block)
            .and_then(|()| out.flush())
            .map_err(|e| io_err(&self.tmp, e))?;
        self.n_frames += 1;
        Ok(())
    }

    /// Frames added so far.
    pub fn n_frames(&self) -> usize {
        self.n_frames
    }

    /// Writes the frame count, fsyncs and renames the file over the target. At least one
    /// frame must have been added.
    pub fn finish(mut self) -> Result<(), PointCacheError> {
        if self.n_frames == 0 {
            return Err(PointCacheError::Usage {
                path: self.path.clone(),
                reason: "a point cache needs at least one frame".into(),
            });
        }
        let Some(out) = self.out.take() else {
            return Err(PointCacheError::Usage {
                path: self.path.clone(),
                reason: "the writer was finished or aborted".into(),
            });
        };
        let count = Format::Pc2.i32_to(self.n_frames as i32);
        let written = (|| -> std::io::Result<()> {
            let mut file = out.into_inner().map_err(|e| e.into_error())?;
            file.seek(SeekFrom::Start(PC2_HEADER_LEN - 4))?;
            file.write_all(&count)?;
            file.sync_all()
        })();
        if let Err(source) = written {
            let _ = std::fs::remove_file(&self.tmp);
            return Err(io_err(&self.tmp, source));
        }
        std::fs::rename(&self.tmp, &self.path).map_err(|source| {
            let _ = std::fs::remove_file(&self.tmp);
            io_err(&self.path, source)
        })
    }

    /// Discards the temporary file; the target keeps what it held.
    pub fn abort(mut self) {
        self.discard();
    }

    fn discard(&mut self) {
        if self.out.take().is_some() {
            let _ = std::fs::remove_file(&self.tmp);
        }
    }
}

impl Drop for Pc2Writer {
    fn drop(&mut self) {
        self.discard();
    }
}

/// Writes an MDD file atomically: frame `k` at `times[k]` seconds.
pub fn write_mdd<F: AsRef<[[f32; 3]]>>(
    path: impl AsRef<Path>,
    times: &[f32],
    frames: &[F],
) -> Result<(), PointCacheError> {
    let path = path.as_ref();
    let n_points = check_frames(path, frames)?;
    let usage = |reason: String| PointCacheError::Usage {
        path: path.to_path_buf(),
        reason,
    };
    if times.len() != frames.len() {
        return Err(usage(format!(
            "{} times for {} frames",
            times.len(),
            frames.len()
        )));
    }
    for (k, &t) in times.iter().enumerate() {
        if !t.is_finite() {
            return Err(usage(format!("time of frame {k} ({t}) is not finite")));
        }
        if k > 0 && t <= times[k - 1] {
            return Err(usage(format!(
                "time of frame {k} ({t} s) is not after frame {}'s ({} s)",
                k - 1,
                times[k - 1]
            )));
        }
    }
    let f = Format::Mdd;
    let mut header = Vec::with_capacity(MDD_HEADER_LEN as usize + 4 * times.len());
    header.extend_from_slice(&f.i32_to(frames.len() as i32));
    header.extend_from_slice(&f.i32_to(n_points));
    for &t in times {
        header.extend_from_slice(&f.f32_to(t));
    }
    write_atomic(path, f, &header, frames)
}

/// Checks the frames a writer is given; returns the point count.
fn check_frames<F: AsRef<[[f32; 3]]>>(path: &Path, frames: &[F]) -> Result<i32, PointCacheError> {
    let usage = |reason: String| PointCacheError::Usage {
        path: path.to_path_buf(),
        reason,
    };
    let Some(first) = frames.first() else {
        return Err(usage("a point cache needs at least one frame".into()));
    };
    let n = first.as_ref().len();
    if n == 0 || n > i32::MAX as usize || frames.len() > i32::MAX as usize {
        return Err(usage(format!(
            "{} frames of {n} points: both counts must be in 1..=2³¹−1",
            frames.len()
        )));
    }
    for (k, frame) in frames.iter().enumerate() {
        let frame = frame.as_ref();
        if frame.len() != n {
            return Err(usage(format!(
                "frame {k} has {} points, frame 0 has {n}",
                frame.len()
            )));
        }
        if let Some(vertex) = frame.iter().position(|p| !p.iter().all(|x| x.is_finite())) {
            return Err(PointCacheError::NonFinite {
                path: path.to_path_buf(),
                frame: k,
                vertex,
                position: frame[vertex],
            });
        }
    }
    Ok(n as i32)
}

/// Writes `header` then the frames to a temporary file next to `path`, syncs it and renames
/// it over `path`; on any failure the temporary file is removed and `path` is untouched.
fn write_atomic<F: AsRef<[[f32; 3]]>>(
    path: &Path,
    format: Format,
    header: &[u8],
    frames: &[F],
) -> Result<(), PointCacheError> {
    let tmp = temporary_beside(path);
    let write = || -> std::io::Result<()> {
        let mut out = BufWriter::new(File::create(&tmp)?);
        out.write_all(header)?;
        let mut block = Vec::new();
        for frame in frames {
            block.clear();
            for p in frame.as_ref() {
                for &x in p {
                    block.extend_from_slice(&format.f32_to(x));
                }
            }
            out.write_all(&block)?;
        }
        let file = out.into_inner().map_err(|e| e.into_error())?;
        file.sync_all()
    };
    if let Err(source) = write() {
        let _ = std::fs::remove_file(&tmp);
        return Err(io_err(&tmp, source));
    }
    std::fs::rename(&tmp, path).map_err(|source| {
        let _ = std::fs::remove_file(&tmp);
        io_err(path, source)
    })
}

/// A temporary file name beside `path`, unique per process and call, so concurrent
/// writers never share one.
fn temporary_beside(path: &Path) -> PathBuf {
    static SERIAL: AtomicU64 = AtomicU64::new(0);
    let mut tmp_name = path.file_name().unwrap_or_default().to_os_string();
    tmp_name.push(format!(
        ".tmp{}-{}",
        std::process::id(),
        SERIAL.fetch_add(1, Ordering::Relaxed)
    ));
    path.with_file_name(tmp_name)
}

fn io_err(path: &Path, source: std::io::Error) -> PointCacheError {
    PointCacheError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// Reads until `buf` is full or the file ends; returns the bytes read.
fn read_up_to(file: &mut File, buf: &mut [u8]) -> std::io::Result<usize> {
    let mut got = 0;
    while got < buf.len() {
        match file.read(&mut buf[got..]) {
            Ok(0) => break,
            Ok(n) => got += n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(got)
}
