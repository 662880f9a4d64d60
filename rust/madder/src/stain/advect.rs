//! Advection of the velocity and of the densities (seed §4.3.1–4.3.2).
//!
//! The velocity is one 2-D vector `u_i` per vertex in the vertex frame `F_i`
//! ([`crate::mesh::frames`]); the densities (solvent, solute, colour) are carried as
//! masses per vertex, `m_i = A_i σ_i`, with `A_i` the lumped area (one third of the
//! one-ring's area) that the diffusion ([`super::diffuse`]) uses as its mass matrix.
//!
//! ## Velocity: semi-Lagrangian back-trace with strip following (§4.3.1)
//! For each vertex `i` the foot of the characteristic is the point `p = −h u_i`, written in
//! the `(x, y)` coordinates of `F_i`. The one-ring is flattened by the geodesic polar map
//! of [`Transport`]: spoke `j` is laid at
//!
//! ```text
//! P_j = |e_ij| (cos(α_ij + δ_i), sin(α_ij + δ_i)),
//! ```
//!
//! (true spoke length, rescaled polar angle `α_ij`, frame offset `δ_i`), `i` at the origin.
//! The wedge `(i, j, k)` (spokes `j`, `k` in counter-clockwise order) that contains the
//! direction of `p` is the one with `P_j` strictly to the right of the ray `0 → p` and `P_k`
//! on or to its left (`p × P_j < 0 ≤ p × P_k`) and a convex layout (`P_j × P_k > 0`). If
//! `p` lies in the layout triangle `(0, P_j, P_k)` with barycentric coordinates
//! `(λ_i, λ_j, λ_k)`, the new velocity is the seed's
//!
//! ```text
//! u_i' = λ_i u_i + λ_j R_ij u_j + λ_k R_ik u_k,
//! ```
//!
//! with `R_ij` of eq. 4.4. Otherwise the segment leaves through the far edge `(j, k)` and we
//! *follow the strip* ("it is possible to extend the method … by following the strip of
//! the triangles traversed"): the triangle on the other side of the crossed edge `(r, l)`
//! is unfolded into the same plane from its intrinsic edge lengths, and the straight
//! segment continues, as many triangles as needed. The unfolding is an isometry anchored
//! at the crossing point `X = P_r + f (P_l − P_r)`: with `L = |e_rl|`, `t` the unit layout
//! direction of `r → l` and `n` its normal towards the far side,
//!
//! ```text
//! r* = X − f L t,   P_c = r* + x t + y n,   x = (L_rc² − L_lc² + L²) / 2L,   y = 2 A_rlc / L,
//! ```
//!
//! so the crossing keeps its fraction `f` along the edge. Where the polar map is exact
//! (flat and developable cloth: angle sum `2π`, or border vertices, which are not
//! rescaled) `r* = P_r` up to rounding and the strip is the exact development of the
//! surface. Around a curved vertex the rescaled first triangle cannot be congruent to the
//! true one (`|P_j − P_k| ≠ |e_jk|`); anchoring at `X` keeps the travelled distance exact
//! and confines the distortion to triangles that touch `j` or `k`.
//!
//! A vertex `c` placed by the unfolding carries its velocity into `F_i` with the rotation
//! that maps its polar directions onto the layout: the layout angle of the edge `c → m`
//! minus its polar angle `α_cm + δ_c`, for `m = r` and `m = l`, averaged (the two differ by
//! `(s_c − 1) φ_c`, the holonomy share of the corner at a curved `c`; they agree on
//! developable cloth). The average is taken on unit complex numbers: `e^{i a}` of each
//! edge is its layout direction normalized times `e^{−i(α + δ_c)}`, and the mean angle
//! (on the shorter arc, as the wrapped difference gave it) is the direction of their sum:
//! two `sin_cos` and three square roots instead of two `atan2` and a `sin_cos` (issue 12:
//! at Detail 2 most back-traces end in an unfolded triangle, whose three vertices all
//! need it). The same rotation up to rounding (the Detail bench's stain moved by 2e-15
//! of its peak). For `j` and `k` of the first triangle this formula is eq. 4.4
//! itself (`α_ij + δ_i + π − (α_ji + δ_j) = θ_ij`), so `R_ij` is taken from the
//! [`Transport`] and the one-ring case is bit-identical to the seed's formula. A vertex
//! keeps the rotation it was given when first placed while the strip passes it. The
//! rotation (two `sin_cos` and three square roots) is only evaluated for the vertices
//! whose velocity is read, the last triangle's or a crossing's where the walk stops: the
//! others a long strip passes never need it, nor the look-up of their polar angles (the
//! same operations when read, so the same values).
//!
//! *First wedge.* Placing a spoke costs a `sin_cos`, and the wedge is searched in fan
//! order. A pre-test skips, without placing their spokes, the wedges whose polar sector
//! `[α_ij + δ_i, α_ik + δ_i]` (counter-clockwise, any turn) is more than 10⁻³ rad away
//! from the foot's direction, measured by a polynomial `atan2` good to 10⁻⁵: the exact
//! test above can only pass inside the sector (up to rounding and [`SIDE_TOLERANCE`],
//! below 10⁻¹¹), so the same wedge is found with the same placed spokes, and about two
//! `sin_cos` are done instead of one per wedge passed.
//!
//! The walk is the "straight walk" of point location: each new vertex is classified once
//! as left or right of the line `0 → p`, the exit edge is the one whose endpoints are on
//! opposite sides, and `p` is in the current triangle iff it is not beyond the exit edge
//! (`(P_l − P_r) × (p − P_r) ≥ 0`). A vertex within [`SIDE_TOLERANCE`] (relative, an angle)
//! of the line counts as *on* it, and points on the line are all put on the same side: a
//! consistent symbolic perturbation of the line, so a segment through a vertex (common on
//! regular grids) walks around it instead of getting stuck. Which side matters only for a
//! segment running exactly along a border edge: with "on the line = left" the perturbed
//! segment runs along the border with the cloth on its right; if no wedge of `i` then
//! contains the direction (the cloth is on the left), the walk is redone with "on the
//! line = right". A segment along a straight border (a wind parallel to the hem) thus
//! follows the border instead of stopping at `i` or crossing the border edge at an
//! arbitrary point.
//!
//! Each crossing is a chain of dependent reads, so it is kept short: the crossed edge is
//! the current face's edge opposite the vertex behind, the face beyond it is read from a
//! table of every edge's two faces (built once per call), and the side of a new vertex is
//! decided from `|target × p|` against `max(|p_x|, |p_y|)` (which bounds `|p|` within
//! `√2`), taking the square root only within a factor 1.5 of the threshold, where the
//! exact test decides. Same results bit for bit as the fan searches and the plain test.
//!
//! It stops, and interpolates linearly along the edge at the crossing point, when it
//! meets a **border** (an edge with one face: the fluid cannot come from outside the
//! cloth) or a **non-manifold** edge (no unique continuation), and after
//! [`MAX_CROSSINGS`] crossings (only reachable with `h|u|` hundreds of edge lengths).
//! A vertex whose direction lies in no wedge under either rule (a boundary vertex whose
//! back-trace leaves the cloth at once, a loose vertex) keeps `u_i`: the border point is the vertex itself. A zero
//! velocity returns `u_i` exactly.
//!
//! *Irregular vertices* (bow-ties, non-manifold spokes) use the fallback polar layout of
//! [`Transport`] (fans side by side, not rescaled) and the first wedge, in fan order,
//! that contains the direction; the strip then stops at the first non-manifold edge.
//! *Degenerate layouts*: a wedge whose layout is not convex (a collapsed face, or a
//! rescaled tip angle ≥ π at a very sharp cone vertex) is skipped; a triangle whose layout
//! has zero or non-finite determinant, or an edge of zero length, ends the walk at the
//! last crossing point (for the first triangle: the vertex, giving `u_i`). Barycentric
//! coordinates are clamped to `[0, 1]` and renormalized, which only removes rounding.
//! No NaN is produced from finite input.
//!
//! ## Densities: finite-volume upwind on the median dual (§4.3.1)
//! The seed's flux `F_ij = σ↑ (u_ij · e_ij) w_ij` uses the cotan weight `w_ij`, which is
//! negative across an edge whose opposite angles sum to more than π (obtuse cloth
//! triangles: the circumcentres, hence the Voronoi dual face, fall on the wrong side of
//! the edge). The flux then runs against the velocity, the vertex chosen as upwind gives
//! a negative amount, and the other one can go negative: the tests reproduce it (density
//! `−2·10⁹` after 200 steps of a rotating flow on a sheared grid). Choosing the donor by
//! the sign of `F_ij` instead would restore positivity but not consistency: the Voronoi
//! cells of such a mesh overlap, do not have the lumped areas `A_i` of the diffusion, and
//! move mass against the flow. We use the **median (barycentric) dual** instead.
//! In a triangle `T = (i, j, k)` the dual face between `i` and `j` is the segment from the
//! edge midpoint `m_ij` to the centroid `c_T`; its area vector (length × in-plane normal,
//! oriented from `i` towards `j`) is
//!
//! ```text
//! S_ij^T = (c_T − m_ij) × n̂_T,    n̂_T = e_ij × e_ik / |e_ij × e_ik|,
//! S_ij^T · e_ij = ⅓ n̂_T · (e_ij × e_ik) = ⅔ A_T > 0,
//! ```
//!
//! (because `c_T − m_ij = ⅓ (p_k − m_ij)` and `e_ij × (m_ij − p_i) = 0`): the dual face always
//! separates `i` from `j` the right way round, on any triangle. The median cells are the
//! three quadrilaterals `(p_i, m_ij, c_T, m_ik)` of area `A_T / 3` each, so the dual cell
//! of `i` has exactly the lumped area `A_i` of the diffusion's mass matrix. Around an
//! interior vertex, `S_ij^T + S_ik^T = ½ (p_k − p_j) × n̂_T`, which sums to zero around the
//! closed fan on a flat mesh: the cells are closed, a constant velocity has zero net
//! flux. The volume flux from `i` to `j` (m²/s) is
//!
//! ```text
//! Φ_ij = Σ_{T ∋ ij} u_ij · S_ij^T,      u_ij = ½ (F_i u_i + F_j u_j)   (3-D, the seed's u_ij),
//! ```
//!
//! computed once per edge, so `Φ_ji = −Φ_ij` exactly. A face with
//! `|e_ij × e_ik| ≤` [`FLAT_FACE_REL`]` · ℓ_max²` (its normal is rounding noise) gets
//! `S = 0`: no flux through it, which is still conservative.
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
//!
//! *Layout (issue 16, speed).* The plan is built in two passes over each vertex's edges,
//! in parallel over runs of vertices laid end to end: the first sums the vertex's outflow
//! and lists the `|Φ|` of the edges with a flux, given and received (the donor read off
//! the flux's sign); once the sub-step count is known from the largest Courant number,
//! the second turns them into fractions. The result is a CSR table per vertex (the
//! fractions it gives; the fraction, donor and edge of what it receives, edges without
//! flux left out), built once per step. Each sub-cycle is then one pass over that table
//! for all fields at once, interleaved per vertex, and with the momentum form (below) the
//! momentum in the same pass; the solvent's transported mass is the momentum's divisor,
//! so it is not transported twice. Each value is computed by the same operations in the
//! same order as the former one-field-at-a-time passes: the outputs are bit-identical.
//! The fluxes ([`dual_fluxes`]) inside the simulator's active region visit only the faces
//! with an active edge. The runs are sized from their vertices' edge counts and their
//! fractions written over the `|Φ|` they replace (no regrowth, one copy into the table);
//! a sub-cycle reads each transfer once for up to five fields (per-field sums kept in
//! transfer order), and with several sub-cycles the momentum's rotations `R_vd` are
//! gathered once per plan in transfer order instead of from the edges in every cycle.
//!
//! ### Congruent faces (issue 12, Detail)
//! On a refined cloth the fine faces of one coarse face are congruent: translates of one
//! lattice triangle (the up ones) or of its point reflection (the down ones), on the
//! planar coarse face ([`crate::mesh::refine::Partial::face_congruence`]). Their area
//! vectors are therefore one face's: `S` of the edge opposite corner `k`, oriented along
//! the corners `k+1 → k+2`, is the run's first face's `S` of its corresponding corner
//! `k + c` (the cyclic shift of the corners), negated for a face of the other
//! orientation (the point reflection reverses the edge and the segment `c_T − m` alike,
//! and keeps the normal); it is then oriented from the lower- to the higher-numbered
//! vertex as above. So [`dual_fluxes`] computes the normal, its length and the centroid
//! once per coarse face in the simulator's window, and per fine face only the three dot
//! products. The vectors are the face's own up to the rounding of the fine vertices'
//! barycentric placement (a test compares the fluxes on a folded refined sheet, levels
//! 1–3, to 1e-13 of the largest).
//!
//! ## Momentum advection (§4.3.2)
//! The alternative of §4.3.2 moves the momentum `p_i = m_i u_i` with the same transfers as
//! the solvent: a transfer of fraction `φ` of the donor's mass takes `φ p_donor` with it,
//! which arrives in the receiver's frame as `R_{recv,donor} φ p_donor`. After all sub-steps
//! `u_i' = p_i' / m_i'`, a convex combination of transported velocities. Where `m_i'` is
//! at most [`MOMENTUM_MIN_MASS_REL`] of the largest mass (a dry vertex), the velocity is
//! undefined and the semi-Lagrangian value is returned instead. On a flat mesh `R`
//! preserves world vectors, so the total world momentum is conserved.

use glam::{DMat2, DVec2, DVec3};
use rayon::prelude::*;

use crate::error::ParamError;
use crate::mesh::transport::wrap_angle;
use crate::mesh::{EdgeKind, Geometry, OneRings, Topology, Transport, VertexFrames, Wedge};
use crate::runs::carve;

/// Most triangle crossings of one back-trace. Reached only when `h|u|` spans hundreds of
/// edges; the trace then stops at its last crossing point.
pub(crate) const MAX_CROSSINGS: usize = 256;

/// Largest number of sub-steps of one upwind step; beyond it the limiter keeps masses
/// non-negative.
pub(crate) const MAX_SUBSTEPS: usize = 64;

/// Largest fraction of its mass a vertex gives away in one sub-step before sub-cycling.
pub(crate) const SUBSTEP_COURANT: f64 = 0.9;

/// A face whose `|e_ij × e_ik|` is below this fraction of its longest squared edge (the
/// sine of its largest angle, roughly) has a normal dominated by rounding (`≈ 10⁻¹⁶ ℓ²`
/// absolute error, so more than `10⁻⁴` relative below this bound): its dual area vectors
/// are set to zero.
pub(crate) const FLAT_FACE_REL: f64 = 1e-12;

/// Relative tolerance (an angle, in radians) within which a point counts as lying on the
/// line of the back-trace. The layout positions carry rounding errors of order
/// `10⁻¹⁶ × (number of unfoldings)` relative; a segment running along a straight border
/// must see the border vertices *on* its line, whatever the rounding, to follow it.
pub(crate) const SIDE_TOLERANCE: f64 = 1e-12;

/// Below this length of the sum of two unit complex numbers (two angles within
/// `2 acos(10⁻³/2) ≈ π − 10⁻³` of each other) an unfolded vertex's turn is the mean of
/// the angles themselves ([`Trace`]'s turn, module doc): the bisector's direction is
/// then ill-conditioned. Its two angles differ by the holonomy share of one corner, far
/// from π on any cloth.
const BISECTOR_MIN: f64 = 1e-3;

/// Solvent mass, relative to the largest mass before the step, below which the momentum
/// velocity is not formed. The momentum of a vertex carries an absolute rounding error of
/// a few `10⁻¹⁶` times the mass that passed through it; above this bound that error is
/// below `10⁻³` of the velocity.
pub(crate) const MOMENTUM_MIN_MASS_REL: f64 = 1e-12;

// ---------------------------------------------------------------------------------------
// velocity

/// A vertex placed in the layout plane of the back-trace.
#[derive(Clone, Copy)]
struct Placed {
    v: usize,
    p: DVec2,
    /// Its side of the line `0 → foot` ([`Trace::side`]), computed once.
    side: f64,
    /// Rotation from `F_v` into the layout (= `F_i`) coordinates.
    q: Turn,
}

/// The rotation of a [`Placed`] vertex: a matrix (`i` and its one-ring), or, for a vertex
/// placed by the unfolding, what it is computed from. Only the vertices whose velocity is
/// read (the last triangle's, a crossing's where the walk stops) need it, and most
/// vertices a long strip passes are not read: their `atan2`s and `sin_cos`, and the look-up
/// of their polar angles, are left undone. When read it is computed by the same operations
/// as if it had been computed at once, so the values are the same.
#[derive(Clone, Copy)]
enum Turn {
    Matrix(DMat2),
    /// Layout directions of the edges `c → r` and `c → l` (`c` the placed vertex), and
    /// where the polar angles `α + δ_c` of those edges in `F_c` are stored: each edge and
    /// the end that is `c` ([`Transport::edge_polar`]).
    Unfolded {
        to_r: DVec2,
        to_l: DVec2,
        edge_r: u32,
        edge_l: u32,
        end_r: u8,
        end_l: u8,
    },
}

/// Semi-Lagrangian advection of the velocity over `h` (see the module doc): the value at
/// the foot `−h u_i` of every vertex's characteristic, interpolated in the flattened
/// one-ring and, beyond it, along the unfolded strip of triangles. Loose vertices and zero
/// velocities keep their value.
///
/// # Panics
/// If `rings`, `geometry`, `transport` or `velocity` do not belong to `topology`'s vertices
/// (a programming error).
pub fn advect_velocity(
    topology: &Topology,
    rings: &OneRings,
    geometry: &Geometry,
    transport: &Transport,
    velocity: &[DVec2],
    h: f64,
) -> Vec<DVec2> {
    let mut out = Vec::new();
    advect_velocity_where(
        topology, rings, geometry, transport, velocity, h, None, &mut out,
    );
    out
}

/// [`advect_velocity`] on the vertices where `active` is `true` only (the simulator's
/// active region), into `out` (its allocation kept); the others keep their velocity.
/// Each traced vertex gets exactly the value [`advect_velocity`] gives it.
///
/// # Panics
/// As [`advect_velocity`], and if `active` does not have one entry per vertex.
#[allow(clippy::too_many_arguments)]
pub(crate) fn advect_velocity_in(
    topology: &Topology,
    rings: &OneRings,
    geometry: &Geometry,
    transport: &Transport,
    velocity: &[DVec2],
    h: f64,
    active: &[bool],
    out: &mut Vec<DVec2>,
) {
    assert_eq!(active.len(), topology.n_vertices(), "one flag per vertex");
    advect_velocity_where(
        topology,
        rings,
        geometry,
        transport,
        velocity,
        h,
        Some(active),
        out,
    );
}

#[allow(clippy::too_many_arguments)]
fn advect_velocity_where(
    topology: &Topology,
    rings: &OneRings,
    geometry: &Geometry,
    transport: &Transport,
    velocity: &[DVec2],
    h: f64,
    active: Option<&[bool]>,
    out: &mut Vec<DVec2>,
) {
    let n = topology.n_vertices();
    assert_eq!(rings.n_vertices(), n, "rings of another topology");
    assert_eq!(velocity.len(), n, "one velocity per vertex");
    assert_eq!(
        geometry.vertex_area.len(),
        n,
        "geometry of another topology"
    );
    let edge_faces = edge_faces(topology);
    (0..n)
        .into_par_iter()
        .map(|i| {
            if active.is_none_or(|a| a[i]) {
                back_trace(
                    topology,
                    &edge_faces,
                    rings,
                    geometry,
                    transport,
                    velocity,
                    h,
                    i,
                )
            } else {
                velocity[i]
            }
        })
        .collect_into_vec(out);
}

/// The first two faces of every edge, in face order (`u32::MAX` where there are fewer):
/// both faces of an interior edge, read by the back-trace to cross it.
fn edge_faces(topology: &Topology) -> Vec<[u32; 2]> {
    let mut faces = vec![[u32::MAX; 2]; topology.n_edges()];
    for (f, fe) in topology.face_edges().iter().enumerate() {
        for &e in fe {
            let slot = &mut faces[e as usize];
            if slot[0] == u32::MAX {
                slot[0] = f as u32;
            } else if slot[1] == u32::MAX {
                slot[1] = f as u32;
            }
        }
    }
    faces
}

#[allow(clippy::too_many_arguments)]
fn back_trace(
    topology: &Topology,
    edge_faces: &[[u32; 2]],
    rings: &OneRings,
    geometry: &Geometry,
    transport: &Transport,
    velocity: &[DVec2],
    h: f64,
    i: usize,
) -> DVec2 {
    let u_i = velocity[i];
    let target = -h * u_i;
    if target == DVec2::ZERO || !target.is_finite() {
        return u_i;
    }
    let trace = Trace {
        topology,
        edge_faces,
        rings,
        geometry,
        transport,
        velocity,
        target,
        scale: target.length(),
    };
    // a segment along a border spoke leaves the fan with one tie-breaking rule and runs
    // along the border with the other: try both (see the module doc)
    [true, false]
        .into_iter()
        .find_map(|ties_left| trace.walk(i, ties_left))
        .unwrap_or(u_i)
}

/// One back-trace: the mesh, the field and the foot `target` in the layout of `F_i`.
struct Trace<'a> {
    topology: &'a Topology,
    /// The two faces of every interior edge ([`edge_faces`]).
    edge_faces: &'a [[u32; 2]],
    rings: &'a OneRings,
    geometry: &'a Geometry,
    transport: &'a Transport,
    velocity: &'a [DVec2],
    target: DVec2,
    scale: f64,
}

impl Trace<'_> {
    /// Side of `p` with respect to the line `0 → target` (positive on the left), snapped
    /// to 0 within [`SIDE_TOLERANCE`].
    fn side(&self, p: DVec2) -> f64 {
        let s = self.target.perp_dot(p);
        // `|p|` lies between `m` and `√2 m`: away from the threshold the answer is known
        // without the square root (the walk waits on it); near it, the exact test
        let (a, m) = (s.abs(), p.x.abs().max(p.y.abs()));
        let t = SIDE_TOLERANCE * self.scale;
        let on_line = if a > 1.5 * t * m {
            false
        } else if a <= 0.9 * t * m {
            true
        } else {
            a <= t * p.length()
        };
        if on_line { 0.0 } else { s }
    }

    /// The velocity of a placed vertex, turned into the layout (`F_i`).
    fn value(&self, a: &Placed) -> DVec2 {
        self.turn(a) * self.velocity[a.v]
    }

    /// The rotation `F_v → layout` of a placed vertex `v` (the module doc): for an
    /// unfolded one, the layout angle of each of its edges to `r` and `l` minus that
    /// spoke's polar angle, averaged.
    fn turn(&self, a: &Placed) -> DMat2 {
        match a.q {
            Turn::Matrix(q) => q,
            Turn::Unfolded {
                to_r,
                to_l,
                edge_r,
                edge_l,
                end_r,
                end_l,
            } => {
                let polar_r = self.transport.edge_polar(edge_r as usize)[end_r as usize];
                let polar_l = self.transport.edge_polar(edge_l as usize)[end_l as usize];
                unfolded_turn(to_r, to_l, polar_r, polar_l)
            }
        }
    }

    /// The walk from vertex `i` with points on the line counted as left (`ties_left`) or
    /// right; `None` if no wedge of `i` contains the direction of the foot.
    fn walk(&self, i: usize, ties_left: bool) -> Option<DVec2> {
        let (rings, transport, target) = (self.rings, self.transport, self.target);
        let is_left = |s: f64| if ties_left { s >= 0.0 } else { s > 0.0 };
        // first triangle: the wedge whose sector contains the direction of `target`
        let spokes = rings.spokes(i);
        let spoke_edges = rings.spoke_edges(i);
        let alpha = transport.polar_angles(i);
        let delta = transport.frame_offset(i);
        let place = |s: u32| {
            let s = s as usize;
            let len = self.geometry.edge_length[spoke_edges[s] as usize];
            let (sin, cos) = (alpha[s] + delta).sin_cos();
            len * DVec2::new(cos, sin)
        };
        // a wedge whose polar sector is well clear of the foot's direction cannot pass the
        // test below: skip it without placing its spokes (the module doc, "First wedge")
        let psi = rough_atan2(target.y, target.x);
        let may_hold = |w: &Wedge| {
            let (a, b) = (w.from as usize, w.to as usize);
            let finite = |s: usize| self.geometry.edge_length[spoke_edges[s] as usize].is_finite();
            !(finite(a) && finite(b)) || in_sector(psi, alpha[a] + delta, alpha[b] + delta)
        };
        // consecutive wedges of a fan share a spoke: place each spoke once
        let mut last = (u32::MAX, DVec2::ZERO);
        let (wedge, pj, pk) = rings.wedges(i).iter().find_map(|w| {
            if !may_hold(w) {
                return None;
            }
            let pa = if last.0 == w.from {
                last.1
            } else {
                place(w.from)
            };
            let pb = place(w.to);
            last = (w.to, pb);
            (pa.perp_dot(pb) > 0.0 && !is_left(self.side(pa)) && is_left(self.side(pb)))
                .then_some((w, pa, pb))
        })?;
        let rot = |s: u32| {
            let r = transport.edge_rotation(spoke_edges[s as usize] as usize);
            if i < spokes[s as usize] as usize {
                r
            } else {
                r.transpose()
            }
        };
        let mut behind = Placed {
            v: i,
            p: DVec2::ZERO,
            side: 0.0,
            q: Turn::Matrix(DMat2::IDENTITY),
        };
        let mut right = Placed {
            v: spokes[wedge.from as usize] as usize,
            p: pj,
            side: self.side(pj),
            q: Turn::Matrix(rot(wedge.from)),
        };
        let mut left = Placed {
            v: spokes[wedge.to as usize] as usize,
            p: pk,
            side: self.side(pk),
            q: Turn::Matrix(rot(wedge.to)),
        };
        let mut face = wedge.face as usize;
        // the last entry point (`i`, or a crossing of an edge at a fraction), whose value
        // the degenerate fallbacks return: the crossed edge is (right, behind) if the
        // vertex placed beyond it became `left`, else (behind, left); it is kept as that
        // choice and the fraction, not as copies of the two vertices
        let mut entry: Option<(bool, f64)> = None;
        let at =
            |right: &Placed, left: &Placed, f: f64| self.value(right).lerp(self.value(left), f);

        for crossing in 0..=MAX_CROSSINGS {
            let (pr, pl) = (right.p, left.p);
            if (pl - pr).perp_dot(target - pr) >= 0.0 {
                // the foot is in the current triangle (behind, right, left)
                return Some(match barycentric(behind.p, pr, pl, target) {
                    Some([a, b, c]) => {
                        a * self.value(&behind) + b * self.value(&right) + c * self.value(&left)
                    }
                    None => match entry {
                        None => self.value(&behind),
                        Some((true, f)) => at(&right, &behind, f),
                        Some((false, f)) => at(&behind, &left, f),
                    },
                });
            }
            // the segment crosses the edge (right, left) at fraction f from `right`
            // (right.side ≤ 0 ≤ left.side, not both 0)
            let f = (-right.side / (left.side - right.side)).clamp(0.0, 1.0);
            if crossing == MAX_CROSSINGS {
                return Some(at(&right, &left, f));
            }
            let Some((g, c)) = self.across(face, behind.v, &right, &left, f) else {
                return Some(at(&right, &left, f));
            };
            face = g;
            let went_left = is_left(c.side);
            entry = Some((went_left, f));
            if went_left {
                behind = left;
                left = c;
            } else {
                behind = right;
                right = c;
            }
        }
        unreachable!("the loop returns at its last crossing")
    }

    /// Unfolds the face across edge `(r, l)` of `face` (see the module doc): its index and its
    /// third vertex, placed in the layout. `None` at a border or non-manifold edge, or if the
    /// geometry is too degenerate to place it.
    fn across(
        &self,
        face: usize,
        behind: usize,
        r: &Placed,
        l: &Placed,
        f: f64,
    ) -> Option<(usize, Placed)> {
        let (topology, geometry) = (self.topology, self.geometry);
        // the edge (r, l) is the face's edge opposite its third corner, `behind`
        let k_behind = topology.faces()[face]
            .iter()
            .position(|&x| x as usize == behind)?;
        let e = topology.face_edges()[face][k_behind] as usize;
        if topology.edge_kind(e) != EdgeKind::Interior {
            return None;
        }
        // an interior edge has two faces: the other one
        let [f0, f1] = self.edge_faces[e];
        let g = if f0 as usize == face { f1 } else { f0 } as usize;
        let tri = topology.faces()[g];
        let corner = |v: usize| tri.iter().position(|&x| x as usize == v);
        let (kr, kl) = (corner(r.v)?, corner(l.v)?);
        let kc = 3 - kr - kl;
        let c = tri[kc] as usize;
        let fe = topology.face_edges()[g];
        let len = |k: usize| geometry.edge_length[fe[k] as usize];
        let (l_rl, l_lc, l_rc) = (geometry.edge_length[e], len(kr), len(kl));
        let d = l.p - r.p;
        let t = d.normalize_or_zero();
        if l_rl.is_nan() || l_rl <= 0.0 || t == DVec2::ZERO {
            return None;
        }
        let n = DVec2::new(t.y, -t.x);
        let x = (l_rc * l_rc - l_lc * l_lc + l_rl * l_rl) / (2.0 * l_rl);
        let y = 2.0 * geometry.face_area[g] / l_rl;
        let r_star = r.p + f * d - f * l_rl * t;
        let l_star = r_star + l_rl * t;
        let p = r_star + x * t + y * n;
        if !p.is_finite() {
            return None;
        }
        // rotation F_c → layout from the directions of c → r and c → l, evaluated if read
        Some((
            g,
            Placed {
                v: c,
                p,
                side: self.side(p),
                q: Turn::Unfolded {
                    to_r: r_star - p,
                    to_l: l_star - p,
                    edge_r: fe[kl],
                    edge_l: fe[kr],
                    end_r: u8::from(c > r.v),
                    end_l: u8::from(c > l.v),
                },
            },
        ))
    }
}

/// The rotation `F_c → layout` of a vertex `c` placed by the unfolding, from the layout
/// directions `to_r`, `to_l` of its edges to `r` and `l` and their polar angles in `F_c`:
/// the mean of `arg(to_m) − polar_m` over the two edges, on the shorter arc (module doc),
/// taken on unit complex numbers: `e^{i a} = (to / |to|) e^{−i polar}` per edge, the mean
/// the direction of their sum. Two nearly opposite ([`BISECTOR_MIN`]): the angles.
fn unfolded_turn(to_r: DVec2, to_l: DVec2, polar_r: f64, polar_l: f64) -> DMat2 {
    let unit = |to: DVec2, polar: f64| {
        let (sin, cos) = polar.sin_cos();
        DVec2::new(to.x * cos + to.y * sin, to.y * cos - to.x * sin) / to.length()
    };
    let sum = unit(to_r, polar_r) + unit(to_l, polar_l);
    let len = sum.length();
    if len > BISECTOR_MIN {
        let (cos, sin) = (sum.x / len, sum.y / len);
        DMat2::from_cols_array(&[cos, sin, -sin, cos])
    } else {
        let a_r = to_r.y.atan2(to_r.x) - polar_r;
        let a_l = to_l.y.atan2(to_l.x) - polar_l;
        DMat2::from_angle(a_r + 0.5 * wrap_angle(a_l - a_r))
    }
}

/// Margin (radians) of the first wedge's angular pre-test, [`in_sector`]: far above the
/// error of [`rough_atan2`] (below `10⁻⁵`) and the rounding of the polar angles and of
/// [`SIDE_TOLERANCE`] (below `10⁻¹¹`), far below a wedge's opening.
const SECTOR_MARGIN: f64 = 1e-3;

/// Whether the direction of polar angle `psi` may lie in the counter-clockwise sector from
/// angle `a` to angle `b` (any real angles), [`SECTOR_MARGIN`] included on both sides. A
/// wedge that passes the exact test of the back-trace (`P_a` right of the foot's line,
/// `P_b` on or left of it, `P_a × P_b > 0`) contains the direction of the foot up to
/// rounding, so it always passes this one; a sector of nearly `2π` lets everything pass.
/// `false` for NaN angles.
fn in_sector(psi: f64, a: f64, b: f64) -> bool {
    use std::f64::consts::TAU;
    // psi − a into [−margin, 2π − margin), b − a into [0, 2π); the angles are polar
    // angles within a few turns of each other, so the loops run at most a few times
    let (mut d, mut w) = (psi - a, b - a);
    if !(d.is_finite() && w.is_finite()) {
        return false;
    }
    while d < -SECTOR_MARGIN {
        d += TAU;
    }
    while d >= TAU - SECTOR_MARGIN {
        d -= TAU;
    }
    while w < 0.0 {
        w += TAU;
    }
    while w >= TAU {
        w -= TAU;
    }
    d <= w + SECTOR_MARGIN
}

/// `atan2(y, x)` to within `10⁻⁵` radians, without the library call: a pre-test only
/// ([`in_sector`]), never a value the results depend on. An odd minimax polynomial for
/// `atan` on `[0, 1]`, extended to the plane by the octant's symmetries.
fn rough_atan2(y: f64, x: f64) -> f64 {
    use std::f64::consts::{FRAC_PI_2, PI};
    let (ax, ay) = (x.abs(), y.abs());
    let (lo, hi) = (ax.min(ay), ax.max(ay));
    if hi == 0.0 || !hi.is_finite() {
        return y.atan2(x);
    }
    let t = lo / hi;
    let t2 = t * t;
    let mut a = t
        * (0.999_977_26
            + t2 * (-0.332_623_47
                + t2 * (0.193_543_46
                    + t2 * (-0.116_432_87 + t2 * (0.052_653_32 + t2 * -0.011_721_20)))));
    if ay > ax {
        a = FRAC_PI_2 - a;
    }
    if x < 0.0 {
        a = PI - a;
    }
    if y < 0.0 { -a } else { a }
}

/// Barycentric coordinates of `p` in the triangle `(a, b, c)`, clamped to `[0, 1]` and
/// renormalized; `None` if the triangle is degenerate.
fn barycentric(a: DVec2, b: DVec2, c: DVec2, p: DVec2) -> Option<[f64; 3]> {
    let (v0, v1, w) = (b - a, c - a, p - a);
    let det = v0.perp_dot(v1);
    if det == 0.0 || !det.is_finite() {
        return None;
    }
    let lb = w.perp_dot(v1) / det;
    let lc = v0.perp_dot(w) / det;
    let l = [1.0 - lb - lc, lb, lc].map(|x| x.max(0.0));
    let sum = l[0] + l[1] + l[2];
    let out = l.map(|x| x / sum);
    (sum > 0.0 && out.iter().all(|x| x.is_finite())).then_some(out)
}

// ---------------------------------------------------------------------------------------
// densities

/// Volume flux `Φ_ab` (m²/s) from `a` to `b` through the median-dual faces of every edge
/// `(a, b)` of [`Topology::edges`], `a < b` (see the module doc). `velocity` is per vertex
/// in `frames`.
///
/// # Panics
/// If `positions`, `frames` or `velocity` do not have one entry per vertex.
pub fn dual_fluxes(
    topology: &Topology,
    positions: &[DVec3],
    frames: &VertexFrames,
    velocity: &[DVec2],
) -> Vec<f64> {
    let mut flux = Vec::new();
    dual_fluxes_into(topology, positions, frames, velocity, None, None, &mut flux);
    flux
}

/// [`dual_fluxes`] through the edges whose two ends are `active` (the simulator's active
/// region); the other edges get no flux. Only the faces with an active edge are visited;
/// each active edge gets exactly the value [`dual_fluxes`] gives it (the same face
/// contributions, summed in the same order).
///
/// # Panics
/// As [`dual_fluxes`], and if `active` does not have one entry per vertex.
///
/// With `share` (a refined cloth's congruent faces, as
/// [`crate::mesh::Transport::with_shared_tips`] takes them), the median-dual area vectors
/// of each run of congruent faces are computed once (module doc, "Congruent faces").
///
/// Into `flux` (its allocation kept).
pub(crate) fn dual_fluxes_in(
    topology: &Topology,
    positions: &[DVec3],
    frames: &VertexFrames,
    velocity: &[DVec2],
    active: &[bool],
    share: Option<&[(u32, u8)]>,
    flux: &mut Vec<f64>,
) {
    assert_eq!(active.len(), topology.n_vertices(), "one flag per vertex");
    dual_fluxes_into(
        topology,
        positions,
        frames,
        velocity,
        Some(active),
        share,
        flux,
    );
}

fn dual_fluxes_into(
    topology: &Topology,
    positions: &[DVec3],
    frames: &VertexFrames,
    velocity: &[DVec2],
    active: Option<&[bool]>,
    share: Option<&[(u32, u8)]>,
    flux: &mut Vec<f64>,
) {
    let n = topology.n_vertices();
    assert_eq!(positions.len(), n, "one position per vertex");
    assert_eq!(frames.len(), n, "one frame per vertex");
    assert_eq!(velocity.len(), n, "one velocity per vertex");
    let on = |v: u32| active.is_none_or(|a| a[v as usize]);
    let world: Vec<DVec3> = (0..n)
        .into_par_iter()
        .with_min_len(VERTICES_PER_TASK)
        .map(|i| {
            if on(i as u32) {
                frames.to_world(i, velocity[i])
            } else {
                DVec3::ZERO
            }
        })
        .collect();
    // a face with fewer than two active corners has no active edge
    let needed = |tri: &[u32; 3]| tri.iter().filter(|&&v| on(v)).count() >= 2;
    let per_face: Vec<[f64; 3]> = match share {
        None => topology
            .faces()
            .par_iter()
            .with_min_len(VERTICES_PER_TASK)
            .map(|tri| {
                if needed(tri) {
                    face_fluxes(tri.map(|v| v as usize), positions, &world)
                } else {
                    [0.0; 3]
                }
            })
            .collect(),
        Some(share) => {
            // runs of congruent faces (consecutive, each led by the face they share),
            // one set of area vectors per run (module doc, "Congruent faces")
            let faces = topology.faces();
            assert_eq!(share.len(), faces.len(), "one share per face");
            let starts: Vec<usize> = (0..faces.len())
                .filter(|&t| share[t].0 as usize == t)
                .collect();
            starts
                .par_iter()
                .enumerate()
                .with_min_len(VERTICES_PER_TASK / 16)
                .flat_map_iter(|(i, &lead)| {
                    let end = starts.get(i + 1).copied().unwrap_or(faces.len());
                    let (world, needed) = (&world, &needed);
                    let lead_tri = faces[lead].map(|v| v as usize);
                    // the lead's vectors only if a face of the run needs them
                    let area = faces[lead..end]
                        .iter()
                        .any(needed)
                        .then(|| face_area_vectors(lead_tri, positions));
                    (lead..end).map(move |t| {
                        let tri = faces[t];
                        match area {
                            Some(area) if needed(&tri) => {
                                debug_assert_eq!(
                                    share[t].0 as usize, lead,
                                    "a run shares its lead"
                                );
                                let c = share[t].1 as usize;
                                // a face of the other orientation is the lead turned by π
                                let sign = if c == 0 { 1.0 } else { -1.0 };
                                std::array::from_fn(|k| {
                                    let s = area[(k + c) % 3] * sign;
                                    let (a, b) = (tri[(k + 1) % 3], tri[(k + 2) % 3]);
                                    let s = if a > b { -s } else { s };
                                    0.5 * (world[a as usize] + world[b as usize]).dot(s)
                                })
                            }
                            _ => [0.0; 3],
                        }
                    })
                })
                .collect()
        }
    };
    // gather per edge in face order (deterministic)
    flux.clear();
    flux.resize(topology.n_edges(), 0.0);
    for (fe, contrib) in topology.face_edges().iter().zip(&per_face) {
        for k in 0..3 {
            flux[fe[k] as usize] += contrib[k];
        }
    }
    if active.is_some() {
        for (phi, &[a, b]) in flux.iter_mut().zip(topology.edges()) {
            if !(on(a) && on(b)) {
                *phi = 0.0;
            }
        }
    }
}

/// The median-dual area vectors `S^T` of the edges opposite the corners `k` of a face,
/// each oriented from corner `k + 1` to corner `k + 2` (`S · (p_{k+2} − p_{k+1}) ≥ 0`);
/// zero for a flat face ([`FLAT_FACE_REL`]).
fn face_area_vectors(tri: [usize; 3], pos: &[DVec3]) -> [DVec3; 3] {
    let p = tri.map(|v| pos[v]);
    let normal = (p[1] - p[0]).cross(p[2] - p[0]);
    let longest = (0..3)
        .map(|k| p[(k + 1) % 3].distance_squared(p[(k + 2) % 3]))
        .fold(0.0, f64::max);
    let area2 = normal.length();
    if area2.is_nan() || area2 <= FLAT_FACE_REL * longest {
        return [DVec3::ZERO; 3];
    }
    let unit = normal / area2;
    let centroid = (p[0] + p[1] + p[2]) / 3.0;
    std::array::from_fn(|k| {
        let (a, b) = ((k + 1) % 3, (k + 2) % 3);
        let mid = 0.5 * (p[a] + p[b]);
        let s = (centroid - mid).cross(unit);
        if s.dot(p[b] - p[a]) < 0.0 { -s } else { s }
    })
}

/// `u_ab · S_ab^T` for the edge opposite each corner `k` of a face, from its lower- to its
/// higher-numbered vertex: [`face_area_vectors`] turned round where the corners run from
/// the higher-numbered one (an exact negation), dotted with the edge's mean velocity.
fn face_fluxes(tri: [usize; 3], pos: &[DVec3], world: &[DVec3]) -> [f64; 3] {
    let s = face_area_vectors(tri, pos);
    std::array::from_fn(|k| {
        let (a, b) = (tri[(k + 1) % 3], tri[(k + 2) % 3]);
        let s = if a > b { -s[k] } else { s[k] };
        0.5 * (world[a] + world[b]).dot(s)
    })
}

/// The upwind transport plan of one step `h`: which endpoint donates across each edge and
/// what fraction of the donor's mass it gives per sub-step (see the module doc).
#[derive(Debug, Clone)]
pub struct UpwindPlan {
    /// Edges of the plan's topology.
    n_edges: usize,
    substeps: usize,
    max_courant: f64,
    n_limited: usize,
    /// The transfers as each vertex sees them, built once with the plan.
    flows: Flows,
}

impl UpwindPlan {
    /// Fractions `h |Φ| / (n A_donor)` for `n` sub-steps, with the sub-cycling and limiter
    /// of the module doc. `vertex_area` are the dual (lumped) areas `A_i`, `flux` the
    /// output of [`dual_fluxes`].
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

    fn check(&self, topology: &Topology, len: usize) {
        assert_eq!(self.n_edges, topology.n_edges(), "plan of another topology");
        assert_eq!(len, topology.n_vertices(), "one value per vertex");
    }

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

    /// The sub-cycles on the fields, interleaved per vertex, and, given the transport and
    /// the solvent's momentum, on the momentum too (returned; empty without).
    fn cycles(
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

/// An [`UpwindPlan`]'s transfers per vertex: the fractions it gives away, and the
/// `(fraction, donor, edge)` of what it receives, each in the vertex's edge order, without
/// the edges that carry nothing. Built once with the plan (in parallel over runs of
/// vertices, laid end to end: deterministic), read by every sub-cycle.
#[derive(Debug, Clone, Default)]
struct Flows {
    out_ptr: Vec<u32>,
    out_fraction: Vec<f64>,
    in_ptr: Vec<u32>,
    in_from: Vec<(f64, u32, u32)>,
}

/// One run of vertices in [`UpwindPlan::new`]: their outflows, and their transfers
/// (`|Φ|` where [`Flows`] will hold the fractions; ends relative to the run's start).
#[derive(Default)]
struct Run {
    outflow: Vec<f64>,
    flows: Flows,
}

/// The rotations `R_vd` of the received transfers, as `(cos, sin)` of `[cos −sin; sin cos]`:
/// a table in [`Flows::received`] order ([`Flows::turns`]), or read off the edges'
/// rotations (transposed where `v > d`) each time.
enum Turns<'a> {
    Table(Vec<[f64; 2]>),
    Edges(&'a [[f64; 2]]),
}

/// Vertices per task of the transfer passes (rayon's splitting below this costs more
/// than the work).
const VERTICES_PER_TASK: usize = 1024;

impl Flows {
    /// Runs of consecutive vertices' transfers (each with ends relative to its own
    /// start) laid end to end, in place of these flows (their allocations kept).
    fn concat(&mut self, n: usize, runs: Vec<Flows>) {
        let given: usize = runs.iter().map(|r| r.out_fraction.len()).sum();
        let received: usize = runs.iter().map(|r| r.in_from.len()).sum();
        let f = self;
        f.out_ptr.clear();
        f.out_fraction.clear();
        f.in_ptr.clear();
        f.in_from.clear();
        // exact: the transfers grow a little every sub-step while the liquid spreads, and
        // the doubling of an amortized reserve would keep up to twice their memory
        f.out_ptr.reserve_exact(n + 1);
        f.out_fraction.reserve_exact(given);
        f.in_ptr.reserve_exact(n + 1);
        f.in_from.reserve_exact(received);
        f.out_ptr.push(0);
        f.in_ptr.push(0);
        for run in runs {
            let (o, i) = (f.out_fraction.len() as u32, f.in_from.len() as u32);
            f.out_ptr.extend(run.out_ptr.iter().map(|x| o + x));
            f.in_ptr.extend(run.in_ptr.iter().map(|x| i + x));
            f.out_fraction.extend(run.out_fraction);
            f.in_from.extend(run.in_from);
        }
    }

    fn given(&self, v: usize) -> &[f64] {
        &self.out_fraction[self.out_ptr[v] as usize..self.out_ptr[v + 1] as usize]
    }

    fn received(&self, v: usize) -> &[(f64, u32, u32)] {
        &self.in_from[self.in_ptr[v] as usize..self.in_ptr[v + 1] as usize]
    }

    /// One sub-cycle of `k` interleaved fields `m` into `next`.
    fn cycle(&self, m: &[f64], k: usize, next: &mut [f64]) {
        next.par_chunks_mut(k)
            .enumerate()
            .with_min_len(VERTICES_PER_TASK)
            .for_each(|(v, out)| self.fields_at(v, m, k, out));
    }

    /// The rotation `R_vd` of each received transfer, in [`Flows::received`] order, as
    /// `(cos, sin)` of the matrix `[cos −sin; sin cos]`: the stored rotation of the edge or
    /// its transpose (the sine negated: exact), read once per plan instead of once per
    /// sub-cycle.
    fn turns(&self, transport: &Transport) -> Vec<[f64; 2]> {
        let cos_sin = transport.edge_cos_sin();
        let n = self.in_ptr.len() - 1;
        let mut turns = vec![[0.0; 2]; self.in_from.len()];
        // runs of vertices, each filling its own stretch of the table
        let ranges: Vec<_> = (0..n)
            .step_by(VERTICES_PER_TASK)
            .map(|start| start..(start + VERTICES_PER_TASK).min(n))
            .collect();
        let lens = ranges
            .iter()
            .map(|r| (self.in_ptr[r.end] - self.in_ptr[r.start]) as usize);
        let runs = carve(&mut turns, lens);
        ranges
            .into_par_iter()
            .zip(runs)
            .for_each(|(vertices, out)| {
                let base = self.in_ptr[vertices.start] as usize;
                for v in vertices {
                    for t in self.in_ptr[v] as usize..self.in_ptr[v + 1] as usize {
                        let (_, d, e) = self.in_from[t];
                        let [c, s] = cos_sin[e as usize];
                        out[t - base] = if v < d as usize { [c, s] } else { [c, -s] };
                    }
                }
            });
        turns
    }

    /// [`Flows::cycle`], and the momentum `p` into `p_next` in the same pass (`turns` from
    /// [`Flows::turns`]).
    fn cycle_with_momentum(
        &self,
        m: &[f64],
        k: usize,
        next: &mut [f64],
        turns: &Turns<'_>,
        p: &[DVec2],
        p_next: &mut [DVec2],
    ) {
        next.par_chunks_mut(k)
            .zip(p_next.par_iter_mut())
            .enumerate()
            .with_min_len(VERTICES_PER_TASK)
            .for_each(|(v, (out, pv))| {
                self.fields_at(v, m, k, out);
                *pv = self.momentum_at(v, turns, p);
            });
    }

    /// Vertex `v`'s fields after one sub-cycle: it gives `fraction · m_v` across each of
    /// its outgoing edges and receives `fraction · m_donor` across each incoming one — the
    /// same product on both sides, so the transfer is conservative to rounding — clamped
    /// at zero against rounding. The transfers are read once for all fields, each field
    /// summed in transfer order (the same sums as one field at a time).
    fn fields_at(&self, v: usize, m: &[f64], k: usize, out: &mut [f64]) {
        match k {
            1 => self.fields_at_k::<1>(v, m, out),
            2 => self.fields_at_k::<2>(v, m, out),
            3 => self.fields_at_k::<3>(v, m, out),
            4 => self.fields_at_k::<4>(v, m, out),
            5 => self.fields_at_k::<5>(v, m, out),
            _ => self.fields_at_one_by_one(v, m, k, out),
        }
    }

    /// [`Flows::fields_at`] for `K` fields.
    fn fields_at_k<const K: usize>(&self, v: usize, m: &[f64], out: &mut [f64]) {
        let mv: [f64; K] = m[v * K..(v + 1) * K].try_into().expect("K fields");
        let mut gone = [0.0; K];
        for &fraction in self.given(v) {
            for c in 0..K {
                gone[c] += fraction * mv[c];
            }
        }
        let mut inflow = [0.0; K];
        for &(fraction, d, _) in self.received(v) {
            let md: [f64; K] = m[d as usize * K..(d as usize + 1) * K]
                .try_into()
                .expect("K fields");
            for c in 0..K {
                inflow[c] += fraction * md[c];
            }
        }
        for c in 0..K {
            out[c] = (mv[c] - gone[c]).max(0.0) + inflow[c];
        }
    }

    /// [`Flows::fields_at`] for more than five fields, one field at a time.
    fn fields_at_one_by_one(&self, v: usize, m: &[f64], k: usize, out: &mut [f64]) {
        for (c, o) in out.iter_mut().enumerate() {
            let mv = m[v * k + c];
            let mut gone = 0.0;
            for &fraction in self.given(v) {
                gone += fraction * mv;
            }
            let mut inflow = 0.0;
            for &(fraction, d, _) in self.received(v) {
                inflow += fraction * m[d as usize * k + c];
            }
            *o = (mv - gone).max(0.0) + inflow;
        }
    }

    /// Vertex `v`'s momentum after one sub-cycle: the same fractions of the donors'
    /// momenta, turned into `F_v` by `R_vd` (from `turns`).
    fn momentum_at(&self, v: usize, turns: &Turns<'_>, p: &[DVec2]) -> DVec2 {
        let (mut out, mut inflow) = (DVec2::ZERO, DVec2::ZERO);
        for &fraction in self.given(v) {
            out += fraction * p[v];
        }
        let (start, end) = (self.in_ptr[v] as usize, self.in_ptr[v + 1] as usize);
        for (t, &(fraction, d, e)) in self.in_from[start..end].iter().enumerate() {
            let [c, s] = match turns {
                Turns::Table(table) => table[start + t],
                Turns::Edges(cos_sin) => {
                    let [c, s] = cos_sin[e as usize];
                    if v < d as usize { [c, s] } else { [c, -s] }
                }
            };
            let r = DMat2::from_cols_array(&[c, s, -s, c]);
            inflow += r * (fraction * p[d as usize]);
        }
        (p[v] - out) + inflow
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    struct Mesh {
        t: Topology,
        p: Vec<DVec3>,
        rings: OneRings,
        geometry: Geometry,
        frames: VertexFrames,
        transport: Transport,
    }

    fn mesh(n: usize, faces: Vec<[u32; 3]>, p: Vec<DVec3>) -> Mesh {
        let t = Topology::from_triangles(n, faces).unwrap();
        let rings = OneRings::new(&t);
        let geometry = Geometry::new(&t, &p).unwrap();
        let frames = VertexFrames::new(&rings, &p).unwrap();
        let transport = Transport::new(&t, &rings, &geometry, &frames, &p);
        Mesh {
            t,
            p,
            rings,
            geometry,
            frames,
            transport,
        }
    }

    fn advect(m: &Mesh, u: &[DVec2], h: f64) -> Vec<DVec2> {
        advect_velocity(&m.t, &m.rings, &m.geometry, &m.transport, u, h)
    }

    #[test]
    fn unfolded_turn_is_the_mean_angle() {
        use std::f64::consts::{PI, TAU};
        // against the angles themselves: a_m = arg(to_m) − polar_m, the mean on the
        // shorter arc, over random directions, lengths and polar angles, differences up
        // to nearly π (the fallback below BISECTOR_MIN included)
        let mut s = 0x2545_f491_4f6c_dd1d_u64;
        let mut next = || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 11) as f64 / (1u64 << 53) as f64
        };
        for case in 0..20_000 {
            let (a_r, len_r, len_l) = (TAU * next() - PI, 0.01 + next(), 0.01 + next());
            // the two angles' difference, up to ±(π − 1e-9)
            let gap = if case % 4 == 0 {
                (PI - 1e-9) * (2.0 * next() - 1.0)
            } else {
                0.3 * (2.0 * next() - 1.0)
            };
            let (polar_r, polar_l) = (4.0 * TAU * next() - 2.0 * TAU, TAU * next());
            let dir = |a: f64| DVec2::new(a.cos(), a.sin());
            let to_r = len_r * dir(a_r + polar_r);
            let to_l = len_l * dir(a_r + gap + polar_l);
            let want = DMat2::from_angle(a_r + 0.5 * gap);
            let got = unfolded_turn(to_r, to_l, polar_r, polar_l);
            let err = (got - want)
                .to_cols_array()
                .iter()
                .fold(0.0, |m: f64, x| m.max(x.abs()));
            assert!(err < 1e-12, "{case}: gap {gap}, off by {err:e}");
            assert!((got.determinant() - 1.0).abs() < 1e-14, "a rotation");
        }
    }

    #[test]
    fn congruent_faces_share_their_area_vectors() {
        use crate::mesh::refine::{Partial, folded_grid, tip_shares};
        // folded: each coarse face moves by its own affine map, so its fine faces stay
        // congruent
        let (coarse, _, now) = folded_grid(4, 3);
        for level in 1..=3 {
            let mut part = Partial::new(&coarse, level).unwrap();
            part.build(&(0..coarse.n_faces() as u32).collect::<Vec<_>>());
            let t = part.topology().unwrap();
            let q = part.prolong(&now);
            let share = tip_shares(part.face_congruence().into_iter());
            let frames = VertexFrames::new(&OneRings::new(&t), &q).unwrap();
            let u: Vec<DVec2> = (0..t.n_vertices())
                .map(|v| DVec2::new((v as f64 * 0.7).sin(), (v as f64 * 1.3).cos()))
                .collect();
            // half the vertices active: faces with one active corner get no flux
            let active: Vec<bool> = (0..t.n_vertices()).map(|v| v % 7 != 3).collect();
            let fluxes = |share: Option<&[(u32, u8)]>| {
                let mut flux = Vec::new();
                dual_fluxes_in(&t, &q, &frames, &u, &active, share, &mut flux);
                flux
            };
            let own = fluxes(None);
            let shared = fluxes(Some(&share));
            let peak = own.iter().fold(0.0, |m: f64, x| m.max(x.abs()));
            let worst = own
                .iter()
                .zip(&shared)
                .fold(0.0, |m: f64, (a, b)| m.max((a - b).abs()));
            assert!(
                peak > 0.0 && worst < 1e-13 * peak,
                "level {level}: {worst:e} of {peak:e}"
            );
            for (a, b) in own.iter().zip(&shared) {
                assert_eq!(*a == 0.0, *b == 0.0, "the same edges carry a flux");
            }
            // the orientation matters: without the reflection's sign the fluxes are wrong
            let unsigned: Vec<(u32, u8)> = share.iter().map(|&(r, _)| (r, 0)).collect();
            let wrong = fluxes(Some(&unsigned));
            let off = own
                .iter()
                .zip(&wrong)
                .fold(0.0, |m: f64, (a, b)| m.max((a - b).abs()));
            assert!(
                off > 1e-2 * peak,
                "level {level}: the shift changed nothing"
            );
        }
    }

    #[test]
    fn median_dual_area_vectors_have_two_thirds_of_the_area_along_their_edge() {
        let tri = [0usize, 1, 2];
        let pos = [
            DVec3::new(0.1, -0.2, 0.3),
            DVec3::new(1.3, 0.1, -0.2),
            DVec3::new(-0.4, 0.9, 0.5),
        ];
        let area = 0.5 * (pos[1] - pos[0]).cross(pos[2] - pos[0]).length();
        let centroid = (pos[0] + pos[1] + pos[2]) / 3.0;
        // S of each edge, read off with unit velocities along the axes
        let s: Vec<[f64; 3]> = [DVec3::X, DVec3::Y, DVec3::Z]
            .iter()
            .map(|&w| face_fluxes(tri, &pos, &[w; 3]))
            .collect();
        let [sx, sy, sz] = [&s[0], &s[1], &s[2]];
        for k in 0..3 {
            let sk = DVec3::new(sx[k], sy[k], sz[k]);
            let (a, b) = ((k + 1) % 3, (k + 2) % 3);
            let (a, b) = (a.min(b), a.max(b));
            let e = pos[b] - pos[a];
            let mid = 0.5 * (pos[a] + pos[b]);
            assert!((sk.dot(e) - 2.0 * area / 3.0).abs() < 1e-15, "edge {k}");
            assert!((sk.length() - (centroid - mid).length()).abs() < 1e-15);
            assert!(
                sk.dot(centroid - mid).abs() < 1e-15,
                "normal to the dual face"
            );
        }
        // a collapsed face carries no flux
        let flat = [DVec3::ZERO, DVec3::X, DVec3::new(0.5, 0.0, 0.0)];
        assert_eq!(face_fluxes(tri, &flat, &[DVec3::ONE; 3]), [0.0; 3]);
    }

    #[test]
    fn zero_velocity_and_loose_vertices_keep_their_value() {
        // a fan of 6 around vertex 0, plus a loose vertex 7
        let mut p = vec![DVec3::ZERO];
        for k in 0..6 {
            let a = std::f64::consts::TAU * k as f64 / 6.0;
            p.push(DVec3::new(a.cos(), a.sin(), 0.0));
        }
        p.push(DVec3::new(5.0, 5.0, 0.0));
        let faces = (0..6).map(|k| [0, 1 + k, 1 + (k + 1) % 6]).collect();
        let m = mesh(8, faces, p);
        let mut u = vec![DVec2::new(0.3, -0.1); 8];
        u[0] = DVec2::ZERO;
        u[7] = DVec2::new(1.7, 2.5);
        let out = advect(&m, &u, 0.4);
        assert_eq!(out[0], DVec2::ZERO);
        assert_eq!(out[7], u[7]);
        assert!(out.iter().all(|v| v.is_finite()));
    }

    #[test]
    fn irregular_and_degenerate_meshes_stay_finite() {
        // bow-tie at vertex 0, a fin of three faces on edge 5–6, a collapsed face 5–6–9
        let p = vec![
            DVec3::ZERO,
            DVec3::new(1.0, 0.2, 0.0),
            DVec3::new(0.8, 1.0, 0.0),
            DVec3::new(-1.0, -0.1, 0.0),
            DVec3::new(-0.7, -1.0, 0.0),
            DVec3::new(2.0, 0.0, 0.0),
            DVec3::new(3.0, 0.0, 0.0),
            DVec3::new(2.5, 1.0, 0.0),
            DVec3::new(2.5, -1.0, 0.3),
            DVec3::new(2.5, 0.0, 0.0),
            DVec3::new(2.5, 0.0, 1.0),
        ];
        let faces = vec![
            [0, 1, 2],
            [0, 3, 4],
            [1, 5, 2],
            [5, 6, 7],
            [6, 5, 8],
            [5, 6, 10],
            [5, 9, 7],
            [9, 6, 7],
            [5, 6, 9],
        ];
        let m = mesh(11, faces, p);
        assert_eq!(m.rings.kind(0), crate::mesh::FanKind::Irregular);
        assert_eq!(m.geometry.n_degenerate_faces, 1);
        for (k, h) in [0.1, 1.0, 30.0].into_iter().enumerate() {
            let u: Vec<DVec2> = (0..11)
                .map(|i| DVec2::new((i as f64 + k as f64).sin(), (2.0 * i as f64).cos()))
                .collect();
            let out = advect(&m, &u, h);
            assert!(out.iter().all(|v| v.is_finite()), "h = {h}: {out:?}");
            // interpolation never leaves the range of the (rotated) values
            let umax = u.iter().map(|v| v.length()).fold(0.0, f64::max);
            assert!(out.iter().all(|v| v.length() <= umax * (1.0 + 1e-12)));
            let flux = dual_fluxes(&m.t, &m.p, &m.frames, &u);
            assert!(flux.iter().all(|x| x.is_finite()));
            let plan = UpwindPlan::new(&m.t, &m.geometry.vertex_area, &flux, h).unwrap();
            let mut mass: Vec<f64> = (0..11).map(|i| 1.0 + i as f64).collect();
            let before = mass.clone();
            plan.transport(&m.t, &mut mass);
            assert!(mass.iter().all(|&x| x >= 0.0));
            let (s0, s1): (f64, f64) = (before.iter().sum(), mass.iter().sum());
            assert!((s1 - s0).abs() < 1e-14 * s0);
            let mom = plan.momentum_velocity(&m.t, &m.transport, &before, &u, &out);
            assert!(mom.iter().all(|v| v.is_finite()));
            // several fields at once: bit-identical to one by one
            let mut a: Vec<f64> = (0..11).map(|i| (i as f64 * 0.7).sin().abs()).collect();
            let mut b: Vec<f64> = (0..11).map(|i| 1e-9 * (i * i) as f64).collect();
            let (mut a1, mut b1) = (a.clone(), b.clone());
            plan.transport(&m.t, &mut a1);
            plan.transport(&m.t, &mut b1);
            plan.transport_all(&m.t, &mut [&mut a, &mut b]);
            assert_eq!(
                (a.clone(), b.clone()),
                (a1, b1),
                "h = {h}: transport_all differs from transport"
            );
            // the fields and the momentum in one pass: the same fields, the same velocities
            let mut solvent = before.clone();
            let mut c = b.clone();
            let fused = plan.transport_with_momentum(
                &m.t,
                &m.transport,
                &mut [&mut solvent, &mut c],
                &u,
                &out,
            );
            let (mut s1, mut c1) = (before.clone(), b.clone());
            plan.transport_all(&m.t, &mut [&mut s1, &mut c1]);
            assert_eq!((solvent, c), (s1, c1), "h = {h}: fused fields");
            assert_eq!(fused, mom, "h = {h}: fused momentum");
        }
    }

    #[test]
    fn bad_plan_parameters_are_named() {
        let t = Topology::from_triangles(3, vec![[0, 1, 2]]).unwrap();
        let area = [1.0; 3];
        let flux = [0.1, -0.2, 0.0];
        assert!(UpwindPlan::new(&t, &area, &flux, 0.1).is_ok());
        assert_eq!(
            UpwindPlan::new(&t, &area[..2], &flux, 0.1).unwrap_err(),
            ParamError::Length {
                name: "vertex_area",
                expected: 3,
                got: 2
            }
        );
        assert_eq!(
            UpwindPlan::new(&t, &area, &flux[..1], 0.1).unwrap_err(),
            ParamError::Length {
                name: "flux",
                expected: 3,
                got: 1
            }
        );
        assert!(matches!(
            UpwindPlan::new(&t, &area, &flux, -1.0),
            Err(ParamError::OutOfRange { name: "h", .. })
        ));
        assert!(matches!(
            UpwindPlan::new(&t, &area, &flux, f64::NAN),
            Err(ParamError::OutOfRange { name: "h", .. })
        ));
        assert_eq!(
            UpwindPlan::new(&t, &area, &[0.0, f64::INFINITY, 0.0], 0.1).unwrap_err(),
            ParamError::NonFinite {
                name: "flux",
                index: 1
            }
        );
        assert!(matches!(
            UpwindPlan::new(&t, &[1.0, -1.0, 1.0], &flux, 0.1),
            Err(ParamError::OutOfRange {
                name: "vertex_area",
                ..
            })
        ));
    }

    #[test]
    fn rough_atan2_is_within_its_bound_and_the_sector_test_keeps_every_containing_wedge() {
        use std::f64::consts::{PI, TAU};
        let mut worst = 0.0f64;
        for k in 0..200_000 {
            let t = -PI + TAU * (k as f64 + 0.5) / 200_000.0;
            for r in [1e-300, 1e-3, 1.0, 7.5e5] {
                let (y, x) = (r * t.sin(), r * t.cos());
                worst = worst.max(wrap_angle(rough_atan2(y, x) - y.atan2(x)).abs());
            }
        }
        assert!(worst < 1e-5, "rough atan2 off by {worst:e}");
        for (y, x) in [(0.0, 1.0), (0.0, -1.0), (1.0, 0.0), (-1.0, 0.0), (1.0, 1.0)] {
            assert!(
                (rough_atan2(y, x) - f64::atan2(y, x)).abs() < 1e-5,
                "({y}, {x})"
            );
        }
        // a direction inside a sector (by an independent test: the turn from a to psi
        // and from psi to b both counter-clockwise and below π) passes, in any turn of
        // the angles; one clearly outside fails
        let ccw = |from: f64, to: f64| {
            let (u, v) = ((from.cos(), from.sin()), (to.cos(), to.sin()));
            u.0 * v.1 - u.1 * v.0 >= 0.0 && u.0 * v.0 + u.1 * v.1 > -1.0
        };
        let (mut inside, mut outside) = (0, 0);
        for a_k in 0..24 {
            let a = -PI + a_k as f64 * 0.55;
            for open_k in 1..12 {
                let b = a + open_k as f64 * 0.27;
                for turn in [-TAU, 0.0, TAU] {
                    for psi_k in 0..97 {
                        let psi = wrap_angle(a - 0.4 + psi_k as f64 * 0.041);
                        let inner = ccw(a, psi) && ccw(psi, b) && ccw(a, b);
                        if inner {
                            inside += 1;
                            assert!(in_sector(psi, a + turn, b), "{psi} in ({a}, {b})");
                        }
                        let gap = wrap_angle(psi - a).min(wrap_angle(b - psi));
                        if gap < -2.0 * SECTOR_MARGIN && (b - a) < PI {
                            outside += 1;
                            assert!(!in_sector(psi, a, b + turn), "{psi} not in ({a}, {b})");
                        }
                    }
                }
            }
        }
        assert!(inside > 1000 && outside > 1000, "{inside} {outside}");
        assert!(!in_sector(f64::NAN, 0.0, 1.0) && !in_sector(0.5, 0.0, f64::NAN));
    }

    #[test]
    fn a_vertex_without_area_gives_all_it_has() {
        let t = Topology::from_triangles(3, vec![[0, 1, 2]]).unwrap();
        // edges (0,1), (0,2), (1,2): vertex 0 donates on both its edges, 1 to 2
        let plan = UpwindPlan::new(&t, &[0.0, 1.0, 1.0], &[1.0, 3.0, 0.5], 0.1).unwrap();
        assert_eq!(plan.n_limited(), 1);
        assert!(plan.max_courant().is_infinite());
        assert_eq!(plan.substeps(), 1);
        let mut mass = vec![2.0, 1.0, 0.0];
        plan.transport(&t, &mut mass);
        assert_eq!(mass[0], 0.0);
        assert!((mass[1] - (1.0 + 0.5 - 0.05)).abs() < 1e-15);
        assert!((mass[2] - (1.5 + 0.05)).abs() < 1e-15);
    }
}
