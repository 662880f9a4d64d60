//! Validation of wicking (issue 13 §1: the diffusion rate `D₀ θⁿ` grows with the
//! saturation) against the exact Barenblatt solution of the porous-medium equation.
//!
//! On a flat, still cloth with no forces and no interactions the free solvent obeys
//! `σ̇ = ∇·(D₀ (σ/σ_w)ⁿ ∇σ) = a Δ(σ^m)`, `m = n + 1`, `a = D₀ / (σ_wⁿ m)` (for `σ ≤ σ_w`).
//! In the plane (`d = 2`) with `τ = a t` its self-similar solution of finite mass is
//!
//! ```text
//! U(r, τ) = τ^{−α} (C − k r² τ^{−2β})₊^{1/n},   α = 1/(n+1),  β = α/2,  k = n / (4 (n+1)²),
//! ```
//!
//! a dome with a sharp front at `r_f = √(C/k) τ^β`. Started from `U(·, τ₀)` sampled at the
//! vertices, the simulator must follow it: the profile within 3 % (L1, relative), the
//! front within 3 %, advancing as `t^β`, with mass exact and no density negative, on a
//! jittered mesh whose triangles are obtuse. The linear diffusion (`n = 0`) has no front:
//! its second moment grows linearly in time, and the front test tells the two apart.

use faer::Par;
use glam::DVec3;
use madder::stain::{Conductivity, Forces, Simulator, StainParams, Wicking};

mod common;
use common::{Grid, Split, no_interaction};

const D0: f64 = 2e-4;
const SIGMA_W: f64 = 1.0;

struct Barenblatt {
    n: f64,
    c: f64,
}

impl Barenblatt {
    fn a(&self) -> f64 {
        D0 / (SIGMA_W.powf(self.n) * (self.n + 1.0))
    }
    fn alpha(&self) -> f64 {
        1.0 / (self.n + 1.0)
    }
    fn beta(&self) -> f64 {
        0.5 * self.alpha()
    }
    fn k(&self) -> f64 {
        self.n / (4.0 * (self.n + 1.0).powi(2))
    }
    /// The solution through peak `u0` with front radius `r0`, and the time `t0` it has them.
    fn through(n: f64, u0: f64, r0: f64) -> (Self, f64) {
        let k = n / (4.0 * (n + 1.0).powi(2));
        let tau0 = k * r0 * r0 / u0.powf(n);
        let alpha = 1.0 / (n + 1.0);
        let c = (u0 * tau0.powf(alpha)).powf(n);
        let b = Self { n, c };
        (Self { n, c }, tau0 / b.a())
    }
    fn u(&self, r: f64, t: f64) -> f64 {
        let tau = self.a() * t;
        let inner = self.c - self.k() * r * r * tau.powf(-2.0 * self.beta());
        if inner <= 0.0 {
            0.0
        } else {
            tau.powf(-self.alpha()) * inner.powf(1.0 / self.n)
        }
    }
    fn front(&self, t: f64) -> f64 {
        (self.c / self.k()).sqrt() * (self.a() * t).powf(self.beta())
    }
}

/// `(L1 error / mass, moment front radius)` of the free solvent against `U(·, t)`.
fn compare(sim: &Simulator, pos: &[DVec3], b: &Barenblatt, t: f64) -> (f64, f64) {
    let sigma = sim.density(&sim.fields().free_solvent);
    let area = sim.vertex_area();
    let (mut err, mut mass, mut r2) = (0.0, 0.0, 0.0);
    for i in 0..pos.len() {
        let r = pos[i].length();
        err += area[i] * (sigma[i] - b.u(r, t)).abs();
        mass += area[i] * sigma[i];
        r2 += area[i] * sigma[i] * r * r;
    }
    // for U ∝ (1 − r²/r_f²)^p in the plane, ⟨r²⟩ = r_f² / (p + 2)
    let p = 1.0 / b.n;
    (err / mass, ((p + 2.0) * r2 / mass).sqrt())
}

/// Runs the Barenblatt solution of exponent `n` on a cloth wicking with `exponent`.
fn run(n: f64, exponent: f64) -> (Vec<(f64, f64, f64, f64)>, Barenblatt) {
    let grid = Grid::new(128, 0.32).jitter(0.3).split(Split::Uniform);
    let (topo, pos) = grid.build();
    let params = StainParams {
        forces: Forces {
            gravity: false,
            rectilinear: false,
            coriolis: false,
        },
        interaction: no_interaction(),
        wicking: Wicking {
            exponent,
            density: SIGMA_W,
            picard: 0,
            tolerance: 0.0,
        },
        ..Default::default()
    };
    let mut sim = Simulator::new(
        topo,
        &pos,
        &pos,
        Conductivity::Isotropic(D0),
        params,
        [0.5, 0.1, 0.1],
        Par::Seq,
    )
    .unwrap();
    let (b, t0) = Barenblatt::through(n, 0.8, 0.08);
    let start: Vec<f64> = pos.iter().map(|p| b.u(p.length(), t0)).collect();
    sim.add_liquid(&start, 0.05, None).unwrap();
    let mass0 = sim.totals().solvent;
    // steps growing with t (the solution is self-similar): 3 % of the time so far
    let mut t = t0;
    let mut checks = Vec::new();
    let t_end = t0 * 81.0; // the front triples for n = 1
    let marks = [t0 * 3.0, t0 * 9.0, t0 * 27.0, t_end];
    let mut next = 0;
    while next < marks.len() {
        let h = (0.03 * t).min(marks[next] - t);
        sim.step(&pos, h, None).unwrap();
        t += h;
        let f = sim.fields();
        assert!(
            f.free_solvent.iter().all(|&m| m >= 0.0),
            "negative mass at t = {t}"
        );
        let total = sim.totals().solvent;
        assert!(
            (total - mass0).abs() <= 1e-12 * mass0,
            "mass {total} vs {mass0}"
        );
        if (t - marks[next]).abs() <= 1e-9 * t {
            let (err, front) = compare(&sim, &pos, &b, t);
            checks.push((t, err, front, b.front(t)));
            next += 1;
        }
    }
    (checks, b)
}

fn check(n: f64) {
    let (checks, b) = run(n, n);
    for &(t, err, front, exact) in &checks {
        println!(
            "n = {n}: t = {t:7.1} s  L1 error {:.2} %  front {front:.4} m vs exact {exact:.4} m ({:+.2} %)",
            100.0 * err,
            100.0 * (front / exact - 1.0)
        );
        assert!(
            err < 0.03,
            "n = {n}, t = {t}: profile off by {:.2} %",
            100.0 * err
        );
        assert!(
            (front / exact - 1.0).abs() < 0.03,
            "n = {n}, t = {t}: front {front} vs {exact}"
        );
    }
    // the front advances as t^β: the slope of log r_f against log t over the run
    let (t0, r0) = (checks[0].0, checks[0].2);
    let (t1, r1) = (checks[3].0, checks[3].2);
    let slope = (r1 / r0).ln() / (t1 / t0).ln();
    println!("n = {n}: front ∝ t^{slope:.4} (exact {:.4})", b.beta());
    assert!(
        (slope / b.beta() - 1.0).abs() < 0.03,
        "slope {slope} vs {}",
        b.beta()
    );
}

#[test]
fn barenblatt_n1() {
    check(1.0);
}

#[test]
fn barenblatt_n2() {
    check(2.0);
}

#[test]
fn the_linear_diffusion_misses_the_front() {
    // the same start with a constant rate: the test above tells the two laws apart
    let (checks, _) = run(1.0, 0.0);
    let (_, err, front, exact) = checks[3];
    println!(
        "linear: L1 error {:.1} %, front {front:.4} vs {exact:.4}",
        100.0 * err
    );
    assert!(
        err > 0.1 && (front / exact - 1.0).abs() > 0.1,
        "{err} {front} {exact}"
    );
}

#[test]
fn wicking_off_is_the_linear_diffusion_bit_for_bit() {
    // exponent 0 takes the linear path whatever the density: same bits as the default
    let (topo, pos) = Grid::new(20, 0.5).jitter(0.3).build();
    let run = |wicking: Wicking| {
        let mut sim = Simulator::new(
            topo.clone(),
            &pos,
            &pos,
            Conductivity::Isotropic(D0),
            StainParams {
                wicking,
                ..Default::default()
            },
            [0.5, 0.1, 0.1],
            Par::Seq,
        )
        .unwrap();
        let blob: Vec<f64> = pos
            .iter()
            .map(|p| (-p.length_squared() / 0.01).exp())
            .collect();
        sim.add_liquid(&blob, 0.05, None).unwrap();
        for _ in 0..10 {
            sim.step(&pos, 0.04, None).unwrap();
        }
        sim.solute_density()
    };
    let a = run(Wicking::default());
    let b = run(Wicking {
        exponent: 0.0,
        density: 3.0,
        picard: 0,
        tolerance: 0.0,
    });
    assert!(a.iter().zip(&b).all(|(x, y)| x.to_bits() == y.to_bits()));
}

#[test]
fn bad_wicking_parameters_are_refused() {
    for (exponent, density) in [(-1.0, 1.0), (9.0, 1.0), (f64::NAN, 1.0), (1.0, 0.0)] {
        let p = StainParams {
            wicking: Wicking {
                exponent,
                density,
                picard: 0,
                tolerance: 0.0,
            },
            ..Default::default()
        };
        let e = p.validate().unwrap_err().to_string();
        assert!(e.contains("wicking"), "{e}");
    }
}
