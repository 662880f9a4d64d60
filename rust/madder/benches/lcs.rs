//! `make bench`: FTLE and ridges (`madder::lcs`, seed ch. 5). Prints figures; asserts
//! nothing about time.
//!
//! - the double gyre (A = 0.1, ε = 0.25, ω = 0.2π) on a 401×201-vertex triangulated grid of
//!   [0, 2] × [0, 1], T = −10: flow map + FTLE, then ridges;
//! - FTLE and ridges on a ≈100k-vertex mesh (a 447×223-cell grid, the same flow), flat
//!   (the flat fast path of `lcs::planar`) and rolled into a half cylinder (curved: every
//!   stage point walked across the triangles).

use std::f64::consts::PI;
use std::time::Instant;

use glam::{DVec2, DVec3};
use madder::lcs::{FnVelocity, Motion, RidgeOptions, Scheme, ftle_with, ridges};
use madder::mesh::Topology;

mod common;

fn double_gyre(t: f64, p: DVec2) -> DVec2 {
    let (amp, eps, omega) = (0.1, 0.25, 0.2 * PI);
    let a = eps * (omega * t).sin();
    let b = 1.0 - 2.0 * a;
    let f = a * p.x * p.x + b * p.x;
    let df = 2.0 * a * p.x + b;
    DVec2::new(
        -PI * amp * (PI * f).sin() * (PI * p.y).cos(),
        PI * amp * (PI * f).cos() * (PI * p.y).sin() * df,
    )
}

/// The benches' grid of `nx × ny` cells (`common::grid`, upright in x–z) laid flat over
/// [0, 2] × [0, 1].
fn grid(nx: usize, ny: usize) -> (Topology, Vec<DVec3>) {
    let (topo, p) = common::grid(nx, ny);
    let flat = p.iter().map(|q| DVec3::new(q.x, q.z / 1.2, 0.0)).collect();
    (topo, flat)
}

/// The same grid rolled into a half cylinder around the x axis (circumference 2 per turn,
/// so the roll is an isometry and the FTLE is the flat one): a curved mesh, which walks.
fn roll(p: &[DVec3]) -> Vec<DVec3> {
    let r = 1.0 / PI;
    p.iter()
        .map(|q| DVec3::new(q.x, r * (PI * q.y).cos(), r * (PI * q.y).sin()))
        .collect()
}

/// The gyre on the rolled grid: the flat velocity pushed forward by the roll.
fn rolled_gyre(t: f64, x: DVec3) -> DVec3 {
    let theta = x.z.atan2(x.y);
    let v = double_gyre(t, DVec2::new(x.x, theta / PI));
    DVec3::new(v.x, -v.y * theta.sin(), v.y * theta.cos())
}

/// CPU seconds of this process so far (all threads; `/proc/self/stat`, Linux): on a
/// shared machine the wall time varies with the other jobs, the CPU time much less.
fn cpu_seconds() -> f64 {
    let stat = std::fs::read_to_string("/proc/self/stat").unwrap_or_default();
    let after = stat.rsplit(')').next().unwrap_or("");
    let f: Vec<f64> = after
        .split_whitespace()
        .map(|x| x.parse().unwrap_or(0.0))
        .collect();
    // utime, stime: fields 14, 15 of the line (11, 12 after the command name), in ticks
    f.get(11)
        .zip(f.get(12))
        .map_or(0.0, |(u, s)| (u + s) / 100.0)
}

fn case(label: &str, nx: usize, ny: usize, (scheme, steps): (Scheme, usize), rolled: bool) {
    let (topo, flat) = grid(nx, ny);
    let p = if rolled { roll(&flat) } else { flat };
    let flow = move |t, x: DVec3| {
        if rolled {
            rolled_gyre(t, x)
        } else {
            double_gyre(t, x.truncate()).extend(0.0)
        }
    };
    let mut v = FnVelocity(flow);
    let (t, c) = (Instant::now(), cpu_seconds());
    let motion = Motion::fixed(p.clone());
    let s = ftle_with(&topo, &motion, &mut v, 0.0, -10.0, scheme, steps).unwrap();
    let (t_ftle, c_ftle) = (t.elapsed().as_secs_f64(), cpu_seconds() - c);
    // MADDER_LCS_DUMP=DIR writes σ (raw little-endian f64) per case, to compare versions
    if let Ok(dir) = std::env::var("MADDER_LCS_DUMP") {
        let name: String = label
            .chars()
            .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
            .collect();
        let bytes: Vec<u8> = s.iter().flat_map(|x| x.to_le_bytes()).collect();
        std::fs::write(format!("{dir}/{name}-{scheme:?}-{steps}.f64"), bytes).expect("dump σ");
    }
    let (t, c) = (Instant::now(), cpu_seconds());
    let r = ridges(&topo, &p, &s, &RidgeOptions::default()).unwrap();
    let (t_ridges, c_ridges) = (t.elapsed().as_secs_f64(), cpu_seconds() - c);
    println!(
        "{label}: {} vertices, {scheme:?} × {steps} steps: flow map + FTLE {:.3} s (CPU {:.2} s), ridges {:.3} s (CPU {:.2} s; {} points, {} edges), total {:.3} s",
        topo.n_vertices(),
        t_ftle,
        c_ftle,
        t_ridges,
        c_ridges,
        r.points.len(),
        r.edges.len(),
        t_ftle + t_ridges
    );
}

fn main() {
    // `cargo bench -p madder --bench lcs -- curved` runs the curved case only
    let only_curved = std::env::args().any(|a| a == "curved");
    println!(
        "FTLE + ridges of the double gyre, T = −10, {} rayon threads",
        rayon::current_num_threads()
    );
    // integration errors of the gyre at 401×201 (tests/bench/bench_numbacs.py): RK4 × 25
    // steps 9e-5 of the range, RK8 × 6 1.4e-4, both under numbacs' 1.8e-4 at rtol 1e-4;
    // RK4 × 100 4e-7 against 1.5e-6 at rtol 1e-6
    let runs = [(Scheme::Rk4, 100), (Scheme::Rk4, 25), (Scheme::Rk8, 6)];
    for run in runs {
        if only_curved {
            break;
        }
        case("double gyre 401×201, flat", 400, 200, run, false);
        case("100k-vertex grid, flat", 447, 223, run, false);
    }
    for run in &runs[1..] {
        case(
            "100k-vertex grid rolled into a half cylinder",
            447,
            223,
            *run,
            true,
        );
    }
}
