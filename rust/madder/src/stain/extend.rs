//! The velocity is the liquid's: where the cloth is dry it is extended from the wet region
//! (issue 10; seed §4.3, eqs. 4.1–4.3).
//!
//! Eq. 4.1 is the momentum balance of the liquid film: `u` is only defined where there is
//! liquid (`σ_f > 0`). The discretization stores one velocity per vertex, also on the dry
//! cloth, and that value is read wherever liquid arrives:
//!
//! - the upwind flux of §4.3.1 uses `u_ij = ½(u_i + u_j)` across every edge, so at a wet
//!   front the dry vertex's velocity is half of the flux that moves the liquid onward;
//! - the semi-Lagrangian back-trace interpolates `u` at the foot of a characteristic,
//!   which for the rear of a moving blob lies on the dry cloth behind it.
//!
//! If the dry velocity evolved on its own under the body forces (as the wet one does),
//! then in a trough (the bottom of a fold) the dry velocities of the two sides would meet
//! head on, and liquid arriving there would see `u_ij ≈ 0` and stop dead, where a point
//! mass swings through; a splash whose dry surroundings sit at rest would see its front's
//! flux halved and stall. Neither is physics: the dry value is a fiction of the
//! discretization, and the right fiction is the liquid's own velocity continued a little
//! way past its edge.
//!
//! So before the velocity is read, every vertex that is not *wet* — free-solvent density
//! at most [`WET_FRACTION`] of the region's largest — takes the mean of its already known
//! neighbours' velocities, each transported into its frame by `R_ij` (eq. 4.4),
//!
//! ```text
//! u_i = (1/|K_i|) Σ_{j ∈ K_i} R_ij u_j,      K_i = known neighbours of i,
//! ```
//!
//! ring by ring outward from the wet vertices (ring `r` reads only rings `< r`, so the
//! result does not depend on the order within a ring). A vertex no wet vertex reaches
//! gets zero. On a flat cloth with a uniform velocity the extension is that velocity
//! exactly (a test checks it); at a front it is the front's own velocity, so launched
//! liquid coasts and liquid arriving at the bottom of a trough swings through.
//!
//! The threshold is relative (a vertex with `10⁻⁶` of the peak density carries a velocity
//! of its own): implicit diffusion gives every vertex of the region some liquid, down to
//! `10⁻³⁰` of the peak; the velocity of such a trace comes from its round-off, not from its
//! motion, and the mass it moves is invisible.

use glam::DVec2;
use rayon::prelude::*;

use crate::mesh::{Topology, Transport};

/// A vertex carries a velocity of its own when its free-solvent density is above this
/// fraction of the largest among the vertices considered (module doc).
pub(crate) const WET_FRACTION: f64 = 1e-6;

/// Per vertex: wet (carries a velocity of its own). Only vertices flagged in `region` are
/// considered (and can be wet); `mass` and `area` are per vertex (a vertex without area is
/// dry).
pub(crate) fn wet_vertices(mass: &[f64], area: &[f64], region: &[bool]) -> Vec<bool> {
    let density = |i: usize| {
        if area[i] > 0.0 && region[i] {
            mass[i] / area[i]
        } else {
            0.0
        }
    };
    let peak = (0..mass.len()).map(density).fold(0.0, f64::max);
    let floor = WET_FRACTION * peak;
    (0..mass.len())
        .map(|i| peak > 0.0 && density(i) > floor)
        .collect()
}

/// Vertices per task of the extension's parallel passes.
const EXTEND_PER_TASK: usize = 1024;

/// Replaces the velocity of every vertex that is not `wet` in each of `fields` by the
/// extension of the module doc: ring by ring from the wet vertices, the mean of the known
/// neighbours' values transported by `transport`'s `R_ij`; zero where no wet vertex
/// reaches. Every field gets the same weights. Each ring is found and computed in
/// parallel (a sorted set; each mean summed in edge order from earlier rings only): the
/// result does not depend on the thread count.
///
/// # Panics
/// If `wet` or a field does not have one entry per vertex of `topology`.
pub fn extend_velocity(
    topology: &Topology,
    transport: &Transport,
    wet: &[bool],
    fields: &mut [&mut [DVec2]],
) {
    let n = topology.n_vertices();
    assert_eq!(wet.len(), n, "one wet flag per vertex");
    assert!(
        fields.iter().all(|f| f.len() == n),
        "one velocity per vertex"
    );
    let mut known = wet.to_vec();
    let mut front: Vec<u32> = (0..n as u32).filter(|&v| wet[v as usize]).collect();
    let mut ring: Vec<u32> = Vec::new();
    let mut values: Vec<DVec2> = Vec::new();
    while !front.is_empty() {
        // the dry neighbours of the front, each once, in increasing order (found in
        // parallel: a set, sorted, whatever the split)
        ring.clear();
        ring.par_extend(
            front
                .par_iter()
                .with_min_len(EXTEND_PER_TASK)
                .flat_map_iter(|&v| {
                    let known = &known;
                    topology
                        .vertex_edges(v as usize)
                        .iter()
                        .filter_map(move |&e| {
                            let w = topology.other_end(e as usize, v as usize);
                            (!known[w as usize]).then_some(w)
                        })
                }),
        );
        ring.par_sort_unstable();
        ring.dedup();
        for field in fields.iter_mut() {
            // each value reads only earlier rings: computed in parallel, then written
            let field_now: &[DVec2] = field;
            ring.par_iter()
                .with_min_len(EXTEND_PER_TASK)
                .map(|&i| mean_of_known(topology, transport, &known, field_now, i as usize))
                .collect_into_vec(&mut values);
            for (&i, &u) in ring.iter().zip(&values) {
                field[i as usize] = u;
            }
        }
        for &i in &ring {
            known[i as usize] = true;
        }
        std::mem::swap(&mut front, &mut ring);
    }
    for (i, k) in known.iter().enumerate() {
        if !k {
            fields.iter_mut().for_each(|f| f[i] = DVec2::ZERO);
        }
    }
}

/// `(1/|K|) Σ_{j ∈ K} R_ij u_j` over the known neighbours `K` of `i` (at least one).
fn mean_of_known(
    topology: &Topology,
    transport: &Transport,
    known: &[bool],
    u: &[DVec2],
    i: usize,
) -> DVec2 {
    let (mut sum, mut count) = (DVec2::ZERO, 0usize);
    for &e in topology.vertex_edges(i) {
        let j = topology.other_end(e as usize, i) as usize;
        if known[j] {
            let r = transport.edge_rotation(e as usize);
            let r = if i < j { r } else { r.transpose() };
            sum += r * u[j];
            count += 1;
        }
    }
    sum / count as f64
}
