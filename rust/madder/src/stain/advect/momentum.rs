//! Momentum advection: the solvent's momentum moved by the upwind plan's transfers.
//!
//! ## Momentum advection (§4.3.2)
//! The alternative of §4.3.2 moves the momentum `p_i = m_i u_i` with the same transfers as
//! the solvent: a transfer of fraction `φ` of the donor's mass takes `φ p_donor` with it,
//! which arrives in the receiver's frame as `R_{recv,donor} φ p_donor`. After all sub-steps
//! `u_i' = p_i' / m_i'`, a convex combination of transported velocities. Where `m_i'` is
//! at most [`MOMENTUM_MIN_MASS_REL`] of the largest mass (a dry vertex), the velocity is
//! undefined and the semi-Lagrangian value is returned instead. On a flat mesh `R`
//! preserves world vectors, so the total world momentum is conserved.

use glam::DVec2;
use rayon::prelude::*;

use super::plan::UpwindPlan;
use crate::mesh::{Topology, Transport};

/// Solvent mass, relative to the largest mass before the step, below which the momentum
/// velocity is not formed. The momentum of a vertex carries an absolute rounding error of
/// a few `10⁻¹⁶` times the mass that passed through it; above this bound that error is
/// below `10⁻³` of the velocity.
pub(crate) const MOMENTUM_MIN_MASS_REL: f64 = 1e-12;

impl UpwindPlan {
    /// Velocities after moving the momentum `m_i u_i` with the same transfers as the solvent
    /// (§4.3.2, see the module doc): a transfer of fraction `φ` of the donor's mass takes
    /// `φ` of its momentum, turned into the receiver's frame by `R_ij`; after all sub-steps
    /// `u_i' = p_i' / m_i'`. Where `m_i'` is at most [`MOMENTUM_MIN_MASS_REL`] times the
    /// largest `solvent_before` (or zero), `fallback[i]` (the semi-Lagrangian value) is
    /// returned. `solvent_before` are the solvent masses before this step's transport.
    ///
    /// # Panics
    /// If any per-vertex slice does not have one value per vertex of `topology`.
    pub fn momentum_velocity(
        &self,
        topology: &Topology,
        transport: &Transport,
        solvent_before: &[f64],
        velocity: &[DVec2],
        fallback: &[DVec2],
    ) -> Vec<DVec2> {
        let mut mass = solvent_before.to_vec();
        self.transport_with_momentum(topology, transport, &mut [&mut mass], velocity, fallback)
    }

    /// [`UpwindPlan::transport_all`] and [`UpwindPlan::momentum_velocity`] in one: moves the
    /// fields, the first of which is the solvent, and the solvent's momentum with them, in
    /// one pass over the transfers per sub-cycle; returns the velocities. Every value is
    /// computed by the same operations as the two calls make (the momentum velocity
    /// divides by the transported solvent, which is what `momentum_velocity` recomputes),
    /// so the result is bit-identical to them.
    ///
    /// # Panics
    /// If `fields` is empty, or a field or per-vertex slice does not have one value per
    /// vertex of `topology`.
    pub fn transport_with_momentum(
        &self,
        topology: &Topology,
        transport: &Transport,
        fields: &mut [&mut [f64]],
        velocity: &[DVec2],
        fallback: &[DVec2],
    ) -> Vec<DVec2> {
        let mut out = Vec::new();
        self.transport_with_momentum_into(
            topology, transport, fields, velocity, fallback, &mut out,
        );
        out
    }

    /// [`UpwindPlan::transport_with_momentum`] into `out` (its allocation kept).
    pub(crate) fn transport_with_momentum_into(
        &self,
        topology: &Topology,
        transport: &Transport,
        fields: &mut [&mut [f64]],
        velocity: &[DVec2],
        fallback: &[DVec2],
        out: &mut Vec<DVec2>,
    ) {
        assert!(!fields.is_empty(), "the solvent is the first field");
        for field in fields.iter() {
            self.check(topology, field.len());
        }
        self.check(topology, velocity.len());
        self.check(topology, fallback.len());
        let scale = fields[0].iter().copied().fold(0.0, f64::max);
        let momentum: Vec<DVec2> = fields[0]
            .iter()
            .zip(velocity)
            .map(|(&m, &u)| m * u)
            .collect();
        let momentum = self.cycles(fields, Some((transport, momentum)));
        let mass = &*fields[0];
        let floor = MOMENTUM_MIN_MASS_REL * scale;
        (0..mass.len())
            .into_par_iter()
            .map(|v| {
                let u = momentum[v] / mass[v];
                if mass[v] > floor && mass[v] > 0.0 && u.is_finite() {
                    u
                } else {
                    fallback[v]
                }
            })
            .collect_into_vec(out);
    }
}
