//! `make bench`: the cost of stain Detail (issue 12), side by side in one run on the
//! waving-flag grid of about 20k vertices: Detail 0 with the whole cloth wet against
//! Detail 2 with 10 % of the cloth wet (the fine wet region about 1.6× the cloth's
//! vertex count), per frame as the bake meets it (the cloth's positions in, the step,
//! the per-cloth-vertex read-outs out), and the memory the refined simulator takes
//! (resident set growth over the setup and the frames, the part built lazily as the
//! liquid arrives). Prints figures; asserts nothing about time. `MADDER_BENCH_DUMP=file`
//! writes a case's last-frame fine stain and wetness there (little-endian f64s; run one
//! `--case` at a time), to compare two builds whose checksums differ.
//!
//! A third case runs Detail 0 with Detail 2's pour (the same local stain at the cloth's
//! resolution) and the bench prints the ratio's three factors: active vertices, a local
//! stain's cost per vertex over the all-wet cloth's, and Detail 2's cost per vertex over
//! Detail 0's on the same stain (ARCHITECTURE, "Stain detail", the fifth look). A fourth
//! runs Detail 0 with that pour on a cloth of Detail 2's spacing (the 20k flag with four
//! times the vertices along each side, 316 825 vertices: the refined cloth's lattice, no
//! refinement), and the bench prints Detail 2's cost against it, per frame and per active
//! vertex: what the refinement costs over a cloth as fine (the eighth look).
//!
//! The four cases run in turn three times (`MADDER_BENCH_ROUNDS` another count): the
//! machine this was written on drifts by a quarter between minutes, so one round's ratio
//! compares runs seconds apart, and the bench prints the median of the rounds' ratios,
//! every round's figures and the factors of the medians (the first round's reports in
//! full).
//!
//! The wet share is counted as in `tests/bench/bench_dynamic_paint.py`: the pour's radius
//! is found by bisection, on untimed runs in a process of their own, until the fine
//! vertices wetter than 1 g/m² at the last frame are within 5 % of 10 % of the refined
//! cloth's (the liquid spreads after it lands: a pour over 10 % of the area wets about
//! 15 % by the last frame).

mod common;

use std::time::Instant;

use common::{grid, motion, wave};
use faer::Par;
use glam::DVec3;
use madder::stain::{Conductivity, Detailed, StainParams};

/// A figure of this process's `/proc/self/status` (kB → bytes; 0 elsewhere): `VmRSS`
/// (resident now) or `VmHWM` (the peak resident set).
fn status(key: &str) -> usize {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with(key))?
                .split_whitespace()
                .nth(1)?
                .parse::<usize>()
                .ok()
        })
        .map_or(0, |kb| kb * 1024)
}

/// The pour's radius on the 2 × 1.2 m flag whose disk covers `wet_fraction` of its area.
fn disk_radius(wet_fraction: f64) -> f64 {
    (wet_fraction * 2.4 / std::f64::consts::PI).sqrt()
}

/// Steps Detail `level` with a pour of `radius` (every vertex if `None`) on the flag with
/// `spacing` times the cloth's vertices along each side (1: the 20k-vertex cloth; 4: a
/// cloth of Detail 2's spacing); prints the figures if `report`, and returns the fine
/// vertices wetter than 1 g/m² at the end and the refined cloth's vertex count.
fn bench(
    level: u32,
    radius: Option<f64>,
    spacing: usize,
    frames: usize,
    report: bool,
) -> (usize, usize) {
    // 20 020 vertices on 2 × 1.2 m at spacing 1 (at 4: 316 825, the refined cloth's
    // lattice at Detail 2)
    let (topo, rest) = grid(181 * spacing, 109 * spacing);
    let n = topo.n_vertices();
    let dt = 1.0 / 24.0;
    let centre = DVec3::new(1.0, 0.0, 0.6);
    let pour: Vec<f64> = rest
        .iter()
        .map(|p| {
            if radius.is_none_or(|r| p.distance(centre) < r) {
                1.0
            } else {
                0.0
            }
        })
        .collect();
    let cloth = motion(&rest, frames, dt);
    let before = status("VmRSS:");
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
    let at_setup = status("VmRSS:").saturating_sub(before);
    sim.add_liquid(&pour, 0.05, None).unwrap();
    let t = Instant::now();
    let mut read = 0.0;
    for f in 1..=frames {
        sim.step(&cloth[f], dt, Some(&cloth[f + 1])).unwrap();
        let r = Instant::now();
        std::hint::black_box((sim.solute_density(), sim.wetness(), sim.deposit()));
        read += r.elapsed().as_secs_f64();
    }
    let total = t.elapsed().as_secs_f64() * 1e3 / frames as f64;
    let held = status("VmRSS:").saturating_sub(before);
    let peak = status("VmHWM:").saturating_sub(before);
    let p = sim.profile();
    let (fine_n, built) = (sim.n_fine_vertices(), sim.n_built_vertices());
    let wet = sim.fine().wetness().iter().filter(|&&w| w > 1e-3).count();
    if !report {
        return (wet, fine_n);
    }
    // the last frame's fine stain and wetness (whole refined numbering), for comparing
    // two builds whose results differ (`MADDER_BENCH_DUMP=file`: little-endian f64s)
    if let Some(path) = std::env::var_os("MADDER_BENCH_DUMP") {
        let bytes: Vec<u8> = sim
            .fine_solute_density()
            .iter()
            .chain(&sim.fine_wetness())
            .flat_map(|x| x.to_le_bytes())
            .collect();
        std::fs::write(path, bytes).unwrap();
    }
    // FNV-1a over the bits of the cloth-level read-outs: equal = bit-identical results
    let (s, w, d) = (sim.solute_density(), sim.wetness(), sim.deposit());
    let checksum = s
        .iter()
        .chain(&w)
        .chain(&d)
        .map(|x| x.to_bits())
        .fold(0xcbf2_9ce4_8422_2325_u64, |h, b| {
            (h ^ b).wrapping_mul(0x0100_0000_01b3)
        });
    println!(
        "detail {level}, {:>3.0} % wet at the end (pour radius {}): {n} cloth vertices, {fine_n} refined, {built} built ({wet} wet above 1 g/m²); {total:7.2} ms/frame (read-outs {:.2}), {:.0} active vertices per sub-step ({:.0} in the window), setup {setup:.0} ms ({:.1} MB)",
        100.0 * wet as f64 / fine_n as f64,
        radius.map_or("the whole flag".into(), |r| format!("{:.1} cm", 100.0 * r)),
        read * 1e3 / frames as f64,
        p.active_vertices as f64 / p.substeps as f64,
        p.window_vertices as f64 / p.substeps as f64,
        at_setup as f64 / 1e6,
    );
    println!(
        "    memory (resident set over the one before the setup): {:.1} MB after the frames ({:.0} bytes per built vertex, {:.0} per wet one), peak {:.1} MB ({:.0} per wet vertex)",
        held as f64 / 1e6,
        held as f64 / built as f64,
        held as f64 / wet.max(1) as f64,
        peak as f64 / 1e6,
        peak as f64 / wet.max(1) as f64,
    );
    let per = |s: f64| s * 1e3 / frames as f64;
    println!(
        "    per frame: window {:.1}, geometry {:.1}, forces {:.1}, advection {:.1} (traces {:.1}, plan {:.1}, cycles {:.1}), diffusion {:.1}, interactions {:.1} ms; {:.1} sub-steps, {:.1} transport cycles, CG iterations per sub-step {:.1} density (all fields) + {:.1} velocity, {} window rebuilds; read-outs checksum {checksum:016x}",
        per(p.window),
        per(p.geometry),
        per(p.forces),
        per(p.advection),
        per(p.advection_trace),
        per(p.advection_plan),
        per(p.advection_apply),
        per(p.diffusion),
        per(p.interaction),
        p.substeps as f64 / frames as f64,
        p.transport_cycles as f64 / frames as f64,
        p.density_iterations as f64 / p.substeps.max(1) as f64,
        p.velocity_iterations as f64 / p.substeps.max(1) as f64,
        p.window_rebuilds
    );
    (wet, fine_n)
}

/// The pour radius whose wet count at the last frame is within 5 % of `share` of the
/// refined cloth (bisection on untimed runs, at most 8).
fn calibrate(level: u32, share: f64, frames: usize) -> f64 {
    let (mut lo, mut hi) = (0.0, disk_radius(share));
    let mut radius = hi;
    for _ in 0..8 {
        let (wet, fine) = bench(level, Some(radius), 1, frames, false);
        let got = wet as f64 / fine as f64;
        if (got / share - 1.0).abs() <= 0.05 {
            break;
        }
        if got > share {
            hi = radius;
        } else {
            lo = radius;
            if radius >= hi {
                hi *= 1.5;
            }
        }
        radius = 0.5 * (lo + hi);
    }
    radius
}

/// Each case runs in a process of its own (the bench runs itself with the case's
/// arguments), so that its peak resident set is its own.
fn main() {
    const FRAMES: usize = 12;
    let args: Vec<String> = std::env::args().collect();
    if let Some(i) = args.iter().position(|a| a == "--case") {
        let level: u32 = args[i + 1].parse().unwrap();
        let radius: f64 = args[i + 2].parse().unwrap();
        let spacing: usize = args.get(i + 3).map_or(1, |k| k.parse().unwrap());
        bench(
            level,
            (radius > 0.0).then_some(radius),
            spacing,
            FRAMES,
            true,
        );
        return;
    }
    if let Some(i) = args.iter().position(|a| a == "--calibrate") {
        let level: u32 = args[i + 1].parse().unwrap();
        let share: f64 = args[i + 2].parse().unwrap();
        println!("{}", calibrate(level, share, FRAMES));
        return;
    }
    println!(
        "stain Detail on the waving flag, {} rayon threads",
        rayon::current_num_threads()
    );
    let exe = std::env::current_exe().unwrap();
    let run = |args: &[&str]| {
        let out = std::process::Command::new(&exe)
            .args(args)
            .output()
            .unwrap();
        eprint!("{}", String::from_utf8_lossy(&out.stderr));
        String::from_utf8_lossy(&out.stdout).into_owned()
    };
    let radius = run(&["--calibrate", "2", "0.1"]);
    // the two cases, then Detail 0 with Detail 2's pour (the same local stain at
    // the cloth's resolution), which splits the ratio into its factors; the cases run in
    // turn `rounds` times (the machine's speed drifts between minutes: each round's ratio
    // compares runs seconds apart), the first round's reports printed
    let rounds: usize = std::env::var("MADDER_BENCH_ROUNDS")
        .ok()
        .and_then(|r| r.parse().ok())
        .unwrap_or(3)
        .max(1);
    // and a fourth: Detail 0 on a cloth of Detail 2's spacing with the same pour (the
    // same stain on a cloth that is as fine as the refined one, no refinement)
    let radius = radius.trim();
    let specs = [
        ["0", "0", "1"],
        ["2", radius, "1"],
        ["0", radius, "1"],
        ["0", radius, "4"],
    ];
    // per case: ms a frame of every round, and its active vertices per sub-step
    let mut cases: Vec<(Vec<f64>, f64)> = vec![(Vec::new(), 0.0); specs.len()];
    for round in 0..rounds {
        for (case, [level, radius, spacing]) in cases.iter_mut().zip(specs) {
            let out = run(&["--case", level, radius, spacing]);
            if round == 0 {
                print!("{out}");
            }
            // the figures before " ms/frame" and " active vertices" on the case's first line
            let figure = |unit: &str| {
                out.split(unit)
                    .next()
                    .and_then(|head| head.rsplit(' ').next())
                    .and_then(|t| t.parse::<f64>().ok())
            };
            if let Some((ms, active)) = figure(" ms/frame").zip(figure(" active vertices")) {
                case.0.push(ms);
                case.1 = active;
            }
        }
    }
    if cases.iter().any(|c| c.0.len() != rounds) {
        println!("a case's figures could not be read: no ratio");
        return;
    }
    let median = |v: &[f64]| {
        let mut v = v.to_vec();
        v.sort_by(f64::total_cmp);
        let m = v.len() / 2;
        if v.len() % 2 == 1 {
            v[m]
        } else {
            0.5 * (v[m - 1] + v[m])
        }
    };
    let ratios: Vec<f64> = (0..rounds).map(|r| cases[1].0[r] / cases[0].0[r]).collect();
    let listed = |v: &[f64], digits: usize| {
        v.iter()
            .map(|x| format!("{x:.digits$}"))
            .collect::<Vec<_>>()
            .join(", ")
    };
    println!(
        "detail 2 at 10 % wet / detail 0 all wet: {:.2}× per frame (target ≤ 2×), the median of {rounds} rounds: {}",
        median(&ratios),
        listed(&ratios, 2),
    );
    let [
        (coarse, a_coarse),
        (fine, a_fine),
        (local, a_local),
        (native, a_native),
    ] = [0, 1, 2, 3].map(|k| (median(&cases[k].0), cases[k].1));
    println!(
        "    ms a frame, median (rounds): detail 0 all wet {coarse:.2} ({}), detail 2 {fine:.2} ({}), detail 0 with the same pour {local:.2} ({}), detail 0 with the same pour on a cloth of detail 2's spacing {native:.2} ({})",
        listed(&cases[0].0, 1),
        listed(&cases[1].0, 1),
        listed(&cases[2].0, 1),
        listed(&cases[3].0, 1),
    );
    let per = |ms: f64, active: f64| 1e3 * ms / active;
    let (c_coarse, c_fine, c_local) = (
        per(coarse, a_coarse),
        per(fine, a_fine),
        per(local, a_local),
    );
    println!(
        "    per active vertex and frame (medians): detail 0 all wet {c_coarse:.2} µs, detail 0 with the same pour {c_local:.2} µs, detail 2 {c_fine:.2} µs; the ratio of medians is {:.2} (active vertices) × {:.2} (a local stain's cost per vertex over the all-wet cloth's, at detail 0) × {:.2} (detail 2's over detail 0's on the same stain)",
        a_fine / a_coarse,
        c_local / c_coarse,
        c_fine / c_local,
    );
    let against_fine: Vec<f64> = (0..rounds).map(|r| cases[1].0[r] / cases[3].0[r]).collect();
    println!(
        "    detail 2 / detail 0 on a cloth of detail 2's spacing, the same stain: {:.2}× per frame (median of rounds: {}), {:.2}× per active vertex ({:.2} against {:.2} µs, {a_native:.0} active vertices)",
        median(&against_fine),
        listed(&against_fine, 2),
        c_fine / per(native, a_native),
        c_fine,
        per(native, a_native),
    );
}
