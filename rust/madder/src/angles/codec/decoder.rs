//! The decoder: [`MotionDecoder`] opens a file, checks it, and reads frames in any
//! order (from the nearest keyframe).

use std::fs::File;
use std::io::{Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};

use glam::DVec3;

use super::entropy;
use super::format::{
    Decoding, FLAG_CORNERS_ONCE, FLAG_TRACKED, FLAG_WALK_KEYS, HEADER, MAGIC, VERSION, io_err,
    read_up_to,
};
use super::frame::{Similarity, extrapolates, is_key, reconstruct};
use super::quant::{History, parse_stream};
use crate::angles::encode::AngleMesh;
use crate::error::CodecError;

/// Reads a motion file (module docs). Opening validates the header, the connectivity and
/// that every declared frame is present; frames are decoded on demand.
#[derive(Debug)]
pub struct MotionDecoder {
    pub(super) path: PathBuf,
    pub(super) mesh: AngleMesh,
    pub(super) start: f64,
    pub(super) rate: f64,
    pub(super) bits: u32,
    pub(super) corner_bits: u32,
    pub(super) corners_once: bool,
    pub(super) keyframe_interval: u32,
    pub(super) decoding: Decoding,
    /// Byte range of every frame's payload and its checksum.
    pub(super) blocks: Vec<(u64, u32, u32)>,
    pub(super) file: File,
    /// The next frame whose streams would be decoded, and the state before it.
    pub(super) next: usize,
    pub(super) corners: History,
    pub(super) dihedrals: History,
    /// The placement of frame `next − 1`.
    pub(super) last: Option<Similarity>,
    /// The normalized reconstruction of frame `next − 1`, when it was reconstructed.
    pub(super) last_y: Option<Vec<DVec3>>,
    /// The normalized reconstruction before `last_y`, when of the same chain.
    pub(super) before_y: Option<Vec<DVec3>>,
}

impl MotionDecoder {
    /// Opens `path`. Errors name the file: missing, bad magic, another version, a damaged
    /// header or connectivity, a frame cut off (named).
    pub fn open(path: impl AsRef<Path>) -> Result<Self, CodecError> {
        let path = path.as_ref().to_path_buf();
        let header = |reason: &str| CodecError::Header {
            path: path.clone(),
            reason: reason.to_string(),
        };
        let mut file = File::open(&path).map_err(io_err(&path))?;
        let len = file.metadata().map_err(io_err(&path))?.len();
        let mut h = [0u8; HEADER];
        let got = read_up_to(&mut file, &mut h).map_err(io_err(&path))?;
        if got < 8 || &h[..8] != MAGIC {
            return Err(CodecError::BadMagic { path });
        }
        if got < HEADER {
            return Err(header("the file ends inside the header"));
        }
        let u32_at = |i: usize| u32::from_le_bytes([h[i], h[i + 1], h[i + 2], h[i + 3]]);
        let f64_at = |i: usize| f64::from_le_bytes(h[i..i + 8].try_into().unwrap_or([0; 8]));
        let version = u32_at(8);
        if version != VERSION {
            return Err(CodecError::Version {
                path,
                found: version,
                supported: VERSION,
            });
        }
        let (n_points, n_faces, n_frames) = (
            u32_at(12) as usize,
            u32_at(16) as usize,
            u32_at(20) as usize,
        );
        let (start, rate) = (f64_at(24), f64_at(32));
        let (bits, corner_bits, flags, key) = (h[40] as u32, h[41] as u32, h[42], h[43] as u32);
        let faces_len = 12 * n_faces as u64;
        if (HEADER as u64) + faces_len > len {
            return Err(header(&format!(
                "{n_faces} faces need {} bytes but the file has {len}",
                HEADER as u64 + faces_len
            )));
        }
        let mut raw = vec![0u8; faces_len as usize];
        file.read_exact(&mut raw).map_err(io_err(&path))?;
        let mut crc = crc32fast::Hasher::new();
        crc.update(&h[..44]);
        crc.update(&raw);
        if crc.finalize() != u32_at(44) {
            return Err(header("checksum mismatch"));
        }
        if !(4..=20).contains(&bits) || !(4..=20).contains(&corner_bits) || flags > 7 {
            return Err(header("quantization bits or flags out of range"));
        }
        if flags & FLAG_WALK_KEYS != 0 && flags & FLAG_TRACKED == 0 {
            return Err(header(
                "flag 4 (keyframes from the walk) without flag 2 (tracked)",
            ));
        }
        if !start.is_finite() || !rate.is_finite() || rate <= 0.0 {
            return Err(header("start or rate not finite, or rate not > 0"));
        }
        let faces: Vec<[u32; 3]> = raw
            .chunks_exact(12)
            .map(|c| {
                std::array::from_fn(|i| {
                    u32::from_le_bytes(c[4 * i..4 * i + 4].try_into().unwrap_or([0; 4]))
                })
            })
            .collect();
        let mesh_err = |source| CodecError::Mesh {
            path: path.clone(),
            source,
        };
        let max = faces
            .iter()
            .flatten()
            .map(|&v| v as usize + 1)
            .max()
            .unwrap_or(0);
        if max != n_points {
            return Err(header(&format!(
                "the faces use {max} vertices, the header declares {n_points}"
            )));
        }
        let mesh = AngleMesh::new(n_points, faces).map_err(mesh_err)?;
        mesh.check_connected().map_err(mesh_err)?;
        let mut blocks = Vec::with_capacity(n_frames.min(1 << 20));
        let mut at = HEADER as u64 + faces_len;
        for frame in 0..n_frames {
            let mut b = [0u8; 8];
            file.seek(SeekFrom::Start(at)).map_err(io_err(&path))?;
            if at + 8 > len || read_up_to(&mut file, &mut b).map_err(io_err(&path))? < 8 {
                return Err(CodecError::Truncated {
                    path,
                    frame,
                    n_frames,
                });
            }
            let size = u32::from_le_bytes([b[0], b[1], b[2], b[3]]);
            let crc = u32::from_le_bytes([b[4], b[5], b[6], b[7]]);
            if at + 8 + size as u64 > len {
                return Err(CodecError::Truncated {
                    path,
                    frame,
                    n_frames,
                });
            }
            blocks.push((at + 8, size, crc));
            at += 8 + size as u64;
        }
        Ok(Self {
            path,
            mesh,
            start,
            rate,
            bits,
            corner_bits,
            corners_once: flags & FLAG_CORNERS_ONCE != 0,
            keyframe_interval: key,
            decoding: Decoding::of(flags),
            blocks,
            file,
            next: 0,
            corners: History::default(),
            dihedrals: History::default(),
            last: None,
            last_y: None,
            before_y: None,
        })
    }

    /// The file.
    pub fn path(&self) -> &Path {
        &self.path
    }
    /// Vertices per frame.
    pub fn n_points(&self) -> usize {
        self.mesh.n_vertices()
    }
    /// Frames in the file.
    pub fn n_frames(&self) -> usize {
        self.blocks.len()
    }
    /// The triangles.
    pub fn faces(&self) -> &[[u32; 3]] {
        self.mesh.faces()
    }
    /// Scene frame of sample 0.
    pub fn start(&self) -> f64 {
        self.start
    }
    /// Scene frames between samples.
    pub fn rate(&self) -> f64 {
        self.rate
    }
    /// Quantization bits of the dihedrals and of the corners.
    pub fn bits(&self) -> (u32, u32) {
        (self.bits, self.corner_bits)
    }
    /// Scene frame of every sample: `start + k · rate`.
    pub fn frame_times(&self) -> Vec<f64> {
        (0..self.n_frames())
            .map(|k| self.start + k as f64 * self.rate)
            .collect()
    }

    pub(super) fn corrupt(&self, frame: usize, reason: String) -> CodecError {
        CodecError::Corrupt {
            path: self.path.clone(),
            frame,
            reason,
        }
    }

    /// Decodes the streams of the next frame, advancing the state; returns the placement.
    pub(super) fn step_streams(&mut self) -> Result<Similarity, CodecError> {
        let frame = self.next;
        let (at, size, crc) = self.blocks[frame];
        let mut payload = vec![0u8; size as usize];
        self.file
            .seek(SeekFrom::Start(at))
            .and_then(|_| self.file.read_exact(&mut payload))
            .map_err(io_err(&self.path))?;
        if crc32fast::hash(&payload) != crc {
            return Err(self.corrupt(frame, "checksum mismatch".into()));
        }
        let mut b = entropy::Bytes::new(&payload);
        let parse = |b: &mut entropy::Bytes<'_>, this: &Self| -> Result<_, String> {
            let mut sim = [0f32; 8];
            for c in &mut sim {
                *c = b.f32()?;
            }
            let sim = Similarity(sim);
            sim.check()?;
            let send_corners = !(this.corners_once && frame > 0);
            let corners = if send_corners {
                Some(parse_stream(b, 3 * this.mesh.n_faces(), &this.corners)?)
            } else {
                None
            };
            let dihedrals = parse_stream(b, this.mesh.n_interior(), &this.dihedrals)?;
            if !b.is_empty() {
                return Err("bytes left over after the frame's streams".into());
            }
            // the two streams are independent: decoded side by side
            let (qc, qd) = rayon::join(
                || {
                    corners
                        .map(|c| c.indices(&this.corners, this.corner_bits))
                        .transpose()
                },
                || dihedrals.indices(&this.dihedrals, this.bits),
            );
            let (qc, qd) = (qc?, qd?);
            Ok((sim, qc, qd))
        };
        let (sim, qc, qd) = parse(&mut b, self).map_err(|r| self.corrupt(frame, r))?;
        if let Some(qc) = qc {
            self.corners.push(qc);
        }
        self.dihedrals.push(qd);
        self.next += 1;
        Ok(sim)
    }

    /// Positions of frame `k` (0-based), as the encoder reconstructed them. Sequential
    /// reads only decode the new frame's streams; a backward jump replays the streams
    /// (entropy decoding only) from frame 0.
    pub fn read_frame(&mut self, k: usize) -> Result<Vec<[f32; 3]>, CodecError> {
        if k >= self.n_frames() {
            return Err(CodecError::FrameOutOfRange {
                path: self.path.clone(),
                frame: k as i64,
                n_frames: self.n_frames(),
            });
        }
        let result = self.read_frame_inner(k);
        if result.is_err() {
            // the state may be mid-way: start over on the next read
            self.reset();
        }
        result
    }

    pub(super) fn reset(&mut self) {
        self.next = 0;
        self.corners = History::default();
        self.dihedrals = History::default();
        self.last = None;
        self.last_y = None;
        self.before_y = None;
    }

    pub(super) fn read_frame_inner(&mut self, k: usize) -> Result<Vec<[f32; 3]>, CodecError> {
        let key = self.keyframe_interval;
        if k + 1 == self.next
            && let (Some(sim), Some(y)) = (&self.last, &self.last_y)
        {
            return Ok(sim.apply(y));
        }
        // the first frame to reconstruct: k itself when it is cold or follows the last
        // reconstructed frame, else its keyframe
        let sequential = k == self.next && self.last_y.is_some();
        let from = if is_key(k, key) || sequential {
            k
        } else {
            k - k % key as usize
        };
        if from < self.next {
            // replay the entropy streams from frame 0 (the prediction needs them)
            self.reset();
        }
        while self.next < from {
            self.last = Some(self.step_streams()?);
            self.last_y = None;
            self.before_y = None;
        }
        let mut y = None;
        for j in from..=k {
            let sim = self.step_streams()?;
            let previous = match (&self.last_y, is_key(j, key)) {
                (Some(p), false) => Some(p.as_slice()),
                _ => None,
            };
            let before = match (&self.before_y, extrapolates(j, key)) {
                (Some(p), true) => Some(p.as_slice()),
                _ => None,
            };
            let qc = self.corners.prev.as_deref().unwrap_or_default();
            let qd = self.dihedrals.prev.as_deref().unwrap_or_default();
            let bits = (self.bits, self.corner_bits);
            let yj = reconstruct(&self.mesh, qc, qd, bits, (previous, before), self.decoding)
                .map_err(|source| CodecError::Reconstruct {
                    path: self.path.clone(),
                    frame: j,
                    source,
                })?;
            self.last = Some(sim);
            self.before_y = self.last_y.replace(yj);
            y = Some(sim);
        }
        let sim = y.ok_or_else(|| self.corrupt(k, "no frame decoded".into()))?;
        let yk = self.last_y.as_deref().unwrap_or_default();
        Ok(sim.apply(yk))
    }
}
