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
//! Per covered texel of a woven face: the tile coordinate (affine, 4 multiply-adds), one
//! bilinear read of both correctors and the uptake (one 36-byte `f32` entry of a table of
//! at most 4096 patches, 37 kB for a plain weave with gaps), and 2 multiply-adds per
//! channel. Triangles whose field is zero in every channel skip it (the detail of 0 is 0).
//!
//! How the texel pass is laid out for speed (same arithmetic, same bits as the first,
//! per-texel version; checked on 2048² frames):
//!
//! - **Two phases per triangle.** The coverage scan only records the texels the triangle
//!   writes first ([`Pending`]); [`Texels::shade`] then runs through them: first every
//!   texel's patch and offset ([`Sampler::locate`], branch-free), then the reads and the
//!   channels. Interleaved, each texel's dependent chain (coordinate → wrap → index →
//!   table read → channels) sat between the scan's unpredictable branches; as a batch,
//!   the texels overlap.
//! - **Per-triangle constants hoisted** ([`TriWeave::texels`], [`Sampler`]): the table,
//!   the grid sizes and their inverses (a division per texel before), the uptake's `U`
//!   and `m` per channel as values (1 and 0 on non-deposit channels: `1 · s = s` and
//!   `χ − 0 = χ` exactly, so no per-channel branch and no change of bits).
//! - **No float-to-integer casts** in the loop: Rust's `as` saturates (NaN and range
//!   checks per conversion); the floor and the index come from adding `1.5 · 2^52`
//!   (exact for the `|x| < 2^51` that arise) and the patch is clamped into the grid in
//!   floating point, so the table index is in range by construction.
//!
//! Measured in `benches/texture.rs` (ARCHITECTURE.md has the figures).

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

/// One triangle's detail, set up once per triangle: the tile coordinate at texel `(x, y)`
/// is `base + dx·x + dy·y` (in sample-grid units, cells × the corrector's refinement),
/// and channel `k`'s gradient in tile cells is `grad[k]`.
#[derive(Debug, Default)]
pub(crate) struct TriWeave<'a> {
    sampler: Option<Sampler<'a>>,
    uptake: &'a [bool],
    moment: [f64; 2],
    base: [f64; 2],
    dx: [f64; 2],
    dy: [f64; 2],
    grad: Vec<[f64; 2]>,
}

impl<'a> TriWeave<'a> {
    /// Sets up triangle `t` from the rasterizer's per-texel field `base + gx·x + gy·y`
    /// (one of each per channel); false when the face has no detail, or when its field is
    /// zero in every channel (the detail of 0 is exactly 0: most of a frame is unstained).
    #[inline]
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
        let corr: &'a Corrector = detail.correctors[f as usize];
        let (w, h) = corr.cells();
        let [tx, ty] = corr.threads();
        // A = diag(cells per thread) · J: UV → cells
        // in sample-grid units: × samples per cell
        let r = corr.refine() as f64;
        let (sx, sy) = (r * w as f64 / tx, r * h as f64 / ty);
        let a = [m[0] * sx, m[1] * sx, m[2] * sy, m[3] * sy];
        let s = size as f64;
        self.sampler = Some(corr.sampler());
        self.uptake = detail.uptake;
        self.moment = corr.moment();
        self.dx = [a[0] / s, a[2] / s];
        self.dy = [a[1] / s, a[3] / s];
        self.base = [
            0.5 * (self.dx[0] + self.dy[0]),
            0.5 * (self.dx[1] + self.dy[1]),
        ];
        // ∇_y = A⁻ᵀ ∇_uv, ∇_uv = size · (g_x, g_y) (A in cells: the grid's A over r)
        let inv = r * s / (a[0] * a[3] - a[1] * a[2]);
        self.grad.clear();
        self.grad.extend(gx.iter().zip(gy).map(|(&gu, &gv)| {
            [
                (a[3] * gu - a[2] * gv) * inv,
                (-a[1] * gu + a[0] * gv) * inv,
            ]
        }));
        true
    }

    /// The texel kernel of the triangle last set up (for `c` channels), taken once per
    /// triangle so that the scan's inner loop holds only per-texel work.
    #[inline(always)]
    pub(crate) fn texels(&self, c: usize) -> Texels<'_> {
        Texels {
            sampler: self.sampler.expect("texels() after a successful setup()"),
            uptake: &self.uptake[..c],
            grad: &self.grad[..c],
            moment: self.moment,
            base: self.base,
            dx: self.dx,
            dy: self.dy,
        }
    }
}

/// One set-up triangle's texel kernel ([`TriWeave::texels`]).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Texels<'s> {
    sampler: Sampler<'s>,
    uptake: &'s [bool],
    grad: &'s [[f64; 2]],
    moment: [f64; 2],
    base: [f64; 2],
    dx: [f64; 2],
    dy: [f64; 2],
}

/// A texel a woven triangle covers first, waiting for [`Texels::shade`]: its position
/// (image coordinates), then its patch and offset in it ([`Sampler::locate`]).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Pending {
    x: u32,
    y: u32,
    patch: u32,
    tx: f32,
    ty: f32,
}

impl Pending {
    /// Texel `(x, y)`, not located yet.
    #[inline(always)]
    pub(crate) fn at(x: usize, y: usize) -> Pending {
        Pending {
            x: x as u32,
            y: y as u32,
            patch: 0,
            tx: 0.0,
            ty: 0.0,
        }
    }
}

impl Texels<'_> {
    /// Writes the texels `pending` (image coordinates; `pixels` holds rows from `row0` on,
    /// `size` texels a row, `c` channels a texel; `C` is `c` when fixed, 0 for any).
    /// `field` is the rasterizer's `[base, gx, gy]` per channel: `σ0 = (base + gy·y) +
    /// gx·x`, the same expression (the same bits) as the plain scan.
    ///
    /// Separate from the coverage scan on purpose (module doc, "Cost"): first every
    /// texel's patch, back to back and branch-free, then the reads and the channels.
    #[inline(always)]
    pub(crate) fn shade<const C: usize>(
        &self,
        pending: &mut [Pending],
        c: usize,
        [base, gx, gy]: [&[f64]; 3],
        pixels: &mut [f32],
        row0: usize,
        size: usize,
    ) {
        if C == 0 {
            return self.shade_any(pending, c, [base, gx, gy], pixels, row0, size);
        }
        // per channel, in registers: the field, the gradient in cells, and the uptake's
        // part (`U` and `m` on the deposit's channels; 1 and 0 elsewhere, which gives
        // `σ0 + χ·∇σ0` with the same bits: `1 · s = s`, `χ − 0 = χ`)
        let lanes = |v: &[f64]| -> [f64; C] { std::array::from_fn(|k| v[k]) };
        let (base, gx, gy) = (lanes(base), lanes(gx), lanes(gy));
        let g0: [f64; C] = std::array::from_fn(|k| self.grad[k][0]);
        let g1: [f64; C] = std::array::from_fn(|k| self.grad[k][1]);
        let up: [bool; C] = std::array::from_fn(|k| self.uptake[k]);
        let mx: [f64; C] = std::array::from_fn(|k| if up[k] { self.moment[0] } else { 0.0 });
        let my: [f64; C] = std::array::from_fn(|k| if up[k] { self.moment[1] } else { 0.0 });
        self.locate_all(pending);
        for &Pending {
            x,
            y,
            patch,
            tx,
            ty,
        } in pending.iter()
        {
            let (chi, u) = self.sampler.eval(patch as usize, tx, ty);
            let o = ((y as usize - row0) * size + x as usize) * C;
            let (xf, yf) = (f64::from(x), f64::from(y));
            let out: &mut [f32; C] = (&mut pixels[o..o + C]).try_into().expect("C values");
            for k in 0..C {
                let s = (base[k] + gy[k] * yf) + gx[k] * xf;
                let uk = if up[k] { u } else { 1.0 };
                out[k] = (uk * s + (chi[0] - mx[k]) * g0[k] + (chi[1] - my[k]) * g1[k]) as f32;
            }
        }
    }

    /// Finds every pending texel's patch and offset ([`Sampler::locate`]), in place, back
    /// to back: independent, branch-free iterations.
    #[inline(always)]
    fn locate_all(&self, pending: &mut [Pending]) {
        for t in pending {
            let (x, y) = (f64::from(t.x), f64::from(t.y));
            let p = [
                self.base[0] + self.dx[0] * x + self.dy[0] * y,
                self.base[1] + self.dx[1] * x + self.dy[1] * y,
            ];
            let (i, tx, ty) = self.sampler.locate(p);
            (t.patch, t.tx, t.ty) = (i as u32, tx, ty);
        }
    }

    /// [`Texels::shade`] for any number of channels.
    fn shade_any(
        &self,
        pending: &mut [Pending],
        c: usize,
        [base, gx, gy]: [&[f64]; 3],
        pixels: &mut [f32],
        row0: usize,
        size: usize,
    ) {
        let (base, gx, gy) = (&base[..c], &gx[..c], &gy[..c]);
        let m = self.moment;
        self.locate_all(pending);
        for &Pending {
            x,
            y,
            patch,
            tx,
            ty,
        } in pending.iter()
        {
            let (chi, u) = self.sampler.eval(patch as usize, tx, ty);
            let o = ((y as usize - row0) * size + x as usize) * c;
            let (xf, yf) = (f64::from(x), f64::from(y));
            let out = &mut pixels[o..o + c];
            for k in 0..c {
                let s = (base[k] + gy[k] * yf) + gx[k] * xf;
                let g = self.grad[k];
                out[k] = if self.uptake[k] {
                    u * s + (chi[0] - m[0]) * g[0] + (chi[1] - m[1]) * g[1]
                } else {
                    s + chi[0] * g[0] + chi[1] * g[1]
                } as f32;
            }
        }
    }
}
