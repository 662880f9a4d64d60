//! Long frames after a pour (`stain::simulate`'s module doc, "Sub-steps after a pour"): a
//! scene whose clock runs at a minute a frame (the gallery's) stepped each frame in one
//! sub-step spreads a fresh spill for the whole minute before the fibres hold any of it.
//!
//! The spill: a pool of coffee (the Coffee preset's rates, its wicking, rim and holdup;
//! 0.8 kg/m² within 1.63 cm, what a soft 3 cm Spill Group lands as) on a still, flat
//! 16 cm square of 4 mm cells, dried over an hour. The reference is the same hour in
//! 2-s steps. What is measured is the dry stain, as `rims.rs` measures it: the deposited
//! solute per area (every solute pool), its profile the mean over 1 mm rings about the
//! centre, the outline the outermost ring at least half as dark as the centre, the
//! rim/centre ratio the outer 15 % of that radius against the inner 30 %.
//!
//! Measured (this file's spill): 2-s steps 51.5 mm and 3.41; one-minute frames in one
//! sub-step 76.5 mm and 0.88 (no ring); with the ramp from 0.25 s, 48.5 mm and 2.85 in
//! 76 sub-steps (61 without). The test asserts the ramp within 10 % of the reference's outline
//! and 25 % of its rim/centre, the single sub-steps more than 30 % out, and a ramp that
//! starts as long as the frame is the single sub-step bit for bit.
//!
//! A Frame Time keyed up: the same pool in 0.25 s of frames of 1/24 s (where the ramp
//! after the pour does nothing: it starts as long as the frames), then frames of a minute
//! to the hour, while the pool still spreads. The frames' lengthening starts a ramp of
//! its own. Measured: the reference (the same 0.25 s, then 2-s steps) 46.5 mm and 3.60;
//! minute frames without a ramp (`first_substep` 0) 71.5 mm and 1.02; with it 48.5 mm
//! and 2.86, in 86 sub-steps (67 without).

use faer::Par;
use glam::DVec3;
use madder::mesh::Topology;
use madder::stain::{Conductivity, Simulator, StainParams};

mod common;
use common::{Grid, addon_look, coffee_rates};

const HALF: f64 = 0.08;
const CELLS: usize = 40;
const POOL: f64 = 0.0163;

/// The Coffee preset as the add-on makes it: its rates, its rim, the presets' look.
fn coffee(first_substep: f64) -> StainParams {
    StainParams {
        interaction: coffee_rates(),
        carry_solute: true,
        residual_saturation: 0.1,
        vapour_limited: true,
        dispersivity: 3.5e-3,
        ..addon_look(first_substep)
    }
}

/// A still, flat cloth of `topo` at `pos` with a pool of coffee of radius `pool`, m.
fn pool_of_coffee(topo: Topology, pos: &[DVec3], pool: f64, first_substep: f64) -> Simulator {
    let mut sim = Simulator::new(
        topo,
        pos,
        pos,
        Conductivity::Isotropic(2e-4),
        coffee(first_substep),
        [0.25, 0.13, 0.05],
        Par::Seq,
    )
    .unwrap();
    let liquid: Vec<f64> = pos
        .iter()
        .map(|p| if p.length() < pool { 0.8 } else { 0.0 })
        .collect();
    sim.add_liquid(&liquid, 0.012, None).unwrap();
    sim
}

/// The dry stain after frames of the lengths `frames`, s (each told the next one's
/// length; `first_substep` the ramp's start, 0 off): the deposited solute per area, the
/// vertices' distances from the centre, the sub-steps taken and the relative solute
/// defect.
fn dry_in(frames: &[f64], first_substep: f64) -> (Vec<f64>, Vec<f64>, usize, f64) {
    let (topo, pos) = Grid::new(CELLS, HALF).build();
    let mut sim = pool_of_coffee(topo, &pos, POOL, first_substep);
    let r: Vec<f64> = pos.iter().map(|p| p.length()).collect();
    let poured = sim.totals().solute;
    for (k, &dt) in frames.iter().enumerate() {
        let after = frames.get(k + 1).map(|&h| (&pos[..], h));
        sim.step_until(&pos, dt, after).unwrap();
    }
    let f = sim.fields();
    let held: Vec<f64> = (0..pos.len())
        .map(|i| f.solute[i] + f.absorbed_solute[i] + f.adsorbed[i])
        .collect();
    let defect = (sim.totals().solute - poured).abs() / poured;
    (sim.density(&held), r, sim.profile().substeps, defect)
}

/// The outline (m) and the rim/centre ratio of a dry stain (module doc).
fn measure(deposit: &[f64], r: &[f64]) -> (f64, f64) {
    let rings = (HALF / 1e-3) as usize;
    let mut sum = vec![0.0; rings];
    let mut count = vec![0usize; rings];
    for (&d, &x) in deposit.iter().zip(r) {
        let k = (x / 1e-3) as usize;
        if k < rings {
            sum[k] += d;
            count[k] += 1;
        }
    }
    let profile: Vec<(f64, f64)> = (0..rings)
        .filter(|&k| count[k] > 0)
        .map(|k| ((k as f64 + 0.5) * 1e-3, sum[k] / count[k] as f64))
        .collect();
    let centre = profile[..5].iter().map(|p| p.1).sum::<f64>() / 5.0;
    let outline = profile
        .iter()
        .filter(|p| p.1 >= 0.5 * centre)
        .map(|p| p.0)
        .fold(0.0, f64::max);
    let mean = |lo: f64, hi: f64| {
        let v: Vec<f64> = profile
            .iter()
            .filter(|p| p.0 > lo && p.0 <= hi)
            .map(|p| p.1)
            .collect();
        v.iter().sum::<f64>() / v.len() as f64
    };
    (
        outline,
        mean(0.85 * outline, outline) / mean(0.0, 0.3 * outline),
    )
}

/// Prints the three dry stains (`what`: how the frames ran) and asserts the ramp's
/// outline within 10 % and its rim/centre within 25 % of the reference's, and the single
/// sub-steps' outline more than `plain_out` times the reference's.
fn ramp_matches(
    what: &str,
    reference: (f64, f64, usize),
    plain: (f64, f64, usize),
    ramp: (f64, f64, usize),
    plain_out: f64,
) {
    println!(
        "{what} ({}): outline {:.1} mm, rim/centre {:.2}; one sub-step a frame ({}): {:.1} mm, {:.2}; with the ramp ({}): {:.1} mm, {:.2}",
        reference.2,
        1e3 * reference.0,
        reference.1,
        plain.2,
        1e3 * plain.0,
        plain.1,
        ramp.2,
        1e3 * ramp.0,
        ramp.1
    );
    assert!(
        plain.0 > plain_out * reference.0,
        "single sub-steps {plain:?} against {reference:?}"
    );
    assert!(
        (ramp.0 / reference.0 - 1.0).abs() < 0.1,
        "outline {ramp:?} against {reference:?}"
    );
    assert!(
        (ramp.1 / reference.1 - 1.0).abs() < 0.25,
        "rim/centre {ramp:?} against {reference:?}"
    );
}

/// The outline, rim/centre and sub-steps of the pool dried in `frames` with the ramp from
/// `first_substep` (0: off), after checking that its solute is conserved.
fn dried(frames: &[f64], first_substep: f64) -> (f64, f64, usize) {
    let (d, r, steps, defect) = dry_in(frames, first_substep);
    assert!(defect < 1e-12, "solute defect {defect:e}");
    let (outline, ratio) = measure(&d, &r);
    (outline, ratio, steps)
}

#[test]
fn a_pool_dried_in_minute_frames_after_a_ramp_matches_short_steps() {
    let hour = |dt: f64| vec![dt; (3600.0 / dt).round() as usize];
    let reference = dried(&hour(2.0), 0.0);
    let plain = dried(&hour(60.0), 0.0);
    let ramp = dried(&hour(60.0), 0.25);
    ramp_matches("2-s steps", reference, plain, ramp, 1.3);
    assert!(ramp.2 < 2 * plain.2, "{} sub-steps", ramp.2);
}

#[test]
fn a_ramp_as_long_as_the_frame_is_the_single_sub_step_bit_for_bit() {
    let (topo, pos) = Grid::new(16, 0.02).build();
    let run = |first_substep: f64| {
        let mut sim = pool_of_coffee(topo.clone(), &pos, 0.008, first_substep);
        // the cloth slides along x, faster and faster (no turn: one sub-step a frame)
        for k in 1..=6 {
            let at: Vec<DVec3> = pos
                .iter()
                .map(|p| *p + DVec3::new(0.002 * (k * k) as f64, 0.0, 0.0))
                .collect();
            sim.step(&at, 0.5, None).unwrap();
        }
        (sim.fields().clone(), sim.profile().substeps)
    };
    let (off, steps) = run(0.0);
    assert_eq!(steps, 6);
    for first in [0.5, 2.0] {
        let (on, steps) = run(first);
        assert_eq!(steps, 6, "first sub-step {first}");
        assert_eq!(on, off, "first sub-step {first}");
    }
    // shorter than the frame, it takes more: 0.2 and the rest, 0.3; 0.4 and the rest, 0.1;
    // then one a frame
    let (_, steps) = run(0.2);
    assert_eq!(steps, 8);
}

#[test]
fn a_pool_dried_after_its_frames_lengthen_matches_short_steps() {
    let fall = vec![1.0 / 24.0; 6];
    let clock = |then: f64| -> Vec<f64> {
        [fall.clone(), vec![then; (3599.75 / then).round() as usize]].concat()
    };
    let reference = dried(&clock(2.0), 0.25);
    let plain = dried(&clock(60.0), 0.0);
    let ramp = dried(&clock(60.0), 0.25);
    ramp_matches(
        "0.25 s at 24 fps, then 2-s steps",
        reference,
        plain,
        ramp,
        1.2,
    );
    assert!(ramp.2 < plain.2 + 48, "{} sub-steps", ramp.2);
}
