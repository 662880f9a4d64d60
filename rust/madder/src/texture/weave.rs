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
//! Measured in `benches/texture.rs` (ARCHITECTURE.md has the figures).

use crate::error::TextureError;
use crate::weave::Corrector;

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
pub(crate) struct TriWeave {
    fabric: usize,
    base: [f64; 2],
    dx: [f64; 2],
    dy: [f64; 2],
    grad: Vec<[f64; 2]>,
}

impl TriWeave {
    /// Sets up triangle `t` from the rasterizer's per-texel field `base + gx·x + gy·y`
    /// (one of each per channel); false when the face has no detail, or when its field is
    /// zero in every channel (the detail of 0 is exactly 0: most of a frame is unstained).
    pub(crate) fn setup(
        &mut self,
        detail: &WeaveDetail<'_>,
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
        let corr = detail.correctors[f as usize];
        let (w, h) = corr.cells();
        let [tx, ty] = corr.threads();
        // A = diag(cells per thread) · J: UV → cells
        // in sample-grid units: × samples per cell
        let r = corr.refine() as f64;
        let (sx, sy) = (r * w as f64 / tx, r * h as f64 / ty);
        let a = [m[0] * sx, m[1] * sx, m[2] * sy, m[3] * sy];
        let s = size as f64;
        self.fabric = f as usize;
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

    /// Writes texel `(x, y)`: `sigma[k]` the homogenized value of channel `k` there.
    #[inline]
    pub(crate) fn texel(
        &self,
        detail: &WeaveDetail<'_>,
        x: f64,
        y: f64,
        sigma: impl Fn(usize) -> f64,
        out: &mut [f32],
    ) {
        let corr = detail.correctors[self.fabric];
        let p = [
            self.base[0] + self.dx[0] * x + self.dy[0] * y,
            self.base[1] + self.dx[1] * x + self.dy[1] * y,
        ];
        let (chi, u) = corr.sample(p);
        let m = corr.moment();
        for (k, o) in out.iter_mut().enumerate() {
            let g = self.grad[k];
            let s = sigma(k);
            *o = if detail.uptake[k] {
                u * s + (chi[0] - m[0]) * g[0] + (chi[1] - m[1]) * g[1]
            } else {
                s + chi[0] * g[0] + chi[1] * g[1]
            } as f32;
        }
    }
}
