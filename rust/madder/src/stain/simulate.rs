//! The split-step stain simulator on a deforming mesh (seed §4.3, Fig. 1.3; eqs. 4.1–4.10).
//!
//! State per vertex: the tangent velocity `u_i` (in the comoving–corotating frame `F_i`,
//! [`super::forces`]), the free solvent `σ_f` and the solute dissolved in it `σ_s` (which
//! flow), the absorbed solvent `σ_p` and absorbed solute (held in the fibres), and the
//! adsorbed solute (the permanent deposit). Densities are per unit area; the simulator
//! stores **masses** `m_i = A_i σ_i` (`A_i` the lumped vertex area) because the liquid in
//! a cloth moves with the cloth: when the mesh stretches, the masses ride on the
//! vertices and the densities are re-read on the new areas. Total solute is then a plain
//! sum that only rounding can change.
//!
//! One frame `t → t + H` is `S` sub-steps of `h = H/S`, the positions interpolated
//! linearly between the two frames. Each sub-step, on the geometry at its end:
//!
//! 1. **Forces** (§4.4), the first half: `u̇ = a − k u − 2ω_z J u` over `h/2`, `a` the
//!    tangential gravity and rectilinear force in `F_i`, `k` the drag of the fibres on
//!    the liquid (`k = 0` is the seed's frictionless liquid), `ω` the frames' angular
//!    velocity over the sub-step: integrated exactly for constant `a` and `ω`
//!    ([`super::forces::integrate_velocity`]), so the liquid reaches its terminal
//!    velocity `a/k` at any step (a kick followed by the decay `e^{−kh}` reaches 30 % of
//!    it at 24 fps), and the Coriolis force turns it without changing its speed. The
//!    velocity is then **extended** over the dry cloth from the wet region
//!    ([`super::extend`]): it is the liquid's, and the dry value is what arriving liquid
//!    reads.
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
//!    viscosity, eq. 4.6. Both by warm-started CG ([`crate::ops::WarmCg`]).
//! 5. **Interactions** (§4.5): absorption, adsorption, evaporation ([`super::interact`]).
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
//! be), from the frames at the start of the frame to the Kabsch frames at its end.
//!
//! ## Conservation and sign (why the clamps are safe)
//! The system conserves mass exactly (`1ᵀ(M + hK) = 1ᵀM`) and CG to its tolerance; after
//! each solve the field is rescaled by `Σm / Σm'` so that the total is restored to
//! rounding (a relative correction ≤ 1e-12, proportional, so it keeps zeros and signs).
//! The FEM stiffness is not an M-matrix on obtuse triangles or with strongly anisotropic
//! tensors, so implicit diffusion can leave a tiny negative mass just outside a sharp
//! front. Those deficits are filled from the vertex's positive neighbours, in proportion
//! to their masses (a conservative local redistribution), and anything left — only if
//! the neighbours hold less than the deficit — from all positive vertices in proportion.
//! So every density stays `≥ 0` and every total is kept. Advection is non-negative and
//! conservative by construction ([`super::advect`]); so are the interactions.
//!
//! For the velocity's Bochner Laplacian the edge weights are clamped at zero: with
//! negative (non-Delaunay) weights `K_∇` can be indefinite ([`crate::ops::connection`]),
//! and the velocity diffusion is a viscosity, whose job is smoothing; clamping makes it
//! positive semi-definite on every mesh (the scalar diffusion of the densities keeps the
//! consistent weights).
//!
//! ## Window and active region
//! A stain usually covers a small part of the cloth, so with `active_region` (the
//! default) a frame works on a *window*, a mesh of its own cut out of the cloth:
//!
//! - the **active** vertices: those holding flowing liquid — free solvent or dissolved
//!   solute density above [`ACTIVE_THRESHOLD`] (1e-12) of that field's peak — grown by
//!   [`ACTIVE_RINGS`] (3) rings plus one ring per transport sub-cycle of the frame's
//!   sub-steps (liquid moves at most one ring per sub-cycle, so it cannot reach the
//!   region's edge within the frame). Every phase runs on them. (A threshold of exactly
//!   zero would not do: implicit diffusion gives every vertex of the region a positive,
//!   if 1e-30-level, mass, so the region would grow every step until it covered the
//!   cloth.)
//! - the **held** vertices: not flowing, but holding absorbed solvent or solute above
//!   the same fraction of its peak, which the interactions still change. What is left
//!   below the thresholds everywhere else is *dust* (the far tail of implicit diffusion,
//!   1e-12 of the peaks and less): it stays untouched until liquid comes near again, and
//!   keeps the area of its last step.
//! - the **halo**: the other corners of the active and held vertices' faces, so that
//!   their one-rings are whole: their areas, Kabsch frames, connection and exposure are
//!   exactly the cloth's. The halo holds nothing that can change; it is not written back.
//!
//! Geometry, frames, connection, forces, advection, diffusion and interactions all run on
//! the window only; the cloth outside it costs nothing per frame but reading the
//! positions. A frame gathers the window's state, steps it, and writes it back. The window
//! is kept from frame to frame while the liquid's needed region stays inside its active
//! vertices and is at least half of it; a new one reaches twice as far as the frame
//! needs, plus [`WINDOW_SLACK_RINGS`] rings, so that it lasts a few frames (building one is a topology, fans,
//! patterns and solvers on the window). With `active_region` off, the window is the whole
//! mesh, every vertex active: one code path.
//!
//! - **Diffusion.** `(M + h K_A) σ' = m` on the active vertices, `K_A` keeping the
//!   stiffness of the edges with both ends active, each diagonal recomputed as minus the
//!   sum of its row's kept off-diagonals: a Neumann (no-flux) boundary at the region's
//!   edge. So `1ᵀK_A = 0`, the restricted solve conserves mass exactly like the whole
//!   one, and the total is restored over the region after the solve; the negative-mass
//!   repair draws only from active vertices. The velocity's Bochner system is restricted
//!   the same way (block rows and columns of the active vertices, `K_ii = Σ_{j active}
//!   L_ij` with the clamped weights).
//! - **Advection.** The semi-Lagrangian back-trace runs for active vertices only, and the
//!   flux across every edge with an end outside the active region is zero: the upwind
//!   transport is closed inside it.
//! - **Velocities outside.** The velocity of a vertex that is not in the window is not
//!   stepped. Each vertex keeps the time of its last step and its frame then; when it
//!   enters a window, its velocity is brought to now by the exact solution of the force
//!   equation over the time between, with the current body force and the frame's mean
//!   turn since ([`super::forces::integrate_velocity`]). For forces that did not change in
//!   between this is what stepping it all along would have given: uniform acceleration
//!   (`u + a t` without friction), terminal velocity, steady rotation. (A turn of more
//!   than half a revolution between is aliased.) Dry liquid velocity is a fiction
//!   anyway: it only matters once liquid arrives, and by then the vertex has been
//!   active for [`ACTIVE_RINGS`] sub-steps at least.
//! - **Areas outside.** The window writes back the areas of its active and held vertices;
//!   after each frame the areas of every other vertex that holds a deposit are recomputed
//!   from their faces, so the densities read out are current everywhere.
//!
//! What it truncates: the far tail of implicit diffusion, which on the whole mesh spreads
//! mass beyond the three rings at levels ~1e-12 of the peak and below, and the viscous
//! coupling of the liquid's velocity to the velocity of the dry cloth more than three
//! rings away. With no evaporation the two steps agree to rounding (tests: 6e-15 of the
//! peak after 200 steps). Evaporation drains every vertex holding less than one step's
//! evaporation to zero, so the wet edge is sharp and the whole-mesh step leaks about
//! 1e-10 of the peak per step past three rings, where it evaporates at once; the region
//! keeps that liquid (measured: up to 1e-5 of the peak after 200 steps).
//!
//! ## Failure
//! [`Simulator::step`] works on the window's copy of the state and writes it back only
//! when the whole frame succeeded: an error (bad positions naming the vertex, a solver failure) leaves
//! the simulator at the last good frame.

use std::time::Instant;

use faer::Par;
use glam::{DMat3, DVec2, DVec3};
use rayon::prelude::*;

use super::advect::{UpwindPlan, advect_velocity_in, dual_fluxes};
use super::diffuse::{Conductivity, check_range};
use super::extend::{extend_velocity, wet_vertices};
use super::forces::{
    Forces, corotating_frames_with, frame_angular_velocity, frame_body_acceleration,
    integrate_velocity, rest_frames, second_difference,
};
use super::interact::{Fields, InteractionRates, exposure, interact};
use crate::error::{Error, ParamError};
use crate::mesh::geometry::{check_positions, vertex_area};
use crate::mesh::{Connection, Geometry, OneRings, RingAdjacency, Topology, VertexFrames};
use crate::ops::{LowerCsc, VertexPattern, WarmCg, cotan_stiffness};
use crate::rng::SplitMix64;

/// A vertex is "dry" for the evaporation boundary rule (eq. 4.8) below this liquid
/// density, kg/m² (1 g/m², a film of water 1 µm thick).
pub const DRY_DENSITY: f64 = 1e-3;

/// Relative residual at which the density solves stop. The total is restored exactly
/// after each solve (module doc), so this only limits the accuracy of the profile: 1e-9
/// of the field's norm is far below what a frame can show (a stain is read to ~1e-3).
/// On the waving-flag benchmark at 10k vertices it takes 13 iterations per field, against
/// 15 at 1e-10.
pub const DENSITY_TOLERANCE: f64 = 1e-9;

/// Relative residual of the velocity's (Bochner) solve: the viscosity only smooths the
/// velocity, which then moves the liquid over one step, so 1e-8 is ample.
pub const VELOCITY_TOLERANCE: f64 = 1e-8;

/// Rings of vertices the active region keeps around the flowing liquid, on top of one ring
/// per transport sub-cycle of the previous sub-step (module doc).
pub const ACTIVE_RINGS: usize = 3;

/// A vertex holds flowing liquid when its free-solvent or dissolved-solute density is
/// above this fraction of that field's largest density (module doc, "Active region").
pub const ACTIVE_THRESHOLD: f64 = 1e-12;

/// Rings a new window's active region gets beyond what the frame needs, on top of the
/// frame's own reach again (room for about two more frames of the same flow), so that the
/// window is not rebuilt every frame (module doc).
pub const WINDOW_SLACK_RINGS: usize = 4;

/// A window is rebuilt when its active region exceeds twice the needed one plus this
/// many vertices (the liquid shrank or dried).
pub const WINDOW_SLACK_VERTICES: usize = 256;

/// Largest turn of a vertex frame about its normal in one sub-step, rad (module doc,
/// "Fast rotation"): a frame that turns faster gets more sub-steps.
pub const MAX_TURN: f64 = 0.1;

/// Most sub-steps a frame takes on its own to keep the turn per sub-step below
/// [`MAX_TURN`] (a frame turning by 6.4 rad, a full turn, in one frame).
pub const MAX_AUTO_SUBSTEPS: usize = 64;

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
    /// Sub-steps per frame, at least: a frame whose vertex frames turn by more than
    /// [`MAX_TURN`] takes more on its own (module doc, "Fast rotation").
    pub substeps: u32,
    /// Step only the vertices near the flowing liquid (module doc, "Active region");
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
        self.interaction.validate()
    }
}

/// Everything that changes during a bake (committed frame by frame).
#[derive(Debug, Clone)]
struct State {
    positions: Vec<DVec3>,
    previous: Option<Vec<DVec3>>,
    /// The frame of every vertex at `stamp`, the time its velocity was last stepped
    /// (vertices outside the window are not stepped: module doc, "Window").
    frames: VertexFrames,
    stamp: Vec<f64>,
    /// Lumped areas at the current frame of every vertex that holds anything (and of the
    /// window's vertices); other vertices keep the area they had when last needed.
    vertex_area: Vec<f64>,
    velocity: Vec<DVec2>,
    fields: Fields,
    evaporated: f64,
    time: f64,
    /// Vertices that have ever held liquid or solute (their areas are kept current).
    stained: Vec<u32>,
    is_stained: Vec<bool>,
}

/// Totals over the mesh (kg), for conservation checks and reports.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Totals {
    /// Free + absorbed solvent.
    pub solvent: f64,
    /// Dissolved + absorbed + adsorbed solute.
    pub solute: f64,
    /// Solvent evaporated since the start.
    pub evaporated: f64,
}

/// The stain simulator of chapter 4 on one cloth.
#[derive(Debug)]
pub struct Simulator {
    /// The whole cloth.
    cloth: Cloth,
    params: StainParams,
    loose: Vec<bool>,
    solute_color: [f64; 3],
    state: State,
    profile: Profile,
    /// The window of the last frame (kept while the liquid stays well inside it).
    window: Option<Window>,
    /// Liquid may have been poured outside the window: the next frame looks for it on
    /// the whole mesh.
    rescan: bool,
    /// Transport sub-cycles of the last frame, all its sub-steps together (widens the
    /// next region: liquid moves at most one ring per sub-cycle).
    last_frame_cycles: usize,
}

/// A triangle mesh with what every phase reads: the whole cloth, or a window cut out of it.
#[derive(Debug)]
struct Cloth {
    topology: Topology,
    /// Fans of faces around every vertex.
    rings: OneRings,
    /// Vertex neighbours in edge order (the Kabsch sums, the negative-mass repair).
    adjacency: RingAdjacency,
    rest: Vec<DVec3>,
    rest_frames: VertexFrames,
    /// The fabric's diffusion of the densities.
    conductivity: Conductivity,
    /// The cloth's border, per vertex.
    boundary: Vec<bool>,
}

/// The part of the cloth a frame works on (module doc, "Window"): the *active* vertices
/// (every phase), the *held* ones (wet but not flowing: interactions only), and the
/// *halo*, the other corners of their faces, as a mesh of its own.
#[derive(Debug)]
struct Window {
    /// Mesh vertex of every window vertex, increasing.
    vertices: Vec<u32>,
    /// The window as a mesh of its own (its `boundary` is the cloth's border, not the
    /// window's edge).
    cloth: Cloth,
    pattern: VertexPattern,
    /// Window vertices that are active or held: their whole one-ring is in the window,
    /// so their areas, frames and interactions are those of the cloth.
    whole: Vec<u32>,
    /// The active vertices and the restricted operators on them.
    region: Region,
    cg: Option<(WarmCg, WarmCg)>,
    /// Per mesh vertex: active.
    mask: Vec<bool>,
    /// Per mesh vertex: active or held.
    whole_mask: Vec<bool>,
}

impl Window {
    /// The window of the mesh vertices flagged `active` or `held`.
    fn new(sim: &Simulator, mask: Vec<bool>, held: &[bool]) -> Result<Option<Self>, Error> {
        let topo = &sim.cloth.topology;
        let n = topo.n_vertices();
        let whole_mask: Vec<bool> = (0..n).map(|v| mask[v] || held[v]).collect();
        let mut faces: Vec<u32> = (0..n)
            .filter(|&v| whole_mask[v])
            .flat_map(|v| sim.cloth.rings.wedges(v).iter().map(|w| w.face))
            .collect();
        if faces.is_empty() {
            return Ok(None);
        }
        faces.sort_unstable();
        faces.dedup();
        let mut local = vec![u32::MAX; n];
        for &f in &faces {
            for v in topo.faces()[f as usize] {
                local[v as usize] = 0;
            }
        }
        let vertices: Vec<u32> = (0..n as u32).filter(|&v| local[v as usize] == 0).collect();
        for (j, &v) in vertices.iter().enumerate() {
            local[v as usize] = j as u32;
        }
        let tris = faces
            .iter()
            .map(|&f| topo.faces()[f as usize].map(|v| local[v as usize]))
            .collect();
        let topology = Topology::from_triangles(vertices.len(), tris)?;
        // the fans walked in the cloth's sense (its harmonized orientation)
        let flipped = faces
            .iter()
            .map(|&f| sim.cloth.rings.face_flipped()[f as usize])
            .collect();
        let rings = OneRings::with_orientation(&topology, flipped);
        let adjacency = RingAdjacency::new(&topology);
        let pattern = VertexPattern::new(&topology);
        let mut slot_edge = vec![u32::MAX; pattern.nnz()];
        for (e, &s) in pattern.edge_slot().iter().enumerate() {
            slot_edge[s as usize] = e as u32;
        }
        let region = Region::new(&pattern, &slot_edge, pick(&vertices, &mask));
        let cg = region.solvers();
        let cloth = Cloth {
            rest: pick(&vertices, &sim.cloth.rest),
            rest_frames: VertexFrames {
                frame: pick(&vertices, &sim.cloth.rest_frames.frame),
            },
            conductivity: sim.cloth.conductivity.faces(&faces),
            boundary: pick(&vertices, &sim.cloth.boundary),
            topology,
            rings,
            adjacency,
        };
        Ok(Some(Self {
            whole: (0..vertices.len() as u32)
                .filter(|&j| whole_mask[vertices[j as usize] as usize])
                .collect(),
            vertices,
            cloth,
            pattern,
            region,
            cg,
            mask,
            whole_mask,
        }))
    }

    /// `values` of every mesh vertex, in window order.
    fn gather<T: Copy>(&self, values: &[T]) -> Vec<T> {
        pick(&self.vertices, values)
    }
}

/// Every value finite and `≥ 0`, else the error names the first vertex that is not.
fn check_each_nonnegative(name: &'static str, values: &[f64]) -> Result<(), ParamError> {
    match values.iter().position(|x| !(x.is_finite() && *x >= 0.0)) {
        None => Ok(()),
        Some(index) => Err(ParamError::OutOfRangeAt {
            name,
            index,
            requirement: "finite and ≥ 0",
            value: values[index],
        }),
    }
}

/// `values[i]` for every `i` of `index`, in that order.
fn pick<T: Copy>(index: &[u32], values: &[T]) -> Vec<T> {
    index.iter().map(|&i| values[i as usize]).collect()
}

/// The active region of a window (module doc): the active vertices, the restricted
/// patterns of the two diffusions and their solvers.
#[derive(Debug)]
struct Region {
    /// Active vertices, increasing.
    vertices: Vec<u32>,
    /// Per vertex: active or not.
    mask: Vec<bool>,
    /// Lower triangle of the restricted scalar operator, local numbering.
    scalar: SubCsc,
    /// Per entry of `scalar`: its edge (`u32::MAX` on the diagonal).
    edge: Vec<u32>,
    /// The `2×2` block expansion of `scalar` (the Bochner system).
    bochner: SubCsc,
}

/// A lower-triangle CSC pattern built at run time.
#[derive(Debug)]
struct SubCsc {
    n: usize,
    col_ptr: Vec<u32>,
    row_idx: Vec<u32>,
}

impl LowerCsc for SubCsc {
    fn n(&self) -> usize {
        self.n
    }
    fn col_ptr(&self) -> &[u32] {
        &self.col_ptr
    }
    fn row_idx(&self) -> &[u32] {
        &self.row_idx
    }
}

impl Region {
    /// The restricted patterns of the vertices flagged in `mask`: column `j` (mesh vertex
    /// `a`) holds its diagonal, then the edges `(a, b)`, `b > a`, with `b` active, in the
    /// order of the mesh pattern (local numbers increase with mesh numbers).
    fn new(pattern: &VertexPattern, slot_edge: &[u32], mask: Vec<bool>) -> Self {
        let vertices: Vec<u32> = (0..mask.len() as u32)
            .filter(|&v| mask[v as usize])
            .collect();
        let nv = vertices.len();
        let mut local = vec![u32::MAX; mask.len()];
        for (j, &v) in vertices.iter().enumerate() {
            local[v as usize] = j as u32;
        }
        let (cp, ri) = (pattern.col_ptr(), pattern.row_idx());
        let mut col_ptr = Vec::with_capacity(nv + 1);
        col_ptr.push(0u32);
        let (mut row_idx, mut edge) = (Vec::new(), Vec::new());
        for (j, &a) in vertices.iter().enumerate() {
            row_idx.push(j as u32);
            edge.push(u32::MAX);
            for s in cp[a as usize] as usize + 1..cp[a as usize + 1] as usize {
                let b = local[ri[s] as usize];
                if b != u32::MAX {
                    row_idx.push(b);
                    edge.push(slot_edge[s]);
                }
            }
            col_ptr.push(row_idx.len() as u32);
        }
        let mut b_ptr = Vec::with_capacity(2 * nv + 1);
        b_ptr.push(0u32);
        let mut b_row = Vec::with_capacity(4 * row_idx.len());
        for j in 0..nv {
            for c in 0..2 {
                b_row.push((2 * j + c) as u32);
                for &r in &row_idx[col_ptr[j] as usize + 1..col_ptr[j + 1] as usize] {
                    b_row.extend([2 * r, 2 * r + 1]);
                }
                b_ptr.push(b_row.len() as u32);
            }
        }
        let scalar = SubCsc {
            n: nv,
            col_ptr,
            row_idx,
        };
        let bochner = SubCsc {
            n: 2 * nv,
            col_ptr: b_ptr,
            row_idx: b_row,
        };
        Self {
            vertices,
            mask,
            scalar,
            edge,
            bochner,
        }
    }

    /// Solvers of the two restricted systems (none for an empty region).
    fn solvers(&self) -> Option<(WarmCg, WarmCg)> {
        (!self.vertices.is_empty()).then(|| {
            (
                WarmCg::new(&self.scalar).with_tolerance(DENSITY_TOLERANCE),
                WarmCg::new(&self.bochner).with_tolerance(VELOCITY_TOLERANCE),
            )
        })
    }

    /// Lower-triangle values of `M + K_A` on the scalar sub-pattern from the mesh
    /// stiffness `full` (on `pattern`, without mass): the off-diagonals of the edges inside
    /// the region (clamped at `≤ 0` if `clamp`), each diagonal `A_i` minus the sum of its
    /// row's kept off-diagonals (Neumann: no flux out of the region, `1ᵀK_A = 0`).
    fn scalar_values(
        &self,
        pattern: &VertexPattern,
        full: &[f64],
        area: &[f64],
        clamp: bool,
    ) -> Vec<f64> {
        let (cp, ri) = (&self.scalar.col_ptr, &self.scalar.row_idx);
        let nv = self.vertices.len();
        let mut values = vec![0.0; ri.len()];
        let mut row = vec![0.0; nv];
        for j in 0..nv {
            for s in cp[j] as usize + 1..cp[j + 1] as usize {
                let mut k = full[pattern.edge_slot()[self.edge[s] as usize] as usize];
                if clamp && k > 0.0 {
                    k = 0.0;
                }
                values[s] = k;
                row[j] += k;
                row[ri[s] as usize] += k;
            }
        }
        for (j, &v) in self.vertices.iter().enumerate() {
            values[cp[j] as usize] = area[v as usize] - row[j];
        }
        values
    }

    /// Values of `M ⊗ I₂ + K_∇` on the block pattern from the scalar values of
    /// [`Region::scalar_values`] and the connection (as [`bochner_stiffness`]).
    fn bochner_values(&self, scalar: &[f64], connection: &Connection) -> Vec<f64> {
        let cp = &self.scalar.col_ptr;
        let cos_sin = connection.edge_cos_sin();
        let mut values = Vec::with_capacity(self.bochner.row_idx.len());
        for j in 0..self.vertices.len() {
            let (lo, hi) = (cp[j] as usize, cp[j + 1] as usize);
            for c in 0..2 {
                values.push(scalar[lo]);
                for s in lo + 1..hi {
                    let k = scalar[s];
                    let [cos, sin] = cos_sin[self.edge[s] as usize];
                    if c == 0 {
                        values.extend([k * cos, -k * sin]);
                    } else {
                        values.extend([k * sin, k * cos]);
                    }
                }
            }
        }
        values
    }
}

/// Where the liquid is (module doc, "Window"): among the vertices `scan`, those holding
/// flowing liquid — free solvent or dissolved solute density above [`ACTIVE_THRESHOLD`]
/// of that field's peak over `scan` — and the others holding absorbed solvent or solute
/// above that fraction of its peak (held). What is left below the thresholds is *dust*
/// (1e-12 of the peaks and less, the far tail of implicit diffusion): it stays where it
/// is, untouched, until liquid comes near again. Loose vertices are neither.
fn find_liquid(
    scan: &[u32],
    loose: &[bool],
    fields: &Fields,
    area: &[f64],
) -> (Vec<u32>, Vec<u32>) {
    let floor = |m: &[f64]| {
        ACTIVE_THRESHOLD
            * scan
                .iter()
                .map(|&v| v as usize)
                .filter(|&v| area[v] > 0.0)
                .map(|v| m[v] / area[v])
                .fold(0.0, f64::max)
    };
    let f = fields;
    let flowing_floor = [floor(&f.free_solvent), floor(&f.solute)];
    let held_floor = [floor(&f.absorbed_solvent), floor(&f.absorbed_solute)];
    let (mut flowing, mut held) = (Vec::new(), Vec::new());
    for &v in scan {
        let i = v as usize;
        let above = |m: &[f64], floor: f64| m[i] > 0.0 && m[i] > floor * area[i];
        if loose[i] {
        } else if above(&f.free_solvent, flowing_floor[0]) || above(&f.solute, flowing_floor[1]) {
            flowing.push(v);
        } else if above(&f.absorbed_solvent, held_floor[0])
            || above(&f.absorbed_solute, held_floor[1])
        {
            held.push(v);
        }
    }
    (flowing, held)
}

/// `seeds` grown by `rings` rings of neighbours (loose vertices excluded), as a mask and
/// as a list.
fn grow(
    adjacency: &RingAdjacency,
    loose: &[bool],
    seeds: &[u32],
    rings: usize,
) -> (Vec<bool>, Vec<u32>) {
    let mut mask = vec![false; loose.len()];
    let mut front = seeds.to_vec();
    let mut all = seeds.to_vec();
    for &v in seeds {
        mask[v as usize] = true;
    }
    for _ in 0..rings {
        let mut next = Vec::new();
        for &v in &front {
            for &w in adjacency.neighbours(v as usize) {
                if !mask[w as usize] && !loose[w as usize] {
                    mask[w as usize] = true;
                    next.push(w);
                }
            }
        }
        all.extend_from_slice(&next);
        front = next;
    }
    (mask, all)
}

/// Wall-clock seconds spent in each phase since the simulator was built (for benchmarks).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Profile {
    /// Finding the liquid and (re)building the window.
    pub window: f64,
    /// Geometry, comoving–corotating frames (Kabsch) and the connection.
    pub geometry: f64,
    /// Body forces (and bringing the velocities of vertices entering the window up to
    /// date).
    pub forces: f64,
    /// Velocity and density advection.
    pub advection: f64,
    /// Diffusion of the densities and of the velocity (assembly and CG; the two run
    /// side by side).
    pub diffusion: f64,
    /// Interactions.
    pub interaction: f64,
    /// Sub-steps taken.
    pub substeps: usize,
    /// CG iterations of the density solves (all fields) and of the velocity solve.
    pub density_iterations: usize,
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
}

/// One frame's work on a window, committed when the whole frame succeeded.
struct Local {
    velocity: Vec<DVec2>,
    frames: VertexFrames,
    fields: Fields,
    area: Vec<f64>,
    evaporated: f64,
    /// Transport sub-cycles of the last sub-step.
    cycles: usize,
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
                rest: rest.to_vec(),
                rest_frames,
                conductivity,
                rings,
                adjacency,
                topology,
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
        })
    }

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
    /// Time spent per phase so far.
    pub fn profile(&self) -> Profile {
        self.profile
    }
    pub fn params(&self) -> &StainParams {
        &self.params
    }
    /// Simulated time since the start, s.
    pub fn time(&self) -> f64 {
        self.state.time
    }
    /// Lumped vertex areas of the current frame, m² (of every vertex that holds or held
    /// anything; a vertex that never did keeps an older area).
    pub fn vertex_area(&self) -> &[f64] {
        &self.state.vertex_area
    }
    /// Per-vertex masses, kg.
    pub fn fields(&self) -> &Fields {
        &self.state.fields
    }
    /// Velocities in the vertex frames, m/s (of each vertex's last step: a vertex outside
    /// the window keeps the value it left it with).
    pub fn velocity(&self) -> &[DVec2] {
        &self.state.velocity
    }
    /// Velocities as world vectors, m/s (as [`Simulator::velocity`], in the frame of each
    /// vertex's last step).
    pub fn velocity_world(&self) -> Vec<DVec3> {
        (0..self.state.velocity.len())
            .map(|i| self.state.frames.to_world(i, self.state.velocity[i]))
            .collect()
    }
    /// Replaces the velocity field by world vectors (projected on each vertex's tangent
    /// plane at the current frame), e.g. an initial condition.
    pub fn set_velocity_world(&mut self, velocity: &[DVec3]) -> Result<(), ParamError> {
        self.check_len("velocity", velocity.len())?;
        if let Some(index) = velocity.iter().position(|u| !u.is_finite()) {
            return Err(ParamError::NonFinite {
                name: "velocity",
                index,
            });
        }
        let st = &mut self.state;
        st.frames = corotating_frames_with(
            &self.cloth.adjacency,
            &self.cloth.rest_frames,
            &self.cloth.rest,
            &st.positions,
        );
        st.velocity = (0..velocity.len())
            .map(|i| st.frames.to_local(i, velocity[i]))
            .collect();
        st.stamp.fill(st.time);
        Ok(())
    }

    /// Density `mass / A_i` of a mass field (0 where a vertex has no area).
    pub fn density(&self, mass: &[f64]) -> Vec<f64> {
        mass.iter()
            .zip(&self.state.vertex_area)
            .map(|(m, a)| if *a > 0.0 { m / a } else { 0.0 })
            .collect()
    }

    /// Liquid density (free + absorbed solvent), kg/m².
    pub fn wetness(&self) -> Vec<f64> {
        let f = &self.state.fields;
        let wet: Vec<f64> = f
            .free_solvent
            .iter()
            .zip(&f.absorbed_solvent)
            .map(|(a, b)| a + b)
            .collect();
        self.density(&wet)
    }

    /// Total solute density (dissolved + absorbed + adsorbed), kg/m².
    pub fn solute_density(&self) -> Vec<f64> {
        let f = &self.state.fields;
        let s: Vec<f64> = (0..f.solute.len())
            .map(|i| f.solute[i] + f.absorbed_solute[i] + f.adsorbed[i])
            .collect();
        self.density(&s)
    }

    /// Adsorbed solute density (the permanent deposit), kg/m².
    pub fn deposit(&self) -> Vec<f64> {
        self.density(&self.state.fields.adsorbed)
    }

    /// Colour of the solute at every vertex (mass-weighted mix of the liquids poured;
    /// the liquid's colour where there is no solute).
    pub fn solute_color(&self) -> Vec<[f64; 3]> {
        let f = &self.state.fields;
        match (&f.color_free, &f.color_held) {
            (Some(cf), Some(ch)) => (0..f.solute.len())
                .map(|i| {
                    let s = f.solute[i] + f.absorbed_solute[i] + f.adsorbed[i];
                    if s > 1e-300 {
                        std::array::from_fn(|k| (cf[i][k] + ch[i][k]) / s)
                    } else {
                        self.solute_color
                    }
                })
                .collect(),
            _ => vec![self.solute_color; f.solute.len()],
        }
    }

    /// Totals over the mesh (sums in vertex order).
    pub fn totals(&self) -> Totals {
        let f = &self.state.fields;
        Totals {
            solvent: f.total_solvent(),
            solute: f.total_solute(),
            evaporated: self.state.evaporated,
        }
    }

    fn check_len(&self, name: &'static str, got: usize) -> Result<(), ParamError> {
        let expected = self.cloth.topology.n_vertices();
        if got == expected {
            Ok(())
        } else {
            Err(ParamError::Length {
                name,
                expected,
                got,
            })
        }
    }

    /// Pours liquid: `solvent[i]` kg/m² of solvent at vertex `i`, carrying
    /// `concentration` kg of solute per kg of solvent, of `color` (default: the liquid's).
    /// A colour different from the liquid's switches on per-vertex colour tracking.
    pub fn add_liquid(
        &mut self,
        solvent: &[f64],
        concentration: f64,
        color: Option<[f64; 3]>,
    ) -> Result<(), ParamError> {
        self.check_len("added solvent", solvent.len())?;
        check_each_nonnegative("added solvent", solvent)?;
        check_range(
            "concentration",
            concentration,
            concentration >= 0.0,
            "finite and ≥ 0",
        )?;
        let color = color.unwrap_or(self.solute_color);
        if let Some(index) = color.iter().position(|c| !c.is_finite()) {
            return Err(ParamError::NonFinite {
                name: "liquid colour",
                index,
            });
        }
        if color != self.solute_color {
            self.enable_color();
        }
        for (i, &d) in solvent.iter().enumerate() {
            if d > 0.0 {
                // the area now (a vertex away from the liquid keeps an older one)
                self.state.vertex_area[i] = self.current_area(i);
                self.mark_stained(i);
            }
        }
        let area = &self.state.vertex_area;
        let f = &mut self.state.fields;
        for (i, &d) in solvent.iter().enumerate() {
            let m = d * area[i];
            f.free_solvent[i] += m;
            f.solute[i] += m * concentration;
            if let Some(cf) = f.color_free.as_mut() {
                for k in 0..3 {
                    cf[i][k] += m * concentration * color[k];
                }
            }
        }
        self.rescan = true;
        Ok(())
    }

    /// Tracks colour per vertex from now on (colour masses = solute × liquid colour).
    fn enable_color(&mut self) {
        let f = &mut self.state.fields;
        if f.color_free.is_some() {
            return;
        }
        let c = self.solute_color;
        f.color_free = Some(f.solute.iter().map(|s| c.map(|x| x * s)).collect());
        f.color_held = Some(
            (0..f.solute.len())
                .map(|i| c.map(|x| x * (f.absorbed_solute[i] + f.adsorbed[i])))
                .collect(),
        );
    }

    /// A splash (seed Fig. 4.3): adds a random outgoing velocity around `center` (world)
    /// to every vertex with `weight > 0`: the tangential direction away from the centre,
    /// turned by a random angle in ±0.5 rad, times `speed · weight` and a random factor in
    /// [0.5, 1.5). Random numbers come from `seed` and the vertex index only, so a splash
    /// is the same on any number of threads and any machine.
    pub fn splash(
        &mut self,
        center: DVec3,
        speed: f64,
        seed: u64,
        weight: &[f64],
    ) -> Result<(), ParamError> {
        self.check_len("splash weights", weight.len())?;
        check_range("splash speed", speed, speed >= 0.0, "finite and ≥ 0")?;
        if !center.is_finite() {
            return Err(ParamError::NonFinite {
                name: "splash centre",
                index: 0,
            });
        }
        check_each_nonnegative("splash weight", weight)?;
        // the splashed vertices' velocities and frames, brought to now
        let splashed: Vec<usize> = (0..weight.len()).filter(|&i| weight[i] > 0.0).collect();
        let now: Vec<(DVec2, DMat3)> = splashed
            .par_iter()
            .map(|&i| self.caught_up(i, DVec3::ZERO))
            .collect();
        let st = &mut self.state;
        for (&i, (u, frame)) in splashed.iter().zip(now) {
            let mut rng = SplitMix64::new(seed ^ (i as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15));
            let (r1, r2, r3) = (rng.unit(), rng.unit(), rng.unit());
            st.frames.frame[i] = frame;
            st.stamp[i] = st.time;
            let out = st.frames.to_local(i, st.positions[i] - center);
            let dir = if out.length() > 0.0 {
                out.normalize()
            } else {
                DVec2::from_angle(std::f64::consts::TAU * r3)
            };
            let turned = DVec2::from_angle(r1 - 0.5).rotate(dir);
            st.velocity[i] = u + turned * (speed * weight[i] * (0.5 + r2));
        }
        Ok(())
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
        let rebuilt = self.prepare_window()?;
        let mut prof = self.profile;
        prof.window_rebuilds += usize::from(rebuilt);
        prof.window += clock.elapsed().as_secs_f64();
        let t_end = self.state.time + dt;
        let mut window = self.window.take();
        let result = match window.as_mut() {
            Some(w) => self
                .run_frame(w, positions, dt, after, &mut prof)
                .map(|local| self.commit(w, local, t_end)),
            None => Ok(()),
        };
        self.window = window;
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

    /// Finds the liquid and keeps or rebuilds the window for the next frame (module doc,
    /// "Window"). Returns whether it was rebuilt.
    fn prepare_window(&mut self) -> Result<bool, Error> {
        let n = self.cloth.topology.n_vertices();
        if !self.params.active_region {
            // the whole mesh, every vertex with a face active, once
            if self.window.is_some() {
                return Ok(false);
            }
            let mask = self.loose.iter().map(|l| !l).collect();
            self.window = Window::new(self, mask, &vec![false; n])?;
            return Ok(true);
        }
        // the liquid is inside the window's whole vertices, unless some was poured since
        // (no window and no pour: there is none but dust)
        let scan: Vec<u32> = match (&self.window, self.rescan) {
            (Some(w), false) => w.whole.iter().map(|&j| w.vertices[j as usize]).collect(),
            (None, false) => return Ok(false),
            _ => (0..n as u32).collect(),
        };
        let st = &self.state;
        let (flowing, held) = find_liquid(&scan, &self.loose, &st.fields, &st.vertex_area);
        // liquid moves at most one ring per transport sub-cycle
        let reach = ACTIVE_RINGS + self.last_frame_cycles;
        let (_, needed) = grow(&self.cloth.adjacency, &self.loose, &flowing, reach);
        let fits = self.window.as_ref().is_some_and(|w| {
            needed.iter().all(|&v| w.mask[v as usize])
                && held.iter().all(|&v| w.whole_mask[v as usize])
                && w.region.vertices.len() <= 2 * needed.len() + WINDOW_SLACK_VERTICES
        });
        self.rescan = false;
        if fits {
            return Ok(false);
        }
        let (mask, _) = grow(
            &self.cloth.adjacency,
            &self.loose,
            &flowing,
            // room for about two more frames of the same flow
            2 * reach + WINDOW_SLACK_RINGS - ACTIVE_RINGS,
        );
        let mut is_held = vec![false; n];
        held.iter().for_each(|&v| is_held[v as usize] = true);
        self.window = Window::new(self, mask, &is_held)?;
        Ok(true)
    }

    /// The velocity and frame of vertex `v` at the start of the frame: a vertex that was
    /// outside the window is brought from its last step to now by the exact solution of
    /// its force equation ([`integrate_velocity`]) over the time between, with the body
    /// acceleration of `acceleration` (`p̈`, world) and the frame's mean turn since
    /// (module doc, "Window").
    fn caught_up(&self, v: usize, acceleration: DVec3) -> (DVec2, DMat3) {
        let st = &self.state;
        let (u, f) = (st.velocity[v], st.frames.frame[v]);
        let gap = st.time - st.stamp[v];
        if gap <= 0.0 {
            return (u, f);
        }
        let now = self
            .cloth
            .adjacency
            .rotation(&self.cloth.rest, &st.positions, v)
            * self.cloth.rest_frames.frame[v];
        if self.loose[v] {
            return (DVec2::ZERO, now);
        }
        let p = &self.params;
        let a = frame_body_acceleration(&now, acceleration, p.gravity, p.forces);
        let turn = if p.forces.coriolis {
            frame_angular_velocity(&f, &now, gap).z
        } else {
            0.0
        };
        (integrate_velocity(u, a, turn, p.friction, gap).0, now)
    }

    /// One frame on the window `w`, on copies of its state: nothing in `self` changes.
    fn run_frame(
        &self,
        w: &mut Window,
        positions: &[DVec3],
        dt: f64,
        after: Option<&[DVec3]>,
        prof: &mut Profile,
    ) -> Result<Local, Error> {
        let clock = Instant::now();
        let (p, st) = (&self.params, &self.state);
        let cur = w.gather(&st.positions);
        let next = w.gather(positions);
        // p̈ over the frame interval: the mean of the centred differences at its two ends
        // when the frame after is known (module doc of `forces`)
        let acceleration: Vec<DVec3> = if p.forces.rectilinear {
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
                .collect()
        } else {
            vec![DVec3::ZERO; w.vertices.len()]
        };
        let (velocity, frame): (Vec<DVec2>, Vec<DMat3>) = w
            .vertices
            .par_iter()
            .zip(&acceleration)
            .map(|(&v, &a)| self.caught_up(v as usize, a))
            .unzip();
        let mut local = Local {
            velocity,
            frames: VertexFrames { frame },
            fields: st.fields.gather(&w.vertices),
            area: w.gather(&st.vertex_area),
            evaporated: 0.0,
            cycles: 0,
        };
        prof.forces += clock.elapsed().as_secs_f64();
        let s_count = self.substeps(w, &next, &local.frames, dt);
        let h = dt / s_count as f64;
        for s in 1..=s_count {
            let between: Vec<DVec3>;
            let q = if s == s_count {
                &next
            } else {
                let t = s as f64 / s_count as f64;
                between = cur.iter().zip(&next).map(|(a, b)| a.lerp(*b, t)).collect();
                &between
            };
            self.substep(w, &mut local, q, h, &acceleration, prof)?;
        }
        Ok(local)
    }

    /// Sub-steps of a frame of `dt` on the window `w` from the vertex frames `start` to the
    /// positions `next` (window order): the user's [`StainParams::substeps`], or more so
    /// that the frames of the active vertices turn (about their normals) by at most
    /// [`MAX_TURN`] per sub-step (module doc, "Fast rotation").
    fn substeps(&self, w: &Window, next: &[DVec3], start: &VertexFrames, dt: f64) -> usize {
        let asked = self.params.substeps as usize;
        if !self.params.forces.coriolis {
            return asked;
        }
        let cloth = &w.cloth;
        let turn = w
            .region
            .vertices
            .par_iter()
            .map(|&j| {
                let j = j as usize;
                let end = cloth.adjacency.rotation(&cloth.rest, next, j) * cloth.rest_frames.frame[j];
                frame_angular_velocity(&start.frame[j], &end, dt).z.abs() * dt
            })
            .reduce(|| 0.0, f64::max);
        // a NaN turn (never from finite positions) keeps the user's count
        let needed = (turn / MAX_TURN).ceil();
        if needed > asked as f64 {
            (needed as usize).min(MAX_AUTO_SUBSTEPS)
        } else {
            asked
        }
    }

    /// One sub-step `h` of the window to positions `q` (window order).
    fn substep(
        &self,
        w: &mut Window,
        loc: &mut Local,
        q: &[DVec3],
        h: f64,
        acceleration: &[DVec3],
        prof: &mut Profile,
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
        let geometry = Geometry::new(topo, q)?;
        let frames =
            corotating_frames_with(&w.cloth.adjacency, &w.cloth.rest_frames, &w.cloth.rest, q);
        let connection = Connection::new(topo, &w.cloth.rings, &geometry, &frames, q);
        prof.active_vertices += w.region.vertices.len();
        prof.window_vertices += n;
        lap(&mut prof.geometry);

        // 1. body forces (§4.4), friction and the Coriolis turn, exactly over half the
        // sub-step at the vertex the liquid leaves (kick–drift–kick, module doc); the
        // densities drift with the exact mean velocity of a whole sub-step under them
        let force: Vec<(DVec2, f64)> = (0..n)
            .into_par_iter()
            .map(|j| {
                let f = &frames.frame[j];
                let a = frame_body_acceleration(f, acceleration[j], p.gravity, p.forces);
                let turn = if p.forces.coriolis {
                    frame_angular_velocity(&loc.frames.frame[j], f, h).z
                } else {
                    0.0
                };
                (a, turn)
            })
            .collect();
        let kick = |u: DVec2, (a, turn): (DVec2, f64), t: f64| {
            integrate_velocity(u, a, turn, p.friction, t)
        };
        let (mut forced, mut mean): (Vec<DVec2>, Vec<DVec2>) = (0..n)
            .into_par_iter()
            .map(|j| {
                let u = loc.velocity[j];
                (kick(u, force[j], 0.5 * h).0, kick(u, force[j], h).1)
            })
            .unzip();
        // the velocity is the liquid's: on the dry cloth it is the wet region's, extended
        let wet = wet_vertices(
            &loc.fields.free_solvent,
            &geometry.vertex_area,
            &w.region.mask,
        );
        extend_velocity(topo, &connection, &wet, &mut [&mut forced, &mut mean]);
        lap(&mut prof.forces);

        // 2. advection (§4.3.1–4.3.2), closed inside the active region
        let active = &w.region.mask;
        let advected = advect_velocity_in(
            topo,
            &w.cloth.rings,
            &geometry,
            &connection,
            &forced,
            h,
            active,
        );
        // the densities move with the sub-step's mean velocity: the exact mean under the
        // forces, plus half the change the advection made at its end (module doc)
        let centred: Vec<DVec2> = (0..n)
            .map(|j| {
                if active[j] {
                    mean[j] + 0.5 * (advected[j] - forced[j])
                } else {
                    DVec2::ZERO
                }
            })
            .collect();
        let mut flux = dual_fluxes(topo, q, &frames, &centred);
        for (phi, &[a, b]) in flux.iter_mut().zip(topo.edges()) {
            if !(active[a as usize] && active[b as usize]) {
                *phi = 0.0;
            }
        }
        let plan = UpwindPlan::new(topo, &geometry.vertex_area, &flux, h)?;
        prof.transport_cycles += plan.substeps();
        loc.cycles += plan.substeps();
        // the momentum advection needs the solvent before its transport
        let solvent_before = p
            .momentum_advection
            .then(|| loc.fields.free_solvent.clone());
        {
            let f = &mut loc.fields;
            let mut color = f.color_free.as_ref().map(|c| split_rgb(c));
            let mut fields: Vec<&mut [f64]> = vec![&mut f.free_solvent, &mut f.solute];
            if let Some(c) = color.as_mut() {
                fields.extend(c.iter_mut().map(|v| v.as_mut_slice()));
            }
            plan.transport_all(topo, &mut fields);
            if let (Some(c), Some(cf)) = (color, f.color_free.as_mut()) {
                merge_rgb(&c, cf);
            }
        }
        let arrived = match solvent_before {
            Some(before) => plan.momentum_velocity(topo, &connection, &before, &forced, &advected),
            None => advected,
        };
        lap(&mut prof.advection);
        // the second half of the forces, at the vertex the liquid arrived at
        loc.velocity = arrived
            .into_par_iter()
            .zip(&force)
            .map(|(u, &f)| kick(u, f, 0.5 * h).0)
            .collect();
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
        let (fields, velocity) = (&mut loc.fields, &mut loc.velocity);
        let (densities, viscous) = match w.cg.as_mut() {
            None => (Ok(0), Ok(0)),
            Some((scalar_cg, vector_cg)) => rayon::join(
                || diffuse_densities(&ops, scalar_cg, fields, &geometry, h),
                || {
                    if p.viscosity > 0.0 {
                        let scale = h * p.viscosity;
                        diffuse_velocity(&ops, vector_cg, velocity, &geometry, &connection, scale)
                    } else {
                        Ok(0)
                    }
                },
            ),
        };
        prof.density_iterations += densities?;
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
        let exposed = exposure(
            topo,
            &w.cloth.boundary,
            &wet,
            DRY_DENSITY,
            p.interaction.evaporation_boundary,
        );
        let mut part = loc.fields.gather(&w.whole);
        loc.evaporated += interact(
            &p.interaction,
            &pick(&w.whole, &geometry.vertex_area),
            &pick(&w.whole, &exposed),
            h,
            &mut part,
        )?;
        loc.fields.scatter(&w.whole, &part);
        loc.frames = frames;
        loc.area = geometry.vertex_area;
        lap(&mut prof.interaction);
        prof.substeps += 1;
        Ok(())
    }

    /// Writes a successful frame on `w` back (module doc, "Window"): fields of every
    /// window vertex (the halo's are unchanged), velocities, frames and areas of the
    /// active and held vertices, stamped `time`.
    fn commit(&mut self, w: &Window, local: Local, time: f64) {
        let st = &mut self.state;
        st.fields.scatter(&w.vertices, &local.fields);
        st.evaporated += local.evaporated;
        for &j in &w.whole {
            let (j, v) = (j as usize, w.vertices[j as usize] as usize);
            st.velocity[v] = local.velocity[j];
            st.frames.frame[v] = local.frames.frame[j];
            st.stamp[v] = time;
            st.vertex_area[v] = local.area[j];
            let f = &st.fields;
            if (f.is_live(v) || f.adsorbed[v] > 0.0) && !st.is_stained[v] {
                st.is_stained[v] = true;
                st.stained.push(v as u32);
            }
        }
        self.last_frame_cycles = local.cycles;
    }

    fn mark_stained(&mut self, v: usize) {
        let st = &mut self.state;
        if !st.is_stained[v] {
            st.is_stained[v] = true;
            st.stained.push(v as u32);
        }
    }

    /// The lumped area of vertex `v` at the current positions.
    fn current_area(&self, v: usize) -> f64 {
        let faces = self.cloth.topology.faces();
        vertex_area(
            self.cloth
                .rings
                .wedges(v)
                .iter()
                .map(|w| faces[w.face as usize]),
            &self.state.positions,
        )
    }

    /// Brings the areas of the stained vertices outside the window to the current frame
    /// (the densities read out are their masses over these areas). Dust — a vertex
    /// holding less than [`ACTIVE_THRESHOLD`] of the largest stain density — is dropped
    /// from the list and keeps its last area (its density is 1e-12 of the peak's; a
    /// window that reaches it again puts it back).
    fn refresh_areas(&mut self) {
        let st = &self.state;
        let f = &st.fields;
        let density = |v: usize| {
            let m = f.free_solvent[v]
                + f.solute[v]
                + f.absorbed_solvent[v]
                + f.absorbed_solute[v]
                + f.adsorbed[v];
            if st.vertex_area[v] > 0.0 {
                m / st.vertex_area[v]
            } else {
                0.0
            }
        };
        let floor = ACTIVE_THRESHOLD
            * st.stained
                .iter()
                .map(|&v| density(v as usize))
                .fold(0.0, f64::max);
        let whole = self.window.as_ref().map(|w| &w.whole_mask);
        let (keep, dust): (Vec<u32>, Vec<u32>) = st
            .stained
            .iter()
            .partition(|&&v| density(v as usize) > floor);
        let stale: Vec<u32> = keep
            .iter()
            .copied()
            .filter(|&v| whole.is_none_or(|m| !m[v as usize]))
            .collect();
        let area: Vec<f64> = stale
            .par_iter()
            .map(|&v| self.current_area(v as usize))
            .collect();
        let st = &mut self.state;
        for (v, a) in stale.into_iter().zip(area) {
            st.vertex_area[v as usize] = a;
        }
        for v in dust {
            st.is_stained[v as usize] = false;
        }
        st.stained = keep;
    }
}

/// The operators of a window the diffusion steps read.
struct Ops<'a> {
    topology: &'a Topology,
    adjacency: &'a RingAdjacency,
    pattern: &'a VertexPattern,
    conductivity: &'a Conductivity,
    region: &'a Region,
}

/// `(M + h K_A) σ' = m` for every flowing field on the active vertices, Neumann at the
/// region's edge (module doc), then the exact mass restoration and the non-negativity
/// repair; the masses outside are not touched. Returns the CG iterations.
fn diffuse_densities(
    ops: &Ops<'_>,
    cg: &mut WarmCg,
    f: &mut Fields,
    geometry: &Geometry,
    h: f64,
) -> Result<usize, Error> {
    let region = ops.region;
    let vertices = &region.vertices;
    let nv = vertices.len();
    let area = &geometry.vertex_area;
    let full = ops
        .conductivity
        .stiffness(ops.topology, geometry, ops.pattern, h);
    let values = region.scalar_values(ops.pattern, &full, area, false);
    let mut color = f.color_free.as_ref().map(|c| split_rgb(c));
    let mut fields: Vec<&mut Vec<f64>> = vec![&mut f.free_solvent, &mut f.solute];
    if let Some(c) = color.as_mut() {
        fields.extend(c.iter_mut());
    }
    let rhs: Vec<f64> = fields
        .iter()
        .flat_map(|m| vertices.iter().map(|&v| m[v as usize]))
        .collect();
    // warm start: the densities the masses have now (after advection) on the new areas —
    // the solution for h → 0, closer than the last step's solution because the liquid has
    // moved since
    let mut sigma: Vec<f64> = rhs
        .iter()
        .enumerate()
        .map(|(k, m)| {
            let a = area[vertices[k % nv] as usize];
            if a > 0.0 { m / a } else { 0.0 }
        })
        .collect();
    cg.solve(&values, &rhs, &mut sigma)?;
    for (k, m) in fields.iter_mut().enumerate() {
        let before: f64 = vertices.iter().map(|&v| m[v as usize]).sum();
        let sigma = &sigma[k * nv..(k + 1) * nv];
        for (j, &v) in vertices.iter().enumerate() {
            m[v as usize] = area[v as usize] * sigma[j];
        }
        repair_negative(ops.adjacency, m, vertices, &region.mask);
        let after: f64 = vertices.iter().map(|&v| m[v as usize]).sum();
        if after > 0.0 && before > 0.0 {
            let scale = before / after;
            vertices.iter().for_each(|&v| m[v as usize] *= scale);
        }
    }
    if let (Some(c), Some(cf)) = (color, f.color_free.as_mut()) {
        merge_rgb(&c, cf);
    }
    Ok(cg.last_iterations)
}

/// Eq. 4.6 on the active vertices with clamped (non-negative) edge weights,
/// `(M ⊗ I + h ν K_∇) u' = (M ⊗ I) u` with `scale = h ν`: the block rows and columns of
/// the active vertices, diagonal blocks `K_ii = Σ_{j active} L_ij`; the velocities
/// outside are not touched. Returns the CG iterations.
fn diffuse_velocity(
    ops: &Ops<'_>,
    cg: &mut WarmCg,
    velocity: &mut [DVec2],
    geometry: &Geometry,
    connection: &Connection,
    scale: f64,
) -> Result<usize, Error> {
    let region = ops.region;
    let stiffness = cotan_stiffness(ops.topology, geometry, ops.pattern, scale);
    let area = &geometry.vertex_area;
    let scalar = region.scalar_values(ops.pattern, &stiffness, area, true);
    let values = region.bochner_values(&scalar, connection);
    let nv = region.vertices.len();
    let mut rhs = Vec::with_capacity(2 * nv);
    let mut x = Vec::with_capacity(2 * nv);
    for &v in &region.vertices {
        let (a, u) = (area[v as usize], velocity[v as usize]);
        rhs.extend([a * u.x, a * u.y]);
        x.extend([u.x, u.y]);
    }
    cg.solve(&values, &rhs, &mut x)?;
    for (j, &v) in region.vertices.iter().enumerate() {
        velocity[v as usize] = DVec2::new(x[2 * j], x[2 * j + 1]);
    }
    Ok(cg.last_iterations)
}

/// Fills negative masses among `vertices` (increasing) from their positive neighbours
/// where `mask` (in proportion to their masses), then from all positive `vertices` if the
/// neighbours cannot cover the deficit; conservative, sequential (deterministic), and a
/// no-op when nothing is negative. The masses outside `mask` are not touched.
fn repair_negative(adjacency: &RingAdjacency, mass: &mut [f64], vertices: &[u32], mask: &[bool]) {
    if !vertices.iter().any(|&v| mass[v as usize] < 0.0) {
        return;
    }
    let inside = |j: usize| mask[j];

    let mut leftover = 0.0;
    for &i in vertices {
        let i = i as usize;
        if mass[i] >= 0.0 {
            continue;
        }
        let deficit = -mass[i];
        mass[i] = 0.0;
        let ring = adjacency.neighbours(i);
        let pool: f64 = ring
            .iter()
            .filter(|&&j| inside(j as usize))
            .map(|&j| mass[j as usize].max(0.0))
            .sum();
        let take = deficit.min(pool);
        if take > 0.0 {
            let frac = take / pool;
            for &j in ring.iter().filter(|&&j| inside(j as usize)) {
                let m = &mut mass[j as usize];
                if *m > 0.0 {
                    *m -= *m * frac;
                }
            }
        }
        leftover += deficit - take;
    }
    if leftover > 0.0 {
        let pool: f64 = vertices
            .iter()
            .map(|&v| mass[v as usize])
            .filter(|m| *m > 0.0)
            .sum();
        if pool > 0.0 {
            let keep = (1.0 - leftover / pool).max(0.0);
            vertices.iter().for_each(|&v| mass[v as usize] *= keep);
        }
    }
}

fn split_rgb(c: &[[f64; 3]]) -> [Vec<f64>; 3] {
    std::array::from_fn(|k| c.iter().map(|x| x[k]).collect())
}

fn merge_rgb(c: &[Vec<f64>; 3], out: &mut [[f64; 3]]) {
    for (i, o) in out.iter_mut().enumerate() {
        *o = [c[0][i], c[1][i], c[2][i]];
    }
}
