//! The angle residual and its analytic gradient (§3.3.3), and the descent on the linear
//! map `L` of the embedding `x_v = L q_v` (the 12-D space of the seed modulo the
//! translation, which moves no angle).

use std::f64::consts::PI;

use glam::{DMat3, DVec3};
use rayon::prelude::*;

use super::encode::{AngleMesh, Angles, corner_angle, dihedral};

/// `d` wrapped to `(−π, π]`.
fn wrap(d: f64) -> f64 {
    let mut d = d % (2.0 * PI);
    if d > PI {
        d -= 2.0 * PI;
    } else if d <= -PI {
        d += 2.0 * PI;
    }
    d
}

/// `E = Σ_corners (α − ᾱ)² + Σ_edges (θ − θ̄)²` (the dihedral difference wrapped to
/// `(−π, π]`). Sums in a fixed order.
pub(crate) fn residual(mesh: &AngleMesh, target: &Angles, x: &[DVec3]) -> f64 {
    let faces = mesh.faces();
    let corner: Vec<f64> = faces
        .par_iter()
        .zip(target.corners.par_iter())
        .map(|(t, a)| {
            let p = t.map(|v| x[v as usize]);
            (0..3)
                .map(|c| {
                    let d = corner_angle(p[c], p[(c + 1) % 3], p[(c + 2) % 3]) - a[c];
                    d * d
                })
                .sum::<f64>()
        })
        .collect();
    let edge: Vec<f64> = mesh
        .interior()
        .par_iter()
        .zip(target.dihedrals.par_iter())
        .map(|(e, &t)| {
            let d = wrap(dihedral(mesh, e, x) - t);
            d * d
        })
        .collect();
    corner.iter().sum::<f64>() + edge.iter().sum::<f64>()
}

/// `∂α/∂q` and `∂α/∂r` of the angle at `p` between `q − p` and `r − p` (`∂α/∂p` is minus
/// their sum).
fn corner_gradient(p: DVec3, q: DVec3, r: DVec3) -> (DVec3, DVec3) {
    let (u, w) = (q - p, r - p);
    let perp = |a: DVec3, b: DVec3| {
        // −(b's part across a) / (|b⊥| |a|)
        let bp = b - a * (b.dot(a) / a.length_squared());
        let n = bp.length();
        if n > 0.0 {
            -bp / (n * a.length())
        } else {
            DVec3::ZERO
        }
    };
    (perp(u, w), perp(w, u))
}

/// The gradient of `θ` of interior edge `a → b` (faces `(a, b, k)` and `(b, a, l)`) with
/// respect to `[a, b, k, l]`.
pub(crate) fn dihedral_gradient(a: DVec3, b: DVec3, k: DVec3, l: DVec3) -> [DVec3; 4] {
    let e = b - a;
    let le2 = e.length_squared();
    let n1 = e.cross(k - a);
    let n2 = (a - b).cross(l - b);
    let (m1, m2) = (n1.length_squared(), n2.length_squared());
    if !(le2 > 0.0 && m1 > 0.0 && m2 > 0.0) {
        return [DVec3::ZERO; 4];
    }
    let le = le2.sqrt();
    let gk = -le / m1 * n1;
    let gl = -le / m2 * n2;
    let tk = (k - a).dot(e) / le2;
    let tl = (l - a).dot(e) / le2;
    let ga = -(1.0 - tk) * gk - (1.0 - tl) * gl;
    let gb = -tk * gk - tl * gl;
    [ga, gb, gk, gl]
}

/// `E` and `∂E/∂x_v` for every vertex. Element gradients are computed in parallel and
/// scattered in element order (deterministic).
pub(crate) fn residual_gradient(
    mesh: &AngleMesh,
    target: &Angles,
    x: &[DVec3],
) -> (f64, Vec<DVec3>) {
    let faces = mesh.faces();
    let per_face: Vec<(f64, [DVec3; 3])> = faces
        .par_iter()
        .zip(target.corners.par_iter())
        .map(|(t, a)| {
            let p = t.map(|v| x[v as usize]);
            let mut g = [DVec3::ZERO; 3];
            let mut e = 0.0;
            for c in 0..3 {
                let (c1, c2) = ((c + 1) % 3, (c + 2) % 3);
                let d = corner_angle(p[c], p[c1], p[c2]) - a[c];
                e += d * d;
                let (gq, gr) = corner_gradient(p[c], p[c1], p[c2]);
                g[c1] += 2.0 * d * gq;
                g[c2] += 2.0 * d * gr;
                g[c] -= 2.0 * d * (gq + gr);
            }
            (e, g)
        })
        .collect();
    let per_edge: Vec<(f64, [DVec3; 4])> = mesh
        .interior()
        .par_iter()
        .zip(target.dihedrals.par_iter())
        .map(|(ed, &t)| {
            let d = wrap(dihedral(mesh, ed, x) - t);
            let k = faces[ed.f1 as usize][ed.c1 as usize];
            let l = faces[ed.f2 as usize][ed.c2 as usize];
            let g = dihedral_gradient(
                x[ed.a as usize],
                x[ed.b as usize],
                x[k as usize],
                x[l as usize],
            );
            (d * d, g.map(|gi| 2.0 * d * gi))
        })
        .collect();
    let mut grad = vec![DVec3::ZERO; x.len()];
    let mut total = 0.0;
    for (t, (e, g)) in faces.iter().zip(&per_face) {
        total += e;
        for c in 0..3 {
            grad[t[c] as usize] += g[c];
        }
    }
    for (ed, (e, g)) in mesh.interior().iter().zip(&per_edge) {
        total += e;
        let k = faces[ed.f1 as usize][ed.c1 as usize];
        let l = faces[ed.f2 as usize][ed.c2 as usize];
        for (v, gi) in [ed.a, ed.b, k, l].into_iter().zip(g) {
            grad[v as usize] += *gi;
        }
    }
    (total, grad)
}

/// `x_v = L q_v`.
pub(crate) fn embed(l: DMat3, q: &[DVec3]) -> Vec<DVec3> {
    q.par_iter().map(|&qv| l * qv).collect()
}

/// Gradient descent on `L` (Armijo backtracking; a step is taken only if it lowers `E`).
/// Returns the final `L` and `E` after each accepted step (the first entry is `E(L₀)`).
pub(crate) fn descend(
    mesh: &AngleMesh,
    target: &Angles,
    q: &[DVec3],
    l0: DMat3,
    iterations: usize,
) -> (DMat3, Vec<f64>) {
    let mut l = l0;
    let x0 = embed(l, q);
    // E from `residual` throughout (the gradient's own sum runs in another order)
    let mut e = residual(mesh, target, &x0);
    let mut g = residual_gradient(mesh, target, &x0).1;
    let mut history = vec![e];
    let mut step = f64::NAN;
    for _ in 0..iterations {
        // ∂E/∂L = Σ_v g_v q_vᵀ, summed in vertex order
        let gl = g.iter().zip(q).fold(DMat3::ZERO, |acc, (gv, qv)| {
            acc + DMat3::from_cols(*gv * qv.x, *gv * qv.y, *gv * qv.z)
        });
        let gn2 = [gl.x_axis, gl.y_axis, gl.z_axis]
            .iter()
            .map(|c| c.length_squared())
            .sum::<f64>();
        if !gn2.is_finite() || gn2 <= 0.0 {
            break;
        }
        if !step.is_finite() {
            // first step: move L by 1 % of its size
            let ln = [l.x_axis, l.y_axis, l.z_axis]
                .iter()
                .map(|c| c.length_squared())
                .sum::<f64>()
                .sqrt();
            step = 0.01 * ln / gn2.sqrt();
        }
        let mut accepted = false;
        for _ in 0..40 {
            let cand = l - gl * step;
            let xe = embed(cand, q);
            let ec = residual(mesh, target, &xe);
            if ec <= e - 1e-4 * step * gn2 && ec < e {
                l = cand;
                e = ec;
                g = residual_gradient(mesh, target, &xe).1;
                accepted = true;
                step *= 2.0;
                break;
            }
            step *= 0.5;
        }
        if !accepted {
            break;
        }
        history.push(e);
    }
    (l, history)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fd_check(f: impl Fn(&[DVec3]) -> f64, x: &[DVec3], g: &[DVec3]) {
        let h = 1e-6;
        for v in 0..x.len() {
            for d in 0..3 {
                let mut xp = x.to_vec();
                let mut xm = x.to_vec();
                xp[v][d] += h;
                xm[v][d] -= h;
                let fd = (f(&xp) - f(&xm)) / (2.0 * h);
                assert!(
                    (fd - g[v][d]).abs() < 1e-6 * (1.0 + fd.abs()),
                    "vertex {v} axis {d}: fd {fd} vs {}",
                    g[v][d]
                );
            }
        }
    }

    #[test]
    fn dihedral_gradient_matches_finite_differences() {
        let x = [
            DVec3::new(0.1, -0.2, 0.05),
            DVec3::new(1.2, 0.1, -0.1),
            DVec3::new(0.4, 0.9, 0.3),
            DVec3::new(0.7, -0.8, 0.6),
        ];
        let theta = |p: &[DVec3]| {
            let n1 = (p[1] - p[0]).cross(p[2] - p[0]);
            let n2 = (p[0] - p[1]).cross(p[3] - p[1]);
            n1.cross(n2)
                .dot((p[1] - p[0]).normalize())
                .atan2(n1.dot(n2))
        };
        let g = dihedral_gradient(x[0], x[1], x[2], x[3]);
        fd_check(theta, &x, &g);
    }

    #[test]
    fn corner_gradient_matches_finite_differences() {
        let x = [
            DVec3::new(0.1, -0.2, 0.05),
            DVec3::new(1.2, 0.1, -0.1),
            DVec3::new(0.4, 0.9, 0.3),
        ];
        let (gq, gr) = corner_gradient(x[0], x[1], x[2]);
        let g = [-(gq + gr), gq, gr];
        fd_check(|p: &[DVec3]| corner_angle(p[0], p[1], p[2]), &x, &g);
    }

    #[test]
    fn wrap_is_in_range() {
        assert!((wrap(3.0 * PI / 2.0) + PI / 2.0).abs() < 1e-15);
        assert!((wrap(-3.0 * PI / 2.0) - PI / 2.0).abs() < 1e-15);
        assert_eq!(wrap(0.25), 0.25);
    }
}
