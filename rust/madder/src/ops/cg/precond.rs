//! The preconditioners of [`WarmCg`](super::WarmCg) and their sweeps `y = M⁻¹ r`
//! (their factor is built in `factor.rs`).
//!
//! ## Preconditioner: IC(0)
//! Writing `A = L + D + Lᵀ` (`L` strictly lower), the preconditioner is
//! `M = (I + L̃) D̃ (I + L̃)ᵀ` with `L̃` strictly lower on the pattern of `L` (`Factor`);
//! `M⁻¹ r` is a forward sweep (gathered along the rows of `L̃`), a scaling by `D̃⁻¹` and
//! a backward sweep (gathered along its columns), sequential, in a fixed order, through
//! faer's [`Precond`] trait. Three choices of `(L̃, D̃)` are implemented
//! ([`WarmCg::with_preconditioner`], hidden, for the benchmark and the tests):
//! - Jacobi: `L̃ = 0`, `D̃ = D`.
//! - symmetric Gauss–Seidel: `L̃ = L D⁻¹`, `D̃ = D` (no setup beyond a scaling).
//! - IC(0), the default: the incomplete `LDLᵀ` factor that keeps only the pattern's
//!   entries, `d_k = a_kk − Σ_{j<k} l̃_kj² d_j`, `l̃_ik = (a_ik − Σ_{j<k} l̃_ij l̃_kj d_j) / d_k`
//!   for `(i, k)` in the pattern. The updates `(i, j) ← (i, k)(j, k)` that stay in the
//!   pattern are listed once in [`WarmCg::new`], so refactoring every solve (the values
//!   change every sub-step) is one pass over them, about the cost of one Jacobi-CG
//!   iteration. A pivot `d_k ≤ 10⁻⁸ a_kk` (possible when `A` is not an M-matrix: obtuse
//!   triangles, anisotropy) restarts the factorization of `A + α diag(A)`, `α = 10⁻²`
//!   then `10⁻¹` (Manteuffel's shift), then falls back to Jacobi; and a column the
//!   factor fails to converge is solved again with Jacobi from the same warm start, so
//!   nothing Jacobi solves fails. The factor is built once per [`WarmCg::solve`], before
//!   the columns, which only read it. On the Bochner system the 2×2 diagonal blocks are
//!   diagonal (`(M_jj + h K_jj) I₂`, see [`crate::ops::bochner`]): block-Jacobi *is*
//!   Jacobi there, so the same IC(0) is used on the block pattern.
//!
//! IC(0) divides the iterations by about three, but an iteration costs more than two
//! Jacobi ones (its two sweeps are latency-bound), so it wins on wall time by less, and by
//! more as the system gets stiffer (`h D / Δx²`); symmetric Gauss–Seidel needs no
//! factorization and comes out about level. IC(0) is kept for its fewer iterations.
//!
//! [`WarmCg::with_preconditioner`]: super::WarmCg::with_preconditioner
//! [`WarmCg::new`]: super::WarmCg::new
//! [`WarmCg::solve`]: super::WarmCg::solve

use faer::dyn_stack::{MemStack, StackReq};
use faer::matrix_free::{LinOp, Precond};
use faer::{MatMut, MatRef, Par};

use super::product::by_columns;

/// faer's preconditioner traits for a sweep type with `inv_d` (one entry per unknown) and
/// `solve(x, y)` (`y = M⁻¹ x`, one column): the CG applies it out of place, column by
/// column; in place goes through faer's default copy.
macro_rules! sweep_preconditioner {
    ($t:ident) => {
        impl LinOp<f64> for $t<'_> {
            fn apply_scratch(&self, _rhs_ncols: usize, _par: Par) -> StackReq {
                StackReq::EMPTY
            }

            fn nrows(&self) -> usize {
                self.inv_d.len()
            }

            fn ncols(&self) -> usize {
                self.inv_d.len()
            }

            fn apply(
                &self,
                out: MatMut<'_, f64>,
                rhs: MatRef<'_, f64>,
                _par: Par,
                _: &mut MemStack,
            ) {
                by_columns(self.nrows(), out, rhs, |x, y| self.solve(x, y));
            }

            fn conj_apply(
                &self,
                out: MatMut<'_, f64>,
                rhs: MatRef<'_, f64>,
                par: Par,
                s: &mut MemStack,
            ) {
                self.apply(out, rhs, par, s);
            }
        }

        impl Precond<f64> for $t<'_> {}
    };
}
pub(super) use sweep_preconditioner;

/// The preconditioner of [`WarmCg`] (module doc).
#[doc(hidden)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Preconditioner {
    /// `diag(A)⁻¹`.
    Jacobi,
    /// `(D + L) D⁻¹ (D + L)ᵀ` with `A = L + D + Lᵀ`.
    SymmetricGaussSeidel,
    /// IC(0): `(I + L̃) D̃ (I + L̃)ᵀ` with `L̃` on the strict lower pattern of `A`.
    IncompleteCholesky,
}

/// `M⁻¹` for `M = (I + L̃) D̃ (I + L̃)ᵀ`, `L̃` strictly lower on the pattern, compressed
/// by columns: `y = M⁻¹ r` is a forward sweep, a scaling and a backward sweep, in a fixed
/// order. With no `L̃` values, Jacobi (`D̃⁻¹ = diag(A)⁻¹`).
#[derive(Debug, Clone, Copy)]
pub(super) struct Factor<'a> {
    pub(super) ptr: &'a [u32],
    pub(super) row: &'a [u32],
    pub(super) l: &'a [f64],
    /// `L̃` again, by rows.
    pub(super) u_ptr: &'a [u32],
    pub(super) u_col: &'a [u32],
    pub(super) u: &'a [f64],
    pub(super) inv_d: &'a [f64],
}

impl Factor<'_> {
    fn solve(&self, r: &[f64], y: &mut [f64]) {
        if self.l.is_empty() {
            for ((y, r), d) in y.iter_mut().zip(r).zip(self.inv_d) {
                *y = d * r;
            }
            return;
        }
        let n = y.len();
        // (I + L̃) w = r, row by row
        for i in 0..n {
            let (lo, hi) = (self.u_ptr[i] as usize, self.u_ptr[i + 1] as usize);
            let mut acc = r[i];
            for (u, &j) in self.u[lo..hi].iter().zip(&self.u_col[lo..hi]) {
                acc -= u * y[j as usize];
            }
            y[i] = acc;
        }
        // (I + L̃)ᵀ y = D̃⁻¹ w, row j of L̃ᵀ being column j of L̃
        for j in (0..n).rev() {
            let (lo, hi) = (self.ptr[j] as usize, self.ptr[j + 1] as usize);
            let mut acc = y[j] * self.inv_d[j];
            for (l, &i) in self.l[lo..hi].iter().zip(&self.row[lo..hi]) {
                acc -= l * y[i as usize];
            }
            y[j] = acc;
        }
    }
}

sweep_preconditioner!(Factor);
