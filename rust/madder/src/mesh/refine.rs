//! Regular refinement of a triangle mesh: every triangle split into `4^L` (issue 12's
//! Detail level `L`), the fine vertices placed on the coarse triangles, and the two
//! transfers between the levels.
//!
//! ## The fine mesh
//! Let `N = 2^L`. A point of coarse face `(v₀, v₁, v₂)` on the lattice `(i, j)`,
//! `i, j ≥ 0`, `i + j ≤ N`, has barycentric coordinates `((N−i−j)/N, i/N, j/N)`. The fine
//! triangles are the lattice's "up" triangles `(i,j), (i+1,j), (i,j+1)` and "down" ones
//! `(i+1,j), (i+1,j+1), (i,j+1)`, `N²` in all, oriented as the coarse face. Lattice points
//! are shared where faces meet, so the fine mesh is numbered
//!
//! ```text
//! coarse vertices           0 .. V                     (fine vertex v = coarse vertex v)
//! edge points               V + e (N−1) + (t−1)        t = 1 .. N−1 from the edge's first end
//! face-interior points      V + E (N−1) + f M + k      M = (N−1)(N−2)/2
//! ```
//!
//! and fine face `f 4^L + k` is the `k`-th lattice triangle of coarse face `f` (one
//! template for all faces). Level 0 is the coarse mesh itself, numbered the same.
//!
//! ## Placement: barycentric, not smoothed
//! A fine vertex is the barycentric combination `x_j = Σ_i φ_i(x_j) X_i` of its coarse
//! face's corners, every frame, with the coarse hat functions `φ_i`. The fine mesh is
//! therefore the coarse surface itself, piece for piece: the stain lies exactly on the
//! triangles Blender draws and the UV map textures, the fine UVs are the same barycentric
//! combination of the coarse face's corner UVs (so the weft of every fine face is its
//! coarse face's), and the transfers below are exact. Smoothing (Loop) would move the fine
//! vertices off the rendered surface, change the areas the masses are measured on, and
//! need the neighbours' positions; a subdivision modifier on the cloth renders a smoother
//! surface than the one simulated either way.
//!
//! ## Transfers (mass exact)
//! - **Prolongation** of densities, coarse → fine: `σ_j = Σ_i φ_i(x_j) σ_i`, linear
//!   interpolation. With lumped fine areas `A_j`, `Σ_j A_j φ_i(x_j) = ∫ φ_i = A_i` (the
//!   lumped fine quadrature is exact for a function linear on each fine triangle), so the
//!   fine masses `A_j σ_j` sum to the coarse mass `Σ_i A_i σ_i`, and vertex by vertex the
//!   mass put at coarse vertex `i` is spread over its hat.
//! - **Restriction** of masses, fine → coarse: `m_i = Σ_j φ_i(x_j) m_j`, the transpose. As
//!   `Σ_i φ_i = 1`, totals are preserved to rounding; a coarse density is `m_i / A_i` with
//!   `A_i` the restriction of the fine areas.

use rayon::prelude::*;

use crate::error::{Error, MeshError, ParamError};
use crate::mesh::{EdgeKind, Topology};

/// The finest Detail level: every triangle split into `4³ = 64`.
pub const MAX_LEVEL: u32 = 3;

/// Largest fine mesh a refinement builds (vertices): beyond it the level is refused
/// before anything is allocated.
pub const MAX_FINE_VERTICES: usize = 20_000_000;

/// A coarse mesh refined `4^L` times (module doc).
#[derive(Debug, Clone)]
pub struct Refinement {
    level: u32,
    n_coarse: usize,
    fine: Topology,
    /// Per fine vertex, the (up to three) coarse vertices and hat weights `φ_i(x_j)`
    /// (unused slots have weight 0 and repeat a used vertex).
    weights: Vec<([u32; 3], [f64; 3])>,
    /// The template's lattice triangles, `(i, j)` of each corner, in fine-face order.
    template: Vec<[[u32; 2]; 3]>,
}

/// Fine vertex count of a mesh with `v` vertices, `e` edges and `f` faces at `level`.
pub(crate) fn fine_vertex_count(v: usize, e: usize, f: usize, level: u32) -> usize {
    let n = 1usize << level;
    v + e * (n - 1) + f * ((n - 1) * n.saturating_sub(2) / 2)
}

impl Refinement {
    /// Refines `coarse` `4^level` times. Refuses a level above [`MAX_LEVEL`] and a fine
    /// mesh of more than [`MAX_FINE_VERTICES`] vertices (with the figure), before
    /// allocating it.
    pub fn new(coarse: &Topology, level: u32) -> Result<Self, Error> {
        let n_fine = check_level(coarse, level)?;
        let (v, e, f) = (coarse.n_vertices(), coarse.n_edges(), coarse.n_faces());
        let n = 1u32 << level;
        let template = lattice_triangles(n);
        let per_face = (n as usize - 1) * (n as usize).saturating_sub(2) / 2;
        let interior_base = v + e * (n as usize - 1);

        let mut weights = Vec::with_capacity(n_fine);
        weights.extend((0..v as u32).map(|i| ([i; 3], [1.0, 0.0, 0.0])));
        for &[a, b] in coarse.edges() {
            for t in 1..n {
                let s = t as f64 / n as f64;
                weights.push(([a, b, b], [1.0 - s, s, 0.0]));
            }
        }
        for tri in coarse.faces() {
            for (i, j) in interior_points(n) {
                let (bi, bj) = (i as f64 / n as f64, j as f64 / n as f64);
                weights.push((*tri, [1.0 - bi - bj, bi, bj]));
            }
        }
        debug_assert_eq!(weights.len(), n_fine);

        let mut faces = Vec::with_capacity(f * template.len());
        let mut face_polygon = Vec::with_capacity(f * template.len());
        for (fi, tri) in coarse.faces().iter().enumerate() {
            let edges = coarse.face_edges()[fi];
            let point = |i: u32, j: u32| -> u32 {
                lattice_vertex(coarse, tri, &edges, n, i, j, interior_base + fi * per_face)
            };
            for corners in &template {
                faces.push(corners.map(|[i, j]| point(i, j)));
                face_polygon.push(coarse.face_polygon()[fi]);
            }
        }
        let fine = Topology::with_polygons(n_fine, faces, face_polygon, coarse.n_polygons())?;
        Ok(Self {
            level,
            n_coarse: v,
            fine,
            weights,
            template,
        })
    }

    /// The Detail level `L`.
    pub fn level(&self) -> u32 {
        self.level
    }
    /// Fine faces per coarse face, `4^L`.
    pub fn faces_per_face(&self) -> usize {
        self.template.len()
    }
    /// Vertices of the coarse mesh.
    pub fn n_coarse(&self) -> usize {
        self.n_coarse
    }
    /// The fine mesh.
    pub fn fine(&self) -> &Topology {
        &self.fine
    }
    /// Coarse face of fine face `t`.
    pub fn parent(&self, t: usize) -> usize {
        t / self.template.len()
    }

    /// Barycentric combination of coarse per-vertex values at every fine vertex
    /// (positions; densities: the prolongation of the module doc).
    pub fn prolong<T>(&self, coarse: &[T]) -> Vec<T>
    where
        T: Copy + Send + Sync + std::ops::Mul<f64, Output = T> + std::ops::Add<Output = T>,
    {
        use rayon::prelude::*;
        assert_eq!(coarse.len(), self.n_coarse, "one coarse value per vertex");
        self.weights
            .par_iter()
            .map(|(v, w)| {
                let c = |k: usize| coarse[v[k] as usize];
                c(0) * w[0] + c(1) * w[1] + c(2) * w[2]
            })
            .collect()
    }

    /// Restriction of fine masses to the coarse vertices, `m_i = Σ_j φ_i(x_j) m_j` (the
    /// transpose of [`Refinement::prolong`]; totals preserved). Sums in fine-vertex
    /// order, so the result does not depend on the thread count.
    pub fn restrict(&self, fine: &[f64]) -> Vec<f64> {
        assert_eq!(fine.len(), self.weights.len(), "one fine value per vertex");
        let mut out = vec![0.0; self.n_coarse];
        for ((v, w), &m) in self.weights.iter().zip(fine) {
            for k in 0..3 {
                if w[k] != 0.0 {
                    out[v[k] as usize] += w[k] * m;
                }
            }
        }
        out
    }

    /// The UVs of every fine face's corners from the coarse faces' corner UVs (the same
    /// barycentric combination as the positions, module doc).
    pub fn face_uv(&self, coarse_uv: &[[[f64; 2]; 3]]) -> Vec<[[f64; 2]; 3]> {
        coarse_uv
            .iter()
            .flat_map(|&c| lattice_uv(&self.template, self.level, c))
            .collect()
    }

    /// Per fine face, a per-coarse-face value (fabric tensors, weft angles).
    pub fn face_values<T: Copy>(&self, coarse: &[T]) -> Vec<T> {
        coarse
            .iter()
            .flat_map(|&x| std::iter::repeat_n(x, self.template.len()))
            .collect()
    }
}

/// Where a fine vertex lies on the coarse mesh: at a coarse vertex, inside a coarse edge,
/// or inside a coarse face.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Site {
    Vertex(u32),
    Edge(u32),
    Face(u32),
}

/// The part of a refined mesh over the coarse faces built so far (issue 12's lazy
/// refinement): the same lattice, placement and transfers as [`Refinement`], built
/// coarse face by coarse face as the liquid arrives. Fine vertices and faces are
/// numbered in the order they were built (*local* numbering); [`Partial::global`] gives
/// each vertex's index in [`Refinement`]'s numbering of the whole refined mesh. Memory is
/// `O(coarse mesh)` for the maps plus `O(built fine vertices)`.
#[derive(Debug, Clone)]
pub(crate) struct Partial {
    level: u32,
    coarse: Topology,
    /// Coarse faces around every coarse vertex (CSR) and on every coarse edge.
    vertex_faces: (Vec<u32>, Vec<u32>),
    edge_faces: (Vec<u32>, Vec<u32>),
    template: Vec<[[u32; 2]; 3]>,
    face_built: Vec<bool>,
    /// Coarse face of every block of `4^L` local fine faces.
    built: Vec<u32>,
    vertex_id: Vec<u32>,
    edge_base: Vec<u32>,
    face_base: Vec<u32>,
    /// Per local fine vertex: coarse vertices and hat weights (as [`Refinement`]'s), its
    /// index in the whole refined mesh, and where it lies.
    weights: Vec<([u32; 3], [f64; 3])>,
    global: Vec<u32>,
    site: Vec<Site>,
    faces: Vec<[u32; 3]>,
    n_full: usize,
}

/// Incidence lists `item → owners` as CSR from `(owner, items)` pairs.
fn csr(n: usize, pairs: impl Iterator<Item = (u32, u32)> + Clone) -> (Vec<u32>, Vec<u32>) {
    let mut ptr = vec![0u32; n + 1];
    for (_, item) in pairs.clone() {
        ptr[item as usize + 1] += 1;
    }
    for i in 0..n {
        ptr[i + 1] += ptr[i];
    }
    let mut fill = ptr.clone();
    let mut list = vec![0u32; ptr[n] as usize];
    for (owner, item) in pairs {
        list[fill[item as usize] as usize] = owner;
        fill[item as usize] += 1;
    }
    (ptr, list)
}

fn row(c: &(Vec<u32>, Vec<u32>), i: usize) -> &[u32] {
    &c.1[c.0[i] as usize..c.0[i + 1] as usize]
}

impl Partial {
    /// Nothing built yet of `coarse` refined `4^level` times. The same refusals as
    /// [`Refinement::new`] (level, and the whole refined mesh over
    /// [`MAX_FINE_VERTICES`]), from the counts alone.
    pub(crate) fn new(coarse: &Topology, level: u32) -> Result<Self, Error> {
        let n_full = check_level(coarse, level)?;
        let faces = coarse.faces();
        let vertex_faces = csr(
            coarse.n_vertices(),
            faces
                .iter()
                .enumerate()
                .flat_map(|(f, t)| t.iter().map(move |&v| (f as u32, v))),
        );
        let edge_faces = csr(
            coarse.n_edges(),
            coarse
                .face_edges()
                .iter()
                .enumerate()
                .flat_map(|(f, t)| t.iter().map(move |&e| (f as u32, e))),
        );
        Ok(Self {
            level,
            vertex_faces,
            edge_faces,
            template: lattice_triangles(1 << level),
            face_built: vec![false; coarse.n_faces()],
            built: Vec::new(),
            vertex_id: vec![u32::MAX; coarse.n_vertices()],
            edge_base: vec![u32::MAX; coarse.n_edges()],
            face_base: vec![u32::MAX; coarse.n_faces()],
            weights: Vec::new(),
            global: Vec::new(),
            site: Vec::new(),
            faces: Vec::new(),
            n_full,
            coarse: coarse.clone(),
        })
    }

    /// The Detail level `L`.
    pub(crate) fn level(&self) -> u32 {
        self.level
    }
    /// Vertices of the whole refined mesh.
    pub(crate) fn n_full(&self) -> usize {
        self.n_full
    }
    /// Fine vertices built.
    pub(crate) fn n_vertices(&self) -> usize {
        self.weights.len()
    }
    /// Coarse faces built.
    pub(crate) fn n_built_faces(&self) -> usize {
        self.built.len()
    }
    /// The coarse mesh.
    pub(crate) fn coarse(&self) -> &Topology {
        &self.coarse
    }
    /// Index in the whole refined mesh ([`Refinement`]'s numbering) of every local vertex.
    pub(crate) fn global(&self) -> &[u32] {
        &self.global
    }
    /// Local fine vertex at coarse vertex `v`, if built.
    pub(crate) fn at_vertex(&self, v: usize) -> Option<usize> {
        let j = self.vertex_id[v];
        (j != u32::MAX).then_some(j as usize)
    }
    /// Coarse faces around coarse vertex `v`.
    pub(crate) fn faces_around(&self, v: usize) -> &[u32] {
        row(&self.vertex_faces, v)
    }
    /// The coarse corners of the smallest coarse element holding local vertex `j`.
    pub(crate) fn corners(&self, j: usize) -> Vec<u32> {
        match self.site[j] {
            Site::Vertex(v) => vec![v],
            Site::Edge(e) => self.coarse.edges()[e as usize].to_vec(),
            Site::Face(f) => self.coarse.faces()[f as usize].to_vec(),
        }
    }
    /// Whether every fine face around local vertex `j` is built (its one-ring is the
    /// whole refined mesh's).
    pub(crate) fn is_complete(&self, j: usize) -> bool {
        let all = |faces: &[u32]| faces.iter().all(|&f| self.face_built[f as usize]);
        match self.site[j] {
            Site::Vertex(v) => all(row(&self.vertex_faces, v as usize)),
            Site::Edge(e) => all(row(&self.edge_faces, e as usize)),
            Site::Face(_) => true,
        }
    }

    /// Builds the coarse faces `faces` not built yet (in increasing order), appending
    /// their new fine vertices and faces. Returns how many coarse faces were new.
    pub(crate) fn build(&mut self, faces: &[u32]) -> usize {
        let mut new: Vec<u32> = faces
            .iter()
            .copied()
            .filter(|&f| !self.face_built[f as usize])
            .collect();
        new.sort_unstable();
        new.dedup();
        let n = 1u32 << self.level;
        let (v, e) = (self.coarse.n_vertices(), self.coarse.n_edges());
        let per_face = (n as usize - 1) * (n as usize).saturating_sub(2) / 2;
        let interior_base = v + e * (n as usize - 1);
        for &f in &new {
            let fi = f as usize;
            let tri = self.coarse.faces()[fi];
            let fe = self.coarse.face_edges()[fi];
            for c in tri {
                if self.vertex_id[c as usize] == u32::MAX {
                    self.vertex_id[c as usize] = self.weights.len() as u32;
                    self.weights.push(([c; 3], [1.0, 0.0, 0.0]));
                    self.global.push(c);
                    self.site.push(Site::Vertex(c));
                }
            }
            for &ed in &fe {
                if self.edge_base[ed as usize] == u32::MAX && n > 1 {
                    self.edge_base[ed as usize] = self.weights.len() as u32;
                    let [a, b] = self.coarse.edges()[ed as usize];
                    for t in 1..n {
                        let s = t as f64 / n as f64;
                        self.weights.push(([a, b, b], [1.0 - s, s, 0.0]));
                        self.global.push(v as u32 + ed * (n - 1) + (t - 1));
                        self.site.push(Site::Edge(ed));
                    }
                }
            }
            self.face_base[fi] = self.weights.len() as u32;
            for (k, (i, j)) in interior_points(n).enumerate() {
                let (bi, bj) = (i as f64 / n as f64, j as f64 / n as f64);
                self.weights.push((tri, [1.0 - bi - bj, bi, bj]));
                self.global.push((interior_base + fi * per_face + k) as u32);
                self.site.push(Site::Face(f));
            }
            for corners in &self.template {
                let t = corners.map(|[i, j]| self.local(fi, n, i, j));
                self.faces.push(t);
            }
            self.face_built[fi] = true;
            self.built.push(f);
        }
        new.len()
    }

    /// Local fine vertex of lattice point `(i, j)` of built coarse face `fi`.
    fn local(&self, fi: usize, n: u32, i: u32, j: u32) -> u32 {
        let tri = self.coarse.faces()[fi];
        let fe = self.coarse.face_edges()[fi];
        let on_edge = |a: usize, b: usize, c: usize, t: u32| -> u32 {
            if t == 0 {
                return self.vertex_id[tri[a] as usize];
            }
            if t == n {
                return self.vertex_id[tri[b] as usize];
            }
            let e = fe[c];
            let [first, _] = self.coarse.edges()[e as usize];
            let s = if first == tri[a] { t } else { n - t };
            self.edge_base[e as usize] + (s - 1)
        };
        if j == 0 {
            on_edge(0, 1, 2, i)
        } else if i == 0 {
            on_edge(0, 2, 1, j)
        } else if i + j == n {
            on_edge(1, 2, 0, j)
        } else {
            let before: u32 = (1..j).map(|r| n - r - 1).sum();
            self.face_base[fi] + before + (i - 1)
        }
    }

    /// The built part as a mesh of its own (local numbering; every fine face keeps its
    /// coarse face's polygon).
    pub(crate) fn topology(&self) -> Result<Topology, MeshError> {
        let polygon = self.face_values(self.coarse.face_polygon());
        Topology::with_polygons(
            self.weights.len(),
            self.faces.clone(),
            polygon,
            self.coarse.n_polygons(),
        )
    }

    /// The built part as [`Partial::topology`] makes it, from `old`, the part as it was
    /// before the last builds: only the new faces' edges are sorted
    /// ([`Topology::extended`]); also the new index of every old edge.
    pub(crate) fn extended_topology(
        &self,
        old: &Topology,
    ) -> Result<(Topology, Vec<u32>), MeshError> {
        let polygon = self.face_values(self.coarse.face_polygon());
        old.extended(
            self.weights.len(),
            &self.faces[old.n_faces()..],
            polygon,
            self.coarse.n_polygons(),
        )
    }

    /// Per local fine face, the value of its coarse face (in parallel).
    pub(crate) fn face_values<T: Copy + Send + Sync>(&self, coarse: &[T]) -> Vec<T> {
        let per = self.template.len();
        (0..self.faces.len())
            .into_par_iter()
            .map(|t| coarse[self.built[t / per] as usize])
            .collect()
    }

    /// Per local fine face, its corners' UVs from the coarse faces' (as
    /// [`Refinement::face_uv`]).
    pub(crate) fn face_uv(&self, coarse_uv: &[[[f64; 2]; 3]]) -> Vec<[[f64; 2]; 3]> {
        self.built
            .iter()
            .flat_map(|&f| lattice_uv(&self.template, self.level, coarse_uv[f as usize]))
            .collect()
    }

    /// Per local vertex, whether it lies on the coarse mesh's border (a border vertex of
    /// the whole refined mesh: the built part's own edge is not the cloth's).
    pub(crate) fn boundary(&self) -> Vec<bool> {
        let on_vertex = self.coarse.boundary_vertices();
        self.site
            .iter()
            .map(|s| match *s {
                Site::Vertex(v) => on_vertex[v as usize],
                Site::Edge(e) => self.coarse.edge_kind(e as usize) == EdgeKind::Boundary,
                Site::Face(_) => false,
            })
            .collect()
    }

    /// Per local vertex, the coarse element all of whose fine vertices have congruent
    /// one-rings moving with the same affine maps (their Kabsch rotations are one,
    /// [`crate::mesh::RingAdjacency::shared_rotations`]): coarse edge `e` → `e`, coarse
    /// face `f` → `E + f`; `u32::MAX` at a coarse vertex (its ring is its own). The fine
    /// vertices of one element are built together, so they are consecutive.
    pub(crate) fn congruence(&self) -> Vec<u32> {
        let e = self.coarse.n_edges() as u32;
        self.site
            .iter()
            .map(|s| match *s {
                Site::Vertex(_) => u32::MAX,
                Site::Edge(ed) => ed,
                Site::Face(f) => e + f,
            })
            .collect()
    }

    /// Per local fine face, its class of similar faces and how its corners map onto its
    /// coarse face's: `4 b + c`, `b` the position of its coarse face among the built ones
    /// and corner `k` having the angle of coarse corner `(k + c) % 3` ([`corner_shift`]).
    /// The lattice triangles of one planar coarse face are its translates scaled by
    /// `±1/N`, so their tip angles are the coarse face's
    /// ([`crate::mesh::Transport::with_shared_tips`]). The faces of one class are
    /// consecutive.
    pub(crate) fn face_congruence(&self) -> Vec<u32> {
        let shift: Vec<u32> = self.template.iter().map(corner_shift).collect();
        let per = self.template.len();
        (0..self.faces.len())
            .map(|t| 4 * (t / per) as u32 + shift[t % per])
            .collect()
    }

    /// [`Refinement::prolong`] on the built vertices.
    pub(crate) fn prolong<T>(&self, coarse: &[T]) -> Vec<T>
    where
        T: Copy + Send + Sync + std::ops::Mul<f64, Output = T> + std::ops::Add<Output = T>,
    {
        use rayon::prelude::*;
        assert_eq!(
            coarse.len(),
            self.coarse.n_vertices(),
            "one coarse value per vertex"
        );
        self.weights
            .par_iter()
            .map(|(v, w)| {
                let c = |k: usize| coarse[v[k] as usize];
                c(0) * w[0] + c(1) * w[1] + c(2) * w[2]
            })
            .collect()
    }

    /// [`Refinement::restrict`] of the built vertices' masses (the others hold none), in
    /// local order.
    pub(crate) fn restrict(&self, fine: &[f64]) -> Vec<f64> {
        assert_eq!(fine.len(), self.weights.len(), "one fine value per vertex");
        let mut out = vec![0.0; self.coarse.n_vertices()];
        for ((v, w), &m) in self.weights.iter().zip(fine) {
            for k in 0..3 {
                if w[k] != 0.0 {
                    out[v[k] as usize] += w[k] * m;
                }
            }
        }
        out
    }
}

/// Refuses a level above [`MAX_LEVEL`] and a refined mesh of more than
/// [`MAX_FINE_VERTICES`] vertices (with the figure), from the counts alone. Returns the
/// refined mesh's vertex count.
fn check_level(coarse: &Topology, level: u32) -> Result<usize, Error> {
    if level > MAX_LEVEL {
        return Err(ParamError::OutOfRange {
            name: "detail level",
            requirement: "an integer from 0 to 3",
            value: level as f64,
        }
        .into());
    }
    let (v, e, f) = (coarse.n_vertices(), coarse.n_edges(), coarse.n_faces());
    let n_fine = fine_vertex_count(v, e, f, level);
    if n_fine > MAX_FINE_VERTICES || n_fine > u32::MAX as usize {
        return Err(MeshError::DetailTooLarge {
            level,
            vertices: n_fine,
            max: MAX_FINE_VERTICES,
        }
        .into());
    }
    Ok(n_fine)
}

/// The `N²` lattice triangles of one face, up triangles row by row then down ones.
fn lattice_triangles(n: u32) -> Vec<[[u32; 2]; 3]> {
    let mut t = Vec::with_capacity((n * n) as usize);
    for j in 0..n {
        for i in 0..n - j {
            t.push([[i, j], [i + 1, j], [i, j + 1]]);
            if i + j + 2 <= n {
                t.push([[i + 1, j], [i + 1, j + 1], [i, j + 1]]);
            }
        }
    }
    t
}

/// The coarse corner whose angle corner 0 of lattice triangle `t` has, which is also the
/// shift `c` taking every corner `k` of `t` to coarse corner `(k + c) % 3`: a corner's angle
/// is the coarse face's at the corner whose two edges lie along the same two lattice
/// lines (`i`, `j` or the diagonal), up triangles being translates of the coarse face and
/// down ones its point reflections.
fn corner_shift(t: &[[u32; 2]; 3]) -> u32 {
    // the line of a lattice step: 0 along i (v₀v₁), 1 along j (v₀v₂), 2 diagonal (v₁v₂)
    let line = |a: [u32; 2], b: [u32; 2]| match (a[0] == b[0], a[1] == b[1]) {
        (false, true) => 0,
        (true, false) => 1,
        _ => 2,
    };
    // coarse corner from the set of its two lines: {i, j} → 0, {i, diag} → 1, {j, diag} → 2
    let corner = |k: usize| match line(t[k], t[(k + 1) % 3]) + line(t[k], t[(k + 2) % 3]) {
        1 => 0,
        2 => 1,
        _ => 2,
    };
    let c = corner(0);
    debug_assert!((0..3).all(|k| corner(k) == (k as u32 + c) % 3));
    c
}

/// The shares of [`crate::mesh::Transport::with_shared_tips`] for faces whose classes
/// ([`Partial::face_congruence`], in the faces' order) come in runs, one run per coarse
/// face: the first face of a run serves the run, each face with its corner shift relative
/// to that first one.
pub(crate) fn tip_shares(classes: impl Iterator<Item = u32>) -> Vec<(u32, u8)> {
    let mut run = (u32::MAX, 0u32, 0u32);
    classes
        .enumerate()
        .map(|(k, c)| {
            if run.0 != c / 4 {
                run = (c / 4, k as u32, c % 4);
            }
            (run.1, ((c % 4 + 3 - run.2) % 3) as u8)
        })
        .collect()
}

/// Tests' coarse sheet: an `nx × ny` grid of triangles of unequal angles, flat at rest
/// and folded now (each coarse face moved by its own affine map); `(topology, rest, now)`.
#[cfg(test)]
pub(crate) fn folded_grid(nx: usize, ny: usize) -> (Topology, Vec<glam::DVec3>, Vec<glam::DVec3>) {
    use glam::DVec3;
    let rest: Vec<DVec3> = (0..nx * ny)
        .map(|v| DVec3::new((v % nx) as f64 * 0.3, (v / nx) as f64 * 0.25, 0.0))
        .collect();
    let now = rest
        .iter()
        .map(|p| {
            DVec3::new(
                p.x + 0.2 * p.y,
                0.4 * (2.0 * p.x).sin(),
                p.y + 0.1 * p.x * p.x,
            )
        })
        .collect();
    (crate::mesh::topology::grid_topology(nx, ny), rest, now)
}

/// The lattice points strictly inside a face, in the fine numbering's order.
fn interior_points(n: u32) -> impl Iterator<Item = (u32, u32)> {
    (1..n).flat_map(move |j| (1..n - j).map(move |i| (i, j)))
}

/// Fine vertex of lattice point `(i, j)` of face `tri` (module doc's numbering).
fn lattice_vertex(
    coarse: &Topology,
    tri: &[u32; 3],
    face_edges: &[u32; 3],
    n: u32,
    i: u32,
    j: u32,
    interior_base: usize,
) -> u32 {
    let v = coarse.n_vertices() as u32;
    // the point at `t` steps from corner `a` toward corner `b` (the edge opposite the
    // third corner `c`)
    let on_edge = |a: usize, b: usize, c: usize, t: u32| -> u32 {
        if t == 0 {
            return tri[a];
        }
        if t == n {
            return tri[b];
        }
        let e = face_edges[c];
        let [first, _] = coarse.edges()[e as usize];
        let s = if first == tri[a] { t } else { n - t };
        v + e * (n - 1) + (s - 1)
    };
    if j == 0 {
        on_edge(0, 1, 2, i)
    } else if i == 0 {
        on_edge(0, 2, 1, j)
    } else if i + j == n {
        on_edge(1, 2, 0, j)
    } else {
        // interior: rows j = 1.., each i = 1 .. n−j−1
        let before: u32 = (1..j).map(|r| n - r - 1).sum();
        (interior_base as u32) + before + (i - 1)
    }
}

/// The corner UVs of the lattice triangles `template` of one coarse face at `level`,
/// from the coarse corners' UVs `c` (the positions' barycentric combination; module doc).
fn lattice_uv(
    template: &[[[u32; 2]; 3]],
    level: u32,
    c: [[f64; 2]; 3],
) -> impl Iterator<Item = [[f64; 2]; 3]> + '_ {
    let n = (1u32 << level) as f64;
    template.iter().map(move |corners| {
        corners.map(|[i, j]| {
            let (bi, bj) = (i as f64 / n, j as f64 / n);
            let b0 = 1.0 - bi - bj;
            [
                b0 * c[0][0] + bi * c[1][0] + bj * c[2][0],
                b0 * c[0][1] + bi * c[1][1] + bj * c[2][1],
            ]
        })
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lattice_counts() {
        for n in [1u32, 2, 4, 8] {
            assert_eq!(lattice_triangles(n).len(), (n * n) as usize);
            let m = (n as usize - 1) * (n as usize).saturating_sub(2) / 2;
            assert_eq!(interior_points(n).count(), m);
        }
    }

    #[test]
    fn similar_faces_share_their_tip_angles() {
        use crate::mesh::{Geometry, OneRings, Transport, VertexFrames};
        // folded: each coarse face moves by its own affine map, so its fine faces stay
        // similar to it
        let (coarse, _, now) = folded_grid(4, 3);
        for level in 1..=3 {
            let mut part = Partial::new(&coarse, level).unwrap();
            part.build(&(0..coarse.n_faces() as u32).collect::<Vec<_>>());
            let topo = part.topology().unwrap();
            let q = part.prolong(&now);
            let share = tip_shares(part.face_congruence().into_iter());
            assert!(share.iter().any(|&(_, c)| c != 0), "down faces are shifted");
            let rings = OneRings::new(&topo);
            let geometry = Geometry::new(&topo, &q).unwrap();
            let frames = VertexFrames::new(&rings, &q).unwrap();
            let own = Transport::new(&topo, &rings, &geometry, &frames, &q);
            let shared =
                Transport::with_shared_tips(&topo, &rings, &geometry, &frames, &q, Some(&share));
            let mut worst: f64 = 0.0;
            for v in 0..topo.n_vertices() {
                for (a, b) in own.polar_angles(v).iter().zip(shared.polar_angles(v)) {
                    worst = worst.max((a - b).abs());
                }
                worst = worst.max((own.angle_sum(v) - shared.angle_sum(v)).abs());
            }
            for (a, b) in own.edge_angles().iter().zip(shared.edge_angles()) {
                worst = worst.max(wrap(a - b).abs());
            }
            assert!(worst < 1e-13, "level {level}: shared tips off by {worst:e}");
            // the shift matters: without it the down faces get the wrong corners
            let unshifted: Vec<(u32, u8)> = share.iter().map(|&(r, _)| (r, 0)).collect();
            let wrong = Transport::with_shared_tips(
                &topo,
                &rings,
                &geometry,
                &frames,
                &q,
                Some(&unshifted),
            );
            let off = (0..topo.n_vertices())
                .flat_map(|v| {
                    own.polar_angles(v)
                        .iter()
                        .zip(wrong.polar_angles(v))
                        .map(|(a, b)| (a - b).abs())
                        .collect::<Vec<_>>()
                })
                .fold(0.0, f64::max);
            assert!(
                off > 1e-2,
                "level {level}: the shift changed nothing ({off:e})"
            );
        }
    }

    fn wrap(a: f64) -> f64 {
        crate::mesh::transport::wrap_angle(a)
    }

    #[test]
    fn congruent_rings_share_their_kabsch_rotation() {
        use crate::mesh::RingAdjacency;
        use glam::DVec3;
        // bent and sheared: the rest sheet is flat, the current one folded along a curve
        // (each coarse face moves by its own affine map)
        let (coarse, rest, now) = folded_grid(5, 4);
        for level in 1..=3 {
            let mut part = Partial::new(&coarse, level).unwrap();
            part.build(&(0..coarse.n_faces() as u32).collect::<Vec<_>>());
            let adjacency = RingAdjacency::new(&part.topology().unwrap());
            let (r, q) = (part.prolong(&rest), part.prolong(&now));
            let class = part.congruence();
            // the first vertex of each run of a class serves the run
            let share: Vec<u32> = (0..class.len())
                .map(|j| match class[j] {
                    u32::MAX => j as u32,
                    c => (0..=j).find(|&k| class[k] == c).unwrap() as u32,
                })
                .collect();
            assert!(share.iter().enumerate().all(|(j, &k)| k as usize == j
                || (k as usize) < j && class[k as usize..=j].iter().all(|&c| c == class[j])));
            let own = adjacency.rotations(&r, &q);
            let mut shared = Vec::new();
            adjacency.shared_rotations(&r, &q, &share, &mut shared);
            let shared_count = share.iter().enumerate().filter(|&(j, &k)| k as usize != j);
            assert!(level == 1 || shared_count.count() > 0);
            let worst = own
                .iter()
                .zip(&shared)
                .map(|(a, b)| {
                    (*a - *b)
                        .to_cols_array()
                        .iter()
                        .fold(0.0, |m: f64, x| m.max(x.abs()))
                })
                .fold(0.0, f64::max);
            assert!(
                worst < 1e-13,
                "level {level}: shared rotations off by {worst:e}"
            );
            for (j, &k) in share.iter().enumerate() {
                if k as usize == j {
                    assert_eq!(own[j], shared[j], "a vertex's own rotation is unchanged");
                }
            }
            // placed off the affine maps (a bump inside the faces), the rings are no
            // longer moved alike, and sharing would be wrong
            let bumped: Vec<DVec3> = q
                .iter()
                .zip(&r)
                .map(|(p, x)| *p + DVec3::Z * 0.05 * (7.0 * x.x).sin() * (9.0 * x.y).cos())
                .collect();
            let own = adjacency.rotations(&r, &bumped);
            let mut shared = Vec::new();
            adjacency.shared_rotations(&r, &bumped, &share, &mut shared);
            let worst = own
                .iter()
                .zip(&shared)
                .map(|(a, b)| {
                    (*a - *b)
                        .to_cols_array()
                        .iter()
                        .fold(0.0, |m: f64, x| m.max(x.abs()))
                })
                .fold(0.0, f64::max);
            assert!(
                level == 1 || worst > 1e-3,
                "level {level}: the bump changed nothing ({worst:e})"
            );
        }
    }
}
