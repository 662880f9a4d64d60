//! The waving-flag grid shared by the benchmarks.

use glam::DVec3;
use madder::mesh::Topology;

pub fn grid(nx: usize, ny: usize) -> (Topology, Vec<DVec3>) {
    let idx = |i: usize, j: usize| (i * (nx + 1) + j) as u32;
    let mut faces = Vec::with_capacity(2 * nx * ny);
    for i in 0..ny {
        for j in 0..nx {
            let (a, b, c, d) = (idx(i, j), idx(i, j + 1), idx(i + 1, j + 1), idx(i + 1, j));
            faces.extend([[a, b, c], [a, c, d]]);
        }
    }
    let pos = (0..=ny)
        .flat_map(|i| {
            (0..=nx).map(move |j| {
                DVec3::new(2.0 * j as f64 / nx as f64, 0.0, 1.2 * i as f64 / ny as f64)
            })
        })
        .collect();
    (
        Topology::from_triangles((nx + 1) * (ny + 1), faces).unwrap(),
        pos,
    )
}

/// The flag waving: a travelling wave across the cloth, pinned at x = 0.
pub fn wave(rest: &[DVec3], t: f64) -> Vec<DVec3> {
    rest.iter()
        .map(|p| DVec3::new(p.x, 0.15 * p.x * (4.0 * p.x - 6.0 * t).sin(), p.z))
        .collect()
}

/// The benchmarks' pour: a Gaussian splash of 2 kg/m² at the peak, up on the flag.
#[allow(dead_code)] // not every bench pours it
pub fn pour(rest: &[DVec3]) -> Vec<f64> {
    rest.iter()
        .map(|p| 2.0 * (-(p.distance_squared(DVec3::new(1.0, 0.0, 0.8))) / 0.02).exp())
        .collect()
}

/// The cloth at frames `0 ..= frames + 1` of `dt` (computed before timing: only the
/// stain's step is timed).
#[allow(dead_code)]
pub fn motion(rest: &[DVec3], frames: usize, dt: f64) -> Vec<Vec<DVec3>> {
    (0..=frames + 1)
        .map(|f| wave(rest, f as f64 * dt))
        .collect()
}
