//! Tracked reconstruction (issue 15's warm decode): a frame of a sequence from its angles and
//! the previous frame's positions, by integrating face rotations, face scales and positions
//! with three fixed graph Laplacians factorized once per mesh. The math is in the module
//! docs of [`crate::angles`], "Tracked reconstruction".

use glam::{DMat3, DQuat, DVec3};
use rayon::prelude::*;

use super::cache::Tracker;
use super::encode::{AngleMesh, Angles, NONE};
use super::local::preprocess;
use super::refine::{descend, embed};
use super::spectral::{Reconstruction, normalize};
use crate::error::{AngleError, SolveError};
use crate::ops::restrict::entry_index;
use crate::ops::{CscPattern, LowerCsc, PrefactoredSpd};

/// The rotation iteration stops after a round that turned no face by more than this
/// (radians). On consistent angles the rounds converge quadratically (measured updates
/// 0.15, 1.5·10⁻³, 3·10⁻⁷, 10⁻¹⁵ from the previous frame; 10⁻², 1.3·10⁻⁵, 1.5·10⁻¹¹ from
/// the codec's extrapolated start: the next update is ~0.1 δ²), so what is left after an
/// update of 10⁻⁴ is ~10⁻⁹. On quantized angles they converge linearly at a rate of the
/// order of the quantization noise (12 bits, 100k cloth: updates 1.9·10⁻², 4·10⁻⁵,
/// 9·10⁻⁸, a rate of 2·10⁻³), so what is left is ~10⁻⁴ of the quantization error itself.
/// (A third round that moves nothing visible costs a fifth of a 100k frame's decode.)
const SETTLED: f64 = 1e-4;
/// While the rounds converge quadratically, a round that turned some face by `δ` leaves
/// about `AHEAD δ²` for the next (measured: 0.11–0.13 on the bench's cloth, from the
/// previous frame, the extrapolated start and 12-bit angles alike). With a
/// [`ReconstructOptions::tolerance`](super::ReconstructOptions::tolerance) the rounds also
/// stop once that is below it: the codec's angles carry ±Δ/2 of rounding, and a rotation
/// error of Δ/20 left on top moves the decode's error by a fraction of a percent
/// (measured: 9.319·10⁻³ → 9.322·10⁻³ of the diagonal, 100k cloth at 12 bits) for one
/// round (of two) less.
const AHEAD: f64 = 0.1;
/// ... or after this many rounds (then the caller falls back to the spectral method).
pub(crate) const MAX_ROUNDS: usize = 24;
/// A settled fit whose residual still turns some edge by more than `2 sin(GROSS/2)` is a
/// wrong fixed point (a start too far from the angles), not noise: refused like an
/// unsettled one.
const GROSS: f64 = 1.0;

/// The Laplacian `Σ_(i,j) (δᵢ − δⱼ)(δᵢ − δⱼ)ᵀ + δ₀δ₀ᵀ` of the node pairs `pairs` (a pair
/// listed twice counts twice), factorized: the `δ₀δ₀ᵀ` anchors the constant, which the
/// least-squares problems below leave free, at node 0.
fn laplacian(n: usize, pairs: &[(u32, u32)]) -> Result<PrefactoredSpd<CscPattern>, SolveError> {
    let lower = |&(i, j): &(u32, u32)| if i > j { (i, j) } else { (j, i) };
    let keys = pairs
        .iter()
        .map(|p| {
            let (r, c) = lower(p);
            ((c as u64) << 32) | r as u64
        })
        .chain((0..n as u64).map(|i| (i << 32) | i))
        .collect();
    let graph = CscPattern::from_keys(n, keys);
    let at = |r: u32, c: u32| entry_index(graph.col_ptr(), graph.row_idx(), r, c);
    let mut values = vec![0.0; graph.nnz()];
    for p in pairs {
        let (r, c) = lower(p);
        values[at(r, r)] += 1.0;
        values[at(c, c)] += 1.0;
        values[at(r, c)] -= 1.0;
    }
    values[at(0, 0)] += 1.0;
    let mut solver = PrefactoredSpd::new_simplicial(graph)?;
    solver.factorize(&values)?;
    Ok(solver)
}

impl Tracker {
    fn new(mesh: &AngleMesh) -> Result<Self, SolveError> {
        let dual: Vec<(u32, u32)> = mesh.interior().iter().map(|e| (e.f1, e.f2)).collect();
        let primal: Vec<(u32, u32)> = mesh
            .faces()
            .iter()
            .flat_map(|t| [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])])
            .collect();
        Ok(Self {
            dual: laplacian(mesh.n_faces(), &dual)?,
            primal: laplacian(mesh.n_vertices(), &primal)?,
            tree: spanning_tree(mesh),
        })
    }
}

/// The faces reached from face 0 across interior edges, breadth first (each face's edges in
/// corner order), each with the edge it was reached across. The callers have checked that
/// every face is reached.
fn spanning_tree(mesh: &AngleMesh) -> Vec<(u32, u32)> {
    let nf = mesh.n_faces();
    let mut seen = vec![false; nf];
    let mut tree = Vec::with_capacity(nf.saturating_sub(1));
    seen[0] = true;
    let mut head = 0;
    let mut visit = |f: usize, tree: &mut Vec<(u32, u32)>| {
        for &ie in &mesh.face_interior()[f] {
            if ie == NONE {
                continue;
            }
            let e = &mesh.interior()[ie as usize];
            let g = if e.f1 as usize == f { e.f2 } else { e.f1 };
            if !seen[g as usize] {
                seen[g as usize] = true;
                tree.push((g, ie));
            }
        }
    };
    visit(0, &mut tree);
    while head < tree.len() {
        let f = tree[head].0 as usize;
        visit(f, &mut tree);
        head += 1;
    }
    tree
}

/// A face's unit-side shape from its corners `α` (module docs): the sines and cosines of
/// the half corners, from which everything else follows without another transcendental.
struct Shape {
    /// `(sin, cos)(α_c / 2)`.
    half: [(f64, f64); 3],
}

impl Shape {
    fn new(a: &[f64; 3]) -> Self {
        Self {
            half: a.map(|x| (0.5 * x).sin_cos()),
        }
    }
    /// `sin α_c`.
    fn sin(&self, c: usize) -> f64 {
        let (s, co) = self.half[c];
        2.0 * s * co
    }
    /// The turn `R_z(φ_k)` of the side from corner `k` to corner `k + 1`: its direction in
    /// the face's frame is `φ₀ = 0`, `φ₁ = π − α₁`, `φ₂ = π + α₀`.
    fn side_turn(&self, k: usize) -> DQuat {
        let ((s0, c0), (s1, c1)) = (self.half[0], self.half[1]);
        match k {
            0 => DQuat::IDENTITY,
            // half angle π/2 − α₁/2
            1 => DQuat::from_xyzw(0.0, 0.0, c1, s1),
            // half angle π/2 + α₀/2
            _ => DQuat::from_xyzw(0.0, 0.0, c0, -s0),
        }
    }
    /// The corners `p₁ − p₀ = (1, 0, 0)` and `p₂ − p₀ = (sin α₁/sin α₂)(cos α₀, sin α₀, 0)`.
    fn p2(&self) -> DVec3 {
        let (s0, c0) = self.half[0];
        let l = self.sin(1) / self.sin(2);
        l * DVec3::new(c0 * c0 - s0 * s0, 2.0 * s0 * c0, 0.0)
    }
}

/// The rotation (a unit quaternion) of the frame of `p` (vertex positions of a face): `x`
/// along `p₁ − p₀`, `z` the normal; the identity for a degenerate face.
fn face_rotation(p: [DVec3; 3]) -> DQuat {
    let x = (p[1] - p[0]).normalize_or_zero();
    let z = (p[1] - p[0]).cross(p[2] - p[0]).normalize_or_zero();
    if x == DVec3::ZERO || z == DVec3::ZERO {
        return DQuat::IDENTITY;
    }
    DQuat::from_mat3(&DMat3::from_cols(x, z.cross(x), z)).normalize()
}

/// The residual of a rotation that should be the identity: `2 sin(φ/2) n̂` for a turn by `φ`
/// about `n̂` (twice the quaternion's vector part, the shorter way round). It vanishes
/// exactly where the rotation vector `φ n̂` does and agrees with it to first order, so the
/// rounds converge alike, without a transcendental (module docs).
fn residual(q: DQuat) -> DVec3 {
    if q.w < 0.0 {
        -2.0 * q.xyz()
    } else {
        2.0 * q.xyz()
    }
}

/// `q` turned by the small rotation `ω` (world frame): the unit quaternion of
/// `(1, ω/2) q`, which turns by `2 atan(|ω|/2)`, `|ω|` to second order.
fn turned(w: DVec3, q: DQuat) -> DQuat {
    let h = 0.5 * w;
    (DQuat::from_xyzw(h.x, h.y, h.z, 1.0) * q).normalize()
}

/// Per face, the right-hand side `b_f = Σ_e ±d_e` of the dual least-squares problem
/// `min Σ_e |u_f1 − u_f2 + d_e|²` (`b_f1 −= d_e`, `b_f2 += d_e`), summed in the face's corner
/// order, for the first `k` components of `d`; the result is `k` columns of `|T|`.
fn dual_rhs(mesh: &AngleMesh, d: &[[f64; 4]], k: usize) -> Vec<f64> {
    let nf = mesh.n_faces();
    let mut out = vec![0.0; nf * k];
    let per_face: Vec<[f64; 4]> = mesh
        .face_interior()
        .par_iter()
        .enumerate()
        .map(|(f, fi)| {
            let mut b = [0.0; 4];
            for &ie in fi {
                if ie == NONE {
                    continue;
                }
                let e = &mesh.interior()[ie as usize];
                let sign = if e.f1 as usize == f { -1.0 } else { 1.0 };
                for (c, bc) in b.iter_mut().enumerate().take(k) {
                    *bc += sign * d[ie as usize][c];
                }
            }
            b
        })
        .collect();
    out.par_chunks_mut(nf).enumerate().for_each(|(c, col)| {
        for (o, b) in col.iter_mut().zip(&per_face) {
            *o = b[c];
        }
    });
    out
}

impl AngleMesh {
    /// Reconstructs one frame of a sequence from its angles, tracking the previous frame's
    /// positions `previous` (module docs, "Tracked reconstruction"): the face rotations
    /// start from `previous`'s and are corrected by a few solves with a fixed, prefactored
    /// Laplacian of the faces; the face scales and the positions follow by one solve each.
    /// Exact angles give the exact shape (up to a similarity); on inconsistent angles the
    /// result is a least-squares fit of rotations, scales and positions in turn, not the
    /// spectral method's minimizer. Returns `None` if the rotations did not settle within
    /// [`MAX_ROUNDS`] rounds (a `previous` far from the new shape): the caller then uses
    /// the spectral reconstruction; so does a settled fit that still turns some edge by more
    /// than 1 rad (a wrong fixed point). The placement and the optional descent work as in
    /// [`Self::reconstruct`] (the descent on a linear map of the tracked positions); the
    /// result's `eigenvalues` are zero, `residual` is empty without the descent (its
    /// history with it), and `rounds` counts the rotation rounds.
    ///
    /// Errors: those of [`Self::reconstruct_warm`].
    pub fn reconstruct_tracked(
        &self,
        angles: &Angles,
        previous: &[DVec3],
        options: &super::ReconstructOptions,
    ) -> Result<Option<Reconstruction>, AngleError> {
        self.tracked(angles, Some(previous), options)
    }

    /// The tracked reconstruction without a previous frame: the face rotations start from
    /// the transition rotations composed along a breadth-first spanning tree of the faces
    /// (module docs, "Tracked reconstruction"), the rest as [`Self::reconstruct_tracked`].
    /// On angles a few quantization steps from consistent the start is within a few
    /// hundredths of a radian of the fit; `None` where the rounds do not settle (noisy
    /// angles: the composed rotations drift along the tree), and the caller then uses the
    /// spectral reconstruction.
    ///
    /// Errors: those of [`Self::reconstruct`].
    pub fn reconstruct_tracked_cold(
        &self,
        angles: &Angles,
        options: &super::ReconstructOptions,
    ) -> Result<Option<Reconstruction>, AngleError> {
        self.tracked(angles, None, options)
    }

    /// The checks, the kept [`Tracker`] and [`Self::track`], for both entries.
    fn tracked(
        &self,
        angles: &Angles,
        previous: Option<&[DVec3]>,
        options: &super::ReconstructOptions,
    ) -> Result<Option<Reconstruction>, AngleError> {
        self.check_angles(angles)?;
        self.check_connected()?;
        if let Some(previous) = previous {
            crate::mesh::geometry::check_positions(self.topology(), previous)?;
        }
        if let Some(p) = &options.placement {
            p.check(self.n_faces())?;
        }
        let target = preprocess(angles);
        let cache = self.tracker_cache();
        let mut tracker = cache.take_or(|| Tracker::new(self))?;
        let out = self.track(&target, previous, &mut tracker, options);
        cache.put(tracker);
        Ok(out)
    }

    /// The tracked reconstruction from `start`, or, where it does not settle, the
    /// spectral one warm-started from `previous` (the callers' fallback, written once).
    pub fn reconstruct_following(
        &self,
        angles: &Angles,
        start: &[DVec3],
        previous: &[DVec3],
        options: &super::ReconstructOptions,
    ) -> Result<Reconstruction, AngleError> {
        match self.reconstruct_tracked(angles, start, options)? {
            Some(r) => Ok(r),
            None => self.reconstruct_warm(angles, previous, options),
        }
    }

    /// A frame without a previous one, tracked: from the tree's start
    /// ([`Self::reconstruct_tracked_cold`]), else from the spectral reconstruction
    /// ([`Self::reconstruct_tracked_from_spectral`]).
    pub fn reconstruct_cold(
        &self,
        angles: &Angles,
        options: &super::ReconstructOptions,
    ) -> Result<Vec<DVec3>, AngleError> {
        match self.reconstruct_tracked_cold(angles, options)? {
            Some(r) => Ok(r.positions),
            None => self.reconstruct_tracked_from_spectral(angles, options),
        }
    }

    /// The tracked reconstruction started from the spectral one, or where it does not
    /// settle the spectral one itself (the keyframes of files of flag 2 alone, the cold
    /// start's fallback).
    pub fn reconstruct_tracked_from_spectral(
        &self,
        angles: &Angles,
        options: &super::ReconstructOptions,
    ) -> Result<Vec<DVec3>, AngleError> {
        let spectral = self.reconstruct(angles, options)?.positions;
        Ok(
            match self.reconstruct_tracked(angles, &spectral, options)? {
                Some(r) => r.positions,
                None => spectral,
            },
        )
    }

    fn track(
        &self,
        target: &Angles,
        previous: Option<&[DVec3]>,
        tracker: &mut Tracker,
        options: &super::ReconstructOptions,
    ) -> Option<Reconstruction> {
        let faces = self.faces();
        let nf = faces.len();
        let shape: Vec<Shape> = target.corners.par_iter().map(Shape::new).collect();
        // R_z(π): the side b → a of the second face, turned round to a → b
        let half_turn = DQuat::from_xyzw(0.0, 0.0, 1.0, 0.0);
        // per interior edge: the rotation M with Q₂ = Q₁ M, and the log-ratio of the edge's
        // lengths in its two faces' unit-side shapes (the side opposite corner c has length
        // sin α_c / sin α₂)
        let (turn, ratio): (Vec<DQuat>, Vec<f64>) = self
            .interior()
            .par_iter()
            .zip(target.dihedrals.par_iter())
            .map(|(e, &theta)| {
                let (s1, s2) = (&shape[e.f1 as usize], &shape[e.f2 as usize]);
                let (c1, c2) = (e.c1 as usize, e.c2 as usize);
                let to2 = s2.side_turn((c2 + 1) % 3) * half_turn;
                let m =
                    s1.side_turn((c1 + 1) % 3) * DQuat::from_rotation_x(theta) * to2.conjugate();
                let r = (s1.sin(c1) * s2.sin(2)) / (s1.sin(2) * s2.sin(c2));
                (m, r.ln())
            })
            .unzip();
        let mut q: Vec<DQuat> = match previous {
            Some(previous) => faces
                .par_iter()
                .map(|t| face_rotation(t.map(|v| previous[v as usize])))
                .collect(),
            None => {
                // Q₂ = Q₁ M across every tree edge, from Q = 1 at face 0
                let mut q = vec![DQuat::IDENTITY; nf];
                for &(g, ie) in &tracker.tree {
                    let e = &self.interior()[ie as usize];
                    let m = turn[ie as usize];
                    q[g as usize] = if e.f2 == g {
                        (q[e.f1 as usize] * m).normalize()
                    } else {
                        (q[e.f2 as usize] * m.conjugate()).normalize()
                    };
                }
                q
            }
        };
        // rotations: Q_f ← exp(ω_f) Q_f with L ω = b from c_e = log(Q₁ M Q₂⁻¹); the first
        // round also solves the log-scales (a fourth column)
        let mut rounds = 0;
        let mut log_scale = Vec::new();
        loop {
            if rounds == MAX_ROUNDS {
                return None;
            }
            rounds += 1;
            let k = if rounds == 1 { 4 } else { 3 };
            let d: Vec<[f64; 4]> = self
                .interior()
                .par_iter()
                .zip(turn.par_iter())
                .zip(ratio.par_iter())
                .map(|((e, m), r)| {
                    let c = residual(q[e.f1 as usize] * *m * q[e.f2 as usize].conjugate());
                    [c.x, c.y, c.z, *r]
                })
                .collect();
            let mut b = dual_rhs(self, &d, k);
            tracker.dual.solve_in_place_split(&mut b, 2);
            if k == 4 {
                log_scale = b[3 * nf..].to_vec();
            }
            let largest = q
                .par_iter_mut()
                .enumerate()
                .map(|(f, qf)| {
                    let w = DVec3::new(b[f], b[nf + f], b[2 * nf + f]);
                    *qf = turned(w, *qf);
                    w.length()
                })
                .reduce(|| 0.0, f64::max);
            if !largest.is_finite() {
                return None;
            }
            if largest <= SETTLED || AHEAD * largest * largest <= options.tolerance {
                let gross = 2.0 * (0.5 * GROSS).sin();
                if d.par_iter()
                    .any(|c| c[0] * c[0] + c[1] * c[1] + c[2] * c[2] > gross * gross)
                {
                    return None;
                }
                break;
            }
        }
        // positions: min Σ_faces Σ_sides |x_j − x_i − s_f Q_f (P_j − P_i)|²
        let nv = self.n_vertices();
        let sides: Vec<[DVec3; 3]> = shape
            .par_iter()
            .zip(q.par_iter())
            .zip(log_scale.par_iter())
            .map(|((sh, qf), ls)| {
                let p = [DVec3::ZERO, DVec3::X, sh.p2()];
                let s = ls.exp();
                std::array::from_fn(|k| *qf * ((p[(k + 1) % 3] - p[k]) * s))
            })
            .collect();
        // one column per task, each summed in the faces' order
        let mut b = vec![0.0; 3 * nv];
        b.par_chunks_mut(nv).enumerate().for_each(|(c, col)| {
            for (t, side) in faces.iter().zip(&sides) {
                for k in 0..3 {
                    col[t[k] as usize] -= side[k][c];
                    col[t[(k + 1) % 3] as usize] += side[k][c];
                }
            }
        });
        tracker.primal.solve_in_place_split(&mut b, 2);
        let mut positions: Vec<DVec3> = (0..nv)
            .into_par_iter()
            .map(|v| DVec3::new(b[v], b[nv + v], b[2 * nv + v]))
            .collect();
        // the optional descent (§3.3.3) on a linear map of the positions, as after the
        // spectral method's voting
        let mut residual = Vec::new();
        if options.refine_iterations > 0 {
            let (l, history) = descend(
                self,
                target,
                &positions,
                DMat3::IDENTITY,
                options.refine_iterations,
            );
            positions = embed(l, &positions);
            residual = history;
        }
        match &options.placement {
            Some(p) => p.apply(faces, &mut positions),
            None => normalize(self.edges(), &mut positions),
        }
        Some(Reconstruction {
            positions,
            residual,
            eigenvalues: [0.0; 4],
            rounds,
        })
    }
}
