//! The encoder: options, what it measured, and [`MotionEncoder`], which writes a file
//! frame by frame and decodes its own output (closed loop).

use std::fs::File;
use std::io::{BufWriter, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

use glam::DVec3;

use super::format::{
    Decoding, FLAG_CORNERS_ONCE, FLAG_TRACKED, FLAG_WALK_KEYS, HEADER, MAGIC, VERSION, io_err,
};
use super::frame::{Similarity, extrapolates, is_key, reconstruct};
use super::quant::{History, encode_stream, quantize};
use crate::angles::encode::AngleMesh;
use crate::error::CodecError;

/// Options of [`MotionEncoder`].
#[derive(Debug, Clone, PartialEq)]
pub struct CodecOptions {
    /// Scene frame of sample 0 (PC2 meaning).
    pub start: f64,
    /// Scene frames between samples (PC2 meaning).
    pub rate: f64,
    /// Quantization bits of the dihedral angles (step `2π/2^bits`), 4..=20.
    pub bits: u32,
    /// Quantization bits of the corner angles, 4..=20.
    pub corner_bits: u32,
    /// Corner angles only in frame 0 (else every frame).
    pub corners_once: bool,
    /// Keyframe interval `K` of the warm-started decoding (module docs), 0..=255; 0: every
    /// frame reconstructed cold.
    pub keyframe_interval: u32,
    /// Warm frames by the tracked reconstruction ([`AngleMesh::reconstruct_tracked`], the
    /// default) instead of the warm-started spectral one (module docs).
    pub tracked: bool,
}

impl Default for CodecOptions {
    fn default() -> Self {
        Self {
            start: 1.0,
            rate: 1.0,
            bits: 12,
            corner_bits: 12,
            corners_once: false,
            keyframe_interval: 16,
            tracked: true,
        }
    }
}

/// What the encoder measured by decoding its own output.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CodecStats {
    /// Frames written.
    pub frames: usize,
    /// Vertices per frame.
    pub vertices: usize,
    /// Size of the file.
    pub bytes: u64,
    /// `8 · bytes / (vertices · frames)`, header and connectivity included.
    pub bits_per_vertex_frame: f64,
    /// Largest vertex error over the bounding-box diagonal of the whole sequence.
    pub max_error: f64,
    /// RMS vertex error over the same diagonal.
    pub rms_error: f64,
    /// The diagonal (object units).
    pub diagonal: f64,
}

/// Writes a motion file frame by frame (module docs).
#[derive(Debug)]
pub struct MotionEncoder {
    pub(super) path: PathBuf,
    pub(super) tmp: PathBuf,
    pub(super) file: Option<BufWriter<File>>,
    pub(super) mesh: AngleMesh,
    pub(super) options: CodecOptions,
    pub(super) corners: History,
    pub(super) dihedrals: History,
    /// The previous frame's normalized reconstruction (the warm start).
    pub(super) prev_y: Option<Vec<DVec3>>,
    /// The one before, when it is of the same chain (the extrapolated start).
    pub(super) before_y: Option<Vec<DVec3>>,
    pub(super) frames: usize,
    pub(super) bytes: u64,
    pub(super) max_abs: f64,
    pub(super) sum_sq: f64,
    pub(super) lo: DVec3,
    pub(super) hi: DVec3,
}

impl MotionEncoder {
    /// Starts a motion file at `path` for the triangles `faces` (vertex count: the largest
    /// index + 1). Errors: options out of range, connectivity the angles cannot describe
    /// (names the edge or vertex), the temporary file not writable.
    pub fn create(
        path: impl AsRef<Path>,
        faces: Vec<[u32; 3]>,
        options: CodecOptions,
    ) -> Result<Self, CodecError> {
        let path = path.as_ref().to_path_buf();
        let usage = |reason: String| CodecError::Usage {
            path: path.clone(),
            reason,
        };
        for (name, b) in [("bits", options.bits), ("corner_bits", options.corner_bits)] {
            if !(4..=20).contains(&b) {
                return Err(usage(format!("{name} must be in 4..=20, got {b}")));
            }
        }
        for (name, v) in [("start", options.start), ("rate", options.rate)] {
            if !v.is_finite() {
                return Err(usage(format!("{name} must be finite, got {v}")));
            }
        }
        if options.rate <= 0.0 {
            return Err(usage(format!("rate must be > 0, got {}", options.rate)));
        }
        if options.keyframe_interval > 255 {
            return Err(usage(format!(
                "keyframe_interval must be in 0..=255, got {}",
                options.keyframe_interval
            )));
        }
        let n = faces
            .iter()
            .flatten()
            .map(|&v| v as usize + 1)
            .max()
            .unwrap_or(0);
        let mesh = AngleMesh::new(n, faces).map_err(|source| CodecError::Mesh {
            path: path.clone(),
            source,
        })?;
        mesh.check_connected().map_err(|source| CodecError::Mesh {
            path: path.clone(),
            source,
        })?;
        let name = path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        let tmp = path.with_file_name(format!(".{name}.{}.partial", std::process::id()));
        let file = File::create(&tmp).map_err(io_err(&tmp))?;
        let mut enc = Self {
            path,
            tmp,
            file: Some(BufWriter::new(file)),
            mesh,
            options,
            corners: History::default(),
            dihedrals: History::default(),
            prev_y: None,
            before_y: None,
            frames: 0,
            bytes: 0,
            max_abs: 0.0,
            sum_sq: 0.0,
            lo: DVec3::INFINITY,
            hi: DVec3::NEG_INFINITY,
        };
        let head = enc.header();
        enc.write(&head)?;
        Ok(enc)
    }

    pub(super) fn header(&self) -> Vec<u8> {
        let o = &self.options;
        let mut h = Vec::with_capacity(HEADER + 12 * self.mesh.n_faces());
        h.extend_from_slice(MAGIC);
        h.extend_from_slice(&VERSION.to_le_bytes());
        h.extend_from_slice(&(self.mesh.n_vertices() as u32).to_le_bytes());
        h.extend_from_slice(&(self.mesh.n_faces() as u32).to_le_bytes());
        h.extend_from_slice(&(self.frames as u32).to_le_bytes());
        h.extend_from_slice(&o.start.to_le_bytes());
        h.extend_from_slice(&o.rate.to_le_bytes());
        let flags = if o.corners_once { FLAG_CORNERS_ONCE } else { 0 }
            | if o.tracked {
                FLAG_TRACKED | FLAG_WALK_KEYS
            } else {
                0
            };
        h.extend_from_slice(&[
            o.bits as u8,
            o.corner_bits as u8,
            flags,
            o.keyframe_interval as u8,
        ]);
        let mut faces = Vec::with_capacity(12 * self.mesh.n_faces());
        for f in self.mesh.faces() {
            for v in f {
                faces.extend_from_slice(&v.to_le_bytes());
            }
        }
        let mut crc = crc32fast::Hasher::new();
        crc.update(&h);
        crc.update(&faces);
        h.extend_from_slice(&crc.finalize().to_le_bytes());
        h.extend(faces);
        h
    }

    pub(super) fn write(&mut self, data: &[u8]) -> Result<(), CodecError> {
        let file = self.file.as_mut().ok_or_else(|| CodecError::Usage {
            path: self.path.clone(),
            reason: "the encoder is finished".into(),
        })?;
        file.write_all(data).map_err(io_err(&self.tmp))?;
        self.bytes += data.len() as u64;
        Ok(())
    }

    /// Vertices per frame.
    pub fn n_points(&self) -> usize {
        self.mesh.n_vertices()
    }

    /// Encodes the next frame. Errors name the frame and the vertex or face: a count that
    /// does not match, a non-finite position, a degenerate face. Returns the positions the
    /// decoder will produce for it.
    pub fn add_frame(&mut self, positions: &[DVec3]) -> Result<Vec<[f32; 3]>, CodecError> {
        if self.file.is_none() {
            return Err(CodecError::Usage {
                path: self.path.clone(),
                reason: "the encoder is finished".into(),
            });
        }
        let frame = self.frames;
        let input = |source| CodecError::Input {
            path: self.path.clone(),
            frame,
            source,
        };
        let angles = self.mesh.encode(positions).map_err(input)?;
        let o = self.options.clone();
        let qd: Vec<i64> = angles
            .dihedrals
            .iter()
            .map(|&a| quantize(a, o.bits))
            .collect();
        let send_corners = !(o.corners_once && frame > 0);
        let qc: Vec<i64> = if send_corners {
            angles
                .corners
                .iter()
                .flatten()
                .map(|&a| quantize(a, o.corner_bits))
                .collect()
        } else {
            self.corners.prev.clone().unwrap_or_default()
        };
        let key = o.keyframe_interval;
        let previous = match (&self.prev_y, is_key(frame, key)) {
            (Some(p), false) => Some(p.as_slice()),
            _ => None,
        };
        let before = match (&self.before_y, extrapolates(frame, key)) {
            (Some(p), true) => Some(p.as_slice()),
            _ => None,
        };
        let bits = (o.bits, o.corner_bits);
        let decoding = if o.tracked {
            Decoding::Tracked
        } else {
            Decoding::Spectral
        };
        let y = reconstruct(&self.mesh, &qc, &qd, bits, (previous, before), decoding).map_err(
            |source| CodecError::Reconstruct {
                path: self.path.clone(),
                frame,
                source,
            },
        )?;
        let sim = Similarity::fit(&y, positions);
        let out = sim.apply(&y);
        let mut payload = Vec::new();
        for c in sim.0 {
            payload.extend_from_slice(&c.to_le_bytes());
        }
        if send_corners {
            encode_stream(&qc, &self.corners, o.corner_bits, &mut payload);
        }
        encode_stream(&qd, &self.dihedrals, o.bits, &mut payload);
        if send_corners {
            self.corners.push(qc);
        }
        self.dihedrals.push(qd);
        let mut block = Vec::with_capacity(payload.len() + 8);
        block.extend_from_slice(&(payload.len() as u32).to_le_bytes());
        block.extend_from_slice(&crc32fast::hash(&payload).to_le_bytes());
        block.extend(payload);
        self.write(&block)?;
        self.before_y = self.prev_y.replace(y);
        for (p, q) in positions.iter().zip(&out) {
            let d = (*p - DVec3::new(q[0] as f64, q[1] as f64, q[2] as f64)).length();
            self.max_abs = self.max_abs.max(d);
            self.sum_sq += d * d;
            self.lo = self.lo.min(*p);
            self.hi = self.hi.max(*p);
        }
        self.frames += 1;
        Ok(out)
    }

    /// Writes the frame count, renames the file into place and returns what was measured.
    pub fn finish(mut self) -> Result<CodecStats, CodecError> {
        if self.frames == 0 {
            return Err(CodecError::Usage {
                path: self.path.clone(),
                reason: "no frames were added".into(),
            });
        }
        let head = self.header();
        let Some(file) = self.file.take() else {
            return Err(CodecError::Usage {
                path: self.path.clone(),
                reason: "the encoder is finished".into(),
            });
        };
        let tmp = self.tmp.clone();
        let mut file = file.into_inner().map_err(|e| CodecError::Io {
            path: tmp.clone(),
            source: e.into_error(),
        })?;
        file.seek(SeekFrom::Start(0)).map_err(io_err(&tmp))?;
        file.write_all(&head[..HEADER]).map_err(io_err(&tmp))?;
        file.sync_all().map_err(io_err(&tmp))?;
        drop(file);
        std::fs::rename(&tmp, &self.path).map_err(io_err(&self.path))?;
        let n = (self.frames * self.mesh.n_vertices()) as f64;
        let diagonal = (self.hi - self.lo).length();
        let d = if diagonal > 0.0 { diagonal } else { 1.0 };
        Ok(CodecStats {
            frames: self.frames,
            vertices: self.mesh.n_vertices(),
            bytes: self.bytes,
            bits_per_vertex_frame: 8.0 * self.bytes as f64 / n,
            max_error: self.max_abs / d,
            rms_error: (self.sum_sq / n).sqrt() / d,
            diagonal,
        })
    }

    /// Drops the temporary file; the target path is untouched.
    pub fn abort(mut self) {
        self.discard();
    }

    pub(super) fn discard(&mut self) {
        if self.file.take().is_some() {
            let _ = std::fs::remove_file(&self.tmp);
        }
    }
}

impl Drop for MotionEncoder {
    fn drop(&mut self) {
        self.discard();
    }
}
