//! Triangle-mesh topology: faces, unique edges, edge–face incidence, boundary and
//! non-manifold detection, and the map from Blender polygons to the triangles they were
//! split into (so n-gons work everywhere a per-polygon value is needed).
//!
//! Edges are stored once, as `(a, b)` with `a < b`, in lexicographic order; `face_edges[f][k]`
//! is the edge opposite corner `k` of face `f` (i.e. between corners `k+1` and `k+2`).
//! An edge with one incident face is a boundary edge, with three or more a non-manifold
//! edge. The stain operators are assembled face by face, so they are well defined on
//! boundaries and on non-manifold fans alike; the classification is reported so that the
//! add-on can warn about it and later physics (evaporation boundary coefficient, eq. 4.8)
//! can use it.

use rayon::prelude::*;

use crate::error::MeshError;
use crate::runs;

/// Old edges per task of [`Topology::extended`]'s merge, and vertices per task of its
/// incidence lists.
const GROWTH_CHUNK: usize = 4096;

/// How many faces share an edge.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EdgeKind {
    /// Exactly one incident face.
    Boundary,
    /// Exactly two incident faces.
    Interior,
    /// Three or more incident faces.
    NonManifold,
}

/// Fixed connectivity of a triangle mesh.
#[derive(Debug, Clone)]
pub struct Topology {
    n_vertices: usize,
    faces: Vec<[u32; 3]>,
    edges: Vec<[u32; 2]>,
    face_edges: Vec<[u32; 3]>,
    edge_face_count: Vec<u32>,
    /// Blender polygon index of every triangle (identity when built from triangles).
    face_polygon: Vec<u32>,
    n_polygons: usize,
    /// Vertex → incident edges (increasing edge index), compressed.
    vertex_edge_ptr: Vec<u32>,
    vertex_edge: Vec<u32>,
}

impl Topology {
    /// Builds the topology of `n_vertices` vertices and triangles `faces`.
    ///
    /// Fails on an empty face list, on an index out of range and on a triangle that uses a
    /// vertex twice (naming the face). Vertices used by no face ("loose" vertices) are
    /// allowed: they carry no area and the operators leave them untouched.
    pub fn from_triangles(n_vertices: usize, faces: Vec<[u32; 3]>) -> Result<Self, MeshError> {
        let n = faces.len();
        Self::with_polygons(n_vertices, faces, (0..n as u32).collect(), n)
    }

    /// Like [`Topology::from_triangles`], with `face_polygon[f]` the index of the polygon
    /// (out of `n_polygons`) that triangle `f` belongs to.
    pub fn with_polygons(
        n_vertices: usize,
        faces: Vec<[u32; 3]>,
        face_polygon: Vec<u32>,
        n_polygons: usize,
    ) -> Result<Self, MeshError> {
        if faces.is_empty() {
            return Err(MeshError::Empty);
        }
        if face_polygon.len() != faces.len() {
            return Err(MeshError::PolygonMapLength {
                expected: faces.len(),
                got: face_polygon.len(),
            });
        }
        check_faces(n_vertices, &faces, 0)?;
        // Unique edges: sort the 3F half-edge keys `(low end, high end, slot)`, then
        // run-length them. The keys are distinct, so any sort gives the same order: a
        // counting sort by the low end, then each vertex's few keys sorted in place.
        let key = |f: usize, k: usize| {
            let tri = faces[f];
            let (a, b) = (tri[(k + 1) % 3], tri[(k + 2) % 3]);
            (a.min(b), a.max(b), (3 * f + k) as u32)
        };
        let mut start = vec![0u32; n_vertices + 1];
        for f in 0..faces.len() {
            for k in 0..3 {
                start[key(f, k).0 as usize + 1] += 1;
            }
        }
        for v in 0..n_vertices {
            start[v + 1] += start[v];
        }
        let mut next = start[..n_vertices].to_vec();
        let mut half = vec![(0u32, 0u32, 0u32); 3 * faces.len()];
        for f in 0..faces.len() {
            for k in 0..3 {
                let h = key(f, k);
                half[next[h.0 as usize] as usize] = h;
                next[h.0 as usize] += 1;
            }
        }
        for v in 0..n_vertices {
            half[start[v] as usize..start[v + 1] as usize].sort_unstable();
        }
        let mut edges = Vec::new();
        let mut edge_face_count = Vec::new();
        let mut face_edges = vec![[0u32; 3]; faces.len()];
        for (i, &(a, b, slot)) in half.iter().enumerate() {
            if i == 0 || (half[i - 1].0, half[i - 1].1) != (a, b) {
                edges.push([a, b]);
                edge_face_count.push(0);
            }
            let e = edges.len() - 1;
            edge_face_count[e] += 1;
            face_edges[slot as usize / 3][slot as usize % 3] = e as u32;
        }
        let (vertex_edge_ptr, vertex_edge) = incidence(n_vertices, &edges);
        Ok(Self {
            n_vertices,
            faces,
            edges,
            face_edges,
            edge_face_count,
            face_polygon,
            n_polygons,
            vertex_edge_ptr,
            vertex_edge,
        })
    }

    /// The sub-mesh of the faces `faces` (increasing) of this mesh, without sorting: its
    /// vertices are `vertices` (increasing; every corner of `faces` among them) and
    /// `local[v]` is the new index of mesh vertex `v` (`u32::MAX` if it is not kept).
    /// Because the renumbering keeps the order of vertices and faces, the sub-mesh's edges
    /// are this mesh's edges that some kept face has, in the same (lexicographic) order:
    /// exactly what [`Topology::from_triangles`] on the renumbered faces would build, but
    /// gathered through the maps in time proportional to the sub-mesh (plus one pass over
    /// a per-edge array). Also returns the sub-mesh edge of every mesh edge (`u32::MAX`
    /// where none).
    pub(crate) fn restricted(
        &self,
        faces: &[u32],
        vertices: &[u32],
        local: &[u32],
    ) -> (Self, Vec<u32>) {
        // mesh edge → sub-mesh edge: mark the kept faces' edges, then number them in the
        // mesh's order, vertex by vertex (the edges whose lower end is `a` are contiguous
        // and increasing among `a`'s incident edges)
        let mut edge_local = vec![u32::MAX; self.edges.len()];
        for &f in faces {
            for e in self.face_edges[f as usize] {
                edge_local[e as usize] = 0;
            }
        }
        let mut edges = Vec::new();
        for &a in vertices {
            for &e in self.vertex_edges(a as usize) {
                let [lo, hi] = self.edges[e as usize];
                if lo == a && edge_local[e as usize] == 0 {
                    edge_local[e as usize] = edges.len() as u32;
                    edges.push([local[lo as usize], local[hi as usize]]);
                }
            }
        }
        let mut edge_face_count = vec![0u32; edges.len()];
        let face_edges: Vec<[u32; 3]> = faces
            .iter()
            .map(|&f| {
                self.face_edges[f as usize].map(|e| {
                    let k = edge_local[e as usize];
                    edge_face_count[k as usize] += 1;
                    k
                })
            })
            .collect();
        let n = vertices.len();
        let (vertex_edge_ptr, vertex_edge) = incidence(n, &edges);
        let topology = Self {
            n_vertices: n,
            faces: faces
                .iter()
                .map(|&f| self.faces[f as usize].map(|v| local[v as usize]))
                .collect(),
            edges,
            face_edges,
            edge_face_count,
            face_polygon: (0..faces.len() as u32).collect(),
            n_polygons: faces.len(),
            vertex_edge_ptr,
            vertex_edge,
        };
        (topology, edge_local)
    }

    /// This mesh with `faces` appended (and `n_vertices` vertices, at least this mesh's):
    /// what [`Topology::with_polygons`] on all the faces builds, with only the new faces'
    /// edges sorted. The new edges are merged into the old ones (both in lexicographic
    /// order), so a mesh that grows by a few faces at a time (the lazily refined cloth of
    /// [`super::refine::Partial`]) pays for its new part and one pass over the old, and
    /// every pass runs in parallel: the merge in runs of old edges (each run finds where
    /// it starts among the new edges), the vertices' edge lists as each vertex's old list
    /// renumbered and merged with its new edges, the new faces' sides and edges per face.
    /// Also returns the new index of every old edge. `face_polygon` covers all the faces.
    pub(crate) fn extended(
        &self,
        n_vertices: usize,
        faces: &[[u32; 3]],
        face_polygon: Vec<u32>,
        n_polygons: usize,
    ) -> Result<(Self, Vec<u32>), MeshError> {
        let old_faces = self.faces.len();
        if n_vertices < self.n_vertices || face_polygon.len() != old_faces + faces.len() {
            // not a growth: built from scratch (which also names what is wrong)
            let all: Vec<[u32; 3]> = self.faces.iter().chain(faces).copied().collect();
            let t = Self::with_polygons(n_vertices, all, face_polygon, n_polygons)?;
            return Ok((t, Vec::new()));
        }
        check_faces(n_vertices, faces, old_faces)?;
        // the new faces' sides that are not edges of this mesh, sorted (as `a << 32 | b`,
        // `a < b`: the integers' order is the pairs' lexicographic order)
        let mut keys: Vec<u64> = faces
            .par_iter()
            .flat_map_iter(|tri| {
                (0..3).map(move |k| {
                    let (a, b) = (tri[(k + 1) % 3], tri[(k + 2) % 3]);
                    (u64::from(a.min(b)) << 32) | u64::from(a.max(b))
                })
            })
            .filter(|&key| self.find_edge((key >> 32) as u32, key as u32).is_none())
            .collect();
        // equal keys are equal pairs: the sorted list is the same whoever sorts it
        keys.par_sort_unstable();
        keys.dedup();
        let half: Vec<[u32; 2]> = keys
            .par_iter()
            .map(|&key| [(key >> 32) as u32, key as u32])
            .collect();
        // the merge of the old edges and the new ones (both increasing), in parallel: an
        // old edge moves up by the new edges before it, a new edge sits after the old
        // edges before it
        let new_sorted = &half[..];
        let old_new: Vec<u32> = self
            .edges
            .par_chunks(GROWTH_CHUNK)
            .enumerate()
            .flat_map_iter(|(c, chunk)| {
                let mut before = new_sorted.partition_point(|h| h < &chunk[0]);
                chunk.iter().enumerate().map(move |(k, edge)| {
                    while new_sorted.get(before).is_some_and(|h| h < edge) {
                        before += 1;
                    }
                    (c * GROWTH_CHUNK + k + before) as u32
                })
            })
            .collect();
        let fresh: Vec<u32> = half
            .par_iter()
            .enumerate()
            .map(|(k, h)| (k + self.edges.partition_point(|e| e < h)) as u32)
            .collect();
        let n_edges = self.edges.len() + half.len();
        let mut edges = vec![[0u32; 2]; n_edges];
        runs::scatter_at(&mut edges, &old_new, &self.edges);
        runs::scatter_at(&mut edges, &fresh, &half);
        let (vertex_edge_ptr, vertex_edge) =
            self.grown_incidence(n_vertices, &old_new, &half, &fresh);
        let mut grown = Self {
            n_vertices,
            faces: self.faces.par_iter().chain(faces).copied().collect(),
            edges,
            face_edges: self
                .face_edges
                .par_iter()
                .map(|fe| fe.map(|e| old_new[e as usize]))
                .collect(),
            edge_face_count: Vec::new(),
            face_polygon,
            n_polygons,
            vertex_edge_ptr,
            vertex_edge,
        };
        let mut count = vec![0u32; n_edges];
        runs::scatter_at(&mut count, &old_new, &self.edge_face_count);
        let new_face_edges: Vec<[u32; 3]> = faces
            .par_iter()
            .map(|tri| {
                std::array::from_fn(|k| {
                    let (a, b) = (tri[(k + 1) % 3], tri[(k + 2) % 3]);
                    grown.find_edge(a, b).expect("a side is an edge") as u32
                })
            })
            .collect();
        for fe in &new_face_edges {
            fe.iter().for_each(|&e| count[e as usize] += 1);
        }
        grown.face_edges.extend(new_face_edges);
        grown.edge_face_count = count;
        Ok((grown, old_new))
    }

    /// The vertex → edge incidence of this mesh grown by the edges `half` (increasing) to
    /// `n_vertices` vertices, its old edges renumbered by `old_new` and the new ones
    /// numbered `fresh` (both increasing): each vertex's list is its old list renumbered
    /// (the renumbering keeps the order) merged with its new edges, in parallel over
    /// runs of vertices. The same lists as [`incidence`] on the grown edges.
    fn grown_incidence(
        &self,
        n_vertices: usize,
        old_new: &[u32],
        half: &[[u32; 2]],
        fresh: &[u32],
    ) -> (Vec<u32>, Vec<u32>) {
        // the new edges of each vertex, in increasing edge order
        let (new_ptr, new_edges) = numbered_incidence(n_vertices, half, |k| fresh[k]);
        let old = |v: usize| -> &[u32] {
            if v < self.n_vertices {
                self.vertex_edges(v)
            } else {
                &[]
            }
        };
        let mut ptr = Vec::with_capacity(n_vertices + 1);
        ptr.push(0u32);
        for v in 0..n_vertices {
            let degree = old(v).len() as u32 + new_ptr[v + 1] - new_ptr[v];
            ptr.push(ptr[v] + degree);
        }
        let mut list = vec![0u32; ptr[n_vertices] as usize];
        let lens = (0..n_vertices).map(|v| (ptr[v + 1] - ptr[v]) as usize);
        runs::carve(&mut list, lens)
            .into_par_iter()
            .with_min_len(GROWTH_CHUNK)
            .enumerate()
            .for_each(|(v, out)| {
                let mut was = old(v).iter().map(|&e| old_new[e as usize]).peekable();
                let mut new = new_edges[new_ptr[v] as usize..new_ptr[v + 1] as usize]
                    .iter()
                    .copied()
                    .peekable();
                for slot in out {
                    *slot = match (was.peek(), new.peek()) {
                        (Some(&a), Some(&b)) if b < a => new.next(),
                        (Some(_), _) => was.next(),
                        _ => new.next(),
                    }
                    .expect("one edge per slot");
                }
            });
        (ptr, list)
    }

    /// The edge between `i` and `j`, if any (a search among the edges of the lower).
    fn find_edge(&self, i: u32, j: u32) -> Option<usize> {
        let (a, b) = (i.min(j), i.max(j));
        if a as usize >= self.n_vertices {
            return None;
        }
        self.vertex_edges(a as usize)
            .iter()
            .map(|&e| e as usize)
            .find(|&e| self.edges[e] == [a, b])
    }

    /// The edges incident to vertex `v`, in increasing edge order.
    pub(crate) fn vertex_edges(&self, v: usize) -> &[u32] {
        &self.vertex_edge[self.vertex_edge_ptr[v] as usize..self.vertex_edge_ptr[v + 1] as usize]
    }

    /// The end of edge `e` that is not `v` (`v` must be an end of `e`).
    pub(crate) fn other_end(&self, e: usize, v: usize) -> u32 {
        let [a, b] = self.edges[e];
        if a as usize == v { b } else { a }
    }

    /// Vertices, used by a face or not.
    pub fn n_vertices(&self) -> usize {
        self.n_vertices
    }
    /// Triangles.
    pub fn n_faces(&self) -> usize {
        self.faces.len()
    }
    /// Unique edges.
    pub fn n_edges(&self) -> usize {
        self.edges.len()
    }
    /// Source polygons (the triangles' number when no polygon map was given).
    pub fn n_polygons(&self) -> usize {
        self.n_polygons
    }
    /// The triangles' vertex indices.
    pub fn faces(&self) -> &[[u32; 3]] {
        &self.faces
    }
    /// Unique edges `(a, b)`, `a < b`, sorted.
    pub fn edges(&self) -> &[[u32; 2]] {
        &self.edges
    }
    /// `face_edges()[f][k]`: the edge opposite corner `k` of face `f`.
    pub fn face_edges(&self) -> &[[u32; 3]] {
        &self.face_edges
    }
    /// The source polygon of every triangle (the identity when no polygon map was given).
    pub fn face_polygon(&self) -> &[u32] {
        &self.face_polygon
    }

    /// How many faces share edge `e`: boundary, interior or non-manifold.
    pub fn edge_kind(&self, e: usize) -> EdgeKind {
        match self.edge_face_count[e] {
            1 => EdgeKind::Boundary,
            2 => EdgeKind::Interior,
            _ => EdgeKind::NonManifold,
        }
    }

    /// Indices of edges with exactly one incident face.
    pub fn boundary_edges(&self) -> Vec<usize> {
        (0..self.n_edges())
            .filter(|&e| self.edge_kind(e) == EdgeKind::Boundary)
            .collect()
    }

    /// Indices of edges shared by three or more faces.
    pub fn non_manifold_edges(&self) -> Vec<usize> {
        (0..self.n_edges())
            .filter(|&e| self.edge_kind(e) == EdgeKind::NonManifold)
            .collect()
    }

    /// `true` for every vertex on a boundary edge.
    pub fn boundary_vertices(&self) -> Vec<bool> {
        let mut on = vec![false; self.n_vertices];
        for e in self.boundary_edges() {
            let [a, b] = self.edges[e];
            on[a as usize] = true;
            on[b as usize] = true;
        }
        on
    }

    /// `true` for every vertex used by no face.
    pub fn loose_vertices(&self) -> Vec<bool> {
        let mut loose = vec![true; self.n_vertices];
        for tri in &self.faces {
            for &v in tri {
                loose[v as usize] = false;
            }
        }
        loose
    }
}

/// Fails on an index out of range or a repeated vertex in `faces`, naming the face (its
/// index plus `first`).
fn check_faces(n_vertices: usize, faces: &[[u32; 3]], first: usize) -> Result<(), MeshError> {
    for (f, tri) in faces.iter().enumerate() {
        for (k, &v) in tri.iter().enumerate() {
            if v as usize >= n_vertices {
                return Err(MeshError::VertexOutOfRange {
                    face: first + f,
                    vertex: v,
                    n_vertices,
                });
            }
            if tri[(k + 1) % 3] == v {
                return Err(MeshError::RepeatedVertex {
                    face: first + f,
                    vertex: v,
                });
            }
        }
    }
    Ok(())
}

/// Vertex → incident edge lists (counting sort over the edges, so each list is in
/// increasing edge order).
fn incidence(n: usize, edges: &[[u32; 2]]) -> (Vec<u32>, Vec<u32>) {
    numbered_incidence(n, edges, |e| e as u32)
}

/// [`incidence`] with edge `k` of `edges` listed as `number(k)` (increasing in `k`, so
/// each list stays increasing).
fn numbered_incidence(
    n: usize,
    edges: &[[u32; 2]],
    number: impl Fn(usize) -> u32,
) -> (Vec<u32>, Vec<u32>) {
    let mut ptr = vec![0u32; n + 1];
    for &[a, b] in edges {
        ptr[a as usize + 1] += 1;
        ptr[b as usize + 1] += 1;
    }
    for v in 0..n {
        ptr[v + 1] += ptr[v];
    }
    let mut next = ptr[..n].to_vec();
    let mut list = vec![0u32; ptr[n] as usize];
    for (k, &[a, b]) in edges.iter().enumerate() {
        for v in [a as usize, b as usize] {
            list[next[v] as usize] = number(k);
            next[v] += 1;
        }
    }
    (ptr, list)
}

/// Tests' grid: `w × h` vertices numbered `j w + i`, each cell split along its
/// `(i, j)–(i+1, j+1)` diagonal into two triangles of the same orientation.
#[cfg(test)]
pub(crate) fn grid_topology(w: usize, h: usize) -> Topology {
    let mut faces = Vec::new();
    for j in 0..h - 1 {
        for i in 0..w - 1 {
            let v = (j * w + i) as u32;
            faces.push([v, v + 1, v + w as u32 + 1]);
            faces.push([v, v + w as u32 + 1, v + w as u32]);
        }
    }
    Topology::from_triangles(w * h, faces).unwrap()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_large_mesh_grown_in_scattered_batches_is_the_mesh_built_from_scratch() {
        // a 130 × 130 grid (50k edges: many runs of the parallel merge and incidence),
        // its faces appended in five interleaved batches, so that the new edges fall
        // between old ones everywhere and most vertices gain edges at every growth
        let grid = grid_topology(130, 130);
        let batch = |r: usize| -> Vec<[u32; 3]> {
            grid.faces()
                .iter()
                .enumerate()
                .filter(|(f, _)| (f * 7) % 5 == r)
                .map(|(_, &t)| t)
                .collect()
        };
        let used = |faces: &[[u32; 3]]| faces.iter().flatten().max().map_or(0, |&v| v as usize + 1);
        let mut faces = batch(0);
        let mut t = Topology::from_triangles(used(&faces), faces.clone()).unwrap();
        for r in 1..5 {
            let new = batch(r);
            faces.extend_from_slice(&new);
            let n = used(&faces);
            let k = faces.len();
            let (grown, old_new) = t.extended(n, &new, (0..k as u32).collect(), k).unwrap();
            let want = Topology::from_triangles(n, faces.clone()).unwrap();
            assert_eq!(format!("{grown:?}"), format!("{want:?}"), "batch {r}");
            // every old edge is found again at its new number
            for (e, &ne) in old_new.iter().enumerate() {
                assert_eq!(t.edges()[e], grown.edges()[ne as usize]);
            }
            t = grown;
        }
        assert_eq!(t.n_faces(), grid.n_faces());
    }

    #[test]
    fn two_triangles_share_one_interior_edge() {
        let t = Topology::from_triangles(4, vec![[0, 1, 2], [0, 2, 3]]).unwrap();
        assert_eq!(t.n_edges(), 5);
        assert_eq!(t.boundary_edges().len(), 4);
        assert!(t.non_manifold_edges().is_empty());
        let shared = t.edges().iter().position(|&e| e == [0, 2]).unwrap();
        assert_eq!(t.edge_kind(shared), EdgeKind::Interior);
        // the edge opposite corner 1 of face 0 (vertex 1) is 2–0
        assert_eq!(t.face_edges()[0][1] as usize, shared);
        assert_eq!(t.face_edges()[1][2] as usize, shared);
    }

    #[test]
    fn fin_of_three_faces_is_non_manifold() {
        let t = Topology::from_triangles(5, vec![[0, 1, 2], [1, 0, 3], [0, 1, 4]]).unwrap();
        let e01 = t.edges().iter().position(|&e| e == [0, 1]).unwrap();
        assert_eq!(t.non_manifold_edges(), vec![e01]);
    }

    #[test]
    fn bad_faces_are_named() {
        assert_eq!(
            Topology::from_triangles(3, vec![[0, 1, 2], [0, 1, 7]]).unwrap_err(),
            MeshError::VertexOutOfRange {
                face: 1,
                vertex: 7,
                n_vertices: 3
            }
        );
        assert_eq!(
            Topology::from_triangles(3, vec![[0, 1, 2], [2, 1, 2]]).unwrap_err(),
            MeshError::RepeatedVertex { face: 1, vertex: 2 }
        );
        assert_eq!(
            Topology::from_triangles(3, vec![]).unwrap_err(),
            MeshError::Empty
        );
    }

    #[test]
    fn loose_vertices_are_reported() {
        let t = Topology::from_triangles(4, vec![[0, 1, 2]]).unwrap();
        assert_eq!(t.loose_vertices(), vec![false, false, false, true]);
    }
}
