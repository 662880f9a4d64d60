//! `make bench`: surfaces from angles (`madder::angles`, seed ch. 3). Prints figures; asserts
//! nothing about time.
//!
//! Spectral reconstruction of a closed mesh (a wavy torus, 10k and 100k vertices) from its
//! exact angles and from angles with ±10 % dihedral noise, and the sequential baseline on the
//! same input. Targets (issue 15): 10k ≤ 1 s, 100k ≤ 15 s on 2 cores.
//!
//! Decoding a deforming cloth frame by frame: a square sheet (10k and 100k vertices) rolled
//! about a turning axis with a breathing curvature and a small ripple (smooth,
//! near-isometric), 25 frames a second; frame 0 is decoded cold, each next frame from the
//! previous decode, by the warm-started spectral method (`AngleMesh::reconstruct_warm`) and
//! by the tracked reconstruction (`AngleMesh::reconstruct_tracked`, as the codec decodes:
//! from the previous two tracked decodes extrapolated linearly).
//! Printed: the time per warm frame (min and max over the frames), the cold time of the
//! same frames, the largest warm − cold gap over the bounding box; for the tracked one its
//! time per frame (the first call also factorizes the two Laplacians, once per mesh: its
//! time is printed apart), its rounds and its largest error against the true shape. Target
//! (issue 15): a 100k warm frame ≤ 100 ms on 2 cores.

use std::f64::consts::PI;
use std::time::Instant;

use glam::DVec3;
use madder::angles::{AngleMesh, Angles, Placement, ReconstructOptions};
use madder::rng::SplitMix64;

// the deforming cloth of the module doc and the bounding-box diagonal, shared with the tests
#[path = "../tests/angles_common/mod.rs"]
mod angles_common;
use angles_common::{bbox_diagonal, cloth};

fn torus(nu: usize, nv: usize) -> (Vec<[u32; 3]>, Vec<DVec3>) {
    let idx = |i: usize, j: usize| ((i % nu) * nv + (j % nv)) as u32;
    let mut f = Vec::with_capacity(2 * nu * nv);
    for i in 0..nu {
        for j in 0..nv {
            let (a, b, c, d) = (idx(i, j), idx(i + 1, j), idx(i + 1, j + 1), idx(i, j + 1));
            f.extend([[a, b, c], [a, c, d]]);
        }
    }
    let mut x = Vec::with_capacity(nu * nv);
    for i in 0..nu {
        for j in 0..nv {
            let u = 2.0 * PI * i as f64 / nu as f64;
            let v = 2.0 * PI * j as f64 / nv as f64;
            let r = 0.4 * (1.0 + 0.15 * (5.0 * u).sin() * (3.0 * v).cos());
            let big = 1.0 + r * v.cos();
            x.push(DVec3::new(big * u.cos(), big * u.sin(), r * v.sin()));
        }
    }
    (f, x)
}

fn noisy(a: &Angles, pct: f64) -> Angles {
    let mut rng = SplitMix64::new(1);
    Angles {
        corners: a.corners.clone(),
        dihedrals: a
            .dihedrals
            .iter()
            .map(|d| d * (1.0 + pct / 100.0 * (2.0 * rng.unit() - 1.0)))
            .collect(),
    }
}

fn case(nu: usize, nv: usize) {
    let (f, x) = torus(nu, nv);
    let t = Instant::now();
    let mesh = AngleMesh::new(x.len(), f).unwrap();
    let exact = mesh.encode(&x).unwrap();
    let t_encode = t.elapsed().as_secs_f64();
    println!(
        "torus {} vertices, {} faces: connectivity + encode {:.3} s",
        x.len(),
        mesh.n_faces(),
        t_encode
    );
    for (label, a) in [
        ("exact", exact.clone()),
        ("10 % noise", noisy(&exact, 10.0)),
    ] {
        let t = Instant::now();
        let r = mesh
            .reconstruct(&a, &ReconstructOptions::default())
            .unwrap();
        let t_rec = t.elapsed().as_secs_f64();
        let t = Instant::now();
        let _ = mesh.sequential(&a, None).unwrap();
        let t_seq = t.elapsed().as_secs_f64();
        println!(
            "  {label:10}: spectral {t_rec:.3} s ({} rounds, λ/diag {:.1e} {:.1e} {:.1e} | {:.1e}), sequential {t_seq:.3} s",
            r.rounds, r.eigenvalues[0], r.eigenvalues[1], r.eigenvalues[2], r.eigenvalues[3]
        );
    }
}

fn warm_case(n: usize, frames: usize) {
    let (f, x0) = cloth(n, 0.0);
    let mesh = AngleMesh::new(x0.len(), f.clone()).unwrap();
    // cold decodes on a clone, which has its own solver cache
    let other = mesh.clone();
    let opts = |x: &[DVec3]| ReconstructOptions {
        placement: Some(Placement::of_face(&f, x, f.len() / 2).unwrap()),
        ..Default::default()
    };
    let t = Instant::now();
    let mut previous = mesh
        .reconstruct(&mesh.encode(&x0).unwrap(), &opts(&x0))
        .unwrap()
        .positions;
    let t_first = t.elapsed().as_secs_f64();
    let (mut warm, mut cold, mut gap) = (Vec::new(), Vec::new(), 0.0f64);
    let (mut tracked, mut tgap, mut trounds) = (Vec::new(), 0.0f64, Vec::new());
    let mut set_up = 0.0;
    let (mut previous_tracked, mut before) = (previous.clone(), None::<Vec<DVec3>>);
    let mut rounds = Vec::new();
    for k in 1..=frames {
        let (_, x) = cloth(n, k as f64 / 25.0);
        let a = mesh.encode(&x).unwrap();
        let t = Instant::now();
        let w = mesh.reconstruct_warm(&a, &previous, &opts(&x)).unwrap();
        warm.push(t.elapsed().as_secs_f64());
        rounds.push(w.rounds);
        let t = Instant::now();
        let c = other.reconstruct(&a, &opts(&x)).unwrap();
        cold.push(t.elapsed().as_secs_f64());
        if k == 1 {
            // the Laplacians' factorization, once per mesh
            let t = Instant::now();
            let _ = mesh
                .clone()
                .reconstruct_tracked(&a, &previous_tracked, &opts(&x));
            set_up = t.elapsed().as_secs_f64();
        }
        // as the codec decodes: from the previous two decodes extrapolated, when there are two
        let t = Instant::now();
        let start: Vec<DVec3> = match &before {
            Some(b) => previous_tracked
                .iter()
                .zip(b)
                .map(|(p, q)| 2.0 * *p - *q)
                .collect(),
            None => previous_tracked.clone(),
        };
        let tr = mesh
            .reconstruct_tracked(&a, &start, &opts(&x))
            .unwrap()
            .expect("the rotations settle");
        if k > 1 {
            tracked.push(t.elapsed().as_secs_f64());
        }
        trounds.push(tr.rounds);
        let d = tr
            .positions
            .iter()
            .zip(&x)
            .map(|(p, q)| (*p - *q).length())
            .fold(0.0, f64::max);
        tgap = tgap.max(d / bbox_diagonal(&x));
        before = Some(std::mem::replace(&mut previous_tracked, tr.positions));
        let d = w
            .positions
            .iter()
            .zip(&c.positions)
            .map(|(p, q)| (*p - *q).length())
            .fold(0.0, f64::max);
        gap = gap.max(d / bbox_diagonal(&x));
        previous = w.positions;
    }
    let range = |v: &[f64]| {
        let lo = v.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = v.iter().copied().fold(0.0, f64::max);
        format!("{lo:.3}–{hi:.3} s")
    };
    println!(
        "cloth {} vertices, {frames} frames: first (cold) {t_first:.3} s; warm {} per frame \
         (rounds {rounds:?}), cold {}; max |warm − cold| / diagonal {gap:.1e}",
        x0.len(),
        range(&warm),
        range(&cold),
    );
    println!(
        "  tracked {} per frame after the first (rotation rounds {trounds:?}; first call \
         {set_up:.3} s with the factorizations); max |tracked − true| / diagonal {tgap:.1e}",
        range(&tracked)
    );
}

fn main() {
    println!(
        "angles bench, {} rayon threads",
        rayon::current_num_threads()
    );
    case(125, 80);
    warm_case(99, 4);
    if std::env::var_os("MADDER_BENCH_QUICK").is_none() {
        case(400, 250);
        warm_case(316, 4);
    }
}
