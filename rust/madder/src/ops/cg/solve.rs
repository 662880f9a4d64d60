//! The warm-started CG driver: [`WarmCg::solve`] and [`WarmCg::solve_chained`] on the
//! scalar (or expanded block) systems.
//!
//! Each CG runs with `Par::Seq`: its reductions are then in a fixed order and the result
//! is bit-identical whatever the number of threads. The parallelism is across right-hand
//! sides instead: the columns (solvent and solute, colour) are solved side by side on the
//! rayon pool.
//!
//! Each right-hand side column (solvent, solute, colour) is solved on its own, from its
//! own warm start, so a field a thousand times smaller than another still gets its own
//! relative tolerance. (faer's block CG, which shares the sparse products between
//! columns, converges in the same number of iterations per column but measured slower,
//! its dense block updates costing more than the products it saves.)

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::matrix_free::conjugate_gradient::{CgParams, conjugate_gradient};
use faer::{MatMut, MatRef, Par};
use rayon::prelude::*;

use super::chained::recycle;
use super::factor::{IC_SHIFTS, incomplete_cholesky};
use super::precond::{Factor, Preconditioner};
use super::product::SymOp;
use super::solver::{MAX_ITERATIONS, WarmCg, cg_error, cg_scratch};
use crate::error::SolveError;

impl WarmCg {
    /// Solves `A x = b` for every column, `A` given by its lower-triangle `values` on the
    /// pattern. `x` holds the warm start on entry and the solution on return; `b` and `x`
    /// are column-major with the same number of columns.
    pub fn solve(&mut self, values: &[f64], b: &[f64], x: &mut [f64]) -> Result<(), SolveError> {
        self.solve_columns(values, b, x, false)
    }

    /// [`Self::solve`] for columns that are related (`chained.rs`): one
    /// after the other, each warm start first improved along the correction the previous
    /// column's solve made to its own warm start. Sequential, so deterministic; the same
    /// tolerance per column.
    pub fn solve_chained(
        &mut self,
        values: &[f64],
        b: &[f64],
        x: &mut [f64],
    ) -> Result<(), SolveError> {
        self.solve_columns(values, b, x, true)
    }

    fn solve_columns(
        &mut self,
        values: &[f64],
        b: &[f64],
        x: &mut [f64],
        chained: bool,
    ) -> Result<(), SolveError> {
        let n = self.n;
        assert!(n > 0 && b.len() % n == 0, "rhs is not whole columns");
        assert_eq!(b.len(), x.len(), "warm start and rhs differ in size");
        if !self.analyzed {
            self.analyze();
        }
        for (f, &s) in self.full.iter_mut().zip(&self.slot) {
            *f = values[s as usize];
        }
        for (i, &d) in self.diag.iter().enumerate() {
            let a = values[d as usize];
            if !(a > 0.0 && a.is_finite()) {
                return Err(SolveError::NotPositiveDefinite { pivot: i, n });
            }
            self.inv_diag[i] = 1.0 / a;
        }
        let factored = match self.precond {
            Preconditioner::Jacobi => false,
            Preconditioner::SymmetricGaussSeidel => {
                self.gauss_seidel(values);
                true
            }
            Preconditioner::IncompleteCholesky => {
                self.last_shift = f64::NAN;
                IC_SHIFTS.iter().any(|&shift| {
                    let ok = incomplete_cholesky(
                        self.n,
                        &self.diag,
                        &self.l_ptr,
                        &self.l_row,
                        &self.l_slot,
                        &self.upd_ptr,
                        &self.upd,
                        values,
                        shift,
                        &mut self.l_val,
                        &mut self.inv_d,
                    );
                    if ok {
                        self.last_shift = shift;
                    }
                    ok
                })
            }
        };
        if factored {
            for (u, &p) in self.u_val.iter_mut().zip(&self.u_pos) {
                *u = self.l_val[p as usize];
            }
        }
        self.fit_scratch(n, false);
        let a = SymOp {
            ptr: &self.col_ptr,
            idx: &self.row_idx,
            val: &self.full,
        };
        let jacobi = Factor {
            ptr: &self.l_ptr,
            row: &self.l_row,
            l: &[],
            u_ptr: &self.u_ptr,
            u_col: &self.u_col,
            u: &[],
            inv_d: &self.inv_diag,
        };
        let precond = if factored {
            Factor {
                l: &self.l_val,
                u: &self.u_val,
                inv_d: &self.inv_d,
                ..jacobi
            }
        } else {
            jacobi
        };
        let params = CgParams::<f64> {
            rel_tolerance: self.tolerance,
            max_iters: MAX_ITERATIONS,
            ..Default::default()
        };
        let k = b.len() / n;
        while self.scratch.len() < k {
            self.scratch.push(MemBuffer::new(cg_scratch(a, n)));
        }
        let column = |bc: &[f64], xc: &mut [f64], scratch: &mut MemBuffer| {
            if bc.iter().all(|&v| v == 0.0) {
                xc.fill(0.0);
                return Ok(0);
            }
            let run = |m: Factor<'_>, xc: &mut [f64], scratch: &mut MemBuffer| {
                conjugate_gradient(
                    MatMut::from_column_major_slice_mut(xc, n, 1),
                    m,
                    a,
                    MatRef::from_column_major_slice(bc, n, 1),
                    params,
                    |_| {},
                    Par::Seq,
                    MemStack::new(scratch),
                )
                .map(|info| info.iter_count)
            };
            if !factored {
                return run(jacobi, xc, scratch).map_err(cg_error(n));
            }
            // an incomplete factor is SPD (positive pivots) but can be a poor
            // preconditioner for a matrix far from an M-matrix: a column it fails is
            // solved again with Jacobi from the same warm start
            let start = xc.to_vec();
            match run(precond, xc, scratch) {
                Ok(it) => Ok(it),
                Err(_) => {
                    xc.copy_from_slice(&start);
                    run(jacobi, xc, scratch).map_err(cg_error(n))
                }
            }
        };
        let results: Vec<Result<usize, SolveError>> = if chained && k > 1 {
            // one column after the other, each warm start corrected along the previous
            // column's correction (`recycle`)
            let (scratch, mut results) = (&mut self.scratch[0], Vec::with_capacity(k));
            let (mut ax, mut ad) = (vec![0.0; n], vec![0.0; n]);
            let mut previous: Option<Vec<f64>> = None;
            for (c, (bc, xc)) in b.chunks_exact(n).zip(x.chunks_exact_mut(n)).enumerate() {
                // the correction is counted from the column's own warm start
                let start = (c + 1 < k).then(|| xc.to_vec());
                if let Some(d) = &previous {
                    let norm = bc.iter().map(|v| v * v).sum::<f64>().sqrt();
                    let previous_b = &b[(c - 1) * n..c * n];
                    let threshold = self.tolerance * norm;
                    recycle(a, bc, previous_b, threshold, xc, d, &mut ax, &mut ad);
                }
                let r = column(bc, xc, scratch);
                previous = start.map(|mut d| {
                    d.iter_mut().zip(xc.iter()).for_each(|(d, x)| *d = x - *d);
                    d
                });
                results.push(r);
            }
            results
        } else {
            // columns are independent sequential solves: run them side by side on the
            // rayon pool (each column's arithmetic is the same whatever the thread count)
            b.par_chunks_exact(n)
                .zip(x.par_chunks_exact_mut(n))
                .zip(self.scratch[..k].par_iter_mut())
                .map(|((bc, xc), scratch)| column(bc, xc, scratch))
                .collect()
        };
        self.last_iterations = 0;
        for r in results {
            self.last_iterations += r?;
        }
        Ok(())
    }
}
