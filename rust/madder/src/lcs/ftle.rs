//! Finite-time Lyapunov exponent on a triangle mesh (§5.2, §5.5.1).
//!
//! The flow map `φ = φ_{t0}^{t0+T}` is traced from every vertex ([`super::trace`]); its
//! gradient at vertex `i` is fitted by least squares over the one-ring, in the tangent
//! frame `F_i` of the surface at `t0` ([`crate::mesh::VertexFrames`]): with `d_j` the
//! spoke `x_j − x_i` at `t0` in `(x_i, y_i)` components and `Δ_j = φ(x_j) − φ(x_i)` the 3-D
//! offset of the traced end points on the surface at `t0 + T`,
//!
//! ```text
//! ∇φ_i = (Σ_j Δ_j d_jᵀ) (Σ_j d_j d_jᵀ)⁻¹      (3×2),
//! ```
//!
//! exact for a linear flow map, and centred (second order) where the one-ring is symmetric
//! (interior vertices of a regular grid). Then the Cauchy–Green tensor
//! `C = ∇φᵀ ∇φ` (2×2, §5.2), its largest eigenvalue
//! `λ_max = (tr C + √((C₁₁ − C₂₂)² + 4C₁₂²)) / 2`, and
//!
//! ```text
//! σ = ln √λ_max / |T|.
//! ```
//!
//! On a curved surface the offsets `Δ_j` are chords: where neighbours end `|Δ|` apart on a
//! surface of curvature `κ` along their offset, `|Δ|` is the surface distance times about
//! `1 − κ²|Δ|²/24`, so `σ` is biased low by about `κ²|Δ|²/(24|T|)` where the flow
//! separates neighbours by a sizeable fraction of the radius of curvature: for the
//! octuple gyre on a torus (T = −10, 200×100) the difference from a reference in the
//! surface's metric was 2% of σ's range on average, 10% at the 95th percentile, against
//! 0.06% from a reference that fits the same chords (`tests/ridges.rs` uses the latter). On a flat or developable mesh that stays flat the fit is exact for
//! linear maps. Tracing auxiliary particles at a small offset (the "auxiliary grid" of
//! grid methods) would remove the bias at 4× the particles; it is not built.
//!
//! A vertex whose spokes do not span its tangent plane (a loose vertex, a fan collapsed to
//! a line) gets `σ = 0`.

use glam::{DMat2, DVec2, DVec3};
use rayon::prelude::*;

use super::rk::Scheme;
use super::trace::{Charts, Motion, Velocity, flow_map_with};
use crate::error::LcsError;
use crate::mesh::{OneRings, Topology, VertexFrames};

/// Checks the time span: finite and non-zero.
pub(crate) fn check_span(span: f64) -> Result<(), LcsError> {
    if span == 0.0 || !span.is_finite() {
        return Err(LcsError::ZeroSpan { span });
    }
    Ok(())
}

/// FTLE `σ` per vertex of the flow of `velocity` on the mesh `topology` moving by
/// `motion`, from `t0` over `span` (negative: backward) in `steps` RK4 steps.
///
/// Errors name the bad input: a zero span, a velocity that is not finite (vertex and
/// time), positions of the wrong count or not finite, a time outside the frames.
pub fn ftle(
    topology: &Topology,
    motion: &Motion,
    velocity: &mut dyn Velocity,
    t0: f64,
    span: f64,
    steps: usize,
) -> Result<Vec<f64>, LcsError> {
    ftle_with(topology, motion, velocity, t0, span, Scheme::Rk4, steps)
}

/// [`ftle()`] with the particles traced by `scheme` ([`super::rk`]) in `steps` steps.
pub fn ftle_with(
    topology: &Topology,
    motion: &Motion,
    velocity: &mut dyn Velocity,
    t0: f64,
    span: f64,
    scheme: Scheme,
    steps: usize,
) -> Result<Vec<f64>, LcsError> {
    check_span(span)?;
    if steps == 0 {
        return Err(LcsError::Option {
            name: "steps",
            requirement: "at least 1",
            value: 0.0,
        });
    }
    motion.check(topology)?;
    let start = motion.positions(t0)?;
    motion.at(t0 + span)?;
    // the fit's one-rings and frames at t0 need nothing of the charts: built beside them
    let (charts, (rings, frames)) = rayon::join(
        || Charts::new(topology, &start),
        || {
            let rings = OneRings::new(topology);
            let frames = VertexFrames::new(&rings, &start);
            (rings, frames)
        },
    );
    let charts = charts?;
    let flow = flow_map_with(&charts, motion, velocity, t0, span, scheme, steps)?;
    let at = motion.at(t0 + span)?;
    let end: Vec<DVec3> = flow
        .iter()
        .enumerate()
        .map(|(v, l)| match l {
            Some(l) => charts.world(motion, at, l),
            None => motion.position(at, v),
        })
        .collect();
    Ok(match frames {
        Ok(frames) => fit(&rings, &frames, &start, &end, span),
        Err(_) => vec![0.0; start.len()],
    })
}

/// FTLE from the flow map's end points `end` of the vertices at `start` (module doc).
pub fn ftle_from_flow_map(
    topology: &Topology,
    start: &[DVec3],
    end: &[DVec3],
    span: f64,
) -> Vec<f64> {
    let rings = OneRings::new(topology);
    let Ok(frames) = VertexFrames::new(&rings, start) else {
        return vec![0.0; start.len()];
    };
    fit(&rings, &frames, start, end, span)
}

/// σ per vertex from the end points, with the one-rings and the frames at `start`.
fn fit(
    rings: &OneRings,
    frames: &VertexFrames,
    start: &[DVec3],
    end: &[DVec3],
    span: f64,
) -> Vec<f64> {
    (0..start.len())
        .into_par_iter()
        .map(|i| {
            let (a, b) = one_ring_fit(rings.spokes(i), |j| {
                (frames.to_local(i, start[j] - start[i]), end[j] - end[i])
            });
            let Some(j) = solve_fit(a, b) else {
                return 0.0;
            };
            let c11 = j[0].length_squared();
            let c22 = j[1].length_squared();
            let c12 = j[0].dot(j[1]);
            let lmax = 0.5 * (c11 + c22 + ((c11 - c22).powi(2) + 4.0 * c12 * c12).sqrt());
            if lmax > 0.0 {
                lmax.ln() / (2.0 * span.abs())
            } else {
                0.0
            }
        })
        .collect()
}

/// The normal equations `A = Σ d dᵀ`, `B = Σ Δ dᵀ` (as the two columns `Σ Δ d_x`,
/// `Σ Δ d_y`) of a least-squares gradient over the spokes of `i`.
pub(crate) fn one_ring_fit<V>(
    spokes: &[u32],
    sample: impl Fn(usize) -> (DVec2, V),
) -> (DMat2, [V; 2])
where
    V: Copy + Default + std::ops::Add<Output = V> + std::ops::Mul<f64, Output = V>,
{
    let mut a = DMat2::ZERO;
    let mut b = [V::default(); 2];
    for &j in spokes {
        let (d, delta) = sample(j as usize);
        a += DMat2::from_cols(d * d.x, d * d.y);
        b[0] = b[0] + delta * d.x;
        b[1] = b[1] + delta * d.y;
    }
    (a, b)
}

/// `B A⁻¹`: the columns of the fitted gradient (`None` if `A` is singular).
pub(crate) fn solve_fit<V>(a: DMat2, b: [V; 2]) -> Option<[V; 2]>
where
    V: Copy + std::ops::Add<Output = V> + std::ops::Mul<f64, Output = V>,
{
    let det = a.determinant();
    if det.abs() <= 1e-12 * (a.x_axis.x * a.y_axis.y).abs() || det == 0.0 {
        return None;
    }
    let inv = a.inverse();
    // (B A⁻¹) column k = Σ_m B_m (A⁻¹)_{m k}
    Some([
        b[0] * inv.x_axis.x + b[1] * inv.x_axis.y,
        b[0] * inv.y_axis.x + b[1] * inv.y_axis.y,
    ])
}
