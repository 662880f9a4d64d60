//! Lagrangian coherent structures on (deforming) triangle meshes: FTLE and its ridges
//! (seed chapter 5).
//!
//! ## The math (§5.2)
//! The flow map `φ_{t0}^{t} : D → D` of a velocity `v(x, t)` solves
//! `dφ/dt = v(φ, t)`, `φ_{t0}^{t0}(x) = x`. A small offset `δ` at `t0` becomes
//! `∇φ δ` at `t0 + T`, so the largest stretching is the largest eigenvalue `λ_max` of the
//! Cauchy–Green tensor `C = ∇φᵀ ∇φ`, and the finite-time Lyapunov exponent is
//! `σ = (1/|T|) ln √λ_max`. A ridge of `σ` is a curve `c(s)` with
//! `c′(s) × ∇σ = 0` (eq. 5.1) and `nᵀHn = min_{|u|=1} uᵀHu` for its normal `n`, `H` the
//! Hessian of `σ` (eq. 5.2); following §5.5.3 we ask only for `∇σ · n = 0` with `n`
//! transverse, estimated from the Hessian of a smoothed indicator of high `σ`.
//!
//! ## The pipeline and the files
//! - [`trace`] (§5.5.1), a folder, a file per concern: the particle `(triangle,
//!   barycentric)` (`located.rs`), charts (`charts.rs`) and edge crossings by unfolding
//!   (`walk.rs`), the fixed-step integrator ([`flow_map`], [`flow_map_with`], `flow.rs`);
//!   velocities from an analytic function ([`FnVelocity`]), per-vertex values per frame
//!   ([`VertexVelocity`]) or any [`Velocity`] (the Python binding's callable,
//!   `velocity.rs`); a fixed or deforming mesh ([`Motion`], `time.rs`).
//! - [`rk`] (§5.5.1): the explicit Runge–Kutta schemes, classical RK4 (the default) and
//!   DOP853's eighth-order solution with fixed steps ([`Scheme`]).
//! - `trace/planar.rs` (§5.5.1): the same flow map on a flat fixed mesh without walking,
//!   where a bucket grid (`trace/buckets.rs`) proves a segment stays inside (a fast path of
//!   `trace`).
//! - [`ftle`](mod@ftle) (§5.2, §5.5.1): the flow map's gradient by least squares over the one-ring
//!   in the vertex's tangent frame, Cauchy–Green, `σ` ([`ftle()`](ftle::ftle)).
//! - [`ridges`](mod@ridges) (§5.4, §5.5.2–§5.5.5): threshold into `S` (eq. 5.3), implicit diffusion
//!   smoothing, Hessian and `n_min`, the zero-crossing test with the orientation factor
//!   (eq. 5.4), marching triangles, joining at local maxima, cleanup, spurious valleys
//!   ([`ridges()`](ridges::ridges)).

pub mod ftle;

pub mod ridges;
pub mod rk;
pub mod trace;

pub use ftle::{ftle, ftle_from_flow_map, ftle_with};
pub use ridges::{RidgeOptions, Ridges, ridges};
pub use rk::Scheme;
pub use trace::{
    Charts, FnVelocity, FrameTimes, Located, Motion, Velocity, VertexVelocity, flow_map,
    flow_map_with,
};
