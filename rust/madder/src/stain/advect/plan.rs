//! The upwind plan of one step: from the fluxes, which end of each edge donates and the
//! fraction of its mass it gives per sub-step.
//!
//! ### Upwind transfers, sub-cycling and the limiter
//! Across each edge the donor is the cell the flux through the dual face comes from, the
//! upwind cell (`Φ_ab > 0`: `a` gives to `b`; for a velocity along the edge that is the
//! end it points away from, as `S · e > 0`). Every transfer is then a non-negative amount
//! taken from a non-negative mass, whatever the triangles' angles. In a
//! step `h` it gives the fraction `h |Φ_ab| / A_donor` of its current mass: the seed's
//! `h/A_i F_ij` with `σ↑ = m_donor / A_donor`. Each transfer is subtracted from the donor
//! and added to the receiver, so mass is conserved up to rounding. Vertex `i` gives away
//! `θ_i = h Σ_out |Φ| / A_i` of its mass (its Courant number). Positivity needs
//! `θ_i ≤ 1`; we sub-cycle the step into `n = ⌈max_i θ_i / 0.9⌉` equal sub-steps (at most
//! [`MAX_SUBSTEPS`]) with the fluxes fixed, so each sub-step gives at most 90% away (a
//! margin that keeps `m − Σ transfers ≥ 0` in floating point, where `Σ φ ≤ 0.9` leaves
//! room for any rounding, and keeps the scheme away from the `θ = 1` limit). If
//! `θ_i / n` still exceeds 1 (the cap was hit, or `A_i = 0` with outflow), the
//! **limiter** scales that vertex's outflows down so they sum to exactly 1: it gives all
//! it has, split in proportion to `|Φ|` (this under-transports at that vertex, the price
//! of positivity at a huge step). Only then can rounding leave `m − Σ transfers` a few
//! ulps below zero; that remainder is clamped to 0. With
//! `m_i' = m_i (1 − Σ_out φ) + Σ_in φ m_j`, `Σ_out φ ≤ 1` and non-negative input, every
//! output is non-negative.
//!
//! The plan ([`UpwindPlan`]) stores the fractions and is applied to every transported
//! field (solvent, solute, colour masses): the solute moves with the solvent, so the
//! concentration of a uniform solution stays uniform. Results do not depend on the thread
//! count: every sum is gathered per vertex in its edge order.

use rayon::prelude::*;

use super::VERTICES_PER_TASK;
use super::flows::Flows;
use crate::error::ParamError;
use crate::mesh::Topology;

/// Largest number of sub-steps of one upwind step; beyond it the limiter keeps masses
/// non-negative.
pub(crate) const MAX_SUBSTEPS: usize = 64;

/// Largest fraction of its mass a vertex gives away in one sub-step before sub-cycling.
pub(crate) const SUBSTEP_COURANT: f64 = 0.9;

/// The upwind transport plan of one step `h`: which endpoint donates across each edge and
/// what fraction of the donor's mass it gives per sub-step (see the module doc).
#[derive(Debug, Clone)]
pub struct UpwindPlan {
    /// Edges of the plan's topology.
    n_edges: usize,
    pub(super) substeps: usize,
    max_courant: f64,
    n_limited: usize,
    /// The transfers as each vertex sees them, built once with the plan.
    pub(super) flows: Flows,
}

impl UpwindPlan {
    /// Fractions `h |Φ| / (n A_donor)` for `n` sub-steps, with the sub-cycling and limiter
    /// of the module doc. `vertex_area` are the dual (lumped) areas `A_i`, `flux` the
    /// output of [`dual_fluxes`](super::dual_fluxes).
    ///
    /// Fails on wrong lengths, a non-finite flux or area, a negative area, or an `h` that
    /// is negative or not finite.
    pub fn new(
        topology: &Topology,
        vertex_area: &[f64],
        flux: &[f64],
        h: f64,
    ) -> Result<Self, ParamError> {
        let mut plan = Self::empty();
        plan.renew(topology, vertex_area, flux, h)?;
        Ok(plan)
    }

    /// A plan of no edges, to be [`UpwindPlan::renew`]ed.
    pub(crate) fn empty() -> Self {
        Self {
            n_edges: 0,
            substeps: 1,
            max_courant: 0.0,
            n_limited: 0,
            flows: Flows::default(),
        }
    }

    /// [`UpwindPlan::new`] in this plan's arrays (their allocations kept: the simulator
    /// renews one plan every sub-step, issue 16). The same plan, bit for bit; on error
    /// `self` is left unchanged.
    pub(crate) fn renew(
        &mut self,
        topology: &Topology,
        vertex_area: &[f64],
        flux: &[f64],
        h: f64,
    ) -> Result<(), ParamError> {
        let (n, n_edges) = (topology.n_vertices(), topology.n_edges());
        if vertex_area.len() != n {
            return Err(ParamError::Length {
                name: "vertex_area",
                expected: n,
                got: vertex_area.len(),
            });
        }
        if flux.len() != n_edges {
            return Err(ParamError::Length {
                name: "flux",
                expected: n_edges,
                got: flux.len(),
            });
        }
        if !(h.is_finite() && h >= 0.0) {
            return Err(ParamError::OutOfRange {
                name: "h",
                requirement: "finite and ≥ 0",
                value: h,
            });
        }
        if let Some(index) = flux.iter().position(|x| !x.is_finite()) {
            return Err(ParamError::NonFinite {
                name: "flux",
                index,
            });
        }
        if let Some(index) = vertex_area.iter().position(|x| !x.is_finite()) {
            return Err(ParamError::NonFinite {
                name: "vertex_area",
                index,
            });
        }
        if let Some(&value) = vertex_area.iter().find(|&&a| a < 0.0) {
            return Err(ParamError::OutOfRange {
                name: "vertex_area",
                requirement: "≥ 0",
                value,
            });
        }
        // one pass over each vertex's edges, in its edge order: its outflow (gathered in
        // edge order: the numerator of its Courant number) and the |Φ| it gives and
        // receives, the donor chosen by the sign of the flux
        let edges = topology.edges();
        let runs: Vec<Run> = (0..n.div_ceil(VERTICES_PER_TASK))
            .into_par_iter()
            .map(|c| {
                let vertices = c * VERTICES_PER_TASK..((c + 1) * VERTICES_PER_TASK).min(n);
                // each edge end gives at most one transfer, given or received
                let ends: usize = vertices
                    .clone()
                    .map(|v| topology.vertex_edges(v).len())
                    .sum();
                let mut run = Run {
                    outflow: Vec::with_capacity(vertices.len()),
                    flows: Flows {
                        out_ptr: Vec::with_capacity(vertices.len()),
                        out_fraction: Vec::with_capacity(ends),
                        in_ptr: Vec::with_capacity(vertices.len()),
                        in_from: Vec::with_capacity(ends),
                    },
                };
                for v in vertices {
                    let o: f64 = topology
                        .vertex_edges(v)
                        .iter()
                        .filter_map(|&e| {
                            let phi = flux[e as usize];
                            let [a, b] = edges[e as usize];
                            let d = if phi > 0.0 { a } else { b };
                            if d as usize == v {
                                if phi != 0.0 {
                                    run.flows.out_fraction.push(phi.abs());
                                }
                                Some(phi.abs())
                            } else {
                                if phi != 0.0 {
                                    run.flows.in_from.push((phi.abs(), d, e));
                                }
                                None
                            }
                        })
                        .sum();
                    run.outflow.push(o);
                    run.flows.out_ptr.push(run.flows.out_fraction.len() as u32);
                    run.flows.in_ptr.push(run.flows.in_from.len() as u32);
                }
                run
            })
            .collect();
        let outflow: Vec<f64> = runs
            .iter()
            .flat_map(|r| r.outflow.iter().copied())
            .collect();
        let courant: Vec<f64> = outflow
            .iter()
            .zip(vertex_area)
            .map(|(&o, &a)| {
                if o == 0.0 || h == 0.0 {
                    0.0
                } else if a > 0.0 {
                    h * o / a
                } else {
                    f64::INFINITY
                }
            })
            .collect();
        // vertices without area are left to the limiter, not to the sub-step count
        let max_courant = courant
            .iter()
            .copied()
            .filter(|c| c.is_finite())
            .fold(0.0, f64::max);
        let substeps = ((max_courant / SUBSTEP_COURANT).ceil() as usize).clamp(1, MAX_SUBSTEPS);
        let limited: Vec<bool> = courant.iter().map(|&c| c / substeps as f64 > 1.0).collect();
        let n_limited = limited.iter().filter(|&&l| l).count();
        // |Φ| → the fraction of the donor's mass per sub-step; a transfer that rounds to
        // nothing is dropped
        let fraction = |d: usize, phi: f64| {
            if h == 0.0 {
                0.0
            } else if limited[d] {
                phi / outflow[d]
            } else {
                h * phi / (substeps as f64 * vertex_area[d])
            }
        };
        let runs: Vec<Flows> = runs
            .into_par_iter()
            .enumerate()
            .map(|(c, run)| {
                // in place: the fractions overwrite the |Φ| they come from, the ones that
                // round to nothing are squeezed out
                let mut f = run.flows;
                let (mut o, mut i, mut o_to, mut i_to) = (0, 0, 0, 0);
                for (k, v) in (c * VERTICES_PER_TASK..).take(f.out_ptr.len()).enumerate() {
                    let o_end = f.out_ptr[k] as usize;
                    for t in o..o_end {
                        let x = fraction(v, f.out_fraction[t]);
                        if x != 0.0 {
                            f.out_fraction[o_to] = x;
                            o_to += 1;
                        }
                    }
                    let i_end = f.in_ptr[k] as usize;
                    for t in i..i_end {
                        let (phi, d, e) = f.in_from[t];
                        let x = fraction(d as usize, phi);
                        if x != 0.0 {
                            f.in_from[i_to] = (x, d, e);
                            i_to += 1;
                        }
                    }
                    (o, i) = (o_end, i_end);
                    f.out_ptr[k] = o_to as u32;
                    f.in_ptr[k] = i_to as u32;
                }
                f.out_fraction.truncate(o_to);
                f.in_from.truncate(i_to);
                f
            })
            .collect();
        self.flows.concat(n, runs);
        self.n_edges = n_edges;
        self.substeps = substeps;
        self.max_courant = courant.iter().copied().fold(0.0, f64::max);
        self.n_limited = n_limited;
        Ok(())
    }

    /// Number of equal sub-steps the step is cut into.
    pub fn substeps(&self) -> usize {
        self.substeps
    }

    /// Largest Courant number `θ_i = h Σ_out |Φ| / A_i` of the whole step (infinite if a
    /// vertex without area has outflow).
    pub fn max_courant(&self) -> f64 {
        self.max_courant
    }

    /// Number of vertices whose outflows the limiter scaled down.
    pub fn n_limited(&self) -> usize {
        self.n_limited
    }

    pub(super) fn check(&self, topology: &Topology, len: usize) {
        assert_eq!(self.n_edges, topology.n_edges(), "plan of another topology");
        assert_eq!(len, topology.n_vertices(), "one value per vertex");
    }
}

/// One run of vertices in [`UpwindPlan::new`]: their outflows, and their transfers
/// (`|Φ|` where [`Flows`] will hold the fractions; ends relative to the run's start).
#[derive(Default)]
struct Run {
    outflow: Vec<f64>,
    flows: Flows,
}
