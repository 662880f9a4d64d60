//! The phase times and work counters of the steps so far ([`Profile`]), and the clock
//! that adds each phase's seconds into them ([`Laps`]).

use std::time::Instant;

/// Wall-clock seconds spent in each phase since the simulator was built (for benchmarks).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Profile {
    /// Finding the liquid and (re)building the window.
    pub window: f64,
    /// Geometry, comoving–corotating frames (Kabsch) and the transport `R_ij`.
    pub geometry: f64,
    /// Body forces (and bringing the velocities of vertices entering the window up to
    /// date).
    pub forces: f64,
    /// Velocity and density advection (the sum of the three parts below, and the
    /// centred velocity).
    pub advection: f64,
    /// Part of `advection`: the semi-Lagrangian back-traces of the velocity.
    pub advection_trace: f64,
    /// Part of `advection`: the dual fluxes and the upwind plan.
    pub advection_plan: f64,
    /// Part of `advection`: the sub-cycles applied to the densities and the momentum.
    pub advection_apply: f64,
    /// Diffusion of the densities and of the velocity (assembly and CG; the two run
    /// side by side).
    pub diffusion: f64,
    /// Interactions.
    pub interaction: f64,
    /// Frames stepped.
    pub frames: usize,
    /// Sub-steps taken (with those of the frames tried again).
    pub substeps: usize,
    /// CG iterations of the density solves (all fields).
    pub density_iterations: usize,
    /// CG iterations of the velocity solve.
    pub velocity_iterations: usize,
    /// Transport sub-cycles of the density advection (≥ 1 per sub-step; more when the
    /// liquid crosses more than about one dual cell per step).
    pub transport_cycles: usize,
    /// Active vertices, summed over the sub-steps.
    pub active_vertices: usize,
    /// Window vertices (active, held and halo), summed over the sub-steps.
    pub window_vertices: usize,
    /// Times the window was rebuilt.
    pub window_rebuilds: usize,
    /// Frames run again on a wider window because their liquid outran the one planned
    /// for them (module doc of `simulate`, "Window reach").
    pub window_retries: usize,
    /// Window edges, summed over the sub-steps (for the work model of
    /// `Profile::least_work`, the `roofline` feature).
    pub window_edges: usize,
    /// Window faces, summed over the sub-steps.
    pub window_faces: usize,
    /// Fields carried through the transport sub-cycles, times the sub-cycles, summed.
    pub transport_passes: usize,
    /// Density fields solved (one CG solve each), summed over the sub-steps.
    pub density_solves: usize,
    /// Fields carried along the solved solvents' fluxes, summed over the sub-steps.
    pub carried_fields: usize,
}

/// A clock over consecutive phases: each [`Laps::lap`] adds the seconds since the
/// previous lap (or the start) into one of a [`Profile`]'s times.
pub(super) struct Laps {
    clock: Instant,
}

impl Laps {
    /// Starts the clock now.
    pub(super) fn start() -> Self {
        Self {
            clock: Instant::now(),
        }
    }

    /// Adds the seconds since the previous lap to `slot` and starts the next.
    pub(super) fn lap(&mut self, slot: &mut f64) {
        let now = Instant::now();
        *slot += (now - self.clock).as_secs_f64();
        self.clock = now;
    }
}
