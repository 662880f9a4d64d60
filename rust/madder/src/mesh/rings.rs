//! One-ring fans (seed §4.3.1): the topology-lifetime structures around every vertex,
//! built once per mesh and read by every frame.
//!
//! - [`OneRings`]: the fan of faces around every vertex, ordered counter-clockwise, and its
//!   *spokes* (the neighbours, in the order the fan meets them). Spoke 0 is the vertex's
//!   *reference edge* `e_ik`, which the vertex frames ([`super::frames`]) and the polar map
//!   of the transport ([`super::transport`]) measure angles from.
//! - [`RingAdjacency`]: the neighbours of every vertex in edge order, the sum the one-ring
//!   rotations of §4.4 ([`super::kabsch`]) run over.
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

use rayon::prelude::*;

use super::{EdgeKind, Topology};
use crate::runs::carve;

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
    pub(super) spoke_ptr: Vec<u32>,
    pub(super) spoke_vertex: Vec<u32>,
    spoke_edge: Vec<u32>,
    kind: Vec<FanKind>,
    pub(super) edge_ptr: Vec<u32>,
    pub(super) edge_end: Vec<u32>,
    /// Per edge `(a, b)`: the index of its spoke among the spokes of `a` and of `b`
    /// (global, into the per-spoke arrays; `u32::MAX` if the edge is in no fan).
    pub(super) edge_spoke: Vec<[u32; 2]>,
    reversing: Vec<u32>,
    /// Per face: walked against its vertex order.
    flipped: Vec<bool>,
}

/// Working memory of [`order_fan`], reused from vertex to vertex (one per chunk of
/// vertices: a million vertices would otherwise cost ten million small allocations).
#[derive(Default)]
struct FanScratch {
    /// The two spokes of each wedge in its face's harmonized orientation.
    ends: Vec<[u32; 2]>,
    /// The same as indices into `distinct`.
    end_slot: Vec<[u32; 2]>,
    /// (spoke, wedge) for both spokes of every wedge, sorted (large fans).
    touch: Vec<(u32, u32)>,
    /// Per distinct spoke: how many wedges touch it, and the first two in wedge order.
    count: Vec<u32>,
    first: Vec<[usize; 2]>,
    visited: Vec<bool>,
    /// The walks of the fan's components, one after another: (wedge, forward).
    steps: Vec<(usize, bool)>,
    /// Per walk: its range in `steps` and whether it closed on itself.
    walks: Vec<(usize, usize, bool)>,
    /// The distinct spokes (sorted for a large fan, in order of appearance for a small
    /// one) and their local index, once met.
    distinct: Vec<u32>,
    local: Vec<u32>,
}

/// A run of vertices' slots in the rings' wedge array, filled in order (a wedge per
/// corner, so a run's place is known before its fans are walked).
struct Laid<'a> {
    slots: &'a mut [Wedge],
    len: usize,
}

impl Laid<'_> {
    fn push(&mut self, w: Wedge) {
        self.slots[self.len] = w;
        self.len += 1;
    }
}

/// The rest of a run of vertices' fans, laid end to end as in [`OneRings`] and joined
/// afterwards ([`OneRings::assemble`]): spokes, their edges, and per vertex the spokes it
/// added and the fan's kind.
struct Fans {
    spokes: Vec<u32>,
    spoke_edges: Vec<u32>,
    counts: Vec<u32>,
    kind: Vec<FanKind>,
}

/// The wedge every slot holds until its fan is laid.
const UNLAID: Wedge = Wedge {
    face: u32::MAX,
    corner: 0,
    forward: false,
    from: u32::MAX,
    to: u32::MAX,
};

/// Vertices per run of fans laid by one task.
const CHUNK: usize = 4096;

/// The fans of `n` vertices whose corners are `corners[corner_ptr[v]..corner_ptr[v + 1]]`,
/// each laid by `fan` (which pushes one wedge per corner), in runs of [`CHUNK`] vertices
/// side by side: the wedge array (in vertex order, `corner_ptr` its offsets) and each
/// run's spokes. Writing the wedges in place saves copying every run's wedges into the
/// rings afterwards on one thread (96 MB at a million vertices; ARCHITECTURE "Stain
/// detail", the sixth look).
fn lay_fans(
    n: usize,
    corner_ptr: &[u32],
    corners: &[(u32, u8)],
    fan: impl Fn(usize, &[(u32, u8)], &mut FanScratch, &mut Laid<'_>, &mut Fans) -> FanKind + Sync,
) -> (Vec<Wedge>, Vec<Fans>) {
    let mut wedges = Vec::with_capacity(corners.len());
    // filled side by side, so that the fresh pages are taken on both threads
    wedges.par_extend(rayon::iter::repeat_n(UNLAID, corners.len()));
    let ranges: Vec<_> = (0..n.div_ceil(CHUNK))
        .map(|c| c * CHUNK..n.min((c + 1) * CHUNK))
        .collect();
    let lens = ranges
        .iter()
        .map(|r| (corner_ptr[r.end] - corner_ptr[r.start]) as usize);
    let runs = carve(&mut wedges, lens);
    let fans = ranges
        .into_par_iter()
        .zip(runs)
        .map(|(range, run)| {
            let mut scratch = FanScratch::default();
            let spokes = run.len() + range.len();
            let mut laid = Laid { slots: run, len: 0 };
            let mut out = Fans {
                spokes: Vec::with_capacity(spokes),
                spoke_edges: Vec::with_capacity(spokes),
                counts: Vec::with_capacity(range.len()),
                kind: Vec::with_capacity(range.len()),
            };
            let base = corner_ptr[range.start];
            for v in range {
                let cs = &corners[corner_ptr[v] as usize..corner_ptr[v + 1] as usize];
                let s0 = out.spokes.len();
                let kind = fan(v, cs, &mut scratch, &mut laid, &mut out);
                debug_assert_eq!(
                    laid.len as u32,
                    corner_ptr[v + 1] - base,
                    "a wedge per corner"
                );
                out.counts.push((out.spokes.len() - s0) as u32);
                out.kind.push(kind);
            }
            assert_eq!(laid.len, laid.slots.len(), "a wedge per corner");
            out
        })
        .collect();
    (wedges, fans)
}

/// `parts` end to end, each copied into its own slice of the result side by side.
fn joined<T: Copy + Send + Sync>(parts: &[&[T]], fill: T) -> Vec<T> {
    let total = parts.iter().map(|p| p.len()).sum();
    let mut out = Vec::with_capacity(total);
    out.par_extend(rayon::iter::repeat_n(fill, total));
    carve(&mut out, parts.iter().map(|p| p.len()))
        .into_par_iter()
        .zip(parts)
        .for_each(|(place, part)| place.copy_from_slice(part));
    out
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
    pub(crate) fn with_orientation(topology: &Topology, flipped: Vec<bool>) -> Self {
        assert_eq!(flipped.len(), topology.n_faces(), "one flag per face");
        let n = topology.n_vertices();
        let faces = topology.faces();
        // vertex → incident (face, corner), in face order
        let (corner_ptr, corners) = incidence(n, faces);
        let (edge_ptr, edge_end) = edge_index(topology);
        let face_edges = topology.face_edges();

        // in runs of vertices side by side, each laid out as the whole is
        let (wedges, fans) = lay_fans(n, &corner_ptr, &corners, |_, cs, scratch, laid, out| {
            order_fan(faces, face_edges, &flipped, cs, scratch, laid, out)
        });
        Self::assemble(
            topology, flipped, edge_ptr, edge_end, corner_ptr, wedges, fans,
        )
    }

    /// The fans of `topology`, a part of the mesh of `parent` cut out by
    /// [`Topology::restricted`], walked in the parent's orientation: what
    /// [`OneRings::with_orientation`] with the parent's [`OneRings::face_flipped`] builds,
    /// without walking again the fans the part has whole. The walk of a fan depends only
    /// on its corners in face order and on the order of the vertex numbers, which the
    /// renumbering keeps, so a vertex with all its parent's faces has the parent's fan
    /// with faces, spokes and edges renumbered; only the others (the part's rim) are
    /// walked. `face_parent`, `vertex_parent`: the parent's face and vertex of each of
    /// the part's; `face_local`, `vertex_local`, `edge_local`: the part's face, vertex and
    /// edge of each of the parent's (`u32::MAX` where none).
    pub(crate) fn restricted(
        parent: &OneRings,
        topology: &Topology,
        face_parent: &[u32],
        vertex_parent: &[u32],
        face_local: &[u32],
        vertex_local: &[u32],
        edge_local: &[u32],
    ) -> Self {
        let flipped: Vec<bool> = face_parent
            .iter()
            .map(|&f| parent.flipped[f as usize])
            .collect();
        let maps = [face_local, vertex_local, edge_local];
        Self::derived(parent, topology, flipped, vertex_parent, maps)
    }

    /// The fans of `topology`, grown from the mesh of `old` by faces and vertices appended
    /// ([`Topology::extended`], whose edge map `old_new` it takes), walked in the
    /// orientation `flipped`: a vertex that has no new face keeps its fan (edges
    /// renumbered), the others are walked. As [`OneRings::restricted`], the same as
    /// [`OneRings::with_orientation`] on the grown mesh.
    pub(crate) fn extended(
        old: &OneRings,
        topology: &Topology,
        flipped: Vec<bool>,
        old_new: &[u32],
    ) -> Self {
        let n_old = old.n_vertices() as u32;
        let vertex_parent: Vec<u32> = (0..topology.n_vertices() as u32)
            .map(|v| if v < n_old { v } else { u32::MAX })
            .collect();
        let faces: Vec<u32> = (0..old.flipped.len() as u32).collect();
        let maps = [&faces[..], &vertex_parent[..n_old as usize], old_new];
        Self::derived(old, topology, flipped, &vertex_parent, maps)
    }

    /// [`OneRings::restricted`] and [`OneRings::extended`]: vertex `v` of `topology`
    /// takes the fan of `parent`'s vertex `vertex_parent[v]` (`u32::MAX`: none) when it
    /// has as many corners, through the maps `[face, vertex, edge]` of `parent`'s numbers
    /// to `topology`'s; any other is walked.
    fn derived(
        parent: &OneRings,
        topology: &Topology,
        flipped: Vec<bool>,
        vertex_parent: &[u32],
        [face_local, vertex_local, edge_local]: [&[u32]; 3],
    ) -> Self {
        let n = topology.n_vertices();
        let faces = topology.faces();
        let (corner_ptr, corners) = incidence(n, faces);
        let (edge_ptr, edge_end) = edge_index(topology);
        let face_edges = topology.face_edges();
        let (wedges, fans) = lay_fans(n, &corner_ptr, &corners, |v, cs, scratch, laid, out| {
            let pv = vertex_parent[v] as usize;
            if pv != u32::MAX as usize && cs.len() == parent.wedges(pv).len() {
                // the whole fan: the parent's, renumbered
                for w in parent.wedges(pv) {
                    laid.push(Wedge {
                        face: face_local[w.face as usize],
                        ..*w
                    });
                }
                out.spokes
                    .extend(parent.spokes(pv).iter().map(|&s| vertex_local[s as usize]));
                out.spoke_edges.extend(
                    parent
                        .spoke_edges(pv)
                        .iter()
                        .map(|&e| edge_local[e as usize]),
                );
                parent.kind(pv)
            } else {
                order_fan(faces, face_edges, &flipped, cs, scratch, laid, out)
            }
        });
        Self::assemble(
            topology, flipped, edge_ptr, edge_end, corner_ptr, wedges, fans,
        )
    }

    /// Joins the fans laid by [`lay_fans`] (wedges in place, `corner_ptr` their offsets;
    /// the runs' spokes in vertex order) into the rings of `topology`, with the
    /// orientation-reversing edges and the edges' spokes.
    fn assemble(
        topology: &Topology,
        flipped: Vec<bool>,
        edge_ptr: Vec<u32>,
        edge_end: Vec<u32>,
        corner_ptr: Vec<u32>,
        wedges: Vec<Wedge>,
        fans: Vec<Fans>,
    ) -> Self {
        let n = topology.n_vertices();
        let faces = topology.faces();
        let edges = topology.edges();
        // a wedge per corner: the wedges' offsets are the corners'
        let wedge_ptr = corner_ptr;
        let mut spoke_ptr = Vec::with_capacity(n + 1);
        spoke_ptr.push(0u32);
        let mut kind = Vec::with_capacity(n);
        for f in &fans {
            kind.extend_from_slice(&f.kind);
            for &ns in &f.counts {
                spoke_ptr.push(spoke_ptr.last().unwrap() + ns);
            }
        }
        let (spoke_vertex, spoke_edge) = rayon::join(
            || joined(&fans.iter().map(|f| &f.spokes[..]).collect::<Vec<_>>(), 0),
            || {
                joined(
                    &fans.iter().map(|f| &f.spoke_edges[..]).collect::<Vec<_>>(),
                    0,
                )
            },
        );
        drop(fans);

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
    pub(crate) fn face_flipped(&self) -> &[bool] {
        &self.flipped
    }

    pub(crate) fn n_vertices(&self) -> usize {
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
    pub(crate) fn spoke_edges(&self, v: usize) -> &[u32] {
        &self.spoke_edge[self.spoke_ptr[v] as usize..self.spoke_ptr[v + 1] as usize]
    }

    /// The shape of the fan around `v`.
    pub fn kind(&self, v: usize) -> FanKind {
        self.kind[v]
    }

    /// Index of the edge between `i` and `j`, if any.
    #[cfg(test)]
    pub(crate) fn edge_between(&self, i: usize, j: usize) -> Option<usize> {
        find_edge(&self.edge_ptr, &self.edge_end, i as u32, j as u32)
    }

    /// Edges across which the two endpoints' fans have opposite senses (a non-orientable
    /// mesh's seam): their true transport is a reflection, which [`Transport`](super::Transport) cannot
    /// express. Empty on any orientable mesh, however its faces are oriented.
    pub fn orientation_reversing_edges(&self) -> &[u32] {
        &self.reversing
    }
}

/// The edge lookup of [`find_edge`]: edges are sorted by `(a, b)`, so those starting at
/// `a` are contiguous; returns the first edge of each lower endpoint and every edge's
/// upper endpoint.
fn edge_index(topology: &Topology) -> (Vec<u32>, Vec<u32>) {
    let n = topology.n_vertices();
    let edges = topology.edges();
    let mut edge_ptr = vec![0u32; n + 1];
    for &[a, _] in edges {
        edge_ptr[a as usize + 1] += 1;
    }
    for v in 0..n {
        edge_ptr[v + 1] += edge_ptr[v];
    }
    (edge_ptr, edges.iter().map(|&[_, b]| b).collect())
}

/// Index of the edge `{i, j}` in the sorted edge list (`edge_ptr`: the first edge of each
/// lower endpoint, `edge_end`: every edge's upper endpoint); `None` if there is none.
pub(super) fn find_edge(edge_ptr: &[u32], edge_end: &[u32], i: u32, j: u32) -> Option<usize> {
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
    let faces = topology.faces();
    let pairs = edge_pairs(topology);
    // the edge as face f walks it, from corner k+1 to corner k+2
    let run = |f: u32, k: u8| {
        let t = faces[f as usize];
        (t[(k as usize + 1) % 3], t[(k as usize + 2) % 3])
    };
    // the usual case, every two-face edge already consistent: the walk would flip nothing
    // (each face takes its root's `false`, and no component has a majority of flipped
    // faces), so it is skipped
    let consistent = pairs.par_iter().all(|pair| match pair {
        [a, b] if *b != NO_PAIR => {
            let ((f, k), (g, l)) = (unpack(*a), unpack(*b));
            let (a, b) = run(f, k);
            run(g, l) == (b, a)
        }
        _ => true,
    });
    if consistent {
        return vec![false; faces.len()];
    }
    harmonize_walk(topology, &pairs)
}

/// [`edge_pairs`]' mark of an edge that is not shared by exactly two faces.
const NO_PAIR: u32 = u32::MAX;

/// Per edge that exactly two faces share, the two in face order, each as `3 f + k` (face
/// `f`, its corner `k` opposite the edge); [`NO_PAIR`] twice for any other edge. What the
/// harmonization reads of the edge → face incidence, in one pass over the faces (a
/// million-vertex cloth's construction spent ~40 ms building the whole incidence).
fn edge_pairs(topology: &Topology) -> Vec<[u32; 2]> {
    let mut pairs = vec![[NO_PAIR; 2]; topology.n_edges()];
    for (f, fe) in topology.face_edges().iter().enumerate() {
        for (k, &e) in fe.iter().enumerate() {
            if topology.edge_kind(e as usize) == EdgeKind::Interior {
                let pair = &mut pairs[e as usize];
                pair[usize::from(pair[0] != NO_PAIR)] = 3 * f as u32 + k as u32;
            }
        }
    }
    pairs
}

/// `(face, corner)` of an [`edge_pairs`] entry.
fn unpack(x: u32) -> (u32, u8) {
    (x / 3, (x % 3) as u8)
}

/// The breadth-first walk of [`harmonize_orientation`] over the faces through the edges
/// two faces share ([`edge_pairs`]).
fn harmonize_walk(topology: &Topology, pairs: &[[u32; 2]]) -> Vec<bool> {
    let (faces, face_edges) = (topology.faces(), topology.face_edges());
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
                let pair = pairs[e as usize];
                if pair[1] == NO_PAIR {
                    continue;
                }
                let (a, b) = (unpack(pair[0]), unpack(pair[1]));
                let (g, l) = if a.0 == f { b } else { a };
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

/// Fans of at most this many wedges find a spoke's wedges by scanning them (cheaper than
/// sorting them for the few wedges of a cloth vertex); larger fans sort.
const SMALL_FAN: usize = 16;

/// Orders the fan of one vertex from its incident `(face, corner)` list, walking faces in
/// their harmonized orientation (`flipped`); lays its wedges in `wedges` and appends its
/// spokes and the spokes' edges (read from the face met first, `face_edges`) to `out`.
fn order_fan(
    faces: &[[u32; 3]],
    face_edges: &[[u32; 3]],
    flipped: &[bool],
    corners: &[(u32, u8)],
    scratch: &mut FanScratch,
    wedges: &mut Laid<'_>,
    out: &mut Fans,
) -> FanKind {
    let m = corners.len();
    if m == 0 {
        return FanKind::Loose;
    }
    let FanScratch {
        ends,
        end_slot,
        touch,
        count,
        first,
        visited,
        steps,
        walks,
        distinct,
        local,
    } = scratch;
    // the two spokes of each wedge in the face's harmonized orientation
    ends.clear();
    ends.extend(corners.iter().map(|&(f, k)| {
        let t = faces[f as usize];
        let (p, q) = (t[(k as usize + 1) % 3], t[(k as usize + 2) % 3]);
        if flipped[f as usize] { [q, p] } else { [p, q] }
    }));
    // the fan's distinct spokes, each with the wedges touching it (how many, and the first
    // two in wedge order), and each wedge's two spokes among them: found once, so that
    // the walk below reads them instead of searching (a scan of the spokes found so far
    // for a small fan, a sorted (spoke, wedge) list for a large one; both give the same
    // answers)
    distinct.clear();
    count.clear();
    first.clear();
    end_slot.clear();
    end_slot.resize(m, [u32::MAX; 2]);
    let touched = |i: usize, w: usize, count: &mut Vec<u32>, first: &mut Vec<[usize; 2]>| {
        // a wedge touches a spoke once (its two spokes differ)
        if (count[i] as usize) < 2 {
            first[i][count[i] as usize] = w;
        }
        count[i] += 1;
    };
    if m <= SMALL_FAN {
        for (w, e) in ends.iter().enumerate() {
            for (side, &x) in e.iter().enumerate() {
                let i = match distinct.iter().position(|&d| d == x) {
                    Some(i) => i,
                    None => {
                        distinct.push(x);
                        count.push(0);
                        first.push([usize::MAX; 2]);
                        distinct.len() - 1
                    }
                };
                touched(i, w, count, first);
                end_slot[w][side] = i as u32;
            }
        }
    } else {
        touch.clear();
        for (w, e) in ends.iter().enumerate() {
            touch.push((e[0], w as u32));
            touch.push((e[1], w as u32));
        }
        touch.sort_unstable();
        for &(x, w) in touch.iter() {
            if distinct.last() != Some(&x) {
                distinct.push(x);
                count.push(0);
                first.push([usize::MAX; 2]);
            }
            let (i, w) = (distinct.len() - 1, w as usize);
            touched(i, w, count, first);
            end_slot[w][usize::from(ends[w][0] != x)] = i as u32;
        }
    }
    let (ends, end_slot, count, first) = (&*ends, &*end_slot, &*count, &*first);
    // the wedges touching end `side` of wedge `w`
    let touching = |w: usize, side: usize| {
        let i = end_slot[w][side] as usize;
        (count[i] as usize, first[i])
    };
    let open = |w: usize, side: usize| touching(w, side).0 != 2;

    visited.clear();
    visited.resize(m, false);
    steps.clear();
    walks.clear();
    let mut n_visited = 0;
    while n_visited < m {
        let start = (0..m)
            .find(|&w| !visited[w] && open(w, 0))
            .map(|w| (w, true))
            .or_else(|| {
                (0..m)
                    .find(|&w| !visited[w] && open(w, 1))
                    .map(|w| (w, false))
            })
            .or_else(|| (0..m).find(|&w| !visited[w]).map(|w| (w, true)))
            .expect("an unvisited wedge remains");
        let (mut w, mut fwd) = start;
        let first_spoke = ends[w][if fwd { 0 } else { 1 }];
        let begin = steps.len();
        let closed = loop {
            visited[w] = true;
            n_visited += 1;
            steps.push((w, fwd));
            let exit = ends[w][if fwd { 1 } else { 0 }];
            let (count, t) = touching(w, usize::from(fwd));
            if count != 2 {
                break false;
            }
            let other = if t[0] == w { t[1] } else { t[0] };
            if visited[other] {
                break exit == first_spoke && other == start.0;
            }
            w = other;
            fwd = ends[w][0] == exit;
        };
        // give the walk the orientation of the majority of its faces
        let walk = &mut steps[begin..];
        let n_fwd = walk.iter().filter(|s| s.1).count();
        if 2 * n_fwd < walk.len() {
            walk.reverse();
            walk.iter_mut().for_each(|s| s.1 = !s.1);
        }
        walks.push((begin, steps.len(), closed));
    }

    // spokes in order of first meeting; wedges refer to them by local index
    let s0 = out.spokes.len();
    local.clear();
    local.resize(distinct.len(), u32::MAX);
    // `edge`: the spoke's edge, pushed with a spoke met for the first time
    let mut slot = |i: u32, s: u32, edge: u32, out: &mut Fans| {
        let i = i as usize;
        if local[i] == u32::MAX {
            local[i] = (out.spokes.len() - s0) as u32;
            out.spokes.push(s);
            out.spoke_edges.push(edge);
        }
        local[i]
    };
    for &(w, fwd) in steps.iter() {
        let (a, b) = if fwd { (0, 1) } else { (1, 0) };
        // the edge from the corner `k` to vertex `x` of the face: the one opposite the
        // face's third corner
        let (f, k) = (corners[w].0 as usize, corners[w].1 as usize);
        let edge = |x: u32| {
            if faces[f][(k + 1) % 3] == x {
                face_edges[f][(k + 2) % 3]
            } else {
                face_edges[f][(k + 1) % 3]
            }
        };
        let (sa, sb) = (ends[w][a], ends[w][b]);
        let from = slot(end_slot[w][a], sa, edge(sa), out);
        let to = slot(end_slot[w][b], sb, edge(sb), out);
        wedges.push(Wedge {
            face: corners[w].0,
            corner: corners[w].1,
            forward: fwd != flipped[corners[w].0 as usize],
            from,
            to,
        });
    }
    // every wedge was walked, so every distinct spoke was met
    let manifold = count.iter().all(|&c| c <= 2);
    match (walks.len(), manifold) {
        (1, true) if walks[0].2 => FanKind::Interior,
        (1, true) => FanKind::Boundary,
        _ => FanKind::Irregular,
    }
}

/// The neighbours of every vertex in the order the rotations sum over them (that of
/// [`Topology::edges`], fixed by the topology): built once per mesh, so that a bake's
/// per-frame rotations ([`RingAdjacency::rotations`]) only read it.
#[derive(Debug, Clone)]
pub(crate) struct RingAdjacency {
    ptr: Vec<u32>,
    nbr: Vec<u32>,
}

impl RingAdjacency {
    /// The vertex adjacency of `topology`: each vertex's neighbours in the order of its
    /// incident edges ([`Topology::vertex_edges`]).
    pub(crate) fn new(topology: &Topology) -> Self {
        let n = topology.n_vertices();
        let mut ptr = Vec::with_capacity(n + 1);
        let mut nbr = Vec::with_capacity(2 * topology.n_edges());
        ptr.push(0u32);
        for v in 0..n {
            nbr.extend(
                topology
                    .vertex_edges(v)
                    .iter()
                    .map(|&e| topology.other_end(e as usize, v)),
            );
            ptr.push(nbr.len() as u32);
        }
        Self { ptr, nbr }
    }

    pub(crate) fn n_vertices(&self) -> usize {
        self.ptr.len() - 1
    }

    /// Neighbours of `v` (each vertex sharing an edge with it), in edge order.
    pub(crate) fn neighbours(&self, v: usize) -> &[u32] {
        &self.nbr[self.ptr[v] as usize..self.ptr[v + 1] as usize]
    }
}

#[cfg(test)]
pub(super) mod tests {
    use std::f64::consts::TAU;

    use glam::DVec3;

    use super::*;

    /// Vertex 0 at the centre of a unit hexagon in the plane `z = 0`, with its six faces
    /// counter-clockwise seen from `+z` (`closed`) or only the first four.
    pub(in crate::mesh) fn fan(closed: bool) -> (Topology, Vec<DVec3>) {
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
        let (t, _) = fan(true);
        let r = OneRings::new(&t);
        assert_eq!(r.kind(0), FanKind::Interior);
        assert_eq!(r.spokes(0), &[1, 2, 3, 4, 5, 6]);
        assert!(r.wedges(0).iter().all(|w| w.forward));
        assert_eq!(r.kind(1), FanKind::Boundary);
        // vertex 1 = (1, 0) is on the border: counter-clockwise, its spokes point at 120°
        // (vertex 2, a border edge: the walk starts there), 180° (0) and 240° (6)
        assert_eq!(r.spokes(1), &[2, 0, 6]);
    }

    /// Fans of more than `SMALL_FAN` wedges take the sorted path: the same answers as a
    /// small fan's, read off the geometry (a vertex with 24 faces around it, all of them,
    /// 20 of them, and two separate fans of 10 meeting at it).
    #[test]
    fn large_fans_are_ordered_as_small_ones() {
        let k = 24u32;
        let around = |faces: &[u32]| -> Topology {
            let faces = faces.iter().map(|&j| [0, 1 + j, 1 + (j + 1) % k]).collect();
            Topology::from_triangles(1 + k as usize, faces).unwrap()
        };
        let all: Vec<u32> = (0..k).collect();
        let r = OneRings::new(&around(&all));
        assert_eq!(r.kind(0), FanKind::Interior);
        assert_eq!(r.spokes(0), (1..=k).collect::<Vec<_>>());
        let open: Vec<u32> = (0..20).collect();
        let r = OneRings::new(&around(&open));
        assert_eq!(r.kind(0), FanKind::Boundary);
        assert_eq!(r.spokes(0), (1..=21).collect::<Vec<_>>());
        assert!(r.wedges(0).iter().all(|w| w.forward));
        let bow_tie: Vec<u32> = (0..10).chain(12..22).collect();
        let r = OneRings::new(&around(&bow_tie));
        assert_eq!(r.kind(0), FanKind::Irregular);
        assert_eq!(r.wedges(0).len(), 20);
        assert_eq!(r.spokes(0).len(), 22);
    }

    #[test]
    fn open_fan_is_a_boundary() {
        let (t, _) = fan(false);
        assert_eq!(OneRings::new(&t).kind(0), FanKind::Boundary);
    }

    #[test]
    fn skipping_the_walk_on_a_consistent_mesh_changes_nothing() {
        let walk = |t: &Topology| harmonize_walk(t, &edge_pairs(t));
        // consistent (the fast path), then with a face stored flipped (the walk)
        let (consistent, _) = fan(true);
        let awkward = awkward_mesh();
        for t in [&consistent, &awkward] {
            assert_eq!(harmonize_orientation(t), walk(t));
        }
        assert!(harmonize_orientation(&consistent).iter().all(|&f| !f));
        assert!(harmonize_orientation(&awkward).iter().any(|&f| f));
    }

    /// A 7×7 grid of split quads with what the fans must handle: a face stored flipped,
    /// a hole, a fin of three faces on an edge and a bow-tie vertex.
    fn awkward_mesh() -> Topology {
        let idx = |i: u32, j: u32| i * 8 + j;
        let mut faces = Vec::new();
        for i in 0..7 {
            for j in 0..7 {
                if (i, j) == (3, 3) {
                    continue; // a hole
                }
                let (a, b, c, d) = (idx(i, j), idx(i, j + 1), idx(i + 1, j + 1), idx(i + 1, j));
                faces.extend([[a, b, c], [a, c, d]]);
            }
        }
        faces[17] = [faces[17][0], faces[17][2], faces[17][1]]; // stored flipped
        faces.push([idx(5, 5), idx(5, 6), 64]); // a fin on edge (5,5)-(5,6)
        // a bow-tie: two triangles meeting at corner vertex 7 only
        faces.push([7, 65, 66]);
        Topology::from_triangles(67, faces).unwrap()
    }

    /// The part of `topology` made of the faces around the vertices picked by `pick`,
    /// built from scratch and derived ([`Topology::restricted`],
    /// [`OneRings::restricted`]).
    fn both_ways(topology: &Topology, pick: impl Fn(usize) -> bool) -> [(Topology, OneRings); 2] {
        let rings = OneRings::new(topology);
        let n = topology.n_vertices();
        let mut face_local = vec![u32::MAX; topology.n_faces()];
        for v in (0..n).filter(|&v| pick(v)) {
            rings
                .wedges(v)
                .iter()
                .for_each(|w| face_local[w.face as usize] = 0);
        }
        let faces: Vec<u32> = (0..topology.n_faces() as u32)
            .filter(|&f| face_local[f as usize] == 0)
            .collect();
        let mut local = vec![u32::MAX; n];
        for (k, &f) in faces.iter().enumerate() {
            face_local[f as usize] = k as u32;
            topology.faces()[f as usize]
                .iter()
                .for_each(|&v| local[v as usize] = 0);
        }
        let vertices: Vec<u32> = (0..n as u32).filter(|&v| local[v as usize] == 0).collect();
        vertices
            .iter()
            .enumerate()
            .for_each(|(j, &v)| local[v as usize] = j as u32);
        let flipped: Vec<bool> = faces
            .iter()
            .map(|&f| rings.face_flipped()[f as usize])
            .collect();
        let tris = faces
            .iter()
            .map(|&f| topology.faces()[f as usize].map(|v| local[v as usize]))
            .collect();
        let scratch = Topology::from_triangles(vertices.len(), tris).unwrap();
        let scratch_rings = OneRings::with_orientation(&scratch, flipped);
        let (derived, edge_local) = topology.restricted(&faces, &vertices, &local);
        let derived_rings = OneRings::restricted(
            &rings,
            &derived,
            &faces,
            &vertices,
            &face_local,
            &local,
            &edge_local,
        );
        // the edge map points at the same edges
        for (e, &k) in edge_local.iter().enumerate() {
            if k != u32::MAX {
                let [a, b] = topology.edges()[e];
                assert_eq!(
                    derived.edges()[k as usize],
                    [local[a as usize], local[b as usize]]
                );
            }
        }
        [(scratch, scratch_rings), (derived, derived_rings)]
    }

    #[test]
    fn a_part_derived_from_the_whole_is_the_part_built_from_scratch() {
        let t = awkward_mesh();
        let mut seed = 12345u64;
        let mut picks: Vec<Vec<bool>> = vec![vec![true; 67], (0..67).map(|v| v == 7).collect()];
        for density in [2, 4, 8] {
            picks.push(
                (0..67)
                    .map(|_| {
                        seed = seed
                            .wrapping_mul(6364136223846793005)
                            .wrapping_add(1442695040888963407);
                        (seed >> 33) % density == 0
                    })
                    .collect(),
            );
        }
        let mut rims = 0;
        for pick in picks {
            let [(a, ra), (b, rb)] = both_ways(&t, |v| pick[v]);
            assert_same(&a, &ra, &b, &rb);
            rims += (0..a.n_vertices())
                .filter(|&v| ra.kind(v) != FanKind::Interior)
                .count();
        }
        assert!(rims > 0);
        // the awkward vertices are in the whole mesh's fans
        let r = OneRings::new(&t);
        assert_eq!(r.kind(7), FanKind::Irregular);
        assert_eq!(r.kind(5 * 8 + 5), FanKind::Irregular);
    }

    /// Every array of two topologies and their fans, compared.
    fn assert_same(a: &Topology, ra: &OneRings, b: &Topology, rb: &OneRings) {
        assert_eq!(a.n_vertices(), b.n_vertices());
        assert_eq!(a.faces(), b.faces());
        assert_eq!(a.edges(), b.edges());
        assert_eq!(a.face_edges(), b.face_edges());
        assert_eq!(a.face_polygon(), b.face_polygon());
        assert_eq!(a.n_polygons(), b.n_polygons());
        for e in 0..a.n_edges() {
            assert_eq!(a.edge_kind(e), b.edge_kind(e), "edge {e}");
        }
        for v in 0..a.n_vertices() {
            assert_eq!(a.vertex_edges(v), b.vertex_edges(v), "vertex {v}");
            assert_eq!(ra.wedges(v), rb.wedges(v), "vertex {v}");
            assert_eq!(ra.spokes(v), rb.spokes(v), "vertex {v}");
            assert_eq!(ra.spoke_edges(v), rb.spoke_edges(v), "vertex {v}");
            assert_eq!(ra.kind(v), rb.kind(v), "vertex {v}");
        }
        assert_eq!(ra.face_flipped(), rb.face_flipped());
        assert_eq!(ra.edge_spoke, rb.edge_spoke);
        assert_eq!(ra.edge_ptr, rb.edge_ptr);
        assert_eq!(ra.edge_end, rb.edge_end);
        assert_eq!(
            ra.orientation_reversing_edges(),
            rb.orientation_reversing_edges()
        );
    }

    #[test]
    fn a_mesh_grown_by_appended_faces_is_the_mesh_built_from_scratch() {
        let full = awkward_mesh();
        let flipped = OneRings::new(&full).face_flipped().to_vec();
        let faces = full.faces();
        let part = |k: usize| {
            // the first k faces, on the vertices up to the highest they use
            let n = faces[..k]
                .iter()
                .flatten()
                .max()
                .map_or(0, |&v| v as usize + 1);
            let t = Topology::from_triangles(n, faces[..k].to_vec()).unwrap();
            let r = OneRings::with_orientation(&t, flipped[..k].to_vec());
            (t, r)
        };
        let (mut t, mut r) = part(5);
        let mut grown_vertices = 0;
        for k in [6, 19, 40, 41, faces.len()] {
            let (want, want_rings) = part(k);
            let n = want.n_vertices();
            grown_vertices += n - t.n_vertices();
            let (grown, old_new) = t
                .extended(n, &faces[t.n_faces()..k], (0..k as u32).collect(), k)
                .unwrap();
            assert_eq!(old_new.len(), t.n_edges());
            let rings = OneRings::extended(&r, &grown, flipped[..k].to_vec(), &old_new);
            assert_same(&want, &want_rings, &grown, &rings);
            (t, r) = (grown, rings);
        }
        assert!(grown_vertices > 20);
        // a bad new face is named by its index in the grown mesh
        let bad = t.extended(
            t.n_vertices(),
            &[[0, 1, 1]],
            (0..=t.n_faces() as u32).collect(),
            1,
        );
        assert_eq!(
            bad.unwrap_err(),
            crate::error::MeshError::RepeatedVertex {
                face: t.n_faces(),
                vertex: 1
            }
        );
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

    #[test]
    fn every_spoke_has_the_edge_to_its_neighbour() {
        // read from the faces while the fans are ordered: the edge list's own lookup agrees
        let (closed, _) = fan(true);
        let (open, _) = fan(false);
        for t in [closed, open, awkward_mesh()] {
            let r = OneRings::new(&t);
            for v in 0..t.n_vertices() {
                for (&j, &e) in r.spokes(v).iter().zip(r.spoke_edges(v)) {
                    assert_eq!(r.edge_between(v, j as usize), Some(e as usize));
                }
            }
        }
    }
}
