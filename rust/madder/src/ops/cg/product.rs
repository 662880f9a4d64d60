//! The product `y = A x` of the full symmetric matrix, as faer's matrix-free CG applies it.
//!
//! The product is our own ([`SymOp`]): the matrix being symmetric, its compressed columns
//! are also its rows, and each output entry is gathered along its row,
//! `y_i = Σ_k a_ik x_k` in increasing `k` — the order in which faer's compressed-column
//! product accumulates `y_i` (column after column), so the result is the same to the last
//! bit, without the scatter and with 32-bit indices (faster).

use faer::dyn_stack::{MemStack, StackReq};
use faer::matrix_free::LinOp;
use faer::{MatMut, MatRef, Par};

/// The full symmetric matrix, compressed by columns, which are also its rows: the
/// product gathers every output entry along its row (see the module doc).
#[derive(Debug, Clone, Copy)]
pub(super) struct SymOp<'a> {
    pub(super) ptr: &'a [u32],
    pub(super) idx: &'a [u32],
    pub(super) val: &'a [f64],
}

impl SymOp<'_> {
    /// `y = A x`, each `y_i` summed in increasing column order from `0`.
    pub(super) fn gather(&self, x: &[f64], y: &mut [f64]) {
        for (i, yi) in y.iter_mut().enumerate() {
            let (lo, hi) = (self.ptr[i] as usize, self.ptr[i + 1] as usize);
            let mut acc = 0.0;
            for (a, &k) in self.val[lo..hi].iter().zip(&self.idx[lo..hi]) {
                acc += a * x[k as usize];
            }
            *yi = acc;
        }
    }
}

/// `out = f(rhs)` column by column for the `n × n` matrix-free operators below, `f`
/// writing one contiguous column (`x` into `y`).
pub(super) fn by_columns(
    n: usize,
    mut out: MatMut<'_, f64>,
    rhs: MatRef<'_, f64>,
    f: impl Fn(&[f64], &mut [f64]),
) {
    assert!(out.nrows() == n && rhs.nrows() == n && out.ncols() == rhs.ncols());
    for j in 0..rhs.ncols() {
        let x = rhs.col(j);
        let mut y = out.as_mut().col_mut(j);
        if let (Some(x), Some(y)) = (x.try_as_col_major(), y.as_mut().try_as_col_major_mut()) {
            f(x.as_slice(), y.as_slice_mut());
            continue;
        }
        // strided columns (the CG does not make them): through contiguous copies
        let xs: Vec<f64> = x.iter().copied().collect();
        let mut ys = vec![0.0; n];
        f(&xs, &mut ys);
        y.iter_mut().zip(ys).for_each(|(o, v)| *o = v);
    }
}

impl LinOp<f64> for SymOp<'_> {
    fn apply_scratch(&self, _rhs_ncols: usize, _par: Par) -> StackReq {
        StackReq::EMPTY
    }

    fn nrows(&self) -> usize {
        self.ptr.len() - 1
    }

    fn ncols(&self) -> usize {
        self.ptr.len() - 1
    }

    fn apply(&self, out: MatMut<'_, f64>, rhs: MatRef<'_, f64>, _par: Par, _: &mut MemStack) {
        by_columns(self.nrows(), out, rhs, |x, y| self.gather(x, y));
    }

    fn conj_apply(&self, out: MatMut<'_, f64>, rhs: MatRef<'_, f64>, par: Par, s: &mut MemStack) {
        self.apply(out, rhs, par, s);
    }
}
