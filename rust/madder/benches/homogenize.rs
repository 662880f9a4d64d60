//! `cargo bench -p madder --bench homogenize`: time to homogenize weave tiles (seed §2.2.2).
//! Prints figures; asserts nothing about time.
//!
//! - one discretization (primal + dual solve) of 32², 64², 128² tiles, and the primal alone;
//! - the default `homogenize` (reduction, levels, extrapolation) of random tiles that cannot
//!   be reduced, and of built-in weaves, cold (first use of a grid size: symbolic analysis
//!   included) and warm (grid shared), sequential and parallel;
//! - a custom grid of 2×1-rectangle cells (reduced by square blocks only);
//! - the cost of the extrapolation (its coarse level) and of a cache hit.

use std::hint::black_box;
use std::time::Instant;

use madder::weave::{
    Grid, HomogenizationCache, HomogenizeOptions, Homogenized, Method, PairCoefficients, Tensor2,
    Tile, Weave, cell_tensors, homogenize_report,
};

/// splitmix64
fn random_tile(n: usize, seed: u64) -> Vec<Tensor2> {
    let mut s = seed;
    let mut next = move || {
        s = s.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = s;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    };
    (0..n * n)
        .map(|_| {
            let (a, b, t) = (100f64.powf(next()), 100f64.powf(next()), next() * 3.2);
            let (s, c) = t.sin_cos();
            [
                a * c * c + b * s * s,
                (a - b) * c * s,
                a * s * s + b * c * c,
            ]
        })
        .collect()
}

/// Median and minimum of `reps` runs, in milliseconds.
fn time<T>(reps: usize, mut f: impl FnMut() -> T) -> (f64, f64) {
    let mut v: Vec<f64> = (0..reps)
        .map(|_| {
            let t = Instant::now();
            black_box(f());
            t.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    v.sort_by(f64::total_cmp);
    (v[v.len() / 2], v[0])
}

/// The grids a homogenization solved, coarse first: "w×h + w×h".
fn grid_sizes(r: &Homogenized) -> String {
    let (w, h) = r.reduced;
    let levels: Vec<String> = r
        .levels
        .iter()
        .map(|l| format!("{}×{}", w * l.refine, h * l.refine))
        .collect();
    levels.join(" + ")
}

fn main() {
    let threads = rayon::current_num_threads();
    rayon::join(|| (), || ()); // start the pool outside the timings
    println!("homogenization benchmark ({threads} rayon threads); times in ms, median (min)\n");

    println!("one discretization, P1 on the criss-cross torus (grid shared after the first call):");
    for n in [32usize, 64, 128] {
        let t = random_tile(n, n as u64);
        let ts = Instant::now();
        let grid = Grid::new(n, n).unwrap();
        let symbolic = ts.elapsed().as_secs_f64() * 1e3;
        let (p, pm) = time(7, || grid.effective(&t).unwrap());
        let (b, bm) = time(7, || grid.bounds(&t, true).unwrap());
        let (bs, bsm) = time(7, || grid.bounds(&t, false).unwrap());
        println!(
            "  {n:>3}²: grid + symbolic {symbolic:6.2} | primal {p:6.2} ({pm:.2}) | primal+dual parallel {b:6.2} ({bm:.2}), sequential {bs:6.2} ({bsm:.2}) | L nnz {}",
            grid.factor_nnz()
        );
    }

    println!("\nhomogenize (default options: reduce, finest level ≤ 128² cells, extrapolate):");
    let default = HomogenizeOptions::default();
    let seq = HomogenizeOptions {
        parallel: false,
        ..default
    };
    let no_extrapolation = HomogenizeOptions {
        method: Method::GeometricMean,
        ..default
    };
    for n in [32usize, 64, 128] {
        let t = random_tile(n, 1000 + n as u64);
        Grid::clear_shared();
        let tc = Instant::now();
        let r = homogenize_report(n, n, &t, &default).unwrap();
        let cold = tc.elapsed().as_secs_f64() * 1e3;
        let (warm, wm) = time(11, || homogenize_report(n, n, &t, &default).unwrap());
        let (s, sm) = time(11, || homogenize_report(n, n, &t, &seq).unwrap());
        let levels: Vec<String> = r
            .levels
            .iter()
            .map(|l| format!("{}²", n * l.refine))
            .collect();
        let extra = if r.levels.len() > 1 {
            let (g, gm) = time(11, || {
                homogenize_report(n, n, &t, &no_extrapolation).unwrap()
            });
            format!(
                "finest level only {g:6.2} ({gm:.2}) → the extrapolation's coarse level costs {:+.2}",
                warm - g
            )
        } else {
            "one level (no room to refine within 128² cells), nothing to extrapolate".to_string()
        };
        println!(
            "  random {n:>3}² (levels {:<10}): cold (builds the grids) {cold:6.2} | warm {warm:6.2} ({wm:.2}) | sequential {s:6.2} ({sm:.2}) | {extra}",
            levels.join(" + "),
        );
    }
    let d = PairCoefficients::default();
    for (weave, gaps) in [
        (Weave::Plain, true),
        (Weave::Twill21, true),
        (Weave::Satin5, true),
        (Weave::Basket, false),
    ] {
        let tile = Tile::builtin(weave, gaps);
        let s = cell_tensors(&tile, &d).unwrap();
        let (w, h) = (tile.width(), tile.height());
        let r = homogenize_report(w, h, &s, &default).unwrap();
        let (warm, wm) = time(7, || homogenize_report(w, h, &s, &default).unwrap());
        let (g, _) = time(5, || {
            homogenize_report(w, h, &s, &no_extrapolation).unwrap()
        });
        let (rw, rh) = r.reduced;
        println!(
            "  {:<8} gaps={:<5} {w}×{h} → {rw}×{rh} (levels {:<17}): {warm:6.2} ({wm:.2}) | finest only {g:6.2} | rigorous gap {:.1e}",
            format!("{weave:?}"),
            gaps,
            grid_sizes(&r),
            r.relative_gap()
        );
    }

    // a custom grid whose cells are 2×1 rectangles: reduced only by square blocks, so it
    // stays 4×2 (it used to be squeezed to a 2×2 checkerboard, and was 4 % off)
    let tile = Tile::parse("FFWW\nWWFF").unwrap();
    let s = cell_tensors(&tile, &d).unwrap();
    let r = homogenize_report(4, 2, &s, &default).unwrap();
    let (t, tm) = time(7, || homogenize_report(4, 2, &s, &default).unwrap());
    let (rw, rh) = r.reduced;
    println!(
        "  custom FFWW/WWFF 4×2 → {rw}×{rh} (levels {}): {t:6.2} ({tm:.2})",
        grid_sizes(&r)
    );

    // a 128² tile drawn from a weave at 16 pixels per cell reduces to the weave's own tile
    let tile = Tile::builtin(Weave::Twill31, true);
    let s = cell_tensors(&tile, &d).unwrap();
    let (w, k) = (tile.width(), 16);
    let big: Vec<Tensor2> = (0..(w * k) * (w * k))
        .map(|i| s[((i / (w * k)) / k) * w + (i % (w * k)) / k])
        .collect();
    let (t, tm) = time(7, || {
        homogenize_report(w * k, w * k, &big, &default).unwrap()
    });
    println!("  twill 3/1 drawn as a 128² image (reduces to {w}×{w}): {t:6.2} ({tm:.2})");

    let mut cache = HomogenizationCache::default();
    let t = random_tile(128, 7);
    cache.homogenize(128, 128, &t).unwrap();
    let (hit, hm) = time(21, || cache.homogenize(128, 128, &t).unwrap());
    let tile = Tile::builtin(Weave::Satin5, true);
    let s = cell_tensors(&tile, &d).unwrap();
    cache.homogenize(10, 10, &s).unwrap();
    let (hit_small, hsm) = time(21, || cache.homogenize(10, 10, &s).unwrap());
    println!(
        "\ncache hit (hash of the reduced tile): 128² tile {hit:.3} ({hm:.3}), 10×10 satin {hit_small:.4} ({hsm:.4})"
    );
}
