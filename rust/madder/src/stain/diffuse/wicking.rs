//! The wicking law (issue 13): the density diffusion's rate growing with the
//! fabric's saturation, face by face ([`Wicking`]).

use crate::error::ParamError;
use crate::mesh::Topology;
use crate::stain::check::check_range;

/// Wicking (issue 13): a fabric draws liquid in faster where it is wetter, so the rate of
/// the density diffusion grows with the saturation `θ`,
///
/// ```text
/// D(θ) = D₀ θⁿ,    θ = min(σ_liquid / σ_w, 1),
/// ```
///
/// a porous-medium (Richards-type) law: `σ̇ = ∇·(D₀ θⁿ ∇σ)` has a front of finite speed
/// where the liquid meets dry cloth, instead of the Gaussian tail of linear diffusion.
/// `σ_liquid` is the free plus absorbed solvent density, `σ_w` [`Wicking::density`] (θ
/// stops at 1: a puddle above it spreads at `D₀`, and runs by the flow).
///
/// Discretized per face: face `T` diffuses at `D₀ g_T` with `g_T` the mean of `θ_iⁿ` over
/// its corners (the P1 stiffness with a piecewise-constant coefficient), so a face with
/// one wet corner conducts and the front moves into the next ring. The coefficient is
/// **lagged**: taken from the densities at the start of the solve, one linear solve per
/// sub-step as without wicking (the cost of a step stays that of the linear diffusion plus
/// the per-face factors). Lagging errs by `O(h)` in time; Picard iterations would remove
/// it at one more solve each, and on the Barenblatt test the lagged scheme is already
/// within the test's 3 % at the simulator's steps (`tests/wicking.rs`). The system stays
/// symmetric positive definite and conservative (`1ᵀK = 0` face by face, whatever the
/// factors), so mass is exact and the negative-mass repair keeps every density ≥ 0.
///
/// **Picard iterations** ([`Wicking::picard`]). Lagged, a face conducts only once one of its
/// corners is wet at the start of the solve, so the front advances at most one ring of
/// faces per sub-step: where it should move further (a fast spread, long steps) it is held
/// back, and it advances in graph distance, which on a structured grid is a rounded
/// square. Measured on a spot spreading on a 0.5 mm grid for 6 s (`tests/outlines.rs`):
/// 4-fold Fourier term of the front 10.2 % of the radius at 15 steps, 3.43 % at 60,
/// 0.27 % at 240, 0.017 % at 960, the mean radius 17.0, 35.2, 38.2 and 38.5 mm. Each Picard
/// iteration solves the step again from its start with the factors of the last solution,
/// the fully implicit coefficient `g(θ^{k+1})` (Celia, Bouloutas & Zarba 1990, for
/// Richards' equation), so the front may cross one more ring per iteration. The factors
/// depend on the liquid alone, so the trial solves leave the solute be and only the last
/// one moves it (with a carried solute, its sweeps cost more than the solve). 0 (the
/// default) is the lagged scheme, bit for bit.
///
/// **Until the front stops** ([`Wicking::tolerance`]). A fixed count still caps the front
/// at `picard + 1` rings a sub-step: where a long step should carry it further (the
/// demo's 45-s frames) it stops at a graph-distance line of the mesh, and the liquid piles
/// up at the truncated front. With a
/// tolerance `ε > 0` the iterations go on (up to [`MAX_PICARD`]) until the factors of two
/// successive solutions differ by at most `ε` times their largest on every face, the
/// fixed point of the implicit step (a ring reached only by a film whose factor is below
/// `ε` no longer counts), and one last solve with the converged factors moves the
/// solute. `picard` is then the least number of rounds. Measured on the spot of
/// `tests/outlines.rs` in 15 steps instead of 60: the 4-fold term of the front is
/// asserted below 1 % with `ε = 10⁻³`.
///
/// **Long steps.** A round carries a saturated front about one ring further (the factors
/// of a dry face are 0 until a corner is wet), so a front that should cross more rings
/// in a step than [`MAX_PICARD`] rounds reach is left unsettled, held at a line of graph
/// distance again: the demo's 45-s frames at Detail 2 met it. The simulator then solves
/// that step's diffusion again from its start in two halves, each iterated until it
/// settles, and so on (up to eight pieces): two implicit half steps are the same
/// diffusion over the step, more accurately. Measured on one-way diagonals, the 6 s of
/// `tests/outlines.rs` in one step: held, a hexagon 7.7 % short of 60 steps' radius
/// (2-fold term 4.84 %); halved, 1.3 % beyond it (2-fold 0.009 %).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Wicking {
    /// `n ≥ 0`; 0 is a constant rate (wicking off: the linear diffusion, bit for bit).
    pub exponent: f64,
    /// `σ_w`, kg/m²: the liquid density at which the rate reaches the fabric's `D₀`.
    pub density: f64,
    /// Picard iterations per sub-step (0 to [`MAX_PICARD`]): solves again with the
    /// factors of the last solution (the doc above); 0 = lagged. With a
    /// [`Self::tolerance`], the least number.
    pub picard: u32,
    /// `ε ≥ 0`: iterate on (up to [`MAX_PICARD`]) until no face's factor changes by more
    /// than `ε` times the largest (the doc above); 0 (the default) is the fixed count.
    pub tolerance: f64,
}

/// Most Picard iterations of one sub-step ([`Wicking`]).
pub const MAX_PICARD: u32 = 64;

impl Default for Wicking {
    fn default() -> Self {
        Self {
            exponent: 0.0,
            // the default fibres' saturation ([`crate::stain::InteractionRates`])
            density: 0.1,
            picard: 0,
            tolerance: 0.0,
        }
    }
}

impl Wicking {
    /// Whether the rate depends on the saturation at all.
    pub fn is_on(&self) -> bool {
        self.exponent > 0.0
    }

    /// Checks the exponent (finite, 0 to 8), the density (finite, > 0), the Picard
    /// iterations (at most [`MAX_PICARD`]) and the tolerance (finite, ≥ 0).
    pub fn validate(&self) -> Result<(), ParamError> {
        check_range(
            "wicking Picard iterations",
            self.picard as f64,
            self.picard <= MAX_PICARD,
            "from 0 to 64",
        )?;
        check_range(
            "wicking front tolerance",
            self.tolerance,
            self.tolerance >= 0.0,
            "finite and ≥ 0",
        )?;
        check_range(
            "wicking exponent",
            self.exponent,
            (0.0..=8.0).contains(&self.exponent),
            "from 0 to 8",
        )?;
        check_range(
            "wicking density",
            self.density,
            self.density > 0.0,
            "finite and > 0",
        )
    }

    /// The factor `g_T` of every face of `topology` from the liquid densities of its
    /// vertices (module doc of [`Wicking`]).
    pub fn face_factors(&self, topology: &Topology, liquid_density: &[f64]) -> Vec<f64> {
        let theta: Vec<f64> = liquid_density
            .iter()
            .map(|&s| (s / self.density).clamp(0.0, 1.0).powf(self.exponent))
            .collect();
        crate::stain::irregular::face_means(topology, &theta)
    }
}
