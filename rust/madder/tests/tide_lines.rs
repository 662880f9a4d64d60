//! Validation of tide lines (issue 13 §2). A blob of coffee drying on a flat cloth: with
//! the solute carried by the liquid's flow (`carry_solute`), the wet edge pinned
//! (`residual_saturation`: the fibres' liquid below a tenth of their saturation neither
//! moves nor lets liquid in) and the evaporation limited by vapour diffusion (fastest at
//! the patch's edge, `vapour_limited`), the liquid flows outward to the drying edge and
//! carries its solute there (the coffee-ring mechanism, Deegan et al. 1997): the dry
//! stain's outer 15 % of radius holds at least twice the solute density of its centre.
//! Without that physics (the seed's model) the centre is darkest, and without any one of
//! the three ingredients there is no ring. Solute conserved to 1e-12, densities ≥ 0,
//! thread count irrelevant.

use faer::Par;
use glam::DVec3;
use madder::stain::{Conductivity, Forces, InteractionRates, Simulator, StainParams};

mod common;
use common::{coffee_rates as coffee, disk};

/// A still, flat disk of cloth (radius 0.1 m, `rings` rings) with no body forces, drying
/// as asked, and `amount` kg/m² of coffee-strength liquid poured within 3 cm of its
/// centre. Returns the simulator and the positions.
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

/// How the blob dries: the solute carried by the flow, the residual saturation, the
/// vapour-limited evaporation (the Coffee preset: all three).
#[derive(Clone, Copy, Debug)]
struct Drying {
    carry: bool,
    residual: f64,
    vapour: bool,
}

const COFFEE: Drying = Drying {
    carry: true,
    residual: 0.1,
    vapour: true,
};
const SEED: Drying = Drying {
    carry: false,
    residual: 0.0,
    vapour: false,
};

/// Dries 0.3 kg/m² of coffee poured within 3 cm of the disk's centre (steps of 0.1 s while
/// it spreads, the first 20 s, then 4 s); returns the radial profile of the dry stain's
/// solute density (bins of 2 mm), the solute defect and the smallest density.
fn dry(how: Drying) -> (Vec<f64>, f64, f64) {
    let (mut sim, pos) = spill_with(50, coffee(), how.carry, how.residual, how.vapour, 0.3);
    let solute0 = sim.totals().solute;
    let mut steps = 0;
    while sim.totals().solvent > 1e-9 && steps < 5000 {
        let dt = if sim.time() < 20.0 { 0.1 } else { 4.0 };
        sim.step(&pos, dt, None).unwrap();
        steps += 1;
    }
    assert!(
        sim.totals().solvent <= 1e-9,
        "{how:?}: not dry after {steps} steps"
    );
    let defect = (sim.totals().solute - solute0).abs() / solute0;
    let s = sim.solute_density();
    let lowest = s.iter().cloned().fold(f64::INFINITY, f64::min);
    let area = sim.vertex_area();
    let mut bins = vec![(0.0, 0.0); 50];
    for ((p, &d), &a) in pos.iter().zip(&s).zip(area) {
        let k = ((p.length() / 0.002) as usize).min(49);
        bins[k].0 += a * d;
        bins[k].1 += a;
    }
    println!(
        "{how:?}: dry after {steps} steps ({:.0} s), solute defect {defect:.1e}",
        sim.time()
    );
    (
        bins.iter()
            .map(|(m, a)| if *a > 0.0 { m / a } else { 0.0 })
            .collect(),
        defect,
        lowest,
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
fn a_drying_coffee_blob_leaves_a_ring() {
    let (seed, d0, low0) = dry(SEED);
    let (ring, d1, low1) = dry(COFFEE);
    println!("radial solute density (g/m², 2 mm bins):");
    for (k, (a, b)) in seed.iter().zip(&ring).enumerate() {
        if *a > 0.0 || *b > 0.0 {
            println!(
                "  r = {:4.1} mm   seed's model {:7.3}   tide lines {:7.3}",
                2.0 * k as f64 + 1.0,
                1e3 * a,
                1e3 * b
            );
        }
    }
    let (c0, c1) = (ring_contrast(&seed), ring_contrast(&ring));
    println!("rim/centre: seed's model {c0:.2}, tide lines {c1:.2}");
    assert!(d0 < 1e-12 && d1 < 1e-12, "solute defects {d0:e}, {d1:e}");
    assert!(
        low0 >= 0.0 && low1 >= 0.0,
        "negative densities {low0:e}, {low1:e}"
    );
    assert!(c1 >= 2.0, "rim/centre {c1}");
    assert!(
        c0 < 1.0,
        "without the drying flow the centre is darkest: {c0}"
    );
}

#[test]
fn each_ingredient_of_the_ring_is_needed() {
    // without the flow, the pinned edge or the vapour-limited rim: no ring
    for how in [
        Drying {
            carry: false,
            ..COFFEE
        },
        Drying {
            residual: 0.0,
            ..COFFEE
        },
        Drying {
            vapour: false,
            ..COFFEE
        },
    ] {
        let (profile, defect, lowest) = dry(how);
        let c = ring_contrast(&profile);
        println!("{how:?}: rim/centre {c:.2}");
        assert!(defect < 1e-12 && lowest >= 0.0, "{defect:e} {lowest:e}");
        assert!(c < 1.5, "{how:?}: rim/centre {c}");
    }
}

#[test]
fn the_drying_flow_does_not_depend_on_the_thread_count() {
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            let (mut sim, pos) = spill_with(30, coffee(), true, 0.1, true, 0.3);
            for k in 0..120 {
                sim.step(&pos, if k < 60 { 0.1 } else { 4.0 }, None)
                    .unwrap();
            }
            let f = sim.fields();
            [
                &f.free_solvent,
                &f.absorbed_solvent,
                &f.solute,
                &f.absorbed_solute,
            ]
            .iter()
            .flat_map(|v| v.iter().map(|x| x.to_bits()))
            .collect::<Vec<u64>>()
        })
    };
    assert_eq!(run(1), run(2));
}

#[test]
fn a_uniform_solution_stays_uniform_as_it_spreads() {
    // carried by the solvent's own flux, a solution of one concentration keeps it
    // everywhere the solvent goes (the flow moves solution, not solute against solvent)
    for residual in [0.0, 0.1] {
        uniform_solution(residual);
    }
}

fn uniform_solution(residual: f64) {
    // with a pinned edge too: the fibres' liquid on its own operator
    let mut rates = common::no_interaction();
    if residual > 0.0 {
        rates.absorption = 2.0;
        rates.saturation = 0.1;
    }
    let (mut sim, pos) = spill_with(40, rates, true, residual, false, 1.0);
    for _ in 0..50 {
        sim.step(&pos, 0.5, None).unwrap();
    }
    let f = sim.fields();
    let mut worst: f64 = 0.0;
    for (solvent, solute) in [
        (&f.free_solvent, &f.solute),
        (&f.absorbed_solvent, &f.absorbed_solute),
    ] {
        let peak = solvent.iter().cloned().fold(0.0, f64::max);
        for i in 0..pos.len() {
            if solvent[i] > 1e-6 * peak {
                let e = (solute[i] / solvent[i] / 0.012 - 1.0).abs();
                worst = worst.max(e);
            }
        }
    }
    println!("uniform solution (residual {residual}): concentration off by at most {worst:.2e}");
    assert!(worst < 1e-9, "{worst}");
}

#[test]
fn a_residual_saturation_out_of_range_is_named() {
    for bad in [-0.1, 1.0, f64::NAN] {
        let params = StainParams {
            residual_saturation: bad,
            ..Default::default()
        };
        let msg = params.validate().unwrap_err().to_string();
        assert!(msg.starts_with("residual saturation"), "{msg}");
    }
}
