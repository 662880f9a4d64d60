//! The preconditioner's factor `(I + L̃) D̃ (I + L̃)ᵀ` (`precond.rs`): its pattern and
//! IC(0)'s updates, analysed once per pattern, and its values, rebuilt every solve
//! (IC(0) with Manteuffel's shifts, or symmetric Gauss–Seidel's scaling).

use super::solver::{WarmCg, refill};

impl WarmCg {
    /// The factor's pattern (the strict lower triangle by columns and by rows) and IC(0)'s
    /// updates, from the full pattern: what [`Self::solve`] needs beyond the product
    /// (`precond.rs`). Done once per pattern, when a scalar solve first needs it, or at
    /// [`Self::rebuild`] for IC(0).
    pub(super) fn analyze(&mut self) {
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

    /// `L̃ = L D⁻¹`, `D̃ = D` (`precond.rs`): symmetric Gauss–Seidel.
    pub(super) fn gauss_seidel(&mut self, values: &[f64]) {
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
pub(super) const IC_SHIFTS: [f64; 3] = [0.0, 1e-2, 1e-1];

/// A pivot below this fraction of its (shifted) diagonal counts as a breakdown.
const MIN_PIVOT: f64 = 1e-8;

/// IC(0) of `A + shift·diag(A)` on the pattern, as `(I + L̃) D̃ (I + L̃)ᵀ` (`precond.rs`),
/// right-looking: column `k` updates the diagonal and the in-pattern entries of the
/// columns it couples, then is scaled by `1/d_k`. Returns `false` on a pivot that is not
/// positive (or not finite).
#[allow(clippy::too_many_arguments)]
pub(super) fn incomplete_cholesky(
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
