//! The cell problem's correctors, kept for the texture: the weave's fine scale added back
//! to the homogenized stain (issue 13 part 4, the seed's "dynamical texture for adding back
//! high frequencies taken out during homogenization").
//!
//! # The two-scale expansion (seed §2.2, eqs. 2.1–2.4)
//!
//! Homogenization replaces the rapidly varying tensor `a(x/ε)` of eq. 2.1 by the constant
//! `A` of eq. 2.3. The solution of the real, woven problem is, to first order in the
//! period `ε`,
//!
//! ```text
//! σ(x) ≈ σ0(x) + ε χ(x/ε) · ∇σ0(x)          (χ = (χ_x, χ_y), y = x/ε the tile coordinate)
//! ```
//!
//! with `σ0` the homogenized solution and `χ_i` the periodic corrector of the macroscopic
//! gradient `e_i`: the minimizer of `⟨(e_i + ∇χ_i)ᵀ a (e_i + ∇χ_i)⟩` (eq. 2.4 is its
//! Euler–Lagrange equation). `ε χ · ∇σ0 = χ · ∇_y σ0`, the gradient in tile units, so the
//! texture needs only `χ` on the tile and `σ0`'s gradient per cloth triangle.
//!
//! # Uptake
//!
//! The expansion moves liquid between threads and gaps; what a viewer sees of a dried
//! stain also depends on how much of the deposit each cell takes up (a yarn on the face
//! shows its dye, a yarn on the back is half hidden, a gap holds little). [`Corrector`]
//! keeps a per-cell uptake factor `U` normalized to mean exactly 1 over the tile, and the
//! stain channels of the texture become
//!
//! ```text
//! σ = U(y) σ0 + (χ(y) − m) · ∇_y σ0,      m = ⟨(U − 1) y⟩  (the uptake's first moment)
//! ```
//!
//! `⟨U⟩ = 1` and `⟨χ⟩ = 0` make the detail vanish on average where `σ0` is constant; the
//! moment `m` (a constant vector per tile) removes the one first-order term `⟨(U − 1) y⟩ ·
//! ∇_y σ0` that `U σ0` adds where `σ0` is linear, so the mass over whole tiles is `σ0`'s
//! exactly for a linear `σ0`. Channels without uptake (wetness) get `σ0 + χ · ∇_y σ0`.
//! The default factors ([`default_uptake`]) are not physics from the seed; they are set
//! from what a cell of the tile stands for, before normalization:
//!
//! - a yarn on the face: 1, the reference (the dye wicks through the whole yarn);
//! - a yarn on the back, seen in the slot between two raised yarns: 0.9 (the same dyed
//!   fibres, their flanks shaded by the yarns beside them);
//! - a gap: `max(0, 1 − (1 − C) / a)`, with `a` the share of the tile's cells that are
//!   gaps (¼ in the built-in tiles with gaps: one gap per crossing) and `C` the fabric's
//!   cover factor, the share of the cloth's area its yarns hide ([`COVER_FACTOR`]). A gap
//!   cell is as wide as a yarn, far wider than a real interstice: only its open part,
//!   `(1 − C)` of the cloth, holds no fibre (and no deposit); the rest of it is the
//!   yarns' hairy flanks, which take the dye as a yarn does. With `C = 0.92` and `a = ¼`
//!   a gap takes 0.68.
//!
//! The contrast between yarn and gap is then about 1.5 : 1; the first version's factors
//! (¾ and ⅓, a gap as if entirely open) gave 3 : 1 and a close-up read as a screen print
//! (saturated threads on white gaps).
//!
//! # Discretization
//!
//! The corrector is the primal P1 solve of [`super::cell_problem`] (same assembly, same
//! factorization, the solution kept instead of dropped) on the tile refined `r` times,
//! `r = ⌊√(4096 / (w h))⌋` clamped to `1..=8` (a plain weave with gaps, 4 × 4 cells,
//! gets 32 × 32 samples: a thread is at most a few texels wide, see the add-on's
//! warning, so finer samples would not show). It is stored at the corner vertices and
//! read by bilinear interpolation, periodic; its mean *as interpolated* (the vertex mean)
//! is removed, so `⟨χ⟩ = 0` holds for what the texture samples. [`Corrector::energy`]
//! evaluates `⟨(e_i + ∇χ_i)ᵀ a (e_j + ∇χ_j)⟩` from the stored corners: the primal P1
//! effective tensor of that refinement (an upper bound of eq. 2.3's `A`). Laminates are
//! exact: their corrector is piecewise linear with kinks on cell edges.
//!
//! # Prefiltering (what a texel can hold)
//!
//! The texture samples `χ` and `U` once per texel, at its centre. A cell spans only a
//! few texels at a fabric's real thread count (5 threads/cm on a 1.6 m cloth in a 2048 px
//! image: 1.3 texels a cell), and `U` jumps at cell edges: point samples of it alias into
//! an irregular crosshatch that is not the weave. [`Corrector::filtered`] returns the same
//! corrector convolved with a periodic Gaussian of standard deviation `s` cells (the add-on
//! picks `s` per face as half a texel's footprint, a texture's usual prefilter), so each
//! texel samples the band-limited pattern: the thread's repeat survives, attenuated, and
//! what the texel grid cannot carry is gone. A periodic convolution with a kernel of
//! integral 1 keeps `⟨U⟩ = 1` and `⟨χ⟩ = 0`; the filtered `U` is kept per patch of the
//! sample grid (constant on each, `1/r` of a cell, no longer per cell), and `m` is its
//! first moment over the patches, so the detail still integrates to zero over a tile.
//! The filtered corrector is a picture's prefilter, not a solution of the cell problem:
//! its [`Corrector::energy`] is no longer the effective tensor.
//!
//! Correctors are memoized like the tensors ([`corrector_cached`]): the texture export
//! asks for the same few fabrics on every frame.

use std::collections::VecDeque;
use std::hash::{DefaultHasher, Hash, Hasher};
use std::sync::{Arc, Mutex, OnceLock};

use super::cell_problem::{Grid, corrector_energy};
use super::check::{check_tile, scale_exponent};
use super::homogenize::{bits, refine};
use super::pattern::{Cell, PairCoefficients, Tile, cell_tensors};
use super::{Tensor2, tensor};
use crate::error::WeaveError;

/// Corrector samples per tile, at most: `r² w h ≤ 4096`.
pub const CORRECTOR_SAMPLES: usize = 4096;

/// The largest refinement of a tile cell for its corrector.
pub const MAX_CORRECTOR_REFINE: usize = 8;

/// The cover factor the default uptake assumes: the share of a woven cloth's area its
/// yarns hide. Shirtings, sheetings and table linen are woven to cover factors of about
/// 0.85–0.95; 0.92 is a middle value (module doc).
pub const COVER_FACTOR: f64 = 0.92;

/// The uptake of a cell before normalization (see the module doc): 1 for a yarn on the
/// face, 0.9 for a yarn on the back, `max(0, 1 − (1 − C)/a)` for a gap, `a` the share of
/// the tile's cells that are gaps (0.68 in the built-in tiles with gaps, `a = ¼`).
pub fn default_uptake(cell: Cell, gap_share: f64) -> f64 {
    match cell {
        Cell::Warp { up: true } | Cell::Weft { up: true } => 1.0,
        Cell::Warp { up: false } | Cell::Weft { up: false } => 0.9,
        Cell::Gap => (1.0 - (1.0 - COVER_FACTOR) / gap_share).max(0.0),
    }
}

/// The periodic correctors `χ_x`, `χ_y` of a tile and its per-cell uptake (module doc).
#[derive(Debug, Clone, PartialEq)]
pub struct Corrector {
    width: usize,
    height: usize,
    refine: usize,
    tensors: Vec<Tensor2>,
    chi: [Vec<f64>; 2],
    uptake: Vec<f64>,
    moment: [f64; 2],
    threads: [f64; 2],
    upper: Tensor2,
    /// the prefilter's standard deviation in cells (0: none; [`Corrector::filtered`])
    filter: f64,
    /// per patch `(p, q)` of the sample grid (row-major): the bilinear coefficients
    /// `(c0 + c1 t_x) + t_y (c2 + c3 t_x)` of `χ_x` and `χ_y`, interleaved as `[c0x, c0y,
    /// c2x, c2y, c1x, c1y, c3x, c3y]` ([`Sampler::eval`]: one 4-lane expression), and
    /// the uptake of the cell holding it (8): one read per texel, in `f32` (the image's
    /// precision; half the cache of `f64`)
    patches: Vec<[f32; 9]>,
}

/// `⌊x⌋` for `|x| < 2^63` without a library call (`f64::floor` is one on baseline x86-64).
#[inline(always)]
fn floor(x: f64) -> f64 {
    let t = x as i64 as f64;
    if t > x { t - 1.0 } else { t }
}

/// The texel pass's view of a [`Corrector`] (`Corrector::sampler`): the patch table and
/// its grid. The texel pass gives tile coordinates in 64-bit fixed point, as the
/// fraction of the tile (`p / 2^64` along each axis): the tile's periodic wrap is then the
/// integers' own, and the patch and the offset in it are the high and low words of one
/// product by the grid size.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Sampler<'a> {
    patches: &'a [[f32; 9]],
    n: [u64; 2],
    width: usize,
}

/// `2^-24`: the offset in a patch keeps the 24 high bits of its fraction (an `f32`'s
/// precision near 1).
const OFFSET_UNIT: f32 = 1.0 / 16_777_216.0;

impl Sampler<'_> {
    /// The patch holding the tile position `p` (fixed point: `p[i] / 2^64` of the tile
    /// along axis `i`, already wrapped into `[0, 1)` by construction) and the offset in
    /// it: `p · n / 2^64` is the position in samples, its integer part the patch (always
    /// inside the grid: `p < 2^64`) and its fraction the offset, rounded down to a multiple
    /// of `2^-24` (exact in `f32`). No branch, no float-to-integer conversion.
    #[inline(always)]
    pub(crate) fn locate(&self, p: [u64; 2]) -> (usize, f32, f32) {
        let wx = u128::from(p[0]) * u128::from(self.n[0]);
        let wy = u128::from(p[1]) * u128::from(self.n[1]);
        let (ix, iy) = ((wx >> 64) as usize, (wy >> 64) as usize);
        // the offset's top 24 bits: below 2^24, exact through i32 to f32
        let off = |w: u128| ((w as u64) >> 40) as i32 as f32 * OFFSET_UNIT;
        (iy * self.width + ix, off(wx), off(wy))
    }

    /// `((χ_x, χ_y), U)` at offset `(tx, ty)` in patch `i` (from [`Sampler::locate`]): the
    /// patch's bilinear coefficients, evaluated in `f32`.
    #[inline(always)]
    pub(crate) fn eval(&self, i: usize, tx: f32, ty: f32) -> ([f32; 2], f32) {
        // `i` comes from `locate`, within the grid
        let c = &self.patches[i];
        // [c0 + c1 t_x, c2 + c3 t_x] for χ_x and χ_y at once, then along t_y
        let mut w = [0.0f32; 4];
        for l in 0..4 {
            w[l] = c[l] + tx * c[4 + l];
        }
        ([w[0] + ty * w[2], w[1] + ty * w[3]], c[8])
    }
}

impl Corrector {
    /// The corrector of the `width × height` tile with per-cell tensors `tensors` and
    /// uptake factors `uptake` (both row-major, row 0 at the bottom; the uptake is
    /// normalized to mean 1), `threads` threads per tile along `x` (weft) and `y` (warp).
    /// Errors: a bad tile (as [`super::homogenize()`]), an uptake that is not finite and
    /// ≥ 0 with a positive mean, threads that are not finite and positive.
    pub fn new(
        width: usize,
        height: usize,
        tensors: &[Tensor2],
        uptake: &[f64],
        threads: [f64; 2],
    ) -> Result<Corrector, WeaveError> {
        check_tile(width, height, tensors)?;
        let option = |name, requirement, value| WeaveError::Option {
            name,
            requirement,
            value,
        };
        if uptake.len() != tensors.len() {
            return Err(option("uptake", "one factor per cell", uptake.len() as f64));
        }
        if let Some(&u) = uptake.iter().find(|u| !(u.is_finite() && **u >= 0.0)) {
            return Err(option("uptake", "finite and ≥ 0", u));
        }
        let mean = uptake.iter().sum::<f64>() / uptake.len() as f64;
        if mean.is_nan() || mean <= 0.0 {
            return Err(option("uptake", "of positive mean", mean));
        }
        if let Some(&t) = threads.iter().find(|t| !(t.is_finite() && **t > 0.0)) {
            return Err(option("threads", "finite and > 0", t));
        }
        let r = ((CORRECTOR_SAMPLES / (width * height)) as f64)
            .sqrt()
            .floor()
            .clamp(1.0, MAX_CORRECTOR_REFINE as f64) as usize;
        let (gw, gh) = (width * r, height * r);
        let fine = refine(width, height, tensors, r)?;
        let k = scale_exponent(&fine);
        let (upper, mut chi) = Grid::shared(gw, gh)?.solve_scaled(&fine, k)?;
        // the solve's unit is the refined grid's cell: χ in tile cells is χ_grid / r
        for c in &mut chi {
            let m = c.iter().sum::<f64>() / c.len() as f64;
            c.iter_mut().for_each(|v| *v = (*v - m) / r as f64);
        }
        let uptake: Vec<f64> = uptake.iter().map(|u| u / mean).collect();
        // m = ⟨(U − 1) y⟩: cell (i, j) has mean position (i + ½, j + ½)
        let mut moment = [0.0; 2];
        for (c, u) in uptake.iter().enumerate() {
            let (i, j) = ((c % width) as f64, (c / width) as f64);
            moment[0] += (u - 1.0) * (i + 0.5);
            moment[1] += (u - 1.0) * (j + 0.5);
        }
        let n = uptake.len() as f64;
        let patches = patch_table(&chi, gw, gh, |v| {
            uptake[(v / gw / r) * width + (v % gw) / r]
        });
        Ok(Corrector {
            patches,
            width,
            height,
            refine: r,
            tensors: fine,
            chi,
            uptake,
            moment: moment.map(|m| m / n),
            threads,
            upper: tensor::scale(upper, k),
            filter: 0.0,
        })
    }

    /// This corrector convolved with a periodic Gaussian of standard deviation `sigma`
    /// cells (module doc, "Prefiltering"): `χ` at its corner samples and the uptake per
    /// patch of the sample grid, the moment recomputed over the patches. `sigma = 0`
    /// returns the corrector as it is. Errors: `sigma` not finite and ≥ 0.
    pub fn filtered(&self, sigma: f64) -> Result<Corrector, WeaveError> {
        if !(sigma.is_finite() && sigma >= 0.0) {
            return Err(WeaveError::Option {
                name: "filter",
                requirement: "finite and ≥ 0 (cells)",
                value: sigma,
            });
        }
        if sigma == 0.0 {
            return Ok(self.clone());
        }
        let r = self.refine;
        let (gw, gh) = (self.width * r, self.height * r);
        let kx = gaussian(sigma * r as f64, gw);
        let ky = gaussian(sigma * r as f64, gh);
        let chi = self.chi.clone().map(|c| blur(&c, gw, gh, &kx, &ky));
        let cells: Vec<f64> = (0..gw * gh)
            .map(|v| self.uptake[(v / gw / r) * self.width + (v % gw) / r])
            .collect();
        let patch = blur(&cells, gw, gh, &kx, &ky);
        // m over the patches: patch (p, q) has its centre at ((p + ½)/r, (q + ½)/r)
        let mut moment = [0.0; 2];
        for (v, u) in patch.iter().enumerate() {
            moment[0] += (u - 1.0) * ((v % gw) as f64 + 0.5) / r as f64;
            moment[1] += (u - 1.0) * ((v / gw) as f64 + 0.5) / r as f64;
        }
        Ok(Corrector {
            patches: patch_table(&chi, gw, gh, |v| patch[v]),
            chi,
            moment: moment.map(|m| m / (gw * gh) as f64),
            filter: sigma,
            tensors: self.tensors.clone(),
            uptake: self.uptake.clone(),
            ..*self
        })
    }

    /// The uptake the texture reads in patch `v = q (w r) + p` of the sample grid (the
    /// cell's factor, or the prefiltered value, [`Corrector::filtered`]), as stored (`f32`).
    pub fn uptake_of_patch(&self, v: usize) -> f64 {
        f64::from(self.patches[v][8])
    }

    /// The prefilter's standard deviation in cells ([`Corrector::filtered`]; 0: none).
    pub fn filter(&self) -> f64 {
        self.filter
    }

    /// The corrector of a weave tile with the tensors of `coefficients` and the
    /// [`default_uptake`]; `threads` as in [`Corrector::new`].
    pub fn of_tile(
        tile: &Tile,
        coefficients: &PairCoefficients,
        threads: [f64; 2],
    ) -> Result<Corrector, WeaveError> {
        let tensors = cell_tensors(tile, coefficients)?;
        let cells = tile.cells();
        let gap_share =
            cells.iter().filter(|&&c| c == Cell::Gap).count() as f64 / cells.len() as f64;
        let uptake: Vec<f64> = cells
            .iter()
            .map(|&c| default_uptake(c, gap_share))
            .collect();
        Corrector::new(tile.width(), tile.height(), &tensors, &uptake, threads)
    }

    /// Tile width and height in cells.
    pub fn cells(&self) -> (usize, usize) {
        (self.width, self.height)
    }

    /// Threads per tile along the weft (`x`) and the warp (`y`).
    pub fn threads(&self) -> [f64; 2] {
        self.threads
    }

    /// Corrector samples per cell side.
    pub fn refine(&self) -> usize {
        self.refine
    }

    /// `χ_x` (`i = 0`) or `χ_y` (`i = 1`), in tile cells, at the `(w r) × (h r)` corner
    /// vertices, row-major,
    /// row 0 at the bottom; vertex `(p, q)` sits at the tile coordinate `(p / r, q / r)`.
    pub fn samples(&self, i: usize) -> &[f64] {
        &self.chi[i]
    }

    /// The per-cell uptake factors (mean 1), row-major, row 0 at the bottom.
    pub fn uptake(&self) -> &[f64] {
        &self.uptake
    }

    /// The uptake's first moment `m = ⟨(U − 1) y⟩` in cells.
    pub fn moment(&self) -> [f64; 2] {
        self.moment
    }

    /// `(χ_x, χ_y)` at tile coordinate `y` (in cells, any value: the tile repeats),
    /// bilinear between the corner samples (in `f64`; the texture reads the same function
    /// rounded to `f32`).
    pub fn chi(&self, y: [f64; 2]) -> [f64; 2] {
        let (gw, gh) = (self.width * self.refine, self.height * self.refine);
        let r = self.refine as f64;
        let g = [y[0] * r, y[1] * r];
        let (fx, fy) = (floor(g[0]), floor(g[1]));
        let (tx, ty) = (g[0] - fx, g[1] - fy);
        let x0 = (fx as i64).rem_euclid(gw as i64) as usize;
        let y0 = (fy as i64).rem_euclid(gh as i64) as usize;
        let (x1, y1) = ((x0 + 1) % gw, (y0 + 1) % gh);
        [0, 1].map(|i| {
            let at = |x: usize, y: usize| self.chi[i][y * gw + x];
            let bottom = at(x0, y0) + tx * (at(x1, y0) - at(x0, y0));
            let top = at(x0, y1) + tx * (at(x1, y1) - at(x0, y1));
            bottom + ty * (top - bottom)
        })
    }

    /// The texel pass's view of the corrector ([`Sampler`]).
    pub(crate) fn sampler(&self) -> Sampler<'_> {
        let (gw, gh) = (self.width * self.refine, self.height * self.refine);
        Sampler {
            patches: &self.patches,
            n: [gw as u64, gh as u64],
            width: gw,
        }
    }

    /// The uptake factor of the cell holding tile coordinate `y` (cells, periodic): the
    /// unfiltered per-cell factor, also on a [`Corrector::filtered`] one (what its texels
    /// read is [`Corrector::uptake_of_patch`]).
    #[inline]
    pub fn uptake_at(&self, y: [f64; 2]) -> f64 {
        let i = (y[0].floor() as i64).rem_euclid(self.width as i64) as usize;
        let j = (y[1].floor() as i64).rem_euclid(self.height as i64) as usize;
        self.uptake[j * self.width + i]
    }

    /// `⟨(e_i + ∇χ_i)ᵀ a (e_j + ∇χ_j)⟩` evaluated from the stored corrector (P1 on the
    /// refined tile's criss-cross mesh): the primal effective tensor of that discretization.
    pub fn energy(&self) -> Tensor2 {
        let (gw, gh) = (self.width * self.refine, self.height * self.refine);
        let r = self.refine as f64;
        let chi = self
            .chi
            .clone()
            .map(|c| c.into_iter().map(|v| v * r).collect());
        corrector_energy(gw, gh, &self.tensors, &chi)
    }

    /// The effective tensor the solve itself reported (the same quantity as
    /// [`Corrector::energy`], evaluated on the unshifted corrector, scaled).
    pub fn upper(&self) -> Tensor2 {
        self.upper
    }
}

/// The texel pass's table: per patch `v = q gw + p` of the periodic `gw × gh` sample grid,
/// the bilinear coefficients of `χ_x` and `χ_y` between its four corners, interleaved as
/// [`Corrector`]'s `patches` says, and its uptake `uptake(v)` (8), in `f32`.
fn patch_table(
    chi: &[Vec<f64>; 2],
    gw: usize,
    gh: usize,
    uptake: impl Fn(usize) -> f64,
) -> Vec<[f32; 9]> {
    (0..gw * gh)
        .map(|v| {
            let (p, q) = (v % gw, v / gw);
            let (p1, q1) = ((p + 1) % gw, (q + 1) % gh);
            let mut c = [0.0f32; 9];
            for (i, x) in chi.iter().enumerate() {
                let [v00, v10, v01, v11] =
                    [q * gw + p, q * gw + p1, q1 * gw + p, q1 * gw + p1].map(|k| x[k]);
                let b = [v00, v10 - v00, v01 - v00, v11 - v10 - v01 + v00];
                // c0 → 0, c1 → 4, c2 → 2, c3 → 6; χ_x, χ_y side by side
                for (slot, v) in [0, 4, 2, 6].into_iter().zip(b) {
                    c[slot + i] = v as f32;
                }
            }
            c[8] = uptake(v) as f32;
            c
        })
        .collect()
}

/// The periodic Gaussian of standard deviation `sigma` samples on a ring of `n` samples,
/// folded onto it (weights per offset `0..n`, summing to 1): `exp(−d²/2σ²)` over the
/// offsets `d` within 4σ (and at least one period), each added at `d mod n`.
fn gaussian(sigma: f64, n: usize) -> Vec<f64> {
    let reach = (4.0 * sigma).ceil().max(n as f64) as i64;
    let mut w = vec![0.0; n];
    for d in -reach..=reach {
        w[d.rem_euclid(n as i64) as usize] += (-(d * d) as f64 / (2.0 * sigma * sigma)).exp();
    }
    let total: f64 = w.iter().sum();
    w.iter_mut().for_each(|v| *v /= total);
    w
}

/// `f` on the periodic `gw × gh` grid (row-major) convolved with the folded kernels `kx`
/// along rows and `ky` along columns ([`gaussian`]).
fn blur(f: &[f64], gw: usize, gh: usize, kx: &[f64], ky: &[f64]) -> Vec<f64> {
    let mut rows = vec![0.0; gw * gh];
    for q in 0..gh {
        for p in 0..gw {
            rows[q * gw + p] = (0..gw).map(|d| kx[d] * f[q * gw + (p + d) % gw]).sum();
        }
    }
    let mut out = vec![0.0; gw * gh];
    for q in 0..gh {
        for p in 0..gw {
            out[q * gw + p] = (0..gh).map(|d| ky[d] * rows[((q + d) % gh) * gw + p]).sum();
        }
    }
    out
}

/// [`Corrector::of_tile`] through a process-wide cache of the 16 most recent tiles (keyed
/// by a hash of the tile, the coefficients and the threads, as [`super::cache`]).
pub fn corrector_cached(
    tile: &Tile,
    coefficients: &PairCoefficients,
    threads: [f64; 2],
) -> Result<Arc<Corrector>, WeaveError> {
    type Entries = VecDeque<(u128, Arc<Corrector>)>;
    static CACHE: OnceLock<Mutex<Entries>> = OnceLock::new();
    let cache = CACHE.get_or_init(Default::default);
    let lock = || cache.lock().unwrap_or_else(|e| e.into_inner());
    let tensors = cell_tensors(tile, coefficients)?;
    let hash = |salt: u64| {
        let mut s = DefaultHasher::new();
        (salt, tile).hash(&mut s);
        for &t in &tensors {
            bits(t).hash(&mut s);
        }
        threads.map(|t| (t + 0.0).to_bits()).hash(&mut s);
        s.finish()
    };
    let key = ((hash(0x636f_7272) as u128) << 64) | hash(0x0063_6869) as u128;
    if let Some((_, c)) = lock().iter().find(|(k, _)| *k == key) {
        return Ok(c.clone());
    }
    let c = Arc::new(Corrector::of_tile(tile, coefficients, threads)?);
    let mut l = lock();
    l.push_front((key, c.clone()));
    l.truncate(16);
    Ok(c)
}
