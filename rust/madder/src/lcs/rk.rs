//! The explicit Runge–Kutta schemes of the particle tracer (§5.5.1: "integrate the
//! particles' paths"): fixed steps, the classical RK4 and an eighth-order scheme.
//!
//! ## The schemes
//! An explicit `s`-stage scheme with tableau `(a_ij, b_j, c_i)` advances `p` by one step
//! `h` through the stage points and velocities
//!
//! ```text
//! y_i = p + h Σ_{j<i} a_ij k_j,   k_i = v(t + c_i h, y_i),   p' = p + h Σ_j b_j k_j.
//! ```
//!
//! - [`Scheme::Rk4`]: the classical fourth-order method, 4 stages (`c = 0, ½, ½, 1`).
//! - [`Scheme::Rk8`]: the eighth-order solution of Dormand and Prince's 8(5,3) pair
//!   ("DOP853", Hairer, Nørsett & Wanner, *Solving ODEs I*, §II.10), 12 stages, used with
//!   fixed steps (no error estimate, no step control): results stay deterministic and
//!   every stage's displacement is an explicit combination of the `k_j`, which is all the
//!   walks and the flat path's clearance test need. On the double gyre at 401×201,
//!   T = −10 it reaches numbacs' integration error at rtol 1e-4 in 6 steps, 72
//!   evaluations, where RK4 takes 21 steps, 84 (ARCHITECTURE.md); its global error is
//!   `O(h⁸)` (`tests/rk8.rs` measures the order). Its stage points jump back and forth in
//!   time (`c` = 0, 0.05, 0.08, 0.12, 0.28, 0.33, 0.25, 0.31, 0.65, 0.6, 0.86, 1), which
//!   decides how far the walks go (next section).
//!
//! ## Walking from stage point to stage point
//! The tracer reaches stage point `y_i` from an earlier stage point `y_{src(i)}`, not from
//! `p` ([`super::trace`], "Integrator"): by `h Σ_j (a_ij − a_{src(i),j}) k_j`, and the
//! step's end from the last stage point by `h Σ_j (b_j − a_{s−1,j}) k_j` ([`Moves`]).
//! `src(i)` is the earlier stage nearest in time (ties: the later), since a walk's length,
//! and so its cost, is about `|c_i − c_src| h |v|`. For RK4 that is the stage before
//! (`c` increases), a walk of about one step's displacement per step. For RK8, walking from
//! the stage before would cover `Σ |c_i − c_{i−1}| ≈ 1.27` steps' displacement; from the
//! nearest (stage 6 from 4, 7 and 8 from 5, 10 from 8) about 1.11, 12% fewer crossings on
//! the curved bench. The stage points are kept per particle in a few slots, each reused
//! once no later walk starts from it (3 for RK8, 2 for RK4).
//!
//! On a flat or developable mesh these are the same points as from `p`, up to rounding and
//! to walks stopped at a border (a stage point stopped at a border is where the walks from
//! it start: which stage a walk starts from matters there; the flat path
//! (`trace/planar.rs`) walks from the same sources, so the two agree). On a curved mesh they
//! differ by the holonomy of the vertices passed, a discretization error of the
//! unfolding's order. Stage `c_i = 1` is evaluated at the step's end time computed as
//! `t0 + (n + 1) h`, so it lands on the frames' times exactly.

use glam::DVec2;

/// An explicit fixed-step Runge–Kutta scheme for the particles (module doc).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Scheme {
    /// Classical RK4: 4 stages, order 4.
    #[default]
    Rk4,
    /// Dormand–Prince's eighth-order solution (DOP853's), fixed steps: 12 stages, order 8.
    Rk8,
}

impl Scheme {
    /// The scheme named `"rk4"` or `"rk8"`.
    pub fn from_name(name: &str) -> Option<Self> {
        match name {
            "rk4" => Some(Self::Rk4),
            "rk8" => Some(Self::Rk8),
            _ => None,
        }
    }

    /// Velocity evaluations per step.
    pub fn stages(self) -> usize {
        self.tableau().c.len()
    }

    /// The order of the global error.
    pub fn order(self) -> usize {
        match self {
            Self::Rk4 => 4,
            Self::Rk8 => 8,
        }
    }

    fn tableau(self) -> &'static Tableau {
        match self {
            Self::Rk4 => &RK4,
            Self::Rk8 => &RK8,
        }
    }
}

/// A Butcher tableau: `a[i − 1]` holds row `i`'s `a_ij`, `j < i` (row 0 is empty).
struct Tableau {
    a: &'static [&'static [f64]],
    b: &'static [f64],
    c: &'static [f64],
}

const RK4: Tableau = Tableau {
    a: &[&[0.5], &[0.0, 0.5], &[0.0, 0.0, 1.0]],
    b: &[1.0 / 6.0, 1.0 / 3.0, 1.0 / 3.0, 1.0 / 6.0],
    c: &[0.0, 0.5, 0.5, 1.0],
};

/// DOP853's first 12 stages and its eighth-order weights (Hairer, Nørsett & Wanner; the
/// coefficients as printed there, to double precision).
#[allow(clippy::excessive_precision, clippy::unreadable_literal)]
const RK8: Tableau = Tableau {
    a: &[
        &[0.05260015195876773],
        &[0.0197250569845379, 0.0591751709536137],
        &[0.02958758547680685, 0.0, 0.08876275643042054],
        &[
            0.2413651341592667,
            0.0,
            -0.8845494793282861,
            0.924834003261792,
        ],
        &[
            0.037037037037037035,
            0.0,
            0.0,
            0.17082860872947386,
            0.12546768756682242,
        ],
        &[
            0.037109375,
            0.0,
            0.0,
            0.17025221101954405,
            0.06021653898045596,
            -0.017578125,
        ],
        &[
            0.03709200011850479,
            0.0,
            0.0,
            0.17038392571223998,
            0.10726203044637328,
            -0.015319437748624402,
            0.008273789163814023,
        ],
        &[
            0.6241109587160757,
            0.0,
            0.0,
            -3.3608926294469414,
            -0.868219346841726,
            27.59209969944671,
            20.154067550477894,
            -43.48988418106996,
        ],
        &[
            0.47766253643826434,
            0.0,
            0.0,
            -2.4881146199716677,
            -0.590290826836843,
            21.230051448181193,
            15.279233632882423,
            -33.28821096898486,
            -0.020331201708508627,
        ],
        &[
            -0.9371424300859873,
            0.0,
            0.0,
            5.186372428844064,
            1.0914373489967295,
            -8.149787010746927,
            -18.52006565999696,
            22.739487099350505,
            2.4936055526796523,
            -3.0467644718982196,
        ],
        &[
            2.273310147516538,
            0.0,
            0.0,
            -10.53449546673725,
            -2.0008720582248625,
            -17.9589318631188,
            27.94888452941996,
            -2.8589982771350235,
            -8.87285693353063,
            12.360567175794303,
            0.6433927460157636,
        ],
    ],
    b: &[
        0.054293734116568765,
        0.0,
        0.0,
        0.0,
        0.0,
        4.450312892752409,
        1.8915178993145003,
        -5.801203960010585,
        0.3111643669578199,
        -0.1521609496625161,
        0.20136540080403034,
        0.04471061572777259,
    ],
    c: &[
        0.0,
        0.05260015195876773,
        0.0789002279381516,
        0.1183503419072274,
        0.2816496580927726,
        0.3333333333333333,
        0.25,
        0.3076923076923077,
        0.6512820512820513,
        0.6,
        0.8571428571428571,
        1.0,
    ],
};

/// A scheme's moves between its stage points (module doc, "Walking"): stage point `y_i`
/// (`1 ≤ i < s`) is reached from the earlier stage point nearest in time, `y_{src(i)}`
/// (`y_0 = p`), by `h Σ_j (a_ij − a_{src(i),j}) k_j`, and the step's end from the last
/// stage point by `h Σ_j (b_j − a_{s−1,j}) k_j`. Zero coefficients are dropped.
///
/// The stage points live in a few *slots* (a walk's start and end, per particle), reused
/// once no later move starts from them: [`Self::slot`].
#[derive(Debug, Clone)]
pub(crate) struct Moves {
    rows: Vec<Vec<(usize, f64)>>,
    /// `src[i − 1]`: the stage point the move onto `i` starts from (`i = s`: the end).
    src: Vec<usize>,
    /// The slot each stage point is kept in.
    slot: Vec<usize>,
    slots: usize,
    c: &'static [f64],
}

impl Moves {
    pub(crate) fn new(scheme: Scheme) -> Self {
        let t = scheme.tableau();
        let s = t.c.len();
        let row = |i: usize| -> &[f64] { if i == 0 { &[] } else { t.a[i - 1] } };
        // the earlier stage nearest in time (ties: the later one, so a chain of stages at
        // increasing times, as RK4's, walks from each to the next)
        let src: Vec<usize> = (1..=s)
            .map(|i| {
                if i == s {
                    return i - 1;
                }
                (0..i)
                    .rev()
                    .min_by(|&x, &y| {
                        let (dx, dy) = ((t.c[i] - t.c[x]).abs(), (t.c[i] - t.c[y]).abs());
                        dx.total_cmp(&dy)
                    })
                    .unwrap_or(0)
            })
            .collect();
        let rows = (1..=s)
            .map(|i| {
                let to = if i == s { t.b } else { row(i) };
                let from = row(src[i - 1]);
                (0..to.len())
                    .map(|j| (j, to[j] - from.get(j).copied().unwrap_or(0.0)))
                    .filter(|&(_, c)| c != 0.0)
                    .collect()
            })
            .collect();
        // slots: stage j's is free once every move starting from j is made; the move onto
        // `i` reads its source's slot and writes its own, so the two differ
        let last_read: Vec<usize> = (0..s)
            .map(|j| (1..=s).filter(|&i| src[i - 1] == j).max().unwrap_or(j))
            .collect();
        let mut slot = vec![0; s];
        let mut slots = 0;
        for i in 0..s {
            let busy = |x: usize| (0..i).any(|j| slot[j] == x && last_read[j] >= i);
            slot[i] = (0..).find(|&x| !busy(x)).unwrap_or(0);
            slots = slots.max(slot[i] + 1);
        }
        Self {
            rows,
            src,
            slot,
            slots,
            c: t.c,
        }
    }

    /// Stages per step.
    pub(crate) fn stages(&self) -> usize {
        self.c.len()
    }

    /// The time of stage `i` of step `n` (steps of `h` from `t0`).
    pub(crate) fn time(&self, i: usize, t0: f64, n: usize, h: f64) -> f64 {
        match self.c[i] {
            0.0 => t0 + n as f64 * h,
            1.0 => t0 + (n + 1) as f64 * h,
            c => t0 + n as f64 * h + c * h,
        }
    }

    /// The stage point the move onto stage `i` (`1 ≤ i ≤ s`, `s`: the step's end) starts
    /// from.
    pub(crate) fn source(&self, i: usize) -> usize {
        self.src[i - 1]
    }

    /// The slot stage point `i` is kept in (`0 ≤ i < s`).
    pub(crate) fn slot(&self, i: usize) -> usize {
        self.slot[i]
    }

    /// How many slots the stage points need.
    pub(crate) fn slots(&self) -> usize {
        self.slots
    }

    /// The move of particle `p` onto stage point `i` (`1 ≤ i < s`) from stage point
    /// [`Self::source`]`(i)`, or (`i = s`) to the step's end, from the stage velocities `k`.
    #[inline]
    pub(crate) fn to(&self, i: usize, h: f64, k: &[Vec<DVec2>], p: usize) -> DVec2 {
        let mut d = DVec2::ZERO;
        for &(j, c) in &self.rows[i - 1] {
            d += c * k[j][p];
        }
        h * d
    }
}

/// Slot `a` to read and slot `b` to write (`a ≠ b`).
pub(crate) fn two<T>(slots: &mut [Vec<T>], a: usize, b: usize) -> (&[T], &mut [T]) {
    assert_ne!(a, b, "a move reads and writes the same slot");
    if a < b {
        let (lo, hi) = slots.split_at_mut(b);
        (&lo[a], &mut hi[0])
    } else {
        let (lo, hi) = slots.split_at_mut(a);
        (&hi[0], &mut lo[b])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tableaux_are_consistent_and_moves_reach_the_stage_points() {
        for scheme in [Scheme::Rk4, Scheme::Rk8] {
            let t = scheme.tableau();
            let s = t.c.len();
            assert_eq!(t.a.len(), s - 1);
            assert_eq!(t.b.len(), s);
            // Σ_j a_ij = c_i (each stage point at its own time's first-order place), Σ b = 1
            for i in 1..s {
                assert!((t.a[i - 1].iter().sum::<f64>() - t.c[i]).abs() < 1e-14);
            }
            assert!((t.b.iter().sum::<f64>() - 1.0).abs() < 1e-14);
            // walking the moves from p reaches p + h Σ a_ij k_j, then p + h Σ b_j k_j
            let moves = Moves::new(scheme);
            let k: Vec<Vec<DVec2>> = (0..s)
                .map(|j| vec![DVec2::new((j as f64 * 1.7).sin(), (j as f64 * 0.3).cos())])
                .collect();
            let h = 0.37;
            let mut y = vec![DVec2::ZERO; s + 1];
            for i in 1..=s {
                y[i] = y[moves.source(i)] + moves.to(i, h, &k, 0);
                let row = if i == s { t.b } else { t.a[i - 1] };
                let want: DVec2 = row.iter().zip(&k).map(|(a, kj)| h * a * kj[0]).sum();
                assert!(y[i].distance(want) < 1e-13, "{scheme:?} stage {i}");
            }
            // a stage's slot is not overwritten before the last move from it
            for i in 1..s {
                for j in 0..i {
                    let read_later = (i..=s).any(|r| moves.source(r) == j);
                    if read_later {
                        assert_ne!(moves.slot(i), moves.slot(j), "{scheme:?} {j} {i}");
                    }
                }
            }
        }
    }
}
