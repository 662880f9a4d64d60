//! FTLE on triangle meshes (`madder::lcs`, seed §5.2, §5.5.1) against closed forms: the
//! linear saddle, a rigid rotation, a steady shear; the integrator's order; per-vertex
//! velocities; a mesh that bends isometrically; bad input; determinism (flat and curved);
//! a curved mesh with faces of both windings.

mod lcs_common;

use std::f64::consts::PI;

use glam::{DVec2, DVec3};
use lcs_common::rect_grid;
use madder::error::{LcsError, MeshError};
use madder::lcs::{
    Charts, FnVelocity, FrameTimes, Motion, Velocity, VertexVelocity, flow_map, ftle,
};
use madder::mesh::Topology;

/// FTLE of a planar field on a fixed flat mesh.
fn planar_ftle(
    topo: &Topology,
    p: &[DVec3],
    f: impl Fn(f64, DVec2) -> DVec2 + Sync,
    t0: f64,
    span: f64,
    steps: usize,
) -> Vec<f64> {
    let mut v = FnVelocity(move |t, x: DVec3| f(t, x.truncate()).extend(0.0));
    ftle(topo, &Motion::fixed(p.to_vec()), &mut v, t0, span, steps).unwrap()
}

/// The largest error over the vertices that `keep` selects.
fn max_error(p: &[DVec3], s: &[f64], exact: f64, keep: impl Fn(DVec3) -> bool) -> (f64, usize) {
    let sel: Vec<f64> = p
        .iter()
        .zip(s)
        .filter(|(x, _)| keep(**x))
        .map(|(_, s)| (s - exact).abs())
        .collect();
    (sel.iter().cloned().fold(0.0, f64::max), sel.len())
}

#[test]
fn linear_saddle_has_ftle_lambda_in_the_interior() {
    // u = (λx, −λy): φ = diag(e^{λT}, e^{−λT}), σ = λ exactly, forward and backward
    let lambda = 0.8;
    let (topo, p) = rect_grid(40, 40, [-1.0, 1.0], [-1.0, 1.0]);
    for span in [1.0, -1.0] {
        let s = planar_ftle(
            &topo,
            &p,
            |_, x| DVec2::new(lambda * x.x, -lambda * x.y),
            0.0,
            span,
            20,
        );
        // interior: the one-ring's particles stay inside the square ((|x| + dx) e^{0.8} < 1)
        let (err, n) = max_error(&p, &s, lambda, |x| x.x.abs().max(x.y.abs()) < 0.35);
        eprintln!("saddle T={span}: max |σ − λ| = {err:.2e} over {n} vertices");
        assert!(n > 100 && err < 1e-3, "saddle T={span}: {err}");
    }
}

#[test]
fn rigid_rotation_has_zero_ftle() {
    let (topo, p) = rect_grid(40, 40, [-1.0, 1.0], [-1.0, 1.0]);
    let s = planar_ftle(&topo, &p, |_, x| 1.3 * x.perp(), 0.0, 2.0, 40);
    let (err, n) = max_error(&p, &s, 0.0, |x| x.length() < 0.9);
    eprintln!("rotation: max |σ| = {err:.2e} over {n} vertices");
    assert!(n > 500 && err < 1e-3, "rotation: {err}");
}

#[test]
fn steady_shear_matches_the_closed_form() {
    // u = (γy, 0): ∇φ = [1 γT; 0 1], λ_max = 1 + γ²T²/2 + γT√(1 + γ²T²/4)
    let gamma = 1.5;
    let (topo, p) = rect_grid(60, 20, [-3.0, 3.0], [-1.0, 1.0]);
    for span in [1.0, 2.0, -1.0] {
        let s = planar_ftle(
            &topo,
            &p,
            |_, x| DVec2::new(gamma * x.y, 0.0),
            0.0,
            span,
            10,
        );
        let gt = gamma * span.abs();
        let exact =
            (1.0 + gt * gt / 2.0 + gt * (1.0 + gt * gt / 4.0).sqrt()).ln() / (2.0 * span.abs());
        // interior: the one-ring's particles stay inside (|x| + γ|T|(|y| + dy) < 3)
        let (err, n) = max_error(&p, &s, exact, |x| x.x.abs() < 1.0 && x.y.abs() < 0.5);
        eprintln!("shear T={span}: σ = {exact:.6}, max error {err:.2e} over {n} vertices");
        assert!(n > 50 && err < 1e-3, "shear T={span}: {err}");
    }
}

/// The traced end points of a rigid rotation against the exact rotation, with `steps` steps.
fn rotation_error(steps: usize) -> f64 {
    let (topo, p) = rect_grid(16, 16, [-1.0, 1.0], [-1.0, 1.0]);
    let charts = Charts::new(&topo, &p).unwrap();
    let motion = Motion::fixed(p.clone());
    let omega = 1.0;
    let mut v = FnVelocity(move |_, x: DVec3| omega * DVec3::new(-x.y, x.x, 0.0));
    let span = 1.5;
    let end = flow_map(&charts, &motion, &mut v, 0.0, span, steps).unwrap();
    let (c, s) = (omega * span).sin_cos();
    let _ = (c, s);
    let (sin, cos) = (omega * span).sin_cos();
    p.iter()
        .zip(&end)
        .filter(|(x, _)| x.length() < 0.7)
        .map(|(x, l)| {
            let l = l.unwrap();
            let tri = topo.faces()[l.face as usize].map(|v| p[v as usize]);
            let got = l.bary.x * tri[0] + l.bary.y * tri[1] + l.bary.z * tri[2];
            let want = DVec3::new(cos * x.x - sin * x.y, sin * x.x + cos * x.y, 0.0);
            got.distance(want)
        })
        .fold(0.0, f64::max)
}

#[test]
fn rk4_with_edge_crossings_is_fourth_order() {
    // a rotation moves every particle across many triangles; halving the step divides
    // the error by 2⁴ = 16
    let e: Vec<f64> = [3, 6, 12].iter().map(|&n| rotation_error(n)).collect();
    let order: Vec<f64> = e.windows(2).map(|w| (w[0] / w[1]).log2()).collect();
    eprintln!("rotation end-point errors {e:?}, measured orders {order:.2?}");
    assert!(
        order.iter().all(|&o| o > 3.7 && o < 4.5),
        "orders {order:?}"
    );
    assert!(e[2] < 1e-5);
}

#[test]
fn per_vertex_velocities_interpolate_in_space_and_time() {
    // a saddle whose rate switches linearly in time, given per vertex at three frames:
    // linear in space (exact in the triangles) and in time (exact between frames), so
    // σ = (1/T) ∫ λ(t) dt exactly
    let (topo, p) = rect_grid(30, 30, [-1.0, 1.0], [-1.0, 1.0]);
    let rate = |t: f64| 0.5 + 0.5 * t; // 0.5 at t=0, 1 at t=1, 1.5 at t=2
    let frame = |t: f64| -> Vec<DVec3> {
        p.iter()
            .map(|x| DVec3::new(rate(t) * x.x, -rate(t) * x.y, 0.0))
            .collect()
    };
    let times = FrameTimes::new(vec![0.0, 1.0, 2.0]).unwrap();
    let mut v =
        VertexVelocity::new(times, vec![frame(0.0), frame(1.0), frame(2.0)], &topo).unwrap();
    let s = ftle(&topo, &Motion::fixed(p.clone()), &mut v, 0.0, 2.0, 40).unwrap();
    let exact = (0.5 * 2.0 + 0.25 * 4.0) / 2.0; // ∫0² (0.5 + 0.5t) dt / 2
    let (err, n) = max_error(&p, &s, exact, |x| x.x.abs().max(x.y.abs()) < 0.1);
    eprintln!("per-vertex saddle: σ = {exact}, max error {err:.2e} over {n} vertices");
    assert!(n > 4 && err < 1e-6, "{err}");
}

/// A strip `[0, 2] × [0, 1]` bent about the y axis into a cylinder of curvature `κ`:
/// the isometry `(x, y) ↦ (sin κx / κ, y, (1 − cos κx) / κ)` and its x-tangent.
fn bend(x: f64, y: f64, kappa: f64) -> (DVec3, DVec3) {
    if kappa == 0.0 {
        return (DVec3::new(x, y, 0.0), DVec3::X);
    }
    let a = kappa * x;
    (
        DVec3::new(a.sin() / kappa, y, (1.0 - a.cos()) / kappa),
        DVec3::new(a.cos(), 0.0, a.sin()),
    )
}

/// Mean and interior maximum of `|σ_bent − σ_flat|` on an `n × n/2` strip with `k` frames:
/// the rest field on the flat strip, and the same field pushed forward onto the strip as it
/// bends (κ from 0 to 1.5 over the span).
fn bending_error(n: usize, k: usize) -> (f64, f64, f64) {
    let (topo, rest) = rect_grid(n, n / 2, [0.0, 2.0], [0.0, 1.0]);
    let u = |t: f64, x: &DVec3| lcs_common::gyre(0.1, 0.25, 0.2 * PI, t, x.truncate());
    let (t0, span) = (0.0, 2.5);
    let times: Vec<f64> = (0..k)
        .map(|i| t0 + span * i as f64 / (k - 1) as f64)
        .collect();
    let kappa = |t: f64| 1.5 * (t - t0) / span;
    let per_frame = |f: &dyn Fn(f64, &DVec3) -> DVec3| -> Vec<Vec<DVec3>> {
        times
            .iter()
            .map(|&t| rest.iter().map(|x| f(t, x)).collect())
            .collect()
    };
    let frames = per_frame(&|t, x| bend(x.x, x.y, kappa(t)).0);
    let vel_rest = per_frame(&|t, x| u(t, x).extend(0.0));
    let vel_bent = per_frame(&|t, x| {
        let w = u(t, x);
        w.x * bend(x.x, x.y, kappa(t)).1 + w.y * DVec3::Y
    });
    let ft = FrameTimes::new(times.clone()).unwrap();
    let mut v_rest = VertexVelocity::new(ft.clone(), vel_rest, &topo).unwrap();
    let mut v_bent = VertexVelocity::new(ft.clone(), vel_bent, &topo).unwrap();
    let flat = ftle(
        &topo,
        &Motion::fixed(rest.clone()),
        &mut v_rest,
        t0,
        span,
        50,
    )
    .unwrap();
    let bent = ftle(
        &topo,
        &Motion::frames(ft, frames).unwrap(),
        &mut v_bent,
        t0,
        span,
        50,
    )
    .unwrap();
    let d: Vec<f64> = flat.iter().zip(&bent).map(|(a, b)| (a - b).abs()).collect();
    let mean = d.iter().sum::<f64>() / d.len() as f64;
    let interior = |x: &DVec3| x.x > 0.1 && x.x < 1.9 && x.y > 0.1 && x.y < 0.9;
    let max_in = rest
        .iter()
        .zip(&d)
        .filter(|(x, _)| interior(x))
        .map(|(_, d)| *d)
        .fold(0.0, f64::max);
    (mean, max_in, flat.iter().cloned().fold(0.0, f64::max))
}

#[test]
fn isometric_bending_leaves_ftle_unchanged() {
    // The flow map lives in material coordinates, so an isometry changes nothing but the
    // discretization: the chords of the bent mesh (the velocity's tangent projection and the
    // end points' offsets, both O((κ dx)²)) and the positions' linear interpolation between
    // frames (O((κ Δt/T)²), below the chords' share with 11 frames). Halving dx divides the
    // mean difference by about 4.
    let (mean_a, max_a, smax) = bending_error(40, 11);
    let (mean_b, max_b, _) = bending_error(80, 11);
    eprintln!(
        "bending: mean |σ_bent − σ_flat| {mean_a:.2e} → {mean_b:.2e}, interior max {max_a:.2e} → {max_b:.2e} (σ_max {smax:.3})"
    );
    // the mean converges at second order; the maximum, at vertices whose trajectories pass
    // near a hyperbolic point (where σ is most sensitive to any perturbation), more slowly
    assert!(
        mean_b < 0.35 * mean_a && max_b < 0.5 * max_a,
        "not converging"
    );
    assert!(mean_b < 1e-3 * smax && max_b < 1.5e-2 * smax);
}

/// A velocity that fails the way a buggy callable would: NaN at one point.
struct NanAt(DVec3);

impl Velocity for NanAt {
    fn eval(
        &mut self,
        _t: f64,
        _at: &[madder::lcs::Located],
        points: &[DVec3],
        out: &mut [DVec3],
    ) -> Result<(), LcsError> {
        for (o, x) in out.iter_mut().zip(points) {
            *o = if *x == self.0 {
                DVec3::NAN
            } else {
                DVec3::X * 0.01
            };
        }
        Ok(())
    }
}

#[test]
fn bad_input_is_named() {
    let (topo, p) = rect_grid(4, 4, [0.0, 1.0], [0.0, 1.0]);
    let motion = Motion::fixed(p.clone());
    let mut v = FnVelocity(|_, _| DVec3::X);
    assert_eq!(
        ftle(&topo, &motion, &mut v, 0.0, 0.0, 10).unwrap_err(),
        LcsError::ZeroSpan { span: 0.0 }
    );
    let err = ftle(&topo, &motion, &mut NanAt(p[7]), 0.0, 1.0, 10).unwrap_err();
    assert!(
        matches!(&err, LcsError::NonFiniteVelocity { at, time } if at.contains("vertex 7") && *time == 0.0),
        "{err}"
    );
    let short = Motion::fixed(p[..10].to_vec());
    assert_eq!(
        ftle(&topo, &short, &mut v, 0.0, 1.0, 10).unwrap_err(),
        LcsError::Mesh(MeshError::VertexCountMismatch {
            expected: 25,
            got: 10
        })
    );
    // per-vertex velocities: wrong shape, NaN (vertex and frame named), time out of range
    let ft = FrameTimes::new(vec![0.0, 1.0]).unwrap();
    let err = VertexVelocity::new(ft.clone(), vec![vec![DVec3::X; 25]; 3], &topo).unwrap_err();
    assert_eq!(
        err.to_string(),
        "velocity has shape (3, 25, 3), expected (2, 25, 3)"
    );
    let mut bad = vec![vec![DVec3::X; 25]; 2];
    bad[1][13].y = f64::NAN;
    let err = VertexVelocity::new(ft.clone(), bad, &topo).unwrap_err();
    assert_eq!(
        err.to_string(),
        "velocity at vertex 13 at time 1 is not finite"
    );
    let mut ok = VertexVelocity::new(ft, vec![vec![DVec3::X * 0.1; 25]; 2], &topo).unwrap();
    let err = ftle(&topo, &motion, &mut ok, 0.5, 1.0, 10).unwrap_err();
    assert!(matches!(err, LcsError::TimeOutOfRange { .. }), "{err}");
    assert_eq!(
        FrameTimes::new(vec![0.0, 1.0, 1.0]).unwrap_err(),
        LcsError::FrameTimes {
            index: 2,
            value: 1.0
        }
    );
    assert_eq!(
        Topology::from_triangles(3, vec![]).unwrap_err(),
        MeshError::Empty
    );
}

#[test]
fn results_do_not_depend_on_the_thread_count() {
    let (topo, p) = rect_grid(50, 25, [0.0, 2.0], [0.0, 1.0]);
    let run = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| planar_ftle(&topo, &p, lcs_common::double_gyre, 0.0, -5.0, 25))
    };
    let (a, b) = (run(1), run(2));
    assert!(a.iter().zip(&b).all(|(x, y)| x.to_bits() == y.to_bits()));
}

/// End points of `flow_map` in world space, with the flat fast path or walking everywhere.
fn end_points(
    topo: &Topology,
    p: &[DVec3],
    velocity: &mut dyn Velocity,
    span: f64,
    steps: usize,
    walk_everywhere: bool,
) -> Vec<DVec3> {
    let mut charts = Charts::new(topo, p).unwrap();
    assert!(charts.is_flat());
    if walk_everywhere {
        charts = charts.walk_everywhere();
    }
    let end = flow_map(
        &charts,
        &Motion::fixed(p.to_vec()),
        velocity,
        0.0,
        span,
        steps,
    )
    .unwrap();
    end.iter()
        .zip(p)
        .map(|(l, &x)| {
            // a loose vertex (inside the hole) stays where it is
            let Some(l) = l else { return x };
            let tri = topo.faces()[l.face as usize].map(|v| p[v as usize]);
            l.bary.x * tri[0] + l.bary.y * tri[1] + l.bary.z * tri[2]
        })
        .collect()
}

#[test]
fn the_flat_fast_path_agrees_with_walking() {
    // a grid with a square hole, a flow that sweeps particles into the hole's border and
    // past it (the fast path must not jump the hole) and along the outer border
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
    let fast = end_points(&topo, &p, &mut FnVelocity(flow), 1.6, 24, false);
    let walked = end_points(&topo, &p, &mut FnVelocity(flow), 1.6, 24, true);
    let diff = fast
        .iter()
        .zip(&walked)
        .map(|(a, b)| a.distance(*b))
        .fold(0.0, f64::max);
    // particles stopped by the hole (the free flow moves every particle by ≥ 0.8; the
    // outer border at x = 1.5 stops others), and far travellers
    let on_hole = walked
        .iter()
        .zip(&p)
        .filter(|(a, b)| a.distance(**b) < 0.3 && a.x < 1.4)
        .count();
    let moved = walked
        .iter()
        .zip(&p)
        .filter(|(a, b)| a.distance(**b) > 0.8)
        .count();
    eprintln!(
        "fast path vs walking: max distance {diff:.1e}; {on_hole} stopped by the hole, {moved} moved > 0.8"
    );
    assert!(on_hole > 20 && moved > 500, "{on_hole} {moved}");
    assert!(diff < 1e-10, "{diff}");

    // a velocity that reads the triangles (per-vertex values) on the same flat mesh
    let ft = FrameTimes::new(vec![0.0, 2.0]).unwrap();
    let frames: Vec<Vec<DVec3>> = [0.0, 2.0]
        .iter()
        .map(|&t| p.iter().map(|&x| flow(t, x)).collect())
        .collect();
    let vv = VertexVelocity::new(ft, frames, &topo).unwrap();
    let fast = end_points(&topo, &p, &mut vv.clone(), 1.6, 24, false);
    let walked = end_points(&topo, &p, &mut vv.clone(), 1.6, 24, true);
    let diff = fast
        .iter()
        .zip(&walked)
        .map(|(a, b)| a.distance(*b))
        .fold(0.0, f64::max);
    eprintln!("per-vertex velocity, fast path vs walking: max distance {diff:.1e}");
    assert!(diff < 1e-10, "{diff}");
}

/// A `rect_grid` over [0, 2] × [0, 1] rolled into a half cylinder around the x axis (an
/// isometry), and the double gyre pushed forward onto it: a curved mesh, walked across
/// its triangles.
fn rolled_gyre_ftle(topo: &Topology, flat: &[DVec3], steps: usize) -> Vec<f64> {
    let r = 1.0 / PI;
    let rolled: Vec<DVec3> = flat
        .iter()
        .map(|q| DVec3::new(q.x, r * (PI * q.y).cos(), r * (PI * q.y).sin()))
        .collect();
    let mut v = FnVelocity(|t, x: DVec3| {
        let theta = x.z.atan2(x.y);
        let u = lcs_common::double_gyre(t, DVec2::new(x.x, theta / PI));
        DVec3::new(u.x, -u.y * theta.sin(), u.y * theta.cos())
    });
    ftle(topo, &Motion::fixed(rolled), &mut v, 0.0, -5.0, steps).unwrap()
}

#[test]
fn curved_walks_do_not_depend_on_the_thread_count() {
    // odd vertex count: the walks go two particles at a time, one is left alone
    let (topo, p) = rect_grid(40, 20, [0.0, 2.0], [0.0, 1.0]);
    assert!(topo.n_vertices() % 2 == 1);
    let run = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| rolled_gyre_ftle(&topo, &p, 20))
    };
    let a = run(1);
    for threads in [2, 3] {
        let b = run(threads);
        assert!(a.iter().zip(&b).all(|(x, y)| x.to_bits() == y.to_bits()));
    }
    // and the flow did cross triangles: the FTLE is the gyre's, not zero
    assert!(a.iter().cloned().fold(0.0, f64::max) > 0.1);
}

#[test]
fn curved_walks_do_not_depend_on_the_faces_windings() {
    // every third face listed the other way round: the walks cross edges whose two faces
    // disagree (a reflection in the unfolding); the particles and the FTLE are the same
    let (topo, p) = rect_grid(40, 20, [0.0, 2.0], [0.0, 1.0]);
    let flipped: Vec<[u32; 3]> = topo
        .faces()
        .iter()
        .enumerate()
        .map(|(f, t)| if f % 3 == 0 { [t[0], t[2], t[1]] } else { *t })
        .collect();
    let topo_flipped = Topology::from_triangles(topo.n_vertices(), flipped).unwrap();
    let a = rolled_gyre_ftle(&topo, &p, 20);
    let b = rolled_gyre_ftle(&topo_flipped, &p, 20);
    let diff = a
        .iter()
        .zip(&b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max);
    let max = a.iter().cloned().fold(0.0, f64::max);
    eprintln!("windings flipped: max FTLE difference {diff:.1e} (σ_max {max:.3})");
    assert!(max > 0.1 && diff < 1e-9 * max, "{diff}");
}
