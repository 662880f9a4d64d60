//! Parallel transport between vertex frames (seed §4.3.1, eq. 4.4): the discrete
//! Levi-Civita connection, per frame, from the intrinsic geometry and the frames.
//!
//! Comparing the velocity `u_i` of vertex `i` (in its frame `F_i`, [`super::frames`]) with
//! a neighbour's `u_j` needs the rotation `R_ij` that carries a vector written in `F_j` into
//! `F_i` by parallel transport along the edge. [`Transport`] holds it for every edge, from
//! the geodesic polar map of each one-ring (the ordered fans of [`super::rings`]).
//!
//! ## Geodesic polar map (§4.3.1)
//! Around vertex `i`, let the fan's wedges (face corners at `i`) have tip angles `φ_T`, with
//! sum `γ_i = Σ_T φ_T`. Walking the fan counter-clockwise from the reference edge, the
//! polar angle of the spoke `e_ij` is the sum of the tip angles passed, rescaled so that
//! the one-ring becomes a flat disk:
//!
//! ```text
//! α_ij = s_i Σ_{T between e_ik and e_ij} φ_T,      s_i = 2π / γ_i  (interior vertex).
//! ```
//!
//! Tip angles are *intrinsic*, computed from the (mollified) edge lengths of
//! [`Geometry`]: `φ = atan2(4A, b² + c² − a²)` for the corner opposite side `a` of a face
//! of area `A`, which is `acos((b² + c² − a²) / 2bc)` without the loss of accuracy of
//! `acos` near 0 and π.
//!
//! **Boundary vertices are not rescaled** (`s_i = 1`): their one-ring is a wedge of
//! opening `γ_i` (π on a straight border, π/2 at the corner of a sheet), which the polar
//! map lays flat as it is. Rescaling to a half-disk (`π/γ_i`, as some direction-field
//! papers do) would put the border's *geodesic curvature* into the connection: a uniform
//! wind on a flat tablecloth would turn as it passes a corner. With `s_i = 1` a flat
//! (developable) cloth, borders and corners included, has a trivial connection, and the
//! test suite checks that a constant field is transported exactly everywhere.
//!
//! ## Transport (eq. 4.4)
//! Parallel transport keeps the angle between a vector and the edge it travels along. The
//! direction "from `j` to `i`" has polar angle `α_ji` at `j` and `α_ij + π` at `i`, so a
//! vector at angle `ψ` in `F_j` arrives at angle `ψ + θ_ij` in `F_i` with
//!
//! ```text
//! θ_ij = α_ij − α_ji + π,        R_ij = [cos θ_ij  −sin θ_ij; sin θ_ij  cos θ_ij],
//! ```
//!
//! eq. 4.4, with `R_ij u_j` the transport of `u_j` to `i`. Then `θ_ji = −θ_ij (mod 2π)`:
//! `R_ji = R_ijᵀ`. We store one angle per edge `(a, b)`, `a < b`, namely `θ_ab` wrapped to
//! `(−π, π]`, and return `R_ba` as the exact transpose of `R_ab`, so the convention holds
//! bit for bit (the Bochner Laplacian's symmetry, [`crate::ops::bochner`], relies on it).
//!
//! The holonomy of a face (transport around its three edges) is `Σ_c (s_c − 1) φ_c`: each
//! interior corner `c` contributes its share `φ_c / γ_c` of the vertex's angle defect
//! `2π − γ_c`; boundary corners contribute nothing. Around a closed surface the face
//! holonomies add up to `Σ_v (2π − γ_v) = 2πχ` (discrete Gauss–Bonnet), and around the
//! one-ring of a vertex whose neighbours are flat (or on the border) the holonomy is the
//! vertex's angle defect: the tests check all three (the per-face share, the sum, the
//! one-ring loop) against angles measured independently on the 3-D positions.
//!
//! ## Frames other than the polar ones (§4.4)
//! The seed measures `α` from `x_i`, which is the reference edge. For comoving–corotating
//! frames `F_i = U_i F̄_i` (rest frame turned by the one-ring's best rotation, see
//! [`super::kabsch`]) the reference edge is no longer exactly along `x_i`. [`Transport`]
//! therefore measures, in the given frames, the angle `δ_i` of the reference spoke
//! projected on the `(x_i, y_i)` plane, and uses `α_ij + δ_i` as the angle of spoke `j` in
//! `F_i`. (If the reference spoke is nearly normal to `z_i`, the first spoke `r` that is
//! not gives `δ_i = β_r − α_ir`, `β_r` its projected angle; if none, `δ_i = 0`.) For
//! [`VertexFrames::new`] the offset is zero up to rounding, so the seed's convention is
//! reproduced exactly; the tests check that arbitrarily turned frames keep a flat cloth's
//! transport exact.
//!
//! ## Similar faces (issue 12, Detail)
//! On a refined cloth ([`super::refine`]) the `4^L` fine faces of one coarse face are
//! its translates scaled by `±1/N` (the lattice's up and down triangles on the planar
//! coarse face), so their tip angles are the coarse face's, corner for corner up to a
//! cyclic shift ([`super::refine::Partial::face_congruence`]).
//! [`Transport::with_shared_tips`] computes them on the first fine face of each coarse
//! face and copies them to the others: one set of three `atan2` per coarse face instead
//! of per fine face. They are the others' own angles up to the rounding of each fine
//! vertex's barycentric placement (a test: within 1e-13 rad on a folded refined sheet,
//! levels 1–3). The mollification adds one length to every edge, which breaks the
//! similarity: a mollified geometry computes every face's own.
//!
//! The polar map of an irregular vertex (several fans, [`super::FanKind::Irregular`]) lays
//! its fans side by side without rescaling; see [`super::rings`].

use std::f64::consts::{PI, TAU};

use glam::{DMat2, DMat3, DVec2, DVec3};
use rayon::prelude::*;

use super::frames::{VertexFrames, tangent_direction};
use super::rings::{FanKind, OneRings, find_edge};
use super::{Geometry, Topology};
use crate::runs::carve;

/// Tip angles of the three corners of every face from the intrinsic edge lengths (in
/// parallel; each corner's angle is computed once and read by the fan of its vertex). With
/// `share`, a face `t` with `share[t] = (r, c)`, `r ≠ t`, takes the angles of face `r`
/// turned by `c` (its corner `k` gets `r`'s corner `(k + c) % 3`): similar faces, module
/// doc, "Similar faces".
fn tip_angles(
    topology: &Topology,
    geometry: &Geometry,
    share: Option<&[(u32, u8)]>,
) -> Vec<[f64; 3]> {
    let own = |f: usize| -> [f64; 3] {
        let fe = topology.face_edges()[f];
        let area = geometry.face_area[f];
        let l = |c: usize| geometry.edge_length[fe[c % 3] as usize];
        std::array::from_fn(|k| {
            let (a, b, c) = (l(k), l(k + 1), l(k + 2));
            (4.0 * area).atan2(b * b + c * c - a * a)
        })
    };
    // the mollification adds the same length to every edge, which does not scale with
    // the faces: similar faces stay similar only without it
    let Some(share) = share.filter(|_| geometry.mollify_delta == 0.0) else {
        return (0..topology.n_faces()).into_par_iter().map(own).collect();
    };
    assert_eq!(share.len(), topology.n_faces(), "one share per face");
    let first: Vec<[f64; 3]> = share
        .par_iter()
        .enumerate()
        .map(|(t, &(r, _))| {
            if r as usize == t {
                own(t)
            } else {
                [f64::NAN; 3]
            }
        })
        .collect();
    share
        .par_iter()
        .zip(&first)
        .map(|(&(r, c), &mine)| {
            let theirs = first[r as usize];
            debug_assert!(theirs[0].is_finite(), "a shared face's angles are its own");
            if mine[0].is_nan() {
                std::array::from_fn(|k| theirs[(k + c as usize) % 3])
            } else {
                mine
            }
        })
        .collect()
}

/// Parallel transport `R_ij` of eq. 4.4 (the discrete connection of §4.3.1): polar angles
/// `α_ij` per spoke and transport angles `θ_ij` per edge, in given vertex frames.
#[derive(Debug, Clone, Default)]
pub struct Transport {
    /// Polar angle of every spoke (laid out like [`OneRings::spokes`]), measured from the
    /// reference spoke, counter-clockwise, rescaled.
    alpha: Vec<f64>,
    spoke_ptr: Vec<u32>,
    angle_sum: Vec<f64>,
    offset: Vec<f64>,
    theta: Vec<f64>,
    /// `(cos θ_ab, sin θ_ab)` per edge: the rotation, computed once per frame.
    cos_sin: Vec<[f64; 2]>,
    /// Per edge `(a, b)`: the polar angle of its spoke in the frame of `a` and of `b`
    /// (`α + δ`, the operands of `θ_ab`).
    edge_polar: Vec<[f64; 2]>,
    edge_ptr: Vec<u32>,
    edge_end: Vec<u32>,
}

impl Transport {
    /// The transport of `topology` with ordered fans `rings` and intrinsic `geometry`,
    /// expressed in `frames` (built from, or corotating with, `positions`).
    ///
    /// # Panics
    /// If `rings`, `frames` or `positions` do not have one entry per vertex of `topology`
    /// (a programming error: they all come from the same mesh).
    pub fn new(
        topology: &Topology,
        rings: &OneRings,
        geometry: &Geometry,
        frames: &VertexFrames,
        positions: &[DVec3],
    ) -> Self {
        Self::with_shared_tips(topology, rings, geometry, frames, positions, None)
    }

    /// [`Self::new`], with the tip angles of similar faces computed once (module doc,
    /// "Similar faces"): face `t` with `share[t] = (r, c)`, `r ≠ t`, takes the angles of
    /// face `r` (which has `share[r].0 = r`), its corner `k` that of `r`'s corner
    /// `(k + c) % 3`. Ignored when the geometry is mollified.
    ///
    /// # Panics
    /// As [`Self::new`], and if `share` does not have one entry per face.
    pub(crate) fn with_shared_tips(
        topology: &Topology,
        rings: &OneRings,
        geometry: &Geometry,
        frames: &VertexFrames,
        positions: &[DVec3],
        share: Option<&[(u32, u8)]>,
    ) -> Self {
        let mut transport = Self::default();
        transport.renew(topology, rings, geometry, frames, positions, share);
        transport
    }

    /// [`Self::with_shared_tips`] in this transport's arrays (their allocations kept: the
    /// simulator renews one transport every sub-step instead of allocating it afresh,
    /// issue 16). The same values, bit for bit.
    pub(crate) fn renew(
        &mut self,
        topology: &Topology,
        rings: &OneRings,
        geometry: &Geometry,
        frames: &VertexFrames,
        positions: &[DVec3],
        share: Option<&[(u32, u8)]>,
    ) {
        let n = topology.n_vertices();
        assert_eq!(rings.n_vertices(), n, "rings of another topology");
        assert_eq!(frames.len(), n, "one frame per vertex");
        assert_eq!(positions.len(), n, "one position per vertex");
        // the tip angles are not kept: they are needed only here, and the memory they
        // take is the advection's a moment later
        let tip = tip_angles(topology, geometry, share);
        // polar angles written in place: one slice of the flat array per vertex
        let alpha = &mut self.alpha;
        alpha.clear();
        alpha.resize(rings.spoke_vertex.len(), f64::NAN);
        carve(alpha, (0..n).map(|v| rings.spokes(v).len()))
            .into_par_iter()
            .enumerate()
            .map(|(v, alpha)| {
                let gamma = polar_map(rings, &tip, v, alpha);
                let offset = frame_offset(rings, v, alpha, &frames.frame[v], positions);
                (gamma, offset)
            })
            .unzip_into_vecs(&mut self.angle_sum, &mut self.offset);
        let (alpha, offset) = (&self.alpha, &self.offset);
        // θ_ab from the angle of each edge in the frame of each endpoint, and its rotation
        let edges = topology.edges();
        // written in place, in one parallel pass (a nested unzip collects into lists
        // of chunks and copies them)
        let m = edges.len();
        let (theta, cos_sin, edge_polar) =
            (&mut self.theta, &mut self.cos_sin, &mut self.edge_polar);
        theta.clear();
        theta.resize(m, 0.0);
        cos_sin.clear();
        cos_sin.resize(m, [0.0; 2]);
        edge_polar.clear();
        edge_polar.resize(m, [0.0; 2]);
        theta
            .par_iter_mut()
            .zip(cos_sin)
            .zip(edge_polar)
            .zip(edges.par_iter().zip(&rings.edge_spoke))
            .with_min_len(1024)
            .for_each(|(((theta, cos_sin), polar), (&[a, b], &[sa, sb]))| {
                let angle = |v: u32, s: u32| match alpha.get(s as usize) {
                    Some(&x) => x + offset[v as usize],
                    None => f64::NAN,
                };
                let (ta, tb) = (angle(a, sa), angle(b, sb));
                debug_assert!(ta.is_finite() && tb.is_finite(), "every edge is in a fan");
                *theta = wrap_angle(ta - tb + PI);
                let (sin, cos) = theta.sin_cos();
                *cos_sin = [cos, sin];
                *polar = [ta, tb];
            });
        self.spoke_ptr.clone_from(&rings.spoke_ptr);
        self.edge_ptr.clone_from(&rings.edge_ptr);
        self.edge_end.clone_from(&rings.edge_end);
    }

    /// Polar angles `α_ij` of the spokes of `v` (in [`OneRings::spokes`] order) in the
    /// flattened one-ring, measured from the reference spoke.
    pub fn polar_angles(&self, v: usize) -> &[f64] {
        &self.alpha[self.spoke_ptr[v] as usize..self.spoke_ptr[v + 1] as usize]
    }

    /// Sum `γ_v` of the tip angles around `v` (before rescaling).
    pub fn angle_sum(&self, v: usize) -> f64 {
        self.angle_sum[v]
    }

    /// Angle `δ_v` of the reference spoke in the frame of `v` (0 for the frames of
    /// [`VertexFrames::new`], up to rounding).
    pub fn frame_offset(&self, v: usize) -> f64 {
        self.offset[v]
    }

    /// `θ_ab` of every edge `(a, b)`, `a < b`, in `(−π, π]`.
    pub fn edge_angles(&self) -> &[f64] {
        &self.theta
    }

    /// `(cos θ_ab, sin θ_ab)` of every edge (the entries of [`Self::edge_rotation`]).
    pub(crate) fn edge_cos_sin(&self) -> &[[f64; 2]] {
        &self.cos_sin
    }

    /// The polar angles `α + δ` of edge `e = (a, b)`'s spoke in the frames of `a` and `b`:
    /// the same values as [`Self::polar_angles`] plus [`Self::frame_offset`] give.
    pub(crate) fn edge_polar(&self, e: usize) -> [f64; 2] {
        self.edge_polar[e]
    }

    /// `R_ab` of edge `e = (a, b)`, `a < b` (transport from `F_b` to `F_a`); the same
    /// matrix as `DMat2::from_angle(θ_ab)`, from the stored cosine and sine.
    pub(crate) fn edge_rotation(&self, e: usize) -> DMat2 {
        let [c, s] = self.cos_sin[e];
        DMat2::from_cols_array(&[c, s, -s, c])
    }

    /// `θ_ij` for neighbours `i`, `j` (`None` if they share no edge; `0` if `i == j`).
    pub fn angle(&self, i: usize, j: usize) -> Option<f64> {
        if i == j {
            return Some(0.0);
        }
        let e = find_edge(&self.edge_ptr, &self.edge_end, i as u32, j as u32)?;
        Some(if i < j { self.theta[e] } else { -self.theta[e] })
    }

    /// `R_ij` of eq. 4.4, carrying a vector in `F_j` to `F_i` (`R_ii = I`; `R_ji = R_ijᵀ`
    /// exactly). `None` if `i` and `j` share no edge.
    pub fn rotation(&self, i: usize, j: usize) -> Option<DMat2> {
        if i == j {
            return Some(DMat2::IDENTITY);
        }
        let e = find_edge(&self.edge_ptr, &self.edge_end, i as u32, j as u32)?;
        let r = self.edge_rotation(e);
        Some(if i < j { r } else { r.transpose() })
    }

    /// `R_ij u_j`: the vector `u_j` of `F_j` transported to `F_i`.
    pub fn transport(&self, i: usize, j: usize, u_j: DVec2) -> Option<DVec2> {
        self.rotation(i, j).map(|r| r * u_j)
    }
}

/// Polar angles of the spokes of `v` (into `alpha`, NaN on entry) and the tip-angle sum
/// `γ_v` (returned).
fn polar_map(rings: &OneRings, tip: &[[f64; 3]], v: usize, alpha: &mut [f64]) -> f64 {
    let mut running = 0.0;
    for w in rings.wedges(v) {
        if alpha[w.from as usize].is_nan() {
            alpha[w.from as usize] = running;
        }
        running += tip[w.face as usize][w.corner as usize];
        if alpha[w.to as usize].is_nan() {
            alpha[w.to as usize] = running;
        }
    }
    let gamma = running;
    if rings.kind(v) == FanKind::Interior && gamma > 0.0 {
        let s = TAU / gamma;
        alpha.iter_mut().for_each(|a| *a *= s);
    }
    gamma
}

/// Angle `δ_v` of the reference spoke in `frame` (see the module doc): measured on the
/// first spoke well inside the frame's tangent plane, minus that spoke's polar angle.
fn frame_offset(rings: &OneRings, v: usize, alpha: &[f64], frame: &DMat3, pos: &[DVec3]) -> f64 {
    let (x, y, z) = (frame.x_axis, frame.y_axis, frame.z_axis);
    rings
        .spokes(v)
        .iter()
        .zip(alpha)
        .find_map(|(&j, &a)| {
            let e = pos[j as usize] - pos[v];
            tangent_direction(e, z).map(|t| t.dot(y).atan2(t.dot(x)) - a)
        })
        .map_or(0.0, wrap_angle)
}

/// `a` wrapped to `(−π, π]`: `(a + π).rem_euclid(2π) − π`, with the remainder taken
/// without the library's `fmod` for `|a + π| < 4π` (every angle the transport and the
/// back-trace wrap: sums and differences of a few polar angles). There `x − 2π sign(x)`
/// is exact (Sterbenz), so it is the exact remainder `fmod` returns, and the result has
/// the same bits (a test compares them).
pub(crate) fn wrap_angle(a: f64) -> f64 {
    let x = a + PI;
    let m = if x.abs() < TAU {
        x
    } else if x.abs() < 2.0 * TAU {
        x - TAU.copysign(x)
    } else {
        x % TAU
    };
    let r = if m < 0.0 { m + TAU } else { m } - PI;
    if r == -PI { PI } else { r }
}

#[cfg(test)]
mod tests {
    use super::super::rings::tests::fan;
    use super::*;

    #[test]
    fn closed_fan_polar_angles_are_the_spokes_directions() {
        let (t, p) = fan(true);
        let r = OneRings::new(&t);
        let f = VertexFrames::new(&r, &p).unwrap();
        let g = Geometry::new(&t, &p).unwrap();
        let c = Transport::new(&t, &r, &g, &f, &p);
        for (k, a) in c.polar_angles(0).iter().enumerate() {
            assert!((a - TAU * k as f64 / 6.0).abs() < 1e-14, "spoke {k}: {a}");
        }
        assert!((c.angle_sum(0) - TAU).abs() < 1e-14);
    }

    #[test]
    fn open_fan_is_not_rescaled() {
        let (t, p) = fan(false);
        let r = OneRings::new(&t);
        let f = VertexFrames::new(&r, &p).unwrap();
        let g = Geometry::new(&t, &p).unwrap();
        let c = Transport::new(&t, &r, &g, &f, &p);
        assert!((c.angle_sum(0) - 4.0 * TAU / 6.0).abs() < 1e-14);
        assert!((c.polar_angles(0)[4] - 4.0 * TAU / 6.0).abs() < 1e-14);
    }

    #[test]
    fn wrap_angle_is_rem_euclid_to_the_bit() {
        let reference = |a: f64| {
            let r = (a + PI).rem_euclid(TAU) - PI;
            if r == -PI { PI } else { r }
        };
        let mut special = vec![0.0, -0.0, PI, -PI, TAU, -TAU, 3.0 * PI, -3.0 * PI];
        special.extend([f64::INFINITY, f64::NEG_INFINITY, 1e300, -1e300, 5.0 * PI]);
        for &a in &special {
            for x in [
                a,
                // the neighbours in bit order (below 0.0 wraps to a NaN)
                f64::from_bits(a.to_bits().wrapping_add(1)),
                f64::from_bits(a.to_bits().wrapping_sub(1)),
            ] {
                let (w, r) = (wrap_angle(x), reference(x));
                assert!(
                    w.to_bits() == r.to_bits() || (w.is_nan() && r.is_nan()),
                    "{x}: {w} vs {r}"
                );
            }
        }
        // a pseudo-random sweep over ±5π (both branches and the fallback)
        let mut s = 0x9e37_79b9_7f4a_7c15_u64;
        for _ in 0..200_000 {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            let x = ((s >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 10.0 * PI;
            assert_eq!(wrap_angle(x).to_bits(), reference(x).to_bits(), "{x}");
        }
    }

    #[test]
    fn wrap_angle_range() {
        for a in [-7.0, -PI, -1.0, 0.0, 1.0, PI, 4.0, 13.0] {
            let w = wrap_angle(a);
            assert!(w > -PI && w <= PI);
            assert!(((a - w) / TAU - ((a - w) / TAU).round()).abs() < 1e-12);
        }
    }
}
