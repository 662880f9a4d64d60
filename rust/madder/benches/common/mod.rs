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
