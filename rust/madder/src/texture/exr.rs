//! OpenEXR images: a rasterized field written as a half-float EXR file (and read back).
//!
//! ## Why OpenEXR half, with the `exr` crate
//! Stain densities are linear quantities that span orders of magnitude (a faint halo next
//! to a saturated centre); 16-bit floats keep 11 significant bits at every magnitude from
//! 6·10⁻⁵ to 65504, where an 8- or 16-bit integer PNG would have to choose a range. Blender
//! reads EXR natively (as linear data, no colour transform), in image sequences too. The
//! `exr` crate is pure Rust without `unsafe`, and is the EXR implementation of the `image`
//! crate family.
//!
//! ## Layout
//! One layer, scan-line blocks, in increasing line order; one half-float channel per
//! entry of `channels`, named as given (EXR stores channels sorted by name; readers find
//! them by name: `R`, `G`, `B`, `A` are colour and alpha to Blender). The in-memory image
//! is row-major with row 0 at the **bottom** (as Blender's `Image.pixels` and
//! [`Raster`](super::Raster)); EXR scan lines go top to bottom, so rows are flipped on
//! write and on read. Values round to the nearest half (ties to even); beyond ±65504 they
//! become ±∞, and NaN stays NaN.
//!
//! ## Compression
//! [`Compression::Rle`] by default. Bake output is mostly empty (the stain covers a small
//! part of the UV layout), and run-length encoding collapses the empty runs at memory
//! speed, where ZIP and PIZ work through every byte. One 2048² RGBA frame on 2 cores
//! (`benches/texture.rs`, a stain covering a tenth of the cloth, and a dense field):
//!
//! | compression | stain: ms, MB | dense: ms, MB |
//! |---|---|---|
//! | none | 42, 33.6 | 26, 33.6 |
//! | **RLE** | **23**, 4.2 | **39**, 10.8 |
//! | ZIP1 | 136, 1.8 | 206, 3.2 |
//! | ZIP16 | 116, 1.4 | 171, 2.6 |
//! | PIZ | 97, 2.8 | 123, 7.3 |
//!
//! Only RLE meets the 50 ms budget of a frame at a reasonable size (no compression is as
//! fast but writes 33 MB a frame, 8 GB for a 250-frame bake). RLE and uncompressed scan
//! lines are encoded here ([`Compression::Rle`]'s encoder skips equal bytes 16 at a time;
//! the `exr` crate's own took ~70 ms a frame, ten instructions per byte), in parallel, one
//! block per scan line, and handed to the `exr` crate's block writer, which makes the
//! header and the offset table; ZIP and PIZ go through the `exr` crate's encoders. Every
//! file is read back by the `exr` crate in the tests (and by Blender in
//! `tests/blender/test_texture.py`).
//!
//! ## Safety
//! The file is written to a temporary file in the target's folder and renamed over the
//! target: a failure (unwritable folder, full disk) never leaves a partial file under the
//! final name, and a previous image there stays whole. The temporary file is removed on
//! failure. Errors name the target path. The file is not synced before the rename (one
//! image per frame: a sync each would wait on the disk hundreds of times per bake), so
//! this guards against failed writes, not against a power cut, which can lose the newest
//! images (the bake's cache, synced, can re-export them).

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use exr::prelude as x;
use half::f16;
use half::slice::HalfFloatSliceExt;
use rayon::prelude::*;

use super::raster::{MAX_CHANNELS, MAX_SIZE};
use crate::error::TextureError;

/// How the scan lines of an EXR file are compressed (all lossless).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Compression {
    /// Raw half floats: the largest file, the least work.
    None,
    /// Run-length encoding of the bytes (after the predictor EXR applies): cheap, and
    /// very effective on empty regions. The default.
    Rle,
    /// zlib (deflate) of each scan line.
    Zip1,
    /// zlib of blocks of 16 scan lines.
    Zip16,
    /// Wavelet transform and Huffman coding of blocks of 32 scan lines.
    Piz,
}

impl Compression {
    /// All of them, for benchmarks and tests.
    pub const ALL: [Compression; 5] = [
        Compression::None,
        Compression::Rle,
        Compression::Zip1,
        Compression::Zip16,
        Compression::Piz,
    ];

    fn to_exr(self) -> x::Compression {
        match self {
            Compression::None => x::Compression::Uncompressed,
            Compression::Rle => x::Compression::RLE,
            Compression::Zip1 => x::Compression::ZIP1,
            Compression::Zip16 => x::Compression::ZIP16,
            Compression::Piz => x::Compression::PIZ,
        }
    }
}

/// The compression [`write_exr`] uses (see the module doc for why).
pub const DEFAULT_COMPRESSION: Compression = Compression::Rle;

/// An image read from an EXR file.
#[derive(Debug, Clone, PartialEq)]
pub struct ExrImage {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Channel names, in the order of `pixels`' values: `R`, `G`, `B`, `A` first (those
    /// present), then the others by name (the file's order).
    pub channels: Vec<String>,
    /// `height × width × channels` values, row-major, row 0 at the bottom.
    pub pixels: Vec<f32>,
}

/// Writes `pixels` (`height × width × channels.len()` values, row-major, row 0 at the
/// bottom) as a half-float OpenEXR file at `path`, with [`DEFAULT_COMPRESSION`].
pub fn write_exr(
    path: impl AsRef<Path>,
    pixels: &[f32],
    width: usize,
    height: usize,
    channels: &[&str],
) -> Result<(), TextureError> {
    write_exr_with(path, pixels, width, height, channels, DEFAULT_COMPRESSION)
}

/// [`write_exr`] with the given compression.
pub fn write_exr_with(
    path: impl AsRef<Path>,
    pixels: &[f32],
    width: usize,
    height: usize,
    channels: &[&str],
    compression: Compression,
) -> Result<(), TextureError> {
    let path = path.as_ref();
    for (name, n) in [("width", width), ("height", height)] {
        if n == 0 || n > MAX_SIZE {
            return Err(TextureError::Size {
                name,
                size: n,
                max: MAX_SIZE,
            });
        }
    }
    check_names(channels)?;
    let c = channels.len();
    if pixels.len() != width * height * c {
        return Err(TextureError::Length {
            name: "image",
            expected: width * height * c,
            got: pixels.len(),
        });
    }

    let tmp = temporary(path);
    let io = |source| TextureError::Io {
        path: path.to_path_buf(),
        source,
    };
    let result = (|| {
        let mut out = BufWriter::with_capacity(1 << 20, File::create(&tmp).map_err(io)?);
        match compression {
            Compression::None | Compression::Rle => {
                write_scan_lines(&mut out, pixels, width, height, channels, compression)
            }
            _ => write_with_exr(&mut out, pixels, width, height, channels, compression),
        }
        .map_err(|e| exr_error(path, e))?;
        out.flush().map_err(io)?;
        drop(out.into_inner().map_err(|e| io(e.into_error()))?);
        std::fs::rename(&tmp, path).map_err(io)
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result
}

/// The channels' order in the file: by name, as EXR requires.
fn sorted(channels: &[&str]) -> Vec<usize> {
    let mut order: Vec<usize> = (0..channels.len()).collect();
    order.sort_by_key(|&k| channels[k].as_bytes());
    order
}

/// Writes the file through the `exr` crate's own encoders (ZIP, PIZ): planar half-float
/// channels, scan lines top to bottom.
fn write_with_exr(
    out: &mut BufWriter<File>,
    pixels: &[f32],
    width: usize,
    height: usize,
    channels: &[&str],
    compression: Compression,
) -> exr::error::UnitResult {
    let c = channels.len();
    let planes: Vec<Vec<f16>> = (0..c)
        .map(|k| {
            let mut plane = vec![f16::ZERO; width * height];
            plane.par_chunks_mut(width).enumerate().for_each_init(
                || vec![0.0f32; width],
                |row, (r, out)| {
                    let src = &pixels[(height - 1 - r) * width * c..][..width * c];
                    for (v, texel) in row.iter_mut().zip(src.chunks_exact(c)) {
                        *v = texel[k];
                    }
                    out.convert_from_f32_slice(row);
                },
            );
            plane
        })
        .collect();
    let list = channels
        .iter()
        .zip(planes)
        .map(|(name, plane)| x::AnyChannel::new(*name, x::FlatSamples::F16(plane)))
        .collect();
    let layer = x::Layer::new(
        (width, height),
        x::LayerAttributes::default(),
        x::Encoding {
            compression: compression.to_exr(),
            blocks: x::Blocks::ScanLines,
            line_order: x::LineOrder::Increasing,
        },
        x::AnyChannels::sort(list),
    );
    x::WritableImage::write(&x::Image::from_layer(layer)).to_buffered(out)
}

/// Writes the file with one scan line per block, uncompressed or RLE-compressed here (see
/// [`rle_line`]), the lines encoded in parallel and written in order by the `exr` crate's
/// block writer (which makes the header and the offset table).
fn write_scan_lines(
    out: &mut BufWriter<File>,
    pixels: &[f32],
    width: usize,
    height: usize,
    channels: &[&str],
    compression: Compression,
) -> exr::error::UnitResult {
    use exr::block::chunk::{Chunk, CompressedBlock, CompressedScanLineBlock};
    use exr::meta::attribute::{ChannelDescription, SampleType};
    use exr::meta::header::Header;

    let c = channels.len();
    let order = sorted(channels);
    let descriptions = order
        .iter()
        .map(|&k| ChannelDescription::named(channels[k], SampleType::F16))
        .collect();
    let mut header = Header::new(x::Text::from(""), (width, height), descriptions).with_encoding(
        compression.to_exr(),
        exr::meta::BlockDescription::ScanLines,
        x::LineOrder::Increasing,
    );
    header.own_attributes = x::LayerAttributes::default();
    // one block per scan line for both: file line i is image row height − 1 − i
    let lines: Vec<Vec<u8>> = (0..height)
        .into_par_iter()
        .map_init(
            || vec![f16::ZERO; width * c],
            |half, i| {
                let src = &pixels[(height - 1 - i) * width * c..][..width * c];
                half.convert_from_f32_slice(src);
                encode_line(half, width, c, &order, compression)
            },
        )
        .collect();
    exr::block::write(out, x::SmallVec::from_elem(header, 1), true, |_, writer| {
        for (i, bytes) in lines.into_iter().enumerate() {
            let block = CompressedScanLineBlock {
                y_coordinate: i as i32,
                compressed_pixels_le: bytes,
            };
            exr::block::writer::ChunksWriter::write_chunk(
                writer,
                i,
                Chunk {
                    layer_index: 0,
                    compressed_block: CompressedBlock::ScanLine(block),
                },
            )?;
        }
        Ok(())
    })
}

/// The stored bytes of one scan line: for each channel in file order, the line's half
/// floats, little-endian; RLE-compressed when that is smaller (as the format requires:
/// a reader takes a block of the raw size as uncompressed).
fn encode_line(
    half: &[f16],
    width: usize,
    c: usize,
    order: &[usize],
    compression: Compression,
) -> Vec<u8> {
    let n = width * c;
    // the line's low bytes then its high bytes, samples in file order (channel by channel)
    let mut split = vec![0u8; 2 * n];
    let (lo, hi) = split.split_at_mut(n);
    for (m, &k) in order.iter().enumerate() {
        let (lo, hi) = (&mut lo[m * width..][..width], &mut hi[m * width..][..width]);
        for ((l, h), texel) in lo.iter_mut().zip(hi.iter_mut()).zip(half.chunks_exact(c)) {
            let [a, b] = texel[k].to_bits().to_le_bytes();
            *l = a;
            *h = b;
        }
    }
    if compression == Compression::Rle {
        if let Some(packed) = rle_line(&split) {
            return packed;
        }
    }
    let (lo, hi) = split.split_at(n);
    let mut raw = vec![0u8; 2 * n];
    for ((pair, &l), &h) in raw.chunks_exact_mut(2).zip(lo).zip(hi) {
        pair[0] = l;
        pair[1] = h;
    }
    raw
}

/// OpenEXR's RLE compression of a block's bytes, given already split (`split`: the
/// even-indexed bytes, then the odd-indexed ones), or `None` when it would not be smaller
/// than the raw bytes.
///
/// As OpenEXR does (`ImfRleCompressor.cpp`): the bytes are reordered, the even-indexed
/// ones (here: every sample's low byte) first, then the odd-indexed ones (the high
/// bytes); each byte is replaced by its difference to the previous one plus 128 (mod
/// 256; the first stays); and the result is cut into runs: `k ∈ 0..=127` followed by one
/// byte means `k + 1` copies of it (runs of 3 to 128 bytes are written so), `−k` followed
/// by `k ≤ 127` bytes means those bytes as they are. An empty region (zeros) becomes runs
/// of 128 (the difference of equal bytes), 2 bytes per 128. This encoder is ours because
/// the `exr` crate's takes about ten instructions per byte, 30+ ms for a 2048² RGBA
/// frame; this one skips equal bytes 16 at a time. Any run/literal split decodes to the
/// same bytes: the tests read every file back through the `exr` crate's decoder.
fn rle_line(split: &[u8]) -> Option<Vec<u8>> {
    // the differences (independent per byte: vectorizes)
    let mut d = vec![0u8; split.len()];
    d[0] = split[0];
    for ((out, &cur), &prev) in d[1..].iter_mut().zip(&split[1..]).zip(split) {
        *out = cur.wrapping_sub(prev).wrapping_add(128);
    }

    let len = d.len();
    let mut out = Vec::with_capacity(len / 8 + 16);
    let mut literal_start = 0;
    let flush = |out: &mut Vec<u8>, from: usize, to: usize| {
        let mut k = from;
        while k < to {
            let m = (to - k).min(127);
            out.push((-(m as i8)) as u8);
            out.extend_from_slice(&d[k..k + m]);
            k += m;
        }
    };
    let mut i = 0;
    while i < len {
        let b = d[i];
        let limit = (i + 128).min(len);
        let mut j = i + 1;
        // 16 bytes at a time, as one 128-bit comparison
        let splat = u128::from_ne_bytes([b; 16]);
        while j + 16 <= limit
            && u128::from_ne_bytes(d[j..j + 16].try_into().expect("16 bytes")) == splat
        {
            j += 16;
        }
        while j < limit && d[j] == b {
            j += 1;
        }
        if j - i >= 3 {
            flush(&mut out, literal_start, i);
            out.push((j - i - 1) as u8);
            out.push(b);
            literal_start = j;
            if out.len() >= len {
                return None;
            }
        }
        i = j;
    }
    flush(&mut out, literal_start, len);
    (out.len() < len).then_some(out)
}

/// Reads the first layer of an EXR file at its full resolution, every channel as `f32`.
pub fn read_exr(path: impl AsRef<Path>) -> Result<ExrImage, TextureError> {
    let path = path.as_ref();
    // open it ourselves first: a missing or unreadable file is an I/O error naming the path
    File::open(path).map_err(|source| TextureError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let image = x::read_first_flat_layer_from_file(path).map_err(|e| exr_error(path, e))?;
    let layer = image.layer_data;
    let (width, height) = (layer.size.width(), layer.size.height());
    let mut list: Vec<&x::AnyChannel<x::FlatSamples>> = layer.channel_data.list.iter().collect();
    let rank = |name: &str| {
        ["R", "G", "B", "A"]
            .iter()
            .position(|&n| n == name)
            .unwrap_or(4)
    };
    list.sort_by_key(|ch| rank(&ch.name.to_string()));
    let c = list.len();
    let mut pixels = vec![0.0f32; width * height * c];
    for (k, ch) in list.iter().enumerate() {
        let plane: Vec<f32> = match &ch.sample_data {
            x::FlatSamples::F16(v) => {
                let mut out = vec![0.0f32; v.len()];
                v.convert_to_f32_slice(&mut out);
                out
            }
            x::FlatSamples::F32(v) => v.clone(),
            x::FlatSamples::U32(v) => v.iter().map(|&u| u as f32).collect(),
        };
        for r in 0..height {
            let src = &plane[r * width..(r + 1) * width];
            let row = height - 1 - r;
            for (xx, &v) in src.iter().enumerate() {
                pixels[(row * width + xx) * c + k] = v;
            }
        }
    }
    Ok(ExrImage {
        width,
        height,
        channels: list.iter().map(|ch| ch.name.to_string()).collect(),
        pixels,
    })
}

fn check_names(channels: &[&str]) -> Result<(), TextureError> {
    if channels.is_empty() || channels.len() > MAX_CHANNELS {
        return Err(TextureError::Channels {
            channels: channels.len(),
            max: MAX_CHANNELS,
        });
    }
    for (i, name) in channels.iter().enumerate() {
        let bad = |reason| TextureError::ChannelName {
            name: name.to_string(),
            reason,
        };
        if name.is_empty() {
            return Err(bad("a channel name cannot be empty"));
        }
        // EXR names are NUL-terminated byte strings of at most 255 bytes
        if name.len() > 255 || name.contains('\0') || !name.is_ascii() {
            return Err(bad("must be 1 to 255 ASCII characters without NUL"));
        }
        if channels[..i].contains(name) {
            return Err(bad("appears twice"));
        }
    }
    Ok(())
}

fn exr_error(path: &Path, e: x::Error) -> TextureError {
    match e {
        x::Error::Io(source) => TextureError::Io {
            path: path.to_path_buf(),
            source,
        },
        other => TextureError::Exr {
            path: path.to_path_buf(),
            reason: other.to_string(),
        },
    }
}

/// A temporary name beside `path`, unique in this process.
fn temporary(path: &Path) -> PathBuf {
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    let mut name = path.file_name().unwrap_or_default().to_os_string();
    name.push(format!(
        ".tmp{}-{}",
        std::process::id(),
        COUNTER.fetch_add(1, Ordering::Relaxed)
    ));
    path.with_file_name(name)
}
