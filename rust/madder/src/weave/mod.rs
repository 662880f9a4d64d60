//! Weave patterns and their homogenization (seed chapter 2).
//!
//! A fabric diffuses liquid faster along its yarns than across them, and the pattern of
//! yarns repeats at a scale far below a cloth mesh's triangles. Seed §2.2 replaces the
//! rapidly varying diffusion tensor of eq. 2.1 by one constant effective tensor per fabric
//! (eq. 2.2), computed once from a periodic tile of the weave:
//!
//! 1. [`pattern`] (§2.2.1): a [`Tile`] of [`Cell`]s (warp/weft up/down, gap) — built in
//!    ([`Weave`]), parsed from a text grid, or given cell by cell — and the per-cell tensors
//!    `S = ½[D_left + D_right, 0; 0, D_top + D_bottom]` from a table of pair coefficients
//!    ([`PairCoefficients`], default the seed's). Users may also give per-cell tensors
//!    directly.
//! 2. [`cell_problem`] (eq. 2.4): periodic P1 finite elements on the tile as a torus,
//!    giving rigorous upper and lower bounds on the effective tensor.
//! 3. [`homogenize()`] (eq. 2.3): reduction of the tile, choice of discretization levels and
//!    the primal–dual extrapolation that turns the bounds into one estimate; [`cache`]
//!    memoizes it.
//! 4. [`corrector`](mod@corrector): the cell problem's correctors `χ` kept (not thrown
//!    away after the tensor), with a per-cell uptake, so the texture can add the weave's
//!    fine scale back to the homogenized stain (`σ0 + ε χ(x/ε)·∇σ0`, [`crate::texture`]).
//!
//! **Orientation.** The tile's `x` axis is the weft direction (texture `u`), `y` the warp
//! direction (`v`); cells are row-major with row 0 at the bottom. Tensors are `[s11, s12,
//! s22]` in that (weft, warp) basis.
//!
//! ```
//! use madder::weave::{PairCoefficients, Tile, Weave, cell_tensors, ellipse, homogenize};
//! let tile = Tile::builtin(Weave::Twill21, true);
//! let s = cell_tensors(&tile, &PairCoefficients::default()).unwrap();
//! let a = homogenize(tile.width(), tile.height(), &s).unwrap();
//! let (ratio, angle) = ellipse(a);
//! assert!(ratio > 1.0 && angle.abs() <= std::f64::consts::FRAC_PI_2);
//! ```

pub(crate) mod cache;
pub(crate) mod cell_problem;
pub(crate) mod check;
pub(crate) mod corrector;
pub mod homogenize;
pub(crate) mod pattern;
pub mod tensor;

pub use cache::{HomogenizationCache, homogenize_cached};
pub use cell_problem::{Bounds, Grid};
pub use corrector::{
    CORRECTOR_SAMPLES, COVER_FACTOR, Corrector, MAX_CORRECTOR_REFINE, corrector_cached,
    default_uptake,
};
pub use homogenize::{
    HomogenizeOptions, Homogenized, Level, MAX_CONTRAST, Method, homogenize, homogenize_report,
    homogenize_with,
};
pub use pattern::{Cell, PairCoefficients, Tile, Weave, cell_tensors};

pub use crate::error::WeaveError;

/// A symmetric 2×2 tensor `[s11, s12, s22]` in a (weft, warp) basis: the tile's here, a
/// face's once the homogenized tensor is laid on the cloth ([`crate::ops::aniso`]).
pub type Tensor2 = [f64; 3];

/// The diffusion ellipse of a tensor, for display: `(λ_max / λ_min, θ)` with `θ ∈ (−π/2,
/// π/2]` the angle of the major axis from the weft (`x`) axis, counter-clockwise towards the
/// warp. A tensor that is isotropic to within 10⁻¹⁰ (relative; a homogenized symmetric
/// weave is isotropic only up to rounding, and its axis would be noise) gives the angle 0;
/// a tensor that is not positive definite gives an infinite ratio.
pub fn ellipse(t: Tensor2) -> (f64, f64) {
    let (lo, hi) = tensor::eigenvalues(t);
    let ratio = if lo > 0.0 { hi / lo } else { f64::INFINITY };
    if hi - lo <= 1e-10 * hi.abs() {
        return (ratio, 0.0);
    }
    let mut angle = 0.5 * (2.0 * t[1]).atan2(t[0] - t[2]);
    if angle <= -std::f64::consts::FRAC_PI_2 {
        angle += std::f64::consts::PI;
    }
    (ratio, angle)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::{FRAC_PI_2, FRAC_PI_4};

    #[test]
    fn ellipse_of_known_tensors() {
        assert_eq!(ellipse([2.0, 0.0, 2.0]), (1.0, 0.0));
        assert_eq!(ellipse([4.0, 0.0, 1.0]), (4.0, 0.0));
        let (r, a) = ellipse([1.0, 0.0, 4.0]);
        assert_eq!(r, 4.0);
        assert!((a - FRAC_PI_2).abs() < 1e-15);
        // diag(3, 1) rotated by +45°: [2, 1, 2]
        let (r, a) = ellipse([2.0, 1.0, 2.0]);
        assert!((r - 3.0).abs() < 1e-14 && (a - FRAC_PI_4).abs() < 1e-15);
        let (r, a) = ellipse([2.0, -1.0, 2.0]);
        assert!((r - 3.0).abs() < 1e-14 && (a + FRAC_PI_4).abs() < 1e-15);
        assert_eq!(ellipse([1.0, 2.0, 1.0]).0, f64::INFINITY);
        // isotropic up to rounding: no axis
        assert_eq!(ellipse([371.6, 1e-14, 371.6 + 1e-13]).1, 0.0);
    }
}
