//! Sparse symmetric positive definite solves with faer's Cholesky (`LLᵀ`).
//!
//! [`PrefactoredSpd`] is the time-stepper's solver: the symbolic analysis (fill-reducing
//! AMD ordering, elimination tree, supernode structure) depends only on the
//! [`VertexPattern`], which is fixed for a bake, so it is computed once; each frame only
//! refactorizes numerically, into buffers that are allocated once. [`solve_spd`] is the
//! one-shot form.
//!
//! The solver works on any fixed lower-triangular CSC pattern ([`LowerCsc`]): the scalar
//! [`VertexPattern`] (the default) or, e.g., the `2N×2N` block pattern of the connection
//! Laplacian ([`crate::ops::bochner::BochnerPattern`]).
//!
//! Parallelism is an argument ([`faer::Par`]); the factorization and the triangular solves
//! follow the elimination tree in a fixed order, and the default `Par::Seq` is bit-identical
//! across runs and machines of one architecture.

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::llt::factor::LltError;
use faer::linalg::cholesky::llt::factor::LltRegularization;
use faer::sparse::linalg::SupernodalThreshold;
use faer::sparse::linalg::cholesky::{
    CholeskySymbolicParams, SymbolicCholesky, factorize_symbolic_cholesky,
};
use faer::sparse::{SparseColMatRef, SymbolicSparseColMatRef};
use faer::{Conj, MatMut, Par, Side};

use super::VertexPattern;
use crate::error::SolveError;

/// A fixed sparsity pattern: the lower triangle (diagonal included) of a symmetric
/// `n×n` matrix in compressed sparse column form, rows sorted and unique within each
/// column. (An invalid pattern makes [`PrefactoredSpd::new`] panic: it is a programming
/// error, not an input error.)
pub trait LowerCsc {
    /// Matrix dimension.
    fn n(&self) -> usize;
    /// Column pointers (`n + 1` entries).
    fn col_ptr(&self) -> &[u32];
    /// Row index of every stored entry.
    fn row_idx(&self) -> &[u32];
    /// Number of stored entries.
    fn nnz(&self) -> usize {
        self.row_idx().len()
    }
}

impl LowerCsc for VertexPattern {
    fn n(&self) -> usize {
        VertexPattern::n(self)
    }
    fn col_ptr(&self) -> &[u32] {
        VertexPattern::col_ptr(self)
    }
    fn row_idx(&self) -> &[u32] {
        VertexPattern::row_idx(self)
    }
}

/// A sparse SPD system on a fixed pattern, factorized anew for each set of values.
pub struct PrefactoredSpd<P: LowerCsc = VertexPattern> {
    pattern: P,
    symbolic: SymbolicCholesky<u32>,
    l_values: Vec<f64>,
    scratch: MemBuffer,
    /// Right-hand-side columns the scratch buffer can solve at once.
    scratch_cols: usize,
    par: Par,
    factorized: bool,
}

impl<P: LowerCsc> std::fmt::Debug for PrefactoredSpd<P> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PrefactoredSpd")
            .field("n", &self.pattern.n())
            .field("l_nnz", &self.l_values.len())
            .finish()
    }
}

impl<P: LowerCsc> PrefactoredSpd<P> {
    /// Symbolic analysis of `pattern` (lower triangle).
    pub fn new(pattern: P, par: Par) -> Result<Self, SolveError> {
        Self::with_params(pattern, par, Default::default())
    }

    /// Symbolic analysis of `pattern` for a simplicial (column by column) factor, whatever
    /// its fill. For very sparse factors (a graph Laplacian of a surface mesh: ~30–50
    /// entries a column) the supernodes are so small that the supernodal triangular solve
    /// spends its time in per-supernode dense kernels; the simplicial solve streams the
    /// factor once for up to four right-hand sides at a time (measured in
    /// `angles::track`).
    pub fn new_simplicial(pattern: P) -> Result<Self, SolveError> {
        let params = CholeskySymbolicParams {
            supernodal_flop_ratio_threshold: SupernodalThreshold::FORCE_SIMPLICIAL,
            ..Default::default()
        };
        Self::with_params(pattern, Par::Seq, params)
    }

    fn with_params(
        pattern: P,
        par: Par,
        params: CholeskySymbolicParams<'_>,
    ) -> Result<Self, SolveError> {
        let n = pattern.n();
        let sym = symbolic_view(&pattern);
        let symbolic = factorize_symbolic_cholesky(sym, Side::Lower, Default::default(), params)
            .map_err(|_| SolveError::OutOfMemory)?;
        let req = symbolic
            .factorize_numeric_llt_scratch::<f64>(par, Default::default())
            .or(symbolic.solve_in_place_scratch::<f64>(1, par));
        let scratch = MemBuffer::try_new(req).map_err(|_| SolveError::OutOfMemory)?;
        let l_values = vec![0.0; symbolic.len_val()];
        debug_assert_eq!(symbolic.nrows(), n);
        Ok(Self {
            pattern,
            symbolic,
            l_values,
            scratch,
            scratch_cols: 1,
            par,
            factorized: false,
        })
    }

    pub(crate) fn pattern(&self) -> &P {
        &self.pattern
    }

    /// Numeric factorization of the matrix whose lower triangle is `values` (on the pattern).
    pub fn factorize(&mut self, values: &[f64]) -> Result<(), SolveError> {
        assert_eq!(
            values.len(),
            self.pattern.nnz(),
            "values do not match the pattern"
        );
        self.factorized = false;
        let a = SparseColMatRef::new(symbolic_view(&self.pattern), values);
        let n = self.pattern.n();
        self.symbolic
            .factorize_numeric_llt(
                &mut self.l_values,
                a,
                Side::Lower,
                LltRegularization::default(),
                self.par,
                MemStack::new(&mut self.scratch),
                Default::default(),
            )
            .map_err(
                |LltError::NonPositivePivot { index }| SolveError::NotPositiveDefinite {
                    pivot: index,
                    n,
                },
            )?;
        self.factorized = true;
        Ok(())
    }

    /// Solves `A x = rhs` in place with the last factorization. `rhs` holds one or more
    /// right-hand sides, column-major (`k` columns of `n`), all solved together.
    pub fn solve_in_place(&mut self, rhs: &mut [f64]) {
        assert!(
            self.factorized,
            "solve_in_place called before a successful factorize"
        );
        let n = self.pattern.n();
        assert!(
            n > 0 && rhs.len() % n == 0,
            "right-hand side is not a whole number of columns"
        );
        let k = rhs.len() / n;
        if k > self.scratch_cols {
            let req = self
                .symbolic
                .factorize_numeric_llt_scratch::<f64>(self.par, Default::default())
                .or(self.symbolic.solve_in_place_scratch::<f64>(k, self.par));
            self.scratch = MemBuffer::new(req);
            self.scratch_cols = k;
        }
        solve_block(
            &self.symbolic,
            &self.l_values,
            self.par,
            &mut self.scratch,
            rhs,
            n,
        );
    }
}

/// `k = rhs.len() / n` columns solved with the factor `symbolic`, `values`.
fn solve_block(
    symbolic: &SymbolicCholesky<u32>,
    values: &[f64],
    par: Par,
    scratch: &mut MemBuffer,
    rhs: &mut [f64],
    n: usize,
) {
    let k = rhs.len() / n;
    let llt = faer::sparse::linalg::cholesky::LltRef::<'_, u32, f64>::new(symbolic, values);
    let rhs = MatMut::from_column_major_slice_mut(rhs, n, k);
    llt.solve_in_place_with_conj(Conj::No, rhs, par, MemStack::new(scratch));
}

impl<P: LowerCsc + Sync> PrefactoredSpd<P> {
    /// Solves like [`Self::solve_in_place`], the columns in two fixed groups (the first
    /// `split` columns, then the rest) solved as two rayon tasks, in parallel when a second
    /// thread is free. Each group is the same computation whatever the thread count, so the
    /// result is bit-identical on any number of threads (a group's bits may differ from
    /// solving all columns at once).
    pub fn solve_in_place_split(&mut self, rhs: &mut [f64], split: usize) {
        assert!(
            self.factorized,
            "solve_in_place_split called before a successful factorize"
        );
        let n = self.pattern.n();
        assert!(
            n > 0 && rhs.len() % n == 0 && split * n <= rhs.len(),
            "right-hand side is not a whole number of columns"
        );
        let (first, second) = rhs.split_at_mut(split * n);
        let (symbolic, values, par) = (&self.symbolic, &self.l_values[..], self.par);
        let solve = |block: &mut [f64]| {
            let k = block.len() / n;
            if k > 0 {
                let req = symbolic.solve_in_place_scratch::<f64>(k, par);
                solve_block(symbolic, values, par, &mut MemBuffer::new(req), block, n);
            }
        };
        rayon::join(|| solve(first), || solve(second));
    }
}

/// One-shot solve of `A x = rhs` for the SPD matrix whose lower triangle is `values`.
pub fn solve_spd(
    pattern: &VertexPattern,
    values: &[f64],
    rhs: &[f64],
) -> Result<Vec<f64>, SolveError> {
    let mut s = PrefactoredSpd::new(pattern.clone(), Par::Seq)?;
    s.factorize(values)?;
    let mut x = rhs.to_vec();
    s.solve_in_place(&mut x);
    Ok(x)
}

fn symbolic_view<P: LowerCsc>(p: &P) -> SymbolicSparseColMatRef<'_, u32> {
    SymbolicSparseColMatRef::new_checked(p.n(), p.n(), p.col_ptr(), None, p.row_idx())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::Topology;

    #[test]
    fn solves_a_path_laplacian_plus_identity() {
        // path 0–1–2–3 as a degenerate "mesh" of two fans: use triangles [0,1,2],[1,2,3]
        let t = Topology::from_triangles(4, vec![[0, 1, 2], [1, 3, 2]]).unwrap();
        let p = VertexPattern::new(&t);
        // A = 4 I + (−1 on every edge)
        let mut v = vec![0.0; p.nnz()];
        p.diag_slot().iter().for_each(|&s| v[s as usize] = 4.0);
        p.edge_slot().iter().for_each(|&s| v[s as usize] = -1.0);
        let x_true = [1.0, -2.0, 0.5, 3.0];
        let b = p.sym_matvec(&v, &x_true);
        let x = solve_spd(&p, &v, &b).unwrap();
        for (a, b) in x.iter().zip(x_true) {
            assert!((a - b).abs() < 1e-14);
        }
        // refactorizing with new values reuses the symbolic analysis
        let mut s = PrefactoredSpd::new(p.clone(), Par::Seq).unwrap();
        for scale in [1.0, 2.0, 5.0] {
            let w: Vec<f64> = v.iter().map(|x| x * scale).collect();
            s.factorize(&w).unwrap();
            let mut y = p.sym_matvec(&w, &x_true);
            s.solve_in_place(&mut y);
            assert!(y.iter().zip(x_true).all(|(a, b)| (a - b).abs() < 1e-13));
        }
    }

    /// A dense lower triangle in CSC form, to check the solver on a non-vertex pattern.
    struct Dense(usize, Vec<u32>, Vec<u32>);
    impl LowerCsc for Dense {
        fn n(&self) -> usize {
            self.0
        }
        fn col_ptr(&self) -> &[u32] {
            &self.1
        }
        fn row_idx(&self) -> &[u32] {
            &self.2
        }
    }

    #[test]
    fn solves_on_a_generic_lower_pattern() {
        // A = [4 1 0; 1 3 −1; 0 −1 2]; lower triangle by columns: (0,0) (1,0) (2,0) …
        let p = Dense(3, vec![0, 3, 5, 6], vec![0, 1, 2, 1, 2, 2]);
        let v = [4.0, 1.0, 0.0, 3.0, -1.0, 2.0];
        let mut s = PrefactoredSpd::new(p, Par::Seq).unwrap();
        s.factorize(&v).unwrap();
        // A (1, 2, 3) = (6, 4, 4)
        let mut x = [6.0, 4.0, 4.0];
        s.solve_in_place(&mut x);
        for (a, b) in x.iter().zip([1.0, 2.0, 3.0]) {
            assert!((a - b).abs() < 1e-14, "{a} vs {b}");
        }
    }

    #[test]
    fn indefinite_matrix_is_reported() {
        let t = Topology::from_triangles(3, vec![[0, 1, 2]]).unwrap();
        let p = VertexPattern::new(&t);
        let mut v = vec![0.0; p.nnz()];
        p.diag_slot().iter().for_each(|&s| v[s as usize] = -1.0);
        assert!(matches!(
            solve_spd(&p, &v, &[1.0; 3]),
            Err(SolveError::NotPositiveDefinite { .. })
        ));
    }
}
