//! Meshes and measures shared by the angle tests (seed ch. 3): closed (an ellipsoidal
//! icosphere with a bump, a torus, a genus-2 plate with two holes) and open (a waving sheet,
//! a synthetic flag), and the Procrustes distance with scale, computed independently of the
//! crate (faer's dense SVD).

#![allow(dead_code)]

use std::collections::HashMap;
use std::f64::consts::PI;

use glam::DVec3;
use madder::angles::Angles;
use madder::rng::SplitMix64;

pub type Mesh = (Vec<[u32; 3]>, Vec<DVec3>);

/// An icosahedron subdivided `level` times onto the unit sphere, then stretched to an
/// ellipsoid with a bump (so no symmetry helps the reconstruction).
pub fn blob(level: usize) -> Mesh {
    let t = (1.0 + 5f64.sqrt()) / 2.0;
    let mut x: Vec<DVec3> = [
        (-1.0, t, 0.0),
        (1.0, t, 0.0),
        (-1.0, -t, 0.0),
        (1.0, -t, 0.0),
        (0.0, -1.0, t),
        (0.0, 1.0, t),
        (0.0, -1.0, -t),
        (0.0, 1.0, -t),
        (t, 0.0, -1.0),
        (t, 0.0, 1.0),
        (-t, 0.0, -1.0),
        (-t, 0.0, 1.0),
    ]
    .iter()
    .map(|&(a, b, c)| DVec3::new(a, b, c).normalize())
    .collect();
    let mut f: Vec<[u32; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    for _ in 0..level {
        let mut mid: HashMap<(u32, u32), u32> = HashMap::new();
        let mut nf = Vec::with_capacity(4 * f.len());
        for t in &f {
            let mut m = [0u32; 3];
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                let key = (a.min(b), a.max(b));
                m[k] = *mid.entry(key).or_insert_with(|| {
                    x.push(((x[a as usize] + x[b as usize]) * 0.5).normalize());
                    (x.len() - 1) as u32
                });
            }
            nf.push([t[0], m[0], m[2]]);
            nf.push([t[1], m[1], m[0]]);
            nf.push([t[2], m[2], m[1]]);
            nf.push(m);
        }
        f = nf;
    }
    let x = x
        .iter()
        .map(|p| {
            let bump =
                1.0 + 0.25 * (-((*p - DVec3::new(0.6, 0.5, 0.6)).length_squared()) * 4.0).exp();
            DVec3::new(1.3 * p.x, 0.9 * p.y, 0.7 * p.z) * bump
        })
        .collect();
    (f, x)
}

/// A torus, radii 1 and 0.4, `nu × nv` quads split into triangles.
pub fn torus(nu: usize, nv: usize) -> Mesh {
    let idx = |i: usize, j: usize| ((i % nu) * nv + (j % nv)) as u32;
    let mut f = Vec::new();
    for i in 0..nu {
        for j in 0..nv {
            let (a, b, c, d) = (idx(i, j), idx(i + 1, j), idx(i + 1, j + 1), idx(i, j + 1));
            f.push([a, b, c]);
            f.push([a, c, d]);
        }
    }
    let mut x = Vec::new();
    for i in 0..nu {
        for j in 0..nv {
            let u = 2.0 * PI * i as f64 / nu as f64;
            let v = 2.0 * PI * j as f64 / nv as f64 + 0.3 * (u.sin());
            let r = 1.0 + 0.4 * v.cos();
            x.push(DVec3::new(r * u.cos(), r * u.sin(), 0.4 * v.sin()));
        }
    }
    (f, x)
}

/// The boundary of a 5×3×1 slab of unit cubes with cells (1, 1) and (3, 1) removed: a
/// genus-2 surface. Every unit square is split into `m × m` quads of two triangles, and the
/// surface is warped smoothly so that it is curved everywhere.
pub fn genus2(m: usize) -> Mesh {
    let solid = |i: i64, j: i64, k: i64| {
        (0..5).contains(&i) && (0..3).contains(&j) && k == 0 && !(j == 1 && (i == 1 || i == 3))
    };
    let mut ids: HashMap<[i64; 3], u32> = HashMap::new();
    let mut x = Vec::new();
    let mut f = Vec::new();
    let m = m as i64;
    let mut vid = |p: [i64; 3], x: &mut Vec<DVec3>| {
        *ids.entry(p).or_insert_with(|| {
            x.push(DVec3::new(p[0] as f64, p[1] as f64, p[2] as f64) / m as f64);
            (x.len() - 1) as u32
        })
    };
    let dirs: [[i64; 3]; 6] = [
        [1, 0, 0],
        [-1, 0, 0],
        [0, 1, 0],
        [0, -1, 0],
        [0, 0, 1],
        [0, 0, -1],
    ];
    for i in 0..5 {
        for j in 0..3 {
            if !solid(i, j, 0) {
                continue;
            }
            for n in dirs {
                if solid(i + n[0], j + n[1], n[2]) {
                    continue;
                }
                // tangents u, v with u × v = n
                let axis = n.iter().position(|&c| c != 0).unwrap();
                let (a1, a2) = ((axis + 1) % 3, (axis + 2) % 3);
                let (mut u, mut v) = ([0i64; 3], [0i64; 3]);
                u[a1] = 1;
                v[a2] = 1;
                let sign = n[axis];
                if sign < 0 {
                    std::mem::swap(&mut u, &mut v);
                }
                // the face's corner: the cube's corner, pushed to the far side for +n
                let mut o = [i * m, j * m, 0];
                if sign > 0 {
                    o[axis] += m;
                }
                for s in 0..m {
                    for t in 0..m {
                        let p = |ds: i64, dt: i64| {
                            [
                                o[0] + (s + ds) * u[0] + (t + dt) * v[0],
                                o[1] + (s + ds) * u[1] + (t + dt) * v[1],
                                o[2] + (s + ds) * u[2] + (t + dt) * v[2],
                            ]
                        };
                        let q = [p(0, 0), p(1, 0), p(1, 1), p(0, 1)].map(|c| vid(c, &mut x));
                        f.push([q[0], q[1], q[2]]);
                        f.push([q[0], q[2], q[3]]);
                    }
                }
            }
        }
    }
    let x = x
        .iter()
        .map(|p| {
            DVec3::new(
                p.x + 0.15 * (1.3 * p.y).sin(),
                p.y + 0.1 * (0.9 * p.x + 0.5 * p.z).sin(),
                p.z * (1.0 + 0.2 * p.x) + 0.3 * (0.6 * p.x).sin() * (0.8 * p.y).cos(),
            )
        })
        .collect();
    (f, x)
}

/// An `n × n` sheet over `[0, 1]²`, jittered in the plane and bent.
pub fn sheet(n: usize) -> Mesh {
    let mut rng = SplitMix64::new(7);
    let idx = |i: usize, j: usize| (i * (n + 1) + j) as u32;
    let mut x = Vec::new();
    for i in 0..=n {
        for j in 0..=n {
            let inner = i > 0 && i < n && j > 0 && j < n;
            let h = 1.0 / n as f64;
            let (du, dv) = if inner {
                (0.3 * h * (rng.unit() - 0.5), 0.3 * h * (rng.unit() - 0.5))
            } else {
                (0.0, 0.0)
            };
            let (u, v) = (i as f64 * h + du, j as f64 * h + dv);
            let z = 0.15 * (2.0 * PI * u).sin() * (PI * v).cos() + 0.2 * u * v;
            x.push(DVec3::new(u, v, z));
        }
    }
    let mut f = Vec::new();
    for i in 0..n {
        for j in 0..n {
            let (a, b, c, d) = (idx(i, j), idx(i + 1, j), idx(i + 1, j + 1), idx(i, j + 1));
            if (i + j) % 2 == 0 {
                f.push([a, b, c]);
                f.push([a, c, d]);
            } else {
                f.push([a, b, d]);
                f.push([b, c, d]);
            }
        }
    }
    (f, x)
}

/// A synthetic flag the size of the fixture's (2.0 m × 1.2 m, 41 × 25 vertices, in the XZ
/// plane, pole at x = 0), a travelling wave growing from the pole, at time `t` (s).
pub fn flag(t: f64) -> Mesh {
    let (nx, nz) = (40usize, 24usize);
    let idx = |i: usize, j: usize| (i * (nz + 1) + j) as u32;
    let mut x = Vec::new();
    for i in 0..=nx {
        for j in 0..=nz {
            let (u, w) = (2.0 * i as f64 / nx as f64, 1.2 * j as f64 / nz as f64);
            let amp = 0.12 * u;
            let y = amp * (3.0 * u - 4.0 * t + 0.8 * w).sin();
            // the cloth shortens where it waves, roughly keeping its length
            let sag = -0.05 * u * u * (1.0 + (2.0 * t).sin()) * 0.5;
            x.push(DVec3::new(
                u - 0.02 * amp * (6.0 * u - 8.0 * t).cos(),
                y,
                w + sag,
            ));
        }
    }
    let mut f = Vec::new();
    for i in 0..nx {
        for j in 0..nz {
            let (a, b, c, d) = (idx(i, j), idx(i + 1, j), idx(i + 1, j + 1), idx(i, j + 1));
            f.push([a, b, c]);
            f.push([a, c, d]);
        }
    }
    (f, x)
}

/// Uniform noise of ±`corner_pct` % / ±`dihedral_pct` % of each angle's magnitude.
pub fn noisy(a: &Angles, corner_pct: f64, dihedral_pct: f64, seed: u64) -> Angles {
    let mut rng = SplitMix64::new(seed);
    let mut u = move || 2.0 * rng.unit() - 1.0;
    Angles {
        corners: a
            .corners
            .iter()
            .map(|c| c.map(|x| x * (1.0 + corner_pct / 100.0 * u())))
            .collect(),
        dihedrals: a
            .dihedrals
            .iter()
            .map(|x| x * (1.0 + dihedral_pct / 100.0 * u()))
            .collect(),
    }
}

/// The diagonal of the bounding box.
pub fn bbox_diagonal(x: &[DVec3]) -> f64 {
    let lo = x.iter().fold(DVec3::splat(f64::INFINITY), |a, b| a.min(*b));
    let hi = x
        .iter()
        .fold(DVec3::splat(f64::NEG_INFINITY), |a, b| a.max(*b));
    (hi - lo).length()
}

/// RMS distance from `reference` of `x` after the best similarity (rotation, translation,
/// scale) applied to `x`, over the bounding-box diagonal of `reference`.
pub fn procrustes_rms(x: &[DVec3], reference: &[DVec3]) -> f64 {
    let n = x.len() as f64;
    let cx = x.iter().copied().sum::<DVec3>() / n;
    let cy = reference.iter().copied().sum::<DVec3>() / n;
    let mut h = faer::Mat::<f64>::zeros(3, 3);
    let mut vx = 0.0;
    for (p, q) in x.iter().zip(reference) {
        let (p, q) = (*p - cx, *q - cy);
        vx += p.length_squared();
        for r in 0..3 {
            for c in 0..3 {
                h[(r, c)] += q[r] * p[c];
            }
        }
    }
    let svd = h.svd().unwrap();
    let (u, s, v) = (svd.U(), svd.S(), svd.V());
    let d = (u.determinant() * v.determinant()).signum();
    let dd = [1.0, 1.0, d];
    // R = U diag(dd) Vᵀ, scale = Σ σ dd / Σ|p|²
    let mut r = [[0.0; 3]; 3];
    for (i, row) in r.iter_mut().enumerate() {
        for (j, e) in row.iter_mut().enumerate() {
            *e = (0..3).map(|k| u[(i, k)] * dd[k] * v[(j, k)]).sum();
        }
    }
    let scale = (0..3).map(|k| s[k] * dd[k]).sum::<f64>() / vx;
    let mut err = 0.0;
    for (p, q) in x.iter().zip(reference) {
        let p = *p - cx;
        let rp = DVec3::new(
            r[0][0] * p.x + r[0][1] * p.y + r[0][2] * p.z,
            r[1][0] * p.x + r[1][1] * p.y + r[1][2] * p.z,
            r[2][0] * p.x + r[2][1] * p.y + r[2][2] * p.z,
        );
        err += (scale * rp + cy - *q).length_squared();
    }
    (err / n).sqrt() / bbox_diagonal(reference)
}

/// Max distance over the bounding-box diagonal, no alignment.
pub fn max_rel(x: &[DVec3], reference: &[DVec3]) -> f64 {
    x.iter()
        .zip(reference)
        .map(|(a, b)| (*a - *b).length())
        .fold(0.0, f64::max)
        / bbox_diagonal(reference)
}

/// Euler characteristic `V − E + F`.
pub fn euler(f: &[[u32; 3]], nv: usize) -> i64 {
    let mut edges = std::collections::HashSet::new();
    for t in f {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            edges.insert((a.min(b), a.max(b)));
        }
    }
    nv as i64 - edges.len() as i64 + f.len() as i64
}

/// A deforming cloth at time `t` (s): an `n × n` square sheet (side 1, `(n + 1)²` vertices)
/// rolled about an axis that turns with time, with a curvature that breathes (a
/// developable, hence isometric, bend), plus a small travelling ripple that stretches it
/// slightly: a smooth near-isometric motion.
pub fn cloth(n: usize, t: f64) -> Mesh {
    let idx = |i: usize, j: usize| (i * (n + 1) + j) as u32;
    let phi = 0.3 + 0.5 * t;
    let kappa = 2.0 * PI * 0.5 * (0.6 + 0.4 * (2.0 * t).sin());
    let (sp, cp) = phi.sin_cos();
    let mut x = Vec::with_capacity((n + 1) * (n + 1));
    for i in 0..=n {
        for j in 0..=n {
            let (u, v) = (i as f64 / n as f64 - 0.5, j as f64 / n as f64 - 0.5);
            let (s, w) = (cp * u + sp * v, -sp * u + cp * v);
            let (ks, kc) = (kappa * s).sin_cos();
            let ripple = 0.01 * (6.0 * u + 4.0 * v - 3.0 * t).sin();
            let (a, h) = (ks / kappa, (1.0 - kc) / kappa + ripple);
            x.push(DVec3::new(cp * a - sp * w, sp * a + cp * w, h));
        }
    }
    let mut f = Vec::with_capacity(2 * n * n);
    for i in 0..n {
        for j in 0..n {
            let (a, b, c, d) = (idx(i, j), idx(i + 1, j), idx(i + 1, j + 1), idx(i, j + 1));
            if (i + j) % 2 == 0 {
                f.extend([[a, b, c], [a, c, d]]);
            } else {
                f.extend([[a, b, d], [b, c, d]]);
            }
        }
    }
    (f, x)
}
