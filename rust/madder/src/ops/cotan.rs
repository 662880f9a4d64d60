//! Cotan stiffness and lumped mass (seed §4.3.3, eq. 4.5).
//!
//! The piecewise-linear finite-element stiffness `K_ij = Σ_T ∫_T ∇φ_i · ∇φ_j` is, per
//! triangle, `−½ cot θ_k` on the edge `ij` opposite corner `k`, and the diagonal is the
//! negative sum of its row, `K_ii = Σ_T ½ (cot θ_j + cot θ_k)`. `K` is symmetric positive
//! semi-definite with `K·1 = 0`, which is what makes implicit diffusion conserve mass.
//! The lumped mass is `M_ii = A_i` (one third of the incident face areas).
//! (The seed writes `w_ij = −½(cot α + cot β)` for the off-diagonal; same matrix.)
//!
//! Assembly runs in face order on one thread: it is `O(F)` adds into a fixed pattern,
//! cheap next to the factorization, and a fixed summation order keeps the values
//! bit-identical whatever the thread count.

use super::VertexPattern;
use crate::mesh::{Geometry, Topology};

/// Values of the cotan stiffness `K` on `pattern`, scaled by `scale`.
pub fn cotan_stiffness(
    topology: &Topology,
    geometry: &Geometry,
    pattern: &VertexPattern,
    scale: f64,
) -> Vec<f64> {
    assemble_face_weights(topology, pattern, |f| {
        geometry.face_cot[f].map(|c| -0.5 * scale * c)
    })
}

/// Assembles a stiffness-like matrix from per-face off-diagonal weights: `weights(f)[k]`
/// is the entry `K_ij` of the edge opposite corner `k` (between corners `k+1`, `k+2`).
/// Each face adds `−w` to both endpoints' diagonals, so every row sums to zero face by face
/// (what makes diffusion conserve mass), whatever the weights.
pub(crate) fn assemble_face_weights(
    topology: &Topology,
    pattern: &VertexPattern,
    weights: impl Fn(usize) -> [f64; 3],
) -> Vec<f64> {
    let mut values = vec![0.0; pattern.nnz()];
    let (diag, edge) = (pattern.diag_slot(), pattern.edge_slot());
    for (f, (fe, tri)) in topology
        .face_edges()
        .iter()
        .zip(topology.faces())
        .enumerate()
    {
        let w = weights(f);
        for k in 0..3 {
            let (i, j) = (tri[(k + 1) % 3] as usize, tri[(k + 2) % 3] as usize);
            values[edge[fe[k] as usize] as usize] += w[k];
            values[diag[i] as usize] -= w[k];
            values[diag[j] as usize] -= w[k];
        }
    }
    values
}

/// Adds `scale × M` (lumped mass) to the diagonal of `values`.
pub fn add_lumped_mass(
    geometry: &Geometry,
    pattern: &VertexPattern,
    scale: f64,
    values: &mut [f64],
) {
    for (&s, &a) in pattern.diag_slot().iter().zip(&geometry.vertex_area) {
        values[s as usize] += scale * a;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec3;

    /// A regular grid over [0,1]², split along alternating diagonals.
    fn grid(n: usize) -> (Topology, Vec<DVec3>) {
        let idx = |i: usize, j: usize| (i * (n + 1) + j) as u32;
        let mut faces = Vec::new();
        for i in 0..n {
            for j in 0..n {
                let (a, b, c, d) = (idx(i, j), idx(i, j + 1), idx(i + 1, j + 1), idx(i + 1, j));
                if (i + j) % 2 == 0 {
                    faces.extend([[a, b, c], [a, c, d]]);
                } else {
                    faces.extend([[a, b, d], [b, c, d]]);
                }
            }
        }
        let pos = (0..=n)
            .flat_map(|i| {
                (0..=n).map(move |j| DVec3::new(j as f64 / n as f64, i as f64 / n as f64, 0.0))
            })
            .collect();
        (
            Topology::from_triangles((n + 1) * (n + 1), faces).unwrap(),
            pos,
        )
    }

    #[test]
    fn stiffness_kills_constants_and_linear_functions_inside() {
        let (t, p) = grid(6);
        let g = Geometry::new(&t, &p).unwrap();
        let pat = VertexPattern::new(&t);
        let k = cotan_stiffness(&t, &g, &pat, 1.0);
        let ones = pat.sym_matvec(&k, &vec![1.0; t.n_vertices()]);
        assert!(ones.iter().all(|v| v.abs() < 1e-13));
        // linear precision: K x = 0 at interior vertices for x = 2u − 3v
        let lin: Vec<f64> = p.iter().map(|q| 2.0 * q.x - 3.0 * q.y).collect();
        let kl = pat.sym_matvec(&k, &lin);
        let boundary = t.boundary_vertices();
        for v in 0..t.n_vertices() {
            if !boundary[v] {
                assert!(kl[v].abs() < 1e-12, "vertex {v}: {}", kl[v]);
            }
        }
        // Dirichlet energy of a linear function: xᵀKx = |∇x|² × area = 13
        let energy: f64 = lin.iter().zip(&kl).map(|(a, b)| a * b).sum();
        assert!((energy - 13.0).abs() < 1e-11, "energy {energy}");
    }
}
