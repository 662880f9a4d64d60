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
//! The iteration itself is faer's. A hand-written Jacobi-PCG with the same stopping rule
//! (three fused passes per iteration, no allocation) measured a little faster (faer runs
//! a single column's vector updates through its dense block product); we keep the
//! library's, as the project's dependency policy asks.
//!
//! One file per concern, each with the details it implements:
//! - `solver.rs`: [`WarmCg`]'s state, tolerance and CG work space;
//! - `pattern.rs`: [`WarmCg::new`] and [`WarmCg::rebuild`], the full symmetric pattern
//!   expanded from the lower triangle;
//! - `product.rs`: the product `A x`, bit-identical to faer's, and its faer operator;
//! - `precond.rs`: the preconditioners (Jacobi, symmetric Gauss–Seidel, IC(0)) and their
//!   sweeps `M⁻¹ r`;
//! - `factor.rs`: the incomplete factor's pattern (analysed once per pattern) and values
//!   (every solve);
//! - `solve.rs`: the warm-started CG driver ([`WarmCg::solve`]), one column per
//!   right-hand side;
//! - `chained.rs`: related columns ([`WarmCg::solve_chained`]), each warm start improved
//!   along the previous column's correction;
//! - `rotated.rs`: the velocity's rotated-block system on the scalar pattern
//!   ([`WarmCg::solve_rotated`]).

mod chained;
mod factor;
mod pattern;
mod precond;
mod product;
mod rotated;
mod solve;
mod solver;
#[cfg(test)]
mod tests;

pub use precond::Preconditioner;
pub use solver::WarmCg;
