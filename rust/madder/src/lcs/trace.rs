//! Particle tracing on a (deforming) triangle mesh: the flow map `φ_{t0}^{t0+T}` of §5.2,
//! traced from every vertex as in §5.5.1.
//!
//! ## The particle and its charts
//! A particle is a point of the mesh, `(triangle, barycentric coordinates)`: material
//! coordinates, which move with the cloth when the mesh deforms. Its world position at time
//! `t` is `x = Σ_k b_k x_k(t)`, with the vertex positions `x_k(t)` interpolated linearly
//! between frames ([`Motion`]). The velocity `w(t, x)` ([`Velocity`]) is the fluid's
//! velocity *relative to the cloth*, a 3-D vector; in a triangle `(x_0, x_1, x_2)` at time
//! `t` it is taken as barycentric rates `(ḃ_1, ḃ_2)` by least squares,
//!
//! ```text
//! [E_1·E_1  E_1·E_2] [ḃ_1]   [E_1·w]
//! [E_1·E_2  E_2·E_2] [ḃ_2] = [E_2·w],      E_k = x_k(t) − x_0(t),
//! ```
//!
//! which is the tangent projection of `w` on the triangle's plane, pulled back to material
//! coordinates. Each triangle has a *chart*: its shape at `t0` laid in the plane, corner 0
//! at the origin, corner 1 on the `+x` axis, corner 2 above it (`c_1 = (|E_1|, 0)`,
//! `c_2 = (E_2·u, E_2·(n̂ × u))`, `u = E_1/|E_1|`); the particle's velocity in the chart is
//! `ḃ_1 c_1 + ḃ_2 c_2`. On a fixed mesh that is exactly the projected velocity; on a
//! deforming one it is the velocity seen from the cloth at `t0`, so the flow map is a map
//! of the surface at `t0` to itself, and the FTLE measures its stretching between the
//! surfaces at `t0` and `t0 + T` ([`super::ftle`](mod@super::ftle)). An isometric motion of the cloth
//! (bending without stretching) changes nothing.
//!
//! ## Crossing edges: unfolding
//! A displacement `d` from a particle is a straight segment in its triangle's chart. When
//! it leaves through an edge, the neighbouring triangle's chart is laid next to the current
//! one by the isometry (a rotation, or a reflection if the two faces' windings disagree)
//! that maps the shared edge onto itself, and the segment continues, as many triangles as
//! needed (computed in barycentric coordinates, below) ("following the strip", as the stain's back-trace does in `stain::advect`). The
//! orthogonal map between the charts carries the neighbour's velocity back into the first
//! chart: it is the discrete parallel transport across the edge (the face-to-face form of
//! the transport `R_ij` of eq. 4.4; on a flat or developable mesh it is the identity of the
//! plane, so the transport is exact). The walk stops at a border edge (the particle stays
//! on the border, sliding along it in later steps) or a non-manifold edge.
//!
//! A segment through a vertex leaves by either of the two edges at that vertex; the edge it
//! entered by is never its exit, so the walk turns around the vertex until it finds the
//! wedge that contains the direction.
//!
//! ## Integrator: explicit Runge–Kutta in the chart (RK4, order 4, or RK8, order 8)
//! With step `h = T / steps` and a scheme's tableau ([`super::rk`]: classical RK4 by
//! default, or DOP853's eighth-order solution) the stages are evaluated at
//! `y_i = p + h Σ_j a_ij k_j` from the particle `p`, each stage's velocity brought back
//! into `p`'s chart, and the particle moves to `p + h Σ_j b_j k_j`; for RK4 the stage points
//! are `p + h/2 k_1`, `p + h/2 k_2`, `p + h k_3` and the end `p + h (k_1 + 2k_2 + 2k_3 + k_4) / 6`.
//! Each of these points is walked to from an earlier stage point, the one nearest in time
//! (for RK4 the previous one), not from `p` (`y_i` is `y_{src(i)}` moved by
//! `h Σ_j (a_ij − a_{src(i),j}) k_j`, [`super::rk`], "Walking"): on a flat or developable
//! mesh the unfolded strip is the plane and the points are the same, but a step crosses
//! its edges about once (RK8: 1.11 times) instead of once per stage (the walks are most of
//! the cost). On a curved mesh
//! the unfolding, hence the point reached, depends on the path by the holonomy of the
//! vertices passed, a discretization error of the same order as the unfolding's. On a flat
//! mesh with a velocity that is smooth across the triangles this is the scheme itself,
//! global error `O(h⁴)` or `O(h⁸)` (`tests/ftle.rs`, `tests/rk8.rs` measure the orders).
//! Per-vertex velocities ([`VertexVelocity`]) are linear in each triangle and continuous,
//! but their derivative jumps across edges: the error there is limited by the mesh,
//! `O(Δx²)`, whatever the scheme.
//!
//! Every stage is evaluated for all particles at once ([`Velocity::eval`] gets the batch),
//! which is what lets a Python callable be called once per stage. The walks run in
//! parallel, each particle writing its own slot: results do not depend on the number of
//! threads.
//!
//! ## The walk in barycentric coordinates
//! The unfolding is an isometry of the plane, so it keeps affine combinations: laid next to
//! face `f` across its edge `k` (corners `k + 1`, `k + 2` shared), the neighbour's far
//! corner is a fixed point of `f`'s chart, `G = γ_k c_k + γ_{k+1} c_{k+1} + γ_{k+2} c_{k+2}`
//! (`γ_k < 0`, `Σγ = 1`), precomputed per face and edge ([`Hop`]). A point with
//! coordinates `β` in `f` then has, in the neighbour,
//!
//! ```text
//! β_G = β_k / γ_k,   β_{k+1}' = β_{k+1} − β_k γ_{k+1}/γ_k,   β_{k+2}' = β_{k+2} − β_k γ_{k+2}/γ_k,
//! ```
//!
//! three multiplications and two subtractions, exact up to rounding. A walk carries the
//! segment's two ends `p` (its start) and `q` (its target) in the current face's
//! barycentric coordinates: `q` inside (all coordinates `≥ −10⁻¹²`) ends the walk; else the
//! exit is the edge, other than the entry, with `q_k < 0` that the line meets first, the
//! least `p_k / (p_k − q_k)`, compared by cross-multiplying (both denominators are
//! positive), so a crossing divides nothing. The orthogonal map back to the start chart is
//! composed from each edge's (stored, `[[a, −σb], [b, σa]]`). A border edge stops the walk
//! where the segment meets it (the one division). This replaced a walk that mapped the
//! target into each face's chart through the composed unfolding and solved for its
//! barycentric coordinates (two divisions, a matrix product and a normalisation per
//! crossing); the FTLE of the curved 100k-vertex bench differs from it by at most
//! 4·10⁻¹³ (rounding), the flat path's by 1.2·10⁻¹².
//!
//! ## Memory
//! The walks are most of the time on a curved mesh, and they are chains of dependent reads
//! (the next face is known only once the current face's record is read). So: one 128-byte
//! record per face holds everything a crossing reads ([`Hop`]: the two coefficients `1/γ_k`,
//! `γ_{k+1}/γ_k` and the map per edge, the neighbours, how their corners line up, and the
//! face's vertices); the faces are stored in the Morton order of their centroids, so faces
//! near in space are near in memory ([`space_filling_order`]); the particles are sorted by
//! face every 16 stage walks or so (every 4 RK4 steps, every RK8 step: a similar time for
//! them to scatter; sorting every 4 RK8 steps was 8% slower on the curved bench), so
//! consecutive walks share faces; and two particles are walked a
//! crossing each in turn ([`Charts::walk_pair`]), so their reads overlap. A stage point's
//! face frame (corner, edges, chart axes) is computed from its three vertices rather than
//! stored: a stored frame was a cache miss per stage point, the vertices a small array;
//! the vertices of each face entered are read at the crossing, which starts the read of
//! its record before the crossing's arithmetic is done.
//! None of this changes a value: each particle's arithmetic is its own, in the same order.
//! Faces keep their input numbers outside (a [`Located`] names the input's face).
//!
//! ## Fast paths
//! On a fixed mesh a stage's world point and chart velocity are a few dot products with
//! the face's frame (no 2×2 solve), and per particle the map from a displacement in its
//! chart to barycentric rates at its stage point is kept for the next walk. On a flat
//! fixed mesh the walks themselves are skipped where they are provably straight
//! ([`super::planar`]); the results agree with the walks up to rounding (tested).

use glam::{DMat2, DVec2, DVec3};
use rayon::prelude::*;

use super::planar::{Planar, flow_map_planar};
use super::rk::{Moves, Scheme, two};
use crate::error::{LcsError, MeshError};
use crate::mesh::Topology;
use crate::mesh::geometry::check_positions;

/// Most edges one walk crosses before it stops (only reached by a step of hundreds of
/// edge lengths).
pub(crate) const MAX_CROSSINGS: usize = 1000;

/// Barycentric coordinates above `−BARY_TOLERANCE` count as inside a triangle.
const BARY_TOLERANCE: f64 = 1e-12;

/// A point of the mesh: a triangle and barycentric coordinates in it (summing to 1).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Located {
    /// The triangle.
    pub face: u32,
    /// Barycentric coordinates of its corners `0, 1, 2`.
    pub bary: DVec3,
}

/// Frame times: finite, strictly increasing.
#[derive(Debug, Clone, PartialEq)]
pub struct FrameTimes(Vec<f64>);

impl FrameTimes {
    /// Checks the times, naming the first bad entry.
    pub fn new(times: Vec<f64>) -> Result<Self, LcsError> {
        for (i, &t) in times.iter().enumerate() {
            if !t.is_finite() || (i > 0 && t <= times[i - 1]) {
                return Err(LcsError::FrameTimes { index: i, value: t });
            }
        }
        if times.is_empty() {
            return Err(LcsError::Shape {
                name: "times".into(),
                expected: "at least one frame time".into(),
                got: "(0,)".into(),
            });
        }
        Ok(Self(times))
    }

    /// The times.
    pub fn times(&self) -> &[f64] {
        &self.0
    }

    /// The frame `k` and weight `s` with `t = (1 − s) t_k + s t_{k+1}` (`k + 1` clamped to
    /// the last frame); an error if `t` is outside the frames (beyond rounding).
    pub fn locate(&self, t: f64) -> Result<(usize, f64), LcsError> {
        let ts = &self.0;
        let (first, last) = (ts[0], ts[ts.len() - 1]);
        let slack = 1e-9 * (last - first).abs().max(t.abs()).max(1.0);
        if !(t >= first - slack && t <= last + slack) {
            return Err(LcsError::TimeOutOfRange {
                time: t,
                first,
                last,
            });
        }
        if ts.len() == 1 {
            return Ok((0, 0.0));
        }
        let k = ts.partition_point(|&x| x <= t).clamp(1, ts.len() - 1) - 1;
        let s = ((t - ts[k]) / (ts[k + 1] - ts[k])).clamp(0.0, 1.0);
        Ok((k, s))
    }
}

/// The mesh's vertex positions over time: one frame (a fixed mesh) or frames at given
/// times, linearly interpolated between them.
#[derive(Debug, Clone)]
pub struct Motion {
    times: Option<FrameTimes>,
    frames: Vec<Vec<DVec3>>,
}

impl Motion {
    /// A mesh that does not move.
    pub fn fixed(positions: Vec<DVec3>) -> Self {
        Self {
            times: None,
            frames: vec![positions],
        }
    }

    /// A deforming mesh: `frames[k]` are the positions at `times[k]`.
    pub fn frames(times: FrameTimes, frames: Vec<Vec<DVec3>>) -> Result<Self, LcsError> {
        if frames.len() != times.times().len() {
            return Err(LcsError::Shape {
                name: "positions".into(),
                expected: format!("{} frames (one per frame time)", times.times().len()),
                got: format!("{} frames", frames.len()),
            });
        }
        Ok(Self {
            times: Some(times),
            frames,
        })
    }

    /// Checks every frame against the topology (count, finiteness; names frame and vertex).
    pub(crate) fn check(&self, topology: &Topology) -> Result<(), LcsError> {
        for frame in &self.frames {
            check_positions(topology, frame)?;
        }
        Ok(())
    }

    /// Where to read the positions at time `t`.
    pub(crate) fn at(&self, t: f64) -> Result<Lerp, LcsError> {
        Ok(match &self.times {
            None => Lerp { k: 0, s: 0.0 },
            Some(times) => {
                let (k, s) = times.locate(t)?;
                Lerp { k, s }
            }
        })
    }

    /// The position of vertex `v` at `at`.
    pub(crate) fn position(&self, at: Lerp, v: usize) -> DVec3 {
        let a = self.frames[at.k][v];
        if at.s == 0.0 {
            return a;
        }
        a.lerp(self.frames[(at.k + 1).min(self.frames.len() - 1)][v], at.s)
    }

    /// Whether the mesh does not move (one frame).
    pub(crate) fn is_fixed(&self) -> bool {
        self.frames.len() == 1
    }

    /// All positions at time `t`.
    pub(crate) fn positions(&self, t: f64) -> Result<Vec<DVec3>, LcsError> {
        let at = self.at(t)?;
        Ok((0..self.frames[0].len())
            .map(|v| self.position(at, v))
            .collect())
    }
}

/// A frame index and the weight of the next frame.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Lerp {
    k: usize,
    s: f64,
}

/// A velocity field on the mesh: the fluid's 3-D velocity relative to the cloth.
pub trait Velocity {
    /// Writes the velocity at time `t` at every point into `out`: the point on the mesh
    /// `at[i]` whose world position is `points[i]` (`at` may be empty if
    /// [`Self::uses_location`] is `false`).
    fn eval(
        &mut self,
        t: f64,
        at: &[Located],
        points: &[DVec3],
        out: &mut [DVec3],
    ) -> Result<(), LcsError>;

    /// Whether [`Self::eval`] reads `at` (the points' triangles); a velocity of world
    /// points alone returns `false`, which lets a flat mesh skip locating the points
    /// ([`super::planar`]).
    fn uses_location(&self) -> bool {
        true
    }
}

/// [`Velocity::eval`] at the stage points of the particles from vertices `live`, refusing a
/// non-finite value with an error naming the point and its vertex (shared by the walking
/// and the planar tracer).
pub(crate) fn eval_checked(
    velocity: &mut dyn Velocity,
    t: f64,
    at: &[Located],
    points: &[DVec3],
    live: &[usize],
    out: &mut [DVec3],
) -> Result<(), LcsError> {
    velocity.eval(t, at, points, out)?;
    match out.iter().position(|u| !u.is_finite()) {
        None => Ok(()),
        Some(i) => Err(LcsError::NonFiniteVelocity {
            at: format!(
                "point ({}, {}, {}) (the particle from vertex {})",
                points[i].x, points[i].y, points[i].z, live[i]
            ),
            time: t,
        }),
    }
}

/// An analytic velocity `f(t, x)` of world position (evaluated in parallel).
pub struct FnVelocity<F>(pub F);

impl<F: Fn(f64, DVec3) -> DVec3 + Sync> Velocity for FnVelocity<F> {
    fn eval(
        &mut self,
        t: f64,
        _at: &[Located],
        points: &[DVec3],
        out: &mut [DVec3],
    ) -> Result<(), LcsError> {
        out.par_iter_mut()
            .zip(points)
            .for_each(|(o, &x)| *o = (self.0)(t, x));
        Ok(())
    }

    fn uses_location(&self) -> bool {
        false
    }
}

/// Per-vertex velocities per frame, linear in time between frames and linear in each
/// triangle (barycentric interpolation), e.g. the stain simulator's baked velocity.
#[derive(Debug, Clone)]
pub struct VertexVelocity {
    times: FrameTimes,
    frames: Vec<Vec<DVec3>>,
    faces: Vec<[u32; 3]>,
}

impl VertexVelocity {
    /// `frames[k][v]`: the velocity of vertex `v` of `topology` at `times[k]`. Checks the
    /// shape and that every value is finite (naming vertex and frame time).
    pub fn new(
        times: FrameTimes,
        frames: Vec<Vec<DVec3>>,
        topology: &Topology,
    ) -> Result<Self, LcsError> {
        let n_vertices = topology.n_vertices();
        let k = times.times().len();
        if frames.len() != k || frames.iter().any(|f| f.len() != n_vertices) {
            let got = frames.iter().map(Vec::len).find(|&l| l != n_vertices);
            return Err(LcsError::Shape {
                name: "velocity".into(),
                expected: format!("({k}, {n_vertices}, 3)"),
                got: format!("({}, {}, 3)", frames.len(), got.unwrap_or(n_vertices)),
            });
        }
        for (f, frame) in frames.iter().enumerate() {
            if let Some(v) = frame.iter().position(|u| !u.is_finite()) {
                return Err(LcsError::NonFiniteVelocity {
                    at: format!("vertex {v}"),
                    time: times.times()[f],
                });
            }
        }
        Ok(Self {
            times,
            frames,
            faces: topology.faces().to_vec(),
        })
    }
}

impl VertexVelocity {
    /// The frames' times.
    pub fn times(&self) -> &[f64] {
        self.times.times()
    }
}

impl Velocity for VertexVelocity {
    fn eval(
        &mut self,
        t: f64,
        at: &[Located],
        _points: &[DVec3],
        out: &mut [DVec3],
    ) -> Result<(), LcsError> {
        let (k, s) = self.times.locate(t)?;
        let k1 = (k + 1).min(self.frames.len() - 1);
        let (a, b) = (&self.frames[k], &self.frames[k1]);
        out.par_iter_mut().zip(at).for_each(|(o, l)| {
            let tri = self.faces[l.face as usize];
            *o = (0..3)
                .map(|c| l.bary[c] * a[tri[c] as usize].lerp(b[tri[c] as usize], s))
                .sum();
        });
        Ok(())
    }
}

/// A face's chart and neighbours: what the walks' records ([`Hop`]) are built from, and
/// what a walk from a chart displacement ([`Charts::walk`]) reads at its start.
#[derive(Debug, Clone, Copy)]
struct FaceChart {
    /// `(c_1.x, c_2.x, c_2.y)` (`c_0` at the origin, `c_1.y = 0`); all zero for a
    /// degenerate face.
    chart: [f64; 3],
    /// The corners' vertices.
    verts: [u32; 3],
    /// The face across the edge opposite corner `k` (`u32::MAX` on a border or
    /// non-manifold edge) ...
    nbr: [u32; 3],
    /// ... and that edge's local index in it.
    nbr_edge: [u8; 3],
}

/// How the chart of the face across an edge lies in a face's chart (the unfolding), and
/// which of its corners are the edge's ends (in the face's order `k + 1`, `k + 2`); only
/// while the records [`Hop`] are built.
#[derive(Debug, Clone, Copy)]
struct Link {
    rot: DMat2,
    shift: DVec2,
    corners: [u8; 2],
}

/// What a walk reads of a face it crosses into, in one 128-byte record (module doc,
/// "The walk in barycentric coordinates"): per edge `k` (opposite corner `k`) the
/// neighbour's far corner in this face's barycentric coordinates, the orthogonal map of
/// the neighbour's chart into this one, the neighbour and how its corners line up.
#[derive(Debug, Clone, Copy)]
#[repr(C, align(128))]
struct Hop {
    /// `(1/γ_k, γ_{k+1}/γ_k)` for the neighbour's far corner `G = Σ_m γ_m c_m` (`γ_k < 0`;
    /// `γ_{k+2}/γ_k = 1/γ_k − 1 − γ_{k+1}/γ_k`).
    far: [[f64; 2]; 3],
    /// The first column `(a, b)` of the orthogonal map of the neighbour's chart into this
    /// face's; the second is `σ (−b, a)`, `σ = −1` for a reflection (bit 4 of `code`).
    rot: [[f64; 2]; 3],
    /// The neighbour across edge `k` (`NONE`: border, non-manifold edge, or a degenerate
    /// neighbour, where a walk stops).
    nbr: [u32; 3],
    /// Bits 0–1: the edge's index `l` in the neighbour (its far corner); bits 2–3: the
    /// neighbour's corner at this face's corner `k + 1`; bit 4: the map is a reflection.
    code: [u8; 3],
    /// The face's vertices: what the stage point where a walk ends needs.
    corners: Corners,
}

/// A face's vertices and whether it is degenerate (no chart): what its frame in space is
/// computed from ([`Charts::frame_of`]).
#[derive(Debug, Clone, Copy)]
struct Corners {
    verts: [u32; 3],
    degenerate: bool,
}

/// An orthogonal map of the plane `[[a, −σb], [b, σa]]` (a rotation, or a reflection for
/// `σ = −1`), as a walk composes them.
#[derive(Debug, Clone, Copy)]
struct Orth {
    a: f64,
    b: f64,
    sigma: f64,
}

impl Orth {
    const IDENTITY: Self = Self {
        a: 1.0,
        b: 0.0,
        sigma: 1.0,
    };

    /// `self ∘ (a, b, σ)`.
    fn then(self, [a, b]: [f64; 2], sigma: f64) -> Self {
        Self {
            a: self.a * a - self.sigma * self.b * b,
            b: self.b * a + self.sigma * self.a * b,
            sigma: self.sigma * sigma,
        }
    }

    fn mat(self) -> DMat2 {
        DMat2::from_cols(
            DVec2::new(self.a, self.b),
            self.sigma * DVec2::new(-self.b, self.a),
        )
    }
}

/// `(k + 1) % 3`, `(k + 2) % 3`.
const NEXT: [usize; 3] = [1, 2, 0];
const PREV: [usize; 3] = [2, 0, 1];

/// The triangles' charts at `t0` and their neighbours: what the walks need.
#[derive(Debug, Clone)]
pub struct Charts {
    face: Vec<FaceChart>,
    /// The input's face of each face here (the faces are stored in a space-filling order,
    /// module doc, "Memory"), and the inverse permutation.
    order: Vec<u32>,
    rank: Vec<u32>,
    /// Per face, what a walk crossing into it reads.
    hop: Vec<Hop>,
    /// A face at every vertex and the vertex's corner in it (`u32::MAX` for a loose vertex).
    vertex_face: Vec<(u32, u8)>,
    /// The flat mesh's plane and buckets, if the mesh is flat ([`super::planar`]).
    planar: Option<Planar>,
    /// The vertices at `t0`: a fixed mesh's faces in space ([`Self::frame`]).
    start: Vec<DVec3>,
}

/// A face at `t0` in space: corner 0, the edges `E_1`, `E_2`, and the chart's axes `u`,
/// `n̂ × u` (unit, in the face's plane). On a fixed mesh the world point of barycentric
/// `b` is `x_0 + b_1 E_1 + b_2 E_2` and the chart velocity of `w` (module doc) is
/// `(u·w, (n̂ × u)·w)`, the tangent projection in the chart's orthonormal axes: the same
/// as the least-squares rates `ḃ` mapped by `c_1, c_2`, without the 2×2 solve.
#[derive(Debug, Clone, Copy)]
struct FaceFrame {
    x0: DVec3,
    e1: DVec3,
    e2: DVec3,
    u: DVec3,
    v: DVec3,
}

impl FaceFrame {
    /// The map of a displacement `d` in a chart that `rot` maps this face's chart into, to
    /// barycentric rates `(ḃ_1, ḃ_2)` here: `ḃ_2 = d'_y / c_{2,y}`,
    /// `ḃ_1 = (d'_x − ḃ_2 c_{2,x}) / c_{1,x}` of `d' = rotᵀ d` (zero on a degenerate face,
    /// where a walk does not move).
    fn bary_map(&self, rot: DMat2) -> DMat2 {
        let c1x = self.e1.dot(self.u);
        if c1x == 0.0 {
            return DMat2::ZERO;
        }
        let (c2x, c2y) = (self.e2.dot(self.u), self.e2.dot(self.v));
        let (i1, i2) = (1.0 / c1x, 1.0 / c2y);
        // rows (ḃ_1, ḃ_2) of [[1/c1x, −c2x/(c1x c2y)], [0, 1/c2y]]
        let local = DMat2::from_cols(DVec2::new(i1, 0.0), DVec2::new(-c2x * i1 * i2, i2));
        local * rot.transpose()
    }
}

/// The barycentric displacement `(−ḃ_1 − ḃ_2, ḃ_1, ḃ_2)` of `d` by the map `to_bary`.
fn bary_step(to_bary: DMat2, d: DVec2) -> DVec3 {
    let b = to_bary * d;
    DVec3::new(-b.x - b.y, b.x, b.y)
}

/// No neighbour (border or non-manifold edge) / no face (loose vertex).
const NONE: u32 = u32::MAX;

impl Charts {
    /// Charts of `topology` at `positions` (the shape at `t0`).
    pub fn new(topology: &Topology, positions: &[DVec3]) -> Result<Self, MeshError> {
        check_positions(topology, positions)?;
        let order = space_filling_order(topology.faces(), positions);
        let mut rank = vec![0u32; order.len()];
        for (i, &f) in order.iter().enumerate() {
            rank[f as usize] = i as u32;
        }
        // the faces in the walks' order (module doc, "Memory")
        let faces: Vec<[u32; 3]> = order
            .iter()
            .map(|&f| topology.faces()[f as usize])
            .collect();
        let faces = &faces[..];
        let chart: Vec<[f64; 3]> = faces
            .par_iter()
            .map(|tri| {
                let [x0, x1, x2] = tri.map(|v| positions[v as usize]);
                let (e1, e2) = (x1 - x0, x2 - x0);
                let (l1, n) = (e1.length(), e1.cross(e2));
                if l1 == 0.0 || n.length() <= 1e-14 * l1 * e2.length() {
                    return [0.0; 3];
                }
                let u = e1 / l1;
                let w = n.normalize().cross(u);
                [l1, e2.dot(u), e2.dot(w)]
            })
            .collect();
        // per edge: its first two (face, local edge) and how many faces it has (flat
        // arrays, not a list per edge: this runs on every call)
        let mut edge_faces = vec![[(NONE, 0u8); 2]; topology.n_edges()];
        let mut edge_count = vec![0u8; topology.n_edges()];
        for (f, fe) in topology.face_edges().iter().enumerate() {
            for (k, &e) in fe.iter().enumerate() {
                let c = &mut edge_count[e as usize];
                if *c < 2 {
                    edge_faces[e as usize][*c as usize] = (rank[f], k as u8);
                }
                *c = c.saturating_add(1);
            }
        }
        let mut neighbour = vec![[(NONE, 0u8); 3]; faces.len()];
        for (pair, _) in edge_faces.iter().zip(&edge_count).filter(|(_, c)| **c == 2) {
            let [(f, k), (g, l)] = *pair;
            neighbour[f as usize][k as usize] = (g, l);
            neighbour[g as usize][l as usize] = (f, k);
        }
        // at each vertex its first face in the input's order (the order changes no result)
        let mut vertex_face = vec![(NONE, 0u8); topology.n_vertices()];
        for (f, tri) in topology.faces().iter().enumerate().rev() {
            for (c, &v) in tri.iter().enumerate() {
                vertex_face[v as usize] = (rank[f], c as u8);
            }
        }
        let face = (0..faces.len())
            .map(|f| FaceChart {
                chart: chart[f],
                verts: faces[f],
                nbr: neighbour[f].map(|n| n.0),
                nbr_edge: neighbour[f].map(|n| n.1),
            })
            .collect();
        let mut charts = Self {
            face,
            order,
            rank,
            hop: Vec::new(),
            vertex_face,
            planar: None,
            start: positions.to_vec(),
        };
        // the hop records and the flat path's buckets are independent: built side by side
        let flat = charts.face.iter().all(|f| f.chart[0] != 0.0);
        let (hop, planar) = rayon::join(
            || {
                (0..faces.len())
                    .into_par_iter()
                    .map(|f| charts.hop_of(f))
                    .collect()
            },
            || flat.then(|| Planar::new(topology, positions)).flatten(),
        );
        charts.hop = hop;
        charts.planar = planar;
        Ok(charts)
    }

    /// The same charts without the flat mesh's fast path: every stage point is walked
    /// (for comparing the two; the results agree up to rounding).
    pub fn walk_everywhere(mut self) -> Self {
        self.planar = None;
        self
    }

    /// Whether the mesh is flat and takes the fast path of [`super::planar`].
    pub fn is_flat(&self) -> bool {
        self.planar.is_some()
    }

    /// The vertices of face `f`.
    pub(crate) fn face_verts(&self, f: usize) -> [u32; 3] {
        self.face[self.rank[f] as usize].verts
    }

    /// The unfolding of the neighbour across edge `k` of face `f` into `f`'s chart.
    fn link_across(&self, f: usize, k: usize) -> Link {
        let here = &self.face[f];
        let (g, l) = (here.nbr[k], here.nbr_edge[k] as usize);
        if g == NONE {
            return Link {
                rot: DMat2::IDENTITY,
                shift: DVec2::ZERO,
                corners: [0, 0],
            };
        }
        let (a, b) = (here.verts[(k + 1) % 3], here.verts[(k + 2) % 3]);
        let tg = self.face[g as usize].verts;
        let corner_in_g = |v: u32| (0..3).find(|&m| tg[m] == v).unwrap_or(0);
        let (ga, gb) = (corner_in_g(a), corner_in_g(b));
        let cf = self.corners(f);
        let cg = self.corners(g as usize);
        let (rot, shift) = unfold(
            cf[(k + 1) % 3],
            cf[(k + 2) % 3],
            cf[k],
            cg[ga],
            cg[gb],
            cg[l],
        );
        Link {
            rot,
            shift,
            corners: [ga as u8, gb as u8],
        }
    }

    /// The record [`Hop`] of face `f`, from the unfoldings of its neighbours.
    fn hop_of(&self, f: usize) -> Hop {
        let mut hop = Hop {
            far: [[0.0; 2]; 3],
            rot: [[1.0, 0.0]; 3],
            nbr: [NONE; 3],
            code: [0; 3],
            corners: Corners {
                verts: self.face[f].verts,
                degenerate: self.face[f].chart[0] == 0.0,
            },
        };
        for k in 0..3 {
            let here = &self.face[f];
            let (g, l) = (here.nbr[k], here.nbr_edge[k] as usize);
            if g == NONE || here.chart[0] == 0.0 || self.face[g as usize].chart[0] == 0.0 {
                continue;
            }
            let link = self.link_across(f, k);
            let far = link.rot * self.corners(g as usize)[l] + link.shift;
            let Some(gamma) = self.bary(f, far) else {
                continue;
            };
            if gamma[k] >= 0.0 || !gamma.is_finite() {
                // the neighbour folded onto this face: no unfolding to walk through
                continue;
            }
            let r = 1.0 / gamma[k];
            hop.far[k] = [r, gamma[NEXT[k]] * r];
            hop.rot[k] = [link.rot.x_axis.x, link.rot.x_axis.y];
            let reflect = link.rot.determinant() < 0.0;
            hop.nbr[k] = g;
            hop.code[k] = l as u8 | (link.corners[0] << 2) | (u8::from(reflect) << 4);
        }
        hop
    }

    /// Face `f` at `t0` in space ([`FaceFrame`]), from its vertices: computed where it is
    /// needed rather than stored, since a stored frame per face is a cache miss per stage
    /// point while the vertices are few and the walk has just read the face's [`Hop`].
    fn frame(&self, f: usize) -> FaceFrame {
        self.frame_of(self.hop[f].corners)
    }

    /// [`Self::frame`] of the face with these corners.
    fn frame_of(&self, c: Corners) -> FaceFrame {
        let [x0, x1, x2] = c.verts.map(|v| self.start[v as usize]);
        let (e1, e2) = (x1 - x0, x2 - x0);
        let (u, v) = if c.degenerate {
            (DVec3::ZERO, DVec3::ZERO)
        } else {
            let u = e1 / e1.length();
            (u, e1.cross(e2).normalize().cross(u))
        };
        FaceFrame { x0, e1, e2, u, v }
    }

    /// The corners of face `f` in its chart.
    fn corners(&self, f: usize) -> [DVec2; 3] {
        let [a, b, c] = self.face[f].chart;
        [DVec2::ZERO, DVec2::new(a, 0.0), DVec2::new(b, c)]
    }

    /// Barycentric coordinates of chart point `p` in face `f` (`None` if degenerate).
    fn bary(&self, f: usize, p: DVec2) -> Option<DVec3> {
        let [a, b, c] = self.face[f].chart;
        if a == 0.0 {
            return None;
        }
        let b2 = p.y / c;
        let b1 = (p.x - b2 * b) / a;
        Some(DVec3::new(1.0 - b1 - b2, b1, b2))
    }

    /// The particle that starts at vertex `v` (`None` for a loose vertex).
    pub fn at_vertex(&self, v: usize) -> Option<Located> {
        self.at_vertex_here(v).map(|l| self.outside(&l))
    }

    /// [`Self::at_vertex`] with the face's index here.
    fn at_vertex_here(&self, v: usize) -> Option<Located> {
        let (f, c) = self.vertex_face[v];
        (f != NONE).then(|| {
            let mut bary = DVec3::ZERO;
            bary[c as usize] = 1.0;
            Located { face: f, bary }
        })
    }

    /// The world position of `l` at `at`.
    pub(crate) fn world(&self, motion: &Motion, at: Lerp, l: &Located) -> DVec3 {
        self.world_here(motion, at, &self.here(l))
    }

    /// [`Self::world`] with the face's index here.
    fn world_here(&self, motion: &Motion, at: Lerp, l: &Located) -> DVec3 {
        if motion.is_fixed() {
            let f = &self.frame(l.face as usize);
            return f.x0 + l.bary.y * f.e1 + l.bary.z * f.e2;
        }
        let tri = self.face[l.face as usize].verts;
        (0..3)
            .map(|c| l.bary[c] * motion.position(at, tri[c] as usize))
            .sum()
    }

    /// The velocity `w` at `l` (time `at`) in the chart of `l`'s face (module doc).
    fn chart_velocity(&self, motion: &Motion, at: Lerp, l: &Located, w: DVec3) -> DVec2 {
        let f = l.face as usize;
        if motion.is_fixed() {
            let fr = &self.frame(f);
            return DVec2::new(fr.u.dot(w), fr.v.dot(w));
        }
        let tri = self.face[f].verts;
        let [x0, x1, x2] = tri.map(|v| motion.position(at, v as usize));
        let (e1, e2) = (x1 - x0, x2 - x0);
        let (g11, g12, g22) = (e1.dot(e1), e1.dot(e2), e2.dot(e2));
        let det = g11 * g22 - g12 * g12;
        if self.face[f].chart[0] == 0.0 || det <= 1e-24 * g11 * g22 {
            return DVec2::ZERO;
        }
        let (r1, r2) = (e1.dot(w), e2.dot(w));
        let b1 = (g22 * r1 - g12 * r2) / det;
        let b2 = (g11 * r2 - g12 * r1) / det;
        let [_, c1, c2] = self.corners(f);
        b1 * c1 + b2 * c2
    }

    /// Walks the straight segment `d` (in the chart of `start`'s face) from `start` across
    /// edges (module doc). Returns where it ends and the orthogonal map from the end face's
    /// chart to the start face's chart.
    pub(crate) fn walk(&self, start: &Located, d: DVec2) -> (Located, DMat2) {
        let (end, rot) = self.walk_here(&self.here(start), d);
        (self.outside(&end), rot)
    }

    /// `l` (a face of the input) with the face's index here.
    fn here(&self, l: &Located) -> Located {
        Located {
            face: self.rank[l.face as usize],
            bary: l.bary,
        }
    }

    /// `l` with the input's face index.
    fn outside(&self, l: &Located) -> Located {
        Located {
            face: self.order[l.face as usize],
            bary: l.bary,
        }
    }

    /// [`Self::walk`] with faces indexed here.
    fn walk_here(&self, start: &Located, d: DVec2) -> (Located, DMat2) {
        let [a, b, c] = self.face[start.face as usize].chart;
        if a == 0.0 {
            return (
                Located {
                    face: start.face,
                    bary: clamp(start.bary),
                },
                DMat2::IDENTITY,
            );
        }
        let d2 = d.y / c;
        let d1 = (d.x - d2 * b) / a;
        let (end, rot, _) = self.walk_bary(start, DVec3::new(-d1 - d2, d1, d2));
        (end, rot.mat())
    }

    /// The walk from `start` by the barycentric displacement `delta` (summing to 0), in
    /// barycentric coordinates (module doc): returns where it ends and the orthogonal map
    /// from the end face's chart to the start face's.
    fn walk_bary(&self, start: &Located, delta: DVec3) -> (Located, Orth, Corners) {
        match self.walk_start(start, delta) {
            Err(end) => end,
            Ok(mut w) => loop {
                if let Some(end) = self.walk_cross(&mut w) {
                    return end;
                }
            },
        }
    }

    /// Two walks ([`Self::walk_bary`]) taken a crossing each in turn: each crossing waits
    /// for the next face's record, and the two chains of reads overlap (module doc,
    /// "Memory"). The results are those of the walks taken one by one.
    fn walk_pair(
        &self,
        (sa, da): (&Located, DVec3),
        (sb, db): (&Located, DVec3),
    ) -> [(Located, Orth, Corners); 2] {
        let mut a = self.walk_start(sa, da);
        let mut b = self.walk_start(sb, db);
        loop {
            match (&mut a, &mut b) {
                (Ok(wa), Ok(wb)) => {
                    let ea = self.walk_cross(wa);
                    let eb = self.walk_cross(wb);
                    if let Some(e) = ea {
                        a = Err(e);
                    }
                    if let Some(e) = eb {
                        b = Err(e);
                    }
                }
                (Ok(w), Err(_)) => {
                    if let Some(e) = self.walk_cross(w) {
                        a = Err(e);
                    }
                }
                (Err(_), Ok(w)) => {
                    if let Some(e) = self.walk_cross(w) {
                        b = Err(e);
                    }
                }
                (Err(ea), Err(eb)) => return [*ea, *eb],
            }
        }
    }

    /// The start of a walk: its end if it stays in the start face, else the walk about to
    /// cross the first edge it meets.
    fn walk_start(&self, start: &Located, delta: DVec3) -> Result<Walk, (Located, Orth, Corners)> {
        let (p, q) = (start.bary, start.bary + delta);
        let corners = self.hop[start.face as usize].corners;
        if q.min_element() >= -BARY_TOLERANCE {
            return Err((
                Located {
                    face: start.face,
                    bary: clamp(q),
                },
                Orth::IDENTITY,
                corners,
            ));
        }
        // exit edge: the first one the line p → q crosses outward, the least
        // `p_k / (p_k − q_k)` over `q_k < 0`, compared without dividing
        let mut k = 3usize;
        for c in 0..3 {
            if q[c] < -BARY_TOLERANCE && (k == 3 || p[c] * (p[k] - q[k]) < p[k] * (p[c] - q[c])) {
                k = c;
            }
        }
        let (k1, k2) = (NEXT[k], PREV[k]);
        Ok(Walk {
            face: start.face as usize,
            k,
            pk: [p[k], p[k1], p[k2]],
            qk: [q[k], q[k1], q[k2]],
            rot: Orth::IDENTITY,
            left: MAX_CROSSINGS,
            corners,
        })
    }

    /// One crossing of walk `w` (over its edge `k`); its end if it ends in the face
    /// entered, at a border, or stops.
    fn walk_cross(&self, w: &mut Walk) -> Option<(Located, Orth, Corners)> {
        let k = w.k;
        let (pk, qk) = (w.pk, w.qk);
        let hop = &self.hop[w.face];
        let g = hop.nbr[k];
        if g == NONE || w.left == 0 {
            // a border (or too many crossings): stop where the segment meets the edge
            let t = pk[0] / (pk[0] - qk[0]);
            let cross = [
                0.0,
                pk[1] + t * (qk[1] - pk[1]),
                pk[2] + t * (qk[2] - pk[2]),
            ];
            return Some((
                Located {
                    face: w.face as u32,
                    bary: clamp(unrotate(cross, k)),
                },
                w.rot,
                w.corners,
            ));
        }
        w.left -= 1;
        // read now, used where the walk ends: the read of the next face's record starts
        // while this crossing's arithmetic runs
        w.corners = self.hop[g as usize].corners;
        let code = hop.code[k];
        let l = (code & 3) as usize;
        let [r, ra] = hop.far[k];
        let rb = r - 1.0 - ra;
        let (pa, pb) = (pk[1] - pk[0] * ra, pk[2] - pk[0] * rb);
        let (qa, qb) = (qk[1] - qk[0] * ra, qk[2] - qk[0] * rb);
        // the coordinates at corners l, l + 1, l + 2 of the face entered by its edge l;
        // corner k + 1 here is corner l + 1 there if the windings disagree
        let (px, qx) = if (code >> 2) & 3 == NEXT[l] as u8 {
            ([pk[0] * r, pa, pb], [qk[0] * r, qa, qb])
        } else {
            ([pk[0] * r, pb, pa], [qk[0] * r, qb, qa])
        };
        w.rot = w
            .rot
            .then(hop.rot[k], if code & 16 != 0 { -1.0 } else { 1.0 });
        w.face = g as usize;
        let (in1, in2) = (qx[1] >= -BARY_TOLERANCE, qx[2] >= -BARY_TOLERANCE);
        if in1 && in2 {
            let end = if qx[0] >= -BARY_TOLERANCE {
                qx
            } else {
                // q is behind the entry edge (rounding): stop where the segment entered
                let t = px[0] / (px[0] - qx[0]);
                [
                    0.0,
                    px[1] + t * (qx[1] - px[1]),
                    px[2] + t * (qx[2] - px[2]),
                ]
            };
            return Some((
                Located {
                    face: g,
                    bary: clamp(unrotate(end, l)),
                },
                w.rot,
                w.corners,
            ));
        }
        // the next exit, never the entry edge (0 in this order): edge 2 if it is the only
        // one q is beyond or the line meets it first, else edge 1
        let two = !in2 && (in1 || px[2] * (px[1] - qx[1]) < px[1] * (px[2] - qx[2]));
        (w.k, w.pk, w.qk) = if two {
            (PREV[l], [px[2], px[0], px[1]], [qx[2], qx[0], qx[1]])
        } else {
            (NEXT[l], [px[1], px[2], px[0]], [qx[1], qx[2], qx[0]])
        };
        None
    }
}

/// A walk under way ([`Charts::walk_cross`]): in face `face`, to cross its edge `k` next,
/// with the coordinates of the segment's ends at corners `k, k + 1, k + 2`.
#[derive(Debug, Clone, Copy)]
struct Walk {
    face: usize,
    k: usize,
    pk: [f64; 3],
    qk: [f64; 3],
    /// The map of this face's chart into the start face's.
    rot: Orth,
    /// Crossings left before the walk stops ([`MAX_CROSSINGS`]).
    left: usize,
    /// This face's corners.
    corners: Corners,
}

/// Barycentric coordinates from those at corners `l, l + 1, l + 2`.
fn unrotate(x: [f64; 3], l: usize) -> DVec3 {
    match l {
        0 => DVec3::new(x[0], x[1], x[2]),
        1 => DVec3::new(x[2], x[0], x[1]),
        _ => DVec3::new(x[1], x[2], x[0]),
    }
}

/// The orthogonal map `x ↦ R x + t` of a neighbour's chart into the current one that puts
/// the shared edge's ends `ga, gb` on `pa, pb` and the neighbour's far corner `gf` on the
/// other side of the edge from this face's far corner `far`.
fn unfold(pa: DVec2, pb: DVec2, far: DVec2, ga: DVec2, gb: DVec2, gf: DVec2) -> (DMat2, DVec2) {
    let u = (pb - pa).normalize_or_zero();
    let v = (gb - ga).normalize_or_zero();
    let (cos, sin) = (u.dot(v), v.perp_dot(u));
    let mut rot = DMat2::from_cols(DVec2::new(cos, sin), DVec2::new(-sin, cos));
    let side = |p: DVec2| u.perp_dot(p - pa);
    if side(rot * (gf - ga) + pa) * side(far) > 0.0 {
        // windings disagree: reflect across the edge's line
        let refl = DMat2::from_cols(
            DVec2::new(u.x * u.x - u.y * u.y, 2.0 * u.x * u.y),
            DVec2::new(2.0 * u.x * u.y, u.y * u.y - u.x * u.x),
        );
        rot = refl * rot;
    }
    (rot, pa - rot * ga)
}

/// Barycentric coordinates clamped to `[0, 1]` and renormalized (removes rounding).
pub(crate) fn clamp(b: DVec3) -> DVec3 {
    let c = b.max(DVec3::ZERO);
    let sum = c.element_sum();
    if sum > 0.0 {
        c / sum
    } else {
        DVec3::new(1.0, 0.0, 0.0)
    }
}

/// The particles are reordered by face every this many stage walks (rounded to whole
/// steps: every 4 RK4 steps, every RK8 step, a similar time span of scattering either way).
const SORT_EVERY: usize = 16;

/// Orders the particles by their face (then start vertex, so the order is unique), so that
/// consecutive particles walk through the same faces: the walks are memory-bound, and the
/// particles of a mixing flow scatter over the mesh. Each particle's result is computed on
/// its own, so the order changes no value.
fn sort_by_face(state: &mut [Located], live: &mut [usize]) {
    let mut order: Vec<(u32, usize, Located)> = state
        .iter()
        .zip(live.iter())
        .map(|(l, &v)| (l.face, v, *l))
        .collect();
    order.par_sort_unstable_by_key(|&(f, v, _)| (f, v));
    for (i, (_, v, l)) in order.into_iter().enumerate() {
        live[i] = v;
        state[i] = l;
    }
}

/// Traces one particle from every vertex through `velocity` from `t0` over `span` in
/// `steps` classical RK4 steps (module doc; [`flow_map_with`] for another scheme) and
/// returns where each ends (`None` for a loose vertex).
///
/// `charts` must be built from `motion`'s positions at `t0`. Errors: a velocity that is not
/// finite (naming the particle's start vertex and the time), a time outside the motion's
/// frames, the velocity's own errors.
pub fn flow_map(
    charts: &Charts,
    motion: &Motion,
    velocity: &mut dyn Velocity,
    t0: f64,
    span: f64,
    steps: usize,
) -> Result<Vec<Option<Located>>, LcsError> {
    flow_map_with(charts, motion, velocity, t0, span, Scheme::Rk4, steps)
}

/// [`flow_map`] with the explicit Runge–Kutta scheme `scheme` ([`super::rk`]).
pub fn flow_map_with(
    charts: &Charts,
    motion: &Motion,
    velocity: &mut dyn Velocity,
    t0: f64,
    span: f64,
    scheme: Scheme,
    steps: usize,
) -> Result<Vec<Option<Located>>, LcsError> {
    let moves = Moves::new(scheme);
    if let Some(planar) = &charts.planar
        && motion.is_fixed()
    {
        return flow_map_planar(charts, planar, velocity, t0, span, &moves, steps);
    }
    let n = charts.vertex_face.len();
    let start: Vec<Option<Located>> = (0..n).map(|v| charts.at_vertex_here(v)).collect();
    let mut live: Vec<usize> = (0..n).filter(|&v| start[v].is_some()).collect();
    let mut state: Vec<Located> = live.iter().filter_map(|&v| start[v]).collect();
    let m = state.len();
    let h = span / steps.max(1) as f64;
    let fixed = motion.is_fixed();
    // per particle and slot ([`Moves::slot`]): a stage point, the map of its face's chart
    // into the particle's, and the map of a displacement in the particle's chart to
    // barycentric rates there (for the walks from it)
    let slots = moves.slots();
    let mut slot_at = vec![vec![state[0]; m]; slots];
    let mut slot_rot = vec![vec![Orth::IDENTITY; m]; slots];
    let mut slot_bary = vec![vec![DMat2::ZERO; m]; slots];
    // per particle, at the current stage point: its world position and, on a fixed mesh,
    // the rows of `R (u, n̂ × u)ᵀ`, which give the stage velocity in the particle's chart
    // from `w`
    let mut axes = vec![[DVec3::ZERO; 2]; m];
    let mut points = vec![DVec3::ZERO; m];
    let mut outside_at = if velocity.uses_location() {
        vec![state[0]; m]
    } else {
        Vec::new()
    };
    let mut w = vec![DVec3::ZERO; m];
    let stages = moves.stages();
    let mut k: Vec<Vec<DVec2>> = vec![vec![DVec2::ZERO; m]; stages];
    for step in 0..steps.max(1) {
        if step % (SORT_EVERY / stages).max(1) == 0 {
            sort_by_face(&mut state, &mut live);
        }
        for stage in 0..stages {
            let ts = moves.time(stage, t0, step, h);
            let at = motion.at(ts)?;
            let k_ref = &k;
            let stage_point = |c: Corners,
                               l: &mut Located,
                               r: &mut Orth,
                               x: &mut DVec3,
                               tb: &mut DMat2,
                               ax: &mut [DVec3; 2]| {
                let fr = &charts.frame_of(c);
                *x = if fixed {
                    fr.x0 + l.bary.y * fr.e1 + l.bary.z * fr.e2
                } else {
                    charts.world_here(motion, at, l)
                };
                let rm = r.mat();
                *tb = fr.bary_map(rm);
                // rows of R [u v]ᵀ: k = R (u·w, v·w)
                *ax = [
                    rm.x_axis.x * fr.u + rm.y_axis.x * fr.v,
                    rm.x_axis.y * fr.u + rm.y_axis.y * fr.v,
                ];
            };
            let dst = moves.slot(stage);
            if stage == 0 {
                (
                    slot_at[dst].par_chunks_mut(2),
                    slot_rot[dst].par_chunks_mut(2),
                    points.par_chunks_mut(2),
                    slot_bary[dst].par_chunks_mut(2),
                    axes.par_chunks_mut(2),
                    state.par_chunks(2),
                )
                    .into_par_iter()
                    .for_each(|(l, r, x, tb, ax, p)| {
                        l.copy_from_slice(p);
                        r.fill(Orth::IDENTITY);
                        for j in 0..l.len() {
                            let cj = charts.hop[l[j].face as usize].corners;
                            stage_point(
                                cj, &mut l[j], &mut r[j], &mut x[j], &mut tb[j], &mut ax[j],
                            );
                        }
                    });
            } else {
                // each stage point walked on from the earlier one nearest in time (module
                // doc), two particles at a time ([`Charts::walk_pair`])
                let src = moves.slot(moves.source(stage));
                let (from_at, to_at) = two(&mut slot_at, src, dst);
                let (from_rot, to_rot) = two(&mut slot_rot, src, dst);
                let (from_bary, to_bary) = two(&mut slot_bary, src, dst);
                (
                    to_at.par_chunks_mut(2),
                    to_rot.par_chunks_mut(2),
                    points.par_chunks_mut(2),
                    to_bary.par_chunks_mut(2),
                    axes.par_chunks_mut(2),
                    from_at.par_chunks(2),
                    from_rot.par_chunks(2),
                    from_bary.par_chunks(2),
                )
                    .into_par_iter()
                    .enumerate()
                    .for_each(|(c, (l, r, x, tb, ax, l0, r0, tb0))| {
                        let mv = |j: usize| bary_step(tb0[j], moves.to(stage, h, k_ref, 2 * c + j));
                        let mut corners = [None; 2];
                        if l.len() == 2 {
                            let [(la, ra, ca), (lb, rb, cb)] =
                                charts.walk_pair((&l0[0], mv(0)), (&l0[1], mv(1)));
                            (l[0], r[0]) = (la, r0[0].then([ra.a, ra.b], ra.sigma));
                            (l[1], r[1]) = (lb, r0[1].then([rb.a, rb.b], rb.sigma));
                            corners = [Some(ca), Some(cb)];
                        } else {
                            let (e, rw, ce) = charts.walk_bary(&l0[0], mv(0));
                            (l[0], r[0]) = (e, r0[0].then([rw.a, rw.b], rw.sigma));
                            corners[0] = Some(ce);
                        }
                        for j in 0..l.len() {
                            let cj = corners[j]
                                .unwrap_or_else(|| charts.hop[l[j].face as usize].corners);
                            stage_point(
                                cj, &mut l[j], &mut r[j], &mut x[j], &mut tb[j], &mut ax[j],
                            );
                        }
                    });
            }
            let (stage_at, stage_rot) = (&slot_at[dst], &slot_rot[dst]);
            if velocity.uses_location() {
                // the velocity reads the input's faces
                outside_at
                    .par_iter_mut()
                    .zip(stage_at)
                    .for_each(|(o, l)| *o = charts.outside(l));
            }
            eval_checked(velocity, ts, &outside_at, &points, &live, &mut w)?;
            if fixed {
                k[stage]
                    .par_iter_mut()
                    .zip(&axes)
                    .zip(&w)
                    .for_each(|((ki, ax), wi)| *ki = DVec2::new(ax[0].dot(*wi), ax[1].dot(*wi)));
            } else {
                k[stage]
                    .par_iter_mut()
                    .zip(stage_at)
                    .zip(stage_rot)
                    .zip(&w)
                    .for_each(|(((ki, l), r), &wi)| {
                        *ki = r.mat() * charts.chart_velocity(motion, at, l, wi);
                    });
            }
        }
        let last = |i: usize| moves.to(stages, h, &k, i);
        let src = moves.slot(moves.source(stages));
        (
            state.par_chunks_mut(2),
            slot_at[src].par_chunks(2),
            slot_bary[src].par_chunks(2),
        )
            .into_par_iter()
            .enumerate()
            .for_each(|(c, (p, l, tb))| {
                if p.len() == 2 {
                    let d = [0, 1].map(|j| bary_step(tb[j], last(2 * c + j)));
                    let [a, b] = charts.walk_pair((&l[0], d[0]), (&l[1], d[1]));
                    (p[0], p[1]) = (a.0, b.0);
                } else {
                    p[0] = charts.walk_bary(&l[0], bary_step(tb[0], last(2 * c))).0;
                }
            });
    }
    let mut out = vec![None; n];
    for (i, &v) in live.iter().enumerate() {
        out[v] = Some(charts.outside(&state[i]));
    }
    Ok(out)
}

/// The faces in the order of their centroids along a Morton (Z-order) curve through the
/// bounding box (ties by index): faces near each other in space are near in memory, so
/// that a walk's faces, and those of particles walked one after the other, share cache
/// lines (module doc, "Memory"). Any order gives the same results.
fn space_filling_order(faces: &[[u32; 3]], positions: &[DVec3]) -> Vec<u32> {
    let (lo, hi) = positions
        .iter()
        .fold((DVec3::INFINITY, DVec3::NEG_INFINITY), |(l, h), &p| {
            (l.min(p), h.max(p))
        });
    let scale = ((1u64 << 21) - 1) as f64 / (hi - lo).max_element().max(1e-300);
    // 21 bits per axis, interleaved
    let spread = |x: u64| {
        let mut x = x & 0x1f_ffff;
        x = (x | (x << 32)) & 0x1f00000000ffff;
        x = (x | (x << 16)) & 0x1f0000ff0000ff;
        x = (x | (x << 8)) & 0x100f00f00f00f00f;
        x = (x | (x << 4)) & 0x10c30c30c30c30c3;
        (x | (x << 2)) & 0x1249249249249249
    };
    let mut keyed: Vec<(u64, u32)> = faces
        .par_iter()
        .enumerate()
        .map(|(f, tri)| {
            let c = tri.iter().map(|&v| positions[v as usize]).sum::<DVec3>() / 3.0;
            let q = ((c - lo) * scale).max(DVec3::ZERO);
            let key = spread(q.x as u64) | (spread(q.y as u64) << 1) | (spread(q.z as u64) << 2);
            (key, f as u32)
        })
        .collect();
    keyed.par_sort_unstable();
    keyed.into_iter().map(|(_, f)| f).collect()
}
