//! Irregular fabric (issue 13 §3): a real cloth is not uniform — yarns vary in thickness
//! and twist, the weave is looser here and tighter there — so a spill's outline is ragged,
//! not the circle (or the ellipse, on a twill) of a homogeneous fabric. This module gives
//! the fabric's diffusion rate and absorption a random, spatially correlated multiplier
//! fixed to the cloth's rest surface.
//!
//! ## The field
//! A zero-mean, unit-variance Gaussian random field with the Gaussian covariance
//! `C(r) = exp(−r² / 2ℓ²)` (ℓ the correlation length), sampled by random Fourier
//! features (Rahimi & Recht 2007; the spectral method of Shinozuka):
//!
//! ```text
//! f(x) = √(2/M) Σ_{k<M} cos(ω_k · x + φ_k),    ω_k ~ N(0, I/ℓ²) in ℝ³,   φ_k ~ U[0, 2π),
//! ```
//!
//! whose covariance is `E[f(x) f(y)] = E[cos(ω·(x−y))] = exp(−|x−y|²/2ℓ²)`, the
//! characteristic function of the Gaussian `ω`. `f` is evaluated at a vertex's **rest**
//! position: the field moves with the cloth, and is a function of the point, not of the
//! mesh, so a cloth refined for Detail, or remeshed, sees the same field at the same
//! points. The `M` frequencies and phases come from the seed alone ([`SplitMix64`]), so the
//! field is the same on any machine and any number of threads.
//!
//! ## The multiplier
//! `m(x) = exp(s f(x) − s²/2)` with `s = 2a`, a log-normal multiplier with
//! log-standard deviation twice the amplitude `a` (0 to 1): always positive, with mean 1,
//! so the cloth's average rate is the fabric's. At `a = 0.5` the rate varies by a factor
//! `e^{±1}` ≈ 2.7 (one standard deviation) from place to place, at `a = 1` by `e^{±2}`.
//! The factor 2: a front spreading over many correlation lengths averages the rates it
//! crosses (it is homogenized, as the weave is in chapter 2), so its radius varies far
//! less than the rate: at 20 correlation lengths a log-deviation of 0.5 moved it by 3.6 %
//! (coefficient of variation over the angle), too little to see; 1.0 is the amplitude
//! 0.5 of the slider. It multiplies the density diffusion rate face by face (the mean of the
//! corners' multipliers, like the wicking factor it combines with) and the absorption
//! rate `K_p` vertex by vertex. Amplitude 0 turns it off: the uniform fabric, bit for bit.
//!
//! ## Roughness at every scale (issue 34 §2)
//! One correlation length gives lobes of that one size with smooth sides; an imbibition
//! front in paper or cloth is rough from the fibres up, self-affine with a roughness
//! exponent `α ≈ 0.6`: the height-height correlation of the front `w(l) ∝ l^α` (Family &
//! Vicsek, J. Phys. A 18, L75, 1985, for the scaling; Buldyrev et al., Phys. Rev. A 45,
//! R8313, 1992, and Horváth & Stanley, Phys. Rev. E 52, 5166, 1995, measured `α ≈ 0.63`
//! on paper, the exponent of fronts pinned by a quenched random medium). With a lower
//! cutoff `ℓ_f > 0` (`fine_length`, the fibre or thread scale) the field is instead
//! self-affine between `ℓ_f` and `ℓ` with Hurst exponent `H = α = 0.6`: the same random
//! Fourier features, but with the wave numbers spread log-uniformly over
//! `[1/ℓ, 1/ℓ_f]` and each mode weighted so that the power per logarithmic band falls as
//! `k^{−2H}`,
//!
//! ```text
//! f(x) = √2 Σ_k c_k cos(|ω_k| u_k · x + φ_k),   ln|ω_k| ~ U[ln(1/ℓ), ln(1/ℓ_f)],
//! c_k² = |ω_k|^{−2H} / Σ_j |ω_j|^{−2H},          u_k uniform on the sphere,
//! ```
//!
//! still of unit variance (`Σ c_k² = 1`), with the structure function
//! `E[(f(x+l) − f(x))²] = 2 Σ c_k² (1 − E cos(ω_k·l)) ∝ ∫ k^{−2H} (1 − J(kl)) dk/k ∝ l^{2H}`
//! for `ℓ_f ≪ l ≪ ℓ` (substitute `s = kl`): increments grow as `l^H`, a front following the
//! field's contours is rough with the same exponent, down to `ℓ_f` and up to `ℓ`, beyond
//! which it is the circle again. `ℓ_f = 0` (the default) is the single-scale field above,
//! bit for bit; `ℓ_f ≥ ℓ` is refused.

use glam::DVec3;
use rayon::prelude::*;

use super::check::check_range;
use crate::error::ParamError;
use crate::mesh::Topology;
use crate::rng::SplitMix64;

/// Hurst exponent of the multi-scale field (module doc): the roughness exponent of
/// imbibition fronts in paper and cloth.
pub(crate) const HURST: f64 = 0.6;

/// Fourier modes of the field: its variance is exact for any `M`, and the sample
/// covariance over a cloth many correlation lengths wide matches `C(r)` to a few percent.
pub(crate) const MODES: usize = 256;

/// The irregularity of a fabric (module doc).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Irregularity {
    /// `a`, 0 to 1: half the log-standard deviation of the multiplier (0: uniform
    /// fabric).
    pub amplitude: f64,
    /// `ℓ`, m: the distance over which the fabric's variations are correlated.
    pub correlation_length: f64,
    /// Seed of the field: the same seed gives the same fabric.
    pub seed: u64,
    /// `ℓ_f`, m: the lower cutoff of a multi-scale field, self-affine between `ℓ_f` and
    /// `ℓ` (module doc); 0: the single-scale field of correlation length `ℓ`.
    pub fine_length: f64,
}

impl Default for Irregularity {
    fn default() -> Self {
        Self {
            amplitude: 0.0,
            correlation_length: 0.003,
            seed: 0,
            fine_length: 0.0,
        }
    }
}

impl Irregularity {
    /// Whether the fabric varies at all.
    pub fn is_on(&self) -> bool {
        self.amplitude > 0.0
    }

    /// Checks the amplitude (0 to 1) and the correlation length (finite, > 0).
    pub fn validate(&self) -> Result<(), ParamError> {
        check_range(
            "irregularity",
            self.amplitude,
            (0.0..=1.0).contains(&self.amplitude),
            "from 0 to 1",
        )?;
        check_range(
            "irregularity correlation length",
            self.correlation_length,
            self.correlation_length > 0.0,
            "finite and > 0",
        )?;
        check_range(
            "irregularity fine length",
            self.fine_length,
            self.fine_length >= 0.0 && self.fine_length < self.correlation_length,
            "from 0 (single scale) to below the correlation length",
        )
    }

    /// Whether the field is the multi-scale one (module doc).
    pub fn is_multiscale(&self) -> bool {
        self.fine_length > 0.0
    }

    /// The unit field `f` at `points` (rest positions, m).
    pub fn field(&self, points: &[DVec3]) -> Vec<f64> {
        if self.is_multiscale() {
            return self.multiscale_field(points);
        }
        let mut rng = SplitMix64::new(self.seed ^ 0x6D61_6464_6572_2E69); // "madder.i"
        let scale = 1.0 / self.correlation_length;
        let modes: Vec<(DVec3, f64)> = (0..MODES)
            .map(|_| {
                let w = DVec3::new(normal(&mut rng), normal(&mut rng), normal(&mut rng));
                (w * scale, std::f64::consts::TAU * rng.unit())
            })
            .collect();
        let norm = (2.0 / MODES as f64).sqrt();
        points
            .par_iter()
            .map(|&x| {
                norm * modes
                    .iter()
                    .map(|&(w, phi)| (w.dot(x) + phi).cos())
                    .sum::<f64>()
            })
            .collect()
    }

    /// The self-affine field between `ℓ_f` and `ℓ` (module doc).
    fn multiscale_field(&self, points: &[DVec3]) -> Vec<f64> {
        let mut rng = SplitMix64::new(self.seed ^ 0x6D61_6464_6572_2E6D); // "madder.m"
        let (lo, hi) = (-self.correlation_length.ln(), -self.fine_length.ln());
        let modes: Vec<(DVec3, f64, f64)> = (0..MODES)
            .map(|k| {
                // stratified in ln|ω| so that every octave has its share of modes
                let t = (k as f64 + rng.unit()) / MODES as f64;
                let w = (lo + t * (hi - lo)).exp();
                let u = loop {
                    let v = DVec3::new(normal(&mut rng), normal(&mut rng), normal(&mut rng));
                    if v.length_squared() > 1e-12 {
                        break v.normalize();
                    }
                };
                (
                    u * w,
                    std::f64::consts::TAU * rng.unit(),
                    w.powf(-2.0 * HURST),
                )
            })
            .collect();
        let total: f64 = modes.iter().map(|m| m.2).sum();
        let weights: Vec<(DVec3, f64, f64)> = modes
            .into_iter()
            .map(|(w, phi, p)| (w, phi, (2.0 * p / total).sqrt()))
            .collect();
        points
            .par_iter()
            .map(|&x| {
                weights
                    .iter()
                    .map(|&(w, phi, c)| c * (w.dot(x) + phi).cos())
                    .sum::<f64>()
            })
            .collect()
    }

    /// The multiplier `m = exp(2a f − (2a)²/2)` at `points` (module doc).
    pub fn multiplier(&self, points: &[DVec3]) -> Vec<f64> {
        let a = 2.0 * self.amplitude;
        self.field(points)
            .into_iter()
            .map(|f| (a * f - 0.5 * a * a).exp())
            .collect()
    }
}

/// The mean of the corners' `vertex` values on every face of `topology`.
pub(crate) fn face_means(topology: &Topology, vertex: &[f64]) -> Vec<f64> {
    topology
        .faces()
        .iter()
        .map(|f| (vertex[f[0] as usize] + vertex[f[1] as usize] + vertex[f[2] as usize]) / 3.0)
        .collect()
}

/// A standard normal deviate (Box–Muller, the cosine branch).
fn normal(rng: &mut SplitMix64) -> f64 {
    let u1 = 1.0 - rng.unit(); // (0, 1]
    let u2 = rng.unit();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}
