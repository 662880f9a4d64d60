//! Advection of the velocity and of the densities (seed §4.3.1–4.3.2).
//!
//! The velocity is one 2-D vector `u_i` per vertex in the vertex frame `F_i`
//! ([`crate::mesh::frames`]); the densities (solvent, solute, colour) are carried as
//! masses per vertex, `m_i = A_i σ_i`, with `A_i` the lumped area (one third of the
//! one-ring's area) that the diffusion ([`super::diffuse`]) uses as its mass matrix.
//!
//! One file per step, each with the math it implements:
//! - `trace.rs`: the velocity's semi-Lagrangian back-trace, following the strip of
//!   unfolded triangles (§4.3.1): [`advect_velocity`];
//! - `sector.rs`: the back-trace's angular pre-test of the first wedge;
//! - `flux.rs`: the volume fluxes through the median dual's faces: [`dual_fluxes`];
//! - `plan.rs`: the upwind plan of one step, its sub-cycling and limiter: [`UpwindPlan`];
//! - `flows.rs`: the plan's per-vertex transfer table and one sub-cycle over it;
//! - `apply.rs`: the plan applied to the mass fields ([`UpwindPlan::transport_all`]);
//! - `momentum.rs`: momentum advection (§4.3.2,
//!   [`UpwindPlan::transport_with_momentum`]).

mod apply;
mod flows;
mod flux;
mod momentum;
mod plan;
mod sector;
#[cfg(test)]
mod tests;
mod trace;

pub use flux::dual_fluxes;
pub(crate) use flux::dual_fluxes_in;
pub use plan::UpwindPlan;
pub use trace::advect_velocity;
pub(crate) use trace::advect_velocity_in;

/// Vertices per task of the transfer passes (rayon's splitting below this costs more
/// than the work).
const VERTICES_PER_TASK: usize = 1024;
