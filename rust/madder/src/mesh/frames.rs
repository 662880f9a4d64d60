//! Vertex tangent frames and the discrete Levi-Civita connection (seed §4.3.1, eq. 4.4).
//!
//! The stain's velocity is one 2-D vector `u_i = (u_iˣ, u_iʸ)` per vertex, expressed in a
//! tangent frame `F_i = (x_i, y_i, z_i)` stored at the vertex. Comparing `u_i` with a
//! neighbour's `u_j` needs the rotation `R_ij` that carries a vector written in `F_j` into
//! `F_i` by parallel transport along the edge. This module builds the three ingredients:
//!
//! 1. [`OneRings`] (topology only): the fan of faces around every vertex, ordered
//!    counter-clockwise, and its *spokes* (the neighbours, in the order the fan meets them).
//!    Spoke 0 is the vertex's *reference edge* `e_ik`.
//! 2. [`VertexFrames`] (per frame, extrinsic): `z_i` is the area-weighted average of the
//!    incident face normals, `y_i = (z_i × e_ik) / |z_i × e_ik|`, `x_i = y_i × z_i`: so `x_i`
//!    is the reference edge projected on the tangent plane and `(x_i, y_i, z_i)` is a
//!    right-handed orthonormal frame.
//! 3. [`Connection`] (per frame, intrinsic plus the frames): the geodesic polar map and the
//!    connection angles `θ_ij`.
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
//! ## Connection (eq. 4.4)
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
//! bit for bit (the Bochner Laplacian's symmetry, [`crate::ops::connection`], relies on it).
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
//! [`super::kabsch`]) the reference edge is no longer exactly along `x_i`. [`Connection`]
//! therefore measures, in the given frames, the angle `δ_i` of the reference spoke
//! projected on the `(x_i, y_i)` plane, and uses `α_ij + δ_i` as the angle of spoke `j` in
//! `F_i`. (If the reference spoke is nearly normal to `z_i`, the first spoke `r` that is
//! not gives `δ_i = β_r − α_ir`, `β_r` its projected angle; if none, `δ_i = 0`.) For
//! [`VertexFrames::new`] the offset is zero up to rounding, so the seed's convention is
//! reproduced exactly; the tests check that arbitrarily turned frames keep a flat cloth's
//! transport exact.
//!
//! ## One-ring ordering, non-manifold fans and orientation
//! Blender meshes are usually, not always, consistently oriented. Face orientations are
//! first *harmonized*: a breadth-first walk over faces through edges shared by exactly two
//! faces flips faces so that neighbours agree, and each connected component keeps the
//! orientation of the majority of its faces (so one stray flipped face is corrected, not
//! the rest of the cloth). This is deterministic (lowest face first) and changes nothing on
//! a consistently oriented mesh.
//!
//! The fan of a vertex is then walked wedge to wedge through shared spokes, in the
//! harmonized orientation but without relying on it (an inconsistency left over, on a
//! non-orientable mesh, does not break the walk): a spoke shared by exactly two wedges
//! links them, any other spoke (one wedge: a border; three or more: a non-manifold edge)
//! ends the walk. Walks start, in this priority and in face order, at a wedge entered
//! through an open spoke in its (harmonized) orientation, at a wedge entered through an
//! open spoke against it, then (only closed loops remain) at the first unvisited wedge.
//! Each walk (component) is given the orientation of the majority of its faces (ties keep
//! the walk's), and its wedges record whether they run with or against their face as
//! stored. The vertex normal sums the wedge normals *as walked*, so it always agrees with
//! the counter-clockwise sense of the polar angles.
//!
//! [`FanKind`] classifies the result: `Interior` (one closed loop, the polar map is a
//! disk, `s_i = 2π/γ_i`), `Boundary` (one open fan, `s_i = 1`), `Loose` (no face) and
//! `Irregular` (several fans meeting at the vertex — a bow-tie — or a non-manifold spoke).
//! The polar map of an irregular vertex is not defined; as a fallback its fans are laid
//! side by side in walk order without rescaling, a spoke met twice keeps its first angle,
//! and everything stays finite. An edge whose two endpoints walk a shared face in opposite
//! senses (a Möbius seam) has a reflection, not a rotation, as its true transport; such
//! edges are listed by [`OneRings::orientation_reversing_edges`] so callers can warn.
//!
//! ## Degenerate frames
//! If the wedge normals sum to zero (all faces collapsed, or cancelling sheets), `z_i`
//! falls back to a unit vector perpendicular to the first spoke of non-zero length, or `+Z`
//! if there is none. `x_i` uses the first spoke (in fan order) whose angle to `z_i` has a
//! sine above [`SPOKE_MIN_SINE`] (normally spoke 0); if none has, `x_i` is any unit vector
//! perpendicular to `z_i`. A loose vertex gets the identity frame. No NaN is ever produced.

use std::f64::consts::{PI, TAU};

use glam::{DMat2, DMat3, DVec2, DVec3};
use rayon::prelude::*;

use super::{Geometry, Topology};
use crate::error::MeshError;

/// Smallest sine of the angle between a spoke and the frame normal for the spoke to define
/// the frame's `x` axis (or, in [`Connection`], to measure the frame's offset). Below it
/// the projected direction would carry a relative rounding error above `10⁻¹⁰`.
pub const SPOKE_MIN_SINE: f64 = 1e-6;

/// The shape of the fan of faces around a vertex.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FanKind {
    /// No incident face.
    Loose,
    /// One closed fan: the one-ring is a topological disk around the vertex.
    Interior,
    /// One open fan whose two end spokes are border edges.
    Boundary,
    /// Several fans meeting at the vertex, or a spoke shared by three or more faces.
    Irregular,
}

/// One corner of the fan around a vertex, as the walk passes it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Wedge {
    /// The face.
    pub face: u32,
    /// The face's corner at the vertex (0, 1 or 2).
    pub corner: u8,
    /// `true` if the walk passes the face in its own orientation, i.e. enters through the
    /// spoke to corner `corner + 1` and leaves through the spoke to corner `corner + 2`.
    pub forward: bool,
    /// Local index (into the vertex's spokes) of the spoke the walk enters through.
    pub from: u32,
    /// Local index of the spoke the walk leaves through.
    pub to: u32,
}

/// Ordered fans of faces and spokes around every vertex (topology only).
#[derive(Debug, Clone)]
pub struct OneRings {
    wedge_ptr: Vec<u32>,
    wedges: Vec<Wedge>,
    spoke_ptr: Vec<u32>,
    spoke_vertex: Vec<u32>,
    spoke_edge: Vec<u32>,
    kind: Vec<FanKind>,
    edge_ptr: Vec<u32>,
    edge_end: Vec<u32>,
    /// Per edge `(a, b)`: the index of its spoke among the spokes of `a` and of `b`
    /// (global, into the per-spoke arrays; `u32::MAX` if the edge is in no fan).
    edge_spoke: Vec<[u32; 2]>,
    reversing: Vec<u32>,
    /// Per face: walked against its vertex order.
    flipped: Vec<bool>,
}

/// The walk of one fan component: wedges (index into the vertex's corner list, forward)
/// and whether it closed on itself.
struct Walk {
    steps: Vec<(usize, bool)>,
    closed: bool,
}

impl OneRings {
    /// Orders the fan of every vertex of `topology` (in parallel; deterministic).
    pub fn new(topology: &Topology) -> Self {
        Self::with_orientation(topology, harmonize_orientation(topology))
    }

    /// [`OneRings::new`] with the faces' orientation given: `flipped[f]` if face `f` is
    /// walked against its own vertex order. A part of a mesh cut out with the whole
    /// mesh's [`OneRings::face_flipped`] walks every fan it shares with the whole mesh in
    /// the same sense (its own harmonization could choose another on a part that does
    /// not reach the whole mesh's deciding faces).
    ///
    /// # Panics
    /// If `flipped` does not have one flag per face.
    pub fn with_orientation(topology: &Topology, flipped: Vec<bool>) -> Self {
        assert_eq!(flipped.len(), topology.n_faces(), "one flag per face");
        let n = topology.n_vertices();
        let faces = topology.faces();
        // vertex → incident (face, corner), in face order
        let (corner_ptr, corners) = incidence(n, faces);
        // edge lookup: edges are sorted by (a, b), so those starting at a are contiguous
        let edges = topology.edges();
        let mut edge_ptr = vec![0u32; n + 1];
        for &[a, _] in edges {
            edge_ptr[a as usize + 1] += 1;
        }
        for v in 0..n {
            edge_ptr[v + 1] += edge_ptr[v];
        }
        let edge_end: Vec<u32> = edges.iter().map(|&[_, b]| b).collect();
        let lookup = |i: u32, j: u32| find_edge(&edge_ptr, &edge_end, i, j);

        let fans: Vec<(Vec<Wedge>, Vec<u32>, FanKind)> = (0..n)
            .into_par_iter()
            .map(|v| {
                let c = &corners[corner_ptr[v] as usize..corner_ptr[v + 1] as usize];
                order_fan(faces, &flipped, c)
            })
            .collect();

        let mut wedge_ptr = Vec::with_capacity(n + 1);
        let mut spoke_ptr = Vec::with_capacity(n + 1);
        wedge_ptr.push(0u32);
        spoke_ptr.push(0u32);
        let mut wedges = Vec::with_capacity(corners.len());
        let mut spoke_vertex = Vec::new();
        let mut spoke_edge = Vec::new();
        let mut kind = Vec::with_capacity(n);
        for (v, (w, s, k)) in fans.into_iter().enumerate() {
            wedges.extend_from_slice(&w);
            for &j in &s {
                spoke_edge.push(lookup(v as u32, j).expect("a spoke is an edge") as u32);
            }
            spoke_vertex.extend_from_slice(&s);
            kind.push(k);
            wedge_ptr.push(wedges.len() as u32);
            spoke_ptr.push(spoke_vertex.len() as u32);
        }

        // sense in which each face corner is walked; an edge is orientation-reversing if a
        // face on it is walked forward at one end and backward at the other
        let mut corner_forward = vec![[true; 3]; faces.len()];
        for w in &wedges {
            corner_forward[w.face as usize][w.corner as usize] = w.forward;
        }
        let mut reversing: Vec<u32> = Vec::new();
        for (fe, fwd) in topology.face_edges().iter().zip(&corner_forward) {
            for k in 0..3 {
                if fwd[(k + 1) % 3] != fwd[(k + 2) % 3] {
                    reversing.push(fe[k]);
                }
            }
        }
        reversing.sort_unstable();
        reversing.dedup();

        // a vertex's spokes are distinct neighbours, so every edge is met once per end
        let mut edge_spoke = vec![[u32::MAX; 2]; edges.len()];
        for v in 0..n {
            for s in spoke_ptr[v]..spoke_ptr[v + 1] {
                let e = spoke_edge[s as usize] as usize;
                edge_spoke[e][usize::from(edges[e][0] as usize != v)] = s;
            }
        }

        Self {
            wedge_ptr,
            wedges,
            spoke_ptr,
            spoke_vertex,
            spoke_edge,
            kind,
            edge_ptr,
            edge_end,
            edge_spoke,
            reversing,
            flipped,
        }
    }

    /// Per face: whether the fans walk it against its own vertex order (the harmonized
    /// orientation).
    pub fn face_flipped(&self) -> &[bool] {
        &self.flipped
    }

    pub fn n_vertices(&self) -> usize {
        self.kind.len()
    }

    /// The fan of vertex `v`, in walk (counter-clockwise) order.
    pub fn wedges(&self, v: usize) -> &[Wedge] {
        &self.wedges[self.wedge_ptr[v] as usize..self.wedge_ptr[v + 1] as usize]
    }

    /// Neighbours of `v` in the order the fan meets them; spoke 0 is the reference edge.
    pub fn spokes(&self, v: usize) -> &[u32] {
        &self.spoke_vertex[self.spoke_ptr[v] as usize..self.spoke_ptr[v + 1] as usize]
    }

    /// Edge index (into [`Topology::edges`]) of every spoke of `v`.
    pub fn spoke_edges(&self, v: usize) -> &[u32] {
        &self.spoke_edge[self.spoke_ptr[v] as usize..self.spoke_ptr[v + 1] as usize]
    }

    /// Offset of vertex `v`'s spokes in arrays laid out per spoke (like
    /// [`Connection::polar_angles`]).
    pub fn spoke_offset(&self, v: usize) -> usize {
        self.spoke_ptr[v] as usize
    }

    pub fn kind(&self, v: usize) -> FanKind {
        self.kind[v]
    }

    /// Index of the edge between `i` and `j`, if any.
    pub fn edge_between(&self, i: usize, j: usize) -> Option<usize> {
        find_edge(&self.edge_ptr, &self.edge_end, i as u32, j as u32)
    }

    /// Edges across which the two endpoints' fans have opposite senses (a non-orientable
    /// mesh's seam): their true transport is a reflection, which [`Connection`] cannot
    /// express. Empty on any orientable mesh, however its faces are oriented.
    pub fn orientation_reversing_edges(&self) -> &[u32] {
        &self.reversing
    }
}

fn find_edge(edge_ptr: &[u32], edge_end: &[u32], i: u32, j: u32) -> Option<usize> {
    let (a, b) = (i.min(j) as usize, i.max(j));
    if a == b as usize || a + 1 >= edge_ptr.len() {
        return None;
    }
    let (lo, hi) = (edge_ptr[a] as usize, edge_ptr[a + 1] as usize);
    edge_end[lo..hi].binary_search(&b).ok().map(|k| lo + k)
}

/// Groups per-face triples of keys (vertices or edges, `< n`) by key with a counting sort:
/// `items[ptr[k]..ptr[k+1]]` are the `(face, slot)` where key `k` appears, in face order.
fn incidence(n: usize, per_face: &[[u32; 3]]) -> (Vec<u32>, Vec<(u32, u8)>) {
    let mut ptr = vec![0u32; n + 1];
    for t in per_face {
        for &k in t {
            ptr[k as usize + 1] += 1;
        }
    }
    for k in 0..n {
        ptr[k + 1] += ptr[k];
    }
    let mut next = ptr[..n].to_vec();
    let mut items = vec![(0u32, 0u8); ptr[n] as usize];
    for (f, t) in per_face.iter().enumerate() {
        for (slot, &k) in t.iter().enumerate() {
            items[next[k as usize] as usize] = (f as u32, slot as u8);
            next[k as usize] += 1;
        }
    }
    (ptr, items)
}

/// Which faces to flip so that every edge shared by exactly two faces is crossed
/// consistently: a breadth-first walk over faces through such edges, from the
/// lowest-numbered face of each connected component; each component then keeps the
/// orientation of the majority of its faces (ties: that of its first face). On a
/// non-orientable component some edges stay inconsistent whatever the flips.
fn harmonize_orientation(topology: &Topology) -> Vec<bool> {
    let (faces, face_edges) = (topology.faces(), topology.face_edges());
    let n_edges = topology.n_edges();
    // edge → its incident (face, corner opposite the edge)
    let (ptr, inc) = incidence(n_edges, face_edges);
    // the edge as face f walks it, from corner k+1 to corner k+2
    let run = |f: u32, k: u8| {
        let t = faces[f as usize];
        (t[(k as usize + 1) % 3], t[(k as usize + 2) % 3])
    };
    let mut flipped = vec![false; faces.len()];
    let mut seen = vec![false; faces.len()];
    let mut queue = std::collections::VecDeque::new();
    let mut component = Vec::new();
    for root in 0..faces.len() {
        if seen[root] {
            continue;
        }
        seen[root] = true;
        queue.push_back(root as u32);
        component.clear();
        while let Some(f) = queue.pop_front() {
            component.push(f);
            for (k, &e) in face_edges[f as usize].iter().enumerate() {
                let pair = &inc[ptr[e as usize] as usize..ptr[e as usize + 1] as usize];
                if pair.len() != 2 {
                    continue;
                }
                let (g, l) = if pair[0].0 == f { pair[1] } else { pair[0] };
                if seen[g as usize] {
                    continue;
                }
                // consistent faces walk their shared edge in opposite directions
                let (a, b) = run(f, k as u8);
                let consistent = run(g, l) == (b, a);
                flipped[g as usize] = flipped[f as usize] == consistent;
                seen[g as usize] = true;
                queue.push_back(g);
            }
        }
        let n_flipped = component.iter().filter(|&&f| flipped[f as usize]).count();
        if 2 * n_flipped > component.len() {
            component.iter().for_each(|&f| flipped[f as usize] ^= true);
        }
    }
    flipped
}

/// Orders the fan of one vertex from its incident `(face, corner)` list, walking faces in
/// their harmonized orientation (`flipped`).
fn order_fan(
    faces: &[[u32; 3]],
    flipped: &[bool],
    corners: &[(u32, u8)],
) -> (Vec<Wedge>, Vec<u32>, FanKind) {
    let m = corners.len();
    if m == 0 {
        return (Vec::new(), Vec::new(), FanKind::Loose);
    }
    // the two spokes of each wedge in the face's harmonized orientation
    let ends: Vec<[u32; 2]> = corners
        .iter()
        .map(|&(f, k)| {
            let t = faces[f as usize];
            let (p, q) = (t[(k as usize + 1) % 3], t[(k as usize + 2) % 3]);
            if flipped[f as usize] { [q, p] } else { [p, q] }
        })
        .collect();
    // spoke → wedges touching it
    let mut touch: Vec<(u32, u32)> = Vec::with_capacity(2 * m);
    for (w, e) in ends.iter().enumerate() {
        touch.push((e[0], w as u32));
        touch.push((e[1], w as u32));
    }
    touch.sort_unstable();
    let touching = |s: u32| {
        let lo = touch.partition_point(|&(x, _)| x < s);
        let hi = touch.partition_point(|&(x, _)| x <= s);
        &touch[lo..hi]
    };
    let open = |s: u32| touching(s).len() != 2;

    let mut visited = vec![false; m];
    let mut walks: Vec<Walk> = Vec::new();
    let mut n_visited = 0;
    while n_visited < m {
        let start = (0..m)
            .find(|&w| !visited[w] && open(ends[w][0]))
            .map(|w| (w, true))
            .or_else(|| {
                (0..m)
                    .find(|&w| !visited[w] && open(ends[w][1]))
                    .map(|w| (w, false))
            })
            .or_else(|| (0..m).find(|&w| !visited[w]).map(|w| (w, true)))
            .expect("an unvisited wedge remains");
        let (mut w, mut fwd) = start;
        let first_spoke = ends[w][if fwd { 0 } else { 1 }];
        let mut steps = Vec::new();
        let closed = loop {
            visited[w] = true;
            n_visited += 1;
            steps.push((w, fwd));
            let exit = ends[w][if fwd { 1 } else { 0 }];
            let t = touching(exit);
            if t.len() != 2 {
                break false;
            }
            let other = if t[0].1 as usize == w { t[1].1 } else { t[0].1 } as usize;
            if visited[other] {
                break exit == first_spoke && other == start.0;
            }
            w = other;
            fwd = ends[w][0] == exit;
        };
        // give the walk the orientation of the majority of its faces
        let n_fwd = steps.iter().filter(|s| s.1).count();
        if 2 * n_fwd < steps.len() {
            steps.reverse();
            steps.iter_mut().for_each(|s| s.1 = !s.1);
        }
        walks.push(Walk { steps, closed });
    }

    // spokes in order of first meeting; wedges refer to them by local index
    let mut distinct: Vec<u32> = touch.iter().map(|t| t.0).collect();
    distinct.dedup();
    let mut local = vec![u32::MAX; distinct.len()];
    let mut spokes: Vec<u32> = Vec::with_capacity(distinct.len());
    let mut slot = |s: u32, spokes: &mut Vec<u32>| {
        let k = distinct.binary_search(&s).expect("a wedge's spoke");
        if local[k] == u32::MAX {
            local[k] = spokes.len() as u32;
            spokes.push(s);
        }
        local[k]
    };
    let mut wedges = Vec::with_capacity(m);
    for walk in &walks {
        for &(w, fwd) in &walk.steps {
            let (a, b) = if fwd {
                (ends[w][0], ends[w][1])
            } else {
                (ends[w][1], ends[w][0])
            };
            let from = slot(a, &mut spokes);
            let to = slot(b, &mut spokes);
            wedges.push(Wedge {
                face: corners[w].0,
                corner: corners[w].1,
                forward: fwd != flipped[corners[w].0 as usize],
                from,
                to,
            });
        }
    }
    let manifold = spokes.iter().all(|&s| touching(s).len() <= 2);
    let kind = match (walks.len(), manifold) {
        (1, true) if walks[0].closed => FanKind::Interior,
        (1, true) => FanKind::Boundary,
        _ => FanKind::Irregular,
    };
    (wedges, spokes, kind)
}

/// Per-vertex orthonormal tangent frames (columns `x, y, z`; `z` the vertex normal).
#[derive(Debug, Clone, PartialEq)]
pub struct VertexFrames {
    pub frame: Vec<DMat3>,
}

impl VertexFrames {
    /// The frames of §4.3.1 at `positions`: `z_i` the area-weighted vertex normal, `x_i`
    /// the reference spoke projected on the tangent plane (see the module doc for the
    /// degenerate fallbacks). Fails, naming the first bad vertex, on a wrong number of
    /// positions or a non-finite one.
    pub fn new(rings: &OneRings, positions: &[DVec3]) -> Result<Self, MeshError> {
        if positions.len() != rings.n_vertices() {
            return Err(MeshError::VertexCountMismatch {
                expected: rings.n_vertices(),
                got: positions.len(),
            });
        }
        if let Some(vertex) = positions.iter().position(|p| !p.is_finite()) {
            return Err(MeshError::NonFinitePosition { vertex });
        }
        let frame = (0..rings.n_vertices())
            .into_par_iter()
            .map(|v| {
                let p = positions[v];
                let spoke: Vec<DVec3> = rings
                    .spokes(v)
                    .iter()
                    .map(|&j| positions[j as usize] - p)
                    .collect();
                if spoke.is_empty() {
                    return DMat3::IDENTITY;
                }
                let z = vertex_normal(rings.wedges(v), &spoke);
                let x = spoke
                    .iter()
                    .find_map(|&e| tangent_direction(e, z))
                    .unwrap_or_else(|| z.any_orthonormal_vector());
                DMat3::from_cols(x, z.cross(x), z)
            })
            .collect();
        Ok(Self { frame })
    }

    /// Frames `F_i = U_i F̄_i` turned by one rotation per vertex (the comoving–corotating
    /// frames of §4.4, with `U_i` from [`super::kabsch::one_ring_rotations`]).
    pub fn rotated(&self, rotation: &[DMat3]) -> Self {
        assert_eq!(rotation.len(), self.frame.len(), "one rotation per vertex");
        Self {
            frame: self
                .frame
                .iter()
                .zip(rotation)
                .map(|(f, u)| *u * *f)
                .collect(),
        }
    }

    pub fn len(&self) -> usize {
        self.frame.len()
    }
    pub fn is_empty(&self) -> bool {
        self.frame.is_empty()
    }

    /// The 3-D vector `u.x x_i + u.y y_i` of tangent components `u` at vertex `i`.
    pub fn to_world(&self, i: usize, u: DVec2) -> DVec3 {
        let f = &self.frame[i];
        u.x * f.x_axis + u.y * f.y_axis
    }

    /// Tangent components `(w·x_i, w·y_i)` of a 3-D vector `w` at vertex `i` (its normal
    /// part is dropped).
    pub fn to_local(&self, i: usize, w: DVec3) -> DVec2 {
        let f = &self.frame[i];
        DVec2::new(w.dot(f.x_axis), w.dot(f.y_axis))
    }
}

/// Unit normal from the wedge normals as walked (each `e_from × e_to`, twice the face's
/// area times its normal), with the fallbacks of the module doc.
fn vertex_normal(wedges: &[Wedge], spoke: &[DVec3]) -> DVec3 {
    let n = wedges.iter().fold(DVec3::ZERO, |acc, w| {
        acc + spoke[w.from as usize].cross(spoke[w.to as usize])
    });
    let z = n.normalize_or_zero();
    if z != DVec3::ZERO {
        return z;
    }
    spoke
        .iter()
        .map(|e| e.normalize_or_zero())
        .find(|e| *e != DVec3::ZERO)
        .map_or(DVec3::Z, |e| e.any_orthonormal_vector())
}

/// Unit projection of `e` on the plane normal to `z`, if it is well defined.
fn tangent_direction(e: DVec3, z: DVec3) -> Option<DVec3> {
    let t = e - e.dot(z) * z;
    let (lt, le) = (t.length(), e.length());
    (le > 0.0 && lt > SPOKE_MIN_SINE * le).then(|| t / lt)
}

/// Tip angles of the three corners of every face from the intrinsic edge lengths (in
/// parallel; each corner's angle is computed once and read by the fan of its vertex).
fn tip_angles(topology: &Topology, geometry: &Geometry) -> Vec<[f64; 3]> {
    topology
        .face_edges()
        .par_iter()
        .zip(&geometry.face_area)
        .map(|(fe, &area)| {
            let l = |c: usize| geometry.edge_length[fe[c % 3] as usize];
            std::array::from_fn(|k| {
                let (a, b, c) = (l(k), l(k + 1), l(k + 2));
                (4.0 * area).atan2(b * b + c * c - a * a)
            })
        })
        .collect()
}

/// The discrete connection of §4.3.1: polar angles `α_ij` per spoke and connection angles
/// `θ_ij` per edge, in given vertex frames.
#[derive(Debug, Clone)]
pub struct Connection {
    /// Polar angle of every spoke (laid out like [`OneRings::spokes`]), measured from the
    /// reference spoke, counter-clockwise, rescaled.
    alpha: Vec<f64>,
    spoke_ptr: Vec<u32>,
    angle_sum: Vec<f64>,
    offset: Vec<f64>,
    theta: Vec<f64>,
    /// `(cos θ_ab, sin θ_ab)` per edge: the rotation, computed once per frame.
    cos_sin: Vec<[f64; 2]>,
    edge_ptr: Vec<u32>,
    edge_end: Vec<u32>,
}

impl Connection {
    /// The connection of `topology` with ordered fans `rings` and intrinsic `geometry`,
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
        let n = topology.n_vertices();
        assert_eq!(rings.n_vertices(), n, "rings of another topology");
        assert_eq!(frames.len(), n, "one frame per vertex");
        assert_eq!(positions.len(), n, "one position per vertex");
        let tip = tip_angles(topology, geometry);
        // polar angles written in place: one slice of the flat array per vertex
        let mut alpha = vec![f64::NAN; rings.spoke_vertex.len()];
        let mut slices: Vec<&mut [f64]> = Vec::with_capacity(n);
        let mut rest = alpha.as_mut_slice();
        for v in 0..n {
            let (head, tail) = rest.split_at_mut(rings.spokes(v).len());
            slices.push(head);
            rest = tail;
        }
        let (angle_sum, offset): (Vec<f64>, Vec<f64>) = slices
            .into_par_iter()
            .enumerate()
            .map(|(v, alpha)| {
                let gamma = polar_map(rings, &tip, v, alpha);
                let offset = frame_offset(rings, v, alpha, &frames.frame[v], positions);
                (gamma, offset)
            })
            .unzip();
        // θ_ab from the angle of each edge in the frame of each endpoint, and its rotation
        let edges = topology.edges();
        let (theta, cos_sin): (Vec<f64>, Vec<[f64; 2]>) = edges
            .par_iter()
            .zip(&rings.edge_spoke)
            .map(|(&[a, b], &[sa, sb])| {
                let angle = |v: u32, s: u32| match alpha.get(s as usize) {
                    Some(&x) => x + offset[v as usize],
                    None => f64::NAN,
                };
                let (ta, tb) = (angle(a, sa), angle(b, sb));
                debug_assert!(ta.is_finite() && tb.is_finite(), "every edge is in a fan");
                let theta = wrap_angle(ta - tb + PI);
                let (sin, cos) = theta.sin_cos();
                (theta, [cos, sin])
            })
            .unzip();
        Self {
            alpha,
            spoke_ptr: rings.spoke_ptr.clone(),
            angle_sum,
            offset,
            theta,
            cos_sin,
            edge_ptr: rings.edge_ptr.clone(),
            edge_end: rings.edge_end.clone(),
        }
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
    pub fn edge_cos_sin(&self) -> &[[f64; 2]] {
        &self.cos_sin
    }

    /// `R_ab` of edge `e = (a, b)`, `a < b` (transport from `F_b` to `F_a`); the same
    /// matrix as `DMat2::from_angle(θ_ab)`, from the stored cosine and sine.
    pub fn edge_rotation(&self, e: usize) -> DMat2 {
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

/// `a` wrapped to `(−π, π]`.
fn wrap_angle(a: f64) -> f64 {
    let r = (a + PI).rem_euclid(TAU) - PI;
    if r == -PI { PI } else { r }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fan(closed: bool) -> (Topology, Vec<DVec3>) {
        // vertex 0 at the centre of a hexagon, faces counter-clockwise seen from +z
        let mut p = vec![DVec3::ZERO];
        for k in 0..6 {
            let t = TAU * k as f64 / 6.0;
            p.push(DVec3::new(t.cos(), t.sin(), 0.0));
        }
        let n = if closed { 6 } else { 4 };
        let faces = (0..n)
            .map(|k| [0, 1 + k as u32, 1 + ((k + 1) % 6) as u32])
            .collect();
        (Topology::from_triangles(7, faces).unwrap(), p)
    }

    #[test]
    fn closed_fan_is_interior_and_ordered_counter_clockwise() {
        let (t, p) = fan(true);
        let r = OneRings::new(&t);
        assert_eq!(r.kind(0), FanKind::Interior);
        assert_eq!(r.spokes(0), &[1, 2, 3, 4, 5, 6]);
        assert!(r.wedges(0).iter().all(|w| w.forward));
        assert_eq!(r.kind(1), FanKind::Boundary);
        // vertex 1 = (1, 0) is on the border: counter-clockwise, its spokes point at 120°
        // (vertex 2, a border edge: the walk starts there), 180° (0) and 240° (6)
        assert_eq!(r.spokes(1), &[2, 0, 6]);
        let f = VertexFrames::new(&r, &p).unwrap();
        assert!((f.frame[0].z_axis - DVec3::Z).length() < 1e-15);
        assert!((f.frame[0].x_axis - DVec3::X).length() < 1e-15);
        assert!((f.frame[0].y_axis - DVec3::Y).length() < 1e-15);
        let g = Geometry::new(&t, &p).unwrap();
        let c = Connection::new(&t, &r, &g, &f, &p);
        for (k, a) in c.polar_angles(0).iter().enumerate() {
            assert!((a - TAU * k as f64 / 6.0).abs() < 1e-14, "spoke {k}: {a}");
        }
        assert!((c.angle_sum(0) - TAU).abs() < 1e-14);
    }

    #[test]
    fn open_fan_is_not_rescaled() {
        let (t, p) = fan(false);
        let r = OneRings::new(&t);
        assert_eq!(r.kind(0), FanKind::Boundary);
        let f = VertexFrames::new(&r, &p).unwrap();
        let g = Geometry::new(&t, &p).unwrap();
        let c = Connection::new(&t, &r, &g, &f, &p);
        assert!((c.angle_sum(0) - 4.0 * TAU / 6.0).abs() < 1e-14);
        assert!((c.polar_angles(0)[4] - 4.0 * TAU / 6.0).abs() < 1e-14);
    }

    #[test]
    fn wrap_angle_range() {
        for a in [-7.0, -PI, -1.0, 0.0, 1.0, PI, 4.0, 13.0] {
            let w = wrap_angle(a);
            assert!(w > -PI && w <= PI);
            assert!(((a - w) / TAU - ((a - w) / TAU).round()).abs() < 1e-12);
        }
    }

    #[test]
    fn edge_lookup() {
        let (t, _) = fan(true);
        let r = OneRings::new(&t);
        for (e, &[a, b]) in t.edges().iter().enumerate() {
            assert_eq!(r.edge_between(a as usize, b as usize), Some(e));
            assert_eq!(r.edge_between(b as usize, a as usize), Some(e));
        }
        assert_eq!(r.edge_between(1, 4), None);
        assert_eq!(r.edge_between(3, 3), None);
    }
}
