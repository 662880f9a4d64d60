//! `make bench`: time per frame of the full stain simulator (forces, advection, diffusion
//! of the densities and of the velocity, interactions) on a waving-flag grid, split into
//! its phases. Prints figures; asserts nothing about time.

use std::time::Instant;

use faer::Par;
use glam::DVec3;
use madder::mesh::Topology;
use madder::stain::{Conductivity, Simulator, StainParams};

fn grid(nx: usize, ny: usize) -> (Topology, Vec<DVec3>) {
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
fn wave(rest: &[DVec3], t: f64) -> Vec<DVec3> {
    rest.iter()
        .map(|p| DVec3::new(p.x, 0.15 * p.x * (4.0 * p.x - 6.0 * t).sin(), p.z))
        .collect()
}

fn bench(nx: usize, ny: usize, frames: usize) {
    let (topo, rest) = grid(nx, ny);
    let n = topo.n_vertices();
    let dt = 1.0 / 24.0;
    let t = Instant::now();
    let mut sim = Simulator::new(
        topo,
        &rest,
        &wave(&rest, 0.0),
        Conductivity::Isotropic(0.002),
        StainParams::default(),
        [0.4, 0.05, 0.1],
        Par::Seq,
    )
    .unwrap();
    let setup = t.elapsed().as_secs_f64() * 1e3;
    let pour: Vec<f64> = rest
        .iter()
        .map(|p| 2.0 * (-(p.distance_squared(DVec3::new(1.0, 0.0, 0.8))) / 0.02).exp())
        .collect();
    sim.add_liquid(&pour, 0.05, None).unwrap();
    let t = Instant::now();
    for f in 1..=frames {
        let after = wave(&rest, (f + 1) as f64 * dt);
        sim.step(&wave(&rest, f as f64 * dt), dt, Some(&after)).unwrap();
    }
    let total = t.elapsed().as_secs_f64() * 1e3 / frames as f64;
    let p = sim.profile();
    let per = |s: f64| s * 1e3 / frames as f64;
    println!(
        "{n:>7} vertices, {frames} frames: {total:7.2} ms/frame (setup {setup:.0} ms) = geometry+frames+connection {:.2}, forces {:.2}, advection {:.2}, density diffusion {:.2}, velocity diffusion {:.2}, interactions {:.2}",
        per(p.geometry),
        per(p.forces),
        per(p.advection),
        per(p.diffusion),
        per(p.viscosity),
        per(p.interaction),
    );
}

fn main() {
    println!(
        "full stain simulator on a waving flag grid, {} rayon threads (1 sub-step per frame, all physics on)",
        rayon::current_num_threads()
    );
    bench(127, 77, 48); // ≈ 10k vertices
    bench(407, 245, 12); // ≈ 100k vertices
}
