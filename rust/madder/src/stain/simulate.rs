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
//! 1. **Forces** (§4.4): `u += h·a` with `a` the tangential gravity and rectilinear force
//!    in `F_i`, then the Coriolis rotation (exact, [`super::forces::apply_coriolis`]) with
//!    the frames' angular velocity over the sub-step, then friction `u ← e^{−k h} u` — the
//!    drag of the fibres on the liquid (`k = 0` is the seed's frictionless liquid; the
//!    exponential is the exact solution of `u̇ = −k u`, stable for any `h`).
//! 2. **Advection** (§4.3.1): the velocity semi-Lagrangian, then the densities by
//!    upwind finite volumes ([`super::advect`]); or, with `momentum_advection`, the
//!    velocity follows the solvent's momentum (§4.3.2). The densities move with the
//!    time-centred velocity `½(u^n + u^{n+1})` (start and end of the sub-step): with the
//!    end velocity alone (the plain split step) a liquid accelerating from rest travels
//!    `(n+1)/n` times `½at²` after `n` steps — 12 % too far after 8 frames — and with the
//!    average it travels exactly `½at²`.
//! 3. **Diffusion** (§4.3.3–4.3.4): `(M + h K_S) σ' = m` for the free solvent and the
//!    dissolved solute (and their colour), `K_S` the stiffness of the fabric tensor in
//!    each face's weft basis; the velocity by the connection (Bochner) Laplacian of the
//!    viscosity, eq. 4.6. Both by warm-started CG ([`crate::ops::WarmCg`]).
//! 4. **Interactions** (§4.5): absorption, adsorption, evaporation ([`super::interact`]).
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
//! ## Active region
//! A stain usually covers a small part of the cloth, so with `active_region` (the default)
//! the expensive phases work on the *active region* only, recomputed every sub-step from
//! the masses at its start: the vertices holding flowing liquid — free solvent or
//! dissolved solute density above [`ACTIVE_THRESHOLD`] (1e-12) of that field's largest
//! density — grown by [`ACTIVE_RINGS`] (3) rings plus the previous sub-step's number of
//! transport sub-cycles. (A threshold of exactly zero would not
//! do: implicit diffusion gives every vertex of the region a positive, if 1e-30-level,
//! mass, so the region would grow by three rings every sub-step until it covered the
//! cloth.) Geometry, frames, connection and forces stay global.
//!
//! - **Diffusion.** `(M + h K_A) σ' = m` on the active vertices, `K_A` keeping the
//!   stiffness of the edges with both ends active, each diagonal recomputed as minus the
//!   sum of its row's kept off-diagonals: a Neumann (no-flux) boundary at the region's
//!   edge. So `1ᵀK_A = 0`, the restricted solve conserves mass exactly like the whole
//!   one, and the total is restored over the region after the solve; the negative-mass
//!   repair draws only from active vertices. The velocity's Bochner system is restricted
//!   the same way (block rows and columns of the active vertices, `K_ii = Σ_{j active}
//!   L_ij` with the clamped weights). The patterns and solvers are rebuilt only when the
//!   region changes.
//! - **Advection.** The semi-Lagrangian back-trace runs for active vertices only; and the
//!   upwind transport is closed inside the region (no transfer across an edge with an end
//!   outside, [`UpwindPlan::restrict_to`]; its sub-cycle count is the whole mesh's).
//! - **Outside** the region the flowing masses are left unchanged (the interactions still
//!   act everywhere) and the velocities keep their value after the forces.
//!
//! What it truncates: the far tail of implicit diffusion, which on the whole mesh spreads
//! mass beyond the three rings at levels ~1e-12 of the peak and below, and the viscous
//! coupling of the liquid's velocity to the velocity of the dry cloth more than three
//! rings away. With no evaporation the two steps agree to rounding (tests: 6e-15 of the
//! peak after 200 steps). Evaporation drains every vertex holding less than one step's
//! evaporation to zero, so the wet edge is sharp and the whole-mesh step leaks about
//! 1e-10 of the peak per step past three rings, where it evaporates at once; the region
//! keeps that liquid (measured: up to 1e-5 of the peak after 200 steps; 1e-8 with five
//! rings). The transport is closed inside the region, and each transport sub-cycle moves
//! liquid at most one ring, so the margin is three rings plus the number of sub-cycles
//! the previous sub-step needed: a fast flow widens its region instead of queueing at
//! its edge (only a sudden jump in speed within one sub-step can make liquid wait one
//! sub-step there).
//!
//! ## Failure
//! [`Simulator::step`] works on a copy of the state and commits it only when the whole
//! frame succeeded: an error (bad positions naming the vertex, a solver failure) leaves
//! the simulator at the last good frame.

use std::time::Instant;

use faer::Par;
use glam::{DVec2, DVec3};
use rayon::prelude::*;

use super::advect::{UpwindPlan, advect_velocity, advect_velocity_in, dual_fluxes};
use super::diffuse::{Conductivity, check_range};
use super::forces::{
    Forces, coriolis_turn, corotating_frames_with, frame_acceleration, frame_angular_velocity,
    frame_body_acceleration, rest_frames,
};
use super::interact::{Fields, InteractionRates, exposure, interact};
use crate::error::{Error, ParamError};
use crate::mesh::geometry::check_positions;
use crate::mesh::{Connection, Geometry, OneRings, RingAdjacency, Topology, VertexFrames};
use crate::ops::{
    BochnerPattern, LowerCsc, VertexPattern, WarmCg, add_lumped_mass, add_lumped_mass_blocks,
    bochner_stiffness, cotan_stiffness,
};

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
    /// Sub-steps per frame.
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
            momentum_advection: false,
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
    frames: VertexFrames,
    vertex_area: Vec<f64>,
    velocity: Vec<DVec2>,
    fields: Fields,
    evaporated: f64,
    time: f64,
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
    topology: Topology,
    rings: OneRings,
    /// Vertex neighbours in edge order (the Kabsch sums, the negative-mass repair).
    adjacency: RingAdjacency,
    rest: Vec<DVec3>,
    rest_frames: VertexFrames,
    conductivity: Conductivity,
    params: StainParams,
    pattern: VertexPattern,
    bochner: BochnerPattern,
    scalar_cg: WarmCg,
    vector_cg: WarmCg,
    boundary: Vec<bool>,
    loose: Vec<bool>,
    solute_color: [f64; 3],
    state: State,
    profile: Profile,
    /// Scalar pattern slot → mesh edge (`u32::MAX` on the diagonal).
    slot_edge: Vec<u32>,
    /// The active region of the last sub-step and its solvers (kept while it is unchanged).
    region: Option<Region>,
    /// The density and velocity solvers of `region`.
    region_cg: Option<(WarmCg, WarmCg)>,
    /// Transport sub-cycles of the last sub-step (widens the next region).
    last_transport_cycles: usize,
}

/// The active region of a sub-step (module doc): the vertices, the restricted patterns of
/// the two diffusions and their solvers.
#[derive(Debug)]
struct Region {
    /// Active vertices, increasing.
    vertices: Vec<u32>,
    /// Per mesh vertex: active or not.
    mask: Vec<bool>,
    /// Lower triangle of the restricted scalar operator, local numbering.
    scalar: SubCsc,
    /// Per entry of `scalar`: its mesh edge (`u32::MAX` on the diagonal).
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

/// The active mask (module doc): the vertices whose free solvent or dissolved solute is
/// above [`ACTIVE_THRESHOLD`] of its field's peak density, grown by `rings` rings
/// ([`ACTIVE_RINGS`] plus the last sub-step's transport sub-cycles). Loose vertices are
/// never active.
fn active_mask(
    adjacency: &RingAdjacency,
    loose: &[bool],
    fields: &Fields,
    area: &[f64],
    rings: usize,
) -> Vec<bool> {
    let n = area.len();
    let peak = |m: &[f64]| {
        m.iter()
            .zip(area)
            .filter(|(_, a)| **a > 0.0)
            .map(|(m, a)| m / a)
            .fold(0.0, f64::max)
    };
    let (free, solute) = (&fields.free_solvent, &fields.solute);
    let floor = (
        ACTIVE_THRESHOLD * peak(free),
        ACTIVE_THRESHOLD * peak(solute),
    );
    let mut mask = vec![false; n];
    let mut front = Vec::new();
    for i in 0..n {
        let wet = |m: f64, floor: f64| m > 0.0 && m > floor * area[i];
        if !loose[i] && (wet(free[i], floor.0) || wet(solute[i], floor.1)) {
            mask[i] = true;
            front.push(i as u32);
        }
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
        front = next;
    }
    mask
}

/// Wall-clock seconds spent in each phase since the simulator was built (for benchmarks).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Profile {
    /// Geometry, comoving–corotating frames (Kabsch) and the connection.
    pub geometry: f64,
    /// Body forces.
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
    /// Active-region vertices, summed over the sub-steps (the whole mesh's count per
    /// sub-step without an active region).
    pub active_vertices: usize,
    /// Times the active region changed and its patterns and solvers were rebuilt.
    pub region_rebuilds: usize,
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
        let pattern = VertexPattern::new(&topology);
        let bochner = BochnerPattern::new(&pattern);
        let scalar_cg = WarmCg::new(&pattern).with_tolerance(DENSITY_TOLERANCE);
        let mut slot_edge = vec![u32::MAX; pattern.nnz()];
        for (e, &s) in pattern.edge_slot().iter().enumerate() {
            slot_edge[s as usize] = e as u32;
        }
        let vector_cg = WarmCg::new(&bochner).with_tolerance(VELOCITY_TOLERANCE);
        Ok(Self {
            boundary: topology.boundary_vertices(),
            loose: topology.loose_vertices(),
            rest: rest.to_vec(),
            rest_frames,
            conductivity,
            params,
            pattern,
            bochner,
            scalar_cg,
            vector_cg,
            solute_color,
            state: State {
                positions: positions.to_vec(),
                previous: None,
                frames,
                vertex_area: geometry.vertex_area,
                velocity: vec![DVec2::ZERO; n],
                fields: Fields::zeros(n),
                evaporated: 0.0,
                time: 0.0,
            },
            rings,
            adjacency,
            topology,
            profile: Profile::default(),
            slot_edge,
            region: None,
            region_cg: None,
            last_transport_cycles: 1,
        })
    }

    pub fn topology(&self) -> &Topology {
        &self.topology
    }
    /// The active region of the last sub-step (one flag per vertex), or `None` when the
    /// whole mesh is stepped (`active_region` off, or before the first step).
    pub fn active_region(&self) -> Option<&[bool]> {
        self.region.as_ref().map(|r| r.mask.as_slice())
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
    /// Lumped vertex areas of the current frame, m².
    pub fn vertex_area(&self) -> &[f64] {
        &self.state.vertex_area
    }
    /// Per-vertex masses, kg.
    pub fn fields(&self) -> &Fields {
        &self.state.fields
    }
    /// Velocities in the vertex frames, m/s.
    pub fn velocity(&self) -> &[DVec2] {
        &self.state.velocity
    }
    /// The vertex frames of the current frame (columns `x, y, z`).
    pub fn frames(&self) -> &VertexFrames {
        &self.state.frames
    }
    /// Velocities as world vectors, m/s.
    pub fn velocity_world(&self) -> Vec<DVec3> {
        (0..self.state.velocity.len())
            .map(|i| self.state.frames.to_world(i, self.state.velocity[i]))
            .collect()
    }
    /// Replaces the velocity field (frame components), e.g. an initial condition.
    pub fn set_velocity(&mut self, velocity: Vec<DVec2>) -> Result<(), ParamError> {
        self.check_len("velocity", velocity.len())?;
        if let Some(index) = velocity.iter().position(|u| !u.is_finite()) {
            return Err(ParamError::NonFinite {
                name: "velocity",
                index,
            });
        }
        self.state.velocity = velocity;
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
        let expected = self.topology.n_vertices();
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
        if let Some(index) = solvent.iter().position(|d| !(d.is_finite() && *d >= 0.0)) {
            return Err(ParamError::OutOfRangeAt {
                name: "added solvent",
                index,
                requirement: "finite and ≥ 0",
                value: solvent[index],
            });
        }
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
        if let Some(index) = weight.iter().position(|w| !(w.is_finite() && *w >= 0.0)) {
            return Err(ParamError::OutOfRangeAt {
                name: "splash weight",
                index,
                requirement: "finite and ≥ 0",
                value: weight[index],
            });
        }
        let st = &mut self.state;
        let (frames, positions) = (&st.frames, &st.positions);
        st.velocity.par_iter_mut().enumerate().for_each(|(i, u)| {
            if weight[i] <= 0.0 {
                return;
            }
            let mut rng = SplitMix64(seed ^ (i as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15));
            let (r1, r2, r3) = (rng.unit(), rng.unit(), rng.unit());
            let out = frames.to_local(i, positions[i] - center);
            let dir = if out.length() > 0.0 {
                out.normalize()
            } else {
                DVec2::from_angle(std::f64::consts::TAU * r3)
            };
            let turned = DVec2::from_angle(r1 - 0.5).rotate(dir);
            *u += turned * (speed * weight[i] * (0.5 + r2));
        });
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
        check_positions(&self.topology, positions)?;
        if let Some(a) = after {
            check_positions(&self.topology, a)?;
        }
        let mut state = self.state.clone();
        let cur = state.positions.clone();
        let acceleration = if self.params.forces.rectilinear {
            // p̈ at the start of the interval: centred; at the very first frame, the
            // forward difference if the frame after is known, else zero (the cloth is
            // taken to have moved uniformly before the bake)
            let start = match (&state.previous, after) {
                (Some(prev), _) => frame_acceleration(prev, &cur, positions, dt),
                (None, Some(a)) => frame_acceleration(&cur, positions, a, dt),
                (None, None) => vec![DVec3::ZERO; cur.len()],
            };
            match after {
                Some(a) => frame_acceleration(&cur, positions, a, dt)
                    .iter()
                    .zip(&start)
                    .map(|(e, s)| 0.5 * (*e + *s))
                    .collect(),
                None => start,
            }
        } else {
            vec![DVec3::ZERO; cur.len()]
        };
        let s_count = self.params.substeps;
        let h = dt / s_count as f64;
        for s in 1..=s_count {
            let q: Vec<DVec3> = if s == s_count {
                positions.to_vec()
            } else {
                let t = s as f64 / s_count as f64;
                cur.iter()
                    .zip(positions)
                    .map(|(a, b)| a.lerp(*b, t))
                    .collect()
            };
            self.substep(&mut state, &q, h, &acceleration)?;
        }
        state.previous = Some(cur);
        state.positions = positions.to_vec();
        self.state = state;
        Ok(())
    }

    fn substep(
        &mut self,
        st: &mut State,
        q: &[DVec3],
        h: f64,
        acceleration: &[DVec3],
    ) -> Result<(), Error> {
        let mut clock = Instant::now();
        let mut lap = |slot: &mut f64| {
            let now = Instant::now();
            *slot += (now - clock).as_secs_f64();
            clock = now;
        };
        let mut prof = self.profile;
        let p = self.params.clone();
        let topo = &self.topology;
        let geometry = Geometry::new(topo, q)?;
        let frames = corotating_frames_with(&self.adjacency, &self.rest_frames, &self.rest, q);
        let connection = Connection::new(topo, &self.rings, &geometry, &frames, q);
        // the active region, from the masses at the start of the sub-step (module doc)
        if p.active_region {
            let rings = ACTIVE_RINGS + self.last_transport_cycles;
            let mask = active_mask(
                &self.adjacency,
                &self.loose,
                &st.fields,
                &st.vertex_area,
                rings,
            );
            if self.region.as_ref().is_none_or(|r| r.mask != mask) {
                let region = Region::new(&self.pattern, &self.slot_edge, mask);
                self.region_cg = region.solvers();
                self.region = Some(region);
                prof.region_rebuilds += 1;
            }
        } else {
            self.region = None;
            self.region_cg = None;
        }
        let region = self.region.as_ref();
        prof.active_vertices += region
            .as_ref()
            .map_or(topo.n_vertices(), |r| r.vertices.len());
        lap(&mut prof.geometry);

        // the velocity at the start of the sub-step, for the time-centred flux below
        let start_velocity = st.velocity.clone();
        // 1. body forces (§4.4): half kick, Coriolis rotation, half kick, then friction;
        // loose vertices are held at rest. One pass, vertex by vertex.
        let kicks = p.forces.gravity || p.forces.rectilinear;
        let damp = (p.friction > 0.0).then(|| (-p.friction * h).exp());
        let (old_frames, loose) = (&st.frames.frame, &self.loose);
        st.velocity
            .par_iter_mut()
            .zip(&frames.frame)
            .enumerate()
            .for_each(|(i, (u, f))| {
                let kick = kicks.then(|| {
                    (0.5 * h) * frame_body_acceleration(f, acceleration[i], p.gravity, p.forces)
                });
                if let Some(k) = kick {
                    *u += k;
                }
                if p.forces.coriolis {
                    *u = coriolis_turn(frame_angular_velocity(&old_frames[i], f, h), h, *u);
                }
                if let Some(k) = kick {
                    *u += k;
                }
                if let Some(damp) = damp {
                    *u *= damp;
                }
                if loose[i] {
                    *u = DVec2::ZERO;
                }
            });

        lap(&mut prof.forces);
        // 2. advection (§4.3.1–4.3.2)
        let advected = match &region {
            Some(r) => advect_velocity_in(
                topo,
                &self.rings,
                &geometry,
                &connection,
                &st.velocity,
                h,
                &r.mask,
            ),
            None => advect_velocity(topo, &self.rings, &geometry, &connection, &st.velocity, h),
        };
        let centred: Vec<DVec2> = advected
            .par_iter()
            .zip(&start_velocity)
            .map(|(a, b)| 0.5 * (*a + *b))
            .collect();
        let flux = dual_fluxes(topo, q, &frames, &centred);
        let mut plan = UpwindPlan::new(topo, &geometry.vertex_area, &flux, h)?;
        if let Some(r) = &region {
            plan.restrict_to(topo, &r.mask);
        }
        prof.transport_cycles += plan.substeps();
        self.last_transport_cycles = plan.substeps();
        // the momentum advection needs the solvent before its transport
        let solvent_before = p.momentum_advection.then(|| st.fields.free_solvent.clone());
        {
            let f = &mut st.fields;
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
        st.velocity = match solvent_before {
            Some(before) => {
                plan.momentum_velocity(topo, &connection, &before, &st.velocity, &advected)
            }
            None => advected,
        };

        lap(&mut prof.advection);
        // 3. diffusion (§4.3.3–4.3.4, eq. 4.6): the densities and the velocity are
        // independent systems, solved side by side
        let ops = Ops {
            topology: &self.topology,
            adjacency: &self.adjacency,
            pattern: &self.pattern,
            bochner: &self.bochner,
            loose: &self.loose,
            conductivity: &self.conductivity,
        };
        let (fields, velocity) = (&mut st.fields, &mut st.velocity);
        let (densities, viscous) = match region {
            None => {
                let (scalar_cg, vector_cg) = (&mut self.scalar_cg, &mut self.vector_cg);
                rayon::join(
                    || diffuse_densities(&ops, scalar_cg, fields, &geometry, h),
                    || {
                        if p.viscosity > 0.0 {
                            diffuse_velocity(
                                &ops,
                                vector_cg,
                                velocity,
                                &geometry,
                                &connection,
                                h * p.viscosity,
                            )
                        } else {
                            Ok(0)
                        }
                    },
                )
            }
            Some(r) => match self.region_cg.as_mut() {
                None => (Ok(0), Ok(0)),
                Some((scalar_cg, vector_cg)) => rayon::join(
                    || diffuse_densities_in(&ops, r, scalar_cg, fields, &geometry, h),
                    || {
                        if p.viscosity > 0.0 {
                            diffuse_velocity_in(
                                &ops,
                                r,
                                vector_cg,
                                velocity,
                                &geometry,
                                &connection,
                                h * p.viscosity,
                            )
                        } else {
                            Ok(0)
                        }
                    },
                ),
            },
        };
        prof.density_iterations += densities?;
        prof.velocity_iterations += viscous?;
        lap(&mut prof.diffusion);

        // 4. interactions (§4.5)
        let topo = &self.topology;
        let wet: Vec<f64> = (0..st.vertex_area.len())
            .map(|i| {
                let a = geometry.vertex_area[i];
                let m = st.fields.free_solvent[i] + st.fields.absorbed_solvent[i];
                if a > 0.0 { m / a } else { 0.0 }
            })
            .collect();
        let exposed = exposure(
            topo,
            &self.boundary,
            &wet,
            DRY_DENSITY,
            p.interaction.evaporation_boundary,
        );
        st.evaporated += interact(
            &p.interaction,
            &geometry.vertex_area,
            &exposed,
            h,
            &mut st.fields,
        )?;

        st.frames = frames;
        st.vertex_area = geometry.vertex_area;
        st.time += h;
        lap(&mut prof.interaction);
        prof.substeps += 1;
        self.profile = prof;
        Ok(())
    }
}

/// The fixed operators the diffusion steps read.
struct Ops<'a> {
    topology: &'a Topology,
    adjacency: &'a RingAdjacency,
    pattern: &'a VertexPattern,
    bochner: &'a BochnerPattern,
    loose: &'a [bool],
    conductivity: &'a Conductivity,
}

/// `(M + h K_S) σ' = m` for every flowing field, then the exact mass restoration and the
/// non-negativity repair of the module doc. Returns the CG iterations.
fn diffuse_densities(
    ops: &Ops<'_>,
    cg: &mut WarmCg,
    f: &mut Fields,
    geometry: &Geometry,
    h: f64,
) -> Result<usize, Error> {
    let n = ops.topology.n_vertices();
    let mut values = ops
        .conductivity
        .stiffness(ops.topology, geometry, ops.pattern, h);
    add_lumped_mass(geometry, ops.pattern, 1.0, &mut values);
    for (v, _) in ops.loose.iter().enumerate().filter(|(_, l)| **l) {
        values[ops.pattern.diag_slot()[v] as usize] = 1.0;
    }
    let mut color = f.color_free.as_ref().map(|c| split_rgb(c));
    let mut fields: Vec<&mut Vec<f64>> = vec![&mut f.free_solvent, &mut f.solute];
    if let Some(c) = color.as_mut() {
        fields.extend(c.iter_mut());
    }
    let rhs: Vec<f64> = fields.iter().flat_map(|m| m.iter().copied()).collect();
    // warm start: the densities the masses have now (after advection) on the new areas —
    // the solution for h → 0, closer than the last step's solution because the liquid has
    // moved since
    let mut sigma: Vec<f64> = rhs
        .iter()
        .enumerate()
        .map(|(k, m)| {
            let a = geometry.vertex_area[k % n];
            if a > 0.0 { m / a } else { 0.0 }
        })
        .collect();
    cg.solve(&values, &rhs, &mut sigma)?;
    for (k, m) in fields.iter_mut().enumerate() {
        let before: f64 = m.iter().sum();
        let sigma = &sigma[k * n..(k + 1) * n];
        for i in 0..n {
            if !ops.loose[i] {
                m[i] = geometry.vertex_area[i] * sigma[i];
            }
        }
        repair_negative(ops.adjacency, m);
        let after: f64 = m.iter().sum();
        if after > 0.0 && before > 0.0 {
            let scale = before / after;
            m.iter_mut().for_each(|x| *x *= scale);
        }
    }
    if let (Some(c), Some(cf)) = (color, f.color_free.as_mut()) {
        merge_rgb(&c, cf);
    }
    Ok(cg.last_iterations)
}

/// [`diffuse_densities`] on the active region (module doc): `(M + h K_A) σ' = m` on the
/// active vertices, Neumann at the region's edge; the masses outside are not touched.
fn diffuse_densities_in(
    ops: &Ops<'_>,
    region: &Region,
    cg: &mut WarmCg,
    f: &mut Fields,
    geometry: &Geometry,
    h: f64,
) -> Result<usize, Error> {
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
        repair_negative_in(ops.adjacency, m, vertices, &region.mask);
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

/// [`diffuse_velocity`] on the active region: the block rows and columns of the active
/// vertices, diagonal blocks `K_ii = Σ_{j active} L_ij` (clamped weights); the velocities
/// outside are not touched.
fn diffuse_velocity_in(
    ops: &Ops<'_>,
    region: &Region,
    cg: &mut WarmCg,
    velocity: &mut [DVec2],
    geometry: &Geometry,
    connection: &Connection,
    scale: f64,
) -> Result<usize, Error> {
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

/// Eq. 4.6 with clamped (non-negative) edge weights: `(M ⊗ I + h ν K_∇) u' = (M ⊗ I) u`,
/// `scale = h ν`. Returns the CG iterations.
fn diffuse_velocity(
    ops: &Ops<'_>,
    cg: &mut WarmCg,
    velocity: &mut [DVec2],
    geometry: &Geometry,
    connection: &Connection,
    scale: f64,
) -> Result<usize, Error> {
    let mut stiffness = cotan_stiffness(ops.topology, geometry, ops.pattern, scale);
    clamp_weights(ops.pattern, &mut stiffness);
    let mut values = bochner_stiffness(ops.pattern, ops.bochner, &stiffness, connection);
    add_lumped_mass_blocks(geometry, ops.bochner, 1.0, &mut values);
    let n = ops.topology.n_vertices();
    let mut rhs = Vec::with_capacity(2 * n);
    let mut x = Vec::with_capacity(2 * n);
    for (i, u) in velocity.iter().enumerate() {
        let a = geometry.vertex_area[i];
        rhs.extend([a * u.x, a * u.y]);
        x.extend([u.x, u.y]);
    }
    for (v, _) in ops.loose.iter().enumerate().filter(|(_, l)| **l) {
        let d = ops.bochner.diag_slot()[v];
        values[d[0] as usize] = 1.0;
        values[d[1] as usize] = 1.0;
        rhs[2 * v] = velocity[v].x;
        rhs[2 * v + 1] = velocity[v].y;
    }
    // interleaved (x, y) per vertex is one column of the 2N system
    cg.solve(&values, &rhs, &mut x)?;
    for (i, u) in velocity.iter_mut().enumerate() {
        *u = DVec2::new(x[2 * i], x[2 * i + 1]);
    }
    Ok(cg.last_iterations)
}

/// Makes a scalar stiffness an M-matrix: positive off-diagonal entries (negative edge
/// weights) are dropped and each diagonal recomputed so rows still sum to zero.
fn clamp_weights(pattern: &VertexPattern, values: &mut [f64]) {
    let n = pattern.n();
    let mut diag = vec![0.0; n];
    let (cp, ri) = (pattern.col_ptr(), pattern.row_idx());
    for j in 0..n {
        for s in cp[j]..cp[j + 1] {
            let i = ri[s as usize] as usize;
            if i == j {
                continue;
            }
            let v = &mut values[s as usize];
            if *v > 0.0 {
                *v = 0.0;
            }
            diag[i] -= *v;
            diag[j] -= *v;
        }
    }
    for (j, d) in diag.into_iter().enumerate() {
        values[pattern.diag_slot()[j] as usize] = d;
    }
}

/// Fills negative masses from positive neighbours (in proportion to their masses), then
/// from all positive vertices if the neighbours cannot cover the deficit; conservative,
/// sequential (deterministic), and a no-op when nothing is negative.
fn repair_negative(adjacency: &RingAdjacency, mass: &mut [f64]) {
    if !mass.iter().any(|&m| m < 0.0) {
        return;
    }
    let all: Vec<u32> = (0..mass.len() as u32).collect();
    repair_vertices(adjacency, mass, &all, |_| true);
}

/// [`repair_negative`] inside the active region: deficits are filled from active
/// neighbours and active vertices only, so the masses outside are not touched.
fn repair_negative_in(
    adjacency: &RingAdjacency,
    mass: &mut [f64],
    vertices: &[u32],
    mask: &[bool],
) {
    if !vertices.iter().any(|&v| mass[v as usize] < 0.0) {
        return;
    }
    repair_vertices(adjacency, mass, vertices, |j| mask[j]);
}

/// The repair over `vertices` (increasing), drawing only from vertices where `inside`.
fn repair_vertices(
    adjacency: &RingAdjacency,
    mass: &mut [f64],
    vertices: &[u32],
    inside: impl Fn(usize) -> bool,
) {
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

/// splitmix64 (Steele, Lea & Flood 2014): a tiny, well-mixed generator, enough for
/// reproducible jitter; one per vertex, seeded from the splash seed and the index.
struct SplitMix64(u64);

impl SplitMix64 {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// Uniform in [0, 1).
    fn unit(&mut self) -> f64 {
        (self.next() >> 11) as f64 / (1u64 << 53) as f64
    }
}
