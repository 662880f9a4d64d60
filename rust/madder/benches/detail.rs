//! `make bench`: the cost of stain Detail (issue 12), side by side in one run on the
//! waving-flag grid of about 20k vertices: Detail 0 with the whole cloth wet against
//! Detail 2 with 10 % of the cloth wet (the fine wet region about 1.6× the cloth's
//! vertex count), per frame as the bake meets it (the cloth's positions in, the step,
//! the per-cloth-vertex read-outs out), and the memory the refined simulator takes
//! (resident set growth while it is built). Prints figures; asserts nothing about time.

mod common;

use std::time::Instant;

use common::{grid, motion, wave};
use faer::Par;
use glam::DVec3;
use madder::stain::{Conductivity, Detailed, StainParams};

/// Resident set size of this process, bytes (Linux; 0 elsewhere).
fn rss() -> usize {
    std::fs::read_to_string("/proc/self/statm")
        .ok()
        .and_then(|s| s.split_whitespace().nth(1)?.parse::<usize>().ok())
        .map_or(0, |pages| pages * 4096)
}

fn bench(level: u32, wet_fraction: f64, frames: usize) {
    let (topo, rest) = grid(181, 109); // 20 020 vertices on 2 × 1.2 m
    let n = topo.n_vertices();
    let dt = 1.0 / 24.0;
    let before = rss();
    let t = Instant::now();
    let mut sim = Detailed::new(
        topo,
        &rest,
        &wave(&rest, 0.0),
        Conductivity::Isotropic(2e-4),
        StainParams::default(),
        [0.4, 0.05, 0.1],
        level,
        Par::Seq,
    )
    .unwrap();
    let setup = t.elapsed().as_secs_f64() * 1e3;
    let grown = rss().saturating_sub(before);
    // a disk of `wet_fraction` of the cloth's area (2.4 m²), or all of it
    let radius = (wet_fraction * 2.4 / std::f64::consts::PI).sqrt();
    let centre = DVec3::new(1.0, 0.0, 0.6);
    let pour: Vec<f64> = rest
        .iter()
        .map(|p| {
            if wet_fraction >= 1.0 || p.distance(centre) < radius {
                1.0
            } else {
                0.0
            }
        })
        .collect();
    sim.add_liquid(&pour, 0.05, None).unwrap();
    let cloth = motion(&rest, frames, dt);
    let t = Instant::now();
    let mut read = 0.0;
    for f in 1..=frames {
        sim.step(&cloth[f], dt, Some(&cloth[f + 1])).unwrap();
        let r = Instant::now();
        std::hint::black_box((sim.solute_density(), sim.wetness(), sim.deposit()));
        read += r.elapsed().as_secs_f64();
    }
    let total = t.elapsed().as_secs_f64() * 1e3 / frames as f64;
    let p = sim.profile();
    let fine_n = sim.fine().topology().n_vertices();
    println!(
        "detail {level}, {:>3.0} % wet: {n} cloth vertices, {fine_n} simulated; {total:7.2} ms/frame (read-outs {:.2}), {:.0} active vertices per sub-step, setup {setup:.0} ms, memory +{:.0} MB ({:.0} bytes per simulated vertex)",
        100.0 * wet_fraction,
        read * 1e3 / frames as f64,
        p.active_vertices as f64 / p.substeps as f64,
        grown as f64 / 1e6,
        grown as f64 / fine_n as f64,
    );
    let per = |s: f64| s * 1e3 / frames as f64;
    println!(
        "    per frame: window {:.1}, geometry {:.1}, forces {:.1}, advection {:.1}, diffusion {:.1}, interactions {:.1} ms; {:.1} sub-steps, {:.1} transport cycles, {} window rebuilds",
        per(p.window),
        per(p.geometry),
        per(p.forces),
        per(p.advection),
        per(p.diffusion),
        per(p.interaction),
        p.substeps as f64 / frames as f64,
        p.transport_cycles as f64 / frames as f64,
        p.window_rebuilds
    );
}

fn main() {
    println!(
        "stain Detail on the waving flag, {} rayon threads",
        rayon::current_num_threads()
    );
    bench(0, 1.0, 12);
    bench(2, 0.1, 12);
}
