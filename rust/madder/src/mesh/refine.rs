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

use crate::error::{Error, MeshError, ParamError};
use crate::mesh::Topology;

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
        let n = (1u32 << self.level) as f64;
        coarse_uv
            .iter()
            .flat_map(|c| {
                self.template.iter().map(move |corners| {
                    corners.map(|[i, j]| {
                        let (bi, bj) = (i as f64 / n, j as f64 / n);
                        let b0 = 1.0 - bi - bj;
                        [
                            b0 * c[0][0] + bi * c[1][0] + bj * c[2][0],
                            b0 * c[0][1] + bi * c[1][1] + bj * c[2][1],
                        ]
                    })
                })
            })
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
}
