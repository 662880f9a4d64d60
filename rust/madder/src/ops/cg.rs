//! Warm-started preconditioned conjugate gradients on a fixed sparsity pattern.
//!
//! The simulator solves `(M + hK) x = b` (scalar densities, and the `2N×2N` Bochner system
//! of the velocity, eq. 4.6) every sub-step with new values on the same pattern. At
//! cloth time steps the matrix is strongly diagonally dominant (`M` dominates `hK` unless
//! `h D` is many times the squared edge length), and the solution changes little from one
//! step to the next: CG started from the previous solution converges in a few iterations,
//! in a fraction of the time the numeric refactorization of the prefactored Cholesky
//! ([`super::PrefactoredSpd`]) takes. So the stepper uses this solver; the Cholesky stays
//! for direct solves and as the reference in the tests. (The figures behind this and the
//! choices below are in ARCHITECTURE.md, "Solver"; `cargo bench -p madder --bench
//! diffusion` prints them.)
//!
//! [`WarmCg`] expands the lower-triangle pattern ([`LowerCsc`]) once into the full
//! symmetric matrix that faer's matrix-free CG multiplies with, with the lower slot of every
//! full entry, so each solve only gathers values. The product is our own (`SymOp`): the
//! matrix being symmetric, its compressed columns are also its rows, and each output entry
//! is gathered along its row, `y_i = Σ_k a_ik x_k` in increasing `k` — the order in which
//! faer's compressed-column product accumulates `y_i` (column after column), so the
//! result is the same to the last bit, without the scatter and with 32-bit indices
//! (faster). Each CG runs with `Par::Seq`: its reductions are then in a fixed order and the
//! result is bit-identical whatever the number of threads. The parallelism is across
//! right-hand sides instead: the columns (solvent and solute, colour) are solved side by
//! side on the rayon pool.
//!
//! The expansion is all a solver of rotated blocks ([`WarmCg::solve_rotated`]) needs; the
//! factor's pattern and IC(0)'s updates (below) are analysed when a solver is rebuilt for
//! IC(0), or else at its first scalar solve, so the window's velocity solver never pays
//! for them.
//!
//! The iteration itself is faer's. A hand-written Jacobi-PCG with the same stopping rule
//! (three fused passes per iteration, no allocation) measured a little faster (faer runs
//! a single column's vector updates through its dense block product); we keep the
//! library's, as the project's dependency policy asks.
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
//! Each right-hand side column (solvent, solute, colour) is solved on its own, from its
//! own warm start, so a field a thousand times smaller than another still gets its own
//! relative tolerance. (faer's block CG, which shares the sparse products between
//! columns, converges in the same number of iterations per column but measured slower,
//! its dense block updates costing more than the products it saves.)
//!
//! ## Related columns ([`WarmCg::solve_chained`])
//! The density fields are far from independent: a colour mass is the solute mass times
//! the liquid's RGB (exactly, for one colour), and the solute is the solvent times the
//! poured concentration until evaporation and absorption part them. The system being
//! linear, `b_k = c b_j` gives `x_k = c x_j`, yet solving the columns side by side costs
//! each the full iteration count (on the 100k Blender flag, 5 fields × 7 iterations per
//! sub-step, the same for all five). The chained solve takes them in order and first
//! moves the warm start `x⁰_k` of column `k` along the correction `d = x_{k−1} − x⁰_{k−1}`
//! the previous column's solve made to its own warm start, by the Galerkin step
//!
//! ```text
//! x⁰_k ← x⁰_k + α d,    α = dᵀ(b_k − A x⁰_k) / dᵀA d,
//! ```
//!
//! which minimizes the error's `A`-norm along `d` (`α = 0` is allowed, so the start is never
//! worse in that norm). Before it, the step `c = b_kᵀb_{k−1} / b_{k−1}ᵀb_{k−1}` (the ratio of
//! the right-hand sides) is tried and kept if its residual is already below the
//! tolerance: with `b_k = c b_{k−1}` and warm starts in the same ratio (the stepper's
//! `m / A`) the start is then `c x_{k−1}` to rounding, whose residual is `c` times the
//! previous column's final one, so the column takes no iteration and stays a multiple of
//! the previous one to rounding, as separate solves keep it (CG is invariant under
//! scaling; a colour read as colour mass over solute is then exactly the poured one, which
//! `tests/detail.rs` checks to 1e-9; the Galerkin `α` alone is `c` only to the tolerance).
//! It costs two sparse products and a few dot products (about one iteration), and it is CG
//! with another start, so each column still stops at its own tolerance. On the flag the
//! density iterations fell from 35.5 to 11.4 per sub-step at 1e-9 (solvent 6–10, solute
//! 4–6, colours 0), and the results moved by 7.5e-8 of the stain's peak (f32 read-out).
//! The columns then run one after the other (the velocity's solve runs beside them,
//! `rayon::join` in the stepper); sequential, so the result does not depend on the thread
//! count.
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
use faer::matrix_free::conjugate_gradient::{
    CgError, CgInfo, CgParams, conjugate_gradient, conjugate_gradient_scratch,
};
use faer::matrix_free::{LinOp, Precond};
use faer::{Col, MatMut, MatRef, Par};
use rayon::prelude::*;

use super::solve::LowerCsc;
use crate::error::SolveError;

/// `v` emptied and refilled with `len` copies of `value`, in the memory it holds.
fn refill<T: Copy>(mut v: Vec<T>, len: usize, value: T) -> Vec<T> {
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
/// CG preconditioned by IC(0) (module doc).
pub struct WarmCg {
    n: usize,
    /// The full symmetric pattern, compressed by columns (= by rows).
    col_ptr: Vec<u32>,
    row_idx: Vec<u32>,
    /// For each entry of the full matrix, its slot in the lower-triangle values.
    slot: Vec<u32>,
    /// Slot of each diagonal entry in the lower-triangle values.
    diag: Vec<u32>,
    full: Vec<f64>,
    /// The strict lower triangle, compressed by columns with increasing rows: the pattern
    /// of the incomplete factor `L̃` (see `Factor`); `l_slot` is each entry's slot in the
    /// lower-triangle values.
    l_ptr: Vec<u32>,
    l_row: Vec<u32>,
    l_slot: Vec<u32>,
    /// IC(0) updates of the off-diagonal entries, per eliminated column `k`
    /// (`upd_ptr[k]..upd_ptr[k + 1]`): `l[t] -= l[p] l[q] / d_k` for `[t, p, q]`, the
    /// positions in `l_row` of `(i, j)`, `(i, k)` and `(j, k)`, `i > j > k`, when `(i, j)`
    /// is in the pattern.
    upd_ptr: Vec<u32>,
    upd: Vec<[u32; 3]>,
    /// The strict lower triangle by rows (`u_col` increasing in each row), `u_pos` each
    /// entry's position in `l_row`: the forward sweep gathers along rows.
    u_ptr: Vec<u32>,
    u_col: Vec<u32>,
    u_pos: Vec<u32>,
    u_val: Vec<f64>,
    /// Whether the factor's pattern and IC(0)'s updates above are this pattern's: left
    /// for later when the preconditioner is not IC(0) (the rotated solve never needs
    /// them; a scalar solve analyses first).
    analyzed: bool,
    /// The factor's values, rebuilt every solve: `l` on `l_row`, and `D̃⁻¹`.
    l_val: Vec<f64>,
    inv_d: Vec<f64>,
    /// `diag(A)⁻¹`: the Jacobi preconditioner, and the fallback.
    inv_diag: Vec<f64>,
    precond: Preconditioner,
    /// Diagonal shift the last IC(0) factorization needed (`0` if none; `NaN` if it fell
    /// back to Jacobi).
    last_shift: f64,
    /// The rotated product's two values per full entry ([`WarmCg::solve_rotated`]).
    rotated: Vec<[f64; 2]>,
    /// The same per lower-triangle entry.
    rotated_lower: Vec<[f64; 2]>,
    /// One workspace per right-hand side column.
    scratch: Vec<MemBuffer>,
    /// The system size and kind (rotated or not) `scratch` was made for.
    scratch_for: (usize, bool),
    tolerance: f64,
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
    /// Expands `pattern` (the lower triangle) into the full symmetric pattern; the
    /// factor's pattern and IC(0)'s updates are analysed at the first scalar solve (a
    /// solver set to another preconditioner first, or solving only rotated systems, never
    /// pays for them).
    pub fn new<P: LowerCsc + ?Sized>(pattern: &P) -> Self {
        let mut cg = Self {
            n: 0,
            col_ptr: Vec::new(),
            row_idx: Vec::new(),
            slot: Vec::new(),
            diag: Vec::new(),
            full: Vec::new(),
            l_ptr: Vec::new(),
            l_row: Vec::new(),
            l_slot: Vec::new(),
            upd_ptr: Vec::new(),
            upd: Vec::new(),
            u_ptr: Vec::new(),
            u_col: Vec::new(),
            u_pos: Vec::new(),
            u_val: Vec::new(),
            analyzed: false,
            l_val: Vec::new(),
            inv_d: Vec::new(),
            inv_diag: Vec::new(),
            // not IC(0) while rebuilt: the analysis is left for the first scalar solve
            precond: Preconditioner::Jacobi,
            last_shift: 0.0,
            rotated: Vec::new(),
            rotated_lower: Vec::new(),
            scratch: Vec::new(),
            scratch_for: (0, false),
            tolerance: RELATIVE_TOLERANCE,
            last_iterations: 0,
        };
        cg.rebuild(pattern);
        cg.precond = Preconditioner::IncompleteCholesky;
        cg
    }

    /// Makes this solver [`WarmCg::new`]`(pattern)`'s (its tolerance and preconditioner
    /// kept) in the memory it already holds, the factor analysed now if the
    /// preconditioner is IC(0) (a window build does it beside the fans), else when a
    /// scalar solve first needs it. A window's solvers are rebuilt with every window;
    /// fresh memory is paid for in page faults (measured: two thirds of the symbolic
    /// analysis of a 34k-vertex Bochner system), memory already touched is not.
    pub fn rebuild<P: LowerCsc + ?Sized>(&mut self, pattern: &P) {
        let n = pattern.n();
        let (cp, ri) = (pattern.col_ptr(), pattern.row_idx());
        let mut diag = refill(std::mem::take(&mut self.diag), n, u32::MAX);
        // entries of the full matrix per column: its upper part (the lower entries of the
        // rows above) and its own lower column
        let mut col_ptr = refill(std::mem::take(&mut self.col_ptr), n + 1, 0u32);
        let mut sorted = true;
        for j in 0..n {
            let (lo, hi) = (cp[j] as usize, cp[j + 1] as usize);
            for s in lo..hi {
                let i = ri[s] as usize;
                sorted &= i >= j && (s == lo || ri[s - 1] < ri[s]);
                col_ptr[j + 1] += 1;
                if i != j {
                    col_ptr[i + 1] += 1;
                } else {
                    diag[j] = s as u32;
                }
            }
        }
        assert!(
            diag.iter().all(|&d| d != u32::MAX),
            "pattern lacks a diagonal entry"
        );
        for j in 0..n {
            col_ptr[j + 1] += col_ptr[j];
        }
        let nnz = col_ptr[n] as usize;
        let (row_idx, slot) = if sorted {
            // lower columns with increasing rows: filling column by column puts every full
            // column in increasing row order (its upper rows j < c arrive while j
            // increases, then its own rows ≥ c), as the sort below would, in O(nnz)
            let mut next: Vec<u32> = col_ptr[..n].to_vec();
            let mut row_idx = refill(std::mem::take(&mut self.row_idx), nnz, 0u32);
            let mut slot = refill(std::mem::take(&mut self.slot), nnz, 0u32);
            for j in 0..n {
                for s in cp[j]..cp[j + 1] {
                    let i = ri[s as usize] as usize;
                    let k = next[j] as usize;
                    (row_idx[k], slot[k]) = (i as u32, s);
                    next[j] += 1;
                    if i != j {
                        let k = next[i] as usize;
                        (row_idx[k], slot[k]) = (j as u32, s);
                        next[i] += 1;
                    }
                }
            }
            (row_idx, slot)
        } else {
            let mut entries: Vec<(u32, u32, u32)> = Vec::with_capacity(nnz);
            for j in 0..n {
                for s in cp[j]..cp[j + 1] {
                    let i = ri[s as usize];
                    entries.push((j as u32, i, s));
                    if i as usize != j {
                        entries.push((i, j as u32, s));
                    }
                }
            }
            entries.sort_unstable();
            (
                entries.iter().map(|e| e.1).collect(),
                entries.iter().map(|e| e.2).collect(),
            )
        };
        let full = refill(std::mem::take(&mut self.full), slot.len(), 0.0);
        let inv_diag = refill(std::mem::take(&mut self.inv_diag), n, 0.0);
        (
            self.n,
            self.col_ptr,
            self.row_idx,
            self.slot,
            self.diag,
            self.full,
            self.inv_diag,
        ) = (n, col_ptr, row_idx, slot, diag, full, inv_diag);
        self.last_shift = 0.0;
        self.last_iterations = 0;
        self.analyzed = false;
        // the factor's pattern and updates now if IC(0) needs them every solve; the
        // rotated solve never reads them, a scalar solve analyses on its first call
        if self.precond == Preconditioner::IncompleteCholesky {
            self.analyze();
        }
    }

    /// The factor's pattern (the strict lower triangle by columns and by rows) and IC(0)'s
    /// updates, from the full pattern: what [`Self::solve`] needs beyond the product
    /// (module doc). Done once per pattern, when a scalar solve first needs it, or at
    /// [`Self::rebuild`] for IC(0).
    fn analyze(&mut self) {
        let n = self.n;
        let (col_ptr, row_idx, slot) = (&self.col_ptr, &self.row_idx, &self.slot);
        let nnz = slot.len();
        // the strict lower triangle, rows increasing in each column: the entries of the
        // full columns below their diagonal
        let mut l_ptr = refill(std::mem::take(&mut self.l_ptr), 0, 0u32);
        let mut l_row = refill(std::mem::take(&mut self.l_row), 0, 0u32);
        let mut l_slot = refill(std::mem::take(&mut self.l_slot), 0, 0u32);
        // capacities reserved up front: growing by doubling would copy, and touch twice
        // the memory (reserved pages cost nothing until written)
        let n_lower = (nnz - n) / 2;
        l_ptr.reserve(n + 1);
        l_row.reserve(n_lower);
        l_slot.reserve(n_lower);
        l_ptr.push(0u32);
        for j in 0..n {
            for k in col_ptr[j] as usize..col_ptr[j + 1] as usize {
                if row_idx[k] as usize > j {
                    l_row.push(row_idx[k]);
                    l_slot.push(slot[k]);
                }
            }
            l_ptr.push(l_row.len() as u32);
        }
        // IC(0)'s updates: for every pair of entries (j, k), (i, k) of column k (k < j < i)
        // whose (i, j) is in the pattern, the entry's slot in column j. The rows of column
        // k after j and those of column j both increase, so one merge of the two finds
        // them all (in the order the factorization applies them: by column, then j, then i)
        let mut upd_ptr = refill(std::mem::take(&mut self.upd_ptr), 0, 0u32);
        let mut upd = refill(std::mem::take(&mut self.upd), 0, [0u32; 3]);
        // at most one update per pair of entries of a column
        let pairs: usize = (0..n)
            .map(|k| {
                let m = (l_ptr[k + 1] - l_ptr[k]) as usize;
                m * m.saturating_sub(1) / 2
            })
            .sum();
        upd_ptr.reserve(n + 1);
        upd.reserve(pairs);
        upd_ptr.push(0u32);
        for k in 0..n {
            let (lo, hi) = (l_ptr[k] as usize, l_ptr[k + 1] as usize);
            for q in lo..hi {
                let j = l_row[q] as usize;
                let (mut t, t_end) = (l_ptr[j] as usize, l_ptr[j + 1] as usize);
                for (p, &i) in (q + 1..hi).zip(&l_row[q + 1..hi]) {
                    while t < t_end && l_row[t] < i {
                        t += 1;
                    }
                    if t == t_end {
                        break;
                    }
                    if l_row[t] == i {
                        upd.push([t as u32, p as u32, q as u32]);
                    }
                }
            }
            upd_ptr.push(upd.len() as u32);
        }
        let mut u_ptr = refill(std::mem::take(&mut self.u_ptr), n + 1, 0u32);
        for &i in &l_row {
            u_ptr[i as usize + 1] += 1;
        }
        for i in 0..n {
            u_ptr[i + 1] += u_ptr[i];
        }
        let mut next = u_ptr[..n].to_vec();
        let mut u_col = refill(std::mem::take(&mut self.u_col), l_row.len(), 0u32);
        let mut u_pos = refill(std::mem::take(&mut self.u_pos), l_row.len(), 0u32);
        for j in 0..n {
            for p in l_ptr[j]..l_ptr[j + 1] {
                let i = l_row[p as usize] as usize;
                let s = next[i] as usize;
                (u_col[s], u_pos[s]) = (j as u32, p);
                next[i] += 1;
            }
        }
        let l_val = refill(std::mem::take(&mut self.l_val), l_row.len(), 0.0);
        let u_val = refill(std::mem::take(&mut self.u_val), l_row.len(), 0.0);
        let inv_d = refill(std::mem::take(&mut self.inv_d), n, 0.0);
        (self.l_ptr, self.l_row, self.l_slot, self.upd_ptr, self.upd) =
            (l_ptr, l_row, l_slot, upd_ptr, upd);
        (
            self.u_ptr, self.u_col, self.u_pos, self.u_val, self.l_val, self.inv_d,
        ) = (u_ptr, u_col, u_pos, u_val, l_val, inv_d);
        self.analyzed = true;
    }

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
    /// them (module doc); the default is the fastest measured.
    #[doc(hidden)]
    pub fn with_preconditioner(mut self, precond: Preconditioner) -> Self {
        self.precond = precond;
        self
    }

    /// Solves `A x = b` for every column, `A` given by its lower-triangle `values` on the
    /// pattern. `x` holds the warm start on entry and the solution on return; `b` and `x`
    /// are column-major with the same number of columns.
    pub fn solve(&mut self, values: &[f64], b: &[f64], x: &mut [f64]) -> Result<(), SolveError> {
        self.solve_columns(values, b, x, false)
    }

    /// [`Self::solve`] for columns that are related (module doc, "Related columns"): one
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

    /// Keeps the CG work space if it was made for systems of at least `size` unknowns of
    /// the same kind (`rotated`: [`Self::solve_rotated`]'s), else drops it to be made
    /// anew. Kept across [`Self::rebuild`]: fresh work space is fresh pages, faulted in
    /// at every window (issue 16); its contents are never read before written.
    fn fit_scratch(&mut self, size: usize, rotated: bool) {
        if self.scratch_for.0 < size || self.scratch_for.1 != rotated {
            self.scratch.clear();
            self.scratch_for = (size, rotated);
        }
    }

    /// `L̃ = L D⁻¹`, `D̃ = D` (module doc): symmetric Gauss–Seidel.
    fn gauss_seidel(&mut self, values: &[f64]) {
        for j in 0..self.n {
            let inv = self.inv_diag[j];
            self.inv_d[j] = inv;
            for p in self.l_ptr[j] as usize..self.l_ptr[j + 1] as usize {
                self.l_val[p] = values[self.l_slot[p] as usize] * inv;
            }
        }
    }
}

/// Diagonal shifts tried, in order, when an IC(0) pivot is not positive: the factor of
/// `A + shift·diag(A)` (Manteuffel's shift); after the last, Jacobi.
const IC_SHIFTS: [f64; 3] = [0.0, 1e-2, 1e-1];

/// A pivot below this fraction of its (shifted) diagonal counts as a breakdown.
const MIN_PIVOT: f64 = 1e-8;

fn cg_error(n: usize) -> impl Fn(CgError<f64>) -> SolveError {
    move |e| match e {
        CgError::NoConvergence { rel_residual, .. } => SolveError::NotConverged {
            iterations: MAX_ITERATIONS,
            residual: rel_residual,
        },
        // CG only sees a non-positive curvature, not where: no pivot to name
        _ => SolveError::NotPositiveDefinite { pivot: 0, n },
    }
}

/// IC(0) of `A + shift·diag(A)` on the pattern, as `(I + L̃) D̃ (I + L̃)ᵀ` (module doc),
/// right-looking: column `k` updates the diagonal and the in-pattern entries of the
/// columns it couples, then is scaled by `1/d_k`. Returns `false` on a pivot that is not
/// positive (or not finite).
#[allow(clippy::too_many_arguments)]
fn incomplete_cholesky(
    n: usize,
    diag: &[u32],
    l_ptr: &[u32],
    l_row: &[u32],
    l_slot: &[u32],
    upd_ptr: &[u32],
    upd: &[[u32; 3]],
    values: &[f64],
    shift: f64,
    l: &mut [f64],
    inv_d: &mut [f64],
) -> bool {
    for (d, &s) in inv_d.iter_mut().zip(diag) {
        // the working pivots, inverted as each column is eliminated
        *d = values[s as usize] * (1.0 + shift);
    }
    for (v, &s) in l.iter_mut().zip(l_slot) {
        *v = values[s as usize];
    }
    for k in 0..n {
        let d = inv_d[k];
        let a = values[diag[k] as usize] * (1.0 + shift);
        if !(d > MIN_PIVOT * a && d.is_finite()) {
            return false;
        }
        let inv = 1.0 / d;
        let (lo, hi) = (l_ptr[k] as usize, l_ptr[k + 1] as usize);
        for p in lo..hi {
            let v = l[p];
            inv_d[l_row[p] as usize] -= v * v * inv;
        }
        for &[t, p, q] in &upd[upd_ptr[k] as usize..upd_ptr[k + 1] as usize] {
            l[t as usize] -= l[p as usize] * l[q as usize] * inv;
        }
        for v in &mut l[lo..hi] {
            *v *= inv;
        }
        inv_d[k] = inv;
    }
    true
}

/// Improves the warm start `x` of `A x = b` along `d`, the correction the previous
/// column's solve (right-hand side `b'`) made to its own warm start: `x += β d` (module
/// doc, "Related columns"). First `β = c = bᵀb' / b'ᵀb'`, the ratio of the right-hand
/// sides: when `b = c b'` and the warm starts are in the same ratio (colour masses) the
/// start becomes the previous solution times `c`, to rounding, and is kept if its residual
/// is already below `threshold` (the column then converges at once and stays exactly
/// proportional, as a separate solve, CG being invariant under scaling, would keep it).
/// Otherwise `β = α = dᵀ(b − A x) / dᵀA d`, the step that minimizes the error's `A`-norm
/// along `d` (one Galerkin step), so the start is never worse in that norm. `ax` and `ad`
/// are scratch of length `n`. Sequential, fixed order.
#[allow(clippy::too_many_arguments)]
fn recycle(
    a: SymOp<'_>,
    b: &[f64],
    previous_b: &[f64],
    threshold: f64,
    x: &mut [f64],
    d: &[f64],
    ax: &mut [f64],
    ad: &mut [f64],
) {
    a.gather(x, ax);
    a.gather(d, ad);
    let (mut num, mut den, mut bb, mut pp) = (0.0, 0.0, 0.0, 0.0);
    for i in 0..x.len() {
        num += d[i] * (b[i] - ax[i]);
        den += d[i] * ad[i];
        bb += b[i] * previous_b[i];
        pp += previous_b[i] * previous_b[i];
    }
    if pp > 0.0 {
        let c = bb / pp;
        let r2: f64 = (0..x.len())
            .map(|i| {
                let r = b[i] - ax[i] - c * ad[i];
                r * r
            })
            .sum();
        if r2.sqrt() < threshold {
            x.iter_mut().zip(d).for_each(|(x, d)| *x += c * d);
            return;
        }
    }
    if den > 0.0 && den.is_finite() && num.is_finite() {
        let alpha = num / den;
        x.iter_mut().zip(d).for_each(|(x, d)| *x += alpha * d);
    }
}

fn cg_scratch(a: impl LinOp<f64>, n: usize) -> StackReq {
    let d = Col::<f64>::zeros(n);
    conjugate_gradient_scratch(d.as_ref().as_diagonal(), a, 1, Par::Seq)
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

/// The full symmetric matrix, compressed by columns, which are also its rows: the
/// product gathers every output entry along its row (see the module doc).
#[derive(Debug, Clone, Copy)]
struct SymOp<'a> {
    ptr: &'a [u32],
    idx: &'a [u32],
    val: &'a [f64],
}

impl SymOp<'_> {
    /// `y = A x`, each `y_i` summed in increasing column order from `0`.
    fn gather(&self, x: &[f64], y: &mut [f64]) {
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
fn by_columns(
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
struct Factor<'a> {
    ptr: &'a [u32],
    row: &'a [u32],
    l: &'a [f64],
    /// `L̃` again, by rows.
    u_ptr: &'a [u32],
    u_col: &'a [u32],
    u: &'a [f64],
    inv_d: &'a [f64],
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::{Geometry, OneRings, Topology, Transport, VertexFrames};
    use crate::ops::{
        BochnerPattern, PrefactoredSpd, Restriction, VertexPattern, add_lumped_mass,
        add_lumped_mass_blocks, anisotropic_stiffness, bochner_stiffness, cotan_stiffness,
    };
    use glam::DVec3;

    #[test]
    fn matches_cholesky_on_a_mass_plus_stiffness_system() {
        // a 12×12 jittered grid, h D large enough that K matters
        let n = 12;
        let mut pos = Vec::new();
        for j in 0..n {
            for i in 0..n {
                let jit = ((i * 7 + j * 13) % 5) as f64 * 0.01;
                pos.push(DVec3::new(i as f64 * 0.1 + jit, j as f64 * 0.1 - jit, 0.0));
            }
        }
        let topo = crate::mesh::topology::grid_topology(n, n);
        let geom = Geometry::new(&topo, &pos).unwrap();
        let pattern = VertexPattern::new(&topo);
        let mut values = cotan_stiffness(&topo, &geom, &pattern, 0.05);
        add_lumped_mass(&geom, &pattern, 1.0, &mut values);
        let b: Vec<f64> = (0..2 * n * n)
            .map(|i| ((i * 31 % 17) as f64).sin())
            .collect();
        let mut direct = b.clone();
        let mut chol = PrefactoredSpd::new(pattern.clone(), Par::Seq).unwrap();
        chol.factorize(&values).unwrap();
        chol.solve_in_place(&mut direct);
        let mut cg = WarmCg::new(&pattern);
        let mut x = vec![0.0; b.len()];
        cg.solve(&values, &b, &mut x).unwrap();
        let err = x
            .iter()
            .zip(&direct)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        let scale = direct.iter().map(|v| v.abs()).fold(0.0, f64::max);
        assert!(err < 1e-10 * scale, "CG vs Cholesky: {err:e}");
        // warm-started from the solution, it converges at once
        cg.solve(&values, &b, &mut x).unwrap();
        assert!(cg.last_iterations <= 2, "{}", cg.last_iterations);
    }

    /// A grid sheared by `shear` (obtuse triangles for `shear` ≳ 0.5) with a little
    /// jitter, optionally bent around a cylinder (a curved surface: non-trivial
    /// connection).
    fn sheared_mesh(n: usize, shear: f64, bend: bool) -> (Topology, Vec<DVec3>) {
        let mut pos = Vec::new();
        for j in 0..n {
            for i in 0..n {
                let jit = ((i * 7 + j * 13) % 5) as f64 * 0.01;
                let (u, v) = (
                    i as f64 * 0.1 + shear * j as f64 * 0.1 + jit,
                    j as f64 * 0.1,
                );
                pos.push(if bend {
                    DVec3::new(u.sin(), v - jit, u.cos())
                } else {
                    DVec3::new(u, v - jit, 0.0)
                });
            }
        }
        (crate::mesh::topology::grid_topology(n, n), pos)
    }

    /// `M + K_S` on the sheared mesh, `S` anisotropic (4:1, off the grid axes), scaled so
    /// that `K` dominates: not an M-matrix (positive off-diagonal entries).
    fn obtuse_anisotropic_system(n: usize) -> (VertexPattern, Vec<f64>) {
        let (topo, pos) = sheared_mesh(n, 0.8, false);
        let geom = Geometry::new(&topo, &pos).unwrap();
        let pattern = VertexPattern::new(&topo);
        let nf = topo.n_faces();
        let mut values = anisotropic_stiffness(
            &topo,
            &geom,
            &pattern,
            &vec![0.4; nf],
            &vec![[1.0, 0.2, 0.25]; nf],
            0.1,
        );
        add_lumped_mass(&geom, &pattern, 1.0, &mut values);
        (pattern, values)
    }

    fn max_error(x: &[f64], reference: &[f64]) -> f64 {
        let err = x
            .iter()
            .zip(reference)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        err / reference.iter().map(|v| v.abs()).fold(0.0, f64::max)
    }

    #[test]
    fn preconditioners_match_cholesky_on_an_obtuse_anisotropic_mesh() {
        let n = 16;
        let (pattern, values) = obtuse_anisotropic_system(n);
        // not an M-matrix: some off-diagonal entries are positive
        let positive = (0..n * n)
            .flat_map(|j| pattern.col_ptr()[j] + 1..pattern.col_ptr()[j + 1])
            .filter(|&s| values[s as usize] > 0.0)
            .count();
        assert!(positive > 0, "the test system is an M-matrix");
        let b: Vec<f64> = (0..2 * n * n)
            .map(|i| ((i * 31 % 17) as f64).sin())
            .collect();
        let mut direct = b.clone();
        let mut chol = PrefactoredSpd::new(pattern.clone(), Par::Seq).unwrap();
        chol.factorize(&values).unwrap();
        chol.solve_in_place(&mut direct);
        let mut iterations = Vec::new();
        for p in [
            Preconditioner::Jacobi,
            Preconditioner::SymmetricGaussSeidel,
            Preconditioner::IncompleteCholesky,
        ] {
            let mut cg = WarmCg::new(&pattern).with_preconditioner(p);
            let mut x = vec![0.0; b.len()];
            cg.solve(&values, &b, &mut x).unwrap();
            let err = max_error(&x, &direct);
            assert!(err < 1e-9, "{p:?} vs Cholesky: {err:e}");
            iterations.push(cg.last_iterations);
            if p == Preconditioner::IncompleteCholesky {
                assert_eq!(cg.last_shift, 0.0, "IC(0) needed a shift");
            }
        }
        // the default is IC(0), and it pays: fewer iterations than Jacobi
        assert_eq!(
            WarmCg::new(&pattern).precond,
            Preconditioner::IncompleteCholesky
        );
        assert!(iterations[2] < iterations[0], "{iterations:?}");
    }

    /// The Bochner system (stiffness plus lumped mass) of a sheared `n × n` grid.
    fn bochner_system(n: usize) -> (BochnerPattern, Vec<f64>) {
        let (topo, pos) = sheared_mesh(n, 0.3, true);
        let geom = Geometry::new(&topo, &pos).unwrap();
        let rings = OneRings::new(&topo);
        let frames = VertexFrames::new(&rings, &pos).unwrap();
        let transport = Transport::new(&topo, &rings, &geom, &frames, &pos);
        let scalar = VertexPattern::new(&topo);
        let pattern = BochnerPattern::new(&scalar);
        let stiffness = cotan_stiffness(&topo, &geom, &scalar, 0.05);
        let mut values = bochner_stiffness(&scalar, &pattern, &stiffness, &transport);
        add_lumped_mass_blocks(&geom, &pattern, 1.0, &mut values);
        (pattern, values)
    }

    #[test]
    fn bochner_block_system_still_solves() {
        let n = 12;
        let (pattern, values) = bochner_system(n);
        let b: Vec<f64> = (0..2 * n * n)
            .map(|i| ((i * 7 % 11) as f64).cos())
            .collect();
        let mut direct = b.clone();
        let mut chol = PrefactoredSpd::new(pattern.clone(), Par::Seq).unwrap();
        chol.factorize(&values).unwrap();
        chol.solve_in_place(&mut direct);
        for p in [Preconditioner::Jacobi, Preconditioner::IncompleteCholesky] {
            let mut cg = WarmCg::new(&pattern)
                .with_tolerance(1e-12)
                .with_preconditioner(p);
            let mut x = vec![0.0; b.len()];
            cg.solve(&values, &b, &mut x).unwrap();
            let err = max_error(&x, &direct);
            assert!(err < 1e-9, "{p:?} vs Cholesky: {err:e}");
            // warm-started from the solution, it converges at once
            cg.solve(&values, &b, &mut x).unwrap();
            assert!(cg.last_iterations <= 2, "{p:?}: {}", cg.last_iterations);
        }
    }

    /// The velocity's solve without the block expansion is the expanded system's Jacobi
    /// solve to the last bit, on a restriction (a partial mask, so the edges' rotations
    /// are looked up through the restricted entries), and it solves the system.
    #[test]
    fn rotated_blocks_solve_as_the_expanded_system_bit_for_bit() {
        let n = 14;
        let (topo, pos) = sheared_mesh(n, 0.3, true);
        let geom = Geometry::new(&topo, &pos).unwrap();
        let rings = OneRings::new(&topo);
        let frames = VertexFrames::new(&rings, &pos).unwrap();
        let transport = Transport::new(&topo, &rings, &geom, &frames, &pos);
        let scalar = VertexPattern::new(&topo);
        let mask: Vec<bool> = (0..n * n).map(|v| (v % n) + v / n > 4).collect();
        let region = Restriction::new(&scalar, mask);
        let stiffness = cotan_stiffness(&topo, &geom, &scalar, 0.05);
        let values = region.scalar_values(&scalar, &stiffness, &geom.vertex_area, true);
        let blocks = region.bochner_values(&values, &transport);
        let m = region.vertices.len();
        let b: Vec<f64> = (0..2 * m).map(|i| ((i * 7 % 11) as f64).cos()).collect();
        let start: Vec<f64> = b.iter().map(|v| 0.8 * v).collect();
        let mut expanded = WarmCg::new(region.bochner())
            .with_tolerance(1e-10)
            .with_preconditioner(Preconditioner::Jacobi);
        let mut x = start.clone();
        expanded.solve(&blocks, &b, &mut x).unwrap();
        let mut rotated = WarmCg::new(region.scalar())
            .with_tolerance(1e-10)
            .with_preconditioner(Preconditioner::Jacobi);
        let mut y = start.clone();
        rotated
            .solve_rotated(
                &values,
                region.entry_edges(),
                transport.edge_cos_sin(),
                &b,
                &mut y,
            )
            .unwrap();
        assert!(expanded.last_iterations > 2);
        assert_eq!(rotated.last_iterations, expanded.last_iterations);
        assert!(x.iter().zip(&y).all(|(a, b)| a.to_bits() == b.to_bits()));
        // and it is the solution: against the Cholesky factorization of the blocks
        let mut direct = b.clone();
        let mut chol = PrefactoredSpd::new(region.bochner().clone(), Par::Seq).unwrap();
        chol.factorize(&blocks).unwrap();
        chol.solve_in_place(&mut direct);
        assert!(
            max_error(&y, &direct) < 1e-8,
            "{:e}",
            max_error(&y, &direct)
        );
        // with symmetric Gauss–Seidel on the blocks (the simulator's): the same solution
        // in fewer iterations, deterministic
        let sgs = |threads: usize| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
                .install(|| {
                    let mut cg = WarmCg::new(region.scalar())
                        .with_tolerance(1e-10)
                        .with_preconditioner(Preconditioner::SymmetricGaussSeidel);
                    let mut y = start.clone();
                    let (edges, cos_sin) = (region.entry_edges(), transport.edge_cos_sin());
                    cg.solve_rotated(&values, edges, cos_sin, &b, &mut y)
                        .unwrap();
                    (y, cg.last_iterations)
                })
        };
        let ((s1, it1), (s2, it2)) = (sgs(1), sgs(2));
        assert!(
            max_error(&s1, &direct) < 1e-8,
            "{:e}",
            max_error(&s1, &direct)
        );
        assert!(
            it1 < rotated.last_iterations,
            "{it1} vs {}",
            rotated.last_iterations
        );
        assert_eq!(it1, it2);
        assert!(s1.iter().zip(&s2).all(|(a, b)| a.to_bits() == b.to_bits()));
        // a zero right-hand side gives zero at once; a non-positive diagonal is an error
        let mut z = start.clone();
        rotated
            .solve_rotated(
                &values,
                region.entry_edges(),
                transport.edge_cos_sin(),
                &vec![0.0; 2 * m],
                &mut z,
            )
            .unwrap();
        assert!(z.iter().all(|&v| v == 0.0) && rotated.last_iterations == 0);
        let mut bad = values.clone();
        bad[region.scalar().col_ptr()[3] as usize] = -1.0;
        let err = rotated.solve_rotated(
            &bad,
            region.entry_edges(),
            transport.edge_cos_sin(),
            &b,
            &mut z,
        );
        assert!(matches!(
            err,
            Err(SolveError::NotPositiveDefinite { pivot: 6, .. })
        ));
    }

    /// A solve of a fixed right-hand side for an `m`-vertex block system: the solution
    /// and the iterations.
    fn solve(cg: &mut WarmCg, values: &[f64], m: usize) -> (Vec<f64>, usize) {
        let b: Vec<f64> = (0..2 * m).map(|i| ((i * 7 % 11) as f64).cos()).collect();
        let mut x = vec![0.0; b.len()];
        cg.solve(values, &b, &mut x).unwrap();
        (x, cg.last_iterations)
    }

    #[test]
    fn rebuilt_in_old_memory_is_new_and_its_updates_are_ic0s() {
        let (block, values) = bochner_system(12);
        let (small, small_values) = obtuse_anisotropic_system(7);
        let m = block.n();
        // large → small → large, against fresh solvers: the same iterations, the same bits
        let mut cg = WarmCg::new(&block).with_tolerance(1e-10);
        solve(&mut cg, &values, m);
        for (pattern, vals) in [(&small as &dyn LowerCsc, &small_values), (&block, &values)] {
            cg.rebuild(pattern);
            let mut fresh = WarmCg::new(pattern).with_tolerance(1e-10);
            let (x, it) = solve(&mut cg, vals, pattern.n());
            let (y, jt) = solve(&mut fresh, vals, pattern.n());
            assert_eq!(it, jt);
            assert!(x.iter().zip(&y).all(|(a, b)| a.to_bits() == b.to_bits()));
            // the updates are every (i, j) in the pattern below two entries of a column k,
            // found here by brute force
            let lower: std::collections::HashSet<(u32, u32)> = (0..cg.n)
                .flat_map(|j| {
                    let r = cg.l_ptr[j] as usize..cg.l_ptr[j + 1] as usize;
                    cg.l_row[r].iter().map(move |&i| (i, j as u32))
                })
                .collect();
            let mut expected = Vec::new();
            for k in 0..cg.n {
                let (lo, hi) = (cg.l_ptr[k] as usize, cg.l_ptr[k + 1] as usize);
                for q in lo..hi {
                    for p in q + 1..hi {
                        let (i, j) = (cg.l_row[p], cg.l_row[q]);
                        if lower.contains(&(i, j)) {
                            let c = cg.l_ptr[j as usize] as usize;
                            let t = c + cg.l_row[c..].iter().position(|&r| r == i).unwrap();
                            expected.push([t as u32, p as u32, q as u32]);
                        }
                    }
                }
            }
            assert!(!expected.is_empty());
            assert_eq!(cg.upd, expected);
        }
    }

    #[test]
    fn analysis_left_for_later_is_the_same() {
        // a solver rebuilt with another preconditioner than IC(0) analyses at its first
        // scalar solve (or never, if it only solves rotated): the same bits as a fresh one
        let (block, values) = bochner_system(9);
        let (small, small_values) = obtuse_anisotropic_system(7);
        for (first, then) in [
            (Preconditioner::SymmetricGaussSeidel, None),
            (
                Preconditioner::SymmetricGaussSeidel,
                Some(Preconditioner::IncompleteCholesky),
            ),
            (
                Preconditioner::Jacobi,
                Some(Preconditioner::SymmetricGaussSeidel),
            ),
        ] {
            let mut cg = WarmCg::new(&block)
                .with_tolerance(1e-10)
                .with_preconditioner(first);
            assert!(
                !cg.analyzed,
                "a new solver analyses at its first scalar solve"
            );
            solve(&mut cg, &values, block.n());
            for (pattern, vals) in [(&small as &dyn LowerCsc, &small_values), (&block, &values)] {
                cg.precond = first;
                cg.rebuild(pattern);
                assert!(!cg.analyzed, "{first:?}: analysed before a scalar solve");
                if let Some(p) = then {
                    cg.precond = p;
                }
                let mut fresh = WarmCg::new(pattern)
                    .with_tolerance(1e-10)
                    .with_preconditioner(then.unwrap_or(first));
                let (x, it) = solve(&mut cg, vals, pattern.n());
                let (y, jt) = solve(&mut fresh, vals, pattern.n());
                assert!(cg.analyzed);
                assert_eq!(it, jt);
                assert!(x.iter().zip(&y).all(|(a, b)| a.to_bits() == b.to_bits()));
                assert_eq!(cg.upd, fresh.upd);
                assert_eq!(cg.u_pos, fresh.u_pos);
            }
        }
    }

    #[test]
    fn bit_identical_with_one_or_two_threads() {
        let n = 24;
        let (pattern, values) = obtuse_anisotropic_system(n);
        // three columns, the second a thousand times smaller, solved side by side
        let b: Vec<f64> = (0..3 * n * n)
            .map(|i| ((i * 31 % 17) as f64).sin() * if i / (n * n) == 1 { 1e-3 } else { 1.0 })
            .collect();
        for p in [
            Preconditioner::Jacobi,
            Preconditioner::SymmetricGaussSeidel,
            Preconditioner::IncompleteCholesky,
        ] {
            let run = |threads: usize| {
                rayon::ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .build()
                    .unwrap()
                    .install(|| {
                        let mut cg = WarmCg::new(&pattern)
                            .with_tolerance(1e-9)
                            .with_preconditioner(p);
                        let mut x: Vec<f64> = b.iter().map(|v| 0.9 * v).collect();
                        cg.solve(&values, &b, &mut x).unwrap();
                        let mut y: Vec<f64> = b.iter().map(|v| 0.9 * v).collect();
                        cg.solve_chained(&values, &b, &mut y).unwrap();
                        x.extend(y);
                        (x, cg.last_iterations)
                    })
            };
            let ((x1, it1), (x2, it2)) = (run(1), run(2));
            assert_eq!(it1, it2, "{p:?}");
            assert!(
                x1.iter().zip(&x2).all(|(a, b)| a.to_bits() == b.to_bits()),
                "{p:?}: results differ between 1 and 2 threads"
            );
        }
    }

    #[test]
    fn chained_columns_match_cholesky_and_proportional_ones_are_free() {
        let n = 16;
        let (pattern, values) = obtuse_anisotropic_system(n);
        let nn = n * n;
        let b0: Vec<f64> = (0..nn)
            .map(|i| 1.0 + ((i * 31 % 17) as f64).sin())
            .collect();
        // a second, unrelated column, and multiples of the first (colour masses): the
        // warm starts are `b / 2` throughout, as the stepper's `m / A`
        let b1: Vec<f64> = (0..nn).map(|i| ((i * 7 % 11) as f64).cos()).collect();
        let columns = [b0.clone(), b0.iter().map(|v| 0.05 * v).collect(), b1];
        let b: Vec<f64> = columns.iter().flatten().copied().collect();
        let mut direct = b.clone();
        let mut chol = PrefactoredSpd::new(pattern.clone(), Par::Seq).unwrap();
        chol.factorize(&values).unwrap();
        chol.solve_in_place(&mut direct);
        let solve = |chained: bool, b: &[f64]| {
            let mut cg = WarmCg::new(&pattern).with_tolerance(1e-10);
            let mut x: Vec<f64> = b.iter().map(|v| 0.5 * v).collect();
            if chained {
                cg.solve_chained(&values, b, &mut x).unwrap();
            } else {
                cg.solve(&values, b, &mut x).unwrap();
            }
            (x, cg.last_iterations)
        };
        let (x, chained) = solve(true, &b);
        for c in 0..3 {
            let err = max_error(&x[c * nn..(c + 1) * nn], &direct[c * nn..(c + 1) * nn]);
            assert!(err < 1e-8, "column {c} vs Cholesky: {err:e}");
        }
        // the multiple stays a multiple, to rounding (a colour read as mass / solute is
        // the poured colour), as independent solves keep it (CG is scale-invariant)
        let ratio = max_error(
            &x[nn..2 * nn],
            &x[..nn].iter().map(|v| 0.05 * v).collect::<Vec<_>>(),
        );
        assert!(ratio < 1e-14, "proportional column off by {ratio:e}");
        let (_, independent) = solve(false, &b);
        let (_, first) = solve(false, &b0);
        let (_, last) = solve(false, &columns[2]);
        assert_eq!(independent, 2 * first + last);
        // the multiple of the first column starts from its solution: at most one
        // iteration (its residual is the first one's, scaled, plus rounding); the
        // unrelated column, recycled along a direction that does not help, costs at most
        // what it costs alone (the Galerkin step never makes the start worse)
        assert!(chained <= first + 1 + last, "{chained} vs {first} + {last}");
        assert!(chained < independent, "{chained} vs {independent}");
    }

    /// SPD matrices on a 4-cycle (no chords) whose IC(0) breaks down: the solve shifts
    /// the diagonal, or falls back to Jacobi, and still converges.
    #[test]
    fn incomplete_cholesky_breakdown_falls_back() {
        struct Cycle;
        impl LowerCsc for Cycle {
            fn n(&self) -> usize {
                4
            }
            fn col_ptr(&self) -> &[u32] {
                &[0, 3, 5, 7, 8]
            }
            fn row_idx(&self) -> &[u32] {
                &[0, 1, 3, 1, 2, 2, 3, 3]
            }
        }
        // off-diagonal (1,0), (3,0), (2,1), (3,2); eigenvalues ≥ 0.047 and 0.056
        for (off, shift) in [
            ([-0.27, -0.91, -0.88, 0.28], 0.1),
            ([-0.64, 0.61, -0.67, -0.66], f64::NAN),
        ] {
            let values = [1.0, off[0], off[1], 1.0, off[2], 1.0, off[3], 1.0];
            let x_true = [1.0, -2.0, 0.5, 3.0];
            let mut b = vec![0.0; 4];
            for j in 0..4 {
                for s in Cycle.col_ptr()[j]..Cycle.col_ptr()[j + 1] {
                    let (i, v) = (Cycle.row_idx()[s as usize] as usize, values[s as usize]);
                    b[i] += v * x_true[j];
                    if i != j {
                        b[j] += v * x_true[i];
                    }
                }
            }
            let mut cg = WarmCg::new(&Cycle);
            let mut x = vec![0.0; 4];
            cg.solve(&values, &b, &mut x).unwrap();
            assert!(
                cg.last_shift.to_bits() == shift.to_bits(),
                "shift {} instead of {shift}",
                cg.last_shift
            );
            assert!(max_error(&x, &x_true) < 1e-10, "{x:?}");
        }
    }
}
