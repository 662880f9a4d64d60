//! The spectral reconstruction (§3.3.1–§3.3.2, Algorithm 1): the scalar quadratic form
//! `A₁` (eq. 3.3 substituted into eq. 3.2), its lowest eigenvectors by shift-invert subspace iteration, the
//! affine correction by voting, and the optional descent (§3.3.3). The math is in the
//! module docs of [`crate::angles`].

use glam::{DMat3, DVec3};
use rayon::prelude::*;

use super::cache::Pattern;
use super::encode::{AngleMesh, Angles};
use super::local::{frame, preprocess, transitions};
use super::place::Placement;
use super::refine::{descend, embed, residual};
use crate::error::{AngleError, SolveError};
use crate::mesh::kabsch::svd3;
use crate::ops::restrict::entry_index;
use crate::ops::{CscPattern, PrefactoredSpd};
use crate::rng::SplitMix64;

/// The shift `σ` relative to the mean diagonal of `A₁` (see the module docs).
const SHIFT_REL: f64 = 1e-12;
/// Wanted eigenvectors (after deflating the translation) and the guard vectors.
const WANTED: usize = 3;
const BLOCK: usize = 7;
/// The warm start's block: 3 wanted + 1 guard (module docs, "Warm start").
const WARM_BLOCK: usize = 4;
/// Subspace iteration: converged below this change of the wanted subspace...
const TOL: f64 = 1e-10;
/// ... or when the change stops shrinking below this one (the rounding floor).
const FLOOR: f64 = 1e-8;
const MAX_ROUNDS: usize = 200;

/// Options of [`AngleMesh::reconstruct`].
#[derive(Debug, Clone, Default)]
pub struct ReconstructOptions {
    /// Gradient-descent steps in the 12-D space after the voting (§3.3.3); 0 for none.
    pub refine_iterations: usize,
    /// Where to put the result; `None`: centroid at the origin, mean edge length 1.
    pub placement: Option<Placement>,
    /// The tracked reconstruction only: the rotation error (radians) its rounds may leave
    /// when the angles carry a larger one anyway (the codec: a twentieth of the
    /// quantization step). 0, the default: the rounds settle fully. See
    /// [`AngleMesh::reconstruct_tracked`](super::AngleMesh::reconstruct_tracked).
    pub tolerance: f64,
}

/// The result of a reconstruction.
#[derive(Debug, Clone)]
pub struct Reconstruction {
    /// Vertex positions.
    pub positions: Vec<DVec3>,
    /// The angle residual `E` (module docs) after the voting, then after each accepted
    /// descent step: never increasing.
    pub residual: Vec<f64>,
    /// The lowest eigenvalues of `A₁ / mean diagonal` after the translation: the three
    /// used and the next (a clear gap between the third and the fourth means the angles
    /// were nearly consistent).
    pub eigenvalues: [f64; 4],
    /// Subspace-iteration rounds.
    pub rounds: usize,
}

/// One element of the energy: its unknowns and the rows `Σ coef · unknown` it penalizes.
struct Element<const N: usize> {
    idx: [u32; N],
    rows: [[f64; N]; 3],
}

impl<const N: usize> Element<N> {
    /// The local matrix `Σ rows rowᵀ`, visited as `(global row, global col, value)` for the
    /// lower triangle.
    fn for_each(&self, mut f: impl FnMut(u32, u32, f64)) {
        for i in 0..N {
            for j in 0..N {
                let (r, c) = (self.idx[i], self.idx[j]);
                if r < c {
                    continue;
                }
                let v: f64 = self.rows.iter().map(|row| row[i] * row[j]).sum();
                f(r, c, v);
            }
        }
    }
}

/// Eq. 3.2 for an interior edge with eq. 3.3 substituted (module docs): row `c` is
/// `F₁[c] − Σ_d F₂[d] R[d][c] = 0` with `Fₜ = (x_{p₁} − x_{p₀}, x_{p₂} − x_{p₀}, mₜ)`;
/// unknowns `[x_{f₁'s corners}, m₁, x_{f₂'s corners}, m₂]` (the two shared vertices appear
/// twice: [`Element::for_each`] sums such repeats correctly).
fn edge_element(faces: &[[u32; 3]], nv: usize, f1: u32, f2: u32, r: &DMat3) -> Element<8> {
    let [a0, a1, a2] = faces[f1 as usize];
    let [b0, b1, b2] = faces[f2 as usize];
    let (m1, m2) = ((nv + f1 as usize) as u32, (nv + f2 as usize) as u32);
    // column d of a frame as coefficients on [p₀, p₁, p₂, m]
    const COLS: [[f64; 4]; 3] = [
        [-1.0, 1.0, 0.0, 0.0],
        [-1.0, 0.0, 1.0, 0.0],
        [0.0, 0.0, 0.0, 1.0],
    ];
    let mut rows = [[0.0; 8]; 3];
    for (c, row) in rows.iter_mut().enumerate() {
        row[..4].copy_from_slice(&COLS[c]);
        let col = r.col(c);
        for (d, w) in [col.x, col.y, col.z].into_iter().enumerate() {
            for k in 0..4 {
                row[4 + k] -= w * COLS[d][k];
            }
        }
    }
    Element {
        idx: [a0, a1, a2, m1, b0, b1, b2, m2],
        rows,
    }
}

/// The elements of `A₁`, one per interior edge (with transitions `r`; `None`: identity
/// placeholders, for the pattern only).
fn elements(mesh: &AngleMesh, r: Option<&[DMat3]>) -> Vec<Element<8>> {
    let faces = mesh.faces();
    let nv = mesh.n_vertices();
    mesh.interior()
        .iter()
        .enumerate()
        .map(|(i, e)| {
            let r = r.map_or(DMat3::IDENTITY, |r| r[i]);
            edge_element(faces, nv, e.f1, e.f2, &r)
        })
        .collect()
}

/// The pattern of `A₁` (it depends on the connectivity only; every diagonal entry is in it).
fn pattern_of(mesh: &AngleMesh) -> Pattern {
    let nv = mesh.n_vertices();
    let n = nv + mesh.n_faces();
    let ee = elements(mesh, None);
    let mut keys: Vec<u64> = Vec::with_capacity(36 * ee.len() + n);
    let mut push = |r: u32, c: u32, _v: f64| keys.push(((c as u64) << 32) | r as u64);
    for el in &ee {
        el.for_each(&mut push);
    }
    keys.extend((0..n as u64).map(|i| (i << 32) | i));
    let (col_ptr, row_idx) = CscPattern::from_keys(n, keys).into_parts();
    Pattern {
        n,
        col_ptr: col_ptr.into(),
        row_idx: row_idx.into(),
    }
}

/// The values of `A₁` on `pattern` for the transitions `r` (sums in a fixed order).
fn values_of(mesh: &AngleMesh, pattern: &Pattern, r: &[DMat3]) -> Vec<f64> {
    let ee = elements(mesh, Some(r));
    let (col_ptr, row_idx) = (&pattern.col_ptr, &pattern.row_idx);
    let mut values = vec![0.0; row_idx.len()];
    let mut add = |r: u32, c: u32, v: f64| values[entry_index(col_ptr, row_idx, r, c)] += v;
    for el in &ee {
        el.for_each(&mut add);
    }
    values
}

/// `y = A x` for the symmetric matrix whose lower triangle is `values` on `p`.
fn sym_matvec(p: &Pattern, values: &[f64], x: &[f64], y: &mut [f64]) {
    y.fill(0.0);
    for c in 0..p.n {
        let (s, e) = (p.col_ptr[c] as usize, p.col_ptr[c + 1] as usize);
        let mut acc = 0.0;
        for (&r, &v) in p.row_idx[s..e].iter().zip(&values[s..e]) {
            let r = r as usize;
            if r == c {
                acc += v * x[c];
            } else {
                acc += v * x[r];
                y[r] += v * x[c];
            }
        }
        y[c] += acc;
    }
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// Removes from `x` its component along the unit vector that is `1/√nv` on the first `nv`
/// entries (the translation).
fn deflate(x: &mut [f64], nv: usize) {
    let m = x[..nv].iter().sum::<f64>() / nv as f64;
    x[..nv].iter_mut().for_each(|v| *v -= m);
}

/// Modified Gram–Schmidt, twice, on the `k` columns of `x` (column-major, length `n`).
fn orthonormalize(x: &mut [f64], n: usize, k: usize) {
    for _ in 0..2 {
        for j in 0..k {
            for i in 0..j {
                let (a, b) = x.split_at_mut(j * n);
                let qi = &a[i * n..(i + 1) * n];
                let xj = &mut b[..n];
                let d = dot(qi, xj);
                xj.iter_mut().zip(qi).for_each(|(v, q)| *v -= d * q);
            }
            let xj = &mut x[j * n..(j + 1) * n];
            let nrm = dot(xj, xj).sqrt();
            if nrm > 0.0 {
                xj.iter_mut().for_each(|v| *v /= nrm);
            }
        }
    }
}

/// Eigen-decomposition of a small symmetric matrix (row-major `k×k`) by cyclic Jacobi:
/// eigenvalues ascending and the eigenvectors as columns (row-major `k×k`).
fn jacobi(mut a: Vec<f64>, k: usize) -> (Vec<f64>, Vec<f64>) {
    let mut v = vec![0.0; k * k];
    for i in 0..k {
        v[i * k + i] = 1.0;
    }
    for _sweep in 0..100 {
        let off: f64 = (0..k)
            .flat_map(|i| (0..k).filter(move |&j| j != i).map(move |j| (i, j)))
            .map(|(i, j)| a[i * k + j] * a[i * k + j])
            .sum();
        let diag: f64 = (0..k).map(|i| a[i * k + i] * a[i * k + i]).sum();
        if off <= 1e-32 * diag || off == 0.0 {
            break;
        }
        for p in 0..k {
            for q in p + 1..k {
                let apq = a[p * k + q];
                if apq == 0.0 {
                    continue;
                }
                let tau = (a[q * k + q] - a[p * k + p]) / (2.0 * apq);
                let t = tau.signum() / (tau.abs() + (1.0 + tau * tau).sqrt());
                let t = if tau == 0.0 { 1.0 } else { t };
                let c = 1.0 / (1.0 + t * t).sqrt();
                let s = t * c;
                for r in 0..k {
                    let (arp, arq) = (a[r * k + p], a[r * k + q]);
                    a[r * k + p] = c * arp - s * arq;
                    a[r * k + q] = s * arp + c * arq;
                }
                for r in 0..k {
                    let (apr, aqr) = (a[p * k + r], a[q * k + r]);
                    a[p * k + r] = c * apr - s * aqr;
                    a[q * k + r] = s * apr + c * aqr;
                }
                for r in 0..k {
                    let (vrp, vrq) = (v[r * k + p], v[r * k + q]);
                    v[r * k + p] = c * vrp - s * vrq;
                    v[r * k + q] = s * vrp + c * vrq;
                }
            }
        }
    }
    let mut order: Vec<usize> = (0..k).collect();
    order.sort_by(|&i, &j| a[i * k + i].total_cmp(&a[j * k + j]));
    let vals = order.iter().map(|&i| a[i * k + i]).collect();
    let mut vecs = vec![0.0; k * k];
    for (new, &old) in order.iter().enumerate() {
        for r in 0..k {
            vecs[r * k + new] = v[r * k + old];
        }
    }
    (vals, vecs)
}

/// The 3 lowest eigenvectors of `A₁` orthogonal to the translation (column-major, `n` each),
/// the 4 lowest Ritz values (relative to the mean diagonal) and the rounds taken.
fn lowest(
    solver: &mut PrefactoredSpd<Pattern>,
    values: &[f64],
    nv: usize,
    start: Option<&[f64]>,
) -> Result<(Vec<f64>, [f64; 4], usize), SolveError> {
    // a cheap copy (shared arrays), so the solver stays free to borrow mutably
    let pattern = &solver.pattern().clone();
    let n = pattern.n;
    // cold: 3 wanted + 4 guards; warm: the start is already close, 1 guard suffices
    let block = if start.is_some() { WARM_BLOCK } else { BLOCK };
    let diag_mean = (0..n)
        .map(|c| values[pattern.col_ptr[c] as usize])
        .sum::<f64>()
        / n as f64;
    let mut shift = SHIFT_REL * diag_mean;
    // A₁ is positive semi-definite: the shift makes it definite in exact arithmetic; if
    // rounding still meets a non-positive pivot, retry with a larger shift.
    let mut shifted = values.to_vec();
    loop {
        shifted.copy_from_slice(values);
        for c in 0..n {
            shifted[pattern.col_ptr[c] as usize] += shift;
        }
        match solver.factorize(&shifted) {
            Ok(()) => break,
            Err(SolveError::NotPositiveDefinite { .. }) if shift < 1e-6 * diag_mean => {
                shift *= 100.0;
            }
            Err(e) => return Err(e),
        }
    }
    let mut rng = SplitMix64::new(0x5eed_a461e5);
    let mut x: Vec<f64> = (0..n * block).map(|_| rng.unit() - 0.5).collect();
    if let Some(start) = start {
        // the warm start's columns replace the first random ones (the rest stay guards)
        x[..start.len()].copy_from_slice(start);
    }
    for j in 0..block {
        deflate(&mut x[j * n..(j + 1) * n], nv);
    }
    orthonormalize(&mut x, n, block);
    let mut ax = vec![0.0; n * block];
    let mut prev_change = f64::INFINITY;
    let mut ritz = vec![0.0; block];
    let mut rounds = 0;
    loop {
        rounds += 1;
        let mut y = x.clone();
        solver.solve_in_place(&mut y);
        for j in 0..block {
            deflate(&mut y[j * n..(j + 1) * n], nv);
        }
        orthonormalize(&mut y, n, block);
        y.par_chunks(n)
            .zip(ax.par_chunks_mut(n))
            .for_each(|(yj, axj)| sym_matvec(pattern, values, yj, axj));
        let mut h = vec![0.0; block * block];
        for i in 0..block {
            for j in i..block {
                let v = dot(&y[i * n..(i + 1) * n], &ax[j * n..(j + 1) * n]);
                h[i * block + j] = v;
                h[j * block + i] = v;
            }
        }
        let (vals, vecs) = jacobi(h, block);
        ritz.copy_from_slice(&vals);
        let mut xn = vec![0.0; n * block];
        xn.par_chunks_mut(n).enumerate().for_each(|(j, col)| {
            for i in 0..block {
                let w = vecs[i * block + j];
                col.iter_mut()
                    .zip(&y[i * n..(i + 1) * n])
                    .for_each(|(c, yi)| *c += w * yi);
            }
        });
        // change of the wanted subspace: ‖Xn − X (Xᵀ Xn)‖_F over the wanted columns
        let mut change2 = 0.0;
        for j in 0..WANTED {
            let xj = &xn[j * n..(j + 1) * n];
            let mut r = xj.to_vec();
            for i in 0..WANTED {
                let xi = &x[i * n..(i + 1) * n];
                let d = dot(xi, xj);
                r.iter_mut().zip(xi).for_each(|(v, q)| *v -= d * q);
            }
            change2 += dot(&r, &r);
        }
        let change = change2.sqrt();
        x = xn;
        if change < TOL || (rounds > 2 && change < FLOOR && change > 0.5 * prev_change) {
            break;
        }
        if rounds >= MAX_ROUNDS {
            return Err(SolveError::NotConverged {
                iterations: rounds,
                residual: change,
            });
        }
        prev_change = change;
    }
    x.truncate(n * WANTED);
    let eig = std::array::from_fn(|i| ritz[i] / diag_mean);
    Ok((x, eig, rounds))
}

impl AngleMesh {
    /// Reconstructs vertex positions from angles by the spectral method (seed §3.3,
    /// Algorithm 1): preprocessing, transitions, the quadratic form, its lowest
    /// eigenvectors, the affine correction by voting, the optional descent, then the
    /// placement.
    ///
    /// Errors: angle counts that do not match, a non-finite angle (naming the face corner or
    /// the edge), a mesh whose faces are not all connected across interior edges (naming a
    /// face), a bad placement, a failed eigen-solve.
    pub fn reconstruct(
        &self,
        angles: &Angles,
        options: &ReconstructOptions,
    ) -> Result<Reconstruction, AngleError> {
        self.spectral(angles, options, None)
    }

    /// Reconstructs one frame of a sequence warm-started from the previous frame's
    /// positions `previous` (module docs, "Warm start"): the same spectral method as
    /// [`Self::reconstruct`] and the same stopping rule, but the subspace iteration starts
    /// from `previous` (its coordinates and face frames) instead of random vectors, and
    /// the connectivity-only work (the pattern of `A₁`, its symbolic Cholesky analysis) is
    /// kept in the mesh between calls. `previous` may be anywhere (any similarity of the
    /// previous frame: the placement does not matter) and need not be exact; a poor
    /// `previous` costs rounds, not accuracy. The result agrees with the cold
    /// reconstruction of the same angles to the iteration's tolerance (the wanted subspace
    /// converged to `10⁻¹⁰`).
    ///
    /// Errors: those of [`Self::reconstruct`], and `previous` of the wrong length or with a
    /// non-finite position (naming the vertex).
    pub fn reconstruct_warm(
        &self,
        angles: &Angles,
        previous: &[DVec3],
        options: &ReconstructOptions,
    ) -> Result<Reconstruction, AngleError> {
        crate::mesh::geometry::check_positions(self.topology(), previous)?;
        self.spectral(angles, options, Some(previous))
    }

    fn spectral(
        &self,
        angles: &Angles,
        options: &ReconstructOptions,
        previous: Option<&[DVec3]>,
    ) -> Result<Reconstruction, AngleError> {
        self.check_angles(angles)?;
        self.check_connected()?;
        if let Some(p) = &options.placement {
            p.check(self.n_faces())?;
        }
        let target = preprocess(angles);
        let tr = transitions(self, &target);
        let nv = self.n_vertices();
        let cache = self.solver_cache();
        let mut solver = cache.take_or(|| PrefactoredSpd::new(pattern_of(self), faer::Par::Seq))?;
        let values = values_of(self, solver.pattern(), &tr.r);
        let start = previous.map(|x| start_block(self, x));
        let found = lowest(&mut solver, &values, nv, start.as_deref());
        let n = solver.pattern().n;
        cache.put(solver);
        let (q, eigenvalues, rounds) = found?;
        let col = |a: usize, i: usize| q[a * n + i];
        let qv: Vec<DVec3> = (0..nv)
            .map(|v| DVec3::new(col(0, v), col(1, v), col(2, v)))
            .collect();
        // G_t: row a = eigenvector a's entries of the frame of t
        let g: Vec<DMat3> = (0..self.n_faces())
            .map(|f| {
                let [p0, p1, p2] = self.faces()[f].map(|v| v as usize);
                let at = |i: usize| DVec3::new(col(0, i), col(1, i), col(2, i));
                DMat3::from_cols(at(p1) - at(p0), at(p2) - at(p0), at(nv + f))
            })
            .collect();
        // orientation: most frames with a positive determinant
        let positive = g.iter().filter(|m| m.determinant() > 0.0).count();
        let l0 = if 2 * positive >= g.len() {
            DMat3::IDENTITY
        } else {
            -DMat3::IDENTITY
        };
        let t = vote(self, &tr.local, &g, l0);
        let mut l = t * l0;
        let mut history = vec![residual(self, &target, &embed(l, &qv))];
        if options.refine_iterations > 0 {
            let (l1, h) = descend(self, &target, &qv, l, options.refine_iterations);
            l = l1;
            history = h;
        }
        let mut positions = embed(l, &qv);
        match &options.placement {
            Some(p) => p.apply(self.faces(), &mut positions),
            None => normalize(self.edges(), &mut positions),
        }
        Ok(Reconstruction {
            positions,
            residual: history,
            eigenvalues,
            rounds,
        })
    }

    /// The angle residual `E` (module docs) of `positions` against `angles` after the
    /// preprocessing: what the descent lowers.
    pub fn angle_residual(&self, angles: &Angles, positions: &[DVec3]) -> Result<f64, AngleError> {
        self.check_angles(angles)?;
        crate::mesh::geometry::check_positions(self.topology(), positions)?;
        Ok(residual(self, &preprocess(angles), positions))
    }
}

/// The warm start's block: for each coordinate `d`, the vector of `A₁`'s unknowns that the
/// positions `x` give (their `d`-th coordinates, and row `d` of every face's frame).
fn start_block(mesh: &AngleMesh, x: &[DVec3]) -> Vec<f64> {
    let nv = mesh.n_vertices();
    let n = nv + mesh.n_faces();
    let mut out = vec![0.0; n * WANTED];
    for (d, col) in out.chunks_mut(n).enumerate() {
        for (v, p) in x.iter().enumerate() {
            col[v] = p[d];
        }
        for (f, t) in mesh.faces().iter().enumerate() {
            let fr = frame(t.map(|v| x[v as usize]));
            // a degenerate face of the start has no normal: leave its frame at 0 (only
            // the start is poorer for it)
            if !fr.is_finite() {
                continue;
            }
            col[nv + f] = fr.col(2)[d];
        }
    }
    out
}

/// The voting of §3.3.2: `T = S/‖S‖_F`, `S = Σ_e S_e/‖S_e‖_F` with `S_e` the symmetric
/// polar factor of each edge's least-squares map onto its local construction.
fn vote(mesh: &AngleMesh, local: &[(DMat3, DMat3)], g: &[DMat3], l0: DMat3) -> DMat3 {
    let votes: Vec<Option<DMat3>> = mesh
        .interior()
        .par_iter()
        .zip(local.par_iter())
        .map(|(e, (fb1, fb2))| {
            let f1 = l0 * g[e.f1 as usize];
            let f2 = l0 * g[e.f2 as usize];
            let ba = *fb1 * f1.transpose() + *fb2 * f2.transpose();
            let aa = f1 * f1.transpose() + f2 * f2.transpose();
            let det = aa.determinant();
            if !det.is_finite() || det == 0.0 {
                return None;
            }
            let t = ba * aa.inverse();
            let s = svd3(t);
            let norm = s.sigma.length();
            if !norm.is_finite() || norm <= 0.0 {
                return None;
            }
            let v = s.v;
            let d = DMat3::from_diagonal(s.sigma / norm);
            Some(v * d * v.transpose())
        })
        .collect();
    let s = votes.iter().flatten().fold(DMat3::ZERO, |a, b| a + *b);
    let norm = [s.x_axis, s.y_axis, s.z_axis]
        .iter()
        .map(|c| c.length_squared())
        .sum::<f64>()
        .sqrt();
    if norm > 0.0 {
        s * (1.0 / norm)
    } else {
        DMat3::IDENTITY
    }
}

/// Centroid at the origin, mean edge length 1.
pub(crate) fn normalize(edges: &[[u32; 2]], x: &mut [DVec3]) {
    let c = x.iter().copied().sum::<DVec3>() / x.len() as f64;
    let mean = edges
        .iter()
        .map(|&[a, b]| (x[a as usize] - x[b as usize]).length())
        .sum::<f64>()
        / edges.len() as f64;
    let s = if mean > 0.0 { 1.0 / mean } else { 1.0 };
    for p in x.iter_mut() {
        *p = (*p - c) * s;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn jacobi_diagonalizes() {
        let a = vec![4.0, 1.0, 0.5, 1.0, 3.0, 0.2, 0.5, 0.2, 1.0];
        let (vals, vecs) = jacobi(a.clone(), 3);
        assert!(vals[0] <= vals[1] && vals[1] <= vals[2]);
        for j in 0..3 {
            for i in 0..3 {
                let av: f64 = (0..3).map(|k| a[i * 3 + k] * vecs[k * 3 + j]).sum();
                assert!((av - vals[j] * vecs[i * 3 + j]).abs() < 1e-12);
            }
        }
    }
}
