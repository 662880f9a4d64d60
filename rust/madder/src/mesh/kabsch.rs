//! Best rotation of a vertex's one-ring (seed §4.4): the corotating part of the cloth's
//! motion at every vertex, by the Kabsch procedure.
//!
//! The comoving–corotating frame of vertex `i` is `F_i = U_i F̄_i`, with `F̄_i` its rest
//! frame and
//!
//! ```text
//! U_i = argmin_{R ∈ SO(3)} Σ_{j ∈ N(i)} |(v_j − v_i) − R (v̄_j − v̄_i)|²,
//! ```
//!
//! `v̄` the rest and `v` the current positions. With `p_j = v̄_j − v̄_i`, `q_j = v_j − v_i`
//! and the cross-covariance `H = Σ_j q_j p_jᵀ`, the objective is
//! `const − 2 tr(Rᵀ H)`; with the SVD `H = U Σ Vᵀ` (singular values descending) the
//! maximiser of `tr(Rᵀ H)` over rotations is (Kabsch 1976; Umeyama 1991)
//!
//! ```text
//! U_i = U diag(1, 1, d) Vᵀ,     d = det(U) det(V) = ±1,
//! ```
//!
//! the sign `d` turning the closest orthogonal matrix into the closest *proper* rotation
//! when `H` would be best matched by a reflection. Writing `det(U) u₃ = u₁ × u₂`, this is
//! `u₁ v₁ᵀ + u₂ v₂ᵀ + det(V) (u₁ × u₂) v₃ᵀ`, which never uses `u₃`: a planar one-ring
//! (`σ₃ = 0`, the common case on cloth, where `u₃` is undetermined) gets the rotation that
//! maps the rest plane onto the current one with its orientation.
//!
//! ## The 3×3 SVD
//! glam has no SVD. We use one-sided Jacobi (Hestenes): plane rotations applied to the
//! columns of `H` (and accumulated in `V`) until every pair of columns is orthogonal to
//! working precision; then the column norms are the singular values and the normalised
//! columns the left vectors. It is allocation-free (faer's dense SVD would allocate per
//! vertex), deterministic, converges in a handful of sweeps for 3×3, and is accurate even
//! for rank-deficient `H` because it never forms `HᵀH` (whose eigen-decomposition would
//! square the condition number and lose `u₂` of a thin one-ring). It is tested against
//! faer's SVD.
//!
//! Degenerate one-rings: if `H = 0` (a loose vertex, or a one-ring collapsed to a point)
//! `U_i = I`. If `σ₂ ≤ 10⁻¹⁴ σ₁` (all spokes collinear), every rotation about the line is
//! optimal; we take `u₂` as a fixed unit vector perpendicular to `u₁` (glam's
//! `any_orthonormal_vector`), so the result is still a proper rotation mapping the line
//! onto its image.
//!
//! [`one_ring_rotations`] runs every vertex independently in parallel with a fixed
//! summation order: the result is bit-identical whatever the number of threads.
//!
//! ## Congruent one-rings (issue 12's Detail)
//! On a refined cloth ([`super::refine`]) a fine vertex inside a coarse face, or on a
//! coarse edge, has a one-ring made of the same lattice offsets as every other fine
//! vertex of that face (edge), `p_j = B δ_j` with `B` the face's rest map and `δ_j` the
//! same lattice steps, and the fine vertices are placed affinely on the coarse faces
//! (`q_j = A_f p_j` on the ring's part in face `f`, `A_f` the coarse face's current
//! map). So `H = Σ_f A_f Σ_{j ∈ f} p_j p_jᵀ` is the same matrix for all of them, and so is
//! `U_i`: [`RingAdjacency::shared_rotations`] computes it once, at the first such
//! vertex of a face or edge, and gives it to the others. It equals their own Kabsch
//! rotation up to the rounding of their positions (each placed by its own barycentric
//! sum), not bit for bit; ARCHITECTURE.md (Stain detail) gives the measured effect on
//! the stain.

use glam::{DMat3, DVec3};
use rayon::prelude::*;

use super::Topology;
use super::geometry::check_positions;
use super::rings::RingAdjacency;
use crate::error::MeshError;

/// Relative size below which the second singular value is treated as zero.
const RANK_TOL: f64 = 1e-14;
/// Upper bound on Jacobi sweeps (3×3 matrices converge in ≤ 6 in practice).
const MAX_SWEEPS: usize = 64;

/// Singular value decomposition `m = u diag(sigma) vᵀ` of a 3×3 matrix, singular values
/// in descending order; `u` and `v` orthogonal (determinant ±1).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Svd3 {
    /// Left singular vectors (columns).
    pub u: DMat3,
    /// Singular values, descending.
    pub sigma: DVec3,
    /// Right singular vectors (columns).
    pub v: DMat3,
}

/// One-sided Jacobi SVD of `m` (see the module doc). Columns of `u` belonging to zero
/// singular values are completed to an orthonormal basis.
pub fn svd3(m: DMat3) -> Svd3 {
    let mut a = [m.x_axis, m.y_axis, m.z_axis];
    let mut v = [DVec3::X, DVec3::Y, DVec3::Z];
    for _ in 0..MAX_SWEEPS {
        let mut rotated = false;
        for (p, q) in [(0, 1), (0, 2), (1, 2)] {
            let alpha = a[p].length_squared();
            let beta = a[q].length_squared();
            let gamma = a[p].dot(a[q]);
            if gamma == 0.0 || gamma.abs() <= f64::EPSILON * (alpha * beta).sqrt() {
                continue;
            }
            rotated = true;
            // rotation making columns p, q orthogonal (smaller root: |t| ≤ 1)
            let zeta = (beta - alpha) / (2.0 * gamma);
            let t = zeta.signum() / (zeta.abs() + zeta.hypot(1.0));
            let c = 1.0 / t.hypot(1.0);
            let s = c * t;
            let (ap, aq) = (a[p], a[q]);
            a[p] = c * ap - s * aq;
            a[q] = s * ap + c * aq;
            let (vp, vq) = (v[p], v[q]);
            v[p] = c * vp - s * vq;
            v[q] = s * vp + c * vq;
        }
        if !rotated {
            break;
        }
    }
    let norm = a.map(|c| c.length());
    let mut order = [0usize, 1, 2];
    order.sort_by(|&i, &j| norm[j].total_cmp(&norm[i]));
    let sigma = DVec3::new(norm[order[0]], norm[order[1]], norm[order[2]]);
    let vs = DMat3::from_cols(v[order[0]], v[order[1]], v[order[2]]);
    let u1 = if sigma.x > 0.0 {
        a[order[0]] / sigma.x
    } else {
        DVec3::X
    };
    let u2 = if sigma.y > RANK_TOL * sigma.x {
        let w = a[order[1]] / sigma.y;
        (w - w.dot(u1) * u1).normalize_or_zero()
    } else {
        DVec3::ZERO
    };
    let u2 = if u2 == DVec3::ZERO {
        u1.any_orthonormal_vector()
    } else {
        u2
    };
    let u3 = if sigma.z > RANK_TOL * sigma.x {
        let w = a[order[2]] / sigma.z;
        // keep the sign of the computed vector (det u = ±1), but make it exactly orthogonal
        let c = u1.cross(u2);
        if w.dot(c) >= 0.0 { c } else { -c }
    } else {
        u1.cross(u2)
    };
    Svd3 {
        u: DMat3::from_cols(u1, u2, u3),
        sigma,
        v: vs,
    }
}

/// The proper rotation `R` maximising `tr(Rᵀ h)`, i.e. minimising `Σ |q_j − R p_j|²` for
/// the cross-covariance `h = Σ q_j p_jᵀ` (Kabsch with the reflection correction).
pub fn rotation_from_covariance(h: DMat3) -> DMat3 {
    let Svd3 { u, sigma, v } = svd3(h);
    if sigma.x <= 0.0 || !sigma.x.is_finite() {
        return DMat3::IDENTITY;
    }
    let (u1, u2) = (u.x_axis, u.y_axis);
    let d = v.determinant().signum();
    outer(u1, v.x_axis) + outer(u2, v.y_axis) + outer(d * u1.cross(u2), v.z_axis)
}

/// Best rotation taking the vectors `rest[k]` to `current[k]` (no centring: the seed's
/// one-ring vectors are already relative to the vertex).
pub fn best_rotation(rest: &[DVec3], current: &[DVec3]) -> DMat3 {
    assert_eq!(rest.len(), current.len());
    let h = rest
        .iter()
        .zip(current)
        .fold(DMat3::ZERO, |h, (p, q)| h + outer(*q, *p));
    rotation_from_covariance(h)
}

/// `a bᵀ`.
fn outer(a: DVec3, b: DVec3) -> DMat3 {
    DMat3::from_cols(a * b.x, a * b.y, a * b.z)
}

/// The one-ring rotations over a topology's fixed adjacency ([`RingAdjacency`], built once
/// per mesh): the per-frame part.
impl RingAdjacency {
    /// `U_i` of vertex `i` (see [`one_ring_rotations`]); positions are not checked.
    pub(crate) fn rotation(&self, rest: &[DVec3], current: &[DVec3], i: usize) -> DMat3 {
        let h = self.neighbours(i).iter().fold(DMat3::ZERO, |h, &j| {
            let j = j as usize;
            h + outer(current[j] - current[i], rest[j] - rest[i])
        });
        rotation_from_covariance(h)
    }

    /// `U_i` of every vertex, as [`one_ring_rotations`] but without re-checking the
    /// positions (the caller has). Parallel over vertices, deterministic.
    ///
    /// # Panics
    /// If `rest` or `current` does not have one position per vertex.
    pub(crate) fn rotations(&self, rest: &[DVec3], current: &[DVec3]) -> Vec<DMat3> {
        let n = self.n_vertices();
        assert!(
            rest.len() == n && current.len() == n,
            "one position per vertex"
        );
        (0..n)
            .into_par_iter()
            .map(|i| self.rotation(rest, current, i))
            .collect()
    }

    /// `U_i` of every vertex as [`Self::rotations`], except that vertex `i` with
    /// `share[i] = r ≠ i` takes `U_r` (a vertex whose one-ring is congruent to `r`'s and
    /// moves with the same affine maps, module doc); `share[r] = r` for every such `r`.
    /// Parallel over vertices, deterministic. Into `rotation` (its allocation kept: the
    /// simulator fills one array every sub-step).
    pub(crate) fn shared_rotations(
        &self,
        rest: &[DVec3],
        current: &[DVec3],
        share: &[u32],
        rotation: &mut Vec<DMat3>,
    ) {
        let n = self.n_vertices();
        assert!(
            rest.len() == n && current.len() == n && share.len() == n,
            "one position and one share per vertex"
        );
        (0..n)
            .into_par_iter()
            .map(|i| {
                if share[i] as usize == i {
                    self.rotation(rest, current, i)
                } else {
                    DMat3::ZERO
                }
            })
            .collect_into_vec(rotation);
        for i in 0..n {
            let r = share[i] as usize;
            if r != i {
                debug_assert_eq!(share[r] as usize, r, "a shared rotation is its own");
                rotation[i] = rotation[r];
            }
        }
    }
}

/// `U_i` of every vertex: the rotation that best aligns its rest one-ring
/// `(v̄_j − v̄_i)` to its current one-ring `(v_j − v_i)` (identity for loose vertices).
/// Parallel over vertices, deterministic. Fails if either position array has the wrong
/// length or a non-finite entry. (A bake keeps a [`RingAdjacency`] instead of rebuilding
/// it every frame.)
pub fn one_ring_rotations(
    topology: &Topology,
    rest: &[DVec3],
    current: &[DVec3],
) -> Result<Vec<DMat3>, MeshError> {
    check_positions(topology, rest)?;
    check_positions(topology, current)?;
    Ok(RingAdjacency::new(topology).rotations(rest, current))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: DMat3, b: DMat3, tol: f64) -> bool {
        (a - b).to_cols_array().iter().all(|x| x.abs() <= tol)
    }

    #[test]
    fn svd_reconstructs_and_is_orthogonal() {
        let m = DMat3::from_cols_array(&[0.3, -1.2, 0.7, 2.0, 0.1, -0.4, 0.5, 0.9, 1.1]);
        let s = svd3(m);
        let rec = s.u * DMat3::from_diagonal(s.sigma) * s.v.transpose();
        assert!(close(rec, m, 1e-14));
        assert!(close(s.u.transpose() * s.u, DMat3::IDENTITY, 1e-14));
        assert!(close(s.v.transpose() * s.v, DMat3::IDENTITY, 1e-14));
        assert!(s.sigma.x >= s.sigma.y && s.sigma.y >= s.sigma.z && s.sigma.z >= 0.0);
    }

    #[test]
    fn zero_and_rank_one_covariances_give_proper_rotations() {
        assert_eq!(rotation_from_covariance(DMat3::ZERO), DMat3::IDENTITY);
        // all spokes along x at rest, along y now
        let r = best_rotation(&[DVec3::X, -2.0 * DVec3::X], &[DVec3::Y, -2.0 * DVec3::Y]);
        assert!((r.determinant() - 1.0).abs() < 1e-14);
        assert!(close(r.transpose() * r, DMat3::IDENTITY, 1e-14));
        assert!((r * DVec3::X - DVec3::Y).length() < 1e-14);
    }
}
