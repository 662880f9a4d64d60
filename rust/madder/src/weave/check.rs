//! Checks of a tile's per-cell tensors (dimensions, positive definiteness, contrast) and
//! the power-of-two scale every solve on a tile runs at: what the cell problem, the
//! homogenization and the correctors check first (see "Scaling and contrast" in
//! [`homogenize`](mod@super::homogenize)).

use super::{Tensor2, tensor};
use crate::error::WeaveError;

/// Largest ratio of the largest to the smallest eigenvalue over a tile.
pub const MAX_CONTRAST: f64 = 1e12;

/// Checks a per-cell tensor field: dimensions, and every tensor finite and SPD at any
/// magnitude ([`tensor::is_spd`]); the error names the first bad cell.
pub(crate) fn check_cells(
    width: usize,
    height: usize,
    tensors: &[Tensor2],
) -> Result<(), WeaveError> {
    check_count(width, height, tensors.len())?;
    match tensors.iter().position(|&t| !tensor::is_spd(t)) {
        None => Ok(()),
        Some(i) => {
            let [s11, s12, s22] = tensors[i];
            Err(WeaveError::NotPositiveDefinite {
                row: i / width,
                col: i % width,
                s11,
                s12,
                s22,
            })
        }
    }
}

/// A `width × height` tile must be non-empty and have `width · height` cells.
pub(crate) fn check_count(width: usize, height: usize, got: usize) -> Result<(), WeaveError> {
    if width == 0 || height == 0 {
        return Err(WeaveError::EmptyTile);
    }
    let expected = width.saturating_mul(height);
    if got != expected {
        return Err(WeaveError::CellCount {
            width,
            height,
            expected,
            got,
        });
    }
    Ok(())
}

/// [`check_cells`], then the contrast (largest over smallest eigenvalue over the tile) and
/// the cell with the smallest eigenvalue.
/// [`check_tensors`], and the tile's contrast within [`MAX_CONTRAST`] (the error names
/// the weakest cell): what every solve on a tile needs.
pub(crate) fn check_tile(
    width: usize,
    height: usize,
    tensors: &[Tensor2],
) -> Result<(), WeaveError> {
    let (contrast, weakest) = check_tensors(width, height, tensors)?;
    if contrast > MAX_CONTRAST {
        return Err(WeaveError::Contrast {
            ratio: contrast,
            limit: MAX_CONTRAST,
            row: weakest / width,
            col: weakest % width,
        });
    }
    Ok(())
}

pub(crate) fn check_tensors(
    width: usize,
    height: usize,
    tensors: &[Tensor2],
) -> Result<(f64, usize), WeaveError> {
    check_cells(width, height, tensors)?;
    let (mut lo, mut hi, mut at) = (f64::INFINITY, 0.0f64, 0);
    for (i, &t) in tensors.iter().enumerate() {
        let (l, h) = tensor::eigenvalues_at_any_scale(t);
        if l < lo {
            (lo, at) = (l, i);
        }
        hi = hi.max(h);
    }
    Ok((hi / lo, at))
}

/// The power of two that brings a tile's largest diagonal entry into `[1, 2)`, as its
/// exponent (see "Scaling and contrast" in the module doc).
pub(crate) fn scale_exponent(tensors: &[Tensor2]) -> i32 {
    tensor::exponent(tensors.iter().fold(0.0f64, |m, t| m.max(t[0]).max(t[2])))
}
