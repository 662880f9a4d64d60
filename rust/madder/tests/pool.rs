//! Validation of a spill laid as a pool (issue 34, `Detailed::add_pool`) against exact
//! results:
//!
//! 1. a cosine bump of weights on a fine cloth pools into the disc that holds its mass at
//!    the full depth, `πr² = ∫ w dA = πR²(1/2 − 2/π²)`, with the mass `a Σ w_i A_i` to
//!    rounding, one vertex filled in part, nothing laid beyond the weights, and no dry
//!    vertex more than a cell and a half inside its edge;
//! 2. on a coarse cloth refined by Detail, a painted 3 × 3 patch pools round, not into the
//!    square its linear interpolant's level sets make (the 4-fold Fourier term of the
//!    pool's outline r(θ) against the square's), with the same mass, inside the weights'
//!    reach, on the fine vertices;
//! 3. weights outside [0, 1] or a negative amount are refused, naming the vertex; no
//!    weight or no amount pours nothing.

use std::f64::consts::PI;

use faer::Par;
use glam::DVec3;
use madder::mesh::{Refinement, Topology};
use madder::stain::{Conductivity, Detailed, StainParams};
use madder::{Error, ParamError};

mod common;
use common::Grid;

fn simulator(topo: &Topology, rest: &[DVec3], level: u32) -> Detailed {
    Detailed::new(
        topo.clone(),
        rest,
        rest,
        Conductivity::Isotropic(2e-4),
        StainParams::default(),
        [0.5, 0.1, 0.1],
        level,
        Par::Seq,
    )
    .unwrap()
}

/// The `k`-fold Fourier term of the outline `r(θ)` of the `wet` points around their
/// centroid (the farthest wet point in each of 64 angular bins), relative to its mean.
fn fourier(points: &[DVec3], wet: &[bool], k: f64) -> f64 {
    let inside: Vec<DVec3> = points
        .iter()
        .zip(wet)
        .filter(|(_, w)| **w)
        .map(|(p, _)| *p)
        .collect();
    let c = inside.iter().sum::<DVec3>() / inside.len() as f64;
    let bins = 64;
    let mut r = vec![0.0f64; bins];
    for p in &inside {
        let d = *p - c;
        let b = (((d.y.atan2(d.x) + PI) / (2.0 * PI) * bins as f64) as usize).min(bins - 1);
        r[b] = r[b].max(d.length());
    }
    let mean = r.iter().sum::<f64>() / bins as f64;
    let (mut re, mut im) = (0.0, 0.0);
    for (b, rb) in r.iter().enumerate() {
        let t = (b as f64 + 0.5) / bins as f64 * 2.0 * PI - PI;
        re += rb * (k * t).cos();
        im += rb * (k * t).sin();
    }
    2.0 * re.hypot(im) / bins as f64 / mean
}

#[test]
fn a_cosine_bump_pools_into_the_disc_that_holds_its_mass() {
    let (n, half, radius, amount) = (120, 0.1, 0.08, 1.2);
    let (topo, rest) = Grid::new(n, half).build();
    let w: Vec<f64> = rest
        .iter()
        .map(|p| {
            let r = p.truncate().length();
            if r < radius {
                0.5 * (1.0 + (PI * r / radius).cos())
            } else {
                0.0
            }
        })
        .collect();
    let mut sim = simulator(&topo, &rest, 0);
    let area = sim.vertex_area().to_vec();
    sim.add_pool(&w, amount, 0.05, None).unwrap();
    let mass: f64 = w.iter().zip(&area).map(|(w, a)| amount * w * a).sum();
    assert!((sim.totals().solvent - mass).abs() < 1e-12 * mass);
    let laid = sim.wetness();
    let full = laid.iter().filter(|&&d| (d - amount).abs() < 1e-12).count();
    let wet = laid.iter().filter(|&&d| d > 0.0).count();
    assert!(wet - full <= 1, "{} vertices filled in part", wet - full);
    // the disc of the bump's mass: r = R √(1/2 − 2/π²)
    let edge = rest
        .iter()
        .zip(&laid)
        .filter(|(_, d)| **d > 0.0)
        .map(|(p, _)| p.length())
        .fold(0.0, f64::max);
    let expect = radius * (0.5 - 2.0 / (PI * PI)).sqrt();
    eprintln!("cosine bump's pool: radius {edge:.5} m against {expect:.5} m");
    assert!(
        (edge / expect - 1.0).abs() < 0.03,
        "pool radius {edge} against {expect}"
    );
    // only where the weights reach, and round: no wet vertex beyond the edge's radius
    // by more than a cell, no dry one inside by more than a cell
    let dx = 2.0 * half / n as f64;
    for ((p, d), wi) in rest.iter().zip(&laid).zip(&w) {
        assert!(*d == 0.0 || *wi > 0.0);
        if *d == 0.0 {
            assert!(
                p.length() > edge - 1.5 * dx,
                "a dry vertex at {} inside the pool",
                p.length()
            );
        }
    }
}

#[test]
fn a_painted_patch_on_a_coarse_cloth_pools_round_on_the_refined_vertices() {
    // a 5 cm grid (the flag's), the 3 × 3 vertices at its centre painted 1, Detail 3
    let (n, half, level, amount) = (10, 0.25, 3, 1.2);
    let grid = Grid::new(n, half);
    let (topo, rest) = grid.build();
    let mut w = vec![0.0; rest.len()];
    for i in 4..=6 {
        for j in 4..=6 {
            w[grid.index(i, j) as usize] = 1.0;
        }
    }
    let mut sim = simulator(&topo, &rest, level);
    let area = sim.vertex_area().to_vec();
    sim.add_pool(&w, amount, 0.05, None).unwrap();
    let mass: f64 = w.iter().zip(&area).map(|(w, a)| amount * w * a).sum();
    assert!((sim.totals().solvent - mass).abs() < 1e-12 * mass);
    let refined = Refinement::new(&topo, level).unwrap();
    let points = refined.prolong(&rest);
    let reach = refined.prolong(&w);
    let laid = sim.fine_wetness();
    let wet: Vec<bool> = laid.iter().map(|&d| d > 0.0).collect();
    assert!(
        wet.iter().zip(&reach).all(|(&wet, &r)| !wet || r > 0.0),
        "laid beyond the weights' reach"
    );
    // it is laid on the fine vertices: far more of them wet than the cloth's 9
    assert!(wet.iter().filter(|&&x| x).count() > 9 * 16);
    // the linear interpolant's top region of the same area: the square-ish outline that
    // a pool of the interpolated weights would have
    let cell = area[grid.index(5, 5) as usize] / 64.0;
    let mut order: Vec<usize> = (0..points.len()).filter(|&j| reach[j] > 0.0).collect();
    order.sort_by(|&j, &k| reach[k].total_cmp(&reach[j]).then(j.cmp(&k)));
    let mut square = vec![false; points.len()];
    for &j in order.iter().take((mass / amount / cell).round() as usize) {
        square[j] = true;
    }
    let (round, squared) = (fourier(&points, &wet, 4.0), fourier(&points, &square, 4.0));
    eprintln!("pool outline, 4-fold term: {round:.4} (the interpolant's {squared:.4})");
    assert!(
        squared > 0.08,
        "the interpolant's outline: 4-fold term {squared}"
    );
    assert!(
        round < 0.4 * squared,
        "the pool's 4-fold term {round} against the interpolant's {squared}"
    );
}

#[test]
fn bad_pool_input_is_refused_naming_the_vertex() {
    let (topo, rest) = Grid::new(4, 0.1).build();
    let mut sim = simulator(&topo, &rest, 1);
    let mut w = vec![0.0; rest.len()];
    w[7] = 1.5;
    match sim.add_pool(&w, 1.0, 0.05, None) {
        Err(Error::Param(ParamError::OutOfRangeAt { index: 7, .. })) => {}
        other => panic!("weight 1.5 at vertex 7: {other:?}"),
    }
    w[7] = 1.0;
    assert!(matches!(
        sim.add_pool(&w, -1.0, 0.05, None),
        Err(Error::Param(ParamError::OutOfRange { .. }))
    ));
    assert!(matches!(
        sim.add_pool(&w[1..], 1.0, 0.05, None),
        Err(Error::Param(ParamError::Length { .. }))
    ));
    sim.add_pool(&vec![0.0; rest.len()], 1.0, 0.05, None)
        .unwrap();
    sim.add_pool(&w, 0.0, 0.05, None).unwrap();
    assert_eq!(sim.totals().solvent, 0.0);
}
