//! Validation of the irregular fabric (issue 13 §3), a random multiplier of the diffusion
//! and absorption rates fixed to the rest surface:
//!
//! 1. the field has mean 0, variance 1 and the Gaussian covariance of its correlation
//!    length (measured within 10 %), and is a function of the point alone;
//! 2. amplitude 0 is the uniform fabric bit for bit;
//! 3. at amplitude 0.5 a spill's front is ragged: its radius varies with the angle
//!    (coefficient of variation ≥ 5 % at 20 correlation lengths), where the uniform
//!    fabric's is round (≤ 2 %);
//! 4. identical results for any thread count.

use faer::Par;
use glam::DVec3;
use madder::stain::{Conductivity, Forces, Irregularity, Simulator, StainParams, Wicking};

mod common;
use common::{Grid, no_interaction};

#[test]
fn the_field_has_the_covariance_it_is_made_for() {
    for (seed, ell) in [(1u64, 0.01), (2, 0.004), (3, 0.05)] {
        let irr = Irregularity {
            amplitude: 0.5,
            correlation_length: ell,
            seed,
            fine_length: 0.0,
        };
        // points on a plane 400 ℓ wide, and pairs at distance r in many directions
        let side = 400.0 * ell;
        let mut rng = madder::rng::SplitMix64::new(seed);
        let base: Vec<DVec3> = (0..4000)
            .map(|_| DVec3::new(side * rng.unit(), side * rng.unit(), 0.0))
            .collect();
        let f0 = irr.field(&base);
        let mean = f0.iter().sum::<f64>() / f0.len() as f64;
        let var = f0.iter().map(|x| (x - mean) * (x - mean)).sum::<f64>() / f0.len() as f64;
        assert!(
            mean.abs() < 0.1 && (var - 1.0).abs() < 0.15,
            "mean {mean}, variance {var}"
        );
        let mut estimates = Vec::new();
        for r_over in [0.5, 1.0, 1.5] {
            let r = r_over * ell;
            let shifted: Vec<DVec3> = base
                .iter()
                .map(|p| {
                    let a = std::f64::consts::TAU * rng.unit();
                    *p + r * DVec3::new(a.cos(), a.sin(), 0.0)
                })
                .collect();
            let f1 = irr.field(&shifted);
            let c = f0
                .iter()
                .zip(&f1)
                .map(|(a, b)| (a - mean) * (b - mean))
                .sum::<f64>()
                / (f0.len() as f64 * var);
            // C(r) = exp(−r²/2ℓ²)  ⇒  ℓ = r / √(−2 ln C)
            estimates.push(r / (-2.0 * c.ln()).sqrt());
        }
        let measured = estimates.iter().sum::<f64>() / estimates.len() as f64;
        println!("ℓ = {ell}: measured {measured:.5} ({estimates:.5?})");
        assert!(
            (measured / ell - 1.0).abs() < 0.1,
            "ℓ = {ell}: measured {measured}"
        );
    }
    // a function of the point: the same value whatever else is evaluated
    let irr = Irregularity {
        amplitude: 1.0,
        correlation_length: 0.01,
        seed: 9,
        fine_length: 0.0,
    };
    let p = DVec3::new(0.1234, -0.5, 0.25);
    let alone = irr.field(&[p])[0];
    let among = irr.field(&[DVec3::ZERO, p, DVec3::ONE])[1];
    assert_eq!(alone.to_bits(), among.to_bits());
    // the multiplier is positive with mean 1
    let m = irr.multiplier(
        &(0..20000)
            .map(|k| DVec3::new(0.001 * k as f64, 0.0003 * k as f64, 0.0))
            .collect::<Vec<_>>(),
    );
    assert!(m.iter().all(|&x| x > 0.0));
    let mean = m.iter().sum::<f64>() / m.len() as f64;
    assert!((mean - 1.0).abs() < 0.1, "mean multiplier {mean}");
}

/// A spill spreading by wicking on a flat, still cloth of the given irregularity:
/// returns the front radius in 72 angular sectors (5°) and the simulator.
fn spill(irregularity: Irregularity, threads: usize) -> (Vec<f64>, Simulator) {
    let (topo, pos) = Grid::new(140, 0.175).jitter(0.2).build();
    let params = StainParams {
        forces: Forces {
            gravity: false,
            rectilinear: false,
            coriolis: false,
        },
        interaction: no_interaction(),
        wicking: Wicking {
            exponent: 1.0,
            density: 0.1,
            picard: 0,
            tolerance: 0.0,
        },
        irregularity,
        ..Default::default()
    };
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    pool.install(|| {
        let mut sim = Simulator::new(
            topo,
            &pos,
            &pos,
            Conductivity::Isotropic(2e-3),
            params,
            [0.5, 0.1, 0.1],
            Par::Seq,
        )
        .unwrap();
        let start: Vec<f64> = pos
            .iter()
            .map(|p| if p.length() < 0.03 { 0.1 } else { 0.0 })
            .collect();
        sim.add_liquid(&start, 0.05, None).unwrap();
        for _ in 0..60 {
            sim.step(&pos, 0.1, None).unwrap();
        }
        let wet = sim.wetness();
        let peak = wet.iter().cloned().fold(0.0, f64::max);
        let mut front = vec![0.0f64; 72];
        for (p, &w) in pos.iter().zip(&wet) {
            if w > 0.05 * peak {
                let a = p.y.atan2(p.x) + std::f64::consts::PI;
                let k = ((a / std::f64::consts::TAU * 72.0) as usize).min(71);
                front[k] = front[k].max(p.length());
            }
        }
        (front, sim)
    })
}

fn variation(r: &[f64]) -> (f64, f64) {
    let mean = r.iter().sum::<f64>() / r.len() as f64;
    let sd = (r.iter().map(|x| (x - mean) * (x - mean)).sum::<f64>() / r.len() as f64).sqrt();
    (mean, sd / mean)
}

#[test]
fn an_irregular_fabric_gives_a_ragged_front() {
    let ell = 0.005;
    let (round, _) = spill(Irregularity::default(), 2);
    let (ragged, _) = spill(
        Irregularity {
            amplitude: 0.5,
            correlation_length: ell,
            seed: 3,
            fine_length: 0.0,
        },
        2,
    );
    let (r0, cv0) = variation(&round);
    let (r1, cv1) = variation(&ragged);
    println!(
        "uniform: front {r0:.4} m, CV {:.1} %; irregular (a = 0.5, ℓ = {ell}): front {r1:.4} m = {:.0} ℓ, CV {:.1} %",
        100.0 * cv0,
        r1 / ell,
        100.0 * cv1
    );
    assert!(r1 > 15.0 * ell, "the spill reached only {r1} m");
    assert!(cv0 < 0.02, "uniform CV {cv0}");
    assert!(cv1 >= 0.05, "irregular CV {cv1}");
}

#[test]
fn amplitude_zero_is_the_uniform_fabric_and_threads_do_not_matter() {
    let off = |seed| Irregularity {
        amplitude: 0.0,
        correlation_length: 0.01,
        seed,
        fine_length: 0.0,
    };
    let bits = |s: &Simulator| {
        s.fields()
            .free_solvent
            .iter()
            .chain(&s.fields().absorbed_solute)
            .map(|x| x.to_bits())
            .collect::<Vec<_>>()
    };
    let (_, a) = spill(Irregularity::default(), 2);
    let (_, b) = spill(off(42), 2);
    assert_eq!(bits(&a), bits(&b));
    let on = Irregularity {
        amplitude: 0.7,
        correlation_length: 0.01,
        seed: 5,
        fine_length: 0.0,
    };
    let (_, c) = spill(on, 1);
    let (_, d) = spill(on, 2);
    assert_eq!(bits(&c), bits(&d));
    assert_ne!(bits(&a), bits(&c));
}

#[test]
fn bad_irregularity_is_refused_by_name() {
    for (amplitude, correlation_length) in [(-0.1, 0.01), (1.5, 0.01), (0.5, 0.0), (f64::NAN, 0.01)]
    {
        let p = StainParams {
            irregularity: Irregularity {
                amplitude,
                correlation_length,
                seed: 0,
                fine_length: 0.0,
            },
            ..Default::default()
        };
        let e = p.validate().unwrap_err().to_string();
        assert!(e.contains("irregularity"), "{e}");
    }
}
