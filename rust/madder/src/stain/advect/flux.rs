//! The densities' volume fluxes through the faces of the median dual, per edge.
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

use glam::{DVec2, DVec3};
use rayon::prelude::*;

use super::VERTICES_PER_TASK;
use crate::mesh::{Topology, VertexFrames};

/// A face whose `|e_ij × e_ik|` is below this fraction of its longest squared edge (the
/// sine of its largest angle, roughly) has a normal dominated by rounding (`≈ 10⁻¹⁶ ℓ²`
/// absolute error, so more than `10⁻⁴` relative below this bound): its dual area vectors
/// are set to zero.
pub(crate) const FLAT_FACE_REL: f64 = 1e-12;

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
pub(super) fn face_fluxes(tri: [usize; 3], pos: &[DVec3], world: &[DVec3]) -> [f64; 3] {
    let s = face_area_vectors(tri, pos);
    std::array::from_fn(|k| {
        let (a, b) = (tri[(k + 1) % 3], tri[(k + 2) % 3]);
        let s = if a > b { -s[k] } else { s[k] };
        0.5 * (world[a] + world[b]).dot(s)
    })
}
