//! The step's arrays, kept from one frame to the next ([`StepScratch`], issue 16).

use glam::{DVec2, DVec3};

use crate::mesh::{Geometry, Transport, VertexFrames};
use crate::stain::advect::UpwindPlan;
use crate::stain::forces::VelocityStep;
use crate::stain::state::Local;

/// The step's per-frame and per-sub-step arrays, kept from one frame to the next and
/// cleared and refilled instead of allocated afresh (issue 16).
///
/// A window of 35k vertices (Detail 2, 10 % of the flag wet) makes a frame array of
/// `DMat3` 2.5 MB and one of `DVec2` 0.56 MB, above glibc's mmap threshold or, once that
/// has risen, in its per-thread arenas, which glibc trims when they are freed: every
/// frame touched new pages and the kernel faulted them in (`clear_page`; 17 % of the
/// Detail 2 bench's samples were in the kernel on 2 cores). Kept here, the Detail 0
/// bench (20k vertices, all wet) takes 18k page faults instead of 29k (12 frames;
/// ARCHITECTURE.md, "Close to the limit"). The values written are the same operations on
/// the same numbers as before: the same bits.
///
/// Kept are the arrays that live through the whole sub-step (positions, frames, geometry,
/// transport, forces and velocities, fluxes, the plan) or the whole frame (the frame's
/// working copy of the state, recycled after its commit). The short-lived arrays inside
/// a phase (the flux's and the plan's intermediates, the sub-cycles' fields, the
/// diffusion's and the interactions' arrays) are not: each is freed before the next
/// phase allocates, which then reuses that memory, so they cost no page faults; kept as
/// well, they only added to the peak (3–15 MB measured, as much as they weigh together
/// against the largest of them).
///
/// Sized by the window: when the window shrinks below half the size they were last
/// grown to, they are dropped (and grown again to the new window's size).
#[derive(Debug, Default)]
pub(in crate::stain) struct StepScratch {
    /// Window vertices the buffers were grown for.
    pub(super) vertices: usize,
    /// The window's positions at the frame's start and end, and between them (sub-steps
    /// before the last).
    pub(super) cur: Vec<DVec3>,
    pub(super) next: Vec<DVec3>,
    pub(super) between: Vec<DVec3>,
    /// `p̈` of the window's vertices over the frame interval.
    pub(super) acceleration: Vec<DVec3>,
    /// The frames' turns `ω_z` over the whole frame.
    pub(super) omega: Vec<f64>,
    /// The frames at the frame's end, while the sub-steps before the last run.
    pub(super) end_frames: VertexFrames,
    /// The last committed frame's work: its arrays are the next frame's.
    pub(super) local: Option<Local>,
    /// The sub-step's arrays.
    pub(super) sub: SubstepScratch,
}

/// The arrays of one sub-step ([`StepScratch`]).
#[derive(Debug, Default)]
pub(super) struct SubstepScratch {
    /// The geometry (its vertex areas then swapped with the frame's).
    pub(super) geometry: Geometry,
    /// The vertex frames at the sub-step's end (then swapped with the frame's), and the
    /// transport between them.
    pub(super) frames: VertexFrames,
    pub(super) transport: Transport,
    /// Per vertex: the acceleration, turn and half-kick propagator; the velocity after
    /// the first half kick, and its mean over the sub-step.
    pub(super) force: Vec<(DVec2, f64, VelocityStep)>,
    pub(super) forced: Vec<DVec2>,
    pub(super) mean: Vec<DVec2>,
    /// The semi-Lagrangian velocity, the densities' velocity, and the velocity the
    /// momentum arrived with (then the second half kick's, swapped with the frame's).
    pub(super) advected: Vec<DVec2>,
    pub(super) centred: Vec<DVec2>,
    pub(super) arrived: Vec<DVec2>,
    /// The dual fluxes and the upwind plan.
    pub(super) flux: Vec<f64>,
    pub(super) plan: Option<UpwindPlan>,
}

impl StepScratch {
    /// Drops the buffers when the window of `n` vertices is less than half the size they
    /// were grown to (the memory follows the window).
    pub(super) fn fit(&mut self, n: usize) {
        if 2 * n < self.vertices {
            *self = Self::default();
        }
        self.vertices = self.vertices.max(n);
    }
}
