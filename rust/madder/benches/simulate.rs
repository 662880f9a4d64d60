//! `make bench`: time per frame of the full stain simulator (forces, advection, diffusion
//! of the densities and of the velocity, interactions) on a waving-flag grid, split into
//! its phases. Prints figures; asserts nothing about time. `MADDER_BENCH_WHOLE=1` steps
//! the whole mesh (no active region), `MADDER_BENCH_SMALL=1` only the 10k case,
//! `MADDER_BENCH_100K=1` only the 100k one, without the machine's limits (for profiling),
//! `MADDER_BENCH_PARTS=1` times the pieces one by one.
//!
//! **Cost follows the stain** (issue 16, target 3): the same pour on the 100k flag and on a
//! 1M-vertex cloth with the same vertex spacing (the grid scaled by 3.17 in both
//! directions, so the stain covers the same vertices and the rest of the cloth is dry):
//! the ratio of the per-frame times and the 1M simulator's construction time.
//!
//! On the 100k flag it also steps the default CG tolerances beside the former tight ones
//! and prints the largest difference of the outputs (`against_tight_solves`).
//!
//! **Close to the limit** (issue 16, target 4): after each case, per phase, the bytes and
//! flops the step must move and do at least ([`Profile::least_work`], the model in
//! `stain/work.rs`), the rates that makes, and the time the machine would need for that
//! much work at its measured limits ([`Machine`]): the bandwidth of the memory level the
//! phase's per-sweep working set fits in, or the multiply–add throughput, whichever is
//! slower. `× limit` is the measured time over that bound.

mod common;

use std::time::Instant;

use common::{grid, motion, pour, wave};
use faer::Par;
use madder::stain::{Conductivity, Profile, Simulator, StainParams};
use rayon::prelude::*;

/// The machine's limits as this build reaches them, over all rayon threads: the triad
/// `a = b + s c` (24 bytes an element) at working sets of 1, 16 and 256 MiB (served by
/// L2, L3 and DRAM on this machine's 2 MiB / 32 MiB caches), and the multiply–add rate on
/// an L1-resident array (the code the crate is compiled to: no `target-cpu`, so SSE2).
struct Machine {
    /// (working set in bytes, bytes per second), smallest first.
    levels: Vec<(f64, f64)>,
    /// Floating-point operations per second.
    flops: f64,
}

impl Machine {
    fn measure() -> Self {
        let best = |f: &mut dyn FnMut()| {
            let (mut best, start) = (f64::INFINITY, Instant::now());
            while start.elapsed().as_secs_f64() < 0.3 {
                let t = Instant::now();
                f();
                best = best.min(t.elapsed().as_secs_f64());
            }
            best
        };
        let levels = [1usize << 20, 16 << 20, 256 << 20]
            .iter()
            .map(|&bytes| {
                let n = bytes / 24;
                let (b, c) = (vec![1.0f64; n], vec![2.0f64; n]);
                let mut a = vec![0.0f64; n];
                // one chunk per thread, swept `reps` times in a row, so that the pool's
                // hand-over is a small share even when the sweep sits in L2
                let chunk = n.div_ceil(rayon::current_num_threads());
                let reps = (256 << 20) / bytes;
                let t = best(&mut || {
                    a.par_chunks_mut(chunk)
                        .zip(b.par_chunks(chunk))
                        .zip(c.par_chunks(chunk))
                        .for_each(|((a, b), c)| {
                            for _ in 0..reps {
                                for ((a, b), c) in a.iter_mut().zip(b).zip(c) {
                                    *a = b + 0.5 * c;
                                }
                                std::hint::black_box(&mut *a);
                            }
                        });
                });
                (bytes as f64, 24.0 * (n * reps) as f64 / t)
            })
            .collect();
        let threads = rayon::current_num_threads();
        let (len, reps) = (256, 20_000);
        let t = best(&mut || {
            (0..threads).into_par_iter().for_each(|k| {
                let mut y = vec![k as f64; len];
                for _ in 0..reps {
                    for y in y.iter_mut() {
                        *y = *y * 0.999_999 + 1e-6;
                    }
                    std::hint::black_box(&mut y);
                }
            });
        });
        let flops = 2.0 * (len * reps * threads) as f64 / t;
        Self { levels, flops }
    }

    /// The bandwidth of the smallest level that holds `working_set` bytes, and its name.
    fn bandwidth(&self, working_set: f64) -> (f64, &'static str) {
        let names = ["L2", "L3", "DRAM"];
        let k = self
            .levels
            .iter()
            .position(|&(size, _)| working_set <= size)
            .unwrap_or(self.levels.len() - 1);
        (self.levels[k].1, names[k])
    }

    fn describe(&self) -> String {
        format!(
            "machine limits ({} threads, as built): triad {}, multiply-add {:.1} GFLOP/s",
            rayon::current_num_threads(),
            self.levels
                .iter()
                .zip(["L2", "L3", "DRAM"])
                .map(|(&(size, bw), name)| format!(
                    "{name} ({:.0} MiB) {:.1} GB/s",
                    size / (1u64 << 20) as f64,
                    bw * 1e-9
                ))
                .collect::<Vec<_>>()
                .join(", "),
            self.flops * 1e-9
        )
    }
}

/// Prints, per phase and frame, the least bytes and flops, the rates achieved and the
/// distance from the machine's limit (module doc).
fn report_limits(p: &Profile, frames: usize, machine: &Machine) {
    println!(
        "    {:<12}{:>9}{:>11}{:>12}{:>8}{:>9}{:>10}{:>9}  served by",
        "phase", "ms/frame", "least MB", "least Mflop", "GB/s", "GFLOP/s", "limit ms", "× limit"
    );
    let per = frames as f64;
    for w in p.least_work() {
        let (bw, level) = machine.bandwidth(w.working_set);
        let limit = (w.bytes / bw).max(w.flops / machine.flops);
        let bound = if w.bytes / bw >= w.flops / machine.flops {
            level
        } else {
            "flops"
        };
        println!(
            "    {:<12}{:>9.2}{:>11.1}{:>12.1}{:>8.1}{:>9.2}{:>10.3}{:>9.0}  {bound} ({:.1} MB a sweep)",
            w.name,
            w.seconds * 1e3 / per,
            w.bytes * 1e-6 / per,
            w.flops * 1e-6 / per,
            w.bytes / w.seconds.max(1e-12) * 1e-9,
            w.flops / w.seconds.max(1e-12) * 1e-9,
            limit * 1e3 / per,
            w.seconds / limit.max(1e-12),
            w.working_set * 1e-6,
        );
    }
}

/// Steps the pour on an `nx` × `ny` flag grid scaled by `scale`; prints the phases and
/// returns (construction, per frame) in ms.
fn bench(nx: usize, ny: usize, frames: usize, scale: f64, machine: Option<&Machine>) -> (f64, f64) {
    let (topo, mut rest) = grid(nx, ny);
    rest.iter_mut().for_each(|p| *p *= scale);
    let n = topo.n_vertices();
    let dt = 1.0 / 24.0;
    let t = Instant::now();
    let mut sim = Simulator::new(
        topo,
        &rest,
        &wave(&rest, 0.0),
        Conductivity::default(), // the add-on's default, DEFAULT_DIFFUSION
        StainParams {
            // MADDER_BENCH_WHOLE: step the whole mesh (no active region)
            active_region: std::env::var("MADDER_BENCH_WHOLE").is_err(),
            ..Default::default()
        },
        [0.4, 0.05, 0.1],
        Par::Seq,
    )
    .unwrap();
    let setup = t.elapsed().as_secs_f64() * 1e3;
    sim.add_liquid(&pour(&rest), 0.05, None).unwrap();
    let cloth = motion(&rest, frames, dt);
    let t = Instant::now();
    for f in 1..=frames {
        sim.step(&cloth[f], dt, Some(&cloth[f + 1])).unwrap();
    }
    let total = t.elapsed().as_secs_f64() * 1e3 / frames as f64;
    // MADDER_BENCH_DUMP=dir: the last frame's solute density and wetness, raw f64 (to
    // compare two builds' results, issue 16's before/after errors)
    if let Ok(dir) = std::env::var("MADDER_BENCH_DUMP") {
        let bytes: Vec<u8> = sim
            .solute_density()
            .iter()
            .chain(&sim.wetness())
            .flat_map(|v| v.to_le_bytes())
            .collect();
        std::fs::write(format!("{dir}/{n}-{frames}.f64"), bytes).unwrap();
    }
    let p = sim.profile();
    let per = |s: f64| s * 1e3 / frames as f64;
    // FNV-1a over the bits of the state: equal checksums = bit-identical results
    let f = sim.fields();
    let bits = f
        .free_solvent
        .iter()
        .chain(&f.solute)
        .chain(&f.absorbed_solvent)
        .chain(&f.absorbed_solute)
        .chain(&f.adsorbed)
        .copied()
        .chain(sim.velocity().iter().flat_map(|u| [u.x, u.y]))
        .map(f64::to_bits);
    let checksum = bits.fold(0xcbf2_9ce4_8422_2325_u64, |h, b| {
        (h ^ b).wrapping_mul(0x0100_0000_01b3)
    });
    println!(
        "{n:>7} vertices, {frames} frames: {total:7.2} ms/frame ({:.1} sub-steps, setup {setup:.0} ms) = window {:.2}, geometry+frames+transport {:.2}, forces {:.2}, advection {:.2} (back-traces {:.2}, fluxes+plan {:.2}, sub-cycles {:.2} at {:.2} cycles/sub-step), diffusion {:.2} (density {:.1} + velocity {:.1} CG it.), interactions {:.2}; window {:.1} %, active {:.1} % of the vertices ({} rebuilds); state checksum {checksum:016x}",
        p.substeps as f64 / frames as f64,
        per(p.window),
        per(p.geometry),
        per(p.forces),
        per(p.advection),
        per(p.advection_trace),
        per(p.advection_plan),
        per(p.advection_apply),
        p.transport_cycles as f64 / p.substeps as f64,
        per(p.diffusion),
        p.density_iterations as f64 / frames as f64,
        p.velocity_iterations as f64 / frames as f64,
        per(p.interaction),
        100.0 * p.window_vertices as f64 / (p.substeps * n) as f64,
        100.0 * p.active_vertices as f64 / (p.substeps * n) as f64,
        p.window_rebuilds,
    );
    if let Some(machine) = machine {
        report_limits(&p, frames, machine);
    }
    (setup, total)
}

fn main() {
    println!(
        "full stain simulator on a waving flag grid, {} rayon threads (default parameters: sub-steps as the frames' turn needs, all physics on)",
        rayon::current_num_threads()
    );
    if std::env::var("MADDER_BENCH_PARTS").is_ok() {
        parts(127, 77, 50);
        return;
    }
    if std::env::var("MADDER_BENCH_100K").is_ok() {
        bench(407, 245, 12, 1.0, None);
        return;
    }
    let machine = Machine::measure();
    println!("{}", machine.describe());
    bench(127, 77, 48, 1.0, Some(&machine)); // ≈ 10k vertices
    if std::env::var("MADDER_BENCH_SMALL").is_ok() {
        return;
    }
    let (_, small) = bench(407, 245, 12, 1.0, Some(&machine)); // ≈ 100k vertices
    against_tight_solves(407, 245, 12);
    // ≈ 1M vertices at the 100k grid's spacing: the same stain on a cloth 10× the area
    let (setup, large) = bench(1290, 775, 12, 1290.0 / 407.0, Some(&machine));
    println!(
        "cost follows the stain: the same pour on 1M vertices (same spacing) {large:.1} ms/frame = {:.2}× the 100k cloth's {small:.1} (target ≤ 2×); 1M construction {setup:.0} ms (target ≤ 1000)",
        large / small
    );
}

/// What the CG tolerances change (issue 16): the same run with the default tolerances and
/// with the former 1e-9 (densities) / 1e-8 (velocity), stepped side by side; prints the
/// largest difference of any vertex's wetness and solute density over the frames,
/// relative to the field's peak (an 8-bit channel resolves 3.9e-3), and the iterations.
fn against_tight_solves(nx: usize, ny: usize, frames: usize) {
    let (topo, rest) = grid(nx, ny);
    let dt = 1.0 / 24.0;
    let make = || {
        let mut sim = Simulator::new(
            topo.clone(),
            &rest,
            &wave(&rest, 0.0),
            Conductivity::default(),
            StainParams::default(),
            [0.4, 0.05, 0.1],
            Par::Seq,
        )
        .unwrap();
        sim.add_liquid(&pour(&rest), 0.05, None).unwrap();
        sim
    };
    let (mut loose, mut tight) = (make(), make());
    tight.set_solver_tolerances(1e-9, 1e-8);
    let cloth = motion(&rest, frames, dt);
    let (mut dw, mut ds, mut pw, mut ps) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
    for f in 1..=frames {
        for sim in [&mut loose, &mut tight] {
            sim.step(&cloth[f], dt, Some(&cloth[f + 1])).unwrap();
        }
        let pairs = [
            (loose.wetness(), tight.wetness(), &mut dw, &mut pw),
            (
                loose.solute_density(),
                tight.solute_density(),
                &mut ds,
                &mut ps,
            ),
        ];
        for (a, b, d, peak) in pairs {
            for (x, y) in a.iter().zip(&b) {
                *d = d.max((x - y).abs());
                *peak = peak.max(y.abs());
            }
        }
    }
    let it = |sim: &Simulator| {
        let p = sim.profile();
        let k = p.substeps as f64;
        (
            p.density_iterations as f64 / k,
            p.velocity_iterations as f64 / k,
        )
    };
    let ((ld, lv), (td, tv)) = (it(&loose), it(&tight));
    println!(
        "{:>7} vertices, {frames} frames, default CG tolerances against 1e-9/1e-8: largest difference over the frames {:.1e} of the peak wetness, {:.1e} of the peak solute density (8-bit step 3.9e-3); CG iterations per sub-step, densities {ld:.1} vs {td:.1}, velocity {lv:.1} vs {tv:.1}",
        topo.n_vertices(),
        dw / pw,
        ds / ps,
    );
}

/// `MADDER_BENCH_PARTS=1`: the step's pieces timed one by one on the whole mesh.
fn parts(nx: usize, ny: usize, reps: usize) {
    use madder::mesh::{Geometry, OneRings, Transport, VertexFrames, one_ring_rotations};
    use madder::stain::advect::{UpwindPlan, advect_velocity, dual_fluxes};
    let (topo, rest) = grid(nx, ny);
    let q = wave(&rest, 0.3);
    let rings = OneRings::new(&topo);
    let rf = VertexFrames::new(&rings, &rest).unwrap();
    // MADDER_BENCH_ONLY=name: repeat only that piece (the others run once), e.g. to count
    // one piece's instructions under valgrind
    let only = std::env::var("MADDER_BENCH_ONLY").ok();
    let time = |name: &str, f: &mut dyn FnMut()| {
        if only.as_ref().is_some_and(|o| o != name) {
            f();
            return;
        }
        let t = Instant::now();
        for _ in 0..reps {
            f();
        }
        println!(
            "  {name:<28} {:7.3} ms",
            t.elapsed().as_secs_f64() * 1e3 / reps as f64
        );
    };
    let mut g = Geometry::new(&topo, &q).unwrap();
    time("geometry", &mut || g = Geometry::new(&topo, &q).unwrap());
    let mut rot = Vec::new();
    time("kabsch rotations", &mut || {
        rot = one_ring_rotations(&topo, &rest, &q).unwrap();
    });
    let mut fr = rf.clone();
    time("frames rotated", &mut || fr = rf.rotated(&rot));
    let mut transport = Transport::new(&topo, &rings, &g, &fr, &q);
    time("transport", &mut || {
        transport = Transport::new(&topo, &rings, &g, &fr, &q);
    });
    let u: Vec<glam::DVec2> = (0..topo.n_vertices())
        .map(|i| glam::DVec2::new(0.1, 0.05 * (i as f64).sin()))
        .collect();
    let mut a = Vec::new();
    time("advect velocity", &mut || {
        a = advect_velocity(&topo, &rings, &g, &transport, &u, 1.0 / 24.0);
    });
    // the same field scaled so that a trace crosses about 7 cells, as on the Blender flag
    let mean_edge = g.edge_length.iter().sum::<f64>() / g.edge_length.len() as f64;
    let long: Vec<glam::DVec2> = u
        .iter()
        .map(|&x| x * (7.0 * mean_edge * 24.0 / 0.11))
        .collect();
    let mut b = Vec::new();
    time("advect velocity, ~7 cells", &mut || {
        b = advect_velocity(&topo, &rings, &g, &transport, &long, 1.0 / 24.0);
    });
    let mut fl = Vec::new();
    time("dual fluxes", &mut || fl = dual_fluxes(&topo, &q, &fr, &a));
    let mut m: Vec<f64> = (0..topo.n_vertices()).map(|i| (i % 7) as f64).collect();
    time("upwind plan", &mut || {
        std::hint::black_box(UpwindPlan::new(&topo, &g.vertex_area, &fl, 1.0 / 24.0).unwrap());
    });
    time("plan + transport 2 fields", &mut || {
        let plan = UpwindPlan::new(&topo, &g.vertex_area, &fl, 1.0 / 24.0).unwrap();
        let mut m2 = m.clone();
        plan.transport_all(&topo, &mut [&mut m, &mut m2]);
    });
    // the Blender flag's case: five fields and the momentum
    let mut five: Vec<Vec<f64>> = (0..5).map(|_| m.clone()).collect();
    time("plan + 5 fields + momentum", &mut || {
        let plan = UpwindPlan::new(&topo, &g.vertex_area, &fl, 1.0 / 24.0).unwrap();
        let mut fields: Vec<&mut [f64]> = five.iter_mut().map(|f| f.as_mut_slice()).collect();
        std::hint::black_box(plan.transport_with_momentum(&topo, &transport, &mut fields, &a, &a));
    });
}
