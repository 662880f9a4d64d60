//! The split-step stain simulator on a deforming mesh (seed §4.3, Fig. 1.3; eqs. 4.1–4.10).
//!
//! The state it steps ([`super::state`]): per vertex the tangent velocity `u_i` in the
//! comoving–corotating frame `F_i` ([`super::forces`]) and the masses of the liquid and
//! its solute (§4.5's fields), put there by the sources ([`super::sources`]: poured
//! liquid, splashes).
//!
//! One frame `t → t + H` is `S` sub-steps of `h = H/S`, the positions interpolated
//! linearly between the two frames, on the frame's *window*: the active region around the
//! liquid cut out of the cloth, or the whole cloth with `active_region` off
//! ([`super::window`]). Each sub-step, on the geometry at its end:
//!
//! 1. **Forces** (§4.4), the first half: `u̇ = a − k u − 2ω_z J u` over `h/2`, `a` the
//!    tangential gravity and rectilinear force in `F_i`, `k` the drag of the fibres on
//!    the liquid (`k = 0` is the seed's frictionless liquid), `ω` the frames' angular
//!    velocity over the sub-step: integrated exactly for constant `a` and `ω`
//!    ([`super::forces::integrate_velocity`]; each vertex's propagator computed once
//!    for the two half kicks, [`super::forces::VelocityStep`]), so the liquid reaches
//!    its terminal velocity `a/k` at any step (a kick followed by the decay `e^{−kh}`
//!    reaches 30 % of it at 24 fps), and the Coriolis force turns it without changing
//!    its speed. The velocity is then **extended** over the dry cloth from the wet
//!    region ([`super::extend`]): it is the liquid's, and the dry value is what arriving
//!    liquid reads.
//! 2. **Advection** (§4.3.1–4.3.2): the densities by upwind finite volumes
//!    ([`super::advect`]); the velocity with the solvent's momentum (§4.3.2, the
//!    default: `u = p/m`, the mass-weighted velocity), or semi-Lagrangian (§4.3.1) with
//!    `momentum_advection` off. The densities move with the sub-step's mean velocity:
//!    the exact mean under the forces over the whole sub-step plus half the change the
//!    advection makes (without friction, `½(u^n + u^{n+1})`). With the end velocity
//!    alone (the plain split step) a liquid accelerating from rest travels `(n+1)/n`
//!    times `½at²` after `n` steps — 12 % too far after 8 frames — and with the mean it
//!    travels exactly `½at²`.
//! 3. **Forces**, the second half, at the vertex the liquid arrived at. Half a kick where
//!    the liquid leaves and half where it arrives is the kick–drift–kick (leapfrog)
//!    splitting: second order, and it keeps the energy of a frictionless liquid bounded.
//!    The whole kick at the start (the seed's order) gives a liquid swinging in a trough
//!    the force of where it was, not where it went: with the momentum velocity its swing
//!    grew by 13 % per half period at 25 fps.
//! 4. **Diffusion** (§4.3.3–4.3.4): `(M + h K_S) σ' = m` for the free solvent and the
//!    dissolved solute (and their colour), `K_S` the stiffness of the fabric tensor in
//!    each face's weft basis; the velocity by the connection (Bochner) Laplacian of the
//!    viscosity, eq. 4.6. Both by warm-started CG on the window's active vertices, each
//!    total restored and any negative mass repaired afterwards ([`super::diffuse`]).
//! 5. **Interactions** (§4.5): absorption, adsorption, evaporation ([`super::interact`]),
//!    the evaporation faster on the wet patch's rim (eq. 4.8's factor on its outermost
//!    vertices, or vapour-limited: `vapour_limited`).
//!
//! With `carry_solute` the solute moves with the solvents' fluxes in step 4, and with a
//! `residual_saturation` the fibres' liquid has its own, pinned operator there (issue 13
//! §2, tide lines: [`super::diffuse`]).
//!
//! ## Which velocity (issue 10)
//! The momentum form is the default because only it conserves momentum where streams of
//! liquid meet. The semi-Lagrangian velocity is a Burgers equation for `u` alone: where
//! fast liquid runs into slow liquid (or into a trace of it) the two velocities meet at
//! their plain average, whatever their masses. A blob released in a frictionless trough
//! focuses at the bottom like the pendulums of its parcels (they all arrive together), and
//! there the semi-Lagrangian swing loses 40 % of its amplitude per half period, at any
//! sub-step; with the momentum form the blob follows a point mass to 8 % of the amplitude
//! at one sub-step per 25 fps frame (4 % at two). Both coast exactly when launched on a flat
//! cloth (tests: `tests/liquid_motion.rs`).
//!
//! ## Fast rotation
//! The splitting of forces and advection errs where the frames turn fast: on a disk
//! spinning at 8 rad/s at 25 fps, 7 % off the inertial path at one sub-step. A frame
//! therefore takes as many sub-steps as keep the largest turn of an active vertex's frame
//! about its normal to [`MAX_TURN`] (0.1 rad) per sub-step, on top of the ones asked for
//! ([`StainParams::substeps`]): 1 at 2 rad/s, 4 at 8 rad/s at 25 fps, and the path stays
//! within 5 %. The turn is measured on the window's active vertices only (where liquid can
//! be), from the frames at the start of the frame to the Kabsch frames at its end; its
//! `ω_z` is computed for every window vertex, so that with one sub-step (the usual case)
//! the forces take it instead of computing it again.
//!
//! ## Failure
//! [`Simulator::step`] works on the window's copy of the state and writes it back only
//! when the whole frame succeeded: an error (bad positions naming the vertex, a solver
//! failure) leaves the simulator at the last good frame.

use std::sync::atomic::AtomicU64;
use std::time::Instant;

use faer::Par;
use glam::{DVec2, DVec3};
use rayon::prelude::*;

use super::advect::{UpwindPlan, advect_velocity_in, dual_fluxes_in};
use super::diffuse::{
    Conductivity, DENSITY_TOLERANCE, DensityWork, Ops, SoluteMotion, VELOCITY_TOLERANCE, Wicking,
    check_range, diffuse_densities, diffuse_velocity,
};
use super::extend::{extend_velocity, wet_vertices};
use super::forces::{
    Forces, VelocityStep, corotating_frames_with, frame_angular_velocity, frame_body_acceleration,
    rest_frames, second_difference,
};
use super::interact::{InteractionRates, exposure, interact_varied, vapour_exposure};
use super::irregular::{Irregularity, face_means};
use super::state::{Fields, Local, State, merge_rgb, split_rgb};
use super::window::{Cloth, Window, pick, pick_into};
use crate::error::{Error, ParamError};
use crate::mesh::geometry::check_positions;
use crate::mesh::{Geometry, OneRings, RingAdjacency, Topology, Transport, VertexFrames};
use crate::ops::WarmCg;

/// A vertex is "dry" for the evaporation boundary rule (eq. 4.8) below this liquid
/// density, kg/m² (1 g/m², a film of water 1 µm thick).
pub(crate) const DRY_DENSITY: f64 = 1e-3;

/// Largest turn of a vertex frame about its normal in one sub-step, rad (module doc,
/// "Fast rotation"): a frame that turns faster gets more sub-steps.
pub(crate) const MAX_TURN: f64 = 0.1;

/// Most sub-steps a frame takes on its own to keep the turn per sub-step below
/// [`MAX_TURN`] (a frame turning by 6.4 rad, a full turn, in one frame).
pub(crate) const MAX_AUTO_SUBSTEPS: usize = 64;

/// The default colour of the liquid's solute (linear RGB, a dark red; the add-on's and
/// the Python simulator's default).
pub const DEFAULT_SOLUTE_COLOR: [f64; 3] = [0.45, 0.05, 0.1];

/// Physical parameters of the liquid and the cloth (SI units).
#[derive(Debug, Clone, PartialEq)]
pub struct StainParams {
    /// Gravitational acceleration, world coordinates, m/s².
    pub gravity: DVec3,
    /// Which body forces act.
    pub forces: Forces,
    /// Advect the velocity with the solvent's momentum (§4.3.2) instead of
    /// semi-Lagrangian.
    pub momentum_advection: bool,
    /// Kinematic viscosity of the velocity diffusion, m²/s (`S_v = ν I`).
    pub viscosity: f64,
    /// Drag of the fibres on the liquid, 1/s (`u̇ = −k u`; 0 = frictionless). The
    /// default, 50 /s, is the Poiseuille drag `3ν/H²` of a water film `H ≈ 0.25 mm` thick
    /// on a no-slip cloth (films of 0.1–0.5 mm give 12–300 /s): 0.2 m/s terminal speed
    /// under 1 g.
    pub friction: f64,
    /// Absorption, adsorption and evaporation rates (§4.5).
    pub interaction: InteractionRates,
    /// How the fabric's diffusion rate grows with its saturation (off by default).
    pub wicking: Wicking,
    /// The fabric's random variations of diffusion and absorption (off by default).
    pub irregularity: Irregularity,
    /// The dissolved solute moves with the solvent's capillary flow instead of diffusing
    /// on its own ([`super::diffuse`], "Tide lines"); off by default.
    pub carry_solute: bool,
    /// `θ_r`, from 0 to 1 (exclusive): the fibres' liquid below `θ_r` times their
    /// saturation neither moves nor lets liquid in, so the edge of a wet patch stays where
    /// the spill put it while it dries (issue 13 §2, [`super::diffuse`], "Tide lines");
    /// the fibres' liquid moves only with [`Self::carry_solute`]. 0 (the default) is off.
    pub residual_saturation: f64,
    /// The evaporation is limited by the diffusion of vapour away from the flat wet patch:
    /// fastest at its edge, `J/J̄ = R/(2√(d(2R − d)))` at distance `d` from the edge
    /// ([`super::interact`], "Vapour-limited evaporation"), instead of eq. 4.8's factor on
    /// the outermost vertices. Off by default.
    pub vapour_limited: bool,
    /// Sub-steps per frame, at least: a frame whose vertex frames turn by more than
    /// [`MAX_TURN`] takes more on its own (module doc, "Fast rotation").
    pub substeps: u32,
    /// Step only the vertices near the flowing liquid ([`super::window`]);
    /// `false` steps the whole mesh.
    pub active_region: bool,
}

impl Default for StainParams {
    fn default() -> Self {
        Self {
            gravity: DVec3::new(0.0, 0.0, -9.81),
            forces: Forces::default(),
            momentum_advection: true,
            viscosity: 1e-4,
            friction: 50.0,
            interaction: InteractionRates::default(),
            wicking: Wicking::default(),
            irregularity: Irregularity::default(),
            carry_solute: false,
            residual_saturation: 0.0,
            vapour_limited: false,
            substeps: 1,
            active_region: true,
        }
    }
}

impl StainParams {
    /// Checks every parameter, naming the first one out of range.
    pub fn validate(&self) -> Result<(), ParamError> {
        if let Some(k) = (0..3).find(|&k| !self.gravity[k].is_finite()) {
            return Err(ParamError::NonFinite {
                name: "gravity",
                index: k,
            });
        }
        check_range(
            "viscosity",
            self.viscosity,
            self.viscosity >= 0.0,
            "finite and ≥ 0",
        )?;
        check_range(
            "friction",
            self.friction,
            self.friction >= 0.0,
            "finite and ≥ 0",
        )?;
        check_range(
            "substeps",
            self.substeps as f64,
            self.substeps >= 1,
            "at least 1",
        )?;
        check_range(
            "residual saturation",
            self.residual_saturation,
            (0.0..1.0).contains(&self.residual_saturation),
            "from 0 to 1 (exclusive)",
        )?;
        self.wicking.validate()?;
        self.irregularity.validate()?;
        self.interaction.validate()
    }
}

/// The stain simulator of chapter 4 on one cloth.
#[derive(Debug)]
pub struct Simulator {
    /// The whole cloth.
    pub(super) cloth: Cloth,
    pub(super) params: StainParams,
    pub(super) loose: Vec<bool>,
    pub(super) solute_color: [f64; 3],
    pub(super) state: State,
    pub(super) profile: Profile,
    /// The window of the last frame (kept while the liquid stays well inside it).
    pub(super) window: Option<Window>,
    /// Liquid may have been poured outside the window: the next frame looks for it on
    /// the whole mesh.
    pub(super) rescan: bool,
    /// Transport sub-cycles of the last frame, all its sub-steps together (widens the
    /// next region: liquid moves at most one ring per sub-cycle).
    pub(super) last_frame_cycles: usize,
    /// The window for the next frame was already prepared (by [`super::detail`], which
    /// checks it against the part of the refined cloth built so far).
    pub(super) prepared: bool,
    /// The solvers of a window dropped without a successor (the refined cloth grew,
    /// [`super::detail`]): the next window is built in their memory.
    pub(super) spare: Option<(WarmCg, WarmCg)>,
    /// Relative residual tolerances of the density and the velocity solves
    /// ([`DENSITY_TOLERANCE`], [`VELOCITY_TOLERANCE`]).
    pub(super) tolerances: [f64; 2],
    /// The step's arrays, kept from frame to frame.
    pub(super) scratch: StepScratch,
    /// Per face of the cloth (allocated when first needed): a third of its area at the
    /// current positions, as bits, for the faces around the stained vertices outside the
    /// window ([`Simulator::refresh_areas`]; each written by one corner, read by all).
    pub(super) face_thirds: Vec<AtomicU64>,
}

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
pub(super) struct StepScratch {
    /// Window vertices the buffers were grown for.
    vertices: usize,
    /// The window's positions at the frame's start and end, and between them (sub-steps
    /// before the last).
    cur: Vec<DVec3>,
    next: Vec<DVec3>,
    between: Vec<DVec3>,
    /// `p̈` of the window's vertices over the frame interval.
    acceleration: Vec<DVec3>,
    /// The frames' turns `ω_z` over the whole frame.
    omega: Vec<f64>,
    /// The frames at the frame's end, while the sub-steps before the last run.
    end_frames: VertexFrames,
    /// The last committed frame's work: its arrays are the next frame's.
    local: Option<Local>,
    /// The sub-step's arrays.
    sub: SubstepScratch,
}

/// The arrays of one sub-step ([`StepScratch`]).
#[derive(Debug, Default)]
pub(super) struct SubstepScratch {
    /// The geometry (its vertex areas then swapped with the frame's).
    geometry: Geometry,
    /// The vertex frames at the sub-step's end (then swapped with the frame's), and the
    /// transport between them.
    frames: VertexFrames,
    transport: Transport,
    /// Per vertex: the acceleration, turn and half-kick propagator; the velocity after
    /// the first half kick, and its mean over the sub-step.
    force: Vec<(DVec2, f64, VelocityStep)>,
    forced: Vec<DVec2>,
    mean: Vec<DVec2>,
    /// The semi-Lagrangian velocity, the densities' velocity, and the velocity the
    /// momentum arrived with (then the second half kick's, swapped with the frame's).
    advected: Vec<DVec2>,
    centred: Vec<DVec2>,
    arrived: Vec<DVec2>,
    /// The dual fluxes and the upwind plan.
    flux: Vec<f64>,
    plan: Option<UpwindPlan>,
}

impl StepScratch {
    /// Drops the buffers when the window of `n` vertices is less than half the size they
    /// were grown to (the memory follows the window).
    fn fit(&mut self, n: usize) {
        if 2 * n < self.vertices {
            *self = Self::default();
        }
        self.vertices = self.vertices.max(n);
    }
}

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
    /// Sub-steps taken.
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
    /// Window edges, summed over the sub-steps (for the work model of
    /// [`Profile::least_work`]).
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

impl Simulator {
    /// A dry cloth at rest: `rest` positions define the rest frames `F̄_i`, `positions`
    /// is the first frame. `conductivity` is the fabric's diffusion of the densities
    /// (`S_f`); `solute_color` the colour of the liquid's solute.
    pub fn new(
        topology: Topology,
        rest: &[DVec3],
        positions: &[DVec3],
        conductivity: Conductivity,
        params: StainParams,
        solute_color: [f64; 3],
        par: Par,
    ) -> Result<Self, Error> {
        params.validate()?;
        conductivity.validate(topology.n_faces())?;
        if let Some(index) = solute_color.iter().position(|c| !c.is_finite()) {
            return Err(ParamError::NonFinite {
                name: "solute colour",
                index,
            }
            .into());
        }
        check_positions(&topology, rest)?;
        check_positions(&topology, positions)?;
        let _ = par; // the per-element loops use the rayon pool; the CG is sequential
        let n = topology.n_vertices();
        let rings = OneRings::new(&topology);
        let adjacency = RingAdjacency::new(&topology);
        let rest_frames = rest_frames(&rings, rest)?;
        let frames = corotating_frames_with(&adjacency, &rest_frames, rest, positions);
        let geometry = Geometry::new(&topology, positions)?;
        Ok(Self {
            loose: topology.loose_vertices(),
            cloth: Cloth {
                boundary: topology.boundary_vertices(),
                irregular: params
                    .irregularity
                    .is_on()
                    .then(|| params.irregularity.multiplier(rest)),
                rest: rest.to_vec(),
                rest_frames,
                conductivity,
                rings,
                adjacency,
                topology,
                congruent: None,
                face_congruent: None,
            },
            params,
            solute_color,
            state: State {
                positions: positions.to_vec(),
                previous: None,
                frames,
                stamp: vec![0.0; n],
                vertex_area: geometry.vertex_area,
                velocity: vec![DVec2::ZERO; n],
                fields: Fields::zeros(n),
                evaporated: 0.0,
                time: 0.0,
                stained: Vec::new(),
                is_stained: vec![false; n],
            },
            profile: Profile::default(),
            window: None,
            rescan: true,
            last_frame_cycles: 1,
            prepared: false,
            spare: None,
            tolerances: [DENSITY_TOLERANCE, VELOCITY_TOLERANCE],
            scratch: StepScratch::default(),
            face_thirds: Vec::new(),
        })
    }

    /// The cloth's topology.
    pub fn topology(&self) -> &Topology {
        &self.cloth.topology
    }
    /// The active vertices of the last frame (one flag per vertex), or `None` when the
    /// whole mesh is stepped (`active_region` off) or nothing was stepped yet.
    pub fn active_region(&self) -> Option<&[bool]> {
        if self.params.active_region {
            self.window.as_ref().map(|w| w.mask.as_slice())
        } else {
            None
        }
    }
    /// Replaces the relative residual tolerances of the density and the velocity CG
    /// solves (defaults [`DENSITY_TOLERANCE`] and [`VELOCITY_TOLERANCE`], clamped to
    /// `[1e-14, 1e-4]`): for the benchmark that measures what the defaults change against
    /// tighter solves, and for the tests.
    #[doc(hidden)]
    pub fn set_solver_tolerances(&mut self, density: f64, velocity: f64) {
        self.tolerances = [density.clamp(1e-14, 1e-4), velocity.clamp(1e-14, 1e-4)];
    }

    /// Time spent per phase so far.
    pub fn profile(&self) -> Profile {
        self.profile
    }
    /// Simulated time since the start, s.
    pub fn time(&self) -> f64 {
        self.state.time
    }
    /// Advances one frame to `positions` over `dt` seconds in `params.substeps`
    /// sub-steps. `after`, if known, is the frame after `positions` (one more `dt`
    /// later): the rectilinear force then uses the frame interval's mean acceleration
    /// `½(p̈_k + p̈_{k+1})` (second order) instead of `p̈_k`, and the first frame gets its
    /// acceleration from the motion instead of assuming none. On error the simulator
    /// stays at the previous frame.
    pub fn step(
        &mut self,
        positions: &[DVec3],
        dt: f64,
        after: Option<&[DVec3]>,
    ) -> Result<(), Error> {
        // run the frame on a thread of the rayon pool: the many short parallel loops of a
        // step then start from a worker (work stealing) instead of each handing its work
        // over from outside the pool and blocking the caller until it is done
        rayon::scope(|_| self.step_in_pool(positions, dt, after))
    }

    fn step_in_pool(
        &mut self,
        positions: &[DVec3],
        dt: f64,
        after: Option<&[DVec3]>,
    ) -> Result<(), Error> {
        check_range("time step", dt, dt > 0.0, "finite and > 0")?;
        check_positions(&self.cloth.topology, positions)?;
        if let Some(a) = after {
            check_positions(&self.cloth.topology, a)?;
        }
        let clock = Instant::now();
        let rebuilt = !std::mem::take(&mut self.prepared) && self.prepare_window()?;
        let mut prof = self.profile;
        prof.window_rebuilds += usize::from(rebuilt);
        prof.frames += 1;
        prof.window += clock.elapsed().as_secs_f64();
        let t_end = self.state.time + dt;
        let mut window = self.window.take();
        let mut scratch = std::mem::take(&mut self.scratch);
        let result = match window.as_mut() {
            Some(w) => self
                .run_frame(w, positions, dt, after, &mut prof, &mut scratch)
                .map(|local| {
                    self.commit(w, &local, t_end);
                    scratch.local = Some(local);
                }),
            None => Ok(()),
        };
        self.window = window;
        self.scratch = scratch;
        self.profile = prof;
        // nothing is written before the whole frame succeeded (module doc, "Failure")
        result?;
        let st = &mut self.state;
        st.time = t_end;
        let mut buffer = st.previous.take().unwrap_or_default();
        buffer.clear();
        buffer.extend_from_slice(positions);
        st.previous = Some(std::mem::replace(&mut st.positions, buffer));
        self.refresh_areas();
        Ok(())
    }

    /// One frame on the window `w`, on copies of its state: nothing in `self` changes
    /// (but the kept arrays of `scratch`).
    fn run_frame(
        &self,
        w: &mut Window,
        positions: &[DVec3],
        dt: f64,
        after: Option<&[DVec3]>,
        prof: &mut Profile,
        scratch: &mut StepScratch,
    ) -> Result<Local, Error> {
        let clock = Instant::now();
        let (p, st) = (&self.params, &self.state);
        scratch.fit(w.vertices.len());
        let StepScratch {
            cur,
            next,
            between,
            acceleration,
            omega,
            end_frames,
            local,
            sub,
            ..
        } = scratch;
        pick_into(&w.vertices, &st.positions, cur);
        pick_into(&w.vertices, positions, next);
        // p̈ over the frame interval: the mean of the centred differences at its two ends
        // when the frame after is known (module doc of `forces`)
        if p.forces.rectilinear {
            w.vertices
                .par_iter()
                .map(|&v| {
                    let v = v as usize;
                    let (c, x) = (st.positions[v], positions[v]);
                    let start = match (&st.previous, after) {
                        (Some(prev), _) => second_difference(prev[v], c, x, dt),
                        (None, Some(a)) => second_difference(c, x, a[v], dt),
                        (None, None) => DVec3::ZERO,
                    };
                    match after {
                        Some(a) => 0.5 * (start + second_difference(c, x, a[v], dt)),
                        None => start,
                    }
                })
                .collect_into_vec(acceleration);
        } else {
            acceleration.clear();
            acceleration.resize(w.vertices.len(), DVec3::ZERO);
        }
        let mut local = local.take().unwrap_or_default();
        w.vertices
            .par_iter()
            .zip(&*acceleration)
            .map(|(&v, &a)| self.caught_up(v as usize, a))
            .unzip_into_vecs(&mut local.velocity, &mut local.frames.frame);
        st.fields.gather_into(&w.vertices, &mut local.fields);
        pick_into(&w.vertices, &st.vertex_area, &mut local.area);
        local.evaporated = 0.0;
        local.cycles = 0;
        prof.forces += clock.elapsed().as_secs_f64();
        let clock = Instant::now();
        // the frames at the frame's end: the sub-step count reads them, and the last
        // sub-step's frames are these (the same formula at the same positions)
        w.corotating_frames_into(next, &mut sub.frames);
        let (s_count, omega) = self.substeps(w, &sub.frames, &local.frames, dt, omega);
        // several sub-steps: the end's frames wait for the last one
        if s_count > 1 {
            std::mem::swap(&mut sub.frames, end_frames);
        }
        // one sub-step: its turn is the frame's, just computed
        let omega = omega.filter(|_| s_count == 1);
        prof.geometry += clock.elapsed().as_secs_f64();
        let h = dt / s_count as f64;
        for s in 1..=s_count {
            let last = s == s_count;
            if last && s_count > 1 {
                std::mem::swap(&mut sub.frames, end_frames);
            } else if !last {
                let t = s as f64 / s_count as f64;
                between.clear();
                between.extend(cur.iter().zip(&*next).map(|(a, b)| a.lerp(*b, t)));
            }
            let q = if last { &next[..] } else { &between[..] };
            let turns = if last { omega } else { None };
            self.substep(w, &mut local, q, last, turns, h, acceleration, prof, sub)?;
        }
        Ok(local)
    }

    /// Sub-steps of a frame of `dt` on the window `w` from the vertex frames `start` to the
    /// frames `end` at the frame's positions (window order): the user's
    /// [`StainParams::substeps`], or more so that the frames of the active vertices turn
    /// (about their normals) by at most [`MAX_TURN`] per sub-step (module doc, "Fast
    /// rotation").
    ///
    /// Also returns, with the Coriolis force on, every window vertex's `ω_z` over the
    /// whole frame: with one sub-step it is the sub-step's own, which the forces then
    /// take instead of computing it again (the same call on the same frames and `h = dt`).
    /// `omega` is filled (its allocation kept) and returned.
    fn substeps<'a>(
        &self,
        w: &Window,
        end: &VertexFrames,
        start: &VertexFrames,
        dt: f64,
        omega: &'a mut Vec<f64>,
    ) -> (usize, Option<&'a [f64]>) {
        let asked = self.params.substeps as usize;
        if !self.params.forces.coriolis {
            return (asked, None);
        }
        (0..w.vertices.len())
            .into_par_iter()
            .map(|j| frame_angular_velocity(&start.frame[j], &end.frame[j], dt).z)
            .collect_into_vec(omega);
        let turn = w
            .region
            .vertices
            .par_iter()
            .map(|&j| omega[j as usize].abs() * dt)
            .reduce(|| 0.0, f64::max);
        // a NaN turn (never from finite positions) keeps the user's count
        let needed = (turn / MAX_TURN).ceil();
        let count = if needed > asked as f64 {
            (needed as usize).min(MAX_AUTO_SUBSTEPS)
        } else {
            asked
        };
        (count, Some(omega))
    }

    /// One sub-step `h` of the window to positions `q` (window order), whose vertex frames
    /// are in `sub.frames` if `frames_ready` and whose frames' turns `ω_z` over the
    /// sub-step are `turns` if the caller has them; in `sub`'s arrays.
    #[allow(clippy::too_many_arguments)]
    fn substep(
        &self,
        w: &mut Window,
        loc: &mut Local,
        q: &[DVec3],
        frames_ready: bool,
        turns: Option<&[f64]>,
        h: f64,
        acceleration: &[DVec3],
        prof: &mut Profile,
        sub: &mut SubstepScratch,
    ) -> Result<(), Error> {
        let mut clock = Instant::now();
        let mut lap = |slot: &mut f64| {
            let now = Instant::now();
            *slot += (now - clock).as_secs_f64();
            clock = now;
        };
        let p = &self.params;
        let n = w.vertices.len();
        let topo = &w.cloth.topology;
        sub.geometry.renew(topo, q)?;
        if !frames_ready {
            w.corotating_frames_into(q, &mut sub.frames);
        }
        let (geometry, frames) = (&sub.geometry, &sub.frames);
        sub.transport.renew(
            topo,
            &w.cloth.rings,
            &sub.geometry,
            &sub.frames,
            q,
            w.tip_share.as_deref(),
        );
        let transport = &sub.transport;
        prof.active_vertices += w.region.vertices.len();
        prof.window_vertices += n;
        prof.window_edges += topo.n_edges();
        prof.window_faces += topo.n_faces();
        lap(&mut prof.geometry);

        // 1. body forces (§4.4), friction and the Coriolis turn, exactly over half the
        // sub-step at the vertex the liquid leaves (kick–drift–kick, module doc); the
        // densities drift with the exact mean velocity of a whole sub-step under them
        // — each vertex's half kick is the same propagator before and after the
        // advection (the same turn, friction and h/2), and the decay e^{-kh} is every
        // vertex's: both computed once (`VelocityStep`, the same bits as separate calls)
        let (decay_half, decay_full) = (
            VelocityStep::decay(p.friction, 0.5 * h),
            VelocityStep::decay(p.friction, h),
        );
        (0..n)
            .into_par_iter()
            .map(|j| {
                let f = &frames.frame[j];
                let a = frame_body_acceleration(f, acceleration[j], p.gravity, p.forces);
                let turn = match turns {
                    Some(t) => t[j],
                    None if p.forces.coriolis => {
                        frame_angular_velocity(&loc.frames.frame[j], f, h).z
                    }
                    None => 0.0,
                };
                let half = VelocityStep::with_decay(decay_half, turn, p.friction, 0.5 * h);
                (a, turn, half)
            })
            .collect_into_vec(&mut sub.force);
        let force = &sub.force;
        let (forced, mean) = (&mut sub.forced, &mut sub.mean);
        force
            .par_iter()
            .zip(&loc.velocity)
            .map(|(&(a, turn, half), &u)| {
                let full = VelocityStep::with_decay(decay_full, turn, p.friction, h);
                (half.end(u, a), full.mean(u, a))
            })
            .unzip_into_vecs(forced, mean);
        // the velocity is the liquid's: on the dry cloth it is the wet region's, extended
        let wet = wet_vertices(
            &loc.fields.free_solvent,
            &geometry.vertex_area,
            &w.region.mask,
        );
        extend_velocity(topo, transport, &wet, &mut [forced, mean]);
        let (forced, mean) = (&sub.forced, &sub.mean);
        lap(&mut prof.forces);

        // 2. advection (§4.3.1–4.3.2), closed inside the active region
        let active = &w.region.mask;
        let part = Instant::now();
        advect_velocity_in(
            topo,
            &w.cloth.rings,
            geometry,
            transport,
            forced,
            h,
            active,
            &mut sub.advected,
        );
        let advected = &sub.advected;
        prof.advection_trace += part.elapsed().as_secs_f64();
        let part = Instant::now();
        // the densities move with the sub-step's mean velocity: the exact mean under the
        // forces, plus half the change the advection made at its end (module doc)
        (0..n)
            .into_par_iter()
            .map(|j| {
                if active[j] {
                    mean[j] + 0.5 * (advected[j] - forced[j])
                } else {
                    DVec2::ZERO
                }
            })
            .collect_into_vec(&mut sub.centred);
        dual_fluxes_in(
            topo,
            q,
            frames,
            &sub.centred,
            active,
            w.tip_share.as_deref(),
            &mut sub.flux,
        );
        let plan = sub.plan.get_or_insert_with(UpwindPlan::empty);
        plan.renew(topo, &geometry.vertex_area, &sub.flux, h)?;
        let plan = &*plan;
        prof.transport_cycles += plan.substeps();
        loc.cycles += plan.substeps();
        prof.advection_plan += part.elapsed().as_secs_f64();
        let part = Instant::now();
        // the densities, and with the momentum form the solvent's momentum alongside
        let arrived = {
            let f = &mut loc.fields;
            let mut color = f.color_free.as_ref().map(|c| split_rgb(c));
            let mut fields: Vec<&mut [f64]> = vec![&mut f.free_solvent, &mut f.solute];
            if let Some(c) = color.as_mut() {
                fields.extend(c.iter_mut().map(|v| v.as_mut_slice()));
            }
            prof.transport_passes += plan.substeps() * fields.len();
            let arrived = if p.momentum_advection {
                plan.transport_with_momentum_into(
                    topo,
                    transport,
                    &mut fields,
                    forced,
                    advected,
                    &mut sub.arrived,
                );
                &mut sub.arrived
            } else {
                plan.transport_all(topo, &mut fields);
                &mut sub.advected
            };
            if let (Some(c), Some(cf)) = (color, f.color_free.as_mut()) {
                merge_rgb(&c, cf);
            }
            arrived
        };
        prof.advection_apply += part.elapsed().as_secs_f64();
        lap(&mut prof.advection);
        // the second half of the forces, at the vertex the liquid arrived at
        arrived
            .par_iter_mut()
            .zip(force)
            .for_each(|(u, (a, _, half))| *u = half.end(*u, *a));
        std::mem::swap(&mut loc.velocity, arrived);
        lap(&mut prof.forces);

        // 3. diffusion (§4.3.3–4.3.4, eq. 4.6): the densities and the velocity are
        // independent systems, solved side by side
        let ops = Ops {
            topology: topo,
            adjacency: &w.cloth.adjacency,
            pattern: &w.pattern,
            conductivity: &w.cloth.conductivity,
            region: &w.region,
        };
        // the wicking factor of every face, from the liquid before the solve (lagged),
        // times the irregular fabric's
        let wicking = p.wicking.is_on().then(|| {
            let f = &loc.fields;
            let liquid: Vec<f64> = (0..n)
                .map(|j| {
                    let a = geometry.vertex_area[j];
                    let m = f.free_solvent[j] + f.absorbed_solvent[j];
                    if a > 0.0 { m / a } else { 0.0 }
                })
                .collect();
            p.wicking.face_factors(topo, &liquid)
        });
        let irregular = w.cloth.irregular.as_ref();
        let face_scale = match (wicking, irregular.map(|m| face_means(topo, m))) {
            (Some(g), Some(r)) => Some(g.iter().zip(&r).map(|(g, r)| g * r).collect()),
            (g, r) => g.or(r),
        };
        // the fibres' liquid moves only between vertices above the residual saturation
        // (a pinned edge, "Tide lines" in `diffuse`)
        let held_scale = (p.carry_solute && p.residual_saturation > 0.0).then(|| {
            let floor = p.residual_saturation * p.interaction.saturation;
            let f = &loc.fields;
            let mobile: Vec<bool> = (0..n)
                .map(|j| {
                    let a = geometry.vertex_area[j];
                    a > 0.0 && f.absorbed_solvent[j] > floor * a
                })
                .collect();
            topo.faces()
                .iter()
                .enumerate()
                .map(|(t, c)| {
                    if c.iter().all(|&v| mobile[v as usize]) {
                        face_scale.as_ref().map_or(1.0, |g| g[t])
                    } else {
                        0.0
                    }
                })
                .collect::<Vec<f64>>()
        });
        let (fields, velocity) = (&mut loc.fields, &mut loc.velocity);
        let (densities, viscous) = match w.cg.as_mut() {
            None => (
                Ok(DensityWork {
                    iterations: 0,
                    solves: 0,
                    carried: 0,
                }),
                Ok(0),
            ),
            Some((scalar_cg, vector_cg)) => {
                scalar_cg.set_tolerance(self.tolerances[0]);
                vector_cg.set_tolerance(self.tolerances[1]);
                rayon::join(
                    || {
                        diffuse_densities(
                            &ops,
                            scalar_cg,
                            fields,
                            geometry,
                            h,
                            face_scale.as_deref(),
                            if p.carry_solute {
                                SoluteMotion::Carried {
                                    held_scale: held_scale.as_deref(),
                                }
                            } else {
                                SoluteMotion::Diffused
                            },
                        )
                    },
                    || {
                        if p.viscosity > 0.0 {
                            let scale = h * p.viscosity;
                            diffuse_velocity(&ops, vector_cg, velocity, geometry, transport, scale)
                        } else {
                            Ok(0)
                        }
                    },
                )
            }
        };
        let densities = densities?;
        prof.density_iterations += densities.iterations;
        prof.density_solves += densities.solves;
        prof.carried_fields += densities.carried;
        prof.velocity_iterations += viscous?;
        lap(&mut prof.diffusion);

        // 4. interactions (§4.5) on the active and held vertices (the halo's areas are
        // partial; it holds nothing that can change)
        let wet: Vec<f64> = (0..n)
            .map(|j| {
                let a = geometry.vertex_area[j];
                let m = loc.fields.free_solvent[j] + loc.fields.absorbed_solvent[j];
                if a > 0.0 { m / a } else { 0.0 }
            })
            .collect();
        let exposed = if p.vapour_limited {
            vapour_exposure(
                topo,
                &geometry.edge_length,
                &geometry.vertex_area,
                &w.cloth.boundary,
                &wet,
                DRY_DENSITY,
            )
        } else {
            exposure(
                topo,
                &w.cloth.boundary,
                &wet,
                DRY_DENSITY,
                p.interaction.evaporation_boundary,
            )
        };
        let mut part = loc.fields.gather(&w.whole);
        let absorption_scale = irregular.map(|m| pick(&w.whole, m));
        loc.evaporated += interact_varied(
            &p.interaction,
            &pick(&w.whole, &geometry.vertex_area),
            &pick(&w.whole, &exposed),
            absorption_scale.as_deref(),
            h,
            &mut part,
        )?;
        loc.fields.scatter(&w.whole, &part);

        std::mem::swap(&mut loc.frames, &mut sub.frames);
        std::mem::swap(&mut loc.area, &mut sub.geometry.vertex_area);
        lap(&mut prof.interaction);
        prof.substeps += 1;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A `w × h` grid of unit spacing `d` on the plane `z = 0`, two triangles a cell.
    fn grid(w: usize, h: usize, d: f64) -> (Topology, Vec<DVec3>) {
        let rest = (0..w * h)
            .map(|k| DVec3::new((k % w) as f64 * d, (k / w) as f64 * d, 0.0))
            .collect();
        (crate::mesh::topology::grid_topology(w, h), rest)
    }

    /// The kept step arrays ([`StepScratch`]) carry no value from one frame to the next:
    /// a simulator whose scratch is replaced before every frame — by an empty one, or by
    /// the leftovers of another simulation on a larger window — steps to the same bits
    /// as one that keeps its own, while the liquid spreads (the window is rebuilt and
    /// grows) on a waving, tilting cloth, with one and with three sub-steps a frame.
    #[test]
    fn kept_arrays_carry_nothing_between_frames() {
        let (topo, rest) = grid(60, 40, 0.02);
        let wave = |t: f64| -> Vec<DVec3> {
            rest.iter()
                .map(|p| {
                    // tilted: the liquid runs down towards y = 0
                    let z = 0.01 * (8.0 * p.x + 5.0 * t).sin() + (0.8 + 0.3 * t) * p.y;
                    DVec3::new(p.x, p.y + 0.05 * t * p.x, z)
                })
                .collect()
        };
        let centre = DVec3::new(0.6, 0.6, 0.0);
        let pour: Vec<f64> = rest
            .iter()
            .map(|p| if p.distance(centre) < 0.06 { 0.5 } else { 0.0 })
            .collect();
        let dt = 1.0 / 24.0;
        for substeps in [1, 3] {
            let make = || {
                let params = StainParams {
                    substeps,
                    friction: 5.0,
                    ..StainParams::default()
                };
                let mut sim = Simulator::new(
                    topo.clone(),
                    &rest,
                    &wave(0.0),
                    Conductivity::Isotropic(2e-4),
                    params,
                    DEFAULT_SOLUTE_COLOR,
                    Par::Seq,
                )
                .unwrap();
                sim.add_liquid(&pour, 0.05, None).unwrap();
                sim
            };
            // leftovers of a larger window: the whole cloth wet
            let mut other = make();
            other.add_liquid(&vec![0.2; rest.len()], 0.1, None).unwrap();
            for f in 1..=4 {
                other.step(&wave(f as f64 * dt), dt, None).unwrap();
            }
            let leftovers = std::mem::take(&mut other.scratch);
            assert!(
                leftovers.vertices > 0,
                "the other simulation kept its arrays"
            );
            let (mut kept, mut fresh, mut stale) = (make(), make(), make());
            stale.scratch = leftovers;
            // (`vertices` reset: the larger leftovers are used, not dropped by `fit`)
            stale.scratch.vertices = 0;
            let mut rebuilds = 0;
            for f in 1..=16 {
                let q = wave(f as f64 * dt);
                let after = wave((f + 1) as f64 * dt);
                fresh.scratch = StepScratch::default();
                if f > 1 {
                    // another frame's leftovers each time, of another size
                    std::mem::swap(&mut stale.scratch, &mut other.scratch);
                    stale.scratch.vertices = 0;
                    other.step(&q, dt, None).unwrap();
                }
                for sim in [&mut kept, &mut fresh, &mut stale] {
                    sim.step(&q, dt, Some(&after)).unwrap();
                }
                rebuilds = kept.profile().window_rebuilds;
                let bits = |sim: &Simulator| -> Vec<u64> {
                    let st = &sim.state;
                    st.fields
                        .free_solvent
                        .iter()
                        .chain(&st.fields.solute)
                        .chain(&st.fields.absorbed_solvent)
                        .chain(&st.vertex_area)
                        .chain(st.velocity.iter().flat_map(|u| [&u.x, &u.y]))
                        .map(|x| x.to_bits())
                        .collect()
                };
                let want = bits(&kept);
                assert!(bits(&fresh) == want, "fresh arrays differ at frame {f}");
                assert!(bits(&stale) == want, "stale arrays differ at frame {f}");
            }
            assert!(rebuilds >= 4, "the window was rebuilt as the liquid ran");
            assert!(
                kept.state.fields.free_solvent.iter().any(|&m| m > 0.0),
                "liquid left to compare"
            );
        }
    }
}
