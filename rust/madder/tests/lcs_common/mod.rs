//! Meshes, flows and references shared by `tests/ftle.rs` and `tests/ridges.rs`, written
//! independently of `madder::lcs`: flows (the gyres of §5.6, the Bickley jet), meshes of
//! parametrized surfaces (plane, cylinder, torus), an RK4 integrator in the parameters,
//! the classical grid FTLE (central differences, in the surface's metric), and a pixel
//! ridge detector with its own cleanup.

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
pub fn rk4(
    f: &impl Fn(f64, DVec2) -> DVec2,
    mut x: DVec2,
    t0: f64,
    span: f64,
    steps: usize,
) -> DVec2 {
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

/// Writes a field on a regular grid and ridge points for inspection (when `LCS_DUMP` names
/// a directory): `nx ny x0 x1 y0 y1`, the values, then `P x y` per point.
pub fn dump(name: &str, nx: usize, ny: usize, b: [f64; 4], field: &[f64], points: &[DVec2]) {
    let Ok(dir) = std::env::var("LCS_DUMP") else {
        return;
    };
    let mut s = format!("{nx} {ny} {} {} {} {}\n", b[0], b[1], b[2], b[3]);
    for v in field {
        s += &format!("{v}\n");
    }
    for p in points {
        s += &format!("P {} {}\n", p.x, p.y);
    }
    std::fs::write(format!("{dir}/{name}.txt"), s).unwrap();
}

/// The reference's ridge pixels in connected groups (8-neighbourhood, the grid's row and
/// column indices) of at least `min` pixels: the reference's own cleanup of short ridges.
pub fn long_groups(pix: &[(usize, usize)], min: usize) -> Vec<(usize, usize)> {
    let set: std::collections::HashMap<(usize, usize), usize> =
        pix.iter().enumerate().map(|(k, &p)| (p, k)).collect();
    let mut group = vec![usize::MAX; pix.len()];
    let mut keep = Vec::new();
    for s in 0..pix.len() {
        if group[s] != usize::MAX {
            continue;
        }
        group[s] = s;
        let mut stack = vec![s];
        let mut members = vec![s];
        while let Some(k) = stack.pop() {
            let (i, j) = pix[k];
            for di in -1i64..=1 {
                for dj in -1i64..=1 {
                    let q = ((i as i64 + di) as usize, (j as i64 + dj) as usize);
                    if let Some(&m) = set.get(&q) {
                        if group[m] == usize::MAX {
                            group[m] = s;
                            stack.push(m);
                            members.push(m);
                        }
                    }
                }
            }
        }
        if members.len() >= min {
            keep.extend(members.into_iter().map(|m| pix[m]));
        }
    }
    keep
}

/// The quad gyre: the double gyre's formula on `[0, 2] × [−1, 1]`.
pub fn quad_gyre(t: f64, p: DVec2) -> DVec2 {
    gyre(0.1, 0.25, 0.2 * PI, t, p)
}

/// The octuple gyre of §5.6: the quad gyre mirrored about `x = 2` onto `[0, 4] × [−1, 1]`,
/// periodic in both directions (periods 4 and 2).
pub fn octuple_gyre(t: f64, p: DVec2) -> DVec2 {
    let x = p.x.rem_euclid(4.0);
    let y = (p.y + 1.0).rem_euclid(2.0) - 1.0;
    if x <= 2.0 {
        quad_gyre(t, DVec2::new(x, y))
    } else {
        let w = quad_gyre(t, DVec2::new(4.0 - x, y));
        DVec2::new(-w.x, w.y)
    }
}

/// A parametrized surface: position and tangents at parameters `(x, y)`, and the inverse
/// (parameters of a point on or near it).
pub trait Surface: Sync {
    fn at(&self, q: DVec2) -> (DVec3, DVec3, DVec3);
    fn params(&self, p: DVec3) -> DVec2;
}

/// The torus `((R + r cos ψ) cos φ, (R + r cos ψ) sin φ, r sin ψ)`, `φ = 2πx/lx`,
/// `ψ = 2π(y − y0)/ly`.
pub struct Torus {
    pub big: f64,
    pub small: f64,
    pub lx: f64,
    pub ly: f64,
    pub y0: f64,
}

impl Surface for Torus {
    fn at(&self, q: DVec2) -> (DVec3, DVec3, DVec3) {
        let (kx, ky) = (2.0 * PI / self.lx, 2.0 * PI / self.ly);
        let (sf, cf) = (kx * q.x).sin_cos();
        let (sp, cp) = (ky * (q.y - self.y0)).sin_cos();
        let rho = self.big + self.small * cp;
        (
            DVec3::new(rho * cf, rho * sf, self.small * sp),
            kx * DVec3::new(-rho * sf, rho * cf, 0.0),
            ky * DVec3::new(
                -self.small * sp * cf,
                -self.small * sp * sf,
                self.small * cp,
            ),
        )
    }
    fn params(&self, p: DVec3) -> DVec2 {
        let phi = p.y.atan2(p.x).rem_euclid(2.0 * PI);
        let rho = p.truncate().length();
        let psi = p.z.atan2(rho - self.big).rem_euclid(2.0 * PI);
        DVec2::new(
            phi * self.lx / (2.0 * PI),
            self.y0 + psi * self.ly / (2.0 * PI),
        )
    }
}

/// The cylinder `(R cos θ, y, R sin θ)`, `θ = 2πx/lx`: periodic in x, flat.
pub struct Cylinder {
    pub lx: f64,
}

impl Surface for Cylinder {
    fn at(&self, q: DVec2) -> (DVec3, DVec3, DVec3) {
        let r = self.lx / (2.0 * PI);
        let (s, c) = (q.x / r).sin_cos();
        (
            DVec3::new(r * c, q.y, r * s),
            DVec3::new(-s, 0.0, c),
            DVec3::Y,
        )
    }
    fn params(&self, p: DVec3) -> DVec2 {
        let r = self.lx / (2.0 * PI);
        DVec2::new(p.z.atan2(p.x).rem_euclid(2.0 * PI) * r, p.y)
    }
}

/// A mesh of `surface` over `nx × ny` cells of parameters `[x0, x0 + lx] × [y0, y0 + ly]`,
/// each quad split along its `a–c` diagonal, periodic where `wrap` says (then the last
/// column or row is the first): vertex `(i, j)` is `i cols + j`. Returns the topology, the
/// positions, the parameters and `(cols, rows)`.
pub fn surface_grid(
    surface: &impl Surface,
    (nx, ny): (usize, usize),
    (x0, lx): (f64, f64),
    (y0, ly): (f64, f64),
    wrap: (bool, bool),
) -> (Topology, Vec<DVec3>, Vec<DVec2>, (usize, usize)) {
    let cols = if wrap.0 { nx } else { nx + 1 };
    let rows = if wrap.1 { ny } else { ny + 1 };
    let idx = |i: usize, j: usize| ((i % rows) * cols + j % cols) as u32;
    let mut faces = Vec::new();
    for i in 0..ny {
        for j in 0..nx {
            let (a, b, c, d) = (idx(i, j), idx(i, j + 1), idx(i + 1, j + 1), idx(i + 1, j));
            faces.push([a, b, c]);
            faces.push([a, c, d]);
        }
    }
    let mut q = Vec::new();
    for i in 0..rows {
        for j in 0..cols {
            q.push(DVec2::new(
                x0 + lx * j as f64 / nx as f64,
                y0 + ly * i as f64 / ny as f64,
            ));
        }
    }
    let p = q.iter().map(|&q| surface.at(q).0).collect();
    (
        Topology::from_triangles(q.len(), faces).unwrap(),
        p,
        q,
        (cols, rows),
    )
}

/// Reference FTLE on a parametrized surface: RK4 in the parameters, central differences
/// at `± delta`, and the Cauchy–Green eigenvalue in the surface's metric: the largest
/// `λ` of `G₀⁻¹ ∇φᵀ G₁ ∇φ`, `G = DXᵀ DX` at the start and end points.
pub fn reference_ftle_on(
    surface: &impl Surface,
    f: &(impl Fn(f64, DVec2) -> DVec2 + Sync),
    params: &[DVec2],
    t0: f64,
    span: f64,
    steps: usize,
    delta: f64,
) -> Vec<f64> {
    use glam::DMat2;
    use rayon::prelude::*;
    let metric = |q: DVec2| {
        let (_, a, b) = surface.at(q);
        DMat2::from_cols(
            DVec2::new(a.dot(a), a.dot(b)),
            DVec2::new(a.dot(b), b.dot(b)),
        )
    };
    params
        .par_iter()
        .map(|&x| {
            let m = |d: DVec2| rk4(f, x + d, t0, span, steps);
            let gx = (m(DVec2::new(delta, 0.0)) - m(DVec2::new(-delta, 0.0))) / (2.0 * delta);
            let gy = (m(DVec2::new(0.0, delta)) - m(DVec2::new(0.0, -delta))) / (2.0 * delta);
            let j = DMat2::from_cols(gx, gy);
            let c = metric(x).inverse() * j.transpose() * metric(m(DVec2::ZERO)) * j;
            let (tr, det) = (c.x_axis.x + c.y_axis.y, c.determinant());
            let l = 0.5 * (tr + (tr * tr - 4.0 * det).max(0.0).sqrt());
            l.ln() / (2.0 * span.abs())
        })
        .collect()
}

/// The plane `(x, y, 0)`.
pub struct Plane;

impl Surface for Plane {
    fn at(&self, q: DVec2) -> (DVec3, DVec3, DVec3) {
        (q.extend(0.0), DVec3::X, DVec3::Y)
    }
    fn params(&self, p: DVec3) -> DVec2 {
        p.truncate()
    }
}

/// Ridge pixels of a field on a `cols × rows` grid (row-major), periodic where `wrap` says:
/// vertices above `threshold` that are strict maxima across the grid in at least one of the
/// four directions (x, y, both diagonals) — a detector independent of the mesh method.
/// Non-periodic borders are skipped.
pub fn ridge_pixels(
    sigma: &[f64],
    (cols, rows): (usize, usize),
    wrap: (bool, bool),
    threshold: f64,
) -> Vec<(usize, usize)> {
    let at = |i: i64, j: i64| -> Option<f64> {
        let ok_i = wrap.1 || (0..rows as i64).contains(&i);
        let ok_j = wrap.0 || (0..cols as i64).contains(&j);
        (ok_i && ok_j).then(|| {
            sigma[i.rem_euclid(rows as i64) as usize * cols + j.rem_euclid(cols as i64) as usize]
        })
    };
    let mut out = Vec::new();
    for i in 0..rows as i64 {
        for j in 0..cols as i64 {
            let s = at(i, j).unwrap();
            if s <= threshold {
                continue;
            }
            let dirs = [(0i64, 1i64), (1, 0), (1, 1), (1, -1)];
            let mut interior = true;
            let mut peak = false;
            for (di, dj) in dirs {
                match (at(i + di, j + dj), at(i - di, j - dj)) {
                    (Some(a), Some(b)) => peak |= s > a && s > b,
                    _ => interior = false,
                }
            }
            if interior && peak {
                out.push((i as usize, j as usize));
            }
        }
    }
    out
}

/// Distance between parameter points, periodic with periods `period` (0: not periodic).
pub fn param_distance(a: DVec2, b: DVec2, period: DVec2) -> f64 {
    let wrap = |d: f64, l: f64| if l > 0.0 { d - l * (d / l).round() } else { d };
    DVec2::new(wrap(a.x - b.x, period.x), wrap(a.y - b.y, period.y)).length()
}

/// The largest distance from a point of `a` to the nearest point of `b` (brute force).
pub fn directed_hausdorff(a: &[DVec2], b: &[DVec2], period: DVec2) -> f64 {
    use rayon::prelude::*;
    a.par_iter()
        .map(|p| {
            b.iter()
                .map(|q| param_distance(*p, *q, period))
                .fold(f64::INFINITY, f64::min)
        })
        .reduce(|| 0.0, f64::max)
}

/// The same FTLE as the mesh method defines it on a curved surface, from reference end
/// points: RK4 in the parameters (`steps` steps), the end points mapped onto the surface,
/// the flow map's gradient fitted by least squares over the grid's one-ring (the six
/// neighbours `(0, ±1), (±1, 0), ±(1, 1)` of the `a–c` split) from the 3-D offsets of the
/// end points, in an orthonormal tangent frame of the start point.
pub fn reference_ftle_chords(
    surface: &impl Surface,
    f: &(impl Fn(f64, DVec2) -> DVec2 + Sync),
    params: &[DVec2],
    (cols, rows): (usize, usize),
    wrap: (bool, bool),
    (t0, span, steps): (f64, f64, usize),
) -> Vec<f64> {
    use glam::DMat2;
    use rayon::prelude::*;
    let end: Vec<DVec3> = params
        .par_iter()
        .map(|&q| surface.at(rk4(f, q, t0, span, steps)).0)
        .collect();
    let start: Vec<DVec3> = params.iter().map(|&q| surface.at(q).0).collect();
    (0..params.len())
        .into_par_iter()
        .map(|k| {
            let (i, j) = ((k / cols) as i64, (k % cols) as i64);
            let (_, a, b) = surface.at(params[k]);
            let x = a.normalize();
            let n = a.cross(b).normalize();
            let y = n.cross(x);
            let (mut m, mut bx, mut by) = (DMat2::ZERO, DVec3::ZERO, DVec3::ZERO);
            for (di, dj) in [(0, 1), (0, -1), (1, 0), (-1, 0), (1, 1), (-1, -1)] {
                let (ii, jj) = (i + di, j + dj);
                let ok = (wrap.1 || (0..rows as i64).contains(&ii))
                    && (wrap.0 || (0..cols as i64).contains(&jj));
                if !ok {
                    continue;
                }
                let kk = ii.rem_euclid(rows as i64) as usize * cols
                    + jj.rem_euclid(cols as i64) as usize;
                let e = start[kk] - start[k];
                let d = DVec2::new(e.dot(x), e.dot(y));
                m += DMat2::from_cols(d * d.x, d * d.y);
                bx += (end[kk] - end[k]) * d.x;
                by += (end[kk] - end[k]) * d.y;
            }
            let inv = m.inverse();
            let gx = bx * inv.x_axis.x + by * inv.x_axis.y;
            let gy = bx * inv.y_axis.x + by * inv.y_axis.y;
            let (c11, c12, c22) = (gx.dot(gx), gx.dot(gy), gy.dot(gy));
            let l = 0.5 * (c11 + c22 + ((c11 - c22).powi(2) + 4.0 * c12 * c12).sqrt());
            l.ln() / (2.0 * span.abs())
        })
        .collect()
}
