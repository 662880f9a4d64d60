//! Related columns ([`WarmCg::solve_chained`]): each column's warm start improved along
//! the correction the previous column's solve made.
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
//! [`WarmCg::solve_chained`]: super::WarmCg::solve_chained

use super::product::SymOp;

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
pub(super) fn recycle(
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
