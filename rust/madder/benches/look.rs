//! `make bench`: the cost of the features that give a stain its look (issue 13), each
//! against the same step without it, side by side in one run on the ≈ 10k-vertex waving
//! flag (`benches/simulate.rs`'s grid and pour). Prints figures; asserts nothing about time.
//! Runs (§5) add nothing to the step (free liquid under gravity, absorbed as it passes).

mod common;

use std::time::Instant;

use common::{grid, motion, pour, wave};
use faer::Par;
use madder::stain::{
    Conductivity, InteractionRates, Irregularity, Simulator, StainParams, Wicking,
};

fn ms_per_frame(name: &str, params: StainParams, frames: usize) -> f64 {
    let (topo, rest) = grid(127, 77);
    let dt = 1.0 / 24.0;
    let mut sim = Simulator::new(
        topo,
        &rest,
        &wave(&rest, 0.0),
        Conductivity::Isotropic(2e-4),
        params,
        [0.4, 0.05, 0.1],
        Par::Seq,
    )
    .unwrap();
    sim.add_liquid(&pour(&rest), 0.05, None).unwrap();
    let cloth = motion(&rest, frames, dt);
    let t = Instant::now();
    for f in 1..=frames {
        sim.step(&cloth[f], dt, Some(&cloth[f + 1])).unwrap();
    }
    let ms = t.elapsed().as_secs_f64() * 1e3 / frames as f64;
    let p = sim.profile();
    println!(
        "{name:<28} {ms:7.2} ms/frame (diffusion {:.2} ms, {:.1} density CG it.)",
        p.diffusion * 1e3 / frames as f64,
        p.density_iterations as f64 / frames as f64
    );
    ms
}

fn main() {
    println!(
        "the look of a stain on the waving flag (10k vertices), {} rayon threads",
        rayon::current_num_threads()
    );
    let frames = 48;
    let base = ms_per_frame("linear diffusion", StainParams::default(), frames);
    let wick = ms_per_frame(
        "wicking D0·θ² (issue 13 §1)",
        StainParams {
            wicking: Wicking {
                exponent: 2.0,
                density: 0.1,
                picard: 0,
                tolerance: 0.0,
            },
            ..Default::default()
        },
        frames,
    );
    println!("wicking costs {:.2}× the step without it", wick / base);
    let uneven = ms_per_frame(
        "irregular fabric (§3)",
        StainParams {
            irregularity: Irregularity {
                amplitude: 0.5,
                correlation_length: 0.01,
                seed: 1,
                fine_length: 0.0,
            },
            ..Default::default()
        },
        frames,
    );
    println!(
        "the irregular fabric costs {:.2}× the step without it",
        uneven / base
    );
    // tide lines (§2): the solute carried, the edge pinned and the vapour-limited rim (the
    // Coffee preset's drying); against the seed's Coffee step on the same pour
    let coffee = |tide: bool| StainParams {
        interaction: InteractionRates {
            adsorption: 0.05,
            capacity: 2e-4,
            evaporation_boundary: 1.5,
            ..Default::default()
        },
        carry_solute: tide,
        residual_saturation: if tide { 0.1 } else { 0.0 },
        carried_fraction: 1.0,
        dispersivity: 0.0,
        vapour_limited: tide,
        holdup: 0.0,
        film_creep: 1.0,
        ..Default::default()
    };
    let plain = ms_per_frame("coffee, seed's drying", coffee(false), frames);
    let tide = ms_per_frame("coffee, tide lines (§2)", coffee(true), frames);
    println!("tide lines cost {:.2}× the step without them", tide / plain);
    // runs (§5) are the step itself (free liquid under gravity, absorbed as it passes):
    // nothing is added to it
}
