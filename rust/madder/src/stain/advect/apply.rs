//! The upwind plan applied to the transported mass fields (solvent, solute, colour):
//! every sub-cycle one pass over the transfers for all fields at once.

use glam::DVec2;

use super::flows::Turns;
use super::plan::UpwindPlan;
use crate::mesh::{Topology, Transport};

impl UpwindPlan {
    /// Moves one mass field (kg per vertex, not density) by the plan: every sub-step, each
    /// transfer is subtracted from its donor and added to its receiver. Conservative up to
    /// rounding; non-negative input gives non-negative output.
    ///
    /// # Panics
    /// If `mass` does not have one value per vertex of `topology`, the plan's topology.
    pub fn transport(&self, topology: &Topology, mass: &mut [f64]) {
        self.transport_all(topology, &mut [mass]);
    }

    /// Moves several fields (solvent, solute, colour masses) with the same fractions, each
    /// exactly as [`UpwindPlan::transport`] would.
    ///
    /// The fields move together, interleaved per vertex (one pass over the transfers per
    /// sub-cycle for all of them, into reused buffers); each value is computed by the same
    /// operations in the same order as [`UpwindPlan::transport`], so the result is
    /// bit-identical to moving them one by one.
    ///
    /// # Panics
    /// If a field does not have one value per vertex of `topology`, the plan's topology.
    pub fn transport_all(&self, topology: &Topology, fields: &mut [&mut [f64]]) {
        for field in fields.iter() {
            self.check(topology, field.len());
        }
        if !fields.is_empty() {
            self.cycles(fields, None);
        }
    }

    /// The sub-cycles on the fields, interleaved per vertex, and, given the transport and
    /// the solvent's momentum, on the momentum too (returned; empty without).
    pub(super) fn cycles(
        &self,
        fields: &mut [&mut [f64]],
        momentum: Option<(&Transport, Vec<DVec2>)>,
    ) -> Vec<DVec2> {
        let (k, n) = (fields.len(), fields[0].len());
        let mut m = vec![0.0; n * k];
        for (c, field) in fields.iter().enumerate() {
            for (v, x) in field.iter().enumerate() {
                m[v * k + c] = *x;
            }
        }
        let mut next = vec![0.0; n * k];
        let (transport, mut p) = match momentum {
            Some((t, p)) => (Some(t), p),
            None => (None, Vec::new()),
        };
        let mut p_next = vec![DVec2::ZERO; p.len()];
        // the rotation of every received transfer, gathered once when several sub-cycles
        // read it
        let turns = match transport {
            Some(t) if self.substeps > 1 => Turns::Table(self.flows.turns(t)),
            Some(t) => Turns::Edges(t.edge_cos_sin()),
            None => Turns::Edges(&[]),
        };
        for _ in 0..self.substeps {
            match transport {
                None => self.flows.cycle(&m, k, &mut next),
                Some(_) => {
                    self.flows
                        .cycle_with_momentum(&m, k, &mut next, &turns, &p, &mut p_next);
                }
            }
            std::mem::swap(&mut m, &mut next);
            std::mem::swap(&mut p, &mut p_next);
        }
        for (c, field) in fields.iter_mut().enumerate() {
            for (v, x) in field.iter_mut().enumerate() {
                *x = m[v * k + c];
            }
        }
        p
    }
}
