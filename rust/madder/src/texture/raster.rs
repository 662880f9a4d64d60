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
//! Edge functions of snapped corners within `±2^29` (`|u|, |v| ≲ 2^21 / size`, far beyond
//! any real UV layout) are evaluated in `i64`; larger ones fall back to `i128`, with the
//! corners clamped to `±2^50` first so that nothing overflows (such a corner is thousands
//! of tiles off the image: its triangle still covers what it covers, deterministically).
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

use crate::error::TextureError;

/// The largest image side accepted: 16384 texels (a 16384² RGBA float image is 4 GiB).
pub const MAX_SIZE: usize = 16384;

/// Coverage mask value: no triangle covers the texel centre (and no padding reached it).
pub const EMPTY: u8 = 0;
/// Coverage mask value: exactly one triangle covers the texel centre.
pub const INSIDE: u8 = 1;
/// Coverage mask value: two or more triangles cover the texel centre (overlapping UVs); the
/// texel holds the value of the first of them in index order.
pub const OVERLAP: u8 = 2;
/// Coverage mask value: the texel lies outside every triangle and took its value from
/// [`pad`](super::pad).
pub const PADDED: u8 = 3;

/// Sub-texel steps per texel of the snapped coverage grid.
pub const SUB_TEXEL: i64 = 256;

/// Rows of one band, the unit of parallel work.
pub const BAND_ROWS: usize = 16;

/// Triangles per binning task.
const BIN_CHUNK: usize = 16_384;

/// Snapped corners within this bound use `i64` edge functions (products stay below 2^62).
const FAST_LIMIT: i64 = 1 << 29;

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
/// Errors: `size` out of `1..=`[`MAX_SIZE`], no channel, `uv` and `faces` of different
/// lengths, `values` not a whole number of vertices, a face naming a vertex past the
/// values, a non-finite UV (naming the face and corner).
pub fn rasterize(
    faces: &[[u32; 3]],
    uv: &[[[f64; 2]; 3]],
    values: &[f32],
    channels: usize,
    size: usize,
) -> Result<Raster, TextureError> {
    let mut raster = Raster {
        size: 0,
        channels: 0,
        pixels: Vec::new(),
        coverage: Vec::new(),
        overlapping: 0,
    };
    rasterize_into(&mut raster, faces, uv, values, channels, size)?;
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
    check(faces, uv, values, channels, size)?;
    let n_texels = size * size;
    raster.size = size;
    raster.channels = channels;
    raster.pixels.clear();
    raster.pixels.resize(n_texels * channels, 0.0);
    raster.coverage.clear();
    raster.coverage.resize(n_texels, EMPTY);

    let bands = bin(uv, size);
    let band_len = BAND_ROWS * size;
    let ctx = Context {
        faces,
        uv,
        values,
        channels,
        size,
    };
    raster.overlapping = raster
        .pixels
        .par_chunks_mut(band_len * channels)
        .zip(raster.coverage.par_chunks_mut(band_len))
        .zip(bands.par_iter())
        .enumerate()
        .map(|(b, ((pixels, coverage), list))| {
            let mut band = Band {
                row0: b * BAND_ROWS,
                rows: coverage.len() / size,
                pixels,
                coverage,
                overlapping: 0,
                scratch: vec![0.0; 3 * channels],
            };
            for &t in list {
                band.triangle(&ctx, t as usize);
            }
            band.overlapping
        })
        .sum();
    Ok(())
}

/// The input checks, in a fixed order; the first failing face is reported.
fn check(
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
    if channels == 0 {
        return Err(TextureError::NoChannels);
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
    let n_vertices = values.len() / channels;
    let bad = |t: usize| {
        faces[t].iter().any(|&v| v as usize >= n_vertices)
            || uv[t].iter().flatten().any(|x| !x.is_finite())
    };
    if let Some(face) = (0..faces.len()).into_par_iter().find_first(|&t| bad(t)) {
        if let Some(&vertex) = faces[face].iter().find(|&&v| v as usize >= n_vertices) {
            return Err(TextureError::VertexOutOfRange {
                face,
                vertex,
                n_vertices,
            });
        }
        let corner = (0..3)
            .find(|&k| !uv[face][k].iter().all(|x| x.is_finite()))
            .expect("a bad face has a bad vertex or corner");
        let [u, v] = uv[face][corner];
        return Err(TextureError::NonFiniteUv {
            face,
            corner,
            u,
            v,
        });
    }
    Ok(())
}

/// A UV corner on the snapped grid (see the module doc).
fn snap(uv: [f64; 2], size: usize) -> [i64; 2] {
    let scale = (SUB_TEXEL as usize * size) as f64;
    uv.map(|x| (x * scale).round().clamp(-CLAMP, CLAMP) as i64)
}

/// The snapped corners of triangle `t`, and the rows `lo..=hi` whose centres its bounding
/// box meets, clipped to the image; `None` when it meets no texel centre of the image.
fn extent(uv: &[[f64; 2]; 3], size: usize) -> Option<([[i64; 2]; 3], [usize; 4])> {
    let p = uv.map(|c| snap(c, size));
    let range = |k: usize| {
        let lo = p.iter().map(|c| c[k]).min().expect("three corners");
        let hi = p.iter().map(|c| c[k]).max().expect("three corners");
        // centres at 256·i + 128: the first at or above lo, the last at or below hi
        let first = (lo - SUB_TEXEL / 2).div_euclid(SUB_TEXEL)
            + i64::from((lo - SUB_TEXEL / 2).rem_euclid(SUB_TEXEL) != 0);
        let last = (hi - SUB_TEXEL / 2).div_euclid(SUB_TEXEL);
        let first = first.max(0);
        let last = last.min(size as i64 - 1);
        (first <= last).then_some((first as usize, last as usize))
    };
    let (x0, x1) = range(0)?;
    let (y0, y1) = range(1)?;
    Some((p, [x0, x1, y0, y1]))
}

/// For each band, the triangles that may cover one of its texels, in index order.
fn bin(uv: &[[[f64; 2]; 3]], size: usize) -> Vec<Vec<u32>> {
    let n_bands = size.div_ceil(BAND_ROWS);
    let chunks: Vec<Vec<Vec<u32>>> = uv
        .par_chunks(BIN_CHUNK)
        .enumerate()
        .map(|(c, tris)| {
            let mut lists = vec![Vec::new(); n_bands];
            for (i, tri) in tris.iter().enumerate() {
                if let Some((_, [_, _, y0, y1])) = extent(tri, size) {
                    let t = (c * BIN_CHUNK + i) as u32;
                    for list in &mut lists[y0 / BAND_ROWS..=y1 / BAND_ROWS] {
                        list.push(t);
                    }
                }
            }
            lists
        })
        .collect();
    (0..n_bands)
        .into_par_iter()
        .map(|b| {
            let mut list = Vec::with_capacity(chunks.iter().map(|c| c[b].len()).sum());
            for c in &chunks {
                list.extend_from_slice(&c[b]);
            }
            list
        })
        .collect()
}

/// The read-only input shared by the band tasks.
struct Context<'a> {
    faces: &'a [[u32; 3]],
    uv: &'a [[[f64; 2]; 3]],
    values: &'a [f32],
    channels: usize,
    size: usize,
}

/// One band of rows being rasterized by one task.
struct Band<'a> {
    row0: usize,
    rows: usize,
    pixels: &'a mut [f32],
    coverage: &'a mut [u8],
    overlapping: usize,
    /// per channel: value at corner a, then its change towards b and towards c
    scratch: Vec<f64>,
}

/// The integer type of the edge functions: `i64` on the fast path, `i128` otherwise.
trait EdgeInt:
    Copy
    + Ord
    + From<i64>
    + std::ops::Add<Output = Self>
    + std::ops::Sub<Output = Self>
    + std::ops::Mul<Output = Self>
{
}
impl EdgeInt for i64 {}
impl EdgeInt for i128 {}

/// The three edge functions of a counter-clockwise triangle, stepped texel by texel.
struct Edges<T> {
    /// value at the current texel centre, plus 1 on an owning edge (so `inside ⇔ all > 0`)
    e: [T; 3],
    /// change per texel to the right
    dx: [T; 3],
    /// change per row up
    dy: [T; 3],
}

impl<T: EdgeInt> Edges<T> {
    /// Edge functions of the counter-clockwise corners `p` at the centre `s`.
    fn new(p: [[i64; 2]; 3], s: [i64; 2]) -> Self {
        let w = T::from(SUB_TEXEL);
        let zero = T::from(0);
        let one = T::from(1);
        let mut e = [zero; 3];
        let mut dx = [zero; 3];
        let mut dy = [zero; 3];
        for k in 0..3 {
            let (a, b) = (p[k], p[(k + 1) % 3]);
            let ex = T::from(b[0]) - T::from(a[0]);
            let ey = T::from(b[1]) - T::from(a[1]);
            let owns = ey < zero || (ey == zero && ex > zero);
            e[k] = ex * (T::from(s[1]) - T::from(a[1])) - ey * (T::from(s[0]) - T::from(a[0]))
                + if owns { one } else { zero };
            dx[k] = zero - ey * w;
            dy[k] = ex * w;
        }
        Self { e, dx, dy }
    }
}

impl Band<'_> {
    /// Rasterizes triangle `t` into the rows of this band.
    fn triangle(&mut self, ctx: &Context<'_>, t: usize) {
        let Some((mut p, [x0, x1, y0, y1])) = extent(&ctx.uv[t], ctx.size) else {
            return;
        };
        let y0 = y0.max(self.row0);
        let y1 = y1.min(self.row0 + self.rows - 1);
        if y0 > y1 {
            return;
        }
        let mut corner = [0usize, 1, 2];
        let area = (i128::from(p[1][0]) - i128::from(p[0][0]))
            * (i128::from(p[2][1]) - i128::from(p[0][1]))
            - (i128::from(p[1][1]) - i128::from(p[0][1]))
                * (i128::from(p[2][0]) - i128::from(p[0][0]));
        if area == 0 {
            return;
        }
        if area < 0 {
            p.swap(1, 2);
            corner.swap(1, 2);
        }
        self.setup_values(ctx, t, corner);
        let fast = p.iter().flatten().all(|c| c.abs() <= FAST_LIMIT);
        if fast {
            self.scan::<i64>(ctx, t, corner, p, [x0, x1, y0, y1]);
        } else {
            self.scan::<i128>(ctx, t, corner, p, [x0, x1, y0, y1]);
        }
    }

    /// Fills `scratch` with, per channel, the value at corner `a` and its changes to `b`, `c`.
    fn setup_values(&mut self, ctx: &Context<'_>, t: usize, corner: [usize; 3]) {
        let c = ctx.channels;
        let vert = corner.map(|k| ctx.faces[t][k] as usize * c);
        for k in 0..c {
            let fa = f64::from(ctx.values[vert[0] + k]);
            self.scratch[3 * k] = fa;
            self.scratch[3 * k + 1] = f64::from(ctx.values[vert[1] + k]) - fa;
            self.scratch[3 * k + 2] = f64::from(ctx.values[vert[2] + k]) - fa;
        }
    }

    fn scan<T: EdgeInt>(
        &mut self,
        ctx: &Context<'_>,
        t: usize,
        corner: [usize; 3],
        p: [[i64; 2]; 3],
        [x0, x1, y0, y1]: [usize; 4],
    ) {
        let size = ctx.size;
        let c = ctx.channels;
        let half = SUB_TEXEL / 2;
        let start = [
            x0 as i64 * SUB_TEXEL + half,
            y0 as i64 * SUB_TEXEL + half,
        ];
        let Edges { e, dx, dy } = Edges::<T>::new(p, start);
        let zero = T::from(0);

        // barycentric coordinates of b and c as affine functions of the texel index, in
        // f64 from the unsnapped UVs (texel units, centre of texel (x, y) at (x+½, y+½))
        let s = size as f64;
        let q = corner.map(|k| ctx.uv[t][k].map(|x| x * s));
        let (bx, by) = (q[1][0] - q[0][0], q[1][1] - q[0][1]);
        let (cx, cy) = (q[2][0] - q[0][0], q[2][1] - q[0][1]);
        let det = bx * cy - by * cx;
        // λb = ((s - a) × (c - a)) / det, λc = ((b - a) × (s - a)) / det
        let (lb_x, lb_y) = (cy / det, -cx / det);
        let (lc_x, lc_y) = (-by / det, bx / det);
        let degenerate = det == 0.0 || !det.is_finite();

        let mut row_e = e;
        for y in y0..=y1 {
            let mut e = row_e;
            let py = y as f64 + 0.5 - q[0][1];
            let row = (y - self.row0) * size;
            for x in x0..=x1 {
                if e[0] > zero && e[1] > zero && e[2] > zero {
                    let i = row + x;
                    match self.coverage[i] {
                        EMPTY => {
                            self.coverage[i] = INSIDE;
                            let px = x as f64 + 0.5 - q[0][0];
                            let (lb, lc) = if degenerate {
                                (1.0 / 3.0, 1.0 / 3.0)
                            } else {
                                (lb_x * px + lb_y * py, lc_x * px + lc_y * py)
                            };
                            let out = &mut self.pixels[i * c..(i + 1) * c];
                            for (k, o) in out.iter_mut().enumerate() {
                                let v = &self.scratch[3 * k..3 * k + 3];
                                *o = (v[0] + lb * v[1] + lc * v[2]) as f32;
                            }
                        }
                        INSIDE => {
                            self.coverage[i] = OVERLAP;
                            self.overlapping += 1;
                        }
                        _ => {}
                    }
                }
                for k in 0..3 {
                    e[k] = e[k] + dx[k];
                }
            }
            for k in 0..3 {
                row_e[k] = row_e[k] + dy[k];
            }
        }
    }
}
