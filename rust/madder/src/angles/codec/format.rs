//! The `.madm` file format: magic, version, header size and flags, how a file's frames are
//! decoded; and the file I/O helpers both sides share (module doc, "File format").

use std::fs::File;
use std::io::Read;
use std::path::Path;

use crate::error::CodecError;

pub(super) const MAGIC: &[u8; 8] = b"MADDERMO";
/// The format version this build writes and reads.
pub const VERSION: u32 = 1;
pub(super) const HEADER: usize = 48;
pub(super) const FLAG_CORNERS_ONCE: u8 = 1;
/// Warm frames by the tracked reconstruction (else the warm-started spectral one).
pub(super) const FLAG_TRACKED: u8 = 2;
/// With [`FLAG_TRACKED`]: keyframes start from the sequential walk (else from the spectral
/// reconstruction).
pub(super) const FLAG_WALK_KEYS: u8 = 4;

/// How a file's frames are decoded (its header flags; module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Decoding {
    /// Warm frames by the warm-started spectral reconstruction (flags without 2).
    Spectral,
    /// Tracked frames; keyframes start from the spectral reconstruction (flag 2).
    TrackedSpectralKeys,
    /// Tracked frames; keyframes start from the sequential walk (flags 2 and 4).
    Tracked,
}

impl Decoding {
    pub(super) fn of(flags: u8) -> Self {
        match (flags & FLAG_TRACKED != 0, flags & FLAG_WALK_KEYS != 0) {
            (false, _) => Self::Spectral,
            (true, false) => Self::TrackedSpectralKeys,
            (true, true) => Self::Tracked,
        }
    }
}

pub(super) fn io_err(path: &Path) -> impl FnOnce(std::io::Error) -> CodecError + '_ {
    move |source| CodecError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// Reads until `buf` is full or the file ends; returns the bytes read.
pub(super) fn read_up_to(file: &mut File, buf: &mut [u8]) -> std::io::Result<usize> {
    let mut n = 0;
    while n < buf.len() {
        match file.read(&mut buf[n..])? {
            0 => break,
            m => n += m,
        }
    }
    Ok(n)
}
