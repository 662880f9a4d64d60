//! The velocity's rotated-block system solved on the scalar pattern
//! ([`WarmCg::solve_rotated`]): its operator and its block Gauss–Seidel.
//!
//! ## Rotated blocks: the velocity ([`WarmCg::solve_rotated`])
//! The velocity's Bochner system (eq. 4.6) is the scalar matrix with every entry a `2×2`
//! block: `a_ii I₂` on the diagonal, `a_ij R` off it, `R` the rotation of the edge's
//! transport ([`crate::ops::restrict`]). Expanded, it has four times the scalar
//! entries, and assembling it, gathering it into the full pattern and factoring it cost
//! several times its one or two CG iterations. `solve_rotated` keeps the scalar pattern
//! (a solver built on it, [`WarmCg::new`] of the restricted scalar pattern) and stores
//! per full entry the two numbers `(a c, ±a s)` (`+` below the diagonal, `−` above: the
//! upper block is the lower one transposed); the product runs along the scalar rows and
//! writes both components, in the expanded product's order and with its products, so
//! with Jacobi it is the expanded Jacobi solve to the last bit (a test checks it). The
//! preconditioner is symmetric Gauss–Seidel on the blocks, `(D + L) D⁻¹ (D + Lᵀ)` with
//! `D = diag(a_ii) ⊗ I₂`: a forward sweep along each row's entries left of the diagonal,
//! a backward sweep along those right of it, from the same values, no set-up. IC(0)
//! would need the expanded values (or a block factorization), and Jacobi needs about five
//! times the iterations at the velocity's tolerance. SGS takes IC(0)'s iteration count
//! there (1.0 per sub-step on the synthetic flag, as IC(0)). Per sub-step that leaves,
//! of the former assembly, expansion, gather, factorization and sweeps, one pass
//! writing 16 bytes per scalar entry and per iteration three passes over them.

use faer::dyn_stack::{MemBuffer, MemStack, StackReq};
use faer::matrix_free::conjugate_gradient::{CgError, CgInfo, CgParams, conjugate_gradient};
use faer::matrix_free::{LinOp, Precond};
use faer::{MatMut, MatRef, Par};

use super::precond::{Factor, Preconditioner, sweep_preconditioner};
use super::product::by_columns;
use super::solver::{MAX_ITERATIONS, WarmCg, cg_error, cg_scratch};
use crate::error::SolveError;

impl WarmCg {
    /// Solves the `2n × 2n` system whose every entry of this solver's scalar pattern is a
    /// `2×2` block (module doc, "Rotated blocks"): diagonal blocks `a_ii I₂`, the lower
    /// block of entry `s` (row `i` > column `j`) `a_s [c s; −s c]` by columns, `[c, s] =
    /// cos_sin[entry_edge[s]]`, its upper block the transpose: the Bochner system of
    /// [`crate::ops::restrict`]'s `block_values` without expanding it. `values` are the
    /// scalar lower-triangle values; `b` and `x` hold one interleaved column (`x` the warm
    /// start). Jacobi-preconditioned CG, one product pass over the scalar pattern per
    /// iteration; the same arithmetic, to the last bit, as [`Self::solve`] with
    /// [`Preconditioner::Jacobi`] on the expanded values.
    pub fn solve_rotated(
        &mut self,
        values: &[f64],
        entry_edge: &[u32],
        cos_sin: &[[f64; 2]],
        b: &[f64],
        x: &mut [f64],
    ) -> Result<(), SolveError> {
        let n = self.n;
        assert!(
            n > 0 && b.len() == 2 * n,
            "rhs is not one interleaved column"
        );
        assert_eq!(b.len(), x.len(), "warm start and rhs differ in size");
        // inv_diag holds 2n entries here: the block diagonal a_ii I₂, inverted
        self.inv_diag.resize(2 * n, 0.0);
        for (i, &d) in self.diag.iter().enumerate() {
            let a = values[d as usize];
            if !(a > 0.0 && a.is_finite()) {
                return Err(SolveError::NotPositiveDefinite {
                    pivot: 2 * i,
                    n: 2 * n,
                });
            }
            let inv = 1.0 / a;
            self.inv_diag[2 * i] = inv;
            self.inv_diag[2 * i + 1] = inv;
        }
        // per full entry of row i, column j: `(a c, ±a s)`, `+` below the diagonal (the
        // lower block's first row), `−` above (its transpose's); the diagonal's `(a, 0)`
        // (`a c`, `a s`) per lower entry first, in storage order (the edges of a column
        // are consecutive), then spread over the full pattern
        self.rotated_lower.clear();
        self.rotated_lower
            .extend(values.iter().zip(entry_edge).map(|(&a, &e)| match e {
                u32::MAX => [a, 0.0],
                e => {
                    let [c, sn] = cos_sin[e as usize];
                    [a * c, a * sn]
                }
            }));
        self.rotated.resize(self.slot.len(), [0.0; 2]);
        self.fit_scratch(2 * n, true);
        for i in 0..n {
            for k in self.col_ptr[i] as usize..self.col_ptr[i + 1] as usize {
                let [p, q] = self.rotated_lower[self.slot[k] as usize];
                self.rotated[k] = if self.row_idx[k] as usize > i {
                    [p, -q]
                } else {
                    [p, q]
                };
            }
        }
        let op = RotatedOp {
            ptr: &self.col_ptr,
            idx: &self.row_idx,
            val: &self.rotated,
        };
        let jacobi = Factor {
            ptr: &[],
            row: &[],
            l: &[],
            u_ptr: &[],
            u_col: &[],
            u: &[],
            inv_d: &self.inv_diag,
        };
        self.last_iterations = 0;
        if b.iter().all(|&v| v == 0.0) {
            x.fill(0.0);
            return Ok(());
        }
        if self.scratch.is_empty() {
            self.scratch.push(MemBuffer::new(cg_scratch(op, 2 * n)));
        }
        let params = CgParams::<f64> {
            rel_tolerance: self.tolerance,
            max_iters: MAX_ITERATIONS,
            ..Default::default()
        };
        // symmetric Gauss–Seidel on the blocks, from the same values (no set-up beyond
        // the diagonal's inverse), or Jacobi
        let sgs = RotatedSgs {
            op,
            inv_d: &self.inv_diag,
        };
        fn run<M: Precond<f64>>(
            m: M,
            op: RotatedOp<'_>,
            b: &[f64],
            x: &mut [f64],
            params: CgParams<f64>,
            scratch: &mut MemBuffer,
        ) -> Result<CgInfo<f64>, CgError<f64>> {
            let n = b.len();
            conjugate_gradient(
                MatMut::from_column_major_slice_mut(x, n, 1),
                m,
                op,
                MatRef::from_column_major_slice(b, n, 1),
                params,
                |_| {},
                Par::Seq,
                MemStack::new(scratch),
            )
        }
        let scratch = &mut self.scratch[0];
        let info = if self.precond == Preconditioner::SymmetricGaussSeidel {
            run(sgs, op, b, x, params, scratch)
        } else {
            run(jacobi, op, b, x, params, scratch)
        }
        .map_err(cg_error(2 * n))?;
        self.last_iterations = info.iter_count;
        Ok(())
    }
}

/// The rotated-block matrix of [`WarmCg::solve_rotated`] on the full scalar pattern:
/// `val[k] = (p, q)` for the entry `(i, j)`, whose block is `[p q; −q p]` (`(a, 0)` on the
/// diagonal: `a I₂`), applied to interleaved vectors.
#[derive(Debug, Clone, Copy)]
struct RotatedOp<'a> {
    ptr: &'a [u32],
    idx: &'a [u32],
    val: &'a [[f64; 2]],
}

impl RotatedOp<'_> {
    /// `y = A x`, rows `2i` and `2i + 1` summed together along the scalar row `i`, each in
    /// increasing column order from `0`: the order, and the products, of [`SymOp::gather`]
    /// on the expanded matrix (`−q·x` is `−(q·x)` exactly, and adding it subtracting).
    ///
    /// [`SymOp::gather`]: super::product::SymOp::gather
    fn gather(&self, x: &[f64], y: &mut [f64]) {
        for i in 0..self.ptr.len() - 1 {
            let (lo, hi) = (self.ptr[i] as usize, self.ptr[i + 1] as usize);
            let (mut y0, mut y1) = (0.0, 0.0);
            for (&[p, q], &j) in self.val[lo..hi].iter().zip(&self.idx[lo..hi]) {
                let j = j as usize;
                let (x0, x1) = (x[2 * j], x[2 * j + 1]);
                if j == i {
                    y0 += p * x0;
                    y1 += p * x1;
                } else {
                    y0 += p * x0;
                    y0 += q * x1;
                    y1 -= q * x0;
                    y1 += p * x1;
                }
            }
            y[2 * i] = y0;
            y[2 * i + 1] = y1;
        }
    }
}

impl LinOp<f64> for RotatedOp<'_> {
    fn apply_scratch(&self, _rhs_ncols: usize, _par: Par) -> StackReq {
        StackReq::EMPTY
    }

    fn nrows(&self) -> usize {
        2 * (self.ptr.len() - 1)
    }

    fn ncols(&self) -> usize {
        self.nrows()
    }

    fn apply(&self, out: MatMut<'_, f64>, rhs: MatRef<'_, f64>, _par: Par, _: &mut MemStack) {
        by_columns(self.nrows(), out, rhs, |x, y| self.gather(x, y));
    }

    fn conj_apply(&self, out: MatMut<'_, f64>, rhs: MatRef<'_, f64>, par: Par, s: &mut MemStack) {
        self.apply(out, rhs, par, s);
    }
}

/// Symmetric Gauss–Seidel for [`RotatedOp`]: `M = (D + L) D⁻¹ (D + Lᵀ)`, `L` the blocks
/// below the diagonal, `D = diag(a_ii) ⊗ I₂` (`inv_d` its inverse, two entries a vertex):
/// a forward sweep along the rows' entries left of the diagonal, a backward sweep along
/// those right of it, sequential, in a fixed order.
#[derive(Debug, Clone, Copy)]
struct RotatedSgs<'a> {
    op: RotatedOp<'a>,
    inv_d: &'a [f64],
}

impl RotatedSgs<'_> {
    fn solve(&self, r: &[f64], y: &mut [f64]) {
        let RotatedOp { ptr, idx, val } = self.op;
        let n = ptr.len() - 1;
        // (D + L) w = r
        for i in 0..n {
            let (lo, hi) = (ptr[i] as usize, ptr[i + 1] as usize);
            let (mut a0, mut a1) = (r[2 * i], r[2 * i + 1]);
            for (&[p, q], &j) in val[lo..hi].iter().zip(&idx[lo..hi]) {
                let j = j as usize;
                if j >= i {
                    break;
                }
                let (w0, w1) = (y[2 * j], y[2 * j + 1]);
                a0 -= p * w0 + q * w1;
                a1 -= p * w1 - q * w0;
            }
            y[2 * i] = a0 * self.inv_d[2 * i];
            y[2 * i + 1] = a1 * self.inv_d[2 * i + 1];
        }
        // (D + Lᵀ) y = D w: y_i = w_i − D_i⁻¹ Σ_{j > i} A_ij y_j
        for i in (0..n).rev() {
            let (lo, hi) = (ptr[i] as usize, ptr[i + 1] as usize);
            let (mut a0, mut a1) = (0.0, 0.0);
            for (&[p, q], &j) in val[lo..hi].iter().zip(&idx[lo..hi]).rev() {
                let j = j as usize;
                if j <= i {
                    break;
                }
                let (v0, v1) = (y[2 * j], y[2 * j + 1]);
                a0 += p * v0 + q * v1;
                a1 += p * v1 - q * v0;
            }
            y[2 * i] -= a0 * self.inv_d[2 * i];
            y[2 * i + 1] -= a1 * self.inv_d[2 * i + 1];
        }
    }
}

sweep_preconditioner!(RotatedSgs);
