//! The window a frame works on: the active region around the liquid (seed §4.3; the
//! restricted operators of §4.3.3 are [`crate::ops::restrict`]).
//!
//! A stain usually covers a small part of the cloth, so with `active_region` (the
//! default) a frame works on a *window*, a mesh of its own cut out of the cloth:
//!
//! - the **active** vertices: those holding flowing liquid — free solvent or dissolved
//!   solute density above [`ACTIVE_THRESHOLD`] (1e-12) of that field's peak — grown by
//!   [`ACTIVE_RINGS`] (3) rings plus one ring per transport sub-cycle of the frame's
//!   sub-steps (liquid moves at most one ring per sub-cycle, so it cannot reach the
//!   region's edge within the frame; the count is the last frame's, and a frame that
//!   needed more is run again on a wider window: [`super::simulate`], "Window reach").
//!   Every phase runs on them. (A threshold of exactly
//!   zero would not do: implicit diffusion gives every vertex of the region a positive,
//!   if 1e-30-level, mass, so the region would grow every step until it covered the
//!   cloth.)
//! - the **held** vertices: not flowing, but holding absorbed solvent or solute above
//!   the same fraction of its peak, which the interactions still change. What is left
//!   below the thresholds everywhere else is *dust* (the far tail of implicit diffusion,
//!   1e-12 of the peaks and less): it stays untouched until liquid comes near again, and
//!   keeps the area of its last step.
//! - the **halo**: the other corners of the active and held vertices' faces, so that
//!   their one-rings are whole: their areas, Kabsch frames, transport and exposure are
//!   exactly the cloth's. The halo holds nothing that can change; it is not written back.
//!
//! Geometry, frames, transport, forces, advection, diffusion and interactions all run on
//! the window only; the cloth outside it costs nothing per frame but reading the
//! positions. A frame gathers the window's state, steps it, and writes it back. The window
//! is kept from frame to frame while the liquid's needed region stays inside its active
//! vertices and is at least half of it; a new one reaches twice as far as the frame
//! needs, plus [`WINDOW_SLACK_RINGS`] rings, so that it lasts a few frames. With
//! `active_region` off, the window is the whole mesh, every vertex active: one code path.
//!
//! **Building a window derives it from the cloth** (issue 16). Its faces are the cloth's
//! faces around the active and held vertices, read off a per-face mark in the cloth's
//! order, and its vertices keep the cloth's order. A renumbering that keeps the order
//! keeps everything that was sorted, so nothing is sorted again: the window's edges are
//! the cloth's edges that one of its faces has, gathered in the cloth's order
//! ([`Topology::restricted`]); a vertex that has all its cloth faces in the window (every
//! active and held one) has the cloth's fan with faces, spokes and edges renumbered, and
//! only the halo's partial fans are walked ([`OneRings::restricted`]; the fan walk
//! depends on nothing but the corners in face order and the order of the vertex
//! numbers). The pattern, the restriction and the IC(0) analysis follow in time
//! proportional to the window, and the solvers are rebuilt in the memory of the window
//! they replace ([`WarmCg::rebuild`]: fresh pages cost more than the analysis), or of
//! one a growth of the refined cloth dropped ([`super::detail`]); the fans, neighbour
//! lists and gathers are derived beside the pattern, the restriction and the solvers'
//! analysis, which need only the window's topology. The result is the window built from
//! scratch, bit for bit (a test compares every array on a mesh with a hole, a fin, a
//! bow-tie and a flipped face).
//!
//! On a refined cloth the window also knows, per vertex, which fine vertices lie inside
//! one coarse face or on one coarse edge ([`crate::mesh::refine::Partial::congruence`]):
//! those with whole one-rings there share one Kabsch rotation per face and edge
//! ([`Window::corotating_frames_into`], module doc of [`crate::mesh::kabsch`]). Per window
//! face it keeps the first window face of the same coarse face and the shift of its
//! corners ([`crate::mesh::refine::Partial::face_congruence`]): the similar fine faces
//! share their tip angles ([`crate::mesh::Transport::with_shared_tips`]) and their
//! median-dual area vectors ([`super::advect`], "Congruent faces").
//!
//! - **Diffusion.** `(M + h K_A) σ' = m` on the active vertices, `K_A` the stiffness
//!   restricted to them with a Neumann (no-flux) boundary at the region's edge
//!   ([`crate::ops::restrict`]): `1ᵀK_A = 0`, so the restricted solve conserves mass
//!   exactly like the whole one, and the total is restored over the region after the
//!   solve; the negative-mass repair draws only from active vertices
//!   ([`super::diffuse`]). The velocity's Bochner system is restricted the same way
//!   (block rows and columns of the active vertices, `K_ii = Σ_{j active} L_ij` with the
//!   clamped weights).
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

use glam::DVec3;
use rayon::prelude::*;

use super::diffuse::{Conductivity, solvers};
use super::forces::corotating_frames_into;
use super::state::Fields;
use crate::error::Error;
use crate::mesh::{OneRings, RingAdjacency, Topology, VertexFrames};
use crate::ops::{Restriction, VertexPattern, WarmCg};

/// Rings of vertices the active region keeps around the flowing liquid, on top of one ring
/// per transport sub-cycle of the previous sub-step (module doc).
pub(crate) const ACTIVE_RINGS: usize = 3;

/// A vertex holds flowing liquid when its free-solvent or dissolved-solute density is
/// above this fraction of that field's largest density (module doc).
pub(crate) const ACTIVE_THRESHOLD: f64 = 1e-12;

/// Liquid or dissolved solute above this fraction of its peak on a vertex at the active
/// region's edge means the region's no-flux wall held it back: the frame runs again on a wider
/// window ([`super::simulate`], "Window reach"). Far above the implicit diffusion's
/// truncated tail ([`ACTIVE_THRESHOLD`]), far below any front.
pub(crate) const WALL_THRESHOLD: f64 = 1e-6;

/// Rings a new window's active region gets beyond what the frame needs, on top of the
/// frame's own reach again (room for about two more frames of the same flow), so that the
/// window is not rebuilt every frame (module doc).
pub(crate) const WINDOW_SLACK_RINGS: usize = 4;

/// A window is rebuilt when its active region exceeds twice the needed one plus this
/// many vertices (the liquid shrank or dried).
pub(crate) const WINDOW_SLACK_VERTICES: usize = 256;

/// A triangle mesh with what every phase reads: the whole cloth, or a window cut out of it.
#[derive(Debug)]
pub(super) struct Cloth {
    pub(super) topology: Topology,
    /// Fans of faces around every vertex.
    pub(super) rings: OneRings,
    /// Vertex neighbours in edge order (the Kabsch sums, the negative-mass repair).
    pub(super) adjacency: RingAdjacency,
    pub(super) rest: Vec<DVec3>,
    pub(super) rest_frames: VertexFrames,
    /// The fabric's diffusion of the densities.
    pub(super) conductivity: Conductivity,
    /// The cloth's border, per vertex.
    pub(super) boundary: Vec<bool>,
    /// The irregular fabric's multiplier per vertex ([`super::irregular`]), if any.
    pub(super) irregular: Option<Vec<f64>>,
    /// On a refined cloth, per vertex the coarse element whose fine vertices share one
    /// Kabsch rotation ([`crate::mesh::refine::Partial::congruence`]; `u32::MAX`: none).
    pub(super) congruent: Option<Vec<u32>>,
    /// On a refined cloth, per face its class of similar faces and corner shift
    /// ([`crate::mesh::refine::Partial::face_congruence`]).
    pub(super) face_congruent: Option<Vec<u32>>,
}

/// The part of the cloth a frame works on (module doc): the *active* vertices
/// (every phase), the *held* ones (wet but not flowing: interactions only), and the
/// *halo*, the other corners of their faces, as a mesh of its own.
#[derive(Debug)]
pub(super) struct Window {
    /// Mesh vertex of every window vertex, increasing.
    pub(super) vertices: Vec<u32>,
    /// The window as a mesh of its own (its `boundary` is the cloth's border, not the
    /// window's edge).
    pub(super) cloth: Cloth,
    pub(super) pattern: VertexPattern,
    /// Window vertices that are active or held: their whole one-ring is in the window,
    /// so their areas, frames and interactions are those of the cloth.
    pub(super) whole: Vec<u32>,
    /// The active vertices and the restricted operators on them (window numbering).
    pub(super) region: Restriction,
    pub(super) cg: Option<(WarmCg, WarmCg)>,
    /// On a refined cloth, per window vertex the one whose Kabsch rotation it takes (its
    /// own, or the first active or held vertex of its coarse face or edge, when it is
    /// active or held itself: a whole one-ring), see [`Window::corotating_frames_into`].
    pub(super) share: Option<Vec<u32>>,
    /// On a refined cloth, per window face the window face whose tip angles it takes and
    /// the shift of its corners ([`crate::mesh::Transport::with_shared_tips`]): the first
    /// window face of its coarse face.
    pub(super) tip_share: Option<Vec<(u32, u8)>>,
    /// Per mesh vertex: active.
    pub(super) mask: Vec<bool>,
    /// Per mesh vertex: active or held.
    pub(super) whole_mask: Vec<bool>,
}

impl Window {
    /// The window of the mesh vertices flagged `active` or `held`; `reuse`: the solvers
    /// of a window it replaces, whose memory it takes over.
    pub(super) fn new(
        cloth: &Cloth,
        mask: Vec<bool>,
        held: &[bool],
        reuse: Option<(WarmCg, WarmCg)>,
    ) -> Result<Option<Self>, Error> {
        let topo = &cloth.topology;
        let n = topo.n_vertices();
        let whole_mask: Vec<bool> = (0..n).map(|v| mask[v] || held[v]).collect();
        // the faces of the active and held vertices, in the cloth's order (marked, then
        // read off in order: no sort), and their corners
        let mut face_local = vec![u32::MAX; topo.n_faces()];
        for v in (0..n).filter(|&v| whole_mask[v]) {
            for w in cloth.rings.wedges(v) {
                face_local[w.face as usize] = 0;
            }
        }
        let faces: Vec<u32> = (0..topo.n_faces() as u32)
            .filter(|&f| face_local[f as usize] == 0)
            .collect();
        if faces.is_empty() {
            return Ok(None);
        }
        let mut local = vec![u32::MAX; n];
        for (k, &f) in faces.iter().enumerate() {
            face_local[f as usize] = k as u32;
            for v in topo.faces()[f as usize] {
                local[v as usize] = 0;
            }
        }
        let vertices: Vec<u32> = (0..n as u32).filter(|&v| local[v as usize] == 0).collect();
        for (j, &v) in vertices.iter().enumerate() {
            local[v as usize] = j as u32;
        }
        // the window's edges and fans are the cloth's, renumbered (module doc); the
        // pattern, the restriction and the solvers' analysis need only its topology, so
        // the fans and the rest are derived beside them (the two sides are uneven: one
        // core idles through the end of the larger)
        let (topology, edge_local) = topo.restricted(&faces, &vertices, &local);
        let ((pattern, region, cg), (rings, adjacency, rest, rest_frames, boundary, irregular)) =
            rayon::join(
                || {
                    // the pattern and the restriction need only the window's topology: they
                    // run on the solvers' side too
                    let pattern = VertexPattern::new(&topology);
                    let region = Restriction::new(&pattern, pick(&vertices, &mask));
                    let cg = solvers(&region, reuse);
                    (pattern, region, cg)
                },
                || {
                    let rings = OneRings::restricted(
                        &cloth.rings,
                        &topology,
                        &faces,
                        &vertices,
                        &face_local,
                        &local,
                        &edge_local,
                    );
                    (
                        rings,
                        RingAdjacency::new(&topology),
                        pick(&vertices, &cloth.rest),
                        VertexFrames {
                            frame: pick(&vertices, &cloth.rest_frames.frame),
                        },
                        pick(&vertices, &cloth.boundary),
                        cloth.irregular.as_ref().map(|m| pick(&vertices, m)),
                    )
                },
            );
        let share = cloth.congruent.as_ref().map(|class| {
            // a coarse element's fine vertices are consecutive in the mesh, hence in the
            // window: the first whole one of a run serves the run's whole ones
            let mut run = (u32::MAX, u32::MAX);
            (0..vertices.len() as u32)
                .map(|j| {
                    let v = vertices[j as usize] as usize;
                    let c = class[v];
                    if c == u32::MAX || !whole_mask[v] {
                        return j;
                    }
                    if run.0 != c {
                        run = (c, j);
                    }
                    run.1
                })
                .collect()
        });
        // a coarse face's fine faces are consecutive in the mesh, hence in the window
        let tip_share = cloth
            .face_congruent
            .as_ref()
            .map(|class| crate::mesh::refine::tip_shares(faces.iter().map(|&f| class[f as usize])));
        let part = Cloth {
            rest,
            rest_frames,
            conductivity: cloth.conductivity.faces(&faces),
            boundary,
            irregular,
            topology,
            rings,
            adjacency,
            congruent: None,
            face_congruent: None,
        };
        Ok(Some(Self {
            whole: (0..vertices.len() as u32)
                .filter(|&j| whole_mask[vertices[j as usize] as usize])
                .collect(),
            vertices,
            cloth: part,
            pattern,
            region,
            cg,
            share,
            tip_share,
            mask,
            whole_mask,
        }))
    }

    /// The comoving–corotating frames `F_j = U_j F̄_j` of the window's vertices at
    /// `positions` (window order): one Kabsch rotation per vertex
    /// ([`corotating_frames_into`]), or on a refined cloth one per coarse face and edge
    /// for the fine vertices with whole one-rings there (congruent rings moving
    /// affinely: the same rotation up to rounding, [`crate::mesh::kabsch`]). Into `out`
    /// (its array kept).
    pub(super) fn corotating_frames_into(&self, positions: &[DVec3], out: &mut VertexFrames) {
        let c = &self.cloth;
        match &self.share {
            None => corotating_frames_into(&c.adjacency, &c.rest_frames, &c.rest, positions, out),
            Some(share) => {
                // the rotations `U_j`, then `U_j F̄_j` over them in place
                c.adjacency
                    .shared_rotations(&c.rest, positions, share, &mut out.frame);
                for (u, f) in out.frame.iter_mut().zip(&c.rest_frames.frame) {
                    *u *= *f;
                }
            }
        }
    }
}

/// `values[i]` for every `i` of `index`, in that order.
pub(super) fn pick<T: Copy>(index: &[u32], values: &[T]) -> Vec<T> {
    let mut out = Vec::new();
    pick_into(index, values, &mut out);
    out
}

/// [`pick`] into `out` (its allocation kept).
pub(super) fn pick_into<T: Copy>(index: &[u32], values: &[T], out: &mut Vec<T>) {
    out.clear();
    out.extend(index.iter().map(|&i| values[i as usize]));
}

/// Where the liquid is (module doc): among the vertices `scan`, those holding
/// flowing liquid — free solvent or dissolved solute density above [`ACTIVE_THRESHOLD`]
/// of that field's peak over `scan` — and the others holding absorbed solvent or solute
/// above that fraction of its peak (held). What is left below the thresholds is *dust*
/// (1e-12 of the peaks and less, the far tail of implicit diffusion): it stays where it
/// is, untouched, until liquid comes near again. Loose vertices are neither. Absorbed
/// solvent above the density `mobile_held` (kg/m²) flows too (the fibres' liquid above
/// the residual saturation, issue 13 §2; `INFINITY`: it never does).
pub(super) fn find_liquid(
    scan: &[u32],
    loose: &[bool],
    fields: &Fields,
    area: &[f64],
    mobile_held: f64,
) -> (Vec<u32>, Vec<u32>) {
    let f = fields;
    let by_field = [
        &f.free_solvent,
        &f.solute,
        &f.absorbed_solvent,
        &f.absorbed_solute,
    ];
    // the four peaks in one parallel sweep (a maximum does not depend on the order)
    let peak = scan
        .par_iter()
        .map(|&v| v as usize)
        .filter(|&v| area[v] > 0.0)
        .fold(
            || [0.0; 4],
            |p, v| std::array::from_fn(|k| f64::max(p[k], by_field[k][v] / area[v])),
        )
        .reduce(
            || [0.0; 4],
            |a, b| std::array::from_fn(|k| f64::max(a[k], b[k])),
        );
    let floor = peak.map(|p| ACTIVE_THRESHOLD * p);
    // 1 flowing, 2 held, 0 neither
    let class: Vec<u8> = scan
        .par_iter()
        .map(|&v| {
            let i = v as usize;
            let above = |k: usize| {
                let m = by_field[k][i];
                m > 0.0 && m > floor[k] * area[i]
            };
            if loose[i] {
                0
            } else if above(0) || above(1) || f.absorbed_solvent[i] > mobile_held * area[i] {
                1
            } else if above(2) || above(3) {
                2
            } else {
                0
            }
        })
        .collect();
    let (mut flowing, mut held) = (Vec::new(), Vec::new());
    for (&v, c) in scan.iter().zip(class) {
        match c {
            1 => flowing.push(v),
            2 => held.push(v),
            _ => {}
        }
    }
    (flowing, held)
}

/// `seeds` grown by `rings` rings of neighbours (loose vertices excluded), as a mask and
/// as a list; also the last ring added (to grow further with [`grow_on`]).
pub(super) fn grow(
    adjacency: &RingAdjacency,
    loose: &[bool],
    seeds: &[u32],
    rings: usize,
) -> (Vec<bool>, Vec<u32>, Vec<u32>) {
    let mut mask = vec![false; loose.len()];
    for &v in seeds {
        mask[v as usize] = true;
    }
    let mut all = seeds.to_vec();
    let front = grow_on(adjacency, loose, &mut mask, &mut all, seeds.to_vec(), rings);
    (mask, all, front)
}

/// Grows the region `mask` (listed in `all`) whose last ring is `front` by `rings` more
/// rings: the region [`grow`] would give with that many more rings, without walking the
/// first ones again. Returns the last ring.
pub(super) fn grow_on(
    adjacency: &RingAdjacency,
    loose: &[bool],
    mask: &mut [bool],
    all: &mut Vec<u32>,
    mut front: Vec<u32>,
    rings: usize,
) -> Vec<u32> {
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
    front
}

/// What the next frame's window is to be ([`Simulator::plan_window`]).
///
/// [`Simulator::plan_window`]: super::Simulator::plan_window
pub(super) enum WindowPlan {
    /// The current window still serves.
    Keep,
    /// A new window: its active vertices (`mask`) and the held ones, per cloth vertex.
    Build { mask: Vec<bool>, held: Vec<bool> },
}

impl WindowPlan {
    /// The active and held vertices of a window to build (the window's `whole`), or
    /// `None` to keep the current one.
    pub(super) fn whole(&self) -> Option<impl Iterator<Item = usize> + '_> {
        match self {
            WindowPlan::Keep => None,
            WindowPlan::Build { mask, held } => {
                Some((0..mask.len()).filter(move |&v| mask[v] || held[v]))
            }
        }
    }
}
