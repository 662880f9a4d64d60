//! Setting a [`WarmCg`] up on a pattern: the lower triangle ([`LowerCsc`]) expanded once
//! into the full symmetric pattern that the product multiplies with, with the lower slot of
//! every full entry, so each solve only gathers values (`product.rs`).
//!
//! The expansion is all a solver of rotated blocks ([`WarmCg::solve_rotated`]) needs; the
//! factor's pattern and IC(0)'s updates (below) are analysed when a solver is rebuilt for
//! IC(0), or else at its first scalar solve, so the window's velocity solver never pays
//! for them.

use super::precond::Preconditioner;
use super::solver::{RELATIVE_TOLERANCE, WarmCg, refill};
use crate::ops::solve::LowerCsc;

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
}
