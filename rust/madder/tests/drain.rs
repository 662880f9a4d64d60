//! Gravity in the fibres' liquid (`stain::drain`, issue 34 §1): a vertical strip of
//! fabric holding some liquid settles into capillary equilibrium. Where the flux
//! `−D(θ)∇σ + σ_w D(θ) ĝ / H` vanishes, `∂θ/∂z = −1/H` whatever the wicking's rate and
//! exponent, so the liquid lies in a wedge `θ(z) = θ₀ − z/H` from the strip's bottom up to
//! `θ₀ H`, with `θ₀ = √(2 m / (σ_w H))` for `m` the liquid per metre of the strip's width
//! over `σ_w` (kg/m over kg/m²) — Richards' equation's hydrostatic profile with a linear
//! retention, exact. Without the capillary height the same liquid spreads evenly up the
//! whole strip.

use faer::Par;
use glam::DVec3;
use madder::mesh::Topology;
use madder::stain::{Conductivity, InteractionRates, Simulator, StainParams, Wicking};

mod common;
use common::sheet;

const COLS: usize = 8; // 2 cm wide
const ROWS: usize = 48; // 12 cm tall
const CELL: f64 = 2.5e-3;
const H: f64 = 0.05; // the capillary height, m
const SIGMA_W: f64 = 0.1; // kg/m², the saturation
const THETA: f64 = 0.1; // the liquid poured, as a saturation over the whole strip

/// The strip hanging in the XZ plane, bottom at z = 0 (`COLS × ROWS` cells).
fn strip() -> (Topology, Vec<DVec3>) {
    let (topo, pos, _) = sheet(COLS as f64 * CELL, ROWS as f64 * CELL, CELL);
    (topo, pos)
}

fn params(capillary_height: f64) -> StainParams {
    StainParams {
        wicking: Wicking {
            exponent: 2.0,
            density: SIGMA_W,
            picard: 2,
            tolerance: 1e-3,
        },
        interaction: InteractionRates {
            absorption: 2.0,
            saturation: SIGMA_W,
            adsorption: 0.0,
            capacity: 0.0,
            evaporation: 0.0,
            evaporation_boundary: 1.0,
        },
        carry_solute: true,
        capillary_height,
        // the whole strip active: the fibres' liquid moves only in the window's active
        // region (around free liquid), and this one is all absorbed within seconds
        active_region: false,
        ..Default::default()
    }
}

/// The strip wetted evenly at `THETA` and left `seconds`: per row (bottom first) the
/// liquid's saturation, the total liquid before and after, and the concentrations of the
/// fibres' liquid.
fn settle(capillary_height: f64, seconds: usize) -> (Vec<f64>, f64, f64, Vec<f64>) {
    let (topo, pos) = strip();
    let mut sim = Simulator::new(
        topo,
        &pos,
        &pos,
        Conductivity::Isotropic(2e-4),
        params(capillary_height),
        [0.4, 0.05, 0.1],
        Par::Seq,
    )
    .unwrap();
    let total = |sim: &Simulator| {
        let f = sim.fields();
        f.free_solvent
            .iter()
            .chain(&f.absorbed_solvent)
            .sum::<f64>()
    };
    sim.add_liquid(&vec![THETA * SIGMA_W; pos.len()], 0.02, None)
        .unwrap();
    let before = total(&sim);
    for _ in 0..seconds {
        sim.step(&pos, 1.0, Some(&pos)).unwrap();
    }
    let (f, area) = (sim.fields(), sim.vertex_area());
    let rows = (0..=ROWS)
        .map(|i| {
            let k = i * (COLS + 1)..(i + 1) * (COLS + 1);
            let m: f64 = k
                .clone()
                .map(|v| f.free_solvent[v] + f.absorbed_solvent[v])
                .sum();
            m / (k.map(|v| area[v]).sum::<f64>() * SIGMA_W)
        })
        .collect();
    let concentration = (0..pos.len())
        .filter(|&v| f.absorbed_solvent[v] > 1e-3 * SIGMA_W * area[v])
        .map(|v| f.absorbed_solute[v] / f.absorbed_solvent[v])
        .collect();
    (rows, before, total(&sim), concentration)
}

#[test]
fn a_hanging_strip_settles_into_the_capillary_wedge() {
    let (theta, before, after, concentration) = settle(H, 600);
    // the exact wedge: m = THETA × the strip's height, per unit width, over σ_w
    let height = ROWS as f64 * CELL;
    let theta0 = (2.0 * THETA * height / H).sqrt();
    let exact = |i: usize| (theta0 - i as f64 * CELL / H).max(0.0);
    let (mut sq, mut count) = (0.0, 0);
    for (i, &t) in theta.iter().enumerate() {
        if exact(i) > 0.15 {
            sq += (t - exact(i)).powi(2);
            count += 1;
        }
    }
    let rms = (sq / count as f64).sqrt();
    // the wedge's slope, fitted over the same rows: −1/H
    let rows: Vec<(f64, f64)> = (0..theta.len())
        .filter(|&i| exact(i) > 0.15)
        .map(|i| (i as f64 * CELL, theta[i]))
        .collect();
    let (mz, mt) = rows
        .iter()
        .fold((0.0, 0.0), |(a, b), &(z, t)| (a + z, b + t));
    let (mz, mt) = (mz / rows.len() as f64, mt / rows.len() as f64);
    let slope = rows.iter().map(|&(z, t)| (z - mz) * (t - mt)).sum::<f64>()
        / rows.iter().map(|&(z, _)| (z - mz).powi(2)).sum::<f64>();
    let top = theta.iter().rposition(|&t| t > 0.05).unwrap() as f64 * CELL;
    let want_top = (theta0 - 0.05) * H;
    println!(
        "wedge: θ₀ {theta0:.3} (measured bottom {:.3}), slope {:.2}/m against {:.2}/m, RMS off \
         the wedge {rms:.4} over {count} rows, top (θ > 0.05) {:.1} mm against {:.1} mm; rows {:?}",
        theta[0],
        slope,
        -1.0 / H,
        top * 1e3,
        want_top * 1e3,
        theta
            .iter()
            .map(|t| (t * 1000.0).round() / 1000.0)
            .collect::<Vec<_>>()
    );
    assert!(rms < 0.015, "RMS {rms}");
    assert!((slope * H + 1.0).abs() < 0.01, "slope {slope}");
    assert!(
        (top - want_top).abs() <= 2.0 * CELL,
        "top {top} against {want_top}"
    );
    // mass kept (no evaporation, nothing drips: the hem is the strip's own border) and
    // the solution moves whole
    assert!(
        (after - before).abs() < 1e-12 * before,
        "{before} → {after}"
    );
    for c in concentration {
        assert!((c - 0.02).abs() < 1e-9, "concentration {c}");
    }
    // without the capillary height the same liquid wicks up the strip, far above the
    // wedge (5 cm, 20 rows up: the wedge's film is gone there), and piles nowhere
    let (level, ..) = settle(0.0, 600);
    println!(
        "no capillary height: θ at the bottom {:.3}, at 5 cm {:.3}, at the top {:.3}",
        level[0], level[20], level[ROWS]
    );
    assert!(level[20] > 0.5 * THETA && level[0] < 2.0 * THETA);
    assert!(theta[20] < 1e-3 && theta[0] > 4.0 * THETA);
}

/// A spot of `params` on `pos` (the strip's mesh, placed anywhere), stepped `frames`
/// frames of 1/24 s with the cloth at `at(k)`: the fields.
fn spot(params: StainParams, at: impl Fn(usize) -> Vec<DVec3>) -> madder::stain::Fields {
    let (topo, _) = strip();
    let p0 = at(0);
    let mut sim = Simulator::new(
        topo,
        &p0,
        &p0,
        Conductivity::Isotropic(2e-4),
        params,
        [0.4, 0.05, 0.1],
        Par::Seq,
    )
    .unwrap();
    let centre = p0[p0.len() / 2];
    let pour: Vec<f64> = p0
        .iter()
        .map(|p| {
            if (*p - centre).length() < 6e-3 {
                0.3
            } else {
                0.0
            }
        })
        .collect();
    sim.add_liquid(&pour, 0.02, None).unwrap();
    for k in 1..=48 {
        sim.step(&at(k), 1.0 / 24.0, Some(&at(k + 1))).unwrap();
    }
    sim.fields().clone()
}

#[test]
fn nothing_drains_on_a_level_cloth_or_in_free_fall() {
    let (_, pos) = strip();
    // the strip laid flat (XY plane)
    let level: Vec<DVec3> = pos.iter().map(|p| DVec3::new(p.x, p.z, 0.0)).collect();
    let (on, off) = (|| params(H), || params(0.0));
    assert_eq!(
        spot(on(), |_| level.clone()),
        spot(off(), |_| level.clone())
    );
    // hanging, at rest, it drains; falling freely with it, it does not (to rounding: the
    // cloth's acceleration is a divided difference of its positions)
    let hanging = |_| pos.clone();
    let falling = |k: usize| {
        let t = k as f64 / 24.0;
        pos.iter()
            .map(|p| *p - DVec3::new(0.0, 0.0, 0.5 * 9.81 * t * t))
            .collect::<Vec<_>>()
    };
    let moved = |a: &madder::stain::Fields, b: &madder::stain::Fields| {
        a.absorbed_solvent
            .iter()
            .zip(&b.absorbed_solvent)
            .map(|(x, y)| (x - y).abs())
            .fold(0.0, f64::max)
            / a.absorbed_solvent.iter().cloned().fold(0.0, f64::max)
    };
    let drained = moved(&spot(on(), hanging), &spot(off(), hanging));
    let fell = moved(&spot(on(), falling), &spot(off(), falling));
    println!("hanging: the fibres' liquid moved by {drained:.2e} of its peak; falling: {fell:.2e}");
    assert!(drained > 1e-3 && fell < 1e-9, "{drained} {fell}");
}
