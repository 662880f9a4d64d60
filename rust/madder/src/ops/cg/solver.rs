//! [`WarmCg`]: the solver's state (its pattern, factor, values and work space), its
//! tolerance and preconditioner, and what the solves share (errors, work space).
//! Built by `pattern.rs`, solved by `solve.rs` and `rotated.rs`.

use faer::dyn_stack::{MemBuffer, StackReq};
use faer::matrix_free::LinOp;
use faer::matrix_free::conjugate_gradient::{CgError, conjugate_gradient_scratch};
use faer::{Col, Par};

use super::precond::Preconditioner;
use crate::error::SolveError;

/// `v` emptied and refilled with `len` copies of `value`, in the memory it holds.
pub(super) fn refill<T: Copy>(mut v: Vec<T>, len: usize, value: T) -> Vec<T> {
    v.clear();
    v.resize(len, value);
    v
}

/// Default relative residual tolerance. Mass is conserved by the system up to the
/// residual (`1ᵀ(M + hK) = 1ᵀM`), and the stepper restores it exactly afterwards, so the
/// tolerance only sets how accurately the *profile* is resolved; callers choose it per
/// system ([`WarmCg::with_tolerance`]).
pub(crate) const RELATIVE_TOLERANCE: f64 = 1e-12;

/// Iteration cap: a solve that has not converged after this many iterations is an error
/// (the matrix was not positive definite, or the data was not finite).
pub(crate) const MAX_ITERATIONS: usize = 2000;

/// A symmetric positive definite system on a fixed pattern, solved by warm-started
/// CG preconditioned by IC(0) (overview in the `cg` module doc).
pub struct WarmCg {
    pub(super) n: usize,
    /// The full symmetric pattern, compressed by columns (= by rows).
    pub(super) col_ptr: Vec<u32>,
    pub(super) row_idx: Vec<u32>,
    /// For each entry of the full matrix, its slot in the lower-triangle values.
    pub(super) slot: Vec<u32>,
    /// Slot of each diagonal entry in the lower-triangle values.
    pub(super) diag: Vec<u32>,
    pub(super) full: Vec<f64>,
    /// The strict lower triangle, compressed by columns with increasing rows: the pattern
    /// of the incomplete factor `L̃` (see `Factor`); `l_slot` is each entry's slot in the
    /// lower-triangle values.
    pub(super) l_ptr: Vec<u32>,
    pub(super) l_row: Vec<u32>,
    pub(super) l_slot: Vec<u32>,
    /// IC(0) updates of the off-diagonal entries, per eliminated column `k`
    /// (`upd_ptr[k]..upd_ptr[k + 1]`): `l[t] -= l[p] l[q] / d_k` for `[t, p, q]`, the
    /// positions in `l_row` of `(i, j)`, `(i, k)` and `(j, k)`, `i > j > k`, when `(i, j)`
    /// is in the pattern.
    pub(super) upd_ptr: Vec<u32>,
    pub(super) upd: Vec<[u32; 3]>,
    /// The strict lower triangle by rows (`u_col` increasing in each row), `u_pos` each
    /// entry's position in `l_row`: the forward sweep gathers along rows.
    pub(super) u_ptr: Vec<u32>,
    pub(super) u_col: Vec<u32>,
    pub(super) u_pos: Vec<u32>,
    pub(super) u_val: Vec<f64>,
    /// Whether the factor's pattern and IC(0)'s updates above are this pattern's: left
    /// for later when the preconditioner is not IC(0) (the rotated solve never needs
    /// them; a scalar solve analyses first).
    pub(super) analyzed: bool,
    /// The factor's values, rebuilt every solve: `l` on `l_row`, and `D̃⁻¹`.
    pub(super) l_val: Vec<f64>,
    pub(super) inv_d: Vec<f64>,
    /// `diag(A)⁻¹`: the Jacobi preconditioner, and the fallback.
    pub(super) inv_diag: Vec<f64>,
    pub(super) precond: Preconditioner,
    /// Diagonal shift the last IC(0) factorization needed (`0` if none; `NaN` if it fell
    /// back to Jacobi).
    pub(super) last_shift: f64,
    /// The rotated product's two values per full entry ([`WarmCg::solve_rotated`]).
    pub(super) rotated: Vec<[f64; 2]>,
    /// The same per lower-triangle entry.
    pub(super) rotated_lower: Vec<[f64; 2]>,
    /// One workspace per right-hand side column.
    pub(super) scratch: Vec<MemBuffer>,
    /// The system size and kind (rotated or not) `scratch` was made for.
    pub(super) scratch_for: (usize, bool),
    pub(super) tolerance: f64,
    /// Iterations of the last solve, summed over its columns.
    pub last_iterations: usize,
}

impl std::fmt::Debug for WarmCg {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("WarmCg")
            .field("n", &self.n)
            .field("nnz", &self.slot.len())
            .finish_non_exhaustive()
    }
}

impl WarmCg {
    /// The same solver stopping at relative residual `tolerance` (clamped to
    /// `[1e-14, 1e-4]`).
    pub fn with_tolerance(mut self, tolerance: f64) -> Self {
        self.tolerance = tolerance.clamp(1e-14, 1e-4);
        self
    }

    /// Sets the relative residual tolerance (clamped as in [`Self::with_tolerance`]).
    pub fn set_tolerance(&mut self, tolerance: f64) {
        self.tolerance = tolerance.clamp(1e-14, 1e-4);
    }

    /// The same solver with another preconditioner: for benchmarks and tests that compare
    /// them (`precond.rs`); the default is the fastest measured.
    #[doc(hidden)]
    pub fn with_preconditioner(mut self, precond: Preconditioner) -> Self {
        self.precond = precond;
        self
    }

    /// Keeps the CG work space if it was made for systems of at least `size` unknowns of
    /// the same kind (`rotated`: [`Self::solve_rotated`]'s), else drops it to be made
    /// anew. Kept across [`Self::rebuild`]: fresh work space is fresh pages, faulted in
    /// at every window (issue 16); its contents are never read before written.
    pub(super) fn fit_scratch(&mut self, size: usize, rotated: bool) {
        if self.scratch_for.0 < size || self.scratch_for.1 != rotated {
            self.scratch.clear();
            self.scratch_for = (size, rotated);
        }
    }
}

pub(super) fn cg_error(n: usize) -> impl Fn(CgError<f64>) -> SolveError {
    move |e| match e {
        CgError::NoConvergence { rel_residual, .. } => SolveError::NotConverged {
            iterations: MAX_ITERATIONS,
            residual: rel_residual,
        },
        // CG only sees a non-positive curvature, not where: no pivot to name
        _ => SolveError::NotPositiveDefinite { pivot: 0, n },
    }
}

pub(super) fn cg_scratch(a: impl LinOp<f64>, n: usize) -> StackReq {
    let d = Col::<f64>::zeros(n);
    conjugate_gradient_scratch(d.as_ref().as_diagonal(), a, 1, Par::Seq)
}
