//! The weave back at texture resolution (issue 13 part 4): the cell problem's correctors
//! (`weave::Corrector`) against closed forms and the effective tensor, and the texel pass
//! (`texture::rasterize_with`) against exact properties:
//!
//! - a laminate's corrector is the closed-form piecewise-linear function, and its energy
//!   the harmonic / arithmetic means;
//! - `⟨(e_i + ∇χ_i)ᵀ a (e_j + ∇χ_j)⟩` from the stored corrector equals the primal bound of
//!   the same discretization, and lies in the homogenization's bracket;
//! - every texel is the two-scale formula `U σ0 + (χ − m)·∇_y σ0` (and `σ0 + χ·∇_y σ0`
//!   without uptake) evaluated in `f64` from the corrector's own `chi` and `uptake_at`
//!   at the texel centre's tile coordinate (a turned map, negative tile coordinates);
//! - the detail integrates to zero over whole tiles (mass within 1e-6) with a gradient and
//!   the uptake contrast;
//! - absent where the stain is flat with no uptake contrast (equal to the plain raster);
//! - faces without a fabric are the plain raster bit for bit; the same bits on 1 and 2
//!   threads; a channel's texels the same bits whatever the channel count (the kernels
//!   for 1–4 channels and for any count agree); bad input names the face.

use madder::error::TextureError;
use madder::texture::{NO_WEAVE, WeaveDetail, rasterize, rasterize_with};
use madder::weave::{
    COVER_FACTOR, Cell, Corrector, Grid, HomogenizeOptions, PairCoefficients, Tile, Weave,
    cell_tensors, homogenize_report,
};

/// Faces, their corner UVs and the vertices' UVs.
type Square = (Vec<[u32; 3]>, Vec<[[f64; 2]; 3]>, Vec<[f64; 2]>);

/// `n × n` quads of the unit square in UV, two triangles each; vertex `(i, j)` at
/// `(j/n, i/n)`.
fn square(n: usize) -> Square {
    let idx = |i: usize, j: usize| (i * (n + 1) + j) as u32;
    let pos: Vec<[f64; 2]> = (0..(n + 1) * (n + 1))
        .map(|v| {
            [
                (v % (n + 1)) as f64 / n as f64,
                (v / (n + 1)) as f64 / n as f64,
            ]
        })
        .collect();
    let mut faces = Vec::new();
    for i in 0..n {
        for j in 0..n {
            let (a, b, c, d) = (idx(i, j), idx(i, j + 1), idx(i + 1, j + 1), idx(i + 1, j));
            faces.extend([[a, b, c], [a, c, d]]);
        }
    }
    let uv = faces.iter().map(|f| f.map(|v| pos[v as usize])).collect();
    (faces, uv, pos)
}

fn plain_with_gaps() -> Corrector {
    Corrector::of_tile(
        &Tile::builtin(Weave::Plain, true),
        &PairCoefficients::default(),
        [2.0, 2.0],
    )
    .unwrap()
}

#[test]
fn laminate_corrector_is_the_closed_form() {
    // stripes along x: columns of conductivity k, isotropic cells
    let k = [1.0, 4.0, 2.0, 8.0];
    let tensors: Vec<[f64; 3]> = k.iter().map(|&k| [k, 0.0, k]).collect();
    let c = Corrector::new(4, 1, &tensors, &[1.0; 4], [4.0, 1.0]).unwrap();
    let r = c.refine();
    let harmonic = 4.0 / k.iter().map(|k| 1.0 / k).sum::<f64>();
    let arithmetic = k.iter().sum::<f64>() / 4.0;
    // (1 + χ') k = H: χ(x) = ∫₀ˣ (H/k − 1), piecewise linear with kinks on cell edges
    let big_f = |x: f64| {
        let mut s = 0.0;
        for (i, &ki) in k.iter().enumerate() {
            let len = (x - i as f64).clamp(0.0, 1.0);
            s += len * (harmonic / ki - 1.0);
        }
        s
    };
    let (gw, gh) = (4 * r, r);
    let exact: Vec<f64> = (0..gw * gh)
        .map(|v| big_f((v % gw) as f64 / r as f64))
        .collect();
    let mean = exact.iter().sum::<f64>() / exact.len() as f64;
    for (v, (&got, &want)) in c.samples(0).iter().zip(&exact).enumerate() {
        assert!(
            (got - (want - mean)).abs() < 1e-12,
            "χ_x at {v}: {got} vs {}",
            want - mean
        );
    }
    assert!(c.samples(1).iter().all(|x| x.abs() < 1e-12));
    let e = c.energy();
    assert!((e[0] - harmonic).abs() < 1e-12 * harmonic, "{e:?}");
    assert!(e[1].abs() < 1e-12 && (e[2] - arithmetic).abs() < 1e-12 * arithmetic);
    // and the bilinear read-out between samples is the same piecewise-linear function
    let x = 1.3;
    assert!((c.chi([x, 0.37])[0] - (big_f(x) - mean)).abs() < 1e-12);
}

#[test]
fn corrector_energy_reproduces_the_effective_tensor() {
    let tile = Tile::builtin(Weave::Twill21, true);
    let coefficients = PairCoefficients::default();
    let c = Corrector::of_tile(&tile, &coefficients, [3.0, 3.0]).unwrap();
    let r = c.refine();
    let (w, h) = (tile.width(), tile.height());
    // the same discretization's primal bound, computed by the homogenization's own path
    let tensors = cell_tensors(&tile, &coefficients).unwrap();
    let fine = madder::weave::homogenize::refine(w, h, &tensors, r).unwrap();
    let upper = Grid::new(w * r, h * r)
        .unwrap()
        .bounds(&fine, false)
        .unwrap()
        .upper;
    let e = c.energy();
    for k in 0..3 {
        assert!(
            (e[k] - upper[k]).abs() <= 1e-10 * upper[0],
            "{e:?} vs {upper:?}"
        );
        assert!((c.upper()[k] - upper[k]).abs() <= 1e-12 * upper[0]);
    }
    // inside the bracket of the homogenization, close to its estimate
    let hom = homogenize_report(w, h, &tensors, &HomogenizeOptions::default()).unwrap();
    for k in [0, 2] {
        assert!(e[k] >= hom.lower[k] && e[k] <= upper[k] * (1.0 + 1e-12));
        assert!(
            (e[k] - hom.tensor[k]).abs() < 2e-3 * hom.tensor[k],
            "{e:?} vs {:?}",
            hom.tensor
        );
    }
    // zero mean, uptake of mean 1 with contrast: relative to a yarn on the face, a yarn on
    // the back keeps 0.9 and a gap 1 − (1 − C)/¼ (a quarter of the twill's cells are gaps)
    for i in 0..2 {
        assert!(c.samples(i).iter().sum::<f64>().abs() < 1e-12 * c.samples(i).len() as f64);
    }
    let u = c.uptake();
    assert!((u.iter().sum::<f64>() / u.len() as f64 - 1.0).abs() < 1e-15);
    let cells = tile.cells();
    assert_eq!(
        cells.iter().filter(|&&k| k == Cell::Gap).count() * 4,
        cells.len()
    );
    let face = u[cells
        .iter()
        .position(|&k| k == Cell::Weft { up: true })
        .unwrap()];
    for (k, &cell) in cells.iter().enumerate() {
        let want = match cell {
            Cell::Gap => 1.0 - 4.0 * (1.0 - COVER_FACTOR),
            Cell::Warp { up } | Cell::Weft { up } => [0.9, 1.0][up as usize],
        };
        assert!(
            (u[k] / face - want).abs() < 1e-12,
            "cell {k} ({cell:?}): {}",
            u[k] / face
        );
    }
    assert!(
        cells
            .iter()
            .any(|&k| matches!(k, Cell::Warp { up: false } | Cell::Weft { up: false }))
    );
}

/// The plain-with-gaps tile laid at 8 texels a cell on a 256² image: 16 threads per UV
/// unit, 32 texels a tile, 8 tiles across the square.
fn aligned_detail<'a>(
    corr: &'a [&'a Corrector],
    n_faces: usize,
    map: &'a mut Vec<[f64; 4]>,
    fabric: &'a mut Vec<u32>,
) -> WeaveDetail<'a> {
    *map = vec![[16.0, 0.0, 0.0, 16.0]; n_faces];
    *fabric = vec![0; n_faces];
    WeaveDetail {
        correctors: corr,
        face_fabric: fabric,
        face_map: map,
        uptake: &[true, false],
    }
}

#[test]
fn detail_integrates_to_zero_over_whole_tiles() {
    // unfiltered, and prefiltered at half a cell (the uptake then varies per patch)
    for sigma in [0.0, 0.5] {
        detail_integrates_to_zero(&plain_with_gaps().filtered(sigma).unwrap());
    }
}

fn detail_integrates_to_zero(corr: &Corrector) {
    let (faces, uv, pos) = square(16);
    // a linear stain and a linear wetness
    let values: Vec<f32> = pos
        .iter()
        .flat_map(|p| {
            [
                (0.3 + 0.2 * p[0] + 0.1 * p[1]) as f32,
                (0.8 - 0.5 * p[1]) as f32,
            ]
        })
        .collect();
    let (mut map, mut fabric) = (Vec::new(), Vec::new());
    let cs = [corr];
    let detail = aligned_detail(&cs, faces.len(), &mut map, &mut fabric);
    let plain = rasterize(&faces, &uv, &values, 2, 256).unwrap();
    let woven = rasterize_with(&faces, &uv, &values, 2, 256, Some(&detail)).unwrap();
    assert_eq!(plain.coverage, woven.coverage);
    for k in 0..2 {
        let sum = |r: &madder::texture::Raster| {
            r.pixels
                .iter()
                .skip(k)
                .step_by(2)
                .map(|&x| x as f64)
                .sum::<f64>()
        };
        let (a, b) = (sum(&plain), sum(&woven));
        let rel = ((b - a) / a).abs();
        println!("channel {k}: mass {b} vs {a}, relative error {rel:e}");
        assert!(rel < 1e-6, "channel {k}: mass {b} vs {a} ({rel:e})");
        // and the detail is really there
        let diff = plain
            .pixels
            .iter()
            .zip(&woven.pixels)
            .skip(k)
            .step_by(2)
            .map(|(p, w)| (p - w).abs())
            .fold(0.0f32, f32::max);
        // (the prefilter at half a cell keeps about a third of the uptake's contrast)
        let least = match (k, corr.filter() > 0.0) {
            (0, false) => 0.1,
            (0, true) => 0.02,
            _ => 1e-3,
        };
        assert!(diff > least, "channel {k}: {diff}");
    }
}

/// The texel pass (fixed-point tile position, `f32` table and channels) against the formula
/// evaluated independently in `f64` at each texel centre: `y = A uv` with `A = diag(w /
/// t_x, h / t_y) J` in cells, `∇_y σ0 = A⁻ᵀ ∇_uv σ0` for a field linear in UV, `χ(y)` by
/// [`Corrector::chi`], `U(y)` by [`Corrector::uptake_at`]. A turned weave at a thread count
/// that puts no texel centre on a cell edge; tile coordinates of both signs.
#[test]
fn texels_are_the_two_scale_formula() {
    let corr = Corrector::of_tile(
        &Tile::builtin(Weave::Twill21, true),
        &PairCoefficients::default(),
        [3.0, 3.0],
    )
    .unwrap();
    let (faces, uv, pos) = square(6);
    // σ0 = a + b u + c v per channel
    let lin = [[0.4, 0.3, -0.2], [0.7, -0.25, 0.15]];
    let values: Vec<f32> = pos
        .iter()
        .flat_map(|p| lin.map(|[a, b, c]| (a + b * p[0] + c * p[1]) as f32))
        .collect();
    let (cs, sn) = (37f64.to_radians().cos(), 37f64.to_radians().sin());
    let k = 23.7;
    let j = [k * cs, k * sn, -k * sn, k * cs];
    let map = vec![j; faces.len()];
    let fabric = vec![0u32; faces.len()];
    let corrs = [&corr];
    let detail = WeaveDetail {
        correctors: &corrs,
        face_fabric: &fabric,
        face_map: &map,
        uptake: &[true, false],
    };
    let size = 160;
    let r = rasterize_with(&faces, &uv, &values, 2, size, Some(&detail)).unwrap();
    let (w, h) = corr.cells();
    let [tx, ty] = corr.threads();
    let a = [
        j[0] * w as f64 / tx,
        j[1] * w as f64 / tx,
        j[2] * h as f64 / ty,
        j[3] * h as f64 / ty,
    ];
    let det = a[0] * a[3] - a[1] * a[2];
    let m = corr.moment();
    let (mut worst, mut texels, mut negative) = (0.0f64, 0, 0);
    for y in 0..size {
        for x in 0..size {
            if r.coverage[y * size + x] == 0 {
                continue;
            }
            texels += 1;
            let u = [
                (x as f64 + 0.5) / size as f64,
                (y as f64 + 0.5) / size as f64,
            ];
            let t = [a[0] * u[0] + a[1] * u[1], a[2] * u[0] + a[3] * u[1]];
            negative += usize::from(t[0] < 0.0 || t[1] < 0.0);
            let chi = corr.chi(t);
            let big_u = corr.uptake_at(t);
            for (ch, [a0, b, c]) in lin.into_iter().enumerate() {
                let s0 = a0 + b * u[0] + c * u[1];
                // A⁻ᵀ (b, c)
                let g = [(a[3] * b - a[2] * c) / det, (-a[1] * b + a[0] * c) / det];
                let want = if ch == 0 {
                    big_u * s0 + (chi[0] - m[0]) * g[0] + (chi[1] - m[1]) * g[1]
                } else {
                    s0 + chi[0] * g[0] + chi[1] * g[1]
                };
                let got = f64::from(r.texel(x, y)[ch]);
                worst = worst.max((got - want).abs());
            }
        }
    }
    println!("{texels} texels ({negative} at negative tile coordinates): max |Δ| {worst:e}");
    assert!(texels > 20_000 && negative > 5_000, "{texels}, {negative}");
    assert!(worst < 2e-6, "max |Δ| {worst:e}");
}

#[test]
fn no_detail_where_the_stain_is_flat_and_uptake_uniform() {
    let tile = Tile::builtin(Weave::Twill21, true);
    let tensors = cell_tensors(&tile, &PairCoefficients::default()).unwrap();
    let n = tensors.len();
    let corr = Corrector::new(
        tile.width(),
        tile.height(),
        &tensors,
        &vec![1.0; n],
        [3.0; 2],
    )
    .unwrap();
    let (faces, uv, pos) = square(9);
    let values: Vec<f32> = pos.iter().flat_map(|_| [0.37f32, 0.61]).collect();
    let map = vec![[40.0, -23.0, 23.0, 40.0]; faces.len()];
    let fabric = vec![0u32; faces.len()];
    let cs = [&corr];
    let detail = WeaveDetail {
        correctors: &cs,
        face_fabric: &fabric,
        face_map: &map,
        uptake: &[true, false],
    };
    let plain = rasterize(&faces, &uv, &values, 2, 200).unwrap();
    let woven = rasterize_with(&faces, &uv, &values, 2, 200, Some(&detail)).unwrap();
    assert_eq!(plain, woven);
}

#[test]
fn faces_without_fabric_are_the_plain_raster_and_threads_do_not_matter() {
    let corr = plain_with_gaps();
    let (faces, uv, pos) = square(12);
    let values: Vec<f32> = pos
        .iter()
        .flat_map(|p| {
            let s = (-((p[0] - 0.4).powi(2) + (p[1] - 0.5).powi(2)) / 0.05).exp() as f32;
            [s, 0.5 * s]
        })
        .collect();
    let cs = [&corr];
    let none = vec![NO_WEAVE; faces.len()];
    let map = vec![[0.0; 4]; faces.len()];
    let off = WeaveDetail {
        correctors: &cs,
        face_fabric: &none,
        face_map: &map,
        uptake: &[true, true],
    };
    let plain = rasterize(&faces, &uv, &values, 2, 300).unwrap();
    assert_eq!(
        rasterize_with(&faces, &uv, &values, 2, 300, Some(&off)).unwrap(),
        plain
    );
    // woven at 30°, every other face on: the same bits on 1 and 2 threads
    let (c, s) = (30f64.to_radians().cos(), 30f64.to_radians().sin());
    let k = 37.0;
    let map = vec![[k * c, k * s, -k * s, k * c]; faces.len()];
    let fabric: Vec<u32> = (0..faces.len() as u32)
        .map(|t| if t % 2 == 0 { 0 } else { NO_WEAVE })
        .collect();
    let on = WeaveDetail {
        correctors: &cs,
        face_fabric: &fabric,
        face_map: &map,
        uptake: &[true, false],
    };
    let run = |threads| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| rasterize_with(&faces, &uv, &values, 2, 300, Some(&on)).unwrap())
    };
    let one = run(1);
    assert_eq!(one, run(2));
    assert_ne!(one, plain);
}

/// The texel pass has a kernel per channel count (1–4) and one for any count: a channel's
/// texels must not depend on which ran, nor on the other channels. Five channels (the
/// general kernel) against the same channels rasterized one at a time (the 1-channel
/// kernel), uptake on some and off others: the same bits.
#[test]
fn a_channel_is_the_same_whatever_the_channel_count() {
    let corr = plain_with_gaps();
    let (faces, uv, pos) = square(10);
    let field = |p: &[f64; 2], k: usize| -> f32 {
        let (x, y) = (p[0] - 0.3 - 0.1 * k as f64, p[1] - 0.6);
        ((1.0 + k as f64) * (-(x * x + y * y) / 0.04).exp()) as f32
    };
    const C: usize = 5;
    let values: Vec<f32> = pos
        .iter()
        .flat_map(|p| (0..C).map(move |k| field(p, k)))
        .collect();
    let uptake: &'static [bool] = &[true, false, true, true, false];
    let (c, s) = (25f64.to_radians().cos(), 25f64.to_radians().sin());
    let k = 29.0;
    let map = vec![[k * c, k * s, -k * s, k * c]; faces.len()];
    let fabric = vec![0u32; faces.len()];
    let cs = [&corr];
    let detail = |uptake: &'static [bool]| WeaveDetail {
        correctors: &cs,
        face_fabric: &fabric,
        face_map: &map,
        uptake,
    };
    let size = 200;
    let all = rasterize_with(&faces, &uv, &values, C, size, Some(&detail(uptake))).unwrap();
    let plain = rasterize(&faces, &uv, &values, C, size).unwrap();
    assert_ne!(all.pixels, plain.pixels, "the detail is on");
    for (k, &up) in uptake.iter().enumerate() {
        let one: Vec<f32> = pos.iter().map(|p| field(p, k)).collect();
        let flags: &'static [bool] = if up { &[true] } else { &[false] };
        let alone = rasterize_with(&faces, &uv, &one, 1, size, Some(&detail(flags))).unwrap();
        for (i, &v) in alone.pixels.iter().enumerate() {
            assert_eq!(
                v.to_bits(),
                all.pixels[i * C + k].to_bits(),
                "channel {k}, texel {i}"
            );
        }
    }
}

#[test]
fn bad_weave_input_names_the_face() {
    let corr = plain_with_gaps();
    let (faces, uv, pos) = square(2);
    let values: Vec<f32> = pos.iter().map(|_| 0.5).collect();
    let cs = [&corr];
    let mut fabric = vec![0u32; faces.len()];
    let mut map = vec![[10.0, 0.0, 0.0, 10.0]; faces.len()];
    fabric[3] = 1;
    let run = |fabric: &[u32], map: &[[f64; 4]]| {
        let d = WeaveDetail {
            correctors: &cs,
            face_fabric: fabric,
            face_map: map,
            uptake: &[true],
        };
        rasterize_with(&faces, &uv, &values, 1, 16, Some(&d)).unwrap_err()
    };
    let e = run(&fabric, &map);
    assert!(matches!(e, TextureError::WeaveFace { face: 3, .. }), "{e}");
    assert!(
        e.to_string().contains("face 3") && e.to_string().contains("fabric 1"),
        "{e}"
    );
    fabric[3] = 0;
    map[5] = [1.0, 2.0, 2.0, 4.0];
    let e = run(&fabric, &map);
    assert!(
        matches!(e, TextureError::WeaveFace { face: 5, .. }) && e.to_string().contains("singular"),
        "{e}"
    );
    map[5] = [f64::NAN, 0.0, 0.0, 1.0];
    assert!(run(&fabric, &map).to_string().contains("not finite"));
    let e = run(&fabric[1..], &map);
    assert!(
        matches!(
            e,
            TextureError::Length {
                name: "face_fabric",
                ..
            }
        ),
        "{e}"
    );
}

/// The prefilter is a Gaussian blur: on the periodic sample grid it multiplies the Fourier
/// coefficient of frequency `k` (per tile) by `exp(−2π² s² k² / w²)` (`s` in cells, `w`
/// the tile's width in cells). Checked on `χ_x` and the uptake along rows, coefficient by
/// coefficient, against that closed form; the means (⟨U⟩ = 1, ⟨χ⟩ = 0) are kept.
#[test]
fn prefilter_is_the_gaussian_in_fourier_space() {
    let c = plain_with_gaps();
    assert_eq!(c.filtered(0.0).unwrap(), c);
    assert!(c.filtered(-1.0).is_err() && c.filtered(f64::NAN).is_err());
    let s = 0.4;
    let f = c.filtered(s).unwrap();
    assert_eq!(f.filter(), s);
    let r = c.refine();
    let (w, h) = c.cells();
    let (gw, gh) = (w * r, h * r);
    // the unfiltered uptake per patch, from the per-cell factors
    let patches = |u: &dyn Fn(usize, usize) -> f64| -> Vec<f64> {
        (0..gw * gh).map(|v| u(v % gw, v / gw)).collect()
    };
    let before_u = patches(&|p, q| c.uptake()[(q / r) * w + p / r]);
    let after_u = patches(&|p, q| f.uptake_of_patch(q * gw + p));
    // the 2-D DFT coefficient (kx, ky) of a grid
    let dft = |g: &[f64], kx: usize, ky: usize| -> (f64, f64) {
        let (mut re, mut im) = (0.0, 0.0);
        for (v, x) in g.iter().enumerate() {
            let a = 2.0
                * std::f64::consts::PI
                * ((kx * (v % gw)) as f64 / gw as f64 + (ky * (v / gw)) as f64 / gh as f64);
            re += x * a.cos();
            im -= x * a.sin();
        }
        (re, im)
    };
    let mut checked = 0;
    // χ is kept in f64; the uptake as the texture reads it, in f32
    for (before, after, tol) in [
        (c.samples(0).to_vec(), f.samples(0).to_vec(), 1e-9),
        (before_u, after_u, 1e-6),
    ] {
        let mean = after.iter().sum::<f64>() / after.len() as f64;
        let want = before.iter().sum::<f64>() / before.len() as f64;
        assert!((mean - want).abs() < tol, "mean {mean} vs {want}");
        for (kx, ky) in [(1, 0), (2, 0), (0, 1), (1, 1), (2, 2), (4, 0)] {
            let (b, a) = (dft(&before, kx, ky), dft(&after, kx, ky));
            let norm = (b.0 * b.0 + b.1 * b.1).sqrt();
            if norm < 1e-6 * before.len() as f64 {
                continue; // a frequency the pattern does not hold
            }
            let pi2 = 2.0 * std::f64::consts::PI.powi(2) * s * s;
            let gain = (-pi2
                * ((kx * kx) as f64 / (w * w) as f64 + (ky * ky) as f64 / (h * h) as f64))
                .exp();
            let err = ((a.0 - gain * b.0).powi(2) + (a.1 - gain * b.1).powi(2)).sqrt() / norm;
            assert!(err < tol, "({kx}, {ky}): gain {gain}, error {err:e}");
            checked += 1;
        }
    }
    assert!(checked >= 4, "{checked}");
}
