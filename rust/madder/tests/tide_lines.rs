//! Validation of tide lines (issue 13 §2): with `carry_solute` the dissolved solute moves
//! with the solvent's capillary flow. A blob of coffee drying on a flat cloth evaporates
//! faster at its rim (eq. 4.8's boundary factor), the solvent flows outward to replace
//! it and carries solute there (the coffee-ring mechanism, Deegan et al. 1997): the dry
//! stain's outer 15 % of radius holds at least twice the solute density of its centre.
//! Without the flow the stain is darkest at its centre. Solute conserved to 1e-12.
//!
//! Status: the transport is exact (a uniform solution stays uniform to 1e-14 however
//! sharp the solvent's front), but it does not make the ring: on this model the spill
//! keeps spreading (its edge is never pinned) and the faster evaporation covers only the
//! outermost ring of vertices, so the dry stain still falls off from its centre
//! (rim/centre 0.37 with the flow, 0.43 without). The ring test is kept, ignored, as the
//! target.

use faer::Par;
use glam::DVec3;
use madder::stain::{Conductivity, Forces, InteractionRates, Simulator, StainParams};

mod common;
use common::disk;

/// The Coffee preset's rates (addon/presets.py).
fn coffee() -> InteractionRates {
    InteractionRates {
        absorption: 2.0,
        saturation: 0.1,
        adsorption: 0.05,
        capacity: 1e-3,
        evaporation: 5e-5,
        evaporation_boundary: 1.5,
    }
}

/// A still, flat disk of cloth (radius 0.1 m, `rings` rings) with no body forces, the
/// solute carried by the flow or not, and 1 kg/m² of coffee-strength liquid poured within
/// 3 cm of its centre. Returns the simulator and the positions.
fn spill(rings: usize, interaction: InteractionRates, carry: bool) -> (Simulator, Vec<DVec3>) {
    spill_with(rings, interaction, carry, 0.0, false, 1.0)
}

fn spill_with(
    rings: usize,
    interaction: InteractionRates,
    carry: bool,
    residual: f64,
    vapour: bool,
    amount: f64,
) -> (Simulator, Vec<DVec3>) {
    let (topo, pos) = disk(rings, 0.1);
    let params = StainParams {
        forces: Forces {
            gravity: false,
            rectilinear: false,
            coriolis: false,
        },
        interaction,
        carry_solute: carry,
        residual_saturation: residual,
        vapour_limited: vapour,
        wicking: madder::stain::Wicking {
            exponent: std::env::var("WICK")
                .ok()
                .and_then(|v| v.parse().ok())
                .unwrap_or(0.0),
            density: 0.1,
        },
        ..Default::default()
    };
    let mut sim = Simulator::new(
        topo,
        &pos,
        &pos,
        Conductivity::Isotropic(2e-4),
        params,
        [0.25, 0.13, 0.05],
        Par::Seq,
    )
    .unwrap();
    let start: Vec<f64> = pos
        .iter()
        .map(|p| if p.length() < 0.03 { amount } else { 0.0 })
        .collect();
    sim.add_liquid(&start, 0.012, None).unwrap();
    (sim, pos)
}

/// Dries a blob of coffee; returns the radial profile of the dry stain's solute density
/// (bins of 2 mm) and the solute defect.
fn dry(carry: bool) -> (Vec<f64>, f64) {
    let (mut sim, pos) = spill(50, coffee(), carry);
    let solute0 = sim.totals().solute;
    let mut steps = 0;
    while sim.totals().solvent > 1e-9 && steps < 20000 {
        sim.step(&pos, 4.0, None).unwrap();
        steps += 1;
    }
    let defect = (sim.totals().solute - solute0).abs() / solute0;
    let s = sim.solute_density();
    let area = sim.vertex_area();
    let mut bins = vec![(0.0, 0.0); 50];
    for ((p, &d), &a) in pos.iter().zip(&s).zip(area) {
        let k = ((p.length() / 0.002) as usize).min(49);
        bins[k].0 += a * d;
        bins[k].1 += a;
    }
    println!("carry {carry}: dry after {steps} steps of 4 s, solute defect {defect:.1e}");
    (
        bins.iter()
            .map(|(m, a)| if *a > 0.0 { m / a } else { 0.0 })
            .collect(),
        defect,
    )
}

/// Mean density over the outer 15 % of the stain's radius against its centre (r < 30 %).
fn ring_contrast(profile: &[f64]) -> f64 {
    let peak = profile.iter().cloned().fold(0.0, f64::max);
    let edge = profile.iter().rposition(|&d| d > 0.01 * peak).unwrap() + 1;
    let outer = ((0.85 * edge as f64).floor() as usize)..edge;
    let centre = 0..((0.3 * edge as f64).ceil() as usize);
    let mean = |r: std::ops::Range<usize>| {
        let n = r.len() as f64;
        profile[r].iter().sum::<f64>() / n
    };
    mean(outer) / mean(centre)
}

#[test]
fn a_drying_coffee_blob_keeps_its_solute() {
    for carry in [false, true] {
        let (profile, defect) = dry(carry);
        assert!(defect < 1e-12, "carry {carry}: solute defect {defect:e}");
        assert!(profile.iter().all(|&d| d >= 0.0));
        println!("carry {carry}: rim/centre {:.2}", ring_contrast(&profile));
    }
}

/// The target, not reached by this model (module doc of `stain::diffuse`,
/// "Tide lines"): run with `--ignored` to see the profiles.
#[test]
#[ignore = "open (issue 13 §2): the capillary flow alone leaves no ring; measured rim/centre 0.37"]
fn a_drying_coffee_blob_leaves_a_ring() {
    let (flat, d0) = dry(false);
    let (ring, d1) = dry(true);
    println!("radial solute density (g/m², 2 mm bins):");
    for (k, (a, b)) in flat.iter().zip(&ring).enumerate() {
        if *a > 0.0 || *b > 0.0 {
            println!(
                "  r = {:4.1} mm   diffusing {:7.3}   carried {:7.3}",
                2.0 * k as f64 + 1.0,
                1e3 * a,
                1e3 * b
            );
        }
    }
    let (c0, c1) = (ring_contrast(&flat), ring_contrast(&ring));
    println!("rim/centre: diffusing solute {c0:.2}, carried by the flow {c1:.2}");
    assert!(d0 < 1e-12 && d1 < 1e-12, "solute defects {d0:e}, {d1:e}");
    assert!(c1 >= 2.0, "rim/centre {c1}");
    assert!(c0 < 1.0, "without the flow the centre is darkest: {c0}");
}

#[test]
fn a_uniform_solution_stays_uniform_as_it_spreads() {
    // carried by the solvent's own flux, a solution of one concentration keeps it
    // everywhere the solvent goes (the flow moves solution, not solute against solvent)
    let (mut sim, pos) = spill(40, common::no_interaction(), true);
    for _ in 0..50 {
        sim.step(&pos, 0.5, None).unwrap();
    }
    let f = sim.fields();
    let peak = f.free_solvent.iter().cloned().fold(0.0, f64::max);
    let mut worst: f64 = 0.0;
    for i in 0..pos.len() {
        if f.free_solvent[i] > 1e-6 * peak {
            let e = (f.solute[i] / f.free_solvent[i] / 0.012 - 1.0).abs();
            worst = worst.max(e);
        }
    }
    println!("uniform solution: concentration off by at most {worst:.2e}");
    assert!(worst < 1e-9, "{worst}");
}

#[test]
#[ignore]
fn explore() {
    let get = |k: &str, d: f64| {
        std::env::var(k)
            .ok()
            .and_then(|v| v.parse().ok())
            .unwrap_or(d)
    };
    let mut rates = coffee();
    rates.capacity = get("CAP", 1e-3);
    rates.adsorption = get("KD", 0.05);
    let (mut sim, pos) = spill_with(
        get("RINGS", 50.0) as usize,
        rates,
        get("CARRY", 1.0) > 0.0,
        get("RES", 0.2),
        get("VAP", 1.0) > 0.0,
        get("AMOUNT", 0.3),
    );
    let solute0 = sim.totals().solute;
    let mut steps = 0;
    let t = std::time::Instant::now();
    while sim.totals().solvent > 1e-9 && steps < 20000 {
        let dt = if sim.time() < get("T0", 20.0) {
            get("DT0", 0.1)
        } else {
            get("DT", 4.0)
        };
        sim.step(&pos, dt, None).unwrap();
        steps += 1;
    }
    let defect = (sim.totals().solute - solute0).abs() / solute0;
    let s = sim.solute_density();
    let area = sim.vertex_area();
    let mut bins = vec![(0.0, 0.0); 50];
    for ((p, &d), &a) in pos.iter().zip(&s).zip(area) {
        let k = ((p.length() / 0.002) as usize).min(49);
        bins[k].0 += a * d;
        bins[k].1 += a;
    }
    let profile: Vec<f64> = bins
        .iter()
        .map(|(m, a)| if *a > 0.0 { m / a } else { 0.0 })
        .collect();
    let line: Vec<String> = profile.iter().map(|d| format!("{:.2}", d * 1e3)).collect();
    println!("{}", line.join(" "));
    println!(
        "steps {steps} ({:.1} s), defect {defect:.1e}, min {:.1e}, rim/centre {:.2}",
        t.elapsed().as_secs_f64(),
        s.iter().cloned().fold(f64::INFINITY, f64::min),
        ring_contrast(&profile)
    );
}
