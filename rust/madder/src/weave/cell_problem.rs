//! The periodic cell problem (seed eq. 2.4) on one discretization: P1 finite elements on a
//! criss-cross triangulation of the tile as a torus, solved for an upper bound (the primal
//! problem) and a lower bound (the dual problem) of the effective tensor (eq. 2.3).
//!
//! # Discretization
//!
//! The tile is `w × h` unit square cells with a constant tensor `a` each. Every cell is
//! split into four triangles by its two diagonals (a vertex at its centre). This
//! *criss-cross* split has the full symmetry of the square: a quarter turn or a mirror of
//! the tile maps the mesh onto itself, so the discrete effective tensor of a rotated tile
//! is exactly the rotated tensor, and no direction is favoured. (A two-triangle split with
//! one diagonal direction is not invariant under a quarter turn, couples `x` and `y` on
//! tiles without a diagonal mirror, and is less accurate: 4.5% high against 3.4% on the
//! 1:10 checkerboard at 64×64.) The centre vertex touches only its own cell, so it is
//! eliminated cell by cell (static condensation, exact): what remains is one unknown per
//! cell corner, `w·h` unknowns on the torus with a 9-point stencil.
//!
//! Periodicity is topological: corner `(x, y)` is vertex `(x mod w) + w (y mod h)`.
//!
//! # Energy form (eqs. 2.3–2.4)
//!
//! For a macroscopic gradient `ξ`, the corrector `χ` minimizes the cell energy
//! `E(χ; ξ) = ∫ (ξ + ∇χ)ᵀ a (ξ + ∇χ)` over periodic P1 functions; its Euler–Lagrange
//! equation is the weak form of eq. 2.4, and the minimum is `|Y| ξᵀ A_h ξ`, which equals
//! eq. 2.3 by Galerkin orthogonality. Per cell, after condensing the centre vertex, the
//! energy is a quadratic form in `(u_0..u_3, ξ_x, ξ_y)` (corners counter-clockwise from
//! the bottom left):
//!
//! ```text
//! E_cell = [u; ξ]ᵀ [ K_c  B_c ; B_cᵀ  a ] [u; ξ]
//! ```
//!
//! (the `ξξ` block is exactly `a`: the centre's coupling to `ξ` sums to zero over the four
//! triangles). Assembled, `K χ_i = −B e_i` for `i = x, y`: **one** sparse Cholesky
//! factorization, two right-hand sides. `A_h` is then evaluated as the energy itself,
//! `A_h,ij = Σ_cells [χ_i; e_i]ᵀ M_cell [χ_j; e_j] / |Y|`, not as `⟨a⟩ − …`: the energy is
//! stationary at the discrete solution, so rounding errors of the solve enter it only
//! quadratically, and there is no cancellation when `A` is much smaller than `⟨a⟩`.
//!
//! # The null space
//!
//! On the torus `K` is singular: constants have zero energy. We pin the corrector at
//! vertex 0 (drop its row and column). The reduced matrix is SPD (the torus mesh is
//! connected), and its solution solves the full system too — the dropped equation is the
//! negative sum of the others because every right-hand side sums to zero (`Σ_v ∇φ_v = 0`).
//! Only `∇χ` enters the energy, so the constant chosen is irrelevant.
//!
//! The solution itself, `χ_x` and `χ_y` at the corners, is what
//! [`super::corrector`](mod@super::corrector) keeps for the texture (issue 13 part 4).
//!
//! # Bounds (Keller duality)
//!
//! P1 minimizes the energy over a subspace, so `A_h ≥ A` as quadratic forms: the primal
//! solve is an **upper bound**. In 2D the flux `a(ξ + ∇χ)` is divergence free, hence a
//! rotated gradient, and the medium `b = Rᵀ a⁻¹ R = a / det a` (`R` the quarter turn) has
//! effective tensor `A(b) = Rᵀ A(a)⁻¹ R = A(a) / det A(a)`. Solving the primal problem for
//! `b` bounds `A(b)` from above, so `L = U_b / det U_b ≤ A(a)`: a **lower bound** from the
//! same mesh, pattern and symbolic factorization. `[L, U]` brackets the true effective
//! tensor rigorously (up to rounding), and `U − L` is a computable error bound.
//!
//! Laminates are reproduced exactly by both: their correctors are piecewise linear in the
//! layer coordinate with kinks on cell edges, which P1 on cell-aligned triangles contains
//! (and the dual of a laminate is a laminate).
//!
//! # Cost
//!
//! `w·h − 1` unknowns, a 9-point stencil, faer's sparse Cholesky with its approximate
//! minimum degree ordering (on these tori it matched a hand-written geometric nested
//! dissection in fill and time, so we keep the library's). The symbolic analysis depends
//! only on `(w, h)`; [`Grid::shared`] keeps the last few grids, so homogenizing another
//! tile of the same size — the add-on's case while the user edits a weave — redoes only
//! the numeric factorization ([`Grid::clear_shared`] frees them).

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::llt::factor::{LltError, LltRegularization};
use faer::sparse::linalg::cholesky::{
    SymbolicCholesky, SymmetricOrdering, factorize_symbolic_cholesky,
};
use faer::sparse::{SparseColMatRef, SymbolicSparseColMatRef};
use faer::{Conj, MatMut, Par, Side};
use std::sync::{Arc, Mutex, OnceLock};

use super::check::{check_cells, scale_exponent};
use super::{Tensor2, tensor};
use crate::error::{SolveError, WeaveError};

/// Rigorous two-sided bounds on the effective tensor from one discretization.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Bounds {
    /// Primal P1 effective tensor: `A ≤ upper`.
    pub upper: Tensor2,
    /// Dual (Keller) P1 effective tensor: `lower ≤ A`.
    pub lower: Tensor2,
}

const NONE: u32 = u32::MAX;

/// How many grids [`Grid::shared`] keeps: the two levels of two tile sizes. A 128×128 grid
/// holds about 10 MB (mostly the symbolic factor).
pub(crate) const SHARED_GRIDS: usize = 4;

/// Everything about one `w × h` torus grid that does not depend on the tensors: the sparse
/// pattern of the reduced stiffness, where each cell's entries go, and the symbolic
/// Cholesky factorization.
pub struct Grid {
    w: usize,
    h: usize,
    col_ptr: Vec<u32>,
    row_idx: Vec<u32>,
    /// For cell `c` and local pair `(p, q)` (corners), the slot `cell_slot[16 c + 4 p + q]`
    /// of the lower-triangle entry it adds to, or `NONE` (upper triangle or pinned vertex).
    cell_slot: Vec<u32>,
    symbolic: SymbolicCholesky<u32>,
}

impl std::fmt::Debug for Grid {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Grid")
            .field("w", &self.w)
            .field("h", &self.h)
            .field("l_nnz", &self.symbolic.len_val())
            .finish()
    }
}

fn shared_grids() -> &'static Mutex<Vec<Arc<Grid>>> {
    static CACHE: OnceLock<Mutex<Vec<Arc<Grid>>>> = OnceLock::new();
    CACHE.get_or_init(Default::default)
}

/// Reduced (pinned) index of corner vertex `v`: vertex 0 is pinned, the others shift down.
#[inline]
fn reduced(v: usize) -> Option<usize> {
    v.checked_sub(1)
}

impl Grid {
    /// The grid of a `w × h` tile (fails on an empty one).
    pub fn new(w: usize, h: usize) -> Result<Grid, WeaveError> {
        if w == 0 || h == 0 {
            return Err(WeaveError::EmptyTile);
        }
        let nv = w * h;
        let n = nv - 1;
        // cell c's corners, counter-clockwise from the bottom left
        let corners = |c: usize| {
            let (x, y) = (c % w, c / w);
            let (x1, y1) = ((x + 1) % w, (y + 1) % h);
            [y * w + x, y * w + x1, y1 * w + x1, y1 * w + x]
        };
        // vertex v couples to the 9 corners of its 4 cells; its column keeps those with a
        // reduced index ≥ its own (the pinned vertex 0 has none), sorted, without the
        // repeats that wrapping produces on tiles 1 or 2 cells wide
        let mut col_ptr = Vec::with_capacity(n + 1);
        col_ptr.push(0u32);
        let mut row_idx = Vec::with_capacity(5 * n);
        for v in 1..nv {
            let (x, y) = (v % w, v / w);
            let mut nb = [0u32; 9];
            let mut m = 0;
            for dy in [h - 1, 0, 1] {
                for dx in [w - 1, 0, 1] {
                    let u = ((y + dy) % h) * w + (x + dx) % w;
                    if u >= v {
                        nb[m] = (u - 1) as u32;
                        m += 1;
                    }
                }
            }
            let nb = &mut nb[..m];
            nb.sort_unstable();
            for (i, &r) in nb.iter().enumerate() {
                if i == 0 || r != nb[i - 1] {
                    row_idx.push(r);
                }
            }
            col_ptr.push(row_idx.len() as u32);
        }
        let mut cell_slot = vec![NONE; 16 * nv];
        for c in 0..nv {
            let g = corners(c);
            for p in 0..4 {
                for q in 0..4 {
                    if let (Some(r), Some(k)) = (reduced(g[p]), reduced(g[q])) {
                        if r >= k {
                            let (lo, hi) = (col_ptr[k] as usize, col_ptr[k + 1] as usize);
                            let s = lo + row_idx[lo..hi].binary_search(&(r as u32)).unwrap();
                            cell_slot[16 * c + 4 * p + q] = s as u32;
                        }
                    }
                }
            }
        }
        let sym = SymbolicSparseColMatRef::new_checked(n, n, &col_ptr, None, &row_idx);
        let symbolic = factorize_symbolic_cholesky(
            sym,
            Side::Lower,
            SymmetricOrdering::Amd,
            Default::default(),
        )
        .map_err(|_| SolveError::OutOfMemory)?;
        Ok(Grid {
            w,
            h,
            col_ptr,
            row_idx,
            cell_slot,
            symbolic,
        })
    }

    /// The `w × h` grid from a small process-wide cache of the most recently used ones
    /// ([`SHARED_GRIDS`]), built on a miss. A grid is a pure function of its size, so
    /// sharing it changes no result.
    pub(crate) fn shared(w: usize, h: usize) -> Result<Arc<Grid>, WeaveError> {
        let lock = || shared_grids().lock().unwrap_or_else(|e| e.into_inner());
        {
            let mut c = lock();
            if let Some(i) = c.iter().position(|g| g.w == w && g.h == h) {
                let g = c.remove(i);
                c.insert(0, g.clone());
                return Ok(g);
            }
        }
        let g = Arc::new(Grid::new(w, h)?);
        let mut c = lock();
        c.insert(0, g.clone());
        c.truncate(SHARED_GRIDS);
        Ok(g)
    }

    /// Drops the grids kept by [`Grid::shared`] (their memory is freed once no solve holds
    /// them).
    pub fn clear_shared() {
        shared_grids()
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .clear();
    }

    /// Number of nonzeros of the Cholesky factor.
    pub fn factor_nnz(&self) -> usize {
        self.symbolic.len_val()
    }

    /// The primal P1 effective tensor `A_h ≥ A` of the `w × h` tile with per-cell tensors
    /// `a` (row-major, row 0 at the bottom). A tensor that is not finite and SPD is an
    /// error naming its cell ([`check_cells`]). The solve runs on the tile scaled by a
    /// power of two to order 1 (exact; `A_h` is 1-homogeneous in `a`), so any magnitude
    /// works.
    pub fn effective(&self, a: &[Tensor2]) -> Result<Tensor2, WeaveError> {
        let (w, h) = (self.w, self.h);
        check_cells(w, h, a)?;
        let k = scale_exponent(a);
        self.effective_scaled(a, k).map(|t| tensor::scale(t, k))
    }

    /// [`Grid::effective`] of the checked tile `a · 2^-k`.
    fn effective_scaled(&self, a: &[Tensor2], k: i32) -> Result<Tensor2, WeaveError> {
        self.solve_scaled(a, k).map(|(e, _)| e)
    }

    /// The primal solve of [`Grid::effective_scaled`], keeping its solution: the effective
    /// tensor of `a · 2^−k` and the correctors `[χ_x, χ_y]` of `e_x`, `e_y` at the `w·h`
    /// corner vertices (row-major, row 0 at the bottom; pinned: `χ = 0` at vertex 0).
    /// The correctors of `a · 2^−k` and of `a` are the same (eq. 2.4 is homogeneous in `a`).
    pub(crate) fn solve_scaled(
        &self,
        a: &[Tensor2],
        k: i32,
    ) -> Result<(Tensor2, [Vec<f64>; 2]), WeaveError> {
        let (w, h) = (self.w, self.h);
        let nv = w * h;
        if nv == 1 {
            // one cell: its four corners are one (pinned) vertex, and the condensed centre
            // does not couple to ξ, so the energy is ξᵀaξ
            return Ok((tensor::scale(a[0], -k), [vec![0.0], vec![0.0]]));
        }
        let n = nv - 1;
        let forms: Vec<CellForm> = a
            .iter()
            .map(|&t| CellForm::new(tensor::scale(t, -k)))
            .collect();
        let corners = |c: usize| {
            let (x, y) = (c % w, c / w);
            let (x1, y1) = ((x + 1) % w, (y + 1) % h);
            [y * w + x, y * w + x1, y1 * w + x1, y1 * w + x]
        };

        // assemble K (lower triangle) and the two right-hand sides −B e_x, −B e_y
        let mut values = vec![0.0; self.row_idx.len()];
        let mut rhs = vec![0.0; 2 * n];
        for (c, f) in forms.iter().enumerate() {
            let slots = &self.cell_slot[16 * c..16 * c + 16];
            for (s, k) in slots.iter().zip(&f.k) {
                if *s != NONE {
                    values[*s as usize] += k;
                }
            }
            for (p, v) in corners(c).into_iter().enumerate() {
                if let Some(r) = reduced(v) {
                    rhs[r] -= f.b[p][0];
                    rhs[n + r] -= f.b[p][1];
                }
            }
        }

        // factorize once, solve both
        let par = Par::Seq;
        let req = self
            .symbolic
            .factorize_numeric_llt_scratch::<f64>(par, Default::default())
            .or(self.symbolic.solve_in_place_scratch::<f64>(2, par));
        let mut scratch = MemBuffer::try_new(req).map_err(|_| SolveError::OutOfMemory)?;
        let mut l_values = vec![0.0; self.symbolic.len_val()];
        let sym = SymbolicSparseColMatRef::new_checked(n, n, &self.col_ptr, None, &self.row_idx);
        let llt =
            self.symbolic
                .factorize_numeric_llt(
                    &mut l_values,
                    SparseColMatRef::new(sym, &values),
                    Side::Lower,
                    LltRegularization::default(),
                    par,
                    MemStack::new(&mut scratch),
                    Default::default(),
                )
                .map_err(|LltError::NonPositivePivot { index }| {
                    SolveError::NotPositiveDefinite { pivot: index, n }
                })?;
        llt.solve_in_place_with_conj(
            Conj::No,
            MatMut::from_column_major_slice_mut(&mut rhs, n, 2),
            par,
            MemStack::new(&mut scratch),
        );

        // the energy, cell by cell (pinned vertex: χ = 0)
        let chi = [0, 1].map(|i| {
            (0..nv)
                .map(|v| reduced(v).map_or(0.0, |r| rhs[i * n + r]))
                .collect::<Vec<f64>>()
        });
        Ok((cell_energy(w, h, &forms, &chi), chi))
    }

    /// Both bounds on this grid (the dual solve reuses the pattern and symbolic
    /// factorization). With `parallel`, the two solves run on two threads; each is
    /// sequential inside, so the result is the same bits either way. Checked and scaled
    /// as [`Grid::effective`]; the dual medium is formed from the scaled tensors, whose
    /// determinants neither underflow nor overflow.
    pub fn bounds(&self, a: &[Tensor2], parallel: bool) -> Result<Bounds, WeaveError> {
        check_cells(self.w, self.h, a)?;
        let k = scale_exponent(a);
        let dual = || {
            let b: Vec<Tensor2> = a
                .iter()
                .map(|&t| tensor::keller_dual(tensor::scale(t, -k)))
                .collect();
            self.effective_scaled(&b, 0).map(tensor::keller_dual)
        };
        let (upper, lower) = if parallel {
            rayon::join(|| self.effective_scaled(a, k), dual)
        } else {
            (self.effective_scaled(a, k), dual())
        };
        Ok(Bounds {
            upper: tensor::scale(upper?, k),
            lower: tensor::scale(lower?, k),
        })
    }
}

/// `⟨(e_i + ∇χ_i)ᵀ a (e_j + ∇χ_j)⟩` over the `w × h` torus (eq. 2.3 as an energy, module
/// doc), `χ` given at the corner vertices (the condensed centres take their optimal
/// values): the P1 effective tensor when `χ` solves the cell problem.
fn cell_energy(w: usize, h: usize, forms: &[CellForm], chi: &[Vec<f64>; 2]) -> Tensor2 {
    let mut e = [0.0; 3];
    for (c, f) in forms.iter().enumerate() {
        let (x, y) = (c % w, c / w);
        let (x1, y1) = ((x + 1) % w, (y + 1) % h);
        let g = [y * w + x, y * w + x1, y1 * w + x1, y1 * w + x];
        let u = [g.map(|v| chi[0][v]), g.map(|v| chi[1][v])];
        for (slot, (i, j)) in [(0, 0), (0, 1), (1, 1)].into_iter().enumerate() {
            e[slot] += f.energy(&u[i], i, &u[j], j);
        }
    }
    let area = (w * h) as f64;
    [e[0] / area, e[1] / area, e[2] / area]
}

/// [`cell_energy`] of the tensors `a` (unscaled), for a corrector computed elsewhere.
pub(crate) fn corrector_energy(w: usize, h: usize, a: &[Tensor2], chi: &[Vec<f64>; 2]) -> Tensor2 {
    let forms: Vec<CellForm> = a.iter().map(|&t| CellForm::new(t)).collect();
    cell_energy(w, h, &forms, chi)
}

/// The condensed quadratic form of one unit cell with tensor `a`: corner block `k` (4×4,
/// row-major), corner–gradient block `b` (4×2); the gradient–gradient block is `a` itself.
struct CellForm {
    a: Tensor2,
    k: [f64; 16],
    b: [[f64; 2]; 4],
}

/// Gradients of the P1 hat functions of the criss-cross triangles of the unit cell, for
/// local vertices 0..3 (corners `(0,0), (1,0), (1,1), (0,1)`) and 4 (centre). Triangle `t`
/// is `(corner t, corner t+1, centre)`, area ¼; a hat's gradient is the inward normal of
/// the opposite edge over twice the area, `(−e_y, e_x) / 2|T|`.
const GRADS: [[[f64; 2]; 5]; 4] = {
    let mut g = [[[0.0; 2]; 5]; 4];
    let p = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0], [0.5, 0.5]];
    let mut t = 0;
    while t < 4 {
        let v = [t, (t + 1) % 4, 4];
        let mut k = 0;
        while k < 3 {
            let (a, b) = (p[v[(k + 1) % 3]], p[v[(k + 2) % 3]]);
            g[t][v[k]] = [-(b[1] - a[1]) * 2.0, (b[0] - a[0]) * 2.0];
            k += 1;
        }
        t += 1;
    }
    g
};

/// The 5×5 cell stiffness `Q = Σ_t |T| Gᵀ a G` is linear in `(a11, a12, a22)`:
/// `Q = a11 Q[0] + a12 Q[1] + a22 Q[2]`. `C[p] = Σ_t |T| ∇φ_p` gives the coupling to the
/// macroscopic gradient, `a · C[p]`.
const BASIS: ([[[f64; 5]; 5]; 3], [[f64; 2]; 5]) = {
    let mut q = [[[0.0; 5]; 5]; 3];
    let mut c = [[0.0; 2]; 5];
    let mut t = 0;
    while t < 4 {
        let g = GRADS[t];
        let mut p = 0;
        while p < 5 {
            c[p][0] += 0.25 * g[p][0];
            c[p][1] += 0.25 * g[p][1];
            let mut r = 0;
            while r < 5 {
                q[0][p][r] += 0.25 * g[p][0] * g[r][0];
                q[1][p][r] += 0.25 * (g[p][0] * g[r][1] + g[p][1] * g[r][0]);
                q[2][p][r] += 0.25 * g[p][1] * g[r][1];
                r += 1;
            }
            p += 1;
        }
        t += 1;
    }
    (q, c)
};

impl CellForm {
    fn new(a: Tensor2) -> CellForm {
        let (qb, cb) = &BASIS;
        let q = |p: usize, r: usize| a[0] * qb[0][p][r] + a[1] * qb[1][p][r] + a[2] * qb[2][p][r];
        // condense the centre (index 4): Schur complement. Its coupling to ξ, a·C[4], is
        // zero (the centre hat's gradients cancel over the four triangles).
        let q44 = q(4, 4);
        let q4 = [q(0, 4), q(1, 4), q(2, 4), q(3, 4)];
        let mut k = [0.0; 16];
        for p in 0..4 {
            for r in 0..4 {
                k[4 * p + r] = q(p, r) - q4[p] * q4[r] / q44;
            }
        }
        let b = [0, 1, 2, 3].map(|p| tensor::apply(a, cb[p]));
        CellForm { a, k, b }
    }

    /// `[u; e_i]ᵀ M [v; e_j]` for corner values `u`, `v`.
    fn energy(&self, u: &[f64; 4], i: usize, v: &[f64; 4], j: usize) -> f64 {
        let mut s = tensor::entry(self.a, i, j);
        for p in 0..4 {
            let k = &self.k[4 * p..4 * p + 4];
            let kv = k[0] * v[0] + k[1] * v[1] + k[2] * v[2] + k[3] * v[3];
            s += u[p] * kv + u[p] * self.b[p][j] + v[p] * self.b[p][i];
        }
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn centre_hat_does_not_couple_to_the_macroscopic_gradient() {
        assert_eq!(BASIS.1[4], [0.0, 0.0]);
        // and the corner couplings sum to zero (Σ_p ∇φ_p = 0)
        let s: [f64; 2] = [0, 1].map(|i| (0..4).map(|p| BASIS.1[p][i]).sum());
        assert_eq!(s, [0.0, 0.0]);
    }

    #[test]
    fn condensed_cell_form_is_exact_for_linear_fields() {
        // a linear u = g·x on the corners with ξ = −g has zero energy (∇u + ξ = 0), and
        // the form annihilates constants
        let f = CellForm::new([3.0, 0.7, 2.0]);
        for p in 0..4 {
            let row: f64 = f.k[4 * p..4 * p + 4].iter().sum();
            assert!(row.abs() < 1e-14);
        }
        let g = [0.3, -1.1];
        let corners = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]];
        let u = corners.map(|c| g[0] * c[0] + g[1] * c[1]);
        // E(u, ξ) = uᵀKu + 2uᵀBξ + ξᵀaξ with ξ = −g
        let xi = [-g[0], -g[1]];
        let mut e = tensor::quad(f.a, xi);
        for p in 0..4 {
            for r in 0..4 {
                e += u[p] * f.k[4 * p + r] * u[r];
            }
            e += 2.0 * u[p] * (f.b[p][0] * xi[0] + f.b[p][1] * xi[1]);
        }
        assert!(e.abs() < 1e-13, "{e}");
    }

    #[test]
    fn homogeneous_medium_is_its_own_effective_tensor() {
        let a = [2.0, -0.4, 5.0];
        for (w, h) in [(1, 1), (2, 1), (1, 3), (4, 4), (5, 3)] {
            let grid = Grid::new(w, h).unwrap();
            let b = grid.bounds(&vec![a; w * h], false).unwrap();
            for (k, ak) in a.iter().enumerate() {
                assert!((b.upper[k] - ak).abs() < 1e-12, "{w}×{h} {b:?}");
                assert!((b.lower[k] - ak).abs() < 1e-12, "{w}×{h} {b:?}");
            }
        }
    }
}
