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
//! (`γ_k < 0`, `Σγ = 1`), precomputed per face and edge ([`Hop`](charts::Hop)). A point with
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
//! record per face holds everything a crossing reads ([`Hop`](charts::Hop): the two coefficients `1/γ_k`,
//! `γ_{k+1}/γ_k` and the map per edge, the neighbours, how their corners line up, and the
//! face's vertices); the faces are stored in the Morton order of their centroids, so faces
//! near in space are near in memory ([`space_filling_order`](charts::space_filling_order)); the particles are sorted by
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
//! ([`planar`]); the results agree with the walks up to rounding (tested).

mod buckets;
mod charts;
mod flow;
mod located;
mod planar;
mod time;
mod velocity;
mod walk;

pub use charts::Charts;
pub use flow::{flow_map, flow_map_with};
pub use located::Located;
pub use time::{FrameTimes, Motion};
pub use velocity::{FnVelocity, Velocity, VertexVelocity};
