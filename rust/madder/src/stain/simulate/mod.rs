//! The split-step stain simulator on a deforming mesh (seed §4.3, Fig. 1.3; eqs. 4.1–4.10).
//!
//! The state it steps ([`super::state`]): per vertex the tangent velocity `u_i` in the
//! comoving–corotating frame `F_i` ([`super::forces`]) and the masses of the liquid and
//! its solute (§4.5's fields), put there by the sources ([`sources`]: poured
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
//! ## Runs (issue 34 §1): the holdup
//! Without it the free liquid is a blob that runs over the dry fibres in a few sub-steps:
//! absorption (`ṗ = K_p (σ_sat A − p)`, time constant `1/K_p = 0.5 s`) sees it at a
//! vertex for `Δx/u` (5 mm at the terminal 0.2 m/s: 25 ms), so the fibres take up 5 %
//! of their saturation and the path stays clean, and the whole blob arrives below. A
//! liquid running down a porous sheet wets it: the pores between the yarns and the
//! roughness pin a film `h_r` at the contact line which the flow has to fill before it
//! moves on and which stays behind (the holdup of trickle-bed and packed-column flow;
//! for a vertical porous sheet, Kim et al., Phys. Fluids 27, 2015). With
//! `holdup = h_r > 0`, in step 2 each vertex keeps `min(f, h_r A)` of its free solvent
//! (and the same fraction of its dissolved solute and colour) out of the transport and
//! adds it back after; the velocity is the moving part's. In step 4 the pinned film
//! hardly spreads either: the free liquid's operator is gated face by face, a face's
//! conductivity times the creep `κ` ([`StainParams::film_creep`], 0.1) where the film
//! its corners hold is no thicker than `s h_r`, `s = |g_t| / g` the slope (the
//! tangential body force over gravity). Held out of the transport alone, a run's film is
//! drained by the free liquid's spreading instead and thins below `h_r` behind its
//! front, so the run never stops (with absorption 0 it climbed 8 cm above its feed, and
//! the film left was a fifth of `h_r`). A gate, not a held share: keeping
//! `min(f, s h_r A)` of each vertex out of the solve leaves the rest spreading toward
//! where more is held, so liquid gathered at the steepest vertices of a wrinkled cloth;
//! a gated face gathers nothing. And a creep, not a wall: with `κ = 0` the film the
//! transport leaves uneven never evens out, and on the demo a few vertices of the
//! hanging front were still wet after two hours of drying and dried near-black, the
//! sides stepped along the mesh; at 0.1 a run's film creeps a few millimetres over its
//! seconds and evens out over the minutes it dries. Scaling by the slope is a modelling
//! choice: the pinned film is what holds against a run, and a level pool (`s = 0`,
//! every face open) spreads as without it, its edge the wicking front's (the rims of
//! [`crate::stain::diffuse`]; holding a level pool's film too moved the presets' rims,
//! wine's rim/centre to 1.72). So
//! - a run's front advances only as fast as the flux fills the holdup ahead of it, and
//!   stops when the excess over `h_r` (and over what the fibres take) is used up: the
//!   area its film stands on is `(fed − absorbed) / h_r` (`tests/runs.rs`: within 8 %;
//!   the fibres' wicking wets a margin beyond it);
//! - the liquid left behind soaks into the fibres at `K_p` for as long as it stays,
//!   and their solute is adsorbed at `K_d`: the path is stained in proportion to the time
//!   liquid stood there, not to the time the front took to pass;
//! - with the irregular fabric the holdup varies (the fabric's multiplier): the front
//!   advances where it is smaller and lags where it is larger, fingers;
//! - at a hem (the boundary below) the flux closes: what arrives gathers there, up to
//!   what a hem holds, and with [`StainParams::drip_hold`] the rest drips off
//!   ([`crate::stain::drip`], after the transport of each sub-step).
//!
//! Mass is moved, never made: `f = (f − held) + held`, exact to the rounding.
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
//! ## Sub-steps after a pour
//! The phases are split, and the interactions' time scales are short: the fibres take
//! up free liquid at `K_p` (`1/K_p = 0.5 s` for the presets), so in a sub-step of a
//! minute (a scene whose clock runs at a minute a frame) a fresh spill spreads for the
//! whole minute before the fibres hold any of it, and dries too wide and too even: a pool
//! of coffee (0.8 kg/m², 1.6 cm; `tests/long_frames.rs`) dried to an outline of 76.5 mm
//! radius with a rim/centre of 0.88 in 60-s steps, 51.5 mm and 3.41 in 2-s steps. What
//! needs the short steps is the first seconds, while the spill spreads; the drying that
//! follows is slow. So with
//! [`StainParams::first_substep`] `h₀ > 0`, liquid poured ([`Simulator::add_liquid`])
//! starts a ramp: the next sub-steps are `h₀, 2h₀, 4h₀, …`, carried on from frame to
//! frame, the last one of a frame cut to end on it, until a sub-step would be as long as
//! the frame; then frames are stepped as before (bit for bit). Each piece of the ramp is
//! split further where the turn asks more sub-steps (equal parts of at most the turn's
//! length). With `h₀ = 0.25 s` the same pool dried to 48.5 mm and 2.85 in 60-s frames,
//! in 76 sub-steps over the hour (the 2-s steps took 1800): a frame of `H` after a pour
//! costs about `log₂(H/h₀)` more sub-steps, and frames shorter than `h₀` (a scene at
//! 24 fps with the add-on's 0.25 s) none.
//!
//! The same holds when the frames themselves lengthen (a Frame Time keyed from 1/24 s
//! while the cloth falls to minutes while the stain dries): with `h₀ > 0`, a frame more
//! than twice as long as the one before starts a ramp at twice the last frame's longest
//! sub-step, so the liquid still running at the change is not stepped over minutes at
//! once. With frames of one length this never happens.
//!
//! ## Window reach
//! A frame's window is planned before the frame, when its transport sub-cycles are not
//! known yet: the liquid crosses at most one ring per sub-cycle, and the reach counts
//! the last frame's. A frame that needs more (the cloth jerked, the liquid was flung
//! after a still frame) would run its liquid into the window's no-flux edge, where it
//! piles up along a straight line of rings. So after the frame the reach counts its own
//! sub-cycles, and if the liquid grown by that many rings no longer fits the window, the
//! frame is not committed but run again on a window planned for them
//! ([`Profile::window_retries`]). Each retry widens the reach, so the tries end; a frame
//! that fits costs nothing more, and the stain is the whole mesh's (a test jerks a still
//! cloth by 1.2 m in a frame: without the retry the window's result is off by 1.7 times
//! the peak, with it by 3e-20).
//!
//! Diffusion is not bound to a ring per sub-cycle: a wicking front iterated until it
//! settles ([`crate::stain::Wicking::tolerance`]) crosses as many rings in one long step
//! as the physics asks. Where it reaches the region's edge the no-flux wall stops it along
//! a line of graph distance, a hexagon on a grid of one-way diagonals, an octagon on
//! alternating ones; the gallery's coffee, whose fibres take the liquid up as it arrives,
//! dried as such a hexagon. So after the frame, liquid (free or absorbed solvent) or
//! dissolved solute above [`WALL_THRESHOLD`] of its peak on a vertex of the region's edge
//! also sends the frame back: the reach gains rings ([`Simulator::spread_rings`], doubled
//! until the window changes) and the frame runs again.
//!
//! ## Failure
//! [`Simulator::step`] works on the window's copy of the state and writes it back only
//! when the whole frame succeeded: an error (bad positions naming the vertex, a solver
//! failure) leaves the simulator at the last good frame.

//!
//! ## Files
//! This file holds the [`Simulator`], its parameters and its construction; the frame and
//! its sub-step count (`frame.rs`), the sub-step's phases (`substep.rs`), the window's
//! upkeep between frames (`window.rs`), what is poured on the cloth (`sources.rs`), what
//! is read out of the state (`readout.rs`); the data they share: the phase times
//! ([`Profile`], `profile.rs`) and the arrays kept from frame to frame (`scratch.rs`).

use std::sync::atomic::AtomicU64;

use faer::Par;
use glam::{DVec2, DVec3};

use super::check::check_range;
use super::diffuse::{Conductivity, DENSITY_TOLERANCE, VELOCITY_TOLERANCE, Wicking};
use super::forces::{Forces, corotating_frames_with, rest_frames};
use super::interact::InteractionRates;
use super::irregular::Irregularity;
use super::state::{Fields, State};
use super::window::{Cloth, Window};
use crate::error::{Error, ParamError};
use crate::mesh::geometry::check_positions;
use crate::mesh::{Geometry, OneRings, RingAdjacency, Topology};
use crate::ops::WarmCg;
use scratch::StepScratch;

mod frame;
mod profile;
mod readout;
mod scratch;
mod sources;
mod substep;
mod window;

pub use profile::Profile;

/// A vertex is "dry" for the evaporation boundary rule (eq. 4.8) below this liquid
/// density, kg/m² (1 g/m², a film of water 1 µm thick).
pub(crate) const DRY_DENSITY: f64 = 1e-3;

/// Largest turn of a vertex frame about its normal in one sub-step, rad (module doc,
/// "Fast rotation"): a frame that turns faster gets more sub-steps.
pub(crate) const MAX_TURN: f64 = 0.1;

/// Most sub-steps a frame takes on its own to keep the turn per sub-step below
/// [`MAX_TURN`] (a frame turning by 6.4 rad, a full turn, in one frame).
pub(crate) const MAX_AUTO_SUBSTEPS: usize = 64;

/// The default [`StainParams::film_creep`] `κ`: a pinned film's faces keep a tenth of the
/// free liquid's conductivity (module doc, "Runs"). Over a run's seconds the film creeps a
/// few millimetres, so the holdup's volume law holds (`tests/runs.rs`); over a drying
/// frame of minutes it evens out, where at `κ = 0` a film the transport left uneven
/// dries in points.
pub const FILM_CREEP: f64 = 0.1;

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
    /// `φ`, from 0 (exclusive) to 1: the share of the dissolved solute the solvent's flow
    /// carries at each transfer with [`Self::carry_solute`]; the rest stays where it is.
    /// Applied at every transfer, the solute moves at `φ` times the liquid's speed: a
    /// linear retardation `R = 1/φ` (a sorbing solute in a porous medium, Freeze & Cherry
    /// 1979, ch. 9), in the spreading as in the drying. It does not model a Marangoni return
    /// of the drying flow alone (Hu & Larson 2006): measured (`tests/rims.rs`'s liquids),
    /// wine's rim/centre with `φ = 0.5` is 0.57, a dark centre, not a modest rim. 1 (the
    /// default) carries it all, the coffee-ring flow of Deegan et al. (1997).
    pub carried_fraction: f64,
    /// `α_L`, m, ≥ 0: the longitudinal dispersivity of the carried solute in the fibres
    /// (mechanical dispersion `D = α_L |u|`, Bear 1972), so the solute spreads back against
    /// the flow that brings it and a tide line is about `α_L` wide at any mesh spacing
    /// ([`super::diffuse`], "Tide lines"); the upwind sweep's own dispersion (half an
    /// edge) is subtracted. 0 (the default) is off.
    pub dispersivity: f64,
    /// The evaporation is limited by the diffusion of vapour away from the flat wet patch:
    /// fastest at its edge, `J/J̄ = R/(2√(d(2R − d)))` at distance `d` from the edge
    /// ([`super::interact`], "Vapour-limited evaporation"), instead of eq. 4.8's factor on
    /// the outermost vertices. Off by default.
    pub vapour_limited: bool,
    /// `h_r`, kg/m²: the free liquid a vertex holds back from the flow (the run's
    /// holdup, module doc "Runs"): a film pinned in the weave's pores that the liquid
    /// running over it must first fill, and which stays behind, soaking into the fibres
    /// and dyeing them, when the run has passed. Scaled by the irregular fabric's
    /// multiplier. 0 (the default) is off.
    pub holdup: f64,
    /// `κ`, from 0 to 1: the share of the free liquid's conductivity left on a face where
    /// the run's holdup pins the film (module doc, "Runs"): the pinned film creeps at `κ`
    /// times the rate of the liquid above it. 1 is off (the holdup acts in the transport
    /// alone); the default 0.1 keeps a run's film at `h_r` over the seconds it runs
    /// (`tests/runs.rs`) and evens it out over the minutes it dries. Acts with a holdup.
    pub film_creep: f64,
    /// `λ`, kg/m: the free liquid a hanging hem holds per metre of the cloth's border
    /// before it drips off ([`crate::stain::drip`]); what drips is counted in
    /// [`super::Totals`]. 0 (the default) is off: the border holds everything.
    pub drip_hold: f64,
    /// `H`, m: the capillary height of the fabric, how high a vertical strip wicks up from
    /// a reservoir; with it the fibres' liquid drains along the body force at the wicking's
    /// conductivity over `H` ([`crate::stain::drain`], Richards' equation), so a hanging
    /// wet region spreads down faster than up and rises no higher than capillarity holds
    /// it. Acts with [`Self::carry_solute`] (the fibres' liquid moves only then). 0 (the
    /// default) is off: the wicking has no weight.
    pub capillary_height: f64,
    /// Sub-steps per frame, at least: a frame whose vertex frames turn by more than
    /// [`MAX_TURN`] takes more on its own (module doc, "Fast rotation").
    pub substeps: u32,
    /// `h₀`, s, ≥ 0: after liquid is poured, the sub-steps start this long and double
    /// from one to the next until they reach the frame's own (module doc, "Sub-steps after
    /// a pour"). 0 (the default) is off.
    pub first_substep: f64,
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
            carried_fraction: 1.0,
            dispersivity: 0.0,
            vapour_limited: false,
            holdup: 0.0,
            film_creep: FILM_CREEP,
            drip_hold: 0.0,
            capillary_height: 0.0,
            substeps: 1,
            first_substep: 0.0,
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
            "first substep",
            self.first_substep,
            self.first_substep >= 0.0,
            "finite and ≥ 0",
        )?;
        check_range(
            "residual saturation",
            self.residual_saturation,
            (0.0..1.0).contains(&self.residual_saturation),
            "from 0 to 1 (exclusive)",
        )?;
        check_range(
            "carried fraction",
            self.carried_fraction,
            self.carried_fraction > 0.0 && self.carried_fraction <= 1.0,
            "in (0, 1]",
        )?;
        check_range(
            "dispersivity",
            self.dispersivity,
            self.dispersivity >= 0.0,
            "finite and ≥ 0",
        )?;
        check_range("holdup", self.holdup, self.holdup >= 0.0, "finite and ≥ 0")?;
        check_range(
            "film creep",
            self.film_creep,
            (0.0..=1.0).contains(&self.film_creep),
            "from 0 to 1",
        )?;
        check_range(
            "drip hold",
            self.drip_hold,
            self.drip_hold >= 0.0,
            "finite and ≥ 0",
        )?;
        check_range(
            "capillary height",
            self.capillary_height,
            self.capillary_height >= 0.0,
            "finite and ≥ 0",
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
    /// Rings the reach adds for a spread the transport's sub-cycles do not count: a
    /// wicking front that crossed more rings in a frame than planned reached the
    /// region's no-flux edge (module doc, "Window reach"). It only grows.
    pub(super) spread_rings: usize,
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
                previous_dt: 0.0,
                frames,
                stamp: vec![0.0; n],
                vertex_area: geometry.vertex_area,
                velocity: vec![DVec2::ZERO; n],
                fields: Fields::zeros(n),
                evaporated: 0.0,
                dripped: (0.0, 0.0),
                time: 0.0,
                ramp: 0.0,
                longest_substep: 0.0,
                stained: Vec::new(),
                is_stained: vec![false; n],
            },
            profile: Profile::default(),
            window: None,
            rescan: true,
            last_frame_cycles: 1,
            spread_rings: 0,
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
