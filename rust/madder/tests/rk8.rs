//! The eighth-order scheme of the particle tracer (`lcs::rk`, seed §5.5.1) against exact
//! results: polynomial-in-time velocities (the weights and stage times), the linear saddle
//! in two steps (its closed form), the order measured on the double gyre against an RK4
//! reference computed here, the flat fast path against walking, thread-count independence.

mod lcs_common;

use std::f64::consts::PI;

use glam::{DVec2, DVec3};
use lcs_common::rect_grid;
use madder::lcs::{Charts, FnVelocity, Motion, Scheme, flow_map_with, ftle_with};
use madder::mesh::Topology;

/// World end points of the particles from every vertex (flat path or walking everywhere).
fn end_points(
    topo: &Topology,
    p: &[DVec3],
    f: impl Fn(f64, DVec3) -> DVec3 + Sync,
    (t0, span): (f64, f64),
    (scheme, steps): (Scheme, usize),
    walk_everywhere: bool,
) -> Vec<DVec3> {
    let mut charts = Charts::new(topo, p).unwrap();
    if walk_everywhere {
        charts = charts.walk_everywhere();
    }
    let motion = Motion::fixed(p.to_vec());
    let end = flow_map_with(
        &charts,
        &motion,
        &mut FnVelocity(f),
        t0,
        span,
        scheme,
        steps,
    );
    end.unwrap()
        .iter()
        .zip(p)
        .map(|(l, &x)| {
            let Some(l) = l else { return x };
            let tri = topo.faces()[l.face as usize].map(|v| p[v as usize]);
            l.bary.x * tri[0] + l.bary.y * tri[1] + l.bary.z * tri[2]
        })
        .collect()
}

fn planar_ftle(
    topo: &Topology,
    p: &[DVec3],
    f: impl Fn(f64, DVec2) -> DVec2 + Sync,
    span: f64,
    (scheme, steps): (Scheme, usize),
) -> Vec<f64> {
    let mut v = FnVelocity(move |t, x: DVec3| f(t, x.truncate()).extend(0.0));
    ftle_with(
        topo,
        &Motion::fixed(p.to_vec()),
        &mut v,
        0.0,
        span,
        scheme,
        steps,
    )
    .unwrap()
}

#[test]
fn rk8_integrates_polynomials_of_degree_7_in_time_exactly() {
    // v = (t⁷, 3t⁶ − t): one step from t0 = 0.2 over 0.9 moves every particle by the
    // integral; an eighth-order quadrature is exact to degree 7 (not 8: checked below)
    let (topo, p) = rect_grid(20, 20, [-2.0, 2.0], [-2.0, 2.0]);
    let (t0, span) = (0.2, 0.9_f64);
    let t1 = t0 + span;
    let exact = DVec3::new(
        (t1.powi(8) - t0.powi(8)) / 8.0,
        (3.0 * (t1.powi(7) - t0.powi(7)) / 7.0) - (t1 * t1 - t0 * t0) / 2.0,
        0.0,
    );
    let v = |t: f64, _| DVec3::new(t.powi(7), 3.0 * t.powi(6) - t, 0.0);
    for walk in [false, true] {
        let end = end_points(&topo, &p, v, (t0, span), (Scheme::Rk8, 1), walk);
        let err = end
            .iter()
            .zip(&p)
            .filter(|(_, x)| x.x.abs() < 1.0 && x.y.abs() < 1.0)
            .map(|(e, x)| (*e - *x - exact).length())
            .fold(0.0, f64::max);
        eprintln!("degree 7, walking everywhere {walk}: max error {err:.1e}");
        assert!(err < 1e-13, "{err}");
    }
    // degree 8 is not integrated exactly, nor degree 5 by RK4: the test can tell
    let c = p.iter().position(|x| x.length() < 1e-9).unwrap();
    let v8 = |t: f64, _| DVec3::new(t.powi(8), 0.0, 0.0);
    let end = end_points(&topo, &p, v8, (t0, span), (Scheme::Rk8, 1), false);
    let err8 = ((end[c] - p[c]).x - (t1.powi(9) - t0.powi(9)) / 9.0).abs();
    let end = end_points(&topo, &p, v, (t0, span), (Scheme::Rk4, 1), false);
    let err4 = (end[c] - p[c] - exact).length();
    eprintln!("degree 8 with RK8: error {err8:.1e}; degree 7 with RK4: {err4:.1e}");
    assert!(err8 > 1e-7 && err4 > 1e-2, "{err8} {err4}");
}

#[test]
fn rk8_gets_the_linear_saddle_in_two_steps() {
    // u = (λx, −λy): σ = λ; one RK step multiplies x by R(hλ), the scheme's stability
    // polynomial, equal to e^{hλ} up to O((hλ)⁹) for RK8 and O((hλ)⁵) for RK4
    let lambda = 0.8;
    let (topo, p) = rect_grid(40, 40, [-1.0, 1.0], [-1.0, 1.0]);
    let saddle = |_, x: DVec2| DVec2::new(lambda * x.x, -lambda * x.y);
    let inner = |x: &DVec3| x.x.abs().max(x.y.abs()) < 0.35;
    let err = |s: &[f64]| {
        p.iter()
            .zip(s)
            .filter(|(x, _)| inner(x))
            .map(|(_, s)| (s - lambda).abs())
            .fold(0.0, f64::max)
    };
    for span in [1.0, -1.0] {
        let e8 = err(&planar_ftle(&topo, &p, saddle, span, (Scheme::Rk8, 2)));
        let e4 = err(&planar_ftle(&topo, &p, saddle, span, (Scheme::Rk4, 2)));
        eprintln!("saddle T={span}, 2 steps: |σ − λ| RK8 {e8:.1e}, RK4 {e4:.1e}");
        assert!(e8 < 1e-8, "RK8 {e8}");
        assert!(e4 > 1e-5, "RK4 {e4}");
    }
}

/// The largest end-point error of RK8 with `steps` steps on the double gyre over T = −4,
/// against classical RK4 with 4000 steps (the reference, computed here), over particles
/// well inside [0, 2] × [0, 1].
fn gyre_error(topo: &Topology, p: &[DVec3], steps: usize) -> f64 {
    let (t0, span) = (0.5, -4.0);
    let f = |t, x: DVec3| lcs_common::double_gyre(t, x.truncate()).extend(0.0);
    let end = end_points(topo, p, f, (t0, span), (Scheme::Rk8, steps), false);
    end.iter()
        .zip(p)
        .filter(|(_, x)| (0.2..1.8).contains(&x.x) && (0.2..0.8).contains(&x.y))
        .map(|(e, x)| {
            let want = lcs_common::rk4(&lcs_common::double_gyre, x.truncate(), t0, span, 4000);
            e.truncate().distance(want)
        })
        .fold(0.0, f64::max)
}

#[test]
fn rk8_is_eighth_order() {
    // a nonlinear, time-dependent flow: halving the step divides the error by 2⁸ = 256
    let (topo, p) = rect_grid(20, 10, [0.0, 2.0], [0.0, 1.0]);
    let e: Vec<f64> = [3, 6, 12]
        .iter()
        .map(|&n| gyre_error(&topo, &p, n))
        .collect();
    let order: Vec<f64> = e.windows(2).map(|w| (w[0] / w[1]).log2()).collect();
    eprintln!("double gyre end-point errors {e:?}, measured orders {order:.2?}");
    assert!(e[2] > 1e-12, "above rounding: {e:?}");
    assert!(
        order.iter().all(|&o| o > 7.3 && o < 9.5),
        "orders {order:?}"
    );
}

#[test]
fn rk8_flat_path_agrees_with_walking() {
    // a grid with a square hole and a flow that sweeps particles into its border
    let (full, p) = rect_grid(48, 32, [-1.5, 1.5], [-1.0, 1.0]);
    let in_hole = |x: DVec3| x.x.abs() < 0.4 && x.y.abs() < 0.3;
    let faces: Vec<[u32; 3]> = full
        .faces()
        .iter()
        .filter(|t| !in_hole(t.iter().map(|&v| p[v as usize]).sum::<DVec3>() / 3.0))
        .copied()
        .collect();
    let topo = Topology::from_triangles(p.len(), faces).unwrap();
    let flow = |t: f64, x: DVec3| DVec3::new(0.8 + 0.3 * (t + x.y).sin(), 0.4 * x.x, 0.0);
    let run = |walk| end_points(&topo, &p, flow, (0.0, 1.6), (Scheme::Rk8, 6), walk);
    let (fast, walked) = (run(false), run(true));
    let diff = fast
        .iter()
        .zip(&walked)
        .map(|(a, b)| a.distance(*b))
        .fold(0.0, f64::max);
    let stopped = walked
        .iter()
        .zip(&p)
        .filter(|(a, b)| a.distance(**b) < 0.3 && a.x < 1.4)
        .count();
    eprintln!("RK8 fast path vs walking: max distance {diff:.1e}; {stopped} stopped by the hole");
    assert!(stopped > 20, "{stopped}");
    assert!(diff < 1e-10, "{diff}");
}

#[test]
fn rk8_results_do_not_depend_on_the_thread_count() {
    // flat (the fast path) and rolled into a half cylinder (walked), odd vertex count
    let (topo, p) = rect_grid(40, 20, [0.0, 2.0], [0.0, 1.0]);
    let r = 1.0 / PI;
    let rolled: Vec<DVec3> = p
        .iter()
        .map(|q| DVec3::new(q.x, r * (PI * q.y).cos(), r * (PI * q.y).sin()))
        .collect();
    let rolled_gyre = |t, x: DVec3| {
        let theta = x.z.atan2(x.y);
        let u = lcs_common::double_gyre(t, DVec2::new(x.x, theta / PI));
        DVec3::new(u.x, -u.y * theta.sin(), u.y * theta.cos())
    };
    let flat_gyre = |t, x: DVec3| lcs_common::double_gyre(t, x.truncate()).extend(0.0);
    let run = |threads: usize, curved: bool| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| {
                let m = Motion::fixed(if curved { rolled.clone() } else { p.clone() });
                if curved {
                    ftle_with(
                        &topo,
                        &m,
                        &mut FnVelocity(rolled_gyre),
                        0.0,
                        -5.0,
                        Scheme::Rk8,
                        5,
                    )
                } else {
                    ftle_with(
                        &topo,
                        &m,
                        &mut FnVelocity(flat_gyre),
                        0.0,
                        -5.0,
                        Scheme::Rk8,
                        5,
                    )
                }
                .unwrap()
            })
    };
    for curved in [false, true] {
        let a = run(1, curved);
        assert!(a.iter().cloned().fold(0.0, f64::max) > 0.1);
        for threads in [2, 3] {
            let b = run(threads, curved);
            assert!(a.iter().zip(&b).all(|(x, y)| x.to_bits() == y.to_bits()));
        }
    }
}
