//! Rasterization of per-vertex fields into UV space (see the [module doc](super) for the
//! conventions and the math).
//!
//! ## Coverage, exactly
//! Coverage is decided in integer arithmetic on UVs snapped to a grid of 1/256 texel
//! ([`SUB_TEXEL`]): corner `(u, v)` becomes `(round(256·size·u), round(256·size·v))`, and
//! the centre of texel `(x, y)` is `(256·x + 128, 256·y + 128)` on the same grid. A corner
//! moves by at most 1/512 texel, far below what a picture shows, and in exchange every
//! edge function below is exact, so the tie rule is exact too: two triangles sharing an
//! edge see the same snapped endpoints (the same UV gives the same integers), hence edge
//! functions of opposite sign, never both positive, and a centre on the edge is taken by
//! exactly one of them. Floating-point edge functions cannot promise that (the two
//! triangles round differently), and a shared edge would drop or double texels at random.
//!
//! For a triangle `a, b, c` turned counter-clockwise (`v` up, as in the image), the edge
//! function of the edge `p → q` at the point `s` is
//! `E(s) = (q_x − p_x)(s_y − p_y) − (q_y − p_y)(s_x − p_x)`, positive on the interior side.
//! A centre is inside when every edge has `E > 0`, or `E = 0` on an edge that *owns* its
//! points: one going down (`q_y < p_y`), or going right along a horizontal (`q_y = p_y`,
//! `q_x > p_x`): the *bottom-left rule*, the mirror image of Direct3D's top-left rule in a
//! `y`-up image. Reversing an edge flips ownership, so of two triangles sharing an edge
//! exactly one owns it; at a vertex shared by a fan of triangles the rule gives the centre
//! to exactly one of them as well (the standard argument, valid because the arithmetic is
//! exact). Triangles of zero snapped area cover nothing.
//!
//! The snapped corners are integers held in `f64`. Within `±2^25` (`|u|, |v| ≤ 2^17 /
//! size`: 64 at 2048 texels, 8 at 16384, beyond any real UV layout) every difference is
//! below 2^26, every product below 2^52 and every edge function below 2^53, so `f64`
//! evaluates them exactly, at full speed; a triangle with a corner farther out falls back
//! to `i128`, its corners clamped to `±2^50` first so that nothing overflows (such a
//! corner lies thousands of tiles off the image: the triangle still covers what it
//! covers, deterministically).
//!
//! ## Values
//! A covered texel gets the barycentric interpolation of its triangle's three vertex values
//! at the texel centre, computed in `f64` from the *unsnapped* UVs and rounded to `f32`
//! once, so a field linear in UV over a triangle is reproduced to float rounding at every
//! centre the triangle covers.
//!
//! ## Parallel and deterministic
//! The image is cut into bands of [`BAND_ROWS`] rows. The triangles are binned into the
//! bands their covered rows meet (chunks of triangles binned in parallel, then each band's
//! list concatenated in chunk order, so every list is in triangle order); then each band is
//! rasterized by one task, triangle by triangle in index order, the first triangle to
//! cover a texel writing it. No two tasks write the same texel and no texel depends on the
//! schedule, so the image, its coverage and the overlap count are the same bits on any
//! number of threads.

use rayon::prelude::*;

pub(crate) use super::coverage::CLAIMED;
pub use super::coverage::{EMPTY, INSIDE, MAX_CHANNELS, MAX_SIZE, OVERLAP, PADDED};
use super::weave::{Run, TriWeave, WeaveDetail};
use crate::error::TextureError;

/// Sub-texel steps per texel of the snapped coverage grid.
pub const SUB_TEXEL: i64 = 256;

/// Rows of one band, the unit of parallel work.
pub const BAND_ROWS: usize = 32;

/// Triangles per binning task.
const BIN_CHUNK: usize = 16_384;

/// Snapped corners within this bound have edge functions exact in `f64` (below 2^53).
const FAST_LIMIT: f64 = (1u64 << 25) as f64;

/// Snapped corners are clamped to this bound, so that `i128` edge functions cannot overflow.
const CLAMP: f64 = (1u64 << 50) as f64;

/// A field rasterized into UV space.
#[derive(Debug, Clone, PartialEq)]
pub struct Raster {
    /// Side of the square image, in texels.
    pub size: usize,
    /// Values per texel.
    pub channels: usize,
    /// `size × size × channels` values, row-major, row 0 at the bottom (`v ∈ [0, 1/size)`),
    /// as Blender's `Image.pixels`: texel `(x, y)`, channel `k` is at
    /// `(y·size + x)·channels + k`. Texels no triangle covers hold 0 until padded.
    pub pixels: Vec<f32>,
    /// `size × size` coverage flags, same order: [`EMPTY`], [`INSIDE`], [`OVERLAP`] or
    /// [`PADDED`]. A separate mask, not an alpha channel: the channels stay the field's.
    pub coverage: Vec<u8>,
    /// Texels whose centre lies inside two or more triangles (overlapping UV islands, or a
    /// UV fold inside one island). Shared edges and vertices never count: the tie rule gives
    /// each centre on them to one triangle only.
    pub overlapping: usize,
}

impl Raster {
    /// An empty raster (every texel [`EMPTY`] and 0).
    pub fn empty(size: usize, channels: usize) -> Self {
        Self {
            size,
            channels,
            pixels: vec![0.0; size * size * channels],
            coverage: vec![EMPTY; size * size],
            overlapping: 0,
        }
    }

    /// Texels covered by a triangle ([`INSIDE`] or [`OVERLAP`]).
    pub fn inside_count(&self) -> usize {
        self.coverage
            .iter()
            .filter(|&&c| c == INSIDE || c == OVERLAP)
            .count()
    }

    /// The `channels` values of texel `(x, y)` (row `y` from the bottom).
    pub fn texel(&self, x: usize, y: usize) -> &[f32] {
        let i = (y * self.size + x) * self.channels;
        &self.pixels[i..i + self.channels]
    }
}

/// Rasterizes a per-vertex field over triangles given in UV space.
///
/// `faces[t]` are the vertices whose values triangle `t` interpolates, `uv[t]` its three
/// corners' UVs (one triple per triangle, so a vertex on a UV seam has one UV per side),
/// `values` the field, `n_vertices × channels` row-major, and `size` the side of the
/// square image. A texel whose centre lies in a triangle (closed, with the bottom-left tie
/// rule) gets the barycentric interpolation of the three vertex values; see [`Raster`] for
/// the layout and the coverage mask. Runs on the current rayon pool; the result does not
/// depend on its size.
///
/// Errors: `size` out of `1..=`[`MAX_SIZE`], channels out of `1..=`[`MAX_CHANNELS`], `uv` and `faces` of different
/// lengths, `values` not a whole number of vertices, a face naming a vertex past the
/// values, a non-finite UV (each naming the first face and corner at fault).
pub fn rasterize(
    faces: &[[u32; 3]],
    uv: &[[[f64; 2]; 3]],
    values: &[f32],
    channels: usize,
    size: usize,
) -> Result<Raster, TextureError> {
    rasterize_with(faces, uv, values, channels, size, None)
}

/// [`rasterize`], adding the weave's fine scale on the faces `weave` gives a fabric
/// (module [`super::weave`]); `None` is [`rasterize`] bit for bit. Errors as
/// [`rasterize`], plus `weave`'s arrays of the wrong length and a face with a fabric index
/// past its correctors or a map that is not finite or singular (naming the face).
pub fn rasterize_with(
    faces: &[[u32; 3]],
    uv: &[[[f64; 2]; 3]],
    values: &[f32],
    channels: usize,
    size: usize,
    weave: Option<&WeaveDetail<'_>>,
) -> Result<Raster, TextureError> {
    check_shape(faces, uv, values, channels, size)?;
    if let Some(w) = weave {
        w.check(faces.len(), channels)?;
    }
    let bands = bin(faces, uv, values.len() / channels, size)?;
    // fresh zeroed memory: the bands need not clear it
    let mut raster = Raster::empty(size, channels);
    raster.overlapping = fill(
        &mut raster.pixels,
        &mut raster.coverage,
        &bands,
        &Context {
            faces,
            uv,
            values,
            channels,
            size,
            weave,
        },
        false,
    );
    Ok(raster)
}

/// [`rasterize`] into an existing raster, reusing its buffers (a sequence of frames at one
/// size allocates once). On error the raster is left unchanged.
pub fn rasterize_into(
    raster: &mut Raster,
    faces: &[[u32; 3]],
    uv: &[[[f64; 2]; 3]],
    values: &[f32],
    channels: usize,
    size: usize,
) -> Result<(), TextureError> {
    check_shape(faces, uv, values, channels, size)?;
    let bands = bin(faces, uv, values.len() / channels, size)?;
    raster.size = size;
    raster.channels = channels;
    raster.pixels.resize(size * size * channels, 0.0);
    raster.coverage.resize(size * size, EMPTY);
    raster.overlapping = fill(
        &mut raster.pixels,
        &mut raster.coverage,
        &bands,
        &Context {
            faces,
            uv,
            values,
            channels,
            size,
            weave: None,
        },
        true,
    );
    Ok(())
}

/// [`rasterize`] into caller-owned buffers: `pixels` of `size × size × channels` values and
/// `coverage` of `size × size` (every texel is overwritten). Returns the overlapping texel
/// count. On error the buffers are left unchanged.
#[allow(clippy::too_many_arguments)]
pub fn rasterize_to(
    pixels: &mut [f32],
    coverage: &mut [u8],
    faces: &[[u32; 3]],
    uv: &[[[f64; 2]; 3]],
    values: &[f32],
    channels: usize,
    size: usize,
) -> Result<usize, TextureError> {
    rasterize_to_with(pixels, coverage, faces, uv, values, channels, size, None)
}

/// [`rasterize_to`] with the weave detail of [`rasterize_with`].
#[allow(clippy::too_many_arguments)]
pub fn rasterize_to_with(
    pixels: &mut [f32],
    coverage: &mut [u8],
    faces: &[[u32; 3]],
    uv: &[[[f64; 2]; 3]],
    values: &[f32],
    channels: usize,
    size: usize,
    weave: Option<&WeaveDetail<'_>>,
) -> Result<usize, TextureError> {
    check_shape(faces, uv, values, channels, size)?;
    if let Some(w) = weave {
        w.check(faces.len(), channels)?;
    }
    for (name, expected, got) in [
        ("pixels", size * size * channels, pixels.len()),
        ("coverage", size * size, coverage.len()),
    ] {
        if got != expected {
            return Err(TextureError::Length {
                name,
                expected,
                got,
            });
        }
    }
    let bands = bin(faces, uv, values.len() / channels, size)?;
    Ok(fill(
        pixels,
        coverage,
        &bands,
        &Context {
            faces,
            uv,
            values,
            channels,
            size,
            weave,
        },
        true,
    ))
}

/// The checks that need no pass over the faces.
fn check_shape(
    faces: &[[u32; 3]],
    uv: &[[[f64; 2]; 3]],
    values: &[f32],
    channels: usize,
    size: usize,
) -> Result<(), TextureError> {
    if size == 0 || size > MAX_SIZE {
        return Err(TextureError::Size {
            name: "size",
            size,
            max: MAX_SIZE,
        });
    }
    if channels == 0 || channels > MAX_CHANNELS {
        return Err(TextureError::Channels {
            channels,
            max: MAX_CHANNELS,
        });
    }
    if uv.len() != faces.len() {
        return Err(TextureError::Length {
            name: "uv",
            expected: faces.len(),
            got: uv.len(),
        });
    }
    if values.len() % channels != 0 {
        return Err(TextureError::ValuesLength {
            got: values.len(),
            channels,
        });
    }
    Ok(())
}

/// The error of face `t`, if it names a vertex past `n_vertices` or has a non-finite UV.
fn face_error(
    t: usize,
    face: &[u32; 3],
    uv: &[[f64; 2]; 3],
    n_vertices: usize,
) -> Option<TextureError> {
    if let Some(&vertex) = face.iter().find(|&&v| v as usize >= n_vertices) {
        return Some(TextureError::VertexOutOfRange {
            face: t,
            vertex,
            n_vertices,
        });
    }
    let corner = (0..3).find(|&k| !(uv[k][0].is_finite() && uv[k][1].is_finite()))?;
    let [u, v] = uv[corner];
    Some(TextureError::NonFiniteUv {
        face: t,
        corner,
        u,
        v,
    })
}

/// `x` (within ±2^51) rounded to the nearest integer, ties to even.
#[inline]
fn round_near(x: f64) -> f64 {
    const MAGIC: f64 = 6_755_399_441_055_744.0; // 1.5 · 2^52
    (x + MAGIC) - MAGIC
}

/// `x` rounded to the nearest integer (ties to even), clamped to `±CLAMP`, as an `f64`:
/// adding and removing 1.5·2⁵² leaves the integer part in the default rounding mode
/// (inline, where `f64::round` is a library call on baseline x86-64).
#[inline]
fn round_clamped(x: f64) -> f64 {
    round_near(x.clamp(-CLAMP, CLAMP))
}

/// The texel rows (or columns) whose centres `256·i + 128` lie in the snapped range
/// `[lo, hi]`, clipped to `0..size`: `(first, last)`.
#[inline]
fn centres(lo: f64, hi: f64, size: usize) -> Option<(usize, usize)> {
    let half = (SUB_TEXEL / 2) as f64;
    // lo, hi are integers within ±2^50: exact as i64
    let lo = (lo - half) as i64;
    let hi = (hi - half) as i64;
    // first centre at or above lo: ceil(lo / 256); last at or below hi: floor(hi / 256)
    let first = (lo + SUB_TEXEL - 1).div_euclid(SUB_TEXEL).max(0);
    let last = hi.div_euclid(SUB_TEXEL).min(size as i64 - 1);
    (first <= last).then_some((first as usize, last as usize))
}

/// The rows `y0..=y1` whose centres the triangle's bounding box meets, clipped to the image.
#[inline]
fn rows(uv: &[[f64; 2]; 3], scale: f64, size: usize) -> Option<(usize, usize)> {
    let v = [
        round_clamped(uv[0][1] * scale),
        round_clamped(uv[1][1] * scale),
        round_clamped(uv[2][1] * scale),
    ];
    centres(v[0].min(v[1]).min(v[2]), v[0].max(v[1]).max(v[2]), size)
}

/// For each band, the triangles that may cover one of its texels, in index order; checks
/// the faces on the way (the first bad face is reported).
fn bin(
    faces: &[[u32; 3]],
    uv: &[[[f64; 2]; 3]],
    n_vertices: usize,
    size: usize,
) -> Result<Vec<Vec<u32>>, TextureError> {
    let n_bands = size.div_ceil(BAND_ROWS);
    let scale = (SUB_TEXEL as usize * size) as f64;
    let chunks: Vec<Result<Vec<Vec<u32>>, TextureError>> = uv
        .par_chunks(BIN_CHUNK)
        .zip(faces.par_chunks(BIN_CHUNK))
        .enumerate()
        .map(|(c, (tris, fs))| {
            let mut lists = vec![Vec::new(); n_bands];
            for (i, (tri, f)) in tris.iter().zip(fs).enumerate() {
                let t = c * BIN_CHUNK + i;
                let finite = tri.iter().flatten().all(|x| x.is_finite());
                if !finite || f.iter().any(|&v| v as usize >= n_vertices) {
                    return Err(face_error(t, f, tri, n_vertices).expect("a bad face"));
                }
                if let Some((y0, y1)) = rows(tri, scale, size) {
                    for list in &mut lists[y0 / BAND_ROWS..=y1 / BAND_ROWS] {
                        list.push(t as u32);
                    }
                }
            }
            Ok(lists)
        })
        .collect();
    let chunks = chunks.into_iter().collect::<Result<Vec<_>, _>>()?;
    Ok((0..n_bands)
        .into_par_iter()
        .map(|b| {
            let mut list = Vec::with_capacity(chunks.iter().map(|c| c[b].len()).sum());
            for c in &chunks {
                list.extend_from_slice(&c[b]);
            }
            list
        })
        .collect())
}

/// The read-only input shared by the band tasks.
struct Context<'a> {
    faces: &'a [[u32; 3]],
    uv: &'a [[[f64; 2]; 3]],
    values: &'a [f32],
    channels: usize,
    size: usize,
    weave: Option<&'a WeaveDetail<'a>>,
}

/// Rasterizes every band (clearing it first if `clear`); returns the overlapping count.
fn fill<'w>(
    pixels: &mut [f32],
    coverage: &mut [u8],
    bands: &[Vec<u32>],
    ctx: &Context<'w>,
    clear: bool,
) -> usize {
    let (size, c) = (ctx.size, ctx.channels);
    let band_len = BAND_ROWS * size;
    pixels
        .par_chunks_mut(band_len * c)
        .zip(coverage.par_chunks_mut(band_len))
        .zip(bands.par_iter())
        .enumerate()
        .map(|(b, ((pixels, coverage), list))| {
            if clear {
                pixels.fill(0.0);
                coverage.fill(EMPTY);
            }
            let mut band = Band {
                row0: b * BAND_ROWS,
                rows: coverage.len() / size,
                pixels,
                coverage,
                overlapping: 0,
                base: vec![0.0; c],
                gx: vec![0.0; c],
                gy: vec![0.0; c],
                rowv: vec![0.0; c],
                tw: TriWeave::default(),
            };
            match c {
                1 => band.triangles::<1>(ctx, list),
                2 => band.triangles::<2>(ctx, list),
                3 => band.triangles::<3>(ctx, list),
                4 => band.triangles::<4>(ctx, list),
                _ => band.triangles::<0>(ctx, list),
            }
            band.overlapping
        })
        .sum()
}

/// One band of rows being rasterized by one task.
struct Band<'a, 'w> {
    row0: usize,
    rows: usize,
    pixels: &'a mut [f32],
    coverage: &'a mut [u8],
    overlapping: usize,
    /// per channel, the value at the centre of texel `(x, y)` is
    /// `base + gx · x + gy · y`; `rowv = base + gy · y` for the row being scanned
    base: Vec<f64>,
    gx: Vec<f64>,
    gy: Vec<f64>,
    rowv: Vec<f64>,
    /// the weave detail of the triangle being scanned (module [`super::weave`])
    tw: TriWeave<'w>,
}

/// The arithmetic of the edge functions: `f64` on the fast path (exact, see the module
/// doc), `i128` otherwise. Inputs are the snapped corners, integers held in `f64`.
trait Edge:
    Copy
    + PartialOrd
    + std::ops::Add<Output = Self>
    + std::ops::Sub<Output = Self>
    + std::ops::Mul<Output = Self>
{
    const ZERO: Self;
    const ONE: Self;
    /// An integer-valued `f64` within ±2^50, exactly.
    fn of(x: f64) -> Self;
}

impl Edge for f64 {
    const ZERO: Self = 0.0;
    const ONE: Self = 1.0;
    #[inline]
    fn of(x: f64) -> Self {
        x
    }
}

impl Edge for i128 {
    const ZERO: Self = 0;
    const ONE: Self = 1;
    #[inline]
    fn of(x: f64) -> Self {
        x as i64 as i128
    }
}

/// Twice the signed area of the snapped triangle (positive when counter-clockwise).
#[inline]
fn area2<T: Edge>(p: &[[f64; 2]; 3]) -> T {
    let d = |i: usize, k: usize| T::of(p[i][k]) - T::of(p[0][k]);
    d(1, 0) * d(2, 1) - d(1, 1) * d(2, 0)
}

/// The three edge functions of a counter-clockwise triangle at the centre `s`, plus 1 on
/// an owning edge (so that a centre is inside when all three are `> 0`: the functions are
/// integers), and their changes per texel to the right and per row up.
#[inline(always)]
fn edges<T: Edge>(p: &[[f64; 2]; 3], s: [f64; 2]) -> ([T; 3], [T; 3], [T; 3]) {
    let w = T::of(SUB_TEXEL as f64);
    let mut e = [T::ZERO; 3];
    let mut dx = [T::ZERO; 3];
    let mut dy = [T::ZERO; 3];
    for k in 0..3 {
        let (a, b) = (p[k], p[(k + 1) % 3]);
        let ex = T::of(b[0]) - T::of(a[0]);
        let ey = T::of(b[1]) - T::of(a[1]);
        let owns = ey < T::ZERO || (ey == T::ZERO && ex > T::ZERO);
        e[k] = ex * (T::of(s[1]) - T::of(a[1])) - ey * (T::of(s[0]) - T::of(a[0]))
            + if owns { T::ONE } else { T::ZERO };
        dx[k] = T::ZERO - ey * w;
        dy[k] = ex * w;
    }
    (e, dx, dy)
}

impl<'w> Band<'_, 'w> {
    /// Rasterizes the listed triangles in order, for `C` channels (0: any number).
    fn triangles<const C: usize>(&mut self, ctx: &Context<'w>, list: &[u32]) {
        let scale = (SUB_TEXEL as usize * ctx.size) as f64;
        let (band0, band1) = (self.row0, self.row0 + self.rows - 1);
        for &t in list {
            let t = t as usize;
            let uv = &ctx.uv[t];
            let su = [uv[0][0] * scale, uv[1][0] * scale, uv[2][0] * scale];
            let sv = [uv[0][1] * scale, uv[1][1] * scale, uv[2][1] * scale];
            // within ±2^25 the rounding needs no clamp, and the edge functions fit f64
            let fast = su.iter().chain(&sv).all(|x| x.abs() <= FAST_LIMIT);
            let mut p = if fast {
                std::array::from_fn(|k| [round_near(su[k]), round_near(sv[k])])
            } else {
                std::array::from_fn(|k| [round_clamped(su[k]), round_clamped(sv[k])])
            };
            let Some((x0, x1)) = centres(
                p[0][0].min(p[1][0]).min(p[2][0]),
                p[0][0].max(p[1][0]).max(p[2][0]),
                ctx.size,
            ) else {
                continue;
            };
            let Some((y0, y1)) = centres(
                p[0][1].min(p[1][1]).min(p[2][1]),
                p[0][1].max(p[1][1]).max(p[2][1]),
                ctx.size,
            ) else {
                continue;
            };
            let (y0, y1) = (y0.max(band0), y1.min(band1));
            if y0 > y1 {
                continue;
            }
            let area = if fast {
                area2::<f64>(&p)
            } else {
                area2::<i128>(&p).signum() as f64
            };
            if area == 0.0 {
                continue;
            }
            let mut corner = [0usize, 1, 2];
            if area < 0.0 {
                p.swap(1, 2);
                corner.swap(1, 2);
            }
            // the corners in texels, unsnapped (su, sv are in 1/256 texel)
            let q = corner.map(|k| [su[k] / SUB_TEXEL as f64, sv[k] / SUB_TEXEL as f64]);
            self.setup_values::<C>(ctx, t, corner, q);
            let c = if C == 0 { ctx.channels } else { C };
            let woven = ctx.weave.is_some_and(|d| {
                let field = [&self.base[..c], &self.gx[..c], &self.gy[..c]];
                self.tw.setup(d, t, ctx.size, field)
            });
            let w = SUB_TEXEL as f64;
            let s = [x0 as f64 * w + w / 2.0, y0 as f64 * w + w / 2.0];
            let box_ = [x0, x1, y0, y1];
            match (fast, woven) {
                (true, false) => {
                    let (e, dx, dy) = edges::<f64>(&p, s);
                    self.scan::<f64, C, false>(ctx, e, dx, dy, box_);
                }
                (true, true) => {
                    let (e, dx, dy) = edges::<f64>(&p, s);
                    self.scan::<f64, C, true>(ctx, e, dx, dy, box_);
                }
                (false, false) => {
                    let (e, dx, dy) = edges::<i128>(&p, s);
                    self.scan::<i128, C, false>(ctx, e, dx, dy, box_);
                }
                (false, true) => {
                    let (e, dx, dy) = edges::<i128>(&p, s);
                    self.scan::<i128, C, true>(ctx, e, dx, dy, box_);
                }
            }
        }
    }

    /// Writes, per channel, the triangle's field as an affine function of the position in
    /// texels relative to the image origin, from the unsnapped UVs: with `q` the corners
    /// in texels, `λ_b`, `λ_c` are affine in the position, and the value is
    /// `f_a + λ_b (f_b − f_a) + λ_c (f_c − f_a)`.
    #[inline]
    fn setup_values<const C: usize>(
        &mut self,
        ctx: &Context<'_>,
        t: usize,
        corner: [usize; 3],
        q: [[f64; 2]; 3],
    ) {
        let c = if C == 0 { ctx.channels } else { C };
        let (bx, by) = (q[1][0] - q[0][0], q[1][1] - q[0][1]);
        let (cx, cy) = (q[2][0] - q[0][0], q[2][1] - q[0][1]);
        let det = bx * cy - by * cx;
        // λ_b = ((s − a) × (c − a)) / det, λ_c = ((b − a) × (s − a)) / det; a triangle that
        // is flat in f64 but not once snapped (sub-1/256-texel slivers) takes the mean
        let flat = !(det != 0.0 && det.is_finite());
        let (lbx, lby, lcx, lcy) = if flat {
            (0.0, 0.0, 0.0, 0.0)
        } else {
            let inv = 1.0 / det;
            (cy * inv, -cx * inv, -by * inv, bx * inv)
        };
        let v = ctx.faces[t];
        let [fa, fb, fc] = corner.map(|k| &ctx.values[v[k] as usize * c..][..c]);
        let (base, gx, gy) = (&mut self.base[..c], &mut self.gx[..c], &mut self.gy[..c]);
        for k in 0..c {
            let a = f64::from(fa[k]);
            let db = f64::from(fb[k]) - a;
            let dc = f64::from(fc[k]) - a;
            let x = db * lbx + dc * lcx;
            let y = db * lby + dc * lcy;
            // value = f_a + gx (x + ½ − a_x) + gy (y + ½ − a_y) at the centre of texel (x, y)
            base[k] = if flat {
                a + (db + dc) / 3.0
            } else {
                a + x * (0.5 - q[0][0]) + y * (0.5 - q[0][1])
            };
            gx[k] = x;
            gy[k] = y;
        }
    }

    #[inline]
    fn scan<T: Edge, const C: usize, const W: bool>(
        &mut self,
        ctx: &Context<'_>,
        e: [T; 3],
        dx: [T; 3],
        dy: [T; 3],
        [x0, x1, y0, y1]: [usize; 4],
    ) {
        let size = ctx.size;
        let c = if C == 0 { ctx.channels } else { C };
        let zero = T::ZERO;
        // the band's buffers as locals: the loop below then keeps them in registers
        let Band {
            row0,
            pixels,
            coverage,
            overlapping,
            base,
            gx,
            gy,
            rowv,
            tw,
            ..
        } = self;
        let (base, gx, gy, rowv) = (&base[..c], &gx[..c], &gy[..c], &mut rowv[..c]);
        // the triangle's weave kernel, once (W: set up by `triangles`)
        let woven = W.then(|| tw.texels(c));
        // woven: per row, the span of the texels it covers first (marked CLAIMED), shaded
        // after the scan; a triangle meets at most BAND_ROWS rows of the band
        let mut runs = [Run::default(); BAND_ROWS];
        let mut n_runs = 0;
        let mut over = 0;
        let mut row_e = e;
        let n = x1 + 1 - x0;
        for y in y0..=y1 {
            let yf = y as f64;
            for k in 0..c {
                rowv[k] = base[k] + gy[k] * yf;
            }
            let row = (y - *row0) * size + x0;
            let cov = &mut coverage[row..row + n];
            let pix = &mut pixels[row * c..(row + n) * c];
            let [mut e0, mut e1, mut e2] = row_e;
            let mut xf = x0 as f64;
            let mut entered = false;
            // woven: the first and last texel of the row claimed (none while first > last)
            let (mut first, mut last) = (n, 0);
            for (i, (m, out)) in cov.iter_mut().zip(pix.chunks_exact_mut(c)).enumerate() {
                // one branch, not three (the outcome is hard to predict on small triangles)
                let inside = (e0 > zero) & (e1 > zero) & (e2 > zero);
                if inside {
                    entered = true;
                    if *m == EMPTY {
                        if W {
                            *m = CLAIMED;
                            first = first.min(i);
                            last = i;
                        } else {
                            *m = INSIDE;
                            for k in 0..c {
                                out[k] = (rowv[k] + gx[k] * xf) as f32;
                            }
                        }
                    } else if *m == INSIDE {
                        *m = OVERLAP;
                        over += 1;
                    }
                } else if entered {
                    // the covered texels of a row are contiguous: the triangle is convex
                    break;
                }
                e0 = e0 + dx[0];
                e1 = e1 + dx[1];
                e2 = e2 + dx[2];
                xf += 1.0;
            }
            if W && first <= last {
                runs[n_runs] = Run::new(y, x0 + first, x0 + last);
                n_runs += 1;
            }
            row_e = [row_e[0] + dy[0], row_e[1] + dy[1], row_e[2] + dy[2]];
        }
        if let Some(kernel) = &woven {
            let runs = &runs[..n_runs];
            kernel.shade::<C>(runs, c, [base, gx, gy], pixels, coverage, *row0, size);
        }
        *overlapping += over;
    }
}
