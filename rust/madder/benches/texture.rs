//! `make bench`: one 2048² frame of UV texture output (module `madder::texture`):
//! rasterize (without and with the weave's detail, issue 13 part 4), pad (4 texels) and
//! write the EXR, for two triangle loads built synthetically:
//!
//! - *fine*: a 20k-vertex cloth (a 140 × 140 grid of the unit square, 141² = 19,881
//!   vertices) refined 16× (Detail 2), i.e. a 560 × 560 grid, 627,200 small triangles of
//!   about 6.7 texels each;
//! - *coarse*: the 140 × 140 grid itself, 39,200 large triangles (about 107 texels).
//!
//! The grid is laid out in UV as two islands (left and right halves, a margin around
//! each), so that padding has seams and borders to grow. The field is RGBA: a stain (a
//! Gaussian spot over about a tenth of the cloth, zero elsewhere: a typical bake frame,
//! mostly empty) and, for the EXR only, a dense field too (every texel non-zero, the worst
//! case for compression). Prints figures (best and median of several runs, and the CPU
//! time of the process per run: on a machine shared with other work the wall time grows
//! much more than the CPU time); asserts nothing about time. `MADDER_BENCH_SIZE=1024`
//! changes the size; `MADDER_BENCH_PROFILE=n` (with `MADDER_BENCH_THREADS=t`) only
//! rasterizes the fine load n times into fresh memory (`MADDER_BENCH_WEAVE=1`: with the
//! weave's detail; `MADDER_BENCH_DENSE=1`: the dense field), `MADDER_BENCH_PROFILE_EXR=n`
//! only writes its EXR n times, for a profiler (`perf stat` / `perf record`).

use std::time::Instant;

use madder::texture::{self, Compression, Raster, WeaveDetail};
use madder::weave::{Corrector, PairCoefficients, Tile, Weave};

const CHANNELS: usize = 4;

/// A grid of `n × n` quads of the unit square (two triangles each), in UV as two islands.
struct Load {
    name: &'static str,
    faces: Vec<[u32; 3]>,
    uv: Vec<[[f64; 2]; 3]>,
    stain: Vec<f32>,
    dense: Vec<f32>,
}

fn load(name: &'static str, n: usize) -> Load {
    load_jittered(name, n, 0.0)
}

/// [`load`] with the interior vertices moved by a smooth displacement of up to `jitter`
/// grid steps (irregular triangles of every orientation; none flips for `jitter < ½`).
fn load_jittered(name: &'static str, n: usize, jitter: f64) -> Load {
    let idx = |i: usize, j: usize| (i * (n + 1) + j) as u32;
    let pos = |v: u32| {
        let (i, j) = (v as usize / (n + 1), v as usize % (n + 1));
        let (x, y) = (j as f64 / n as f64, i as f64 / n as f64);
        let inner = if i == 0 || j == 0 || i == n || j == n || 2 * j == n {
            0.0
        } else {
            jitter / n as f64
        };
        [
            x + inner * (7.3 * x + 3.1 * y).sin(),
            y + inner * (5.9 * x - 8.7 * y).cos(),
        ]
    };
    let mut faces = Vec::with_capacity(2 * n * n);
    for i in 0..n {
        for j in 0..n {
            let (a, b, c, d) = (idx(i, j), idx(i, j + 1), idx(i + 1, j + 1), idx(i + 1, j));
            faces.extend([[a, b, c], [a, c, d]]);
        }
    }
    // left half → [0.02, 0.48] × [0.02, 0.98], right half → [0.52, 0.98] × [0.02, 0.98]
    let uv = faces
        .iter()
        .map(|f| {
            let p = f.map(pos);
            let right = p.iter().map(|q| q[0]).sum::<f64>() / 3.0 > 0.5;
            p.map(|[x, y]| {
                let u = if right {
                    0.52 + (x - 0.5) * 0.92
                } else {
                    0.02 + x * 0.92
                };
                [u, 0.02 + y * 0.96]
            })
        })
        .collect();
    let nv = (n + 1) * (n + 1);
    let mut stain = Vec::with_capacity(nv * CHANNELS);
    let mut dense = Vec::with_capacity(nv * CHANNELS);
    for v in 0..nv as u32 {
        let [x, y] = pos(v);
        let r2 = (x - 0.35).powi(2) + (y - 0.6).powi(2);
        let s = (-r2 / 0.01).exp();
        let s = if s < 1e-3 { 0.0 } else { s as f32 };
        stain.extend([0.45 * s, 0.05 * s, 0.1 * s, s]);
        let d = (0.5 + 0.5 * (17.0 * x).sin() * (13.0 * y).cos()) as f32;
        dense.extend([d, 1.0 - d, 0.5 * d, 1.0]);
    }
    Load {
        name,
        faces,
        uv,
        stain,
        dense,
    }
}

/// CPU time of the whole process so far (user + system), in ms, from /proc/self/stat
/// (clock ticks of 10 ms: meaningful over several runs). `None` off Linux.
fn cpu_ms() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    // the fields after the command name (which is in parentheses and may hold spaces)
    let rest = &stat[stat.rfind(')')? + 2..];
    let f: Vec<&str> = rest.split(' ').collect();
    let ticks: f64 = f.get(11)?.parse::<f64>().ok()? + f.get(12)?.parse::<f64>().ok()?;
    Some(ticks * 10.0)
}

/// Timings of `runs` calls of `f`: best and median wall time, and the mean CPU time of
/// the process per call (all threads; on a machine shared with other work the wall time
/// grows, the CPU time much less), in ms.
struct Timing {
    best: f64,
    median: f64,
    cpu: Option<f64>,
}

impl std::fmt::Display for Timing {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{:6.1} ms (median {:6.1}", self.best, self.median)?;
        match self.cpu {
            Some(c) => write!(f, ", cpu {c:6.1})"),
            None => write!(f, ")"),
        }
    }
}

/// `", {r}× (cpu)"`: the ratio of the CPU times per run (steadier than the wall time on a
/// shared machine), when known.
fn cpu_ratio(a: &Timing, b: &Timing) -> String {
    match (a.cpu, b.cpu) {
        (Some(x), Some(y)) if y > 0.0 => format!(", {:.2}× (cpu)", x / y),
        _ => String::new(),
    }
}

fn time<T>(runs: usize, mut f: impl FnMut() -> T) -> (Timing, T) {
    let mut times = Vec::with_capacity(runs);
    let mut out = None;
    let cpu0 = cpu_ms();
    for _ in 0..runs {
        let t = Instant::now();
        out = Some(f());
        times.push(t.elapsed().as_secs_f64() * 1e3);
    }
    let cpu = cpu_ms().zip(cpu0).map(|(b, a)| (b - a) / runs as f64);
    times.sort_by(f64::total_cmp);
    let timing = Timing {
        best: times[0],
        median: times[runs / 2],
        cpu,
    };
    (timing, out.expect("runs ≥ 1"))
}

/// The weave's detail (issue 13 part 4) on every face: a plain weave with gaps at 1000
/// threads per UV unit (about half a thread per texel at 2048²), weft at 30°.
struct Woven {
    corr: Corrector,
    map: Vec<[f64; 4]>,
    fabric: Vec<u32>,
}

impl Woven {
    fn new(n_faces: usize) -> Woven {
        let corr = Corrector::of_tile(
            &Tile::builtin(Weave::Plain, true),
            &PairCoefficients::default(),
            [2.0, 2.0],
        )
        .unwrap();
        let (c, s) = (30f64.to_radians().cos(), 30f64.to_radians().sin());
        Woven {
            corr,
            map: vec![[1000.0 * c, 1000.0 * s, -1000.0 * s, 1000.0 * c]; n_faces],
            fabric: vec![0u32; n_faces],
        }
    }

    fn detail<'a>(&'a self, correctors: &'a [&'a Corrector]) -> WeaveDetail<'a> {
        WeaveDetail {
            correctors,
            face_fabric: &self.fabric,
            face_map: &self.map,
            uptake: &[true; CHANNELS],
        }
    }
}

/// The detail's cost on one load and thread count: with / without, best wall and CPU
/// time, for the typical frame and the dense one.
struct Ratios {
    typical: (f64, Option<f64>),
    dense: (f64, Option<f64>),
}

fn ratio(a: &Timing, b: &Timing) -> (f64, Option<f64>) {
    let cpu = a
        .cpu
        .zip(b.cpu)
        .filter(|(_, y)| *y > 0.0)
        .map(|(x, y)| x / y);
    (a.best / b.best, cpu)
}

fn bench(l: &Load, size: usize, threads: usize) -> Ratios {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    pool.install(|| {
        let (fresh, r) = time(9, || {
            texture::rasterize(&l.faces, &l.uv, &l.stain, CHANNELS, size).unwrap()
        });
        let mut reuse = Raster::empty(size, CHANNELS);
        let (reused, _) = time(9, || {
            texture::rasterize_into(&mut reuse, &l.faces, &l.uv, &l.stain, CHANNELS, size)
                .unwrap();
        });
        // pad's own time: the copies it works on are made beforehand
        let mut copies: Vec<Raster> = (0..9).map(|_| r.clone()).collect();
        let mut it = copies.iter_mut();
        let (padding, n) = time(9, || {
            texture::pad(it.next().unwrap(), texture::DEFAULT_PADDING)
        });
        let w = Woven::new(l.faces.len());
        let cs = [&w.corr];
        let detail = w.detail(&cs);
        let (woven, _) = time(9, || {
            texture::rasterize_with(&l.faces, &l.uv, &l.stain, CHANNELS, size, Some(&detail))
                .unwrap()
        });
        println!(
            "  {:>6}, {threads} thread(s): rasterize {fresh}, into a reused raster {reused}; pad 4 {padding}",
            l.name,
        );
        println!(
            "          with the weave's detail {woven}: {:.2}× the rasterization (best), {:.2}× (median){}",
            woven.best / fresh.best,
            woven.median / fresh.median,
            cpu_ratio(&woven, &fresh),
        );
        // the worst case: every texel stained (the detail is skipped where the field is 0)
        let (dense, _) = time(9, || {
            texture::rasterize(&l.faces, &l.uv, &l.dense, CHANNELS, size).unwrap()
        });
        let (dense_woven, _) = time(9, || {
            texture::rasterize_with(&l.faces, &l.uv, &l.dense, CHANNELS, size, Some(&detail))
                .unwrap()
        });
        println!(
            "          dense field: rasterize {dense}, with the detail {dense_woven}: {:.2}× (best), {:.2}× (median){}",
            dense_woven.best / dense.best,
            dense_woven.median / dense.median,
            cpu_ratio(&dense_woven, &dense),
        );
        if threads == 1 {
            println!(
                "          {} texels inside, {} padded, {} overlapping",
                r.inside_count(),
                n,
                r.overlapping
            );
        }
        Ratios {
            typical: ratio(&woven, &fresh),
            dense: ratio(&dense_woven, &dense),
        }
    })
}

fn bench_exr(l: &Load, size: usize) {
    let dir = std::env::temp_dir().join(format!("madder-bench-texture-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    for (what, values) in [("stain", &l.stain), ("dense", &l.dense)] {
        let mut r = texture::rasterize(&l.faces, &l.uv, values, CHANNELS, size).unwrap();
        texture::pad(&mut r, texture::DEFAULT_PADDING);
        for c in Compression::ALL {
            let path = dir.join(format!("{what}-{c:?}.exr"));
            let (write, _) = time(5, || {
                texture::write_exr_with(&path, &r.pixels, size, size, &["R", "G", "B", "A"], c)
                    .unwrap();
            });
            let bytes = std::fs::metadata(&path).unwrap().len();
            let (read, _) = time(3, || texture::read_exr(&path).unwrap());
            println!(
                "  write_exr {what:>5} {:<5} {write}, {:6.2} MB; read {:6.1} ms{}",
                format!("{c:?}"),
                bytes as f64 / 1e6,
                read.best,
                if c == texture::exr::DEFAULT_COMPRESSION {
                    "  <- default"
                } else {
                    ""
                }
            );
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// `MADDER_BENCH_BITS=dir`: rasterizes with the weave's detail the fine, coarse and a
/// jittered mesh, each with three fabrics (plain with gaps at 30°, twill 2/1 with gaps at
/// −73°, satin without gaps at 11°, about half a thread per texel) and both fields (4
/// channels, uptake on RGB, off on A), on 2 threads. Writes each image's `f32`s to `dir`
/// when the file is absent; otherwise compares with it and prints the largest absolute
/// difference (and the largest relative to the value), for checking that a change of the
/// texel pass moves the bits by no more than it says.
fn bits(dir: &std::path::Path, fine: &Load, size: usize) {
    std::fs::create_dir_all(dir).unwrap();
    let coarse = load("coarse", 140);
    let jitter = load_jittered("jitter", 300, 0.35);
    let fabrics = [
        (Weave::Plain, true, 2.0, 30.0, 1000.0),
        (Weave::Twill21, true, 3.0, -73.0, 900.0),
        (Weave::Satin5, false, 5.0, 11.0, 1100.0),
    ];
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(2)
        .build()
        .unwrap();
    let mut worst = (0.0f64, 0.0f64);
    for l in [fine, &coarse, &jitter] {
        for (weave, gaps, threads, angle, k) in fabrics {
            let corr = Corrector::of_tile(
                &Tile::builtin(weave, gaps),
                &PairCoefficients::default(),
                [threads; 2],
            )
            .unwrap();
            let (c, s) = (f64::to_radians(angle).cos(), f64::to_radians(angle).sin());
            let map = vec![[k * c, k * s, -k * s, k * c]; l.faces.len()];
            let fabric = vec![0u32; l.faces.len()];
            let cs = [&corr];
            let detail = WeaveDetail {
                correctors: &cs,
                face_fabric: &fabric,
                face_map: &map,
                uptake: &[true, true, true, false],
            };
            for (what, values) in [("stain", &l.stain), ("dense", &l.dense)] {
                let r = pool.install(|| {
                    texture::rasterize_with(&l.faces, &l.uv, values, CHANNELS, size, Some(&detail))
                        .unwrap()
                });
                let name = format!("{}-{weave:?}-{what}-{size}.f32", l.name);
                let path = dir.join(&name);
                let bytes: Vec<u8> = r.pixels.iter().flat_map(|x| x.to_le_bytes()).collect();
                let Ok(old) = std::fs::read(&path) else {
                    std::fs::write(&path, bytes).unwrap();
                    println!("  {name}: written");
                    continue;
                };
                let (mut abs, mut rel, mut differ) = (0.0f64, 0.0f64, 0usize);
                for (a, b) in old.chunks_exact(4).zip(bytes.chunks_exact(4)) {
                    let a = f32::from_le_bytes(a.try_into().unwrap()) as f64;
                    let b = f32::from_le_bytes(b.try_into().unwrap()) as f64;
                    let d = (a - b).abs();
                    differ += usize::from(d > 0.0);
                    abs = abs.max(d);
                    rel = rel.max(d / a.abs().max(1e-30));
                }
                println!(
                    "  {name}: {differ} values differ, max |Δ| {abs:.3e}, max |Δ|/|value| {rel:.3e}"
                );
                worst = (worst.0.max(abs), worst.1.max(rel));
            }
        }
    }
    println!("largest |Δ| {:.3e}, relative {:.3e}", worst.0, worst.1);
}

fn main() {
    let size: usize = std::env::var("MADDER_BENCH_SIZE")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(2048);
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    println!("texture: one {size}² RGBA frame, {cores} cores");
    let fine = load("fine", 560);
    // MADDER_BENCH_PROFILE_EXR=n: only n EXR writes of the fine load's stain (for perf)
    if let Some(n) = std::env::var("MADDER_BENCH_PROFILE_EXR")
        .ok()
        .and_then(|s| s.parse::<usize>().ok())
    {
        let mut r = texture::rasterize(&fine.faces, &fine.uv, &fine.stain, CHANNELS, size).unwrap();
        texture::pad(&mut r, texture::DEFAULT_PADDING);
        let path = std::env::temp_dir().join(format!("madder-bench-{}.exr", std::process::id()));
        for _ in 0..n {
            texture::write_exr(&path, &r.pixels, size, size, &["R", "G", "B", "A"]).unwrap();
        }
        let _ = std::fs::remove_file(&path);
        return;
    }
    // MADDER_BENCH_PROFILE=n: only n rasterizations of the fine load, on one thread or
    // MADDER_BENCH_THREADS (for perf)
    if let Some(n) = std::env::var("MADDER_BENCH_PROFILE")
        .ok()
        .and_then(|s| s.parse::<usize>().ok())
    {
        let threads = std::env::var("MADDER_BENCH_THREADS")
            .ok()
            .and_then(|s| s.parse().ok())
            .unwrap_or(1);
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        // MADDER_BENCH_WEAVE=1: with the weave's detail
        let woven = Woven::new(fine.faces.len());
        let cs = [&woven.corr];
        let detail = std::env::var_os("MADDER_BENCH_WEAVE").map(|_| woven.detail(&cs));
        // MADDER_BENCH_DENSE=1: the dense field (every texel stained)
        let field = if std::env::var_os("MADDER_BENCH_DENSE").is_some() {
            &fine.dense
        } else {
            &fine.stain
        };
        pool.install(|| {
            for _ in 0..n {
                // into fresh memory, with or without the detail, as `bench` compares them
                std::hint::black_box(
                    texture::rasterize_with(
                        &fine.faces,
                        &fine.uv,
                        field,
                        CHANNELS,
                        size,
                        detail.as_ref(),
                    )
                    .unwrap(),
                );
            }
        });
        return;
    }
    // MADDER_BENCH_BITS=dir: the detail's images for three meshes × three fabrics × two
    // fields, written to dir the first time, compared with what dir holds after
    if let Some(dir) = std::env::var_os("MADDER_BENCH_BITS") {
        bits(std::path::Path::new(&dir), &fine, size);
        return;
    }
    let coarse = load("coarse", 140);
    let mut summary = Vec::new();
    for l in [&fine, &coarse] {
        println!(
            "{}: {} triangles, {} vertices",
            l.name,
            l.faces.len(),
            l.stain.len() / CHANNELS
        );
        for threads in [1, cores] {
            summary.push((l.name, threads, bench(l, size, threads)));
        }
    }
    // issue 13's budget: the detail at most 1.5× the rasterization without it
    println!("weave detail / plain rasterization, {size}², best wall (CPU time):");
    let show = |(w, c): (f64, Option<f64>)| match c {
        Some(c) => format!("{w:.2}× ({c:.2}×)"),
        None => format!("{w:.2}×"),
    };
    for (name, threads, r) in &summary {
        println!(
            "  {name:>6}, {threads} thread(s): typical frame {}, every texel stained {}",
            show(r.typical),
            show(r.dense)
        );
    }
    println!("EXR (fine load, padded; {cores} cores):");
    bench_exr(&fine, size);
}
