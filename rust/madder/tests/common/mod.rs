//! Test meshes and measurements shared by the integration tests (`mod common;`).
//!
//! - [`Grid`]: `n×n` quads over `[−half, half]²`. Vertex `(i, j)` (row `i` along y, column
//!   `j` along x) is `i·(n+1) + j` at `(−half + j·dx, −half + i·dx)`, `dx = 2·half/n`.
//!   Quad `(i, j)` has corners `a = (i, j)`, `b = (i, j+1)`, `c = (i+1, j+1)`,
//!   `d = (i+1, j)` and is split into `[a, b, c], [a, c, d]` ([`Split::Uniform`]) or, where
//!   `i + j` is odd, into `[a, b, d], [b, c, d]` ([`Split::Alternating`], the default);
//!   every face is counter-clockwise seen from +z. Interior vertices can be jittered by up
//!   to `±jitter/2 · dx` in x and y, from [`hash`] (or another hash); the
//!   border stays straight. Positions are `(x, y, 0)` or any `place(x, y)`.
//! - [`hash`] (and [`hash_unmixed_salt`]): deterministic pseudo-random numbers in [−½, ½).
//! - [`Built`]: one-rings, geometry, vertex frames and transport of a mesh.
//! - [`gaussian`], [`centroid`], [`covariance`]: a blob at every vertex and the mass-weighted
//!   moments of a field.
//! - [`sheet`]: a vertical `w × h` sheet in the XZ plane (runs, drips, drainage).
//! - [`no_interaction`], [`coffee_rates`], [`addon_look`]: parameters several tests share
//!   (the Coffee preset's rates, the look the add-on's presets give).

#![allow(dead_code)]

use std::f64::consts::PI;

use glam::{DVec2, DVec3};
use madder::mesh::{Geometry, OneRings, Topology, Transport, VertexFrames};
use madder::stain::{InteractionRates, StainParams, Wicking};

/// Deterministic pseudo-random number in [−½, ½) for key `k` and stream `salt`.
pub fn hash(k: usize, salt: u64) -> f64 {
    finish(
        (k as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ salt.wrapping_mul(0xD6E8_FEB8_6659_FD93),
    )
}

/// [`hash`] with the salt xored in without mixing: another fixed stream, kept because the
/// diffusion tests' jittered meshes are drawn from it.
pub fn hash_unmixed_salt(k: usize, salt: u64) -> f64 {
    finish((k as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ salt)
}

fn finish(mut x: u64) -> f64 {
    x ^= x >> 31;
    x = x.wrapping_mul(0xBF58_476D_1CE4_E5B9);
    x ^= x >> 29;
    (x >> 11) as f64 / (1u64 << 53) as f64 - 0.5
}

/// How a [`Grid`] splits its quads into triangles.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Split {
    /// Along alternating diagonals (`a–c` where `i + j` is even, `b–d` where it is odd).
    Alternating,
    /// Every quad along its `a–c` diagonal.
    Uniform,
}

/// A grid of `n×n` quads over `[−half, half]²` (see the module doc for the layout).
#[derive(Clone, Copy)]
pub struct Grid {
    n: usize,
    half: f64,
    jitter: f64,
    hash: fn(usize, u64) -> f64,
    split: Split,
}

impl Grid {
    /// Regular grid, quads split along alternating diagonals.
    pub fn new(n: usize, half: f64) -> Self {
        Grid {
            n,
            half,
            jitter: 0.0,
            hash,
            split: Split::Alternating,
        }
    }

    /// Moves interior vertex `k` by `(hash(k, 1), hash(k, 2)) · jitter · dx`.
    pub fn jitter(self, jitter: f64) -> Self {
        self.jitter_with(jitter, hash)
    }

    /// [`Grid::jitter`] with the numbers drawn from `hash` instead.
    pub fn jitter_with(self, jitter: f64, hash: fn(usize, u64) -> f64) -> Self {
        Grid {
            jitter,
            hash,
            ..self
        }
    }

    pub fn split(self, split: Split) -> Self {
        Grid { split, ..self }
    }

    /// Index of vertex `(i, j)`: row `i` along y, column `j` along x.
    pub fn index(&self, i: usize, j: usize) -> u32 {
        (i * (self.n + 1) + j) as u32
    }

    pub fn faces(&self) -> Vec<[u32; 3]> {
        let n = self.n;
        let mut faces = Vec::with_capacity(2 * n * n);
        for i in 0..n {
            for j in 0..n {
                let (a, b) = (self.index(i, j), self.index(i, j + 1));
                let (c, d) = (self.index(i + 1, j + 1), self.index(i + 1, j));
                if self.split == Split::Uniform || (i + j) % 2 == 0 {
                    faces.extend([[a, b, c], [a, c, d]]);
                } else {
                    faces.extend([[a, b, d], [b, c, d]]);
                }
            }
        }
        faces
    }

    /// `place(x, y)` at every (jittered) grid point, in vertex order.
    pub fn positions(&self, place: impl Fn(f64, f64) -> DVec3) -> Vec<DVec3> {
        let (n, half) = (self.n, self.half);
        let dx = 2.0 * half / n as f64;
        let mut pos = Vec::with_capacity((n + 1) * (n + 1));
        for i in 0..=n {
            for j in 0..=n {
                let interior = i > 0 && j > 0 && i < n && j < n;
                let k = i * (n + 1) + j;
                let (jx, jy) = if interior && self.jitter != 0.0 {
                    (
                        (self.hash)(k, 1) * self.jitter,
                        (self.hash)(k, 2) * self.jitter,
                    )
                } else {
                    (0.0, 0.0)
                };
                let (x, y) = (-half + (j as f64 + jx) * dx, -half + (i as f64 + jy) * dx);
                pos.push(place(x, y));
            }
        }
        pos
    }

    /// Faces and flat positions `(x, y, 0)`, before building a topology.
    pub fn arrays(&self) -> (Vec<[u32; 3]>, Vec<DVec3>) {
        (self.faces(), self.positions(|x, y| DVec3::new(x, y, 0.0)))
    }

    /// Flat mesh, positions `(x, y, 0)`.
    pub fn build(&self) -> (Topology, Vec<DVec3>) {
        self.build_with(|x, y| DVec3::new(x, y, 0.0))
    }

    /// Mesh with positions `place(x, y)`.
    pub fn build_with(&self, place: impl Fn(f64, f64) -> DVec3) -> (Topology, Vec<DVec3>) {
        let pos = self.positions(place);
        (
            Topology::from_triangles(pos.len(), self.faces()).unwrap(),
            pos,
        )
    }
}

/// The per-mesh structures of the transport: one-rings, geometry, frames, transport.
pub struct Built {
    pub rings: OneRings,
    pub geometry: Geometry,
    pub frames: VertexFrames,
    pub transport: Transport,
}

/// [`Built`] with the default vertex frames of `p`.
pub fn build(t: &Topology, p: &[DVec3]) -> Built {
    let rings = OneRings::new(t);
    let frames = VertexFrames::new(&rings, p).unwrap();
    build_with(t, p, rings, frames)
}

/// [`Built`] with the given one-rings and frames.
pub fn build_with(t: &Topology, p: &[DVec3], rings: OneRings, frames: VertexFrames) -> Built {
    let geometry = Geometry::new(t, p).unwrap();
    let transport = Transport::new(t, &rings, &geometry, &frames, p);
    Built {
        rings,
        geometry,
        frames,
        transport,
    }
}

/// `amp · exp(−|p − c|²/(2 var))` at every point (distance in the XY plane).
pub fn gaussian(points: &[DVec3], c: DVec2, var: f64, amp: f64) -> Vec<f64> {
    points
        .iter()
        .map(|p| amp * (-(p.truncate() - c).length_squared() / (2.0 * var)).exp())
        .collect()
}

/// Mass-weighted centroid of `points` (one per vertex).
pub fn centroid(mass: &[f64], points: &[DVec3]) -> DVec3 {
    let total: f64 = mass.iter().sum();
    mass.iter().zip(points).map(|(m, p)| *m * *p).sum::<DVec3>() / total
}

/// Mass-weighted 2×2 covariance `[xx, xy, yy]` of the XY coordinates about the centroid.
pub fn covariance(mass: &[f64], points: &[DVec3]) -> [f64; 3] {
    let c = centroid(mass, points);
    let total: f64 = mass.iter().sum();
    let mut v = [0.0; 3];
    for (m, p) in mass.iter().zip(points) {
        let d = *p - c;
        v[0] += m * d.x * d.x;
        v[1] += m * d.x * d.y;
        v[2] += m * d.y * d.y;
    }
    v.map(|x| x / total)
}

/// A polar disk of `rings` rings (ring `k` has `6k` vertices at radius `k/rings · radius`)
/// in the XY plane, neighbouring rings zipped together by angle.
pub fn disk(rings: usize, radius: f64) -> (Topology, Vec<DVec3>) {
    let mut pos = vec![DVec3::ZERO];
    let mut ring_ids: Vec<Vec<(u32, f64)>> = vec![vec![(0, 0.0)]];
    for k in 1..=rings {
        let r = radius * k as f64 / rings as f64;
        let m = 6 * k;
        let mut ids = Vec::with_capacity(m);
        for j in 0..m {
            let a = 2.0 * PI * j as f64 / m as f64;
            ids.push((pos.len() as u32, a));
            pos.push(DVec3::new(r * a.cos(), r * a.sin(), 0.0));
        }
        ring_ids.push(ids);
    }
    let mut faces = Vec::new();
    let first = &ring_ids[1];
    for j in 0..first.len() {
        faces.push([0, first[j].0, first[(j + 1) % first.len()].0]);
    }
    for k in 2..=rings {
        let (inner, outer) = (&ring_ids[k - 1], &ring_ids[k]);
        let (ni, no) = (inner.len(), outer.len());
        let angle = |ring: &[(u32, f64)], i: usize| {
            if i >= ring.len() {
                ring[i % ring.len()].1 + 2.0 * PI
            } else {
                ring[i].1
            }
        };
        let (mut i, mut j) = (0, 0);
        while i < ni || j < no {
            let advance_outer = j < no && (i == ni || angle(outer, j + 1) <= angle(inner, i + 1));
            if advance_outer {
                faces.push([inner[i % ni].0, outer[j].0, outer[(j + 1) % no].0]);
                j += 1;
            } else {
                faces.push([inner[i].0, outer[j % no].0, inner[(i + 1) % ni].0]);
                i += 1;
            }
        }
    }
    (Topology::from_triangles(pos.len(), faces).unwrap(), pos)
}

/// `points` turned by `angle` about the z axis (a disk spinning in its plane).
pub fn spun(points: &[DVec3], angle: f64) -> Vec<DVec3> {
    let (s, c) = angle.sin_cos();
    points
        .iter()
        .map(|p| DVec3::new(c * p.x - s * p.y, s * p.x + c * p.y, p.z))
        .collect()
}

/// No absorption, adsorption or evaporation.
pub fn no_interaction() -> InteractionRates {
    InteractionRates {
        absorption: 0.0,
        saturation: 0.0,
        adsorption: 0.0,
        capacity: 0.0,
        evaporation: 0.0,
        evaporation_boundary: 1.0,
    }
}

/// The Coffee preset's rates (addon/presets.py).
pub fn coffee_rates() -> InteractionRates {
    InteractionRates {
        absorption: 2.0,
        saturation: 0.1,
        adsorption: 0.05,
        capacity: 2e-4,
        evaporation: 5e-5,
        evaporation_boundary: 1.5,
    }
}

/// What the add-on's liquid presets give beside a liquid's rates and rim
/// (addon/presets.py): Wicking 2 with two Picard rounds and on until the front settles
/// (10⁻³), the run holdup of 0.05 kg/m², and its First Step, `first_substep` (0: off).
pub fn addon_look(first_substep: f64) -> StainParams {
    StainParams {
        wicking: Wicking {
            exponent: 2.0,
            density: 0.1,
            picard: 2,
            tolerance: 1e-3,
        },
        holdup: 0.05,
        first_substep,
        ..Default::default()
    }
}

/// A vertical sheet (issue 34 §1): `w × h` m in the XZ plane at spacing `dx`, vertex
/// `j·(nu+1) + i` at `(i dx, 0, j dx)`, quads split along alternating diagonals (no
/// preferred diagonal for the run to follow).
pub fn sheet(w: f64, h: f64, dx: f64) -> (Topology, Vec<DVec3>, usize) {
    let (nu, nv) = ((w / dx).round() as usize, (h / dx).round() as usize);
    let row = nu + 1;
    let pos = (0..=nv)
        .flat_map(|j| (0..=nu).map(move |i| DVec3::new(dx * i as f64, 0.0, dx * j as f64)))
        .collect();
    let mut faces = Vec::new();
    for j in 0..nv {
        for i in 0..nu {
            let a = (j * row + i) as u32;
            let (b, c, d) = (a + 1, a + 1 + row as u32, a + row as u32);
            if (i + j) % 2 == 0 {
                faces.push([a, b, c]);
                faces.push([a, c, d]);
            } else {
                faces.push([a, b, d]);
                faces.push([b, c, d]);
            }
        }
    }
    (
        Topology::from_triangles(row * (nv + 1), faces).unwrap(),
        pos,
        row,
    )
}
