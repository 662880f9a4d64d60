//! Per-frame geometry of a deforming mesh (seed §4.3.3): edge lengths, face areas, the
//! cotangent of every corner, and the lumped (barycentric) vertex areas `A_i`.
//!
//! Everything here is *intrinsic*: computed from edge lengths alone, in `f64`.
//! For a triangle with sides `a, b, c` the area is Heron's formula in Kahan's
//! cancellation-free ordering (`a ≥ b ≥ c`):
//!
//! ```text
//! A = ¼ √((a+(b+c)) (c−(a−b)) (c+(a−b)) (a+(b−c)))
//! ```
//!
//! and the cotangent of the corner opposite side `a` is `cot α = (b² + c² − a²) / (4A)`.
//! The lumped mass of a vertex is one third of the area of its incident faces,
//! `M_ii = A_i = Σ_{T∋i} A_T / 3`.
//!
//! ## Zero-area faces: intrinsic mollification
//! Cloth meshes do contain faces of (near-)zero area: collapsed triangles after a
//! cloth collision, slivers from triangulating a concave n-gon. For those, `cot` divides
//! by zero and the cotan Laplacian gets Inf/NaN entries. We use the *intrinsic
//! mollification* of Sharp & Crane ("A Laplacian for Nonmanifold Triangle Meshes",
//! SGP 2020, §4.5): with `ε = 10⁻⁶ ×` the mean edge length, we find the smallest `δ ≥ 0`
//! such that every triangle satisfies the triangle inequality with margin `ε` once `δ` is
//! added to *every* edge length, and we add it. This changes nothing on a healthy mesh
//! (`δ = 0`), turns a degenerate face into a valid, thin one (area `O(ℓ √(ℓ ε))`,
//! cotangents `O(√(ℓ/ε))`, about 10³ for `ε = 10⁻⁶ ℓ`), keeps every row sum of the Laplacian exactly zero (so diffusion still
//! conserves mass) and keeps every vertex with an incident face at positive mass (so
//! `M + hL` stays positive definite). The alternative, dropping degenerate faces, would
//! leave a vertex whose faces are all degenerate with a zero row; and clamping cotangents
//! to an arbitrary bound breaks the linear precision of the operator on healthy meshes.

use glam::DVec3;
use rayon::prelude::*;

use super::Topology;
use crate::error::MeshError;

/// Relative size of the mollification margin, as a fraction of the mean edge length.
pub(crate) const MOLLIFY_EPS_REL: f64 = 1e-6;

/// Geometry of one frame of a mesh with fixed [`Topology`].
#[derive(Debug, Clone, Default)]
pub struct Geometry {
    /// Mollified intrinsic length of every edge (indexed like [`Topology::edges`]).
    pub edge_length: Vec<f64>,
    /// Area of every face.
    pub face_area: Vec<f64>,
    /// `face_cot[f][k]`: cotangent of the angle at corner `k` of face `f`.
    pub face_cot: Vec<[f64; 3]>,
    /// Lumped mass `A_i` (one third of the incident face areas) per vertex.
    pub vertex_area: Vec<f64>,
    /// The length `δ` added to every edge by the mollification (0 on a healthy mesh).
    pub mollify_delta: f64,
    /// Number of faces whose triangle inequality margin was below `ε` before mollifying.
    pub n_degenerate_faces: usize,
}

impl Geometry {
    /// Geometry of `topology` at vertex `positions` (any precision, converted to `f64`).
    ///
    /// Fails with [`MeshError::VertexCountMismatch`] or [`MeshError::NonFinitePosition`]
    /// (naming the first bad vertex).
    pub fn new<P: Copy + Into<DVec3> + Sync>(
        topology: &Topology,
        positions: &[P],
    ) -> Result<Self, MeshError> {
        let mut geometry = Self::default();
        geometry.renew(topology, positions)?;
        Ok(geometry)
    }

    /// [`Geometry::new`] in this geometry's arrays (their allocations kept: the simulator
    /// renews one geometry every sub-step instead of allocating its arrays afresh, see
    /// the step scratch of `stain::simulate`). The same values, bit for bit; on error
    /// `self` is left unchanged.
    pub(crate) fn renew<P: Copy + Into<DVec3> + Sync>(
        &mut self,
        topology: &Topology,
        positions: &[P],
    ) -> Result<(), MeshError> {
        check_positions(topology, positions)?;
        topology
            .edges()
            .par_iter()
            .map(|&[a, b]| {
                positions[a as usize]
                    .into()
                    .distance(positions[b as usize].into())
            })
            .collect_into_vec(&mut self.edge_length);
        self.complete(topology);
        Ok(())
    }

    /// The rest of the geometry from the raw edge lengths in `self.edge_length` (mollified
    /// in place), into the arrays already there.
    fn complete(&mut self, topology: &Topology) {
        let edge_length = &mut self.edge_length;
        let mean = edge_length.iter().sum::<f64>() / edge_length.len().max(1) as f64;
        let eps = MOLLIFY_EPS_REL * mean;
        let margin = |f: &[u32; 3]| {
            let [a, b, c] = f.map(|e| edge_length[e as usize]);
            (b + c - a).min(c + a - b).min(a + b - c)
        };
        let (delta, n_degenerate_faces) = topology
            .face_edges()
            .iter()
            .map(margin)
            .filter(|&m| m < eps)
            .fold((0.0f64, 0usize), |(d, n), m| (d.max(eps - m), n + 1));
        if delta > 0.0 {
            edge_length.iter_mut().for_each(|l| *l += delta);
        }
        let edge_length = &*edge_length;
        topology
            .face_edges()
            .par_iter()
            .map(|fe| triangle_area_cot(fe.map(|e| edge_length[e as usize])))
            .unzip_into_vecs(&mut self.face_area, &mut self.face_cot);
        let vertex_area = &mut self.vertex_area;
        vertex_area.clear();
        vertex_area.resize(topology.n_vertices(), 0.0);
        for (tri, &area) in topology.faces().iter().zip(&self.face_area) {
            for &v in tri {
                vertex_area[v as usize] += area / 3.0;
            }
        }
        self.mollify_delta = delta;
        self.n_degenerate_faces = n_degenerate_faces;
    }

    /// Total area of the mesh.
    #[cfg(test)]
    pub(crate) fn total_area(&self) -> f64 {
        self.face_area.iter().sum()
    }
}

/// Checks that there is one finite position per vertex, naming the first bad vertex.
pub fn check_positions<P: Copy + Into<DVec3>>(
    topology: &Topology,
    positions: &[P],
) -> Result<(), MeshError> {
    if positions.len() != topology.n_vertices() {
        return Err(MeshError::VertexCountMismatch {
            expected: topology.n_vertices(),
            got: positions.len(),
        });
    }
    match positions.iter().position(|&p| !p.into().is_finite()) {
        Some(vertex) => Err(MeshError::NonFinitePosition { vertex }),
        None => Ok(()),
    }
}

/// Area and corner cotangents of a triangle with side `l[k]` opposite corner `k`.
/// Requires a strict triangle inequality (guaranteed after mollification).
fn triangle_area_cot(l: [f64; 3]) -> (f64, [f64; 3]) {
    let area = heron(l);
    let sq = l.map(|x| x * x);
    let cot = std::array::from_fn(|k| (sq[(k + 1) % 3] + sq[(k + 2) % 3] - sq[k]) / (4.0 * area));
    (area, cot)
}

/// Heron's formula in Kahan's cancellation-free ordering (module doc).
fn heron(l: [f64; 3]) -> f64 {
    let mut s = l;
    s.sort_by(|x, y| y.total_cmp(x));
    let [a, b, c] = s;
    0.25 * ((a + (b + c)) * (c - (a - b)) * (c + (a - b)) * (a + (b - c)))
        .max(0.0)
        .sqrt()
}

/// The lumped area `A_v = Σ_{T∋v} A_T / 3` of one vertex from the positions of its
/// faces' corners (the [`Geometry`] value, unmollified), for a vertex whose area is
/// needed without the whole mesh's geometry.
pub(crate) fn vertex_area<P: Copy + Into<DVec3>>(
    faces: impl Iterator<Item = [u32; 3]>,
    positions: &[P],
) -> f64 {
    faces.map(|f| face_third(&f, positions)).sum()
}

/// The lumped areas `A_v = Σ_{T∋v} A_T / 3` of every vertex (unmollified, as
/// [`vertex_area`]), summed face by face in face order.
pub fn vertex_areas<P: Copy + Into<DVec3>>(topology: &Topology, positions: &[P]) -> Vec<f64> {
    let mut area = vec![0.0; topology.n_vertices()];
    for f in topology.faces() {
        let a = face_third(f, positions);
        for &v in f {
            area[v as usize] += a;
        }
    }
    area
}

/// [`vertex_areas`] in parallel, given each vertex's faces in increasing order
/// (`faces_of(v)`): every face's third once, then each vertex's sum in face order, so
/// the same bits as [`vertex_areas`] whatever the thread count.
pub(crate) fn vertex_areas_par<'a, P: Copy + Into<DVec3> + Sync>(
    topology: &Topology,
    positions: &[P],
    faces_of: impl Fn(usize) -> &'a [u32] + Sync,
) -> Vec<f64> {
    use rayon::prelude::*;
    let third: Vec<f64> = topology
        .faces()
        .par_iter()
        .map(|f| face_third(f, positions))
        .collect();
    (0..topology.n_vertices())
        .into_par_iter()
        .map(|v| faces_of(v).iter().fold(0.0, |a, &f| a + third[f as usize]))
        .collect()
}

/// A third of face `f`'s area (its share of each corner's lumped area).
pub(crate) fn face_third<P: Copy + Into<DVec3>>(f: &[u32; 3], positions: &[P]) -> f64 {
    let p = f.map(|v| positions[v as usize].into());
    heron([
        p[1].distance(p[2]),
        p[2].distance(p[0]),
        p[0].distance(p[1]),
    ]) / 3.0
}

#[cfg(test)]
mod tests {
    use super::*;

    fn right_triangle() -> (Topology, Vec<DVec3>) {
        let t = Topology::from_triangles(3, vec![[0, 1, 2]]).unwrap();
        (t, vec![DVec3::ZERO, DVec3::X, DVec3::Y])
    }

    #[test]
    fn right_triangle_area_and_cotangents() {
        let (t, p) = right_triangle();
        let g = Geometry::new(&t, &p).unwrap();
        assert!((g.face_area[0] - 0.5).abs() < 1e-15);
        let [c0, c1, c2] = g.face_cot[0];
        assert!(c0.abs() < 1e-15, "right angle at corner 0: cot = {c0}");
        assert!((c1 - 1.0).abs() < 1e-14 && (c2 - 1.0).abs() < 1e-14);
        assert_eq!(
            g.vertex_area
                .iter()
                .map(|a| (a * 6.0).round() as i32)
                .collect::<Vec<_>>(),
            vec![1, 1, 1]
        );
        assert_eq!(g.mollify_delta, 0.0);
    }

    #[test]
    fn collapsed_face_is_mollified_to_finite_values() {
        // face 1 is flat: vertex 3 lies on the segment 0–1
        let t = Topology::from_triangles(4, vec![[0, 1, 2], [1, 0, 3]]).unwrap();
        let p = [DVec3::ZERO, DVec3::X, DVec3::Y, DVec3::new(0.5, 0.0, 0.0)];
        let g = Geometry::new(&t, &p).unwrap();
        assert_eq!(g.n_degenerate_faces, 1);
        assert!(g.mollify_delta > 0.0 && g.mollify_delta <= MOLLIFY_EPS_REL * 2.0);
        // sides 1+δ, ½+δ, ½+δ: area ≈ ¼√(2δ)
        assert!(
            (g.face_area[1] - 0.25 * (2.0 * g.mollify_delta).sqrt()).abs()
                < 1e-6 * g.face_area[1].max(1e-3)
        );
        assert!(g.face_cot.iter().flatten().all(|c| c.is_finite()));
        assert!(g.vertex_area.iter().all(|&a| a > 0.0));
    }

    #[test]
    fn nan_position_is_named() {
        let (t, mut p) = right_triangle();
        p[2].y = f64::NAN;
        assert_eq!(
            Geometry::new(&t, &p).unwrap_err(),
            MeshError::NonFinitePosition { vertex: 2 }
        );
        assert_eq!(
            Geometry::new(&t, &p[..2]).unwrap_err(),
            MeshError::VertexCountMismatch {
                expected: 3,
                got: 2
            }
        );
    }
}
