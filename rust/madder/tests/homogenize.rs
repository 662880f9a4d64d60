//! Homogenization (seed §2.2.2) against exact and independent results: laminates with
//! anisotropic layers, the Keller–Dykhne checkerboard, Mortola–Steffé's four-phase
//! checkerboard, the Wiener bounds on random tiles, rotation covariance, the convergence
//! of the primal–dual extrapolation on tiles without a closed form, and tiles whose cells
//! are rectangles (runs of unequal length along x and y) against the change of variables
//! that makes them squares and against rigorous brackets of the unreduced tile.

use madder::rng::SplitMix64;
use madder::weave::homogenize::{bounds, reduce, refine};
use madder::weave::tensor::{self, is_psd};
use madder::weave::{
    Cell, HomogenizationCache, HomogenizeOptions, Method, PairCoefficients, Tensor2, Tile, Weave,
    WeaveError, cell_tensors, ellipse, homogenize, homogenize_cached, homogenize_report,
    homogenize_with,
};

/// Largest entry difference over the largest entry of `b`.
fn rel(a: Tensor2, b: Tensor2) -> f64 {
    let s = b.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    a.iter()
        .zip(&b)
        .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()))
        / s
}

fn sub(a: Tensor2, b: Tensor2) -> Tensor2 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn iso(k: f64) -> Tensor2 {
    [k, 0.0, k]
}

/// The tests' random numbers: splitmix64, plus random SPD tensors.
struct Rng(SplitMix64);
impl Rng {
    fn next(&mut self) -> u64 {
        self.0.next_u64()
    }
    fn unit(&mut self) -> f64 {
        self.0.unit()
    }
    fn log_uniform(&mut self, lo: f64, hi: f64) -> f64 {
        self.0.log_uniform(lo, hi)
    }
    /// A random `w × h` tile, each side in `sides`, of [`Rng::spd`] tensors.
    fn tile(
        &mut self,
        sides: std::ops::RangeInclusive<usize>,
        lo: f64,
        hi: f64,
    ) -> (usize, usize, Vec<Tensor2>) {
        let span = (sides.end() - sides.start() + 1) as u64;
        let w = sides.start() + (self.next() % span) as usize;
        let h = sides.start() + (self.next() % span) as usize;
        (w, h, (0..w * h).map(|_| self.spd(lo, hi)).collect())
    }
    /// A random SPD tensor: eigenvalues log-uniform in [lo, hi], random axes.
    fn spd(&mut self, lo: f64, hi: f64) -> Tensor2 {
        let (l1, l2) = (self.log_uniform(lo, hi), self.log_uniform(lo, hi));
        let th = self.unit() * std::f64::consts::PI;
        let (s, c) = th.sin_cos();
        [
            l1 * c * c + l2 * s * s,
            (l1 - l2) * c * s,
            l1 * s * s + l2 * c * c,
        ]
    }
}

/// Exact effective tensor of layers stacked along x (each layer uniform in y), thickness
/// weights `w`.
fn laminate_x(layers: &[(f64, Tensor2)]) -> Tensor2 {
    let total: f64 = layers.iter().map(|l| l.0).sum();
    let avg =
        |f: &dyn Fn(Tensor2) -> f64| layers.iter().map(|&(w, a)| w * f(a)).sum::<f64>() / total;
    let a11 = 1.0 / avg(&|a| 1.0 / a[0]);
    let m = avg(&|a| a[1] / a[0]);
    [
        a11,
        a11 * m,
        avg(&|a| a[2] - a[1] * a[1] / a[0]) + a11 * m * m,
    ]
}

/// The tile rotated a quarter turn counter-clockwise: cell (x, y) moves to (h−1−y, x) and
/// its tensor to R a Rᵀ = [a22, −a12, a11].
fn rotate(w: usize, h: usize, t: &[Tensor2]) -> (usize, usize, Vec<Tensor2>) {
    let (w2, h2) = (h, w);
    let mut out = vec![[0.0; 3]; w * h];
    for y in 0..h {
        for x in 0..w {
            let a = t[y * w + x];
            out[x * w2 + (h - 1 - y)] = [a[2], -a[1], a[0]];
        }
    }
    (w2, h2, out)
}

fn checkerboard(k1: f64, k2: f64) -> Vec<Tensor2> {
    vec![iso(k1), iso(k2), iso(k2), iso(k1)]
}

fn opts(method: Method, max_cells: usize) -> HomogenizeOptions {
    HomogenizeOptions {
        method,
        max_cells,
        ..Default::default()
    }
}

#[test]
fn laminates_with_anisotropic_layers_are_exact() {
    let mut rng = Rng(SplitMix64::new(7));
    for trial in 0..20 {
        // layers of 1–3 cells, 2–6 layers, tensors with contrast up to 10⁴ and any axes
        let n = 2 + trial % 5;
        let layers: Vec<(usize, Tensor2)> = (0..n)
            .map(|_| (1 + (rng.next() % 3) as usize, rng.spd(0.01, 100.0)))
            .collect();
        let w: usize = layers.iter().map(|l| l.0).sum();
        let h = 1 + trial % 3;
        let row: Vec<Tensor2> = layers
            .iter()
            .flat_map(|&(k, a)| std::iter::repeat_n(a, k))
            .collect();
        let tiles: Vec<Tensor2> = (0..h).flat_map(|_| row.iter().copied()).collect();
        let exact = laminate_x(
            &layers
                .iter()
                .map(|&(k, a)| (k as f64, a))
                .collect::<Vec<_>>(),
        );

        // default: reduced to a one-row laminate, solved unrefined
        let a = homogenize(w, h, &tiles).unwrap();
        assert!(rel(a, exact) < 1e-10, "{trial}: {a:?} vs {exact:?}");
        // no reduction: a refined 2-D mesh, extrapolated — still exact
        let o = HomogenizeOptions {
            reduce: false,
            max_cells: 2000,
            ..Default::default()
        };
        let r = homogenize_report(w, h, &tiles, &o).unwrap();
        assert!(h == 1 || r.levels.len() == 2 && r.levels[1].refine > 1);
        assert!(
            rel(r.tensor, exact) < 1e-10,
            "{trial}: {:?} vs {exact:?}",
            r.tensor
        );
        assert!(rel(r.upper, r.lower) < 1e-10);

        // the transposed laminate (layers along y): rotate the tile a quarter turn
        let (w2, h2, t2) = rotate(w, h, &tiles);
        let exact_rot = [exact[2], -exact[1], exact[0]];
        let a = homogenize(w2, h2, &t2).unwrap();
        assert!(rel(a, exact_rot) < 1e-10, "{trial}: {a:?} vs {exact_rot:?}");
        let a = homogenize_with(w2, h2, &t2, &o).unwrap();
        assert!(rel(a, exact_rot) < 1e-10, "{trial}: {a:?} vs {exact_rot:?}");
    }
}

#[test]
fn transposed_laminate_formula() {
    // layers along y written out with the y-formula, independently of `rotate`
    let layers = [
        (1.0, [3.0, 1.0, 2.0]),
        (2.0, [10.0, -4.0, 5.0]),
        (1.0, [1.0, 0.2, 0.5]),
    ];
    let total = 4.0;
    let avg =
        |f: &dyn Fn(Tensor2) -> f64| layers.iter().map(|&(w, a)| w * f(a)).sum::<f64>() / total;
    let a22 = 1.0 / avg(&|a| 1.0 / a[2]);
    let m = avg(&|a| a[1] / a[2]);
    let exact = [
        avg(&|a| a[0] - a[1] * a[1] / a[2]) + a22 * m * m,
        a22 * m,
        a22,
    ];
    let tiles = vec![layers[0].1, layers[1].1, layers[1].1, layers[2].1]; // 1 × 4, bottom up
    assert!(rel(homogenize(1, 4, &tiles).unwrap(), exact) < 1e-12);
}

#[test]
fn figure_2_4_alternating_columns_are_anisotropic_unlike_the_average() {
    // columns of isotropic 1 and 100 (seed Fig. 2.4)
    let t: Vec<Tensor2> = (0..8 * 8)
        .map(|i| iso(if i % 2 == 0 { 1.0 } else { 100.0 }))
        .collect();
    let a = homogenize(8, 8, &t).unwrap();
    let harmonic = 2.0 / (1.0 + 1.0 / 100.0);
    let arithmetic = 50.5;
    assert!(rel(a, [harmonic, 0.0, arithmetic]) < 1e-12, "{a:?}");
    assert!((harmonic - 1.980198).abs() < 1e-6);
    let (ratio, angle) = ellipse(a);
    assert!((ratio - 25.5025).abs() < 1e-3 && (angle - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
    // the plain average is isotropic: ellipse ratio 1
    assert_eq!(ellipse([arithmetic, 0.0, arithmetic]).0, 1.0);
}

#[test]
fn checkerboard_is_keller_dykhne() {
    for (k1, k2) in [(1.0, 10.0), (1.0, 100.0), (3.0, 1000.0), (2.0, 2.5)] {
        let exact = iso(f64::sqrt(k1 * k2));
        // as the 2×2 tile and drawn as a 64×64 tile (32 cells per square, shifted by 5)
        let a = homogenize(2, 2, &checkerboard(k1, k2)).unwrap();
        assert!(rel(a, exact) < 1e-2, "{k1}/{k2}: {a:?}");
        let n = 64;
        let big: Vec<Tensor2> = (0..n * n)
            .map(|i| {
                let (x, y) = ((i % n + 5) % n, i / n);
                iso(if (x / 32 + y / 32) % 2 == 0 { k1 } else { k2 })
            })
            .collect();
        let b = homogenize(n, n, &big).unwrap();
        assert!(rel(b, exact) < 1e-2, "{k1}/{k2}: {b:?}");
        // observed: exact to rounding, because the checkerboard is self-dual (module doc)
        assert!(rel(a, exact) < 1e-10 && rel(b, exact) < 1e-10);
        // and without the reduction, at 64×64 elements, one level: still within 1%
        let o = HomogenizeOptions {
            reduce: false,
            method: Method::GeometricMean,
            ..Default::default()
        };
        assert!(rel(homogenize_with(n, n, &big, &o).unwrap(), exact) < 1e-2);
    }
}

#[test]
fn plain_p1_is_biased_high_on_the_checkerboard() {
    // the seed's plain discretization at 64×64 elements: 3.4% high at contrast 10, 74% at
    // 100 (criss-cross P1; the corner singularity r^α, α = 0.39 and 0.13)
    let p1 = |k2: f64| {
        let o = opts(Method::Primal, 64 * 64);
        homogenize_with(2, 2, &checkerboard(1.0, k2), &o).unwrap()[0] / k2.sqrt() - 1.0
    };
    let (e10, e100) = (p1(10.0), p1(100.0));
    assert!((0.03..0.04).contains(&e10), "{e10}");
    assert!((0.7..0.8).contains(&e100), "{e100}");
}

/// Mortola–Steffé (proved by Craster–Obnosov and by Milton, 2001): four squares σ₁ (bottom
/// left), σ₂ (bottom right), σ₃ (top right), σ₄ (top left) have a diagonal effective tensor
/// with `A11 A22 = [σ₁σ₃(σ₂+σ₄) + σ₂σ₄(σ₁+σ₃)] / Σσ` and
/// `A11 / A22 = (σ₁+σ₄)(σ₂+σ₃) / ((σ₁+σ₂)(σ₃+σ₄))`.
#[test]
fn four_phase_checkerboard_is_mortola_steffe() {
    for s in [
        [1.0f64, 2.0, 5.0, 10.0],
        [1.0, 100.0, 3.0, 30.0],
        [7.0, 0.5, 40.0, 2.0],
    ] {
        let [s1, s2, s3, s4] = s;
        let det = (s1 * s3 * (s2 + s4) + s2 * s4 * (s1 + s3)) / (s1 + s2 + s3 + s4);
        let ratio = (s1 + s4) * (s2 + s3) / ((s1 + s2) * (s3 + s4));
        let exact = [(det * ratio).sqrt(), 0.0, (det / ratio).sqrt()];
        let t = vec![iso(s1), iso(s2), iso(s4), iso(s3)];
        let a = homogenize(2, 2, &t).unwrap();
        assert!(rel(a, exact) < 1e-10, "{s:?}: {a:?} vs {exact:?}");
    }
}

#[test]
fn wiener_bounds_spd_and_bracket_on_random_tiles() {
    let mut rng = Rng(SplitMix64::new(2024));
    for trial in 0..60 {
        let (w, h, t) = rng.tile(1..=7, 0.1, 1000.0);
        let r = homogenize_report(w, h, &t, &opts(Method::Extrapolated, 48 * 48)).unwrap();
        let a = r.tensor;
        // arithmetic ⟨S⟩ and harmonic ⟨S⁻¹⟩⁻¹ means
        let n = (w * h) as f64;
        let mean = |f: &dyn Fn(Tensor2) -> Tensor2| {
            t.iter().fold([0.0; 3], |s, &x| {
                let y = f(x);
                [s[0] + y[0] / n, s[1] + y[1] / n, s[2] + y[2] / n]
            })
        };
        let arith = mean(&|x| x);
        let harm = tensor::inverse(mean(&tensor::inverse));
        let tol = 1e-12 * arith[0].max(arith[2]);
        assert!(
            is_psd(sub(arith, a), tol),
            "{trial}: A ≤ ⟨S⟩ fails: {a:?} {arith:?}"
        );
        assert!(
            is_psd(sub(a, harm), tol),
            "{trial}: A ≥ ⟨S⁻¹⟩⁻¹ fails: {a:?} {harm:?}"
        );
        // symmetric positive definite (symmetric by representation)
        assert!(a[0] > 0.0 && tensor::det(a) > 0.0, "{trial}: {a:?}");
        // inside the rigorous bracket, which is inside the Wiener bounds
        assert!(is_psd(sub(r.upper, a), tol) && is_psd(sub(a, r.lower), tol));
        assert!(is_psd(sub(arith, r.upper), tol) && is_psd(sub(r.lower, harm), tol));
        assert!((0.0..=1.0).contains(&r.weight));
    }
}

#[test]
fn quarter_turn_and_mirror_transform_the_tensor() {
    let mut rng = Rng(SplitMix64::new(99));
    for trial in 0..20 {
        let (w, h, t) = rng.tile(1..=6, 0.5, 50.0);
        let o = opts(Method::Extrapolated, 40 * 40);
        let a = homogenize_with(w, h, &t, &o).unwrap();
        let (w2, h2, t2) = rotate(w, h, &t);
        let b = homogenize_with(w2, h2, &t2, &o).unwrap();
        assert!(
            rel(b, [a[2], -a[1], a[0]]) < 1e-10,
            "{trial}: {a:?} → {b:?}"
        );
        // four quarter turns: back to the start
        let (w3, h3, t3) = rotate(w2, h2, &t2);
        let (w4, h4, t4) = rotate(w3, h3, &t3);
        let (w5, h5, t5) = rotate(w4, h4, &t4);
        assert_eq!((w5, h5, &t5), (w, h, &t));
        let c = homogenize_with(w3, h3, &t3, &o).unwrap();
        assert!(rel(c, a) < 1e-10, "{trial}: half turn {a:?} → {c:?}");
        // mirror x → −x: s12 flips
        let m: Vec<Tensor2> = (0..w * h)
            .map(|i| {
                let s = t[(i / w) * w + (w - 1 - i % w)];
                [s[0], -s[1], s[2]]
            })
            .collect();
        let d = homogenize_with(w, h, &m, &o).unwrap();
        assert!(
            rel(d, [a[0], -a[1], a[2]]) < 1e-10,
            "{trial}: mirror {a:?} → {d:?}"
        );
    }
}

#[test]
fn keller_duality_commutes_with_homogenization() {
    // the dual medium a / det a has effective tensor A / det A (Keller); the bounds swap
    // roles, φ ↦ 1 − φ, and the estimate follows exactly
    let mut rng = Rng(SplitMix64::new(31));
    for trial in 0..10 {
        let (w, h, t) = rng.tile(2..=5, 0.2, 200.0);
        let dual: Vec<Tensor2> = t.iter().map(|&a| tensor::keller_dual(a)).collect();
        let o = opts(Method::Extrapolated, 40 * 40);
        let a = homogenize_report(w, h, &t, &o).unwrap();
        let b = homogenize_report(w, h, &dual, &o).unwrap();
        assert!(
            rel(b.tensor, tensor::keller_dual(a.tensor)) < 1e-10,
            "{trial}"
        );
        assert!(
            rel(b.upper, tensor::keller_dual(a.lower)) < 1e-10,
            "{trial}"
        );
        assert!(
            (a.weight + b.weight - 1.0).abs() < 1e-6,
            "{trial}: {} {}",
            a.weight,
            b.weight
        );
    }
}

#[test]
fn bounds_tighten_monotonically_under_refinement() {
    let t = vec![
        iso(1.0),
        [20.0, 3.0, 8.0],
        iso(5.0),
        [2.0, 0.0, 40.0],
        iso(1.0),
        iso(60.0),
    ];
    let (w, h) = (3, 2);
    let mut prev: Option<madder::weave::Bounds> = None;
    for r in [1, 2, 4, 8] {
        let b = bounds(w * r, h * r, &refine(w, h, &t, r).unwrap()).unwrap();
        let tol = 1e-12 * b.upper[0].max(b.upper[2]);
        assert!(is_psd(sub(b.upper, b.lower), tol));
        if let Some(p) = prev {
            assert!(
                is_psd(sub(p.upper, b.upper), tol),
                "upper bound grew at r = {r}"
            );
            assert!(
                is_psd(sub(b.lower, p.lower), tol),
                "lower bound fell at r = {r}"
            );
        }
        prev = Some(b);
    }
}

#[test]
fn same_bits_in_parallel_and_sequentially() {
    let mut rng = Rng(SplitMix64::new(5));
    let t: Vec<Tensor2> = (0..5 * 4).map(|_| rng.spd(1.0, 100.0)).collect();
    let p = homogenize_report(5, 4, &t, &HomogenizeOptions::default()).unwrap();
    let s = homogenize_report(
        5,
        4,
        &t,
        &HomogenizeOptions {
            parallel: false,
            ..Default::default()
        },
    )
    .unwrap();
    assert_eq!(p, s);
}

/// Relative error of the estimate (and of the plain bounds) against the exact value, or
/// against the rigorous bracket and estimate of a much finer mesh. Printed with
/// `cargo test --release --test homogenize convergence_table -- --nocapture`; the module
/// doc of `weave::homogenize` carries a copy.
#[test]
fn convergence_table() {
    type Case = (&'static str, usize, usize, Vec<Tensor2>, Option<Tensor2>);
    let plain = Tile::builtin(Weave::Plain, true);
    let twill = Tile::builtin(Weave::Twill21, true);
    let d = PairCoefficients::default();
    let cases: Vec<Case> = vec![
        (
            "checkerboard 1:10",
            2,
            2,
            checkerboard(1.0, 10.0),
            Some(iso(10f64.sqrt())),
        ),
        (
            "checkerboard 1:100",
            2,
            2,
            checkerboard(1.0, 100.0),
            Some(iso(10.0)),
        ),
        (
            "checkerboard 1:1000",
            2,
            2,
            checkerboard(1.0, 1000.0),
            Some(iso(1000f64.sqrt())),
        ),
        (
            "aniso checkerboard",
            2,
            2,
            vec![
                [1.0, 0.0, 10.0],
                [100.0, 0.0, 5.0],
                [100.0, 0.0, 5.0],
                [1.0, 0.0, 10.0],
            ],
            None,
        ),
        (
            "3x3 with s12",
            3,
            3,
            {
                let (p, q, r) = ([1.0, 0.3, 2.0], [50.0, -10.0, 20.0], iso(5.0));
                vec![p, q, r, q, r, p, r, p, q]
            },
            None,
        ),
        (
            "plain+gaps (seed D)",
            4,
            4,
            cell_tensors(&plain, &d).unwrap(),
            None,
        ),
        (
            "twill21+gaps (seed D)",
            6,
            6,
            cell_tensors(&twill, &d).unwrap(),
            None,
        ),
    ];
    eprintln!(
        "{:<22} {:>4}  {:>9} {:>9} {:>9} {:>9} {:>9}   weight",
        "tile", "n", "P1 (U)", "dual (L)", "(U+L)/2", "U #½ L", "extrap."
    );
    for (name, w, h, t, exact) in cases {
        let side = w.max(h);
        let at = |n: usize, method: Method| {
            let r = n / side;
            homogenize_report(w, h, &t, &opts(method, r * r * w * h)).unwrap()
        };
        let (reference, bracket) = match exact {
            Some(e) => (e, None),
            None => {
                let f = at(if side % 2 == 0 { 512 } else { 384 }, Method::Extrapolated);
                (f.tensor, Some(f))
            }
        };
        let refs = if exact.is_some() {
            "exact"
        } else {
            "finest estimate"
        };
        let ns: &[usize] = match side {
            2 | 4 => &[16, 32, 64, 128],
            3 => &[18, 36, 66, 132],
            _ => &[24, 48, 72, 144],
        };
        for &n in ns {
            let e = at(n, Method::Extrapolated);
            let g = at(n, Method::GeometricMean);
            let mid = tensor::lerp(e.upper, e.lower, 0.5);
            eprintln!(
                "{:<22} {:>4}  {:>9.2e} {:>9.2e} {:>9.2e} {:>9.2e} {:>9.2e}   {:.3}",
                name,
                n,
                rel(e.upper, reference),
                rel(e.lower, reference),
                rel(mid, reference),
                rel(g.tensor, reference),
                rel(e.tensor, reference),
                e.weight
            );
            if (64..=72).contains(&n) {
                // ≤ 1% at ~64 elements per side, and inside the finest rigorous bracket
                assert!(rel(e.tensor, reference) < 1e-2, "{name} at {n}");
                // an order of magnitude better than plain P1 where P1 is poor
                if rel(e.upper, reference) > 1e-3 {
                    assert!(
                        rel(e.tensor, reference) * 10.0 < rel(e.upper, reference),
                        "{name}"
                    );
                }
                // and inside the rigorous bracket of the 8× finer mesh (up to its error)
                if let Some(f) = &bracket {
                    let tol = 1e-5 * f.tensor[0].max(f.tensor[2]);
                    assert!(
                        is_psd(sub(f.upper, e.tensor), tol),
                        "{name}: above the fine bracket"
                    );
                    assert!(
                        is_psd(sub(e.tensor, f.lower), tol),
                        "{name}: below the fine bracket"
                    );
                }
            }
        }
        if let Some(f) = bracket {
            eprintln!(
                "{:<22}       reference ({refs}) {:?}, rigorous relative gap {:.1e}",
                "",
                f.tensor.map(|x| (x * 1e6).round() / 1e6),
                f.relative_gap()
            );
        }
    }
}

#[test]
fn builtin_weaves_homogenize() {
    let d = PairCoefficients::default();
    eprintln!(
        "{:<8} {:>5}  {:>30}  {:>22}",
        "weave", "gaps", "effective [s11, s12, s22]", "ellipse (ratio, deg)"
    );
    for weave in Weave::ALL {
        for gaps in [false, true] {
            let tile = Tile::builtin(weave, gaps);
            let s = cell_tensors(&tile, &d).unwrap();
            let r =
                homogenize_report(tile.width(), tile.height(), &s, &Default::default()).unwrap();
            let a = r.tensor;
            let (ratio, angle) = ellipse(a);
            eprintln!(
                "{:<8} {:>5}  [{:>8.3}, {:>8.3}, {:>8.3}]  ({:.3}, {:>6.1}°)  gap {:.1e}",
                format!("{weave:?}"),
                gaps,
                a[0],
                a[1],
                a[2],
                ratio,
                angle.to_degrees(),
                r.relative_gap()
            );
            assert!(a[0] > 0.0 && tensor::det(a) > 0.0);
            // every built-in is mirror-symmetric about a yarn except the twills, so only
            // the twills may couple weft and warp
            if matches!(weave, Weave::Plain | Weave::Basket) {
                assert!(a[1].abs() < 1e-9 * a[0], "{weave:?}: {a:?}");
            }
        }
    }
    // a plain weave without gaps has only warp–weft contacts: uniform 200
    let s = cell_tensors(&Tile::builtin(Weave::Plain, false), &d).unwrap();
    assert!(rel(homogenize(2, 2, &s).unwrap(), iso(200.0)) < 1e-14);
}

#[test]
fn cache_hits_for_the_same_medium() {
    let mut cache = HomogenizationCache::new(2);
    let t = checkerboard(1.0, 7.0);
    let a = cache.homogenize(2, 2, &t).unwrap();
    // the same medium drawn at 3 cells per square and shifted: a hit
    let n = 6;
    let big: Vec<Tensor2> = (0..n * n)
        .map(|i| {
            let (x, y) = ((i % n + 1) % n, i / n);
            iso(if (x / 3 + y / 3) % 2 == 0 { 1.0 } else { 7.0 })
        })
        .collect();
    let b = cache.homogenize(n, n, &big).unwrap();
    assert_eq!(a, b);
    assert_eq!((cache.hits(), cache.misses(), cache.len()), (1, 1, 1));
    // options are part of the key
    let c = cache
        .homogenize_with(2, 2, &t, &opts(Method::Primal, 256))
        .unwrap();
    assert!(c[0] > a[0]);
    assert_eq!((cache.misses(), cache.len()), (2, 2));
    // capacity 2: a third medium evicts the oldest
    cache.homogenize(2, 2, &checkerboard(1.0, 3.0)).unwrap();
    assert_eq!(cache.len(), 2);
    cache.homogenize(2, 2, &t).unwrap();
    assert_eq!(cache.misses(), 4);
    // errors are reported, not cached
    assert!(cache.homogenize(1, 1, &[[1.0, 2.0, 1.0]]).is_err());
    assert_eq!(cache.len(), 2);
    // the process-wide cache agrees with the uncached call
    assert_eq!(homogenize_cached(2, 2, &t).unwrap(), a);
    assert_eq!(homogenize_cached(2, 2, &t).unwrap(), a);
}

#[test]
fn bad_input_names_the_cell() {
    let good = iso(1.0);
    assert_eq!(homogenize(0, 3, &[]), Err(WeaveError::EmptyTile));
    assert!(matches!(
        homogenize(2, 2, &[good; 3]),
        Err(WeaveError::CellCount {
            expected: 4,
            got: 3,
            ..
        })
    ));
    // row 1 (second from the bottom), column 2
    for bad in [
        [1.0, 2.0, 1.0],
        [-1.0, 0.0, 1.0],
        [1.0, 0.0, 0.0],
        [f64::NAN, 0.0, 1.0],
    ] {
        let mut t = vec![good; 3 * 2];
        t[3 + 2] = bad;
        let e = homogenize(3, 2, &t).unwrap_err();
        assert!(
            matches!(e, WeaveError::NotPositiveDefinite { row: 1, col: 2, .. }),
            "{e:?}"
        );
        assert!(e.to_string().contains("cell (row 1, column 2)"), "{e}");
    }
    let mut t = vec![good; 4];
    t[1] = iso(1e-13);
    assert!(matches!(
        homogenize(2, 2, &t),
        Err(WeaveError::Contrast { row: 0, col: 1, .. })
    ));
    // coefficient tables
    for (i, name) in [
        "gap–gap",
        "weft–weft",
        "warp–warp",
        "gap–weft",
        "gap–warp",
        "weft–warp",
    ]
    .into_iter()
    .enumerate()
    {
        for v in [0.0, -3.0, f64::INFINITY] {
            let mut d = PairCoefficients::default();
            *[
                &mut d.gap_gap,
                &mut d.weft_weft,
                &mut d.warp_warp,
                &mut d.gap_weft,
                &mut d.gap_warp,
                &mut d.weft_warp,
            ][i] = v;
            assert!(
                matches!(d.validate(), Err(WeaveError::NonPositiveCoefficient { pair, value }) if pair == name && value == v)
            );
            // cell_tensors names the first cell bordering such a pair (and ignores pairs the
            // tile does not contain)
            let tile = Tile::builtin(Weave::Plain, true);
            let uses = |r: isize, c: isize| {
                [(0, -1, true), (0, 1, true), (-1, 0, false), (1, 0, false)]
                    .iter()
                    .any(|&(dr, dc, x)| {
                        d.pair_kind(tile.cell(r, c), tile.cell(r + dr, c + dc), x).0 == name
                    })
            };
            let used =
                (0..tile.height() as isize).any(|r| (0..tile.width() as isize).any(|c| uses(r, c)));
            match cell_tensors(&tile, &d) {
                Err(WeaveError::CellCoefficient {
                    row,
                    col,
                    pair,
                    value,
                }) => {
                    assert!(
                        pair == name && value == v && uses(row as isize, col as isize),
                        "{name} at ({row}, {col})"
                    );
                    let e = WeaveError::CellCoefficient {
                        row,
                        col,
                        pair,
                        value,
                    };
                    assert!(
                        e.to_string()
                            .contains(&format!("cell (row {row}, column {col})"))
                    );
                }
                Ok(_) => assert!(!used, "{name} is used by the tile but was not reported"),
                Err(e) => panic!("{e:?}"),
            }
        }
    }
    // text grids
    assert_eq!(Tile::parse(" \n\n"), Err(WeaveError::EmptyTile));
    assert_eq!(
        Tile::parse("WF\nWx"),
        Err(WeaveError::UnknownCell {
            line: 2,
            column: 2,
            ch: 'x'
        })
    );
    assert_eq!(
        Tile::parse("WF\nW"),
        Err(WeaveError::RaggedRow {
            line: 2,
            expected: 2,
            got: 1
        })
    );
    assert!(matches!(
        Tile::new(2, 2, vec![Cell::Gap; 3]),
        Err(WeaveError::CellCount { got: 3, .. })
    ));
    assert_eq!(Tile::new(0, 2, vec![]), Err(WeaveError::EmptyTile));
    // options
    assert!(matches!(
        homogenize_with(1, 1, &[good], &opts(Method::Extrapolated, 0)),
        Err(WeaveError::Option {
            name: "max_cells",
            ..
        })
    ));
    // and the umbrella error keeps the message
    let e: madder::Error = WeaveError::EmptyTile.into();
    assert!(e.to_string().contains("empty"));
}

#[test]
fn reduce_keeps_the_medium() {
    // a 2×3 tile tiled 2×2 and drawn at 2 cells per cell reduces back, and homogenizes the same
    let t = vec![
        iso(1.0),
        iso(4.0),
        iso(9.0),
        [2.0, 1.0, 3.0],
        iso(1.0),
        iso(4.0),
    ];
    let big: Vec<Tensor2> = {
        let r = refine(2, 3, &t, 2).unwrap();
        (0..12 * 8)
            .map(|i| r[((i / 8) % 6) * 4 + (i % 8) % 4])
            .collect()
    };
    let (w, h, small) = reduce(8, 12, &big).unwrap();
    assert_eq!((w, h), (2, 3));
    // the smallest translate of t (it starts at the row [1, 4] that follows [2 1 3])
    assert_eq!(small, vec![t[4], t[5], t[0], t[1], t[2], t[3]]);
    assert_eq!(reduce(2, 3, &t).unwrap().2, small);
    assert_eq!(
        homogenize(8, 12, &big).unwrap(),
        homogenize(2, 3, &t).unwrap()
    );
}

/// Each cell of a `w × h` tile drawn as `kx × ky` unit cells: the medium stretched by
/// `F = diag(kx, ky)`. With `kx = ky = r` it is the tile refined `r` times.
fn stretch(w: usize, h: usize, t: &[Tensor2], kx: usize, ky: usize) -> Vec<Tensor2> {
    let wk = w * kx;
    (0..wk * h * ky)
        .map(|i| t[(i / wk / ky) * w + (i % wk) / kx])
        .collect()
}

/// The tile repeated `kx` times along x and `ky` times along y.
fn repeat(w: usize, h: usize, t: &[Tensor2], kx: usize, ky: usize) -> Vec<Tensor2> {
    let wk = w * kx;
    (0..wk * h * ky)
        .map(|i| t[((i / wk) % h) * w + (i % wk) % w])
        .collect()
}

/// The change of variables `x = F x'`, `F = diag(fx, fy)`, in the cell energy
/// `⟨(ξ + ∇χ)ᵀ a (ξ + ∇χ)⟩` (eq. 2.3; `∇ = F⁻ᵀ∇'`, cell averages unchanged): the medium
/// `a(F⁻¹x)` has effective tensor `F Ã Fᵀ`, with `Ã` that of the medium `F⁻¹ a F⁻ᵀ` on the
/// unstretched cells. `squeeze` is `a ↦ F⁻¹ a F⁻ᵀ`, `unsqueeze` is `Ã ↦ F Ã Fᵀ`.
fn squeeze(a: Tensor2, fx: f64, fy: f64) -> Tensor2 {
    [a[0] / (fx * fx), a[1] / (fx * fy), a[2] / (fy * fy)]
}

fn unsqueeze(a: Tensor2, fx: f64, fy: f64) -> Tensor2 {
    [a[0] * fx * fx, a[1] * fx * fy, a[2] * fy * fy]
}

/// The rigorous bracket `L ≤ A ≤ U` of the tile as given, each cell split into `r × r`
/// elements, with no reduction (one primal and one Keller-dual P1 solve).
fn bracket(w: usize, h: usize, t: &[Tensor2], r: usize) -> madder::weave::Bounds {
    bounds(w * r, h * r, &stretch(w, h, t, r, r)).unwrap()
}

/// Whether `lower − slack ≤ a ≤ upper + slack` as quadratic forms (`slack` relative to
/// `a`'s largest entry).
fn inside(a: Tensor2, b: &madder::weave::Bounds, slack: f64) -> bool {
    let tol = slack * a[0].abs().max(a[2].abs());
    is_psd(sub(b.upper, a), tol) && is_psd(sub(a, b.lower), tol)
}

#[test]
fn checkerboard_of_2x1_rectangles() {
    // 2×1 rectangles of 1 and 10 in a checkerboard: a 4×2 tile whose columns run in pairs
    // and rows one by one (row 0 at the bottom)
    let (k1, k2) = (1.0, 10.0);
    let t = vec![
        iso(k1),
        iso(k1),
        iso(k2),
        iso(k2),
        iso(k2),
        iso(k2),
        iso(k1),
        iso(k1),
    ];
    let a = homogenize(4, 2, &t).unwrap();
    eprintln!("2×1 rectangles, 1 and 10: {a:?}");
    // mirror symmetric: diagonal. Keller's reciprocity A₁₁(k₁, k₂) A₂₂(k₂, k₁) = k₁k₂, and
    // swapping the phases is a shift by one rectangle, so A₁₁ A₂₂ = 10
    assert!(a[1].abs() < 1e-12 * a[0], "{a:?}");
    assert!((a[0] * a[2] / (k1 * k2) - 1.0).abs() < 1e-9, "{a:?}");
    // longer along x: the phases alternate less often along x, so it conducts better
    // there than the square checkerboard's √10 (which the square reduction returned)
    assert!(a[0] > 3.9 && a[2] < 2.6, "{a:?}");
    // inside the rigorous bracket of the unreduced tile at every resolution, which closes
    // in on it: 8, 16, 32 elements per unit cell
    let mut gap = f64::INFINITY;
    for r in [8, 16, 32] {
        let b = bracket(4, 2, &t, r);
        assert!(inside(a, &b, 0.0), "r = {r}: {a:?} outside {b:?}");
        let g = rel(b.upper, b.lower);
        assert!(g < gap, "r = {r}: the bracket did not shrink");
        gap = g;
    }
    // the change of variables: the square checkerboard of k·diag(¼, 1), stretched by 2
    let sq = vec![
        squeeze(iso(k1), 2.0, 1.0),
        squeeze(iso(k2), 2.0, 1.0),
        squeeze(iso(k2), 2.0, 1.0),
        squeeze(iso(k1), 2.0, 1.0),
    ];
    let via = unsqueeze(homogenize(2, 2, &sq).unwrap(), 2.0, 1.0);
    assert!(rel(a, via) < 1e-4, "{a:?} vs {via:?}");
    // the same medium drawn with 3×3 pixels per cell: the same tensor
    assert_eq!(homogenize(12, 6, &stretch(4, 2, &t, 3, 3)).unwrap(), a);
    // and the square checkerboard itself is still Keller–Dykhne
    let s = homogenize(2, 2, &checkerboard(k1, k2)).unwrap();
    assert!(rel(s, iso((k1 * k2).sqrt())) < 1e-10, "{s:?}");
}

#[test]
fn rectangular_cells_follow_the_change_of_variables() {
    // random tiles with every cell drawn as a kx × ky rectangle of unit cells, against the
    // unstretched tile with the squeezed tensors F⁻¹ a F⁻ᵀ (no rectangles anywhere) and
    // against the rigorous bracket of the stretched tile itself
    let mut rng = Rng(SplitMix64::new(4242));
    let mut worst: f64 = 0.0;
    for (trial, (kx, ky)) in [(2, 1), (1, 2), (3, 1), (2, 3), (1, 4), (4, 2)]
        .into_iter()
        .cycle()
        .take(12)
        .enumerate()
    {
        let (w, h, t) = rng.tile(2..=4, 1.0, 10.0);
        let (sw, sh) = (w * kx, h * ky);
        let stretched = stretch(w, h, &t, kx, ky);
        let a = homogenize(sw, sh, &stretched).unwrap();
        let (fx, fy) = (kx as f64, ky as f64);
        let sq: Vec<Tensor2> = t.iter().map(|&x| squeeze(x, fx, fy)).collect();
        let via = unsqueeze(homogenize(w, h, &sq).unwrap(), fx, fy);
        let e = rel(a, via);
        worst = worst.max(e);
        assert!(e < 2e-3, "{trial}: {w}×{h} by {kx}×{ky}: {a:?} vs {via:?}");
        let r = (24 / sw.max(sh)).max(2);
        let b = bracket(sw, sh, &stretched, r);
        assert!(inside(a, &b, 1e-4), "{trial}: {a:?} outside {b:?}");
    }
    eprintln!("rectangular cells: largest difference from the change of variables {worst:.1e}");
}

#[test]
fn periodic_repeats_give_the_same_tensor() {
    // a tile repeated k times along x or y is the same medium: the reduction finds the
    // period, so the answer is the same bits; without the reduction it is the same tensor
    // up to the discretization
    let mut rng = Rng(SplitMix64::new(77));
    for trial in 0..8 {
        let (w, h, t) = rng.tile(1..=4, 1.0, 10.0);
        let a = homogenize(w, h, &t).unwrap();
        for (kx, ky) in [(2, 1), (1, 3), (3, 2)] {
            let big = repeat(w, h, &t, kx, ky);
            let b = homogenize(w * kx, h * ky, &big).unwrap();
            assert_eq!(a, b, "{trial}: {w}×{h} repeated {kx}×{ky}");
            let o = HomogenizeOptions {
                reduce: false,
                ..Default::default()
            };
            let c = homogenize_with(w * kx, h * ky, &big, &o).unwrap();
            assert!(rel(a, c) < 2e-3, "{trial}: unreduced {c:?} vs {a:?}");
        }
    }
}

#[test]
fn laminates_drawn_with_rectangular_pixels_are_exact() {
    // isotropic layers 2, 1 and 3 cells wide along x, each cell drawn as 2×3 pixels:
    // A₁₁ is the width-weighted harmonic mean, A₂₂ the arithmetic mean
    let layers = [(2usize, 4.0), (1, 50.0), (3, 0.5)];
    let row: Vec<Tensor2> = layers
        .iter()
        .flat_map(|&(n, k)| std::iter::repeat_n(iso(k), n))
        .collect();
    let t = stretch(6, 1, &row, 2, 3);
    let a = homogenize(12, 3, &t).unwrap();
    let harmonic = 6.0 / layers.iter().map(|&(n, k)| n as f64 / k).sum::<f64>();
    let arithmetic = layers.iter().map(|&(n, k)| n as f64 * k).sum::<f64>() / 6.0;
    assert!(rel(a, [harmonic, 0.0, arithmetic]) < 1e-12, "{a:?}");
}

#[test]
fn custom_ffww_grid_against_the_unreduced_solve() {
    // the add-on's custom grid "FFWW / WWFF" with the seed's coefficients: each F borders
    // one F (weft–weft 100) and one W (weft–warp 200) along x and W above and below
    // (200); each W borders one W (warp–warp 500) and one F along x, F above and below
    let tile = Tile::parse("FFWW\nWWFF").unwrap();
    let s = cell_tensors(&tile, &PairCoefficients::default()).unwrap();
    let (f, w) = ([150.0, 0.0, 200.0], [350.0, 0.0, 200.0]);
    assert_eq!(s, vec![w, w, f, f, f, f, w, w]);
    let a = homogenize(4, 2, &s).unwrap();
    // A e_y = 200 e_y exactly: every cell has a e_y = 200 e_y, a divergence-free flux
    assert!((a[2] - 200.0).abs() < 1e-10 && a[1].abs() < 1e-10, "{a:?}");
    // the unreduced solve (same discrete problem, shifted by whole cells)
    let o = HomogenizeOptions {
        reduce: false,
        ..Default::default()
    };
    let u = homogenize_with(4, 2, &s, &o).unwrap();
    assert!(rel(a, u) < 1e-12, "{a:?} vs unreduced {u:?}");
    // inside the rigorous bracket of a finer unreduced mesh (up to rounding: A₂₂ is exact)
    let b = bracket(4, 2, &s, 40);
    assert!(inside(a, &b, 1e-12), "{a:?} outside {b:?}");
    // and the change of variables: a 2×2 checkerboard of f and w stretched by 2 along x
    let sq = [f, w, w, f].map(|x| squeeze(x, 2.0, 1.0));
    let via = unsqueeze(homogenize(2, 2, &sq).unwrap(), 2.0, 1.0);
    assert!(rel(a, via) < 1e-4, "{a:?} vs {via:?}");
    eprintln!("FFWW/WWFF: {a:?} (unreduced {u:?})");
}

#[test]
fn cache_keeps_rectangles_apart_from_squares() {
    let mut cache = HomogenizationCache::new(8);
    let square = cache.homogenize(2, 2, &checkerboard(1.0, 10.0)).unwrap();
    // the checkerboard of 2×1 rectangles is another medium: a miss, another tensor
    let t = vec![
        iso(1.0),
        iso(1.0),
        iso(10.0),
        iso(10.0),
        iso(10.0),
        iso(10.0),
        iso(1.0),
        iso(1.0),
    ];
    let rect = cache.homogenize(4, 2, &t).unwrap();
    assert_eq!((cache.hits(), cache.misses()), (0, 2));
    assert!(rel(rect, square) > 0.1, "{rect:?} vs {square:?}");
    // the rectangles drawn at 2×2 pixels per cell and shifted: the same medium, a hit
    let px = stretch(4, 2, &t, 2, 2);
    let shifted: Vec<Tensor2> = (0..8 * 4)
        .map(|i| px[(i / 8) * 8 + (i % 8 + 3) % 8])
        .collect();
    assert_eq!(cache.homogenize(8, 4, &shifted).unwrap(), rect);
    assert_eq!((cache.hits(), cache.misses()), (1, 2));
    // the process-wide cache too
    assert_eq!(homogenize_cached(4, 2, &t).unwrap(), rect);
    assert_eq!(
        homogenize_cached(2, 2, &checkerboard(1.0, 10.0)).unwrap(),
        square
    );
}

#[test]
fn nan_tensors_are_errors_naming_the_cell() {
    let mut t = vec![iso(1.0); 6];
    t[4] = [1.0, f64::NAN, 1.0]; // row 1, column 1 of a 3 × 2 tile
    let named = |r: Result<_, WeaveError>| {
        matches!(
            r,
            Err(WeaveError::NotPositiveDefinite { row: 1, col: 1, .. })
        )
    };
    assert!(named(reduce(3, 2, &t).map(|_| ())));
    assert!(named(bounds(3, 2, &t).map(|_| ())));
    let grid = madder::weave::Grid::new(3, 2).unwrap();
    assert!(named(grid.effective(&t).map(|_| ())));
    assert!(named(grid.bounds(&t, true).map(|_| ())));
    assert!(named(homogenize_cached(3, 2, &t).map(|_| ())));
    assert!(named(
        HomogenizationCache::new(2).homogenize(3, 2, &t).map(|_| ())
    ));
    for reduce in [true, false] {
        let o = HomogenizeOptions {
            reduce,
            ..Default::default()
        };
        assert!(named(homogenize_report(3, 2, &t, &o).map(|_| ())));
    }
}

#[test]
fn tiles_at_extreme_magnitudes_give_the_scaled_answer() {
    // homogenization is 1-homogeneous in the tensors: a tile scaled by c gives c·A.
    // Tensors with s12 ≠ 0 near 1e-170 have determinants that underflow to 0, near 1e160
    // ones that overflow (inf − inf); both must still be judged SPD.
    let mut rng = Rng(SplitMix64::new(11));
    let t: Vec<Tensor2> = (0..3 * 2).map(|_| rng.spd(1.0, 10.0)).collect();
    let a = homogenize(3, 2, &t).unwrap();
    let b1 = bounds(3, 2, &t).unwrap();
    for k in [-1000, -565, 531, 1000] {
        // by a power of two, exactly the same bits scaled
        let s: Vec<Tensor2> = t.iter().map(|&x| tensor::scale(x, k)).collect();
        assert_eq!(homogenize(3, 2, &s).unwrap(), tensor::scale(a, k), "2^{k}");
        let b = bounds(3, 2, &s).unwrap();
        assert_eq!(b.upper, tensor::scale(b1.upper, k), "2^{k}");
        assert_eq!(b.lower, tensor::scale(b1.lower, k), "2^{k}");
    }
    for c in [1e-170, 1e160] {
        let s: Vec<Tensor2> = t.iter().map(|x| x.map(|v| v * c)).collect();
        let got = homogenize(3, 2, &s).unwrap();
        assert!(rel(got, a.map(|v| v * c)) < 1e-13, "{c:e}: {got:?}");
    }
    // a bad tile at 1e-170 is named compactly, not with 170 zeros
    let mut s: Vec<Tensor2> = t.iter().map(|x| x.map(|v| v * 1e-170)).collect();
    s[5] = [1e-170, 2e-170, 1e-170];
    let e = homogenize(3, 2, &s).unwrap_err();
    let msg = e.to_string();
    assert!(
        matches!(e, WeaveError::NotPositiveDefinite { row: 1, col: 2, .. }),
        "{e:?}"
    );
    assert!(
        msg.contains("[s11 1.000e-170, s12 2.000e-170, s22 1.000e-170]") && msg.len() < 250,
        "{msg}"
    );
}
