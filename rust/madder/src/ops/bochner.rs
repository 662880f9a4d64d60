//! The connection (Bochner) Laplacian and implicit diffusion of a tangent vector field
//! (seed §4.3.3, eq. 4.6).
//!
//! A tangent field is one 2-D vector `u_i` per vertex, in the vertex frame `F_i`
//! ([`crate::mesh::frames`]); `R_ij` carries a vector of `F_j` into `F_i` (eq. 4.4). The
//! seed diffuses the velocity by
//!
//! ```text
//! A_i (u_i' − u_i) = h Σ_{j∈N(i)} L_ij (R_ij u_j' − u_i'),                      (4.6)
//! ```
//!
//! with `L_ij ≥ 0` the edge weights of `L_S` (cotan weights `½(cot α + cot β)` for
//! `S = I`, or the anisotropic weights of the viscosity tensor `S_v`). Our scalar
//! stiffness `K` ([`crate::ops::cotan_stiffness`], [`crate::ops::anisotropic_stiffness`])
//! is the positive semi-definite one: `K_ij = −L_ij` off the diagonal and
//! `K_ii = Σ_j L_ij` (every row sums to zero, face by face). Then the right-hand side of
//! (4.6) is `−h (K_∇ u')_i` with the `2N×2N` block matrix
//!
//! ```text
//! (K_∇)_ii = K_ii I₂,     (K_∇)_ij = K_ij R_ij   (i ~ j),
//! ```
//!
//! which is the seed's "replace `L_ij` by `L_ij R_ij`, `R_ii = I`" with our sign, and
//! (4.6) becomes the linear system
//!
//! ```text
//! (M ⊗ I₂ + h K_∇) u' = (M ⊗ I₂) u,            M = diag(A_i) (lumped mass).
//! ```
//!
//! **Symmetry.** The transpose of block `(i, j)` is `K_ij R_ijᵀ`; block `(j, i)` is
//! `K_ji R_ji`. They agree iff `R_ji = R_ijᵀ`, which [`Transport`] guarantees exactly
//! (one angle per edge, the reverse rotation is the transpose), so `K_∇` is symmetric
//! and only its lower triangle is stored.
//!
//! **Definiteness.** Expanding the squares,
//! `uᵀ K_∇ u = Σ_{edges ij} L_ij |u_i − R_ij u_j|²`, so `K_∇` is positive semi-definite
//! whenever every edge weight is `≥ 0` (an intrinsic-Delaunay mesh for the cotan weights)
//! and `M ⊗ I₂ + h K_∇` is then SPD for every `h ≥ 0`. With negative weights (obtuse,
//! non-Delaunay triangles) the scalar FEM matrix stays semi-definite but `K_∇` need not:
//! a face with non-zero holonomy and a negative weight contributes negative energy to
//! nearly parallel fields. On cloth meshes this is rare and `M` dominates for moderate
//! `h`; if it happens the factorization reports [`SolveError::NotPositiveDefinite`] with
//! the failing pivot rather than returning garbage. (Clamping weights would make the
//! operator inconsistent with the scalar diffusion, so we do not.) On a flat mesh
//! `R_ij = Q_iᵀ Q_j` for the in-plane frame rotations `Q_i`, so `K_∇` is `K ⊗ I₂` in a
//! global basis: the vector diffusion is two scalar diffusions, which the tests check.
//!
//! ## Pattern
//! [`BochnerPattern`] expands the scalar [`VertexPattern`] (column `j`: its diagonal,
//! then the rows `b > j` of its edges) block by block: scalar column `j` becomes columns
//! `2j` and `2j+1`, each holding its diagonal then rows `2b, 2b+1` for every edge
//! `(j, b)`. The diagonal block `K_jj I₂` has a zero off-diagonal, so its lower entry
//! `(2j+1, 2j)` is not stored (no fill comes of it: nothing else couples `2j` to `2j+1`
//! before elimination). The pattern is fixed for a bake; [`BochnerSystem`] factorizes it
//! symbolically once with [`PrefactoredSpd`] and only refactorizes numerically per step.
//! A vertex with no face has a zero row; like the scalar stepper, we put `1` on its
//! diagonal and its own velocity on the right-hand side, so it keeps it.

use faer::Par;
use glam::DVec2;

use super::restrict::{block_pattern, block_values, entry_edges};
use super::solve::LowerCsc;
use super::{PrefactoredSpd, VertexPattern};
use crate::error::{Error, ParamError, SolveError};
use crate::mesh::{Geometry, Topology, Transport};

/// Lower triangle of the `2N×2N` block matrix of a connection Laplacian, CSC.
#[derive(Debug, Clone)]
pub struct BochnerPattern {
    n_vertices: usize,
    col_ptr: Vec<u32>,
    row_idx: Vec<u32>,
    diag_slot: Vec<[u32; 2]>,
    edge_slot: Vec<[u32; 4]>,
    /// The edge of every off-diagonal entry of the scalar pattern.
    entry_edge: Vec<u32>,
}

impl BochnerPattern {
    /// The block expansion of the scalar `pattern` (see the module doc;
    /// [`super::restrict::block_pattern`]).
    pub fn new(scalar: &VertexPattern) -> Self {
        let n = scalar.n();
        let sp = scalar.col_ptr();
        let block = block_pattern(scalar);
        let col_ptr = block.col_ptr().to_vec();
        let diag_slot = (0..n)
            .map(|j| [col_ptr[2 * j], col_ptr[2 * j + 1]])
            .collect();
        // scalar slot → its block column and rank among the column's off-diagonals
        let mut slot_col = vec![0u32; scalar.nnz()];
        for j in 0..n {
            for s in sp[j]..sp[j + 1] {
                slot_col[s as usize] = j as u32;
            }
        }
        let edge_slot = scalar
            .edge_slot()
            .iter()
            .map(|&s| {
                let a = slot_col[s as usize] as usize;
                let r = s - sp[a] - 1;
                let (c0, c1) = (col_ptr[2 * a], col_ptr[2 * a + 1]);
                [
                    c0 + 1 + 2 * r,
                    c0 + 2 + 2 * r,
                    c1 + 1 + 2 * r,
                    c1 + 2 + 2 * r,
                ]
            })
            .collect();
        Self {
            n_vertices: n,
            col_ptr,
            row_idx: block.row_idx().to_vec(),
            diag_slot,
            edge_slot,
            entry_edge: entry_edges(scalar),
        }
    }

    /// Vertices of the scalar pattern (the matrix is `2N×2N`).
    pub fn n_vertices(&self) -> usize {
        self.n_vertices
    }

    /// Slots of the two diagonal entries `(2v, 2v)`, `(2v+1, 2v+1)` of every vertex.
    pub fn diag_slot(&self) -> &[[u32; 2]] {
        &self.diag_slot
    }

    /// Slots of the block `(b, a)` of every edge `(a, b)`, `a < b` (indexed like
    /// [`Topology::edges`]): entries `(2b, 2a)`, `(2b+1, 2a)`, `(2b, 2a+1)`,
    /// `(2b+1, 2a+1)`, i.e. the block in column-major order.
    pub fn edge_slot(&self) -> &[[u32; 4]] {
        &self.edge_slot
    }

    /// `y = A x` for the symmetric matrix whose lower triangle is `values`.
    pub fn sym_matvec(&self, values: &[f64], x: &[f64]) -> Vec<f64> {
        assert_eq!(values.len(), self.row_idx.len());
        assert_eq!(x.len(), 2 * self.n_vertices);
        let mut y = vec![0.0; x.len()];
        for j in 0..x.len() {
            let (lo, hi) = (self.col_ptr[j] as usize, self.col_ptr[j + 1] as usize);
            y[j] += values[lo] * x[j];
            for (&i, &v) in self.row_idx[lo + 1..hi].iter().zip(&values[lo + 1..hi]) {
                let i = i as usize;
                y[i] += v * x[j];
                y[j] += v * x[i];
            }
        }
        y
    }
}

impl LowerCsc for BochnerPattern {
    fn n(&self) -> usize {
        2 * self.n_vertices
    }
    fn col_ptr(&self) -> &[u32] {
        &self.col_ptr
    }
    fn row_idx(&self) -> &[u32] {
        &self.row_idx
    }
}

/// Values of `K_∇` on `pattern` from the scalar stiffness `stiffness` (values on `scalar`,
/// e.g. [`crate::ops::cotan_stiffness`]) and the transport `R_ij`.
pub fn bochner_stiffness(
    scalar: &VertexPattern,
    pattern: &BochnerPattern,
    stiffness: &[f64],
    transport: &Transport,
) -> Vec<f64> {
    assert_eq!(
        stiffness.len(),
        scalar.nnz(),
        "stiffness is not on the pattern"
    );
    assert_eq!(
        transport.edge_angles().len(),
        scalar.edge_slot().len(),
        "transport of another topology"
    );
    assert_eq!(
        pattern.n_vertices,
        scalar.n(),
        "block pattern of another pattern"
    );
    block_values(
        scalar,
        stiffness,
        &pattern.entry_edge,
        transport.edge_cos_sin(),
    )
}

/// Adds `scale × (M ⊗ I₂)` (lumped mass) to the diagonal of `values`.
pub fn add_lumped_mass_blocks(
    geometry: &Geometry,
    pattern: &BochnerPattern,
    scale: f64,
    values: &mut [f64],
) {
    for (d, &a) in pattern.diag_slot().iter().zip(&geometry.vertex_area) {
        values[d[0] as usize] += scale * a;
        values[d[1] as usize] += scale * a;
    }
}

/// Implicit diffusion of tangent vector fields (eq. 4.6) with a fixed pattern and a
/// symbolic factorization reused across steps.
#[derive(Debug)]
pub struct BochnerSystem {
    scalar: VertexPattern,
    solver: PrefactoredSpd<BochnerPattern>,
    loose: Vec<bool>,
}

impl BochnerSystem {
    /// Pattern and symbolic analysis for `topology`.
    pub fn new(topology: &Topology, par: Par) -> Result<Self, SolveError> {
        let scalar = VertexPattern::new(topology);
        let solver = PrefactoredSpd::new(BochnerPattern::new(&scalar), par)?;
        Ok(Self {
            scalar,
            solver,
            loose: topology.loose_vertices(),
        })
    }

    /// The scalar pattern the stiffness values must be on.
    pub fn scalar_pattern(&self) -> &VertexPattern {
        &self.scalar
    }

    /// The block pattern of the system.
    pub fn pattern(&self) -> &BochnerPattern {
        self.solver.pattern()
    }

    /// One backward-Euler step of eq. 4.6 over `h`: solves
    /// `(M ⊗ I₂ + h K_∇) u' = (M ⊗ I₂) u` in place of `velocity` (per vertex, in the
    /// frames of `transport`), with `M` the lumped mass of `geometry` and `K_∇` built
    /// from the scalar `stiffness` (values on [`Self::scalar_pattern`], with the viscosity
    /// inside) and `transport`. On error `velocity` is unchanged.
    pub fn diffuse(
        &mut self,
        geometry: &Geometry,
        stiffness: &[f64],
        transport: &Transport,
        h: f64,
        velocity: &mut [DVec2],
    ) -> Result<(), Error> {
        let n = self.scalar.n();
        if !(h.is_finite() && h >= 0.0) {
            return Err(ParamError::OutOfRange {
                name: "time step",
                requirement: "finite and ≥ 0",
                value: h,
            }
            .into());
        }
        for (name, expected, got) in [
            ("velocity", n, velocity.len()),
            ("stiffness", self.scalar.nnz(), stiffness.len()),
            ("vertex areas", n, geometry.vertex_area.len()),
            (
                "connection angles",
                self.scalar.edge_slot().len(),
                transport.edge_angles().len(),
            ),
        ] {
            if expected != got {
                return Err(ParamError::Length {
                    name,
                    expected,
                    got,
                }
                .into());
            }
        }
        if let Some(index) = velocity.iter().position(|u| !u.is_finite()) {
            return Err(ParamError::NonFinite {
                name: "velocity",
                index,
            }
            .into());
        }
        let pattern = self.solver.pattern();
        let mut values: Vec<f64> = bochner_stiffness(&self.scalar, pattern, stiffness, transport)
            .into_iter()
            .map(|v| h * v)
            .collect();
        add_lumped_mass_blocks(geometry, pattern, 1.0, &mut values);
        let mut rhs = Vec::with_capacity(2 * n);
        for (u, &a) in velocity.iter().zip(&geometry.vertex_area) {
            rhs.extend([a * u.x, a * u.y]);
        }
        for (v, _) in self.loose.iter().enumerate().filter(|(_, l)| **l) {
            let d = pattern.diag_slot()[v];
            values[d[0] as usize] = 1.0;
            values[d[1] as usize] = 1.0;
            rhs[2 * v] = velocity[v].x;
            rhs[2 * v + 1] = velocity[v].y;
        }
        self.solver.factorize(&values)?;
        self.solver.solve_in_place(&mut rhs);
        for (v, u) in velocity.iter_mut().enumerate() {
            *u = DVec2::new(rhs[2 * v], rhs[2 * v + 1]);
        }
        Ok(())
    }
}

/// One-shot form of [`BochnerSystem::diffuse`].
pub fn diffuse_tangent_field(
    topology: &Topology,
    geometry: &Geometry,
    stiffness: &[f64],
    transport: &Transport,
    h: f64,
    velocity: &[DVec2],
) -> Result<Vec<DVec2>, Error> {
    let mut system = BochnerSystem::new(topology, Par::Seq)?;
    let mut u = velocity.to_vec();
    system.diffuse(geometry, stiffness, transport, h, &mut u)?;
    Ok(u)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn block_slots_point_at_their_rows_and_columns() {
        let t = Topology::from_triangles(5, vec![[0, 1, 2], [0, 2, 3], [3, 2, 4]]).unwrap();
        let sp = VertexPattern::new(&t);
        let p = BochnerPattern::new(&sp);
        assert_eq!(p.nnz(), 2 * t.n_vertices() + 4 * t.n_edges());
        let col_of = |s: u32| (0..p.n()).find(|&c| p.col_ptr()[c + 1] > s).unwrap() as u32;
        for (v, d) in p.diag_slot().iter().enumerate() {
            for (c, &s) in d.iter().enumerate() {
                let dof = (2 * v + c) as u32;
                assert_eq!((p.row_idx()[s as usize], col_of(s)), (dof, dof));
            }
        }
        for (e, &[a, b]) in t.edges().iter().enumerate() {
            let want = [
                (2 * b, 2 * a),
                (2 * b + 1, 2 * a),
                (2 * b, 2 * a + 1),
                (2 * b + 1, 2 * a + 1),
            ];
            for (k, &s) in p.edge_slot()[e].iter().enumerate() {
                assert_eq!((p.row_idx()[s as usize], col_of(s)), want[k]);
            }
        }
        // rows sorted and unique in every column (faer requires it)
        for c in 0..p.n() {
            let rows = &p.row_idx()[p.col_ptr()[c] as usize..p.col_ptr()[c + 1] as usize];
            assert!(rows.windows(2).all(|w| w[0] < w[1]));
            assert_eq!(rows[0] as usize, c);
        }
    }
}
