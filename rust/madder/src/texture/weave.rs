//! The weave's fine scale added back at texture resolution (issue 13 part 4): a texel pass
//! run by the rasterizer itself, on the texels each triangle writes.
//!
//! # The math (seed §2.2; [`crate::weave::Corrector`] has the derivation)
//!
//! Stain channels: `σ = U(y) σ0 + (χ(y) − m)·∇_y σ0`; other channels: `σ0 + χ(y)·∇_y σ0`.
//! Per texel, `σ0` is the rasterized (barycentric) value at its centre, `y` the tile
//! coordinate of that centre in cells and `∇_y σ0` the homogenized field's gradient in
//! tile units. Per triangle `t`, the caller gives `J_t`, the linear map from UV to
//! *threads* along the fabric's weft and warp (threads per UV unit: `thread count × world
//! length per UV unit`, rotated by the weft angle, see the add-on's `weave_maps`). The
//! rasterizer scales it by the tile's cells per thread to `A_t` (UV → cells), so
//!
//! ```text
//! y = A_t · uv,       ∇_y σ0 = A_t⁻ᵀ ∇_uv σ0,       ∇_uv σ0 = size · (g_x, g_y),
//! ```
//!
//! with `(g_x, g_y)` the per-texel gradient the rasterizer already holds for the triangle
//! (P1: constant over it). The tile is anchored at UV `(0, 0)`, so neighbouring triangles
//! with the same map continue one another's weave.
//!
//! # Why inside the rasterizer (and not a pass over the finished image)
//!
//! The detail needs, per texel, which triangle covers it: the triangle's gradient, map and
//! fabric. The rasterizer knows that while it writes the texel; a later pass would need a
//! per-texel triangle index (4 bytes a texel written and read back) or a second
//! rasterization. So [`super::rasterize_with`] takes an optional [`WeaveDetail`]; without
//! it (or for faces without a fabric) every texel is computed by the same code as before,
//! bit for bit. Same bands, same order: the result does not depend on the thread count.
//!
//! # Cost
//!
//! Per covered texel of a woven face: the tile position (two integer adds), the patch
//! and the offset in it (one integer product per axis), one bilinear read of both
//! correctors and the uptake (one 36-byte `f32` entry of a table of at most 4096
//! patches, 37 kB for a plain weave with gaps), and a multiply-add per channel and term,
//! in `f32`. Triangles whose field is zero in every channel skip it (the detail of 0 is
//! 0).
//!
//! How the texel pass is laid out for speed:
//!
//! - **Two phases per triangle.** The coverage scan only marks the texels the triangle
//!   covers first ([`super::coverage::CLAIMED`]) and keeps, per row, the span between the
//!   first and the last ([`Run`]); [`Texels::shade`] then walks the spans. (Shading
//!   inside the scan, on each texel as it is claimed, measured no faster.)
//! - **The tile position in 64-bit fixed point**, as the fraction of the tile along each
//!   axis (`p / 2^64`): the texel centre `(x, y)` is `phase + x · step_x + y · step_y`
//!   with wrapping integer arithmetic, so the tile's periodic wrap is the integers' own
//!   overflow (no floor, no modulo) and along a span the position steps by one add,
//!   exactly (the same bits as the product). The patch is the high word of `p · n` (`n`
//!   samples along the axis: always inside the grid) and the offset in it the low word's
//!   24 high bits, exact in `f32`. The steps are the per-texel map `A / size` in tiles,
//!   wrapped, from the `f64` they are computed in (relative error 2⁻⁵³): over 16384
//!   texels the position is off by at most ~2⁻⁴⁰ of a tile, the order of the `f64`
//!   arithmetic it replaces (a texel lands on the other side of a cell edge, and takes
//!   the other cell's uptake, only if its centre lies within ~10⁻¹⁰ samples of it).
//! - **The channels in `f32`**: `σ0` as the plain scan has it (the same `f64` expression)
//!   at the span's first texel, rounded once, then `σ0 + g_x d` in `f32` along the
//!   span; `U σ0 + χ_x g_x + χ_y g_y − m·g` with the gradient in cells `g` and the
//!   offset `−m·g` per channel rounded to `f32` per triangle (from a per-map matrix
//!   `size · A⁻ᵀ`). Four channels are then one 4-lane SSE2 vector per operation (the
//!   compiler vectorizes the fixed-count kernel; the any-count one does the same
//!   arithmetic channel by channel, the same bits). Against the `f64` arithmetic this
//!   moves a value by a few `f32` roundings: at most 2.4·10⁻⁷ on 2048² frames of three
//!   meshes × three fabrics (`MADDER_BENCH_BITS` in the bench), 10³ times below a
//!   half-float step at 1 (the EXR output) and 10⁴ below an 8-bit step.
//! - **Per-map constants kept** ([`MapSetup`]): the fixed-point steps, the gradient
//!   matrix and the uptake's offset depend only on the fabric and the face's map, and
//!   are recomputed only when they change from one triangle to the next.
//! - **The table** interleaves `χ_x` and `χ_y` (`[c0x, c0y, c2x, c2y, c1x, c1y, c3x,
//!   c3y, U]`): both bilinear forms are the same 4-lane expression (the compiler
//!   currently still evaluates it lane by lane; the loads are contiguous either way).
//!
//! Measured in `benches/texture.rs` (ARCHITECTURE.md has the figures).

use super::coverage::{CLAIMED, INSIDE, MAX_CHANNELS};
use crate::error::TextureError;
use crate::weave::Corrector;
use crate::weave::corrector::Sampler;

/// Face without weave detail in [`WeaveDetail::face_fabric`].
pub const NO_WEAVE: u32 = u32::MAX;

/// The weave detail's input: the fabrics' correctors and, per triangle, which fabric and
/// how its UVs map to threads (module doc).
#[derive(Debug, Clone, Copy)]
pub struct WeaveDetail<'a> {
    /// The fabrics' correctors.
    pub correctors: &'a [&'a Corrector],
    /// Per triangle, its fabric (an index into `correctors`) or [`NO_WEAVE`].
    pub face_fabric: &'a [u32],
    /// Per triangle, `J_t` row-major `[j11, j12, j21, j22]`: threads along the weft
    /// `= j11 u + j12 v`, along the warp `= j21 u + j22 v`. A zero map means no detail.
    pub face_map: &'a [[f64; 4]],
    /// Per channel, whether the uptake applies (the deposit's channels) or only the
    /// corrector (e.g. wetness).
    pub uptake: &'a [bool],
}

impl WeaveDetail<'_> {
    /// Checks the lengths against `n_faces` and `channels`, and each woven face's fabric
    /// index and map (finite; invertible unless zero).
    pub(crate) fn check(&self, n_faces: usize, channels: usize) -> Result<(), TextureError> {
        for (name, expected, got) in [
            ("face_fabric", n_faces, self.face_fabric.len()),
            ("face_map", n_faces, self.face_map.len()),
            ("uptake", channels, self.uptake.len()),
        ] {
            if got != expected {
                return Err(TextureError::Length {
                    name,
                    expected,
                    got,
                });
            }
        }
        for (face, (&f, m)) in self.face_fabric.iter().zip(self.face_map).enumerate() {
            if f == NO_WEAVE {
                continue;
            }
            let problem = if f as usize >= self.correctors.len() {
                format!(
                    "fabric {f}, but there are {} fabrics",
                    self.correctors.len()
                )
            } else if !m.iter().all(|x| x.is_finite()) {
                format!("its UV-to-thread map {m:?} is not finite")
            } else if m.iter().any(|&x| x != 0.0) && m[0] * m[3] - m[1] * m[2] == 0.0 {
                format!("its UV-to-thread map {m:?} is singular")
            } else {
                continue;
            };
            return Err(TextureError::WeaveFace { face, problem });
        }
        Ok(())
    }
}

/// `2^64` as an `f64`: tile fractions to 64-bit fixed point.
const TWO_64: f64 = 18_446_744_073_709_551_616.0;

/// `v` (in tiles) as a 64-bit fixed-point fraction of the tile, wrapped: `frac(v) · 2^64`.
/// `v − ⌊v⌋` is exact in `f64`; a fraction that rounds up to 1 saturates to `2^64 − 1`, one
/// unit (`2^-64` tile) from the wrapped 0. Per fabric and map, not per texel.
fn fixed(v: f64) -> u64 {
    ((v - v.floor()) * TWO_64) as u64
}

/// The part of a triangle's detail that depends only on its fabric and map, kept while the
/// next triangle has the same (most do: one fabric, one map per island or object).
#[derive(Debug, Clone, Copy)]
struct MapSetup<'a> {
    key: (u32, [u64; 4]),
    sampler: Sampler<'a>,
    /// `size · A⁻ᵀ` (A: UV → cells), row-major: the rasterizer's per-texel gradient to
    /// the gradient in tile cells; and `−mᵀ size A⁻ᵀ`, the uptake's offset `−m·g` from
    /// the same per-texel gradient
    grad: [f64; 4],
    offset: [f64; 2],
    /// the tile position of texel `(x, y)`'s centre is `phase + x · step_x + y · step_y`
    /// (wrapping: the tile repeats), fixed point
    phase: [u64; 2],
    step_x: [u64; 2],
    step_y: [u64; 2],
}

impl<'a> MapSetup<'a> {
    #[cold]
    #[inline(never)]
    fn new(corr: &'a Corrector, key: (u32, [u64; 4]), m: [f64; 4], size: usize) -> Self {
        let (w, h) = corr.cells();
        let [tx, ty] = corr.threads();
        // A = diag(cells per thread) · J: UV → cells; over the tile's cells: UV → tiles
        let (cx, cy) = (w as f64 / tx, h as f64 / ty);
        let a = [m[0] * cx, m[1] * cx, m[2] * cy, m[3] * cy];
        let s = size as f64;
        // per texel, in tiles: x → (a11, a21) / (w size), y → (a12, a22) / (h size)
        let dx = [m[0] / tx / s, m[2] / ty / s];
        let dy = [m[1] / tx / s, m[3] / ty / s];
        // size · A⁻ᵀ = size / det A · [[a22, −a21], [−a12, a11]]
        let inv = s / (a[0] * a[3] - a[1] * a[2]);
        let grad = [a[3] * inv, -a[2] * inv, -a[1] * inv, a[0] * inv];
        let m = corr.moment();
        MapSetup {
            key,
            sampler: corr.sampler(),
            grad,
            offset: [
                -(m[0] * grad[0] + m[1] * grad[2]),
                -(m[0] * grad[1] + m[1] * grad[3]),
            ],
            phase: [0, 1].map(|i| fixed(0.5 * (dx[i] + dy[i]))),
            step_x: dx.map(fixed),
            step_y: dy.map(fixed),
        }
    }
}

/// One triangle's detail, set up once per triangle (its map's part once per run of
/// triangles sharing fabric and map, [`MapSetup`]).
#[derive(Debug, Default)]
pub(crate) struct TriWeave<'a> {
    map: Option<MapSetup<'a>>,
    uptake: &'a [bool],
}

impl<'a> TriWeave<'a> {
    /// Sets up triangle `t` from the rasterizer's per-texel field `base + gx·x + gy·y`
    /// (one of each per channel); false when the face has no detail, or when its field is
    /// zero in every channel (the detail of 0 is exactly 0: most of a frame is unstained).
    /// The per-channel part (the gradient in cells) is left to [`Texels::shade`], where
    /// the channel count is a constant and the values stay in registers.
    #[inline(always)]
    pub(crate) fn setup(
        &mut self,
        detail: &WeaveDetail<'a>,
        t: usize,
        size: usize,
        [base, gx, gy]: [&[f64]; 3],
    ) -> bool {
        let f = detail.face_fabric[t];
        let m = detail.face_map[t];
        let zero = |v: &[f64]| v.iter().all(|&x| x == 0.0);
        if f == NO_WEAVE || zero(&m) || (zero(base) && zero(gx) && zero(gy)) {
            return false;
        }
        // compared element by element: a whole-array compare spilled `m` to the stack and
        // read it back in wider words (a store-forwarding stall per triangle)
        let same = |k: &(u32, [u64; 4])| {
            k.0 == f
                && k.1[0] == m[0].to_bits()
                && k.1[1] == m[1].to_bits()
                && k.1[2] == m[2].to_bits()
                && k.1[3] == m[3].to_bits()
        };
        if !self.map.as_ref().is_some_and(|map| same(&map.key)) {
            let key = (f, m.map(f64::to_bits));
            self.map = Some(MapSetup::new(detail.correctors[f as usize], key, m, size));
        }
        self.uptake = detail.uptake;
        true
    }

    /// The texel kernel of the triangle last set up (for `c` channels), taken once per
    /// triangle so that the scan's inner loop holds only per-texel work.
    #[inline(always)]
    pub(crate) fn texels(&self, c: usize) -> Texels<'_> {
        let map = self.map.expect("texels() after a successful setup()");
        Texels {
            sampler: map.sampler,
            uptake: &self.uptake[..c],
            grad: map.grad,
            offset: map.offset,
            phase: map.phase,
            step_x: map.step_x,
            step_y: map.step_y,
        }
    }
}

/// One set-up triangle's texel kernel ([`TriWeave::texels`]).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Texels<'s> {
    sampler: Sampler<'s>,
    uptake: &'s [bool],
    grad: [f64; 4],
    offset: [f64; 2],
    phase: [u64; 2],
    step_x: [u64; 2],
    step_y: [u64; 2],
}

/// The texels of one row a woven triangle covers first, waiting for [`Texels::shade`]:
/// row `y`, texels `x0..=x1` (image coordinates), those among them marked
/// [`CLAIMED`] (the others, if any, belong to an earlier triangle).
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct Run {
    y: u32,
    x0: u32,
    x1: u32,
}

impl Run {
    /// Row `y`, texels `x0..=x1`.
    #[inline(always)]
    pub(crate) fn new(y: usize, x0: usize, x1: usize) -> Run {
        Run {
            y: y as u32,
            x0: x0 as u32,
            x1: x1 as u32,
        }
    }
}

impl Texels<'_> {
    /// Per channel, the gradient in tile cells, `g = A⁻ᵀ ∇_uv σ0` (`∇_uv σ0 = size ·
    /// (g_x, g_y)`), and the uptake's offset `−m·g` (0 without uptake: `U σ0 + (χ − m)·g
    /// = U σ0 + χ·g − m·g`), rounded to `f32`: `[g_x, g_y, offset]`, each one lane a
    /// channel (so that `C` channels are a few vector operations).
    #[inline(always)]
    fn gradients<const C: usize>(
        &self,
        gu: [f64; C],
        gv: [f64; C],
        up: [bool; C],
    ) -> [[f32; C]; 3] {
        let (g, o) = (self.grad, self.offset);
        let mut out = [[0.0f32; C]; 3];
        for k in 0..C {
            out[0][k] = (g[0] * gu[k] + g[1] * gv[k]) as f32;
            out[1][k] = (g[2] * gu[k] + g[3] * gv[k]) as f32;
            out[2][k] = if up[k] {
                (o[0] * gu[k] + o[1] * gv[k]) as f32
            } else {
                0.0
            };
        }
        out
    }

    /// The tile position of texel `(x, y)`'s centre, fixed point (wrapped by the integer
    /// arithmetic itself).
    #[inline(always)]
    fn position(&self, x: u32, y: u32) -> [u64; 2] {
        let (x, y) = (u64::from(x), u64::from(y));
        [0, 1].map(|i| {
            self.phase[i]
                .wrapping_add(self.step_x[i].wrapping_mul(x))
                .wrapping_add(self.step_y[i].wrapping_mul(y))
        })
    }

    /// Writes the claimed texels of `runs` and marks them [`INSIDE`] (image coordinates;
    /// `pixels` and `coverage` hold rows from `row0` on, `size` texels a row, `c` channels
    /// a texel; `C` is `c` when fixed, 0 for any). `field` is the rasterizer's `[base,
    /// gx, gy]` per channel: `σ0 = (base + gy·y) + gx·x`, the same expression (the same
    /// bits) as the plain scan, rounded to `f32`; the rest in `f32`:
    /// `U σ0 + χ_x g_x + χ_y g_y − m·g`. Along a run the tile position steps by
    /// `step_x`, exactly (integers).
    ///
    /// Separate from the coverage scan on purpose (module doc, "Cost").
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    pub(crate) fn shade<const C: usize>(
        &self,
        runs: &[Run],
        c: usize,
        [base, gx, gy]: [&[f64]; 3],
        pixels: &mut [f32],
        coverage: &mut [u8],
        row0: usize,
        size: usize,
    ) {
        if C == 0 {
            return self.shade_any(runs, c, [base, gx, gy], pixels, coverage, row0, size);
        }
        // per channel, in registers: the field, the gradient in cells, the offset, and
        // whether the uptake applies (`U` on the deposit's channels; 1 elsewhere)
        // (plain loops: `array::from_fn` over a closure was left a call per triangle)
        let (mut b, mut x, mut y) = ([0.0f64; C], [0.0f64; C], [0.0f64; C]);
        let mut up = [false; C];
        for k in 0..C {
            (b[k], x[k], y[k], up[k]) = (base[k], gx[k], gy[k], self.uptake[k]);
        }
        let (base, gx, gy) = (b, x, y);
        let [g0, g1, offset] = self.gradients(gx, gy, up);
        let mut gx32 = [0.0f32; C];
        for k in 0..C {
            gx32[k] = gx[k] as f32;
        }
        for &Run { y, x0, x1 } in runs {
            let yf = f64::from(y);
            let mut row = [0.0f64; C];
            for k in 0..C {
                row[k] = base[k] + gy[k] * yf;
            }
            let o = (y as usize - row0) * size;
            let (x0, x1) = (x0 as usize, x1 as usize);
            let cov = &mut coverage[o + x0..=o + x1];
            let pix = &mut pixels[(o + x0) * C..(o + x1 + 1) * C];
            let mut p = self.position(x0 as u32, y);
            // σ0 at the run's first texel as the plain scan has it, then along the run
            let mut s0 = [0.0f32; C];
            for k in 0..C {
                s0[k] = (row[k] + gx[k] * x0 as f64) as f32;
            }
            let mut d = 0.0f32;
            for (m, out) in cov.iter_mut().zip(pix.chunks_exact_mut(C)) {
                if *m == CLAIMED {
                    *m = INSIDE;
                    let (i, tx, ty) = self.sampler.locate(p);
                    let (chi, u) = self.sampler.eval(i, tx, ty);
                    for k in 0..C {
                        let s = s0[k] + gx32[k] * d;
                        let uk = if up[k] { u } else { 1.0 };
                        out[k] = uk * s + chi[0] * g0[k] + chi[1] * g1[k] + offset[k];
                    }
                }
                p = [
                    p[0].wrapping_add(self.step_x[0]),
                    p[1].wrapping_add(self.step_x[1]),
                ];
                d += 1.0;
            }
        }
    }

    /// [`Texels::shade`] for any number of channels (the same arithmetic per channel).
    #[allow(clippy::too_many_arguments)]
    fn shade_any(
        &self,
        runs: &[Run],
        c: usize,
        [base, gx, gy]: [&[f64]; 3],
        pixels: &mut [f32],
        coverage: &mut [u8],
        row0: usize,
        size: usize,
    ) {
        let (base, gx, gy) = (&base[..c], &gx[..c], &gy[..c]);
        let mut g = [[0.0f32; 3]; MAX_CHANNELS];
        for k in 0..c {
            let [g0, g1, offset] = self.gradients([gx[k]], [gy[k]], [self.uptake[k]]);
            g[k] = [g0[0], g1[0], offset[0]];
        }
        for &Run { y, x0, x1 } in runs {
            let yf = f64::from(y);
            let o = (y as usize - row0) * size;
            for x in x0..=x1 {
                let m = &mut coverage[o + x as usize];
                if *m != CLAIMED {
                    continue;
                }
                *m = INSIDE;
                let (i, tx, ty) = self.sampler.locate(self.position(x, y));
                let (chi, u) = self.sampler.eval(i, tx, ty);
                let d = (x - x0) as f32;
                let out = &mut pixels[(o + x as usize) * c..][..c];
                for k in 0..c {
                    let s0 = ((base[k] + gy[k] * yf) + gx[k] * f64::from(x0)) as f32;
                    let s = s0 + gx[k] as f32 * d;
                    let uk = if self.uptake[k] { u } else { 1.0 };
                    out[k] = uk * s + chi[0] * g[k][0] + chi[1] * g[k][1] + g[k][2];
                }
            }
        }
    }
}
