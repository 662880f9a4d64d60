//! The Madder bake cache: one file per baked object, holding named per-vertex `f32` fields
//! for a contiguous range of frames.
//!
//! ## Layout (version 2, little-endian)
//! ```text
//! header   magic  b"MADDERC\0"                 8 bytes
//!          version u32 = 2
//!          n_vertices u32, n_fields u32, first_frame i32, n_frames u32
//!          frame_time f64                      (version 2 only: seconds per frame, 0 = not recorded)
//!          n_fields × name: 32 bytes, UTF-8, NUL-padded
//!          header_crc u32                      (CRC-32 of everything above)
//! frames   n_frames × block, in frame order:
//!          frame i32, n_fields × n_vertices × f32, block_crc u32 (of frame + data)
//! ```
//! Blocks have a fixed size, so frame `f` is at a computed offset and playback reads one
//! block, not the whole file. Values are kept at full `f32` precision: densities span
//! orders of magnitude (a faint halo next to a saturated centre), and the shader needs the
//! faint end.
//!
//! ## Versions
//! Version 1 (Madder before the LCS tools) has no `frame_time`; the reader reads both, and
//! [`CacheReader::frame_time`] is `None` for a version-1 file (or a version-2 file written
//! without one). Version 2 records the time between frames because the fields may include
//! a velocity (the add-on's optional `velocity_x/y/z`, m/s, with the cloth's
//! `position_x/y/z`, m): integrating it (seed ch. 5, `lcs`) needs the bake's frame time,
//! which the scene's frame rate no longer tells once it is changed after the bake. Which
//! fields a cache holds is already in its header (named fields), so the velocity itself
//! needed no format change: a cache without it simply lacks those names.
//!
//! ## Safety
//! [`CacheWriter`] writes to a temporary file next to the target and renames it over the
//! target only in [`CacheWriter::finish`], after an fsync: a bake that fails or is
//! cancelled (writer dropped) leaves the previous cache untouched. [`CacheReader`]
//! validates the header, the file length and each block's checksum, and names the file and
//! frame in every error, so a truncated or corrupt file is reported, never trusted.
//!
//! ## Damaged files
//! A damaged cache is read as far as it is whole. Blocks have a fixed size and each carries
//! its own checksum, so the header alone tells which blocks a short file still holds: a
//! file cut inside frame `k` opens, frames before `k` read normally, and reading frame `k`
//! or a later one is [`CacheError::Truncated`] naming the frame read and the first one cut
//! ([`CacheReader::truncated_at`]). A block whose checksum fails is
//! [`CacheError::Checksum`] for that frame only; its neighbours still read. Only a damaged
//! header (or a file longer than its frames: not a file this writer made) refuses the
//! whole file.

use std::fs::File;
use std::io::{BufWriter, Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

use crate::error::CacheError;
use crate::io::attributes::{StainColour, stain_attributes};

pub(crate) const MAGIC: &[u8; 8] = b"MADDERC\0";
pub(crate) const VERSION: u32 = 2;
/// The first version, without `frame_time`, still read.
pub(crate) const VERSION_1: u32 = 1;
const NAME_LEN: usize = 32;

/// Streams frames into a new cache file; the target is replaced only on [`finish`](Self::finish).
pub struct CacheWriter {
    path: PathBuf,
    tmp: PathBuf,
    out: Option<BufWriter<File>>,
    n_vertices: usize,
    n_fields: usize,
    first_frame: i32,
    n_frames: u32,
    n_frames_expected: u32,
}

impl CacheWriter {
    /// Starts a cache for `n_frames` frames from `first_frame`, with fields `names` (no
    /// frame time recorded).
    pub fn create(
        path: impl AsRef<Path>,
        n_vertices: usize,
        names: &[&str],
        first_frame: i32,
        n_frames: u32,
    ) -> Result<Self, CacheError> {
        Self::create_timed(path, n_vertices, names, first_frame, n_frames, 0.0)
    }

    /// [`Self::create`], recording `frame_time` seconds between frames (finite, > 0; 0 records
    /// none).
    pub fn create_timed(
        path: impl AsRef<Path>,
        n_vertices: usize,
        names: &[&str],
        first_frame: i32,
        n_frames: u32,
        frame_time: f64,
    ) -> Result<Self, CacheError> {
        let path = path.as_ref().to_path_buf();
        let usage = |reason: String| CacheError::Usage { reason };
        if names.is_empty() {
            return Err(usage("a cache needs at least one field".into()));
        }
        if let Some(n) = names
            .iter()
            .find(|n| n.is_empty() || n.len() > NAME_LEN || n.contains('\0'))
        {
            return Err(usage(format!(
                "field name '{n}' must be 1..={NAME_LEN} bytes without NUL"
            )));
        }
        if n_vertices == 0 || n_vertices > u32::MAX as usize {
            return Err(usage(format!("vertex count {n_vertices} out of range")));
        }
        if !frame_range_fits(first_frame, n_frames) {
            return Err(usage(format!(
                "{n_frames} frames from frame {first_frame} run past the i32 frame range"
            )));
        }
        if !(frame_time.is_finite() && frame_time >= 0.0) {
            return Err(usage(format!(
                "frame time {frame_time} s must be finite and ≥ 0 (0: not recorded)"
            )));
        }
        let mut tmp_name = path.file_name().unwrap_or_default().to_os_string();
        tmp_name.push(format!(".tmp{}", std::process::id()));
        let tmp = path.with_file_name(tmp_name);
        let io = |source| CacheError::Io {
            path: tmp.clone(),
            source,
        };
        let mut out = BufWriter::new(File::create(&tmp).map_err(io)?);
        let mut header = Vec::new();
        header.extend_from_slice(MAGIC);
        header.extend_from_slice(&VERSION.to_le_bytes());
        header.extend_from_slice(&(n_vertices as u32).to_le_bytes());
        header.extend_from_slice(&(names.len() as u32).to_le_bytes());
        header.extend_from_slice(&first_frame.to_le_bytes());
        header.extend_from_slice(&n_frames.to_le_bytes());
        header.extend_from_slice(&frame_time.to_le_bytes());
        for n in names {
            let mut field = [0u8; NAME_LEN];
            field[..n.len()].copy_from_slice(n.as_bytes());
            header.extend_from_slice(&field);
        }
        let crc = crc32fast::hash(&header);
        header.extend_from_slice(&crc.to_le_bytes());
        out.write_all(&header).map_err(io)?;
        Ok(Self {
            path,
            tmp,
            out: Some(out),
            n_vertices,
            n_fields: names.len(),
            first_frame,
            n_frames: 0,
            n_frames_expected: n_frames,
        })
    }

    /// Appends the next frame: `fields[k]` holds field `k` for every vertex.
    pub fn push_frame(&mut self, fields: &[&[f32]]) -> Result<(), CacheError> {
        if self.n_frames >= self.n_frames_expected {
            return Err(CacheError::Usage {
                reason: format!("all {} frames are already written", self.n_frames),
            });
        }
        if fields.len() != self.n_fields || fields.iter().any(|f| f.len() != self.n_vertices) {
            return Err(CacheError::Usage {
                reason: format!(
                    "expected {} fields of {} values",
                    self.n_fields, self.n_vertices
                ),
            });
        }
        // fits: the range was checked in create
        let frame = (self.first_frame as i64 + self.n_frames as i64) as i32;
        let mut block = Vec::with_capacity(8 + 4 * self.n_fields * self.n_vertices);
        block.extend_from_slice(&frame.to_le_bytes());
        for f in fields {
            for v in f.iter() {
                block.extend_from_slice(&v.to_le_bytes());
            }
        }
        let crc = crc32fast::hash(&block);
        block.extend_from_slice(&crc.to_le_bytes());
        let tmp = &self.tmp;
        let out = self.out.as_mut().expect("writer is open until finish");
        out.write_all(&block).map_err(|source| CacheError::Io {
            path: tmp.clone(),
            source,
        })?;
        self.n_frames += 1;
        Ok(())
    }

    /// Flushes, syncs and atomically moves the finished file over the target.
    pub fn finish(mut self) -> Result<PathBuf, CacheError> {
        if self.n_frames != self.n_frames_expected {
            return Err(CacheError::Usage {
                reason: format!(
                    "{} of {} frames written",
                    self.n_frames, self.n_frames_expected
                ),
            });
        }
        let io = |source| CacheError::Io {
            path: self.tmp.clone(),
            source,
        };
        let out = self.out.take().expect("writer is open until finish");
        let file = out.into_inner().map_err(|e| io(e.into_error()))?;
        file.sync_all().map_err(io)?;
        drop(file);
        std::fs::rename(&self.tmp, &self.path).map_err(|source| CacheError::Io {
            path: self.path.clone(),
            source,
        })?;
        Ok(self.path.clone())
    }
}

impl Drop for CacheWriter {
    /// An unfinished writer removes its temporary file; the previous cache stays.
    fn drop(&mut self) {
        if self.out.take().is_some() {
            let _ = std::fs::remove_file(&self.tmp);
        }
    }
}

/// Random access to the frames of a cache file.
#[derive(Debug)]
pub struct CacheReader {
    path: PathBuf,
    file: File,
    n_vertices: usize,
    names: Vec<String>,
    first_frame: i32,
    n_frames: u32,
    version: u32,
    frame_time: Option<f64>,
    /// Whole blocks in the file (`n_frames` unless it is truncated).
    complete: u32,
    header_len: u64,
    /// The last block read and its decoded values, reused (playback reads every frame).
    block: Vec<u8>,
    values: Vec<f32>,
}

impl CacheReader {
    /// Opens a cache and checks its header (a truncated file opens: see
    /// [`Self::truncated_at`]); every error names the file.
    pub fn open(path: impl AsRef<Path>) -> Result<Self, CacheError> {
        let path = path.as_ref().to_path_buf();
        let io = |source| CacheError::Io {
            path: path.clone(),
            source,
        };
        let mut file = File::open(&path).map_err(io)?;
        let header_err = |reason: &str| CacheError::Header {
            path: path.clone(),
            reason: reason.into(),
        };
        let mut fixed = [0u8; 28];
        read_exact_or(&mut file, &mut fixed, || {
            header_err("file is shorter than the header")
        })?;
        if &fixed[..8] != MAGIC {
            return Err(CacheError::BadMagic { path });
        }
        let word = |i: usize| u32::from_le_bytes(fixed[i..i + 4].try_into().unwrap());
        let version = word(8);
        if version != VERSION && version != VERSION_1 {
            return Err(CacheError::Version {
                path,
                found: version,
                supported: VERSION,
            });
        }
        let (n_vertices, n_fields, first_frame, n_frames) = (
            word(12) as usize,
            word(16) as usize,
            word(20) as i32,
            word(24),
        );
        if n_vertices == 0 || n_fields == 0 || n_fields > 64 {
            return Err(header_err("vertex or field count out of range"));
        }
        if !frame_range_fits(first_frame, n_frames) {
            return Err(header_err("frame range does not fit in i32"));
        }
        let timed = if version == VERSION { 8 } else { 0 };
        let mut rest = vec![0u8; timed + n_fields * NAME_LEN + 4];
        read_exact_or(&mut file, &mut rest, || {
            header_err("file is shorter than the header")
        })?;
        let mut header = fixed.to_vec();
        let (rest, crc) = rest.split_at(timed + n_fields * NAME_LEN);
        header.extend_from_slice(rest);
        let crc = u32::from_le_bytes(crc.try_into().unwrap());
        if crc32fast::hash(&header) != crc {
            return Err(header_err("header checksum mismatch"));
        }
        let (time, rest) = rest.split_at(timed);
        let frame_time = match time.try_into().map(f64::from_le_bytes) {
            Ok(t) if t > 0.0 && t.is_finite() => Some(t),
            Ok(0.0) => None,
            Ok(_) => return Err(header_err("frame time is not a finite positive number")),
            Err(_) => None, // version 1: not recorded
        };
        let names = rest
            .chunks(NAME_LEN)
            .map(|c| {
                let end = c.iter().position(|&b| b == 0).unwrap_or(NAME_LEN);
                String::from_utf8(c[..end].to_vec())
                    .map_err(|_| header_err("field name is not UTF-8"))
            })
            .collect::<Result<Vec<_>, _>>()?;
        let header_len = header.len() as u64 + 4;
        let mut reader = Self {
            path: path.clone(),
            file,
            n_vertices,
            names,
            first_frame,
            n_frames,
            version,
            frame_time,
            complete: n_frames,
            header_len,
            block: Vec::new(),
            values: Vec::new(),
        };
        let len = reader
            .file
            .metadata()
            .map_err(|source| CacheError::Io {
                path: reader.path.clone(),
                source,
            })?
            .len();
        let expected = reader
            .block_len()
            .checked_mul(n_frames as u64)
            .and_then(|frames| frames.checked_add(reader.header_len))
            .ok_or_else(|| header_err("declared size overflows 64 bits"))?;
        if len < expected {
            // a truncated file keeps its whole blocks readable; < n_frames, so it fits u32
            reader.complete = (len.saturating_sub(reader.header_len) / reader.block_len()) as u32;
        }
        if len > expected {
            return Err(header_err("file is longer than its frames"));
        }
        Ok(reader)
    }

    /// The file.
    pub fn path(&self) -> &Path {
        &self.path
    }
    /// Values per field and frame.
    pub fn n_vertices(&self) -> usize {
        self.n_vertices
    }
    /// The fields of every frame, in stored order.
    pub fn field_names(&self) -> &[String] {
        &self.names
    }
    /// The format version of the file (1 or 2).
    pub fn version(&self) -> u32 {
        self.version
    }
    /// Seconds between frames, as the bake recorded it (`None`: a version-1 file, or none
    /// recorded).
    pub fn frame_time(&self) -> Option<f64> {
        self.frame_time
    }
    /// The first frame the header declares.
    pub fn first_frame(&self) -> i32 {
        self.first_frame
    }
    /// Frames the header declares (a truncated file holds fewer).
    pub fn n_frames(&self) -> u32 {
        self.n_frames
    }
    /// The last frame the header declares.
    pub fn last_frame(&self) -> i32 {
        // fits: the range was checked at open
        (self.first_frame as i64 + self.n_frames as i64 - 1) as i32
    }
    /// How many frames, from the first, have their whole block in the file (all of them
    /// unless the file is truncated). Their checksums are verified when they are read.
    pub fn complete_frames(&self) -> u32 {
        self.complete
    }
    /// The first frame whose block is cut off, when the file is truncated.
    pub fn truncated_at(&self) -> Option<i32> {
        // < n_frames, so within the range checked at open
        (self.complete < self.n_frames)
            .then(|| (self.first_frame as i64 + self.complete as i64) as i32)
    }

    fn block_len(&self) -> u64 {
        8 + 4 * (self.names.len() * self.n_vertices) as u64
    }

    /// Reads field `name` of `frame`, checking the block's checksum.
    pub fn read(&mut self, frame: i32, name: &str) -> Result<Vec<f32>, CacheError> {
        let k = self.field(name)?;
        let n = self.n_vertices;
        let body = self.read_block(frame)?;
        Ok(decode(&body[4 + 4 * k * n..][..4 * n]))
    }

    /// Reads every field of `frame` with one read and one checksum: field `k` is
    /// `values[k * n_vertices..(k + 1) * n_vertices]`, in the order of [`Self::field_names`].
    pub fn read_frame(&mut self, frame: i32) -> Result<Vec<f32>, CacheError> {
        let body = self.read_block(frame)?;
        Ok(decode(&body[4..]))
    }

    /// The playback attributes of `frame` ([`crate::io::attributes`]) into `rgba` (4 per
    /// vertex), `wetness` and `deposit`, from the fields a bake writes: `solute`,
    /// `wetness`, `deposit`, and `color_r`/`color_g`/`color_b` when it tracked colours
    /// (else the stain is `colour`); `clamp` false keeps fractions over 1 (for the weave's
    /// detail), and `excess` takes the images' share of the dye above saturation (module
    /// [`crate::io::attributes`]). One read and one checksum; no allocation once the reader
    /// has read a frame.
    ///
    /// # Panics
    /// When the buffers' lengths are not `4 × n_vertices`, `n_vertices`, `n_vertices` (and
    /// `n_vertices` for `excess`).
    #[allow(clippy::too_many_arguments)]
    pub fn read_stain(
        &mut self,
        frame: i32,
        references: [f32; 3],
        colour: [f32; 3],
        clamp: bool,
        rgba: &mut [f32],
        wetness: &mut [f32],
        deposit: &mut [f32],
        excess: Option<&mut [f32]>,
    ) -> Result<(), CacheError> {
        let [s, w, d] = [
            self.field("solute")?,
            self.field("wetness")?,
            self.field("deposit")?,
        ];
        let rgb = match ["color_r", "color_g", "color_b"].map(|c| self.field(c)) {
            [Ok(r), Ok(g), Ok(b)] => Some([r, g, b]),
            _ => None,
        };
        self.read_block(frame)?;
        let mut values = std::mem::take(&mut self.values);
        values.resize(self.names.len() * self.n_vertices, 0.0);
        decode_into(&self.block[4..self.block.len() - 4], &mut values);
        let n = self.n_vertices;
        let f = |k: usize| &values[k * n..(k + 1) * n];
        let colour = match rgb {
            Some([r, g, b]) => StainColour::PerVertex([f(r), f(g), f(b)]),
            None => StainColour::Uniform(colour),
        };
        stain_attributes(
            f(s),
            f(w),
            f(d),
            colour,
            references,
            clamp,
            rgba,
            wetness,
            deposit,
            excess,
        );
        self.values = values;
        Ok(())
    }

    fn field(&self, name: &str) -> Result<usize, CacheError> {
        self.names
            .iter()
            .position(|n| n == name)
            .ok_or_else(|| CacheError::FieldMissing {
                path: self.path.clone(),
                field: name.into(),
            })
    }

    /// Reads and checks `frame`'s block into `self.block`; returns its body (frame number
    /// + field data, without the checksum).
    fn read_block(&mut self, frame: i32) -> Result<&[u8], CacheError> {
        if frame < self.first_frame || frame > self.last_frame() {
            return Err(CacheError::FrameMissing {
                path: self.path.clone(),
                frame,
                first: self.first_frame,
                last: self.last_frame(),
            });
        }
        let index = (frame as i64 - self.first_frame as i64) as u64;
        if let Some(first_cut) = self
            .truncated_at()
            .filter(|_| index >= self.complete as u64)
        {
            return Err(CacheError::Truncated {
                path: self.path.clone(),
                frame,
                first_cut,
            });
        }
        let offset = self.header_len + self.block_len() * index;
        // a whole block is in the file, so this allocation is bounded by its size
        self.block.resize(self.block_len() as usize, 0);
        let path = &self.path;
        self.file
            .seek(SeekFrom::Start(offset))
            .map_err(|source| CacheError::Io {
                path: path.clone(),
                source,
            })?;
        // the file shrank after it was opened (it is replaced by rename, so this is rare)
        read_exact_or(&mut self.file, &mut self.block, || CacheError::Truncated {
            path: path.clone(),
            frame,
            first_cut: frame,
        })?;
        let (body, crc) = self.block.split_at(self.block.len() - 4);
        let stored_frame = i32::from_le_bytes(body[..4].try_into().unwrap());
        if crc32fast::hash(body) != u32::from_le_bytes(crc.try_into().unwrap())
            || stored_frame != frame
        {
            return Err(CacheError::Checksum {
                path: path.clone(),
                frame,
            });
        }
        Ok(body)
    }
}

/// Whether frames `first..first + n` (and `last_frame() = first + n − 1`, also for `n = 0`)
/// are all representable as `i32`.
fn frame_range_fits(first: i32, n: u32) -> bool {
    let last = first as i64 + n as i64 - 1;
    last <= i32::MAX as i64 && last >= i32::MIN as i64
}

fn decode(bytes: &[u8]) -> Vec<f32> {
    bytes
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes(c.try_into().unwrap()))
        .collect()
}

fn decode_into(bytes: &[u8], out: &mut [f32]) {
    for (v, c) in out.iter_mut().zip(bytes.chunks_exact(4)) {
        *v = f32::from_le_bytes(c.try_into().unwrap());
    }
}

fn read_exact_or(
    file: &mut File,
    buf: &mut [u8],
    err: impl FnOnce() -> CacheError,
) -> Result<(), CacheError> {
    file.read_exact(buf).map_err(|_| err())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tmpdir(tag: &str) -> PathBuf {
        let d =
            std::env::temp_dir().join(format!("madder-cache-test-{tag}-{}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    fn write(path: &Path, scale: f32) {
        let mut w = CacheWriter::create(path, 3, &["density", "other"], 5, 2).unwrap();
        for f in 0..2 {
            let a: Vec<f32> = (0..3).map(|v| scale * (10 * f + v) as f32).collect();
            let b: Vec<f32> = a.iter().map(|x| -x).collect();
            w.push_frame(&[&a, &b]).unwrap();
        }
        w.finish().unwrap();
    }

    #[test]
    fn round_trip_and_errors_name_file_and_frame() {
        let d = tmpdir("rt");
        let p = d.join("c.madder");
        write(&p, 1.0);
        let mut r = CacheReader::open(&p).unwrap();
        assert_eq!((r.first_frame(), r.last_frame(), r.n_vertices()), (5, 6, 3));
        assert_eq!(r.read(6, "density").unwrap(), vec![10.0, 11.0, 12.0]);
        assert_eq!(r.read(5, "other").unwrap(), vec![0.0, -1.0, -2.0]);
        assert_eq!(
            r.read_frame(6).unwrap(),
            [r.read(6, "density").unwrap(), r.read(6, "other").unwrap()].concat()
        );
        assert!(matches!(
            r.read(7, "density"),
            Err(CacheError::FrameMissing { frame: 7, .. })
        ));
        assert!(matches!(
            r.read(5, "nope"),
            Err(CacheError::FieldMissing { .. })
        ));

        // truncation keeps the whole frames and names the first incomplete one
        let bytes = std::fs::read(&p).unwrap();
        std::fs::write(&p, &bytes[..bytes.len() - 5]).unwrap();
        let mut r = CacheReader::open(&p).unwrap();
        assert_eq!((r.truncated_at(), r.complete_frames()), (Some(6), 1));
        assert_eq!(r.read(5, "density").unwrap(), vec![0.0, 1.0, 2.0]);
        let err = r.read(6, "density").unwrap_err();
        assert!(
            matches!(
                err,
                CacheError::Truncated {
                    frame: 6,
                    first_cut: 6,
                    ..
                }
            ),
            "{err}"
        );
        assert!(err.to_string().contains("c.madder"));

        // a flipped bit in frame 6 is caught by its checksum
        let mut bad = bytes.clone();
        let n = bad.len();
        bad[n - 10] ^= 0x40;
        std::fs::write(&p, &bad).unwrap();
        let mut r = CacheReader::open(&p).unwrap();
        assert!(r.read(5, "density").is_ok());
        assert!(matches!(
            r.read(6, "density"),
            Err(CacheError::Checksum { frame: 6, .. })
        ));

        std::fs::write(&p, b"not a cache at all, just text....").unwrap();
        assert!(matches!(
            CacheReader::open(&p),
            Err(CacheError::BadMagic { .. })
        ));
    }

    /// Regression (found by `fuzz/cache_reader`): a header whose frame range or total size
    /// does not fit overflowed at open; now it is a header error.
    #[test]
    fn header_counts_that_overflow_are_header_errors() {
        let d = tmpdir("overflow");
        let p = d.join("c.madder");
        let header = |n_vertices: u32, first_frame: i32, n_frames: u32| {
            let mut h = MAGIC.to_vec();
            for w in [VERSION, n_vertices, 1, first_frame as u32, n_frames] {
                h.extend_from_slice(&w.to_le_bytes());
            }
            h.extend_from_slice(&0f64.to_le_bytes());
            h.extend_from_slice(&[b'd'; NAME_LEN]);
            let crc = crc32fast::hash(&h);
            h.extend_from_slice(&crc.to_le_bytes());
            h.extend_from_slice(&[0; 64]);
            h
        };
        for (h, why) in [
            (header(u32::MAX, i32::MIN, u32::MAX), "overflows"),
            (header(1, i32::MAX - 1, 3), "frame range"),
            (header(1, i32::MIN, 0), "frame range"),
        ] {
            std::fs::write(&p, &h).unwrap();
            match CacheReader::open(&p) {
                Err(e @ CacheError::Header { .. }) => assert!(e.to_string().contains(why), "{e}"),
                other => panic!("expected a header error, got {other:?}"),
            }
        }
        assert!(matches!(
            CacheWriter::create(&p, 1, &["d"], i32::MAX, 2),
            Err(CacheError::Usage { .. })
        ));
    }

    #[test]
    fn unfinished_writer_keeps_previous_cache() {
        let d = tmpdir("atomic");
        let p = d.join("c.madder");
        write(&p, 1.0);
        let before = std::fs::read(&p).unwrap();
        {
            let mut w = CacheWriter::create(&p, 3, &["density"], 1, 3).unwrap();
            w.push_frame(&[&[9.0, 9.0, 9.0]]).unwrap();
            // dropped here: a cancelled bake
        }
        assert_eq!(std::fs::read(&p).unwrap(), before);
        assert_eq!(
            std::fs::read_dir(&d).unwrap().count(),
            1,
            "temporary file removed"
        );
        // a finished writer replaces it
        write(&p, 2.0);
        assert_eq!(
            CacheReader::open(&p).unwrap().read(6, "density").unwrap(),
            vec![20.0, 22.0, 24.0]
        );
    }
}
