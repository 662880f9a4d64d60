//! Meshes, flows and references shared by `tests/ftle.rs` and `tests/ridges.rs`, written
//! independently of `madder::lcs`: a planar RK4 integrator, central-difference FTLE on a
//! regular grid, and a pixel ridge detector.

#![allow(dead_code)]

use std::f64::consts::PI;

use glam::{DVec2, DVec3};
use madder::mesh::Topology;

/// A regular grid of `nx × ny` cells over `[x0, x1] × [y0, y1]`, every quad split along its
/// `a–c` diagonal, counter-clockwise. Vertex `(i, j)` (row `i` along y) is `i (nx + 1) + j`.
pub fn rect_grid(nx: usize, ny: usize, x: [f64; 2], y: [f64; 2]) -> (Topology, Vec<DVec3>) {
    let idx = |i: usize, j: usize| (i * (nx + 1) + j) as u32;
    let mut faces = Vec::with_capacity(2 * nx * ny);
    for i in 0..ny {
        for j in 0..nx {
            let (a, b, c, d) = (idx(i, j), idx(i, j + 1), idx(i + 1, j + 1), idx(i + 1, j));
            faces.push([a, b, c]);
            faces.push([a, c, d]);
        }
    }
    let mut p = Vec::with_capacity((nx + 1) * (ny + 1));
    for i in 0..=ny {
        for j in 0..=nx {
            p.push(DVec3::new(
                x[0] + (x[1] - x[0]) * j as f64 / nx as f64,
                y[0] + (y[1] - y[0]) * i as f64 / ny as f64,
                0.0,
            ));
        }
    }
    (Topology::from_triangles(p.len(), faces).unwrap(), p)
}

/// A planar velocity field `v(t, x)`.
pub type Flow = fn(f64, DVec2) -> DVec2;

/// The double gyre of §5.6 with `A = 0.1`, `ε = 0.25`, `ω = 0.2π` on `[0, 2] × [0, 1]`.
pub fn double_gyre(t: f64, p: DVec2) -> DVec2 {
    gyre(0.1, 0.25, 0.2 * PI, t, p)
}

/// The steady double gyre (`ε = 0`): the separatrix is `x = 1`.
pub fn steady_gyre(t: f64, p: DVec2) -> DVec2 {
    gyre(0.1, 0.0, 0.2 * PI, t, p)
}

/// `u = −πA sin(πf) cos(πy)`, `v = πA cos(πf) sin(πy) f′`, `f = a x² + b x`,
/// `a = ε sin ωt`, `b = 1 − 2ε sin ωt` (§5.6).
pub fn gyre(amp: f64, eps: f64, omega: f64, t: f64, p: DVec2) -> DVec2 {
    let a = eps * (omega * t).sin();
    let b = 1.0 - 2.0 * a;
    let f = a * p.x * p.x + b * p.x;
    let df = 2.0 * a * p.x + b;
    DVec2::new(
        -PI * amp * (PI * f).sin() * (PI * p.y).cos(),
        PI * amp * (PI * f).cos() * (PI * p.y).sin() * df,
    )
}

/// The Bickley jet (Rypina et al. 2007; the parameters of numbacs' and LCS Tool's
/// examples), on `[0, π r0] × [−3, 3]` (lengths in Mm, time in days).
pub fn bickley(t: f64, p: DVec2) -> DVec2 {
    let u0 = 62.66e-6 * 86400.0; // Mm/day
    let l = 1.77; // Mm
    let r0 = 6.371;
    let c = [0.1446 * u0, 0.205 * u0, 0.461 * u0];
    let eps = [0.075, 0.4, 0.3];
    let k = [2.0 / r0, 4.0 / r0, 6.0 / r0];
    let sech = |z: f64| 1.0 / z.cosh();
    let (x, y) = (p.x, p.y);
    let s2 = sech(y / l).powi(2);
    let th = (y / l).tanh();
    let mut dpsi_dy = -u0 * l * s2 / l; // −U0 sech²(y/L)
    let mut dpsi_dx = 0.0;
    for n in 0..3 {
        let phase = k[n] * (x - c[n] * t);
        // ψ1 = U0 L sech²(y/L) Σ εn cos(kn (x − cn t))
        dpsi_dy += u0 * l * eps[n] * phase.cos() * (-2.0 * s2 * th / l);
        dpsi_dx += -u0 * l * s2 * eps[n] * k[n] * phase.sin();
    }
    // u = −∂ψ/∂y, v = ∂ψ/∂x, with ψ0 = −U0 L tanh(y/L)
    DVec2::new(-dpsi_dy, dpsi_dx)
}

/// Classical RK4 in the plane with `steps` steps: the reference flow map.
pub fn rk4(f: &impl Fn(f64, DVec2) -> DVec2, mut x: DVec2, t0: f64, span: f64, steps: usize) -> DVec2 {
    let h = span / steps as f64;
    for s in 0..steps {
        let t = t0 + s as f64 * h;
        let k1 = f(t, x);
        let k2 = f(t + 0.5 * h, x + 0.5 * h * k1);
        let k3 = f(t + 0.5 * h, x + 0.5 * h * k2);
        let k4 = f(t + h, x + h * k3);
        x += h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4);
    }
    x
}

/// Reference FTLE at the points of a regular `(nx+1) × (ny+1)` grid (row-major, like
/// [`rect_grid`]): RK4 with `steps` steps, the gradient by central differences over
/// auxiliary points at `± delta` (the classical grid method), `σ = ln √λ_max / |T|`.
pub fn reference_ftle(
    f: &(impl Fn(f64, DVec2) -> DVec2 + Sync),
    points: &[DVec3],
    t0: f64,
    span: f64,
    steps: usize,
    delta: f64,
) -> Vec<f64> {
    use rayon::prelude::*;
    points
        .par_iter()
        .map(|p| {
            let x = p.truncate();
            let m = |d: DVec2| rk4(f, x + d, t0, span, steps);
            let gx = (m(DVec2::new(delta, 0.0)) - m(DVec2::new(-delta, 0.0))) / (2.0 * delta);
            let gy = (m(DVec2::new(0.0, delta)) - m(DVec2::new(0.0, -delta))) / (2.0 * delta);
            let (c11, c12, c22) = (gx.dot(gx), gx.dot(gy), gy.dot(gy));
            let l = 0.5 * (c11 + c22 + ((c11 - c22).powi(2) + 4.0 * c12 * c12).sqrt());
            l.ln() / (2.0 * span.abs())
        })
        .collect()
}

/// Ridge pixels of a field on a regular grid (row-major, `nx + 1` columns): vertices above
/// `threshold` that are strict maxima across the grid in at least one of the four
/// directions (x, y, both diagonals) — a detector independent of the mesh method.
pub fn ridge_pixels(sigma: &[f64], nx: usize, ny: usize, threshold: f64) -> Vec<(usize, usize)> {
    let at = |i: usize, j: usize| sigma[i * (nx + 1) + j];
    let mut out = Vec::new();
    for i in 1..ny {
        for j in 1..nx {
            let s = at(i, j);
            if s <= threshold {
                continue;
            }
            let dirs = [(0i64, 1i64), (1, 0), (1, 1), (1, -1)];
            if dirs.iter().any(|&(di, dj)| {
                let a = at((i as i64 + di) as usize, (j as i64 + dj) as usize);
                let b = at((i as i64 - di) as usize, (j as i64 - dj) as usize);
                s > a && s > b
            }) {
                out.push((i, j));
            }
        }
    }
    out
}

/// The largest distance from a point of `a` to the nearest point of `b` (brute force).
pub fn directed_hausdorff(a: &[DVec2], b: &[DVec2]) -> f64 {
    a.iter()
        .map(|p| b.iter().map(|q| p.distance(*q)).fold(f64::INFINITY, f64::min))
        .fold(0.0, f64::max)
}

/// Points of `a` farther than `r` from every point of `b`.
pub fn farther_than(a: &[DVec2], b: &[DVec2], r: f64) -> usize {
    a.iter()
        .filter(|p| b.iter().all(|q| p.distance(*q) > r))
        .count()
}

/// Writes a field on a regular grid and ridge points for inspection (when `LCS_DUMP` names
/// a directory): `nx ny x0 x1 y0 y1`, the values, then `P x y` per point.
pub fn dump(name: &str, nx: usize, ny: usize, b: [f64; 4], field: &[f64], points: &[DVec2]) {
    let Ok(dir) = std::env::var("LCS_DUMP") else { return };
    let mut s = format!("{nx} {ny} {} {} {} {}\n", b[0], b[1], b[2], b[3]);
    for v in field {
        s += &format!("{v}\n");
    }
    for p in points {
        s += &format!("P {} {}\n", p.x, p.y);
    }
    std::fs::write(format!("{dir}/{name}.txt"), s).unwrap();
}
