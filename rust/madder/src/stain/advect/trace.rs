//! The velocity's advection: the semi-Lagrangian back-trace of every vertex, through its
//! flattened one-ring and the strip of unfolded triangles beyond.
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
//! *First wedge.* The wedge is searched in fan order, after an angular pre-test
//! (`sector.rs`).
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

use glam::{DMat2, DVec2};
use rayon::prelude::*;

use super::sector::{in_sector, rough_atan2};
use crate::mesh::transport::wrap_angle;
use crate::mesh::{EdgeKind, Geometry, OneRings, Topology, Transport, Wedge};

/// Most triangle crossings of one back-trace. Reached only when `h|u|` spans hundreds of
/// edges; the trace then stops at its last crossing point.
pub(crate) const MAX_CROSSINGS: usize = 256;

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
        // test below: skip it without placing its spokes (`sector.rs`)
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
pub(super) fn unfolded_turn(to_r: DVec2, to_l: DVec2, polar_r: f64, polar_l: f64) -> DMat2 {
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
