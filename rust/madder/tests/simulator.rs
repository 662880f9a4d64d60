//! Validation of the full stain simulator (issue 3; seed chapter 4, §4.3–4.5) against
//! exact or independent references:
//!
//! 1. a blob on a rotating disk goes straight in the inertial frame (seed Fig. 4.2), and
//!    visibly does not without the Coriolis term;
//! 2. a plane accelerating in its own plane leaves the blob behind by `½at²`; a still plane
//!    tilted by `θ` lets it run down `½g sinθ t²`;
//! 3. woven-fabric spreading: the covariance follows the weft and grows in the ratio of
//!    the tensor's eigenvalues;
//! 4. absorption, adsorption and evaporation of a uniform liquid follow their closed forms;
//! 5. conservation (solute; solvent + evaporated) and non-negativity on a waving,
//!    stretching cloth over 1000 steps;
//! 6. bad input: degenerate faces, non-manifold edges, loose and border vertices; parameters
//!    out of range; a NaN position leaves the simulator untouched;
//! 7. bit-identical results on 1 and 2 threads;
//! 8. splashes: outgoing, within the ±0.5 rad turn, reproducible from the seed;
//! 9. the momentum-advection option: the tilted plane and conservation again.

use std::f64::consts::PI;

use faer::Par;
use glam::{DVec2, DVec3};
use madder::mesh::Topology;
use madder::stain::{
    Conductivity, Fields, Forces, InteractionRates, Simulator, StainParams, WovenFaces,
};
use madder::{Error, MeshError, ParamError};

mod common;
use common::{Grid, centroid, covariance, disk, gaussian, no_interaction, spun};

// ---------------------------------------------------------------------------------------
// meshes and helpers

/// A frictionless, inviscid liquid that does not interact with the cloth.
fn ideal(forces: Forces) -> StainParams {
    StainParams {
        gravity: DVec3::new(0.0, 0.0, -9.81),
        forces,
        momentum_advection: false,
        viscosity: 0.0,
        friction: 0.0,
        interaction: no_interaction(),
        wicking: Default::default(),
        irregularity: Default::default(),
        carry_solute: false,
        residual_saturation: 0.0,
        carried_fraction: 1.0,
        dispersivity: 0.0,
        vapour_limited: false,
        holdup: 0.0,
        film_creep: 1.0,
        substeps: 1,
        first_substep: 0.0,
        drip_hold: 0.0,
        capillary_height: 0.0,
        active_region: true,
    }
}

const ALL_FORCES: Forces = Forces {
    gravity: true,
    rectilinear: true,
    coriolis: true,
};

const NO_FORCES: Forces = Forces {
    gravity: false,
    rectilinear: false,
    coriolis: false,
};

const COLOR: [f64; 3] = [0.45, 0.05, 0.1];

fn simulator(
    topology: &Topology,
    rest: &[DVec3],
    positions: &[DVec3],
    conductivity: Conductivity,
    params: StainParams,
) -> Simulator {
    Simulator::new(
        topology.clone(),
        rest,
        positions,
        conductivity,
        params,
        COLOR,
        Par::Seq,
    )
    .unwrap()
}

/// Eigen-decomposition of a symmetric 2×2 `[a, b, c]`: (largest, smallest, angle of the
/// largest's eigenvector in (−π/2, π/2]).
fn eigen2(m: [f64; 3]) -> (f64, f64, f64) {
    let [a, b, c] = m;
    let mid = 0.5 * (a + c);
    let rad = (0.25 * (a - c) * (a - c) + b * b).sqrt();
    (mid + rad, mid - rad, 0.5 * (2.0 * b).atan2(a - c))
}

/// `x` wrapped into (−π/2, π/2] (an axis has no sign).
fn axis_difference(x: f64) -> f64 {
    let mut d = x.rem_euclid(PI);
    if d > 0.5 * PI {
        d -= PI;
    }
    d
}

fn all_fields(f: &Fields) -> [(&'static str, &[f64]); 5] {
    [
        ("free solvent", &f.free_solvent),
        ("solute", &f.solute),
        ("absorbed solvent", &f.absorbed_solvent),
        ("absorbed solute", &f.absorbed_solute),
        ("adsorbed", &f.adsorbed),
    ]
}

/// Every mass finite and `≥ 0` (and every velocity finite); `what` names the step.
fn assert_sane(sim: &Simulator, what: &str) {
    for (name, v) in all_fields(sim.fields()) {
        if let Some(i) = v.iter().position(|x| !(x.is_finite() && *x >= 0.0)) {
            panic!("{what}: {name} at vertex {i} is {}", v[i]);
        }
    }
    if let Some(i) = sim.velocity().iter().position(|u| !u.is_finite()) {
        panic!("{what}: velocity at vertex {i} is {}", sim.velocity()[i]);
    }
}

fn rel(a: f64, b: f64) -> f64 {
    (a - b).abs() / b.abs()
}

// ---------------------------------------------------------------------------------------
// 1. rotating disk (seed Fig. 4.2)

/// A blob at rest on a disk turning at `ω`: after 1 s, the error of its world centroid
/// against the straight inertial path, relative to the distance travelled.
fn rotating_disk_path_error(coriolis: bool) -> (f64, f64) {
    let omega = 0.5 * PI;
    let dt = 1.0 / 24.0;
    let (topo, rest) = disk(40, 1.0);
    let frame = |k: usize| spun(&rest, omega * dt * k as f64);
    let forces = Forces {
        gravity: false,
        rectilinear: true,
        coriolis,
    };
    let mut sim = simulator(
        &topo,
        &rest,
        &frame(0),
        Conductivity::Isotropic(0.0),
        ideal(forces),
    );
    sim.add_liquid(
        &gaussian(&rest, DVec2::new(0.3, 0.0), 0.04 * 0.04, 1.0),
        0.0,
        None,
    )
    .unwrap();
    let c0 = centroid(&sim.fields().free_solvent, &frame(0));
    for k in 1..=24 {
        sim.step(&frame(k), dt, Some(&frame(k + 1))).unwrap();
        assert_sane(&sim, &format!("frame {k}"));
    }
    let t = sim.time();
    assert!((t - 1.0).abs() < 1e-12);
    let c = centroid(&sim.fields().free_solvent, &frame(24));
    let expected = c0 + DVec3::Z.cross(c0) * omega * t; // p0 + (ω × p0) t
    let travelled = (expected - c0).length();
    let error = (c - expected).length() / travelled;
    println!(
        "rotating disk, Coriolis {coriolis}: centroid {c:.4} expected {expected:.4}, path error {:.2}% of {travelled:.3} m",
        100.0 * error
    );
    (error, travelled)
}

#[test]
fn rotating_disk_blob_moves_straight_in_the_inertial_frame() {
    let (with, _) = rotating_disk_path_error(true);
    let (without, _) = rotating_disk_path_error(false);
    println!(
        "path error: {:.2}% with Coriolis, {:.2}% without",
        100.0 * with,
        100.0 * without
    );
    assert!(with <= 0.05, "path error {:.2}% > 5%", 100.0 * with);
    assert!(
        without > 0.20,
        "without Coriolis the path error is only {:.2}%",
        100.0 * without
    );
}

// ---------------------------------------------------------------------------------------
// 2. accelerating and tilted planes

#[test]
fn accelerating_plane_leaves_the_blob_behind_by_half_a_t_squared() {
    let a = 2.0;
    let dt = 1.0 / 24.0;
    let frames = 12; // 0.5 s
    let (topo, rest) = Grid::new(60, 1.0).build();
    let frame = |k: usize| -> Vec<DVec3> {
        let t = k as f64 * dt;
        rest.iter()
            .map(|p| *p + DVec3::X * (0.5 * a * t * t))
            .collect()
    };
    let forces = Forces {
        gravity: false,
        ..ALL_FORCES
    };
    let mut sim = simulator(
        &topo,
        &rest,
        &frame(0),
        Conductivity::Isotropic(0.0),
        ideal(forces),
    );
    sim.add_liquid(
        &gaussian(&rest, DVec2::new(0.4, 0.0), 0.08 * 0.08, 1.0),
        0.0,
        None,
    )
    .unwrap();
    let c0 = centroid(&sim.fields().free_solvent, &rest);
    for k in 1..=frames {
        sim.step(&frame(k), dt, Some(&frame(k + 1))).unwrap();
        assert_sane(&sim, &format!("frame {k}"));
    }
    let t = sim.time();
    let moved = centroid(&sim.fields().free_solvent, &rest) - c0;
    let expected = -0.5 * a * t * t;
    let err = rel(moved.x, expected);
    println!(
        "accelerating plane: drift {:.5} m vs −½at² = {expected:.5} m ({:.2}%), sideways {:.2e} m",
        moved.x,
        100.0 * err,
        moved.y
    );
    assert!(err <= 0.05, "drift {} vs {expected}", moved.x);
    assert!(
        moved.y.abs() <= 0.01 * expected.abs(),
        "sideways drift {}",
        moved.y
    );
}

/// A still plane tilted by 30° about x, gravity only, `frames` frames at 24 fps: (drift
/// down the slope, expected, drift across). The expected drift from rest under the slope's
/// acceleration `a = g sinθ` is `½at²` without friction and `(a/k)(t − (1 − e^{−kt})/k)`
/// with friction `k` (the solution of `u̇ = a − ku`, integrated).
fn tilted_plane_drift(momentum_advection: bool, friction: f64, frames: usize) -> (f64, f64, f64) {
    let theta = PI / 6.0;
    let g = 9.81;
    let dt = 1.0 / 24.0;
    let (topo, flat) = Grid::new(60, 1.0).build();
    let tilted: Vec<DVec3> = flat
        .iter()
        .map(|p| DVec3::new(p.x, p.y * theta.cos(), p.y * theta.sin()))
        .collect();
    let mut params = ideal(ALL_FORCES); // the plane is still: only gravity acts
    params.momentum_advection = momentum_advection;
    params.friction = friction;
    let mut sim = simulator(
        &topo,
        &tilted,
        &tilted,
        Conductivity::Isotropic(0.0),
        params,
    );
    sim.add_liquid(
        &gaussian(&flat, DVec2::new(0.0, 0.5), 0.08 * 0.08, 1.0),
        0.02,
        None,
    )
    .unwrap();
    let c0 = centroid(&sim.fields().free_solvent, &flat);
    let s0 = sim.totals();
    for k in 1..=frames {
        sim.step(&tilted, dt, Some(&tilted)).unwrap();
        assert_sane(&sim, &format!("frame {k}"));
    }
    let t = sim.time();
    let s1 = sim.totals();
    assert!(rel(s1.solute, s0.solute) <= 1e-12 && rel(s1.solvent, s0.solvent) <= 1e-12);
    let moved = centroid(&sim.fields().free_solvent, &flat) - c0;
    let (a, k) = (g * theta.sin(), friction);
    let expected = if k > 0.0 {
        a / k * (t + (-k * t).exp_m1() / k)
    } else {
        0.5 * a * t * t
    };
    println!(
        "tilted plane (momentum advection {momentum_advection}, friction {k}/s): down the slope {:.5} m vs {expected:.5} m ({:.2}%), across {:.2e} m",
        -moved.y,
        100.0 * rel(-moved.y, expected),
        moved.x
    );
    (-moved.y, expected, moved.x)
}

#[test]
fn tilted_plane_blob_runs_down_half_g_sin_theta_t_squared() {
    let (down, expected, across) = tilted_plane_drift(false, 0.0, 8);
    assert!(rel(down, expected) <= 0.05, "drift {down} vs {expected}");
    assert!(across.abs() <= 0.01 * expected, "sideways drift {across}");
}

#[test]
fn with_friction_the_blob_runs_at_its_terminal_speed() {
    // k = 50/s at 24 fps (kh ≈ 2): the terminal speed a/k is reached within a frame; a
    // kick followed by the decay e^{-kh} would run at 30 % of it
    let (down, expected, across) = tilted_plane_drift(false, 50.0, 24);
    assert!(rel(down, expected) <= 0.05, "drift {down} vs {expected}");
    assert!(across.abs() <= 0.01 * expected, "sideways drift {across}");
}

// ---------------------------------------------------------------------------------------
// 3. anisotropic spreading

#[test]
fn woven_spreading_follows_the_weft_in_the_ratio_of_the_eigenvalues() {
    let (d1, d2) = (1e-2, 2.5e-3);
    let phi = 25f64.to_radians();
    let dt = 1.0 / 24.0;
    let (topo, rest) = Grid::new(64, 1.0).build();
    let (e, e_perp) = (DVec2::from_angle(phi), DVec2::from_angle(phi + 0.5 * PI));
    // the UV map is the mesh turned by −φ: u grows along e, the weft is at φ in the world
    let uv = topo
        .faces()
        .iter()
        .map(|f| {
            f.map(|v| {
                let p = rest[v as usize].truncate();
                [p.dot(e), p.dot(e_perp)]
            })
        })
        .collect();
    let woven = WovenFaces {
        tensor: vec![[d1, 0.0, d2]; topo.n_faces()],
        uv,
        angle: vec![0.0; topo.n_faces()],
    };
    let mut sim = simulator(
        &topo,
        &rest,
        &rest,
        Conductivity::Woven(woven),
        ideal(NO_FORCES),
    );
    sim.add_liquid(&gaussian(&rest, DVec2::ZERO, 0.06 * 0.06, 1.0), 0.0, None)
        .unwrap();
    let c0 = covariance(&sim.fields().free_solvent, &rest);
    let total0 = sim.totals().solvent;
    for k in 1..=24 {
        sim.step(&rest, dt, None).unwrap();
        assert_sane(&sim, &format!("frame {k}"));
    }
    let t = sim.time();
    assert!(rel(sim.totals().solvent, total0) < 1e-12);
    let c1 = covariance(&sim.fields().free_solvent, &rest);
    let (_, _, axis) = eigen2(c1);
    let grown = [c1[0] - c0[0], c1[1] - c0[1], c1[2] - c0[2]];
    let (long, short, grown_axis) = eigen2(grown);
    let ratio = long / short;
    let angle_err = axis_difference(axis - phi).to_degrees();
    println!(
        "woven spreading: covariance axis {:.3}° (weft {:.1}°, error {angle_err:.3}°), growth axis {:.3}°; \
         variance growth {long:.5} / {short:.5} = {ratio:.4} (D1/D2 = {:.1}; continuum 2Dt = {:.5} / {:.5})",
        axis.to_degrees(),
        phi.to_degrees(),
        grown_axis.to_degrees(),
        d1 / d2,
        2.0 * d1 * t,
        2.0 * d2 * t
    );
    assert!(
        angle_err.abs() <= 2.0,
        "covariance axis off the weft by {angle_err}°"
    );
    assert!(
        rel(ratio, d1 / d2) <= 0.05,
        "variance ratio {ratio} vs {}",
        d1 / d2
    );
    // and the rate itself: Var grows by 2Dt along each axis
    assert!(
        rel(long, 2.0 * d1 * t) <= 0.05,
        "variance growth along the weft {long} vs {}",
        2.0 * d1 * t
    );
    assert!(
        rel(short, 2.0 * d2 * t) <= 0.05,
        "variance growth across {short} vs {}",
        2.0 * d2 * t
    );
}

// ---------------------------------------------------------------------------------------
// 4. interactions against their closed forms

/// Uniform liquid on a still flat cloth: nothing flows, so every vertex integrates the
/// interaction ODEs on its own. Checks every vertex at every frame.
fn uniform_run(
    rates: InteractionRates,
    diffusion: f64,
    solvent: f64,
    concentration: f64,
    frames: usize,
    mut check: impl FnMut(f64, &Simulator),
) {
    let (topo, rest) = Grid::new(16, 0.5).build();
    let mut params = ideal(NO_FORCES);
    params.interaction = rates;
    params.substeps = 3;
    let mut sim = simulator(
        &topo,
        &rest,
        &rest,
        Conductivity::Isotropic(diffusion),
        params,
    );
    sim.add_liquid(&vec![solvent; rest.len()], concentration, None)
        .unwrap();
    let dt = 1.0 / 24.0;
    for k in 1..=frames {
        sim.step(&rest, dt, None).unwrap();
        assert_sane(&sim, &format!("frame {k}"));
        check(k as f64 * dt, &sim);
    }
}

fn close(got: f64, expected: f64, what: &str, t: f64, vertex: usize) {
    assert!(
        (got - expected).abs() <= 1e-9 * expected.abs() + 1e-300,
        "t = {t:.4}: {what} at vertex {vertex} is {got:e}, closed form {expected:e} (rel. {:.2e})",
        (got - expected).abs() / expected.abs()
    );
}

#[test]
fn absorption_and_adsorption_follow_their_closed_forms() {
    let (kp, sat, kd, ad) = (2.0, 0.1, 0.5, 2e-3);
    let (f0, c) = (0.5, 0.02); // plenty of free solvent and of solute
    let rates = InteractionRates {
        absorption: kp,
        saturation: sat,
        adsorption: kd,
        capacity: ad,
        evaporation: 0.0,
        evaporation_boundary: 1.2,
    };
    let mut worst: f64 = 0.0;
    uniform_run(rates, 1e-3, f0, c, 48, |t, sim| {
        let p = sat * -(-kp * t).exp_m1();
        let sa = ad * -(-kd * t).exp_m1();
        let f = f0 - p;
        // absorption keeps the concentrations of free and held solution equal, adsorption
        // takes the same fraction of both: the solute left is split like the solvent
        let left = c * f0 - sa;
        let fields = sim.fields();
        let d = |m: &[f64]| sim.density(m);
        let (df, dp) = (d(&fields.free_solvent), d(&fields.absorbed_solvent));
        let (ds, dsp, dsa) = (
            d(&fields.solute),
            d(&fields.absorbed_solute),
            d(&fields.adsorbed),
        );
        for i in 0..df.len() {
            close(dp[i], p, "absorbed solvent", t, i);
            close(df[i], f, "free solvent", t, i);
            close(dsa[i], sa, "adsorbed solute", t, i);
            close(ds[i], left * f / f0, "dissolved solute", t, i);
            close(dsp[i], left * p / f0, "absorbed solute", t, i);
            worst = worst.max(rel(dp[i], p)).max(rel(dsa[i], sa));
        }
        assert_eq!(sim.totals().evaporated, 0.0);
    });
    println!("absorption/adsorption: worst relative error {worst:.2e} over 2 s");
}

#[test]
fn absorption_and_adsorption_stop_when_the_supply_runs_out() {
    let (kp, sat, kd, ad) = (2.0, 0.1, 0.5, 2e-3);
    // less free solvent than saturation, less solute than the adsorption capacity
    let (f0, c) = (0.05, 0.01);
    let supply = c * f0;
    let rates = InteractionRates {
        absorption: kp,
        saturation: sat,
        adsorption: kd,
        capacity: ad,
        evaporation: 0.0,
        evaporation_boundary: 1.2,
    };
    let (mut dried, mut deposited) = (None, None);
    uniform_run(rates, 1e-3, f0, c, 48, |t, sim| {
        let p_free = sat * -(-kp * t).exp_m1();
        let sa_free = ad * -(-kd * t).exp_m1();
        let fields = sim.fields();
        let d = |m: &[f64]| sim.density(m);
        let (df, dp, dsa) = (
            d(&fields.free_solvent),
            d(&fields.absorbed_solvent),
            d(&fields.adsorbed),
        );
        let (ds, dsp) = (d(&fields.solute), d(&fields.absorbed_solute));
        for i in 0..df.len() {
            if p_free < f0 * (1.0 - 1e-9) {
                close(dp[i], p_free, "absorbed solvent", t, i);
            } else if p_free > f0 * (1.0 + 1e-9) {
                // all the free solvent is in the fibres, exactly, with all its solute
                assert_eq!(
                    fields.free_solvent[i], 0.0,
                    "t = {t}: free solvent left at {i}"
                );
                assert_eq!(
                    fields.solute[i], 0.0,
                    "t = {t}: dissolved solute left at {i}"
                );
                close(dp[i], f0, "absorbed solvent", t, i);
                dried.get_or_insert(t);
            }
            if sa_free < supply * (1.0 - 1e-9) {
                close(dsa[i], sa_free, "adsorbed solute", t, i);
            } else if sa_free > supply * (1.0 + 1e-9) {
                assert_eq!(
                    ds[i] + dsp[i],
                    0.0,
                    "t = {t}: solute left undeposited at {i}"
                );
                close(dsa[i], supply, "adsorbed solute", t, i);
                deposited.get_or_insert(t);
            }
        }
    });
    println!(
        "supply limits: free solvent gone at t = {dried:?} s, solute all deposited at t = {deposited:?} s"
    );
    assert!(
        dried.is_some() && deposited.is_some(),
        "the run did not reach both limits"
    );
}

#[test]
fn evaporation_is_faster_on_the_exposed_border_and_is_accounted() {
    let (k, a) = (1e-3, 1.2);
    let f0 = 0.5;
    let rates = InteractionRates {
        absorption: 0.0,
        saturation: 0.1,
        adsorption: 0.0,
        capacity: 2e-3,
        evaporation: k,
        evaporation_boundary: a,
    };
    let (topo, _) = Grid::new(16, 0.5).build();
    let border = topo.boundary_vertices();
    let mut initial = None;
    uniform_run(rates, 0.0, f0, 0.02, 48, |t, sim| {
        let f = sim.density(&sim.fields().free_solvent);
        let area = sim.vertex_area();
        for i in 0..f.len() {
            let expected = if border[i] {
                f0 - a * k * t
            } else {
                f0 - k * t
            };
            close(f[i], expected, "free solvent", t, i);
        }
        let totals = sim.totals();
        let s0 = *initial.get_or_insert(f0 * area.iter().sum::<f64>());
        let lost = s0 - totals.solvent;
        assert!(
            (totals.evaporated - lost).abs() <= 1e-12 * s0,
            "t = {t}: evaporated {} vs solvent lost {lost}",
            totals.evaporated
        );
        // and the model's amount: Σ a_i K A_i t
        let model: f64 = (0..f.len())
            .map(|i| if border[i] { a } else { 1.0 } * k * area[i] * t)
            .sum();
        close(totals.evaporated, model, "evaporated total", t, 0);
        assert!(rel(totals.solute, 0.02 * s0) <= 1e-12);
    });
}

#[test]
fn evaporation_stops_when_the_cloth_is_dry_and_leaves_the_solute() {
    let rates = InteractionRates {
        absorption: 0.0,
        saturation: 0.1,
        adsorption: 0.0,
        capacity: 2e-3,
        evaporation: 1e-3,
        evaporation_boundary: 1.2,
    };
    let (f0, c) = (2e-3, 0.05);
    let mut last = None;
    uniform_run(rates, 0.0, f0, c, 72, |t, sim| {
        let totals = sim.totals();
        last = Some((t, totals, sim.fields().clone(), sim.vertex_area().to_vec()));
    });
    let (t, totals, fields, area) = last.unwrap();
    let s0 = f0 * area.iter().sum::<f64>();
    assert!(t > f0 / 1e-3, "the run is too short to dry");
    assert_eq!(totals.solvent, 0.0, "solvent left after drying");
    assert!(fields.free_solvent.iter().all(|&x| x == 0.0));
    assert!(
        rel(totals.evaporated, s0) <= 1e-12,
        "evaporated {} of {s0}",
        totals.evaporated
    );
    // the solute dried in place
    assert!(fields.solute.iter().all(|&x| x == 0.0));
    for (i, (held, a)) in fields.absorbed_solute.iter().zip(&area).enumerate() {
        close(*held, c * f0 * a, "dried solute", t, i);
    }
}

// ---------------------------------------------------------------------------------------
// 5. conservation on a waving, stretching cloth

/// A 30×30 grid over [−1, 1]² waving (travelling wave in z) and stretching in x and y.
fn waving(n: usize) -> (Topology, Vec<DVec3>, impl Fn(f64) -> Vec<DVec3>) {
    let (topo, rest) = Grid::new(n, 1.0).build();
    let r = rest.clone();
    let at = move |t: f64| -> Vec<DVec3> {
        let sx = 1.0 + 0.2 * (1.3 * t).sin();
        let sy = 1.0 + 0.1 * (0.7 * t).cos() - 0.1;
        r.iter()
            .map(|p| {
                DVec3::new(
                    p.x * sx + 0.05 * (2.0 * p.y + t).sin(),
                    p.y * sy,
                    0.2 * (2.5 * p.x - 4.0 * t).sin() * (1.5 * p.y + t).cos() + 0.3 * p.y,
                )
            })
            .collect()
    };
    (topo, rest, at)
}

/// Everything on: all forces, woven (anisotropic) diffusion with wicking, viscosity, friction, all
/// interactions, a splash and a second pour of another colour.
fn full_params(momentum_advection: bool, substeps: u32) -> StainParams {
    StainParams {
        gravity: DVec3::new(0.0, 0.0, -9.81),
        forces: ALL_FORCES,
        momentum_advection,
        viscosity: 1e-3,
        friction: 2.0,
        interaction: InteractionRates {
            absorption: 2.0,
            saturation: 0.1,
            adsorption: 0.5,
            capacity: 2e-3,
            evaporation: 2e-3,
            evaporation_boundary: 1.2,
        },
        // wicking too (issue 13): a saturation-dependent rate on the woven faces
        wicking: madder::stain::Wicking {
            exponent: 2.0,
            density: 0.1,
            picard: 0,
            tolerance: 0.0,
        },
        // and an irregular fabric
        irregularity: madder::stain::Irregularity {
            amplitude: 0.4,
            correlation_length: 0.05,
            seed: 7,
            fine_length: 0.0,
        },
        // the solute carried by the solvent's flow, to a pinned edge drying fastest there
        carry_solute: true,
        residual_saturation: 0.1,
        carried_fraction: 1.0,
        dispersivity: 0.0,
        vapour_limited: true,
        holdup: 0.0,
        film_creep: 1.0,
        substeps,
        first_substep: 0.0,
        drip_hold: 0.0,
        capillary_height: 0.0,
        active_region: true,
    }
}

fn woven_on(topo: &Topology, rest: &[DVec3], angle: f64) -> Conductivity {
    let (e, e_perp) = (
        DVec2::from_angle(angle),
        DVec2::from_angle(angle + 0.5 * PI),
    );
    Conductivity::Woven(WovenFaces {
        tensor: vec![[4e-3, 5e-4, 1e-3]; topo.n_faces()],
        uv: topo
            .faces()
            .iter()
            .map(|f| {
                f.map(|v| {
                    let p = rest[v as usize].truncate();
                    [p.dot(e), p.dot(e_perp)]
                })
            })
            .collect(),
        angle: vec![0.0; topo.n_faces()],
    })
}

/// Runs `steps` frames of the waving cloth with everything on, checking sign, finiteness
/// and conservation after every step; returns the simulator and the worst relative
/// defects (solute, solvent + evaporated).
fn waving_run(steps: usize, momentum_advection: bool) -> (Simulator, f64, f64) {
    let (topo, rest, at) = waving(30);
    let dt = 1.0 / 30.0;
    let mut sim = simulator(
        &topo,
        &rest,
        &at(0.0),
        woven_on(&topo, &rest, 0.4),
        full_params(momentum_advection, 1),
    );
    sim.add_liquid(
        &gaussian(&rest, DVec2::new(-0.2, 0.3), 0.25 * 0.25, 0.4),
        0.03,
        None,
    )
    .unwrap();
    let weights = gaussian(&rest, DVec2::new(-0.2, 0.3), 0.15 * 0.15, 1.0);
    let nearest = (0..rest.len())
        .min_by(|&a, &b| {
            let d = |i: usize| (rest[i].truncate() - DVec2::new(-0.2, 0.3)).length();
            d(a).total_cmp(&d(b))
        })
        .unwrap();
    sim.splash(at(0.0)[nearest], 1.5, 7, &weights).unwrap();
    let (mut worst_solute, mut worst_solvent): (f64, f64) = (0.0, 0.0);
    let mut reference = sim.totals();
    for k in 1..=steps {
        let t = k as f64 * dt;
        sim.step(&at(t), dt, Some(&at(t + dt))).unwrap();
        assert_sane(&sim, &format!("step {k}"));
        let now = sim.totals();
        let ds = rel(now.solute, reference.solute);
        let dv = rel(
            now.solvent + now.evaporated,
            reference.solvent + reference.evaporated,
        );
        worst_solute = worst_solute.max(ds);
        worst_solvent = worst_solvent.max(dv);
        assert!(
            ds <= 1e-9,
            "step {k}: solute {} vs {}",
            now.solute,
            reference.solute
        );
        assert!(
            dv <= 1e-9,
            "step {k}: solvent + evaporated {} vs {}",
            now.solvent + now.evaporated,
            reference.solvent + reference.evaporated
        );
        if k == steps / 3 {
            // a second liquid of another colour (switches colour tracking on)
            sim.add_liquid(
                &gaussian(&rest, DVec2::new(0.4, -0.3), 0.2 * 0.2, 0.3),
                0.05,
                Some([0.1, 0.2, 0.8]),
            )
            .unwrap();
            reference = sim.totals();
        }
    }
    (sim, worst_solute, worst_solvent)
}

#[test]
fn conservation_on_a_waving_stretching_cloth_over_1000_steps() {
    let (sim, ds, dv) = waving_run(1000, false);
    let t = sim.totals();
    let wet = sim
        .fields()
        .free_solvent
        .iter()
        .filter(|&&m| m > 0.0)
        .count();
    println!(
        "waving cloth, 1000 steps: solute defect ≤ {ds:.2e}, solvent+evaporated defect ≤ {dv:.2e}; \
         evaporated {:.4e} of {:.4e} kg, adsorbed {:.3e} kg, {wet} vertices with free solvent",
        t.evaporated,
        t.solvent + t.evaporated,
        sim.fields().adsorbed.iter().sum::<f64>()
    );
    // the processes did act
    assert!(t.evaporated > 0.05 * (t.solvent + t.evaporated));
    assert!(sim.fields().adsorbed.iter().sum::<f64>() > 0.0);
    assert!(sim.fields().absorbed_solvent.iter().sum::<f64>() > 0.0);
}

// ---------------------------------------------------------------------------------------
// 9. the momentum-advection option

#[test]
fn momentum_advection_tilted_plane_and_conservation() {
    let (down, expected, across) = tilted_plane_drift(true, 0.0, 8);
    assert!(rel(down, expected) <= 0.10, "drift {down} vs {expected}");
    assert!(across.abs() <= 0.02 * expected, "sideways drift {across}");
    let (_, ds, dv) = waving_run(1000, true);
    println!(
        "momentum advection, waving cloth 1000 steps: solute defect ≤ {ds:.2e}, solvent defect ≤ {dv:.2e}"
    );
}

// ---------------------------------------------------------------------------------------
// 6. bad input

/// A 12×12 grid plus: a zero-area flap on a border edge (its third vertex at the edge's
/// midpoint), a zero-area face with a vertex coincident with a border vertex, a fin (a
/// third face on an interior edge: non-manifold), a collapsed interior edge (one vertex
/// moved onto its neighbour), and a loose vertex. Returns the topology and a function of
/// time giving the positions under an affine motion (which keeps the degeneracies exact).
fn bad_mesh() -> (Topology, Vec<DVec3>, impl Fn(f64) -> Vec<DVec3>) {
    let n = 12;
    let grid = Grid::new(n, 0.5);
    let (mut faces, mut pos) = grid.arrays();
    let idx = |i: usize, j: usize| grid.index(i, j);
    // zero-area flap on the border edge (0,3)-(0,4)
    let (a, b) = (idx(0, 3), idx(0, 4));
    pos.push(0.5 * (pos[a as usize] + pos[b as usize]));
    faces.push([b, a, (pos.len() - 1) as u32]);
    // coincident vertex on the border edge (5,12)-(6,12)
    let (c, d) = (idx(5, n), idx(6, n));
    pos.push(pos[c as usize]);
    faces.push([c, d, (pos.len() - 1) as u32]);
    // fin on the interior edge (6,6)-(6,7)
    let (e1, e2) = (idx(6, 6), idx(6, 7));
    pos.push(0.5 * (pos[e1 as usize] + pos[e2 as usize]) + DVec3::new(0.0, 0.02, 0.06));
    faces.push([e1, e2, (pos.len() - 1) as u32]);
    // collapsed interior edge: (3,3) onto (3,4)
    pos[idx(3, 3) as usize] = pos[idx(3, 4) as usize];
    // a loose vertex
    pos.push(DVec3::new(0.7, 0.7, 0.0));
    let topo = Topology::from_triangles(pos.len(), faces).unwrap();
    assert!(!topo.non_manifold_edges().is_empty());
    assert!(topo.loose_vertices().iter().any(|&l| l));
    let rest = pos.clone();
    let at = move |t: f64| -> Vec<DVec3> {
        // tilt about x oscillating, stretch in x, a shear, a translation
        let tilt = 0.5 + 0.3 * (2.0 * t).sin();
        let (s, c) = tilt.sin_cos();
        let stretch = 1.0 + 0.2 * (3.0 * t).sin();
        rest.iter()
            .map(|p| {
                let x = p.x * stretch + 0.1 * (1.5 * t).sin() * p.y;
                DVec3::new(x + 0.1 * t, p.y * c - p.z * s, p.y * s + p.z * c)
            })
            .collect()
    };
    (topo, pos, at)
}

#[test]
fn degenerate_non_manifold_and_border_vertices_step_without_nan() {
    let (topo, rest, at) = bad_mesh();
    let dt = 1.0 / 24.0;
    let mut sim = simulator(
        &topo,
        &rest,
        &at(0.0),
        Conductivity::Isotropic(2e-3),
        full_params(false, 1),
    );
    // liquid everywhere, degenerate and loose vertices included
    let liquid: Vec<f64> = (0..rest.len())
        .map(|i| 0.2 + 0.1 * (i as f64 * 0.37).sin())
        .collect();
    sim.add_liquid(&liquid, 0.03, None).unwrap();
    let weights = vec![1.0; rest.len()];
    sim.splash(DVec3::ZERO, 1.0, 3, &weights).unwrap();
    let r = sim.totals();
    for k in 1..=200 {
        let t = k as f64 * dt;
        sim.step(&at(t), dt, Some(&at(t + dt))).unwrap();
        assert_sane(&sim, &format!("step {k}"));
        let now = sim.totals();
        assert!(
            rel(now.solute, r.solute) <= 1e-9,
            "step {k}: solute {} vs {}",
            now.solute,
            r.solute
        );
        assert!(
            rel(now.solvent + now.evaporated, r.solvent) <= 1e-9,
            "step {k}: solvent {} + evaporated {} vs {}",
            now.solvent,
            now.evaporated,
            r.solvent
        );
    }
    let now = sim.totals();
    println!(
        "bad mesh, 200 steps: solute defect {:.2e}, solvent defect {:.2e}",
        rel(now.solute, r.solute),
        rel(now.solvent + now.evaporated, r.solvent)
    );
}

fn expect_param_error(result: Result<Simulator, Error>, name: &str) {
    match result {
        Err(Error::Param(e @ (ParamError::OutOfRange { .. } | ParamError::NonFinite { .. }))) => {
            let msg = e.to_string();
            assert!(msg.contains(name), "error {msg:?} does not name {name:?}");
        }
        Err(e) => panic!("{name}: wrong error {e:?}"),
        Ok(_) => panic!("{name}: accepted"),
    }
}

#[test]
fn parameters_out_of_range_are_rejected_by_name() {
    let (topo, rest) = Grid::new(4, 0.5).build();
    let make = |edit: &dyn Fn(&mut StainParams), cond: Conductivity| {
        let mut p = StainParams::default();
        edit(&mut p);
        Simulator::new(topo.clone(), &rest, &rest, cond, p, COLOR, Par::Seq)
    };
    let iso = || Conductivity::Isotropic(1e-3);
    expect_param_error(
        make(&|p| p.interaction.absorption = -1.0, iso()),
        "absorption",
    );
    expect_param_error(
        make(&|p| p.interaction.adsorption = -0.1, iso()),
        "adsorption",
    );
    expect_param_error(
        make(&|p| p.interaction.evaporation = -1e-5, iso()),
        "evaporation",
    );
    expect_param_error(
        make(&|p| p.interaction.saturation = f64::NAN, iso()),
        "saturation",
    );
    expect_param_error(make(&|p| p.interaction.capacity = -1.0, iso()), "capacity");
    expect_param_error(
        make(&|p| p.interaction.evaporation_boundary = 0.5, iso()),
        "evaporation boundary",
    );
    expect_param_error(make(&|p| p.friction = -1.0, iso()), "friction");
    expect_param_error(make(&|p| p.viscosity = f64::NAN, iso()), "viscosity");
    expect_param_error(make(&|p| p.substeps = 0, iso()), "substeps");
    expect_param_error(make(&|p| p.gravity.y = f64::NAN, iso()), "gravity");
    expect_param_error(make(&|_| {}, Conductivity::Isotropic(-1e-3)), "diffusion");
    assert!(make(&|_| {}, iso()).is_ok());

    let mut sim = make(&|_| {}, iso()).unwrap();
    for dt in [0.0, -0.1, f64::NAN, f64::INFINITY] {
        match sim.step(&rest, dt, None) {
            Err(Error::Param(e)) => assert!(e.to_string().contains("time step"), "{e}"),
            other => panic!("dt = {dt}: {other:?}"),
        }
    }
    match sim.add_liquid(&vec![-1.0; rest.len()], 0.0, None) {
        Err(e) => println!("negative liquid: {e}"),
        Ok(()) => panic!("negative liquid accepted"),
    }
}

#[test]
fn a_nan_position_names_the_vertex_and_leaves_the_state_unchanged() {
    let (topo, rest, at) = waving(12);
    let dt = 1.0 / 24.0;
    let build = || {
        let mut s = simulator(
            &topo,
            &rest,
            &at(0.0),
            Conductivity::Isotropic(2e-3),
            full_params(false, 2),
        );
        s.add_liquid(&gaussian(&rest, DVec2::ZERO, 0.3 * 0.3, 0.3), 0.02, None)
            .unwrap();
        s
    };
    let (mut sim, mut twin) = (build(), build());
    for k in 1..=5 {
        let t = k as f64 * dt;
        sim.step(&at(t), dt, Some(&at(t + dt))).unwrap();
        twin.step(&at(t), dt, Some(&at(t + dt))).unwrap();
    }
    let (fields, totals, time, velocity) = (
        sim.fields().clone(),
        sim.totals(),
        sim.time(),
        sim.velocity().to_vec(),
    );
    let t = 6.0 * dt;
    let mut bad = at(t);
    bad[17].y = f64::NAN;
    match sim.step(&bad, dt, Some(&at(t + dt))) {
        Err(e @ Error::Mesh(MeshError::NonFinitePosition { vertex: 17 })) => {
            assert!(e.to_string().contains("17"), "{e}");
        }
        other => panic!("NaN position: {other:?}"),
    }
    let mut bad_after = at(t + dt);
    bad_after[23].z = f64::INFINITY;
    match sim.step(&at(t), dt, Some(&bad_after)) {
        Err(e @ Error::Mesh(MeshError::NonFinitePosition { vertex: 23 })) => {
            assert!(e.to_string().contains("23"), "{e}");
        }
        other => panic!("infinite 'after' position: {other:?}"),
    }
    assert_eq!(sim.fields(), &fields);
    assert_eq!(sim.totals(), totals);
    assert_eq!(sim.time(), time);
    assert_eq!(sim.velocity(), &velocity[..]);
    // the next good step works, as if the bad ones never happened
    sim.step(&at(t), dt, Some(&at(t + dt))).unwrap();
    twin.step(&at(t), dt, Some(&at(t + dt))).unwrap();
    assert_sane(&sim, "after the error");
    assert_eq!(sim.fields(), twin.fields());
    assert_eq!(sim.velocity(), twin.velocity());
    assert_eq!(sim.totals(), twin.totals());
}

// ---------------------------------------------------------------------------------------
// 7. determinism

fn bits(sim: &Simulator) -> Vec<u64> {
    let f = sim.fields();
    let mut out: Vec<u64> = all_fields(f)
        .iter()
        .flat_map(|(_, v)| v.iter().map(|x| x.to_bits()))
        .collect();
    for c in [&f.color_free, &f.color_held].into_iter().flatten() {
        out.extend(c.iter().flatten().map(|x| x.to_bits()));
    }
    out.extend(
        sim.velocity()
            .iter()
            .flat_map(|u| [u.x.to_bits(), u.y.to_bits()]),
    );
    let t = sim.totals();
    out.extend([
        t.solvent.to_bits(),
        t.solute.to_bits(),
        t.evaporated.to_bits(),
    ]);
    out
}

#[test]
fn one_and_two_threads_give_bit_identical_fields() {
    let run = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| bits(&waving_run(60, false).0))
    };
    let run_m = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| bits(&waving_run(30, true).0))
    };
    let (a, b) = (run(1), run(2));
    assert_eq!(a.len(), b.len());
    let differ = a.iter().zip(&b).filter(|(x, y)| x != y).count();
    assert_eq!(differ, 0, "{differ} values differ between 1 and 2 threads");
    assert!(
        run_m(1) == run_m(2),
        "momentum advection differs between 1 and 2 threads"
    );
}

// ---------------------------------------------------------------------------------------
// 7b. active region

/// A blob (0.4 kg/m² peak, 3 % solute, gaussian of width `blob.1` at `blob.0`) spreading
/// on the cloth `topo` moving as `at`, `steps` steps of 1/30 s, with isotropic diffusion
/// 5e-4 m²/s and `params`. Checks the state is sane and calls `check(sim, before)` after
/// every step, with the fields before it.
fn blob_run(
    (topo, rest): (&Topology, &[DVec3]),
    at: &impl Fn(f64) -> Vec<DVec3>,
    params: StainParams,
    blob: (DVec2, f64),
    steps: usize,
    mut check: impl FnMut(&Simulator, &Fields),
) -> Simulator {
    let dt = 1.0 / 30.0;
    let mut sim = simulator(topo, rest, &at(0.0), Conductivity::Isotropic(5e-4), params);
    sim.add_liquid(&gaussian(rest, blob.0, blob.1 * blob.1, 0.4), 0.03, None)
        .unwrap();
    for k in 1..=steps {
        let before = sim.fields().clone();
        let t = k as f64 * dt;
        sim.step(&at(t), dt, Some(&at(t + dt))).unwrap();
        assert_sane(&sim, &format!("step {k}"));
        check(&sim, &before);
    }
    sim
}

/// [`blob_run`] on the 40×40 waving cloth, with or without the active region, with
/// `forces` and `interaction` (and the default viscosity and friction).
fn region_run(
    active_region: bool,
    forces: Forces,
    interaction: &InteractionRates,
    steps: usize,
    check: impl FnMut(&Simulator, &Fields),
) -> Simulator {
    let (topo, rest, at) = waving(40);
    let params = StainParams {
        forces,
        active_region,
        interaction: *interaction,
        ..Default::default()
    };
    blob_run(
        (&topo, &rest),
        &at,
        params,
        (DVec2::new(-0.2, 0.3), 0.08),
        steps,
        check,
    )
}

/// `(max |x − y|, max y)`: how far two density fields are apart, and the reference peak.
fn max_difference(x: &[f64], y: &[f64]) -> (f64, f64) {
    let diff = x
        .iter()
        .zip(y)
        .map(|(p, q)| (p - q).abs())
        .fold(0.0, f64::max);
    (diff, y.iter().copied().fold(0.0, f64::max))
}

#[test]
fn the_active_region_matches_the_whole_mesh_and_never_misses_liquid() {
    let whole = region_run(false, NO_FORCES, &no_interaction(), 200, |sim, _| {
        assert!(sim.active_region().is_none());
    });
    let mut smallest = usize::MAX;
    let mut largest = 0;
    let active = region_run(true, NO_FORCES, &no_interaction(), 200, |sim, before| {
        let mask = sim.active_region().expect("active region on");
        let count = mask.iter().filter(|a| **a).count();
        smallest = smallest.min(count);
        largest = largest.max(count);
        let f = sim.fields();
        for (name, now, was) in [
            ("free solvent", &f.free_solvent, &before.free_solvent),
            ("solute", &f.solute, &before.solute),
        ] {
            for i in (0..mask.len()).filter(|&i| !mask[i]) {
                assert!(
                    now[i] <= was[i],
                    "{name} grew outside the region at vertex {i}: {} -> {}",
                    was[i],
                    now[i]
                );
            }
        }
    });
    let n = whole.topology().n_vertices();
    assert!(
        0 < smallest && largest < n,
        "the region is neither empty nor the whole mesh ({smallest}..{largest} of {n})"
    );
    let (a, b) = (active.totals(), whole.totals());
    assert!(
        rel(a.solute, b.solute) <= 1e-12,
        "solute {} vs {}",
        a.solute,
        b.solute
    );
    assert!(
        rel(a.solvent, b.solvent) <= 1e-12,
        "solvent {} vs {}",
        a.solvent,
        b.solvent
    );
    for (name, x, y) in [
        ("solute", active.solute_density(), whole.solute_density()),
        ("wetness", active.wetness(), whole.wetness()),
    ] {
        let (diff, peak) = max_difference(&x, &y);
        assert!(
            diff <= 1e-9 * peak,
            "{name}: max difference {diff:e} of peak {peak:e}"
        );
        eprintln!(
            "{name}: max difference {:.1e} of the peak; region {smallest}..{largest} of {n} vertices",
            diff / peak
        );
    }
}

#[test]
fn the_active_region_with_forces_conserves_and_never_misses_liquid() {
    let mut largest = 0;
    let active = region_run(
        true,
        ALL_FORCES,
        &InteractionRates::default(),
        200,
        |sim, before| {
            let mask = sim.active_region().expect("active region on");
            largest = largest.max(mask.iter().filter(|a| **a).count());
            let f = sim.fields();
            for i in (0..mask.len()).filter(|&i| !mask[i]) {
                assert!(f.free_solvent[i] <= before.free_solvent[i], "vertex {i}");
                assert!(f.solute[i] <= before.solute[i], "vertex {i}");
            }
        },
    );
    let whole = region_run(
        false,
        ALL_FORCES,
        &InteractionRates::default(),
        200,
        |_, _| {},
    );
    let (a, b) = (active.totals(), whole.totals());
    assert!(
        rel(a.solute, b.solute) <= 1e-12,
        "solute {} vs {}",
        a.solute,
        b.solute
    );
    // with evaporation the wet edge is sharp (a vertex holding less than a step's
    // evaporation is drained to zero), and the whole-mesh step leaks ~1e-10 of the peak per
    // step past the region into the dry cloth, where it evaporates; the region keeps it
    // (module doc). Measured 1.4e-5 of the peak after 200 steps here.
    let (x, y) = (active.solute_density(), whole.solute_density());
    let (diff, peak) = max_difference(&x, &y);
    assert!(
        diff <= 1e-4 * peak,
        "max solute density difference {diff:e} of peak {peak:e}"
    );
    eprintln!(
        "with forces: max solute density difference {:.1e} of the peak; region up to {largest} of {} vertices",
        diff / peak,
        x.len()
    );
}

/// Faces listed against the majority's orientation where a window lies: the window walks
/// its fans in the cloth's (majority) orientation, not its own local majority, so the
/// stain on the waving cloth is the same with and without a window, and the same as on
/// the consistently listed mesh.
#[test]
fn a_window_over_flipped_faces_follows_the_cloth_orientation() {
    let grid = Grid::new(60, 1.0);
    let (faces, rest) = grid.arrays();
    let at = waving(60).2;
    // the left 35 % of the faces listed clockwise: a minority of the cloth, the majority
    // of the window around a blob at x = -0.75
    let flipped: Vec<[u32; 3]> = faces
        .iter()
        .map(|&[a, b, c]| {
            let x = (rest[a as usize].x + rest[b as usize].x + rest[c as usize].x) / 3.0;
            if x < -0.3 { [a, c, b] } else { [a, b, c] }
        })
        .collect();
    let original: std::collections::HashSet<[u32; 3]> = faces.iter().copied().collect();
    let run = |faces: &[[u32; 3]], active_region: bool| {
        let topo = Topology::from_triangles(rest.len(), faces.to_vec()).unwrap();
        let params = StainParams {
            forces: ALL_FORCES,
            active_region,
            interaction: no_interaction(),
            ..Default::default()
        };
        let blob = (DVec2::new(-0.75, 0.0), 0.05);
        let sim = blob_run((&topo, &rest), &at, params, blob, 60, |_, _| {});
        if active_region {
            // the premise: within the window, most faces are listed clockwise
            let m = sim.active_region().expect("liquid is flowing");
            let inside: Vec<&[u32; 3]> = faces
                .iter()
                .filter(|f| f.iter().all(|&v| m[v as usize]))
                .collect();
            let clockwise = inside.iter().filter(|f| !original.contains(**f)).count();
            assert!(
                2 * clockwise > inside.len() && inside.len() < faces.len() * 3 / 4,
                "{clockwise} of {} window faces flipped, of {}",
                inside.len(),
                faces.len()
            );
        }
        sim.solute_density()
    };
    let reference = run(&faces, false);
    for (what, got) in [
        ("window", run(&flipped, true)),
        ("whole mesh", run(&flipped, false)),
    ] {
        let (diff, peak) = max_difference(&got, &reference);
        eprintln!(
            "flipped faces, {what}: max solute density difference {:.1e} of the peak",
            diff / peak
        );
        assert!(diff <= 1e-9 * peak, "{what}: {diff:e} of peak {peak:e}");
    }
}

/// A blob that dries into a stain within a few frames, then the cloth stretches to twice
/// its width: the stain's solute density halves wherever it is above the dust level
/// (nothing flows, so every vertex keeps its solute), window or not.
#[test]
fn a_dry_stain_outside_the_window_follows_the_stretching_cloth() {
    let (topo, rest) = Grid::new(30, 0.5).build();
    let run = |active_region: bool| {
        let mut params = ideal(NO_FORCES);
        params.active_region = active_region;
        params.interaction = InteractionRates {
            evaporation: 5.0, // kg/m²/s: the blob dries within a frame or two
            ..InteractionRates::default()
        };
        let mut sim = simulator(&topo, &rest, &rest, Conductivity::Isotropic(1e-4), params);
        sim.add_liquid(
            &gaussian(&rest, DVec2::new(0.1, 0.0), 0.08 * 0.08, 0.5),
            0.05,
            None,
        )
        .unwrap();
        let dt = 1.0 / 24.0;
        for _ in 0..6 {
            sim.step(&rest, dt, None).unwrap();
        }
        let f = sim.fields();
        assert!(
            (0..rest.len()).all(|i| f.free_solvent[i] == 0.0 && f.absorbed_solvent[i] == 0.0),
            "the blob has dried"
        );
        let before = sim.solute_density();
        let stretched: Vec<DVec3> = rest
            .iter()
            .map(|p| DVec3::new(2.0 * p.x, p.y, p.z))
            .collect();
        sim.step(&stretched, dt, None).unwrap();
        if active_region {
            assert!(
                sim.active_region().is_none_or(|m| !m.iter().any(|a| *a)),
                "nothing flows, so nothing is active"
            );
        }
        (before, sim.solute_density(), sim.totals().solute)
    };
    let (before, after, solute) = run(true);
    let (_, whole, whole_solute) = run(false);
    let marked = before.iter().filter(|d| **d > 0.0).count();
    assert!(marked > 50, "a stain formed ({marked} vertices)");
    // dust (below 1e-12 of the largest density the stain had, the wet blob's) keeps its
    // last area (module doc): compare the vertices well above that
    let peak = before.iter().copied().fold(0.0, f64::max);
    let floor = 1e-9 * peak;
    for i in (0..before.len()).filter(|&i| before[i] > floor) {
        let expected = 0.5 * before[i];
        assert!(
            (after[i] - expected).abs() <= 1e-12 * expected.abs().max(1e-300),
            "vertex {i}: {} vs {expected}",
            after[i]
        );
        assert!(
            (after[i] - whole[i]).abs() <= 1e-9 * before[i],
            "vertex {i}: {} vs whole mesh {}",
            after[i],
            whole[i]
        );
    }
    assert!(rel(solute, whole_solute) <= 1e-12);
}

// ---------------------------------------------------------------------------------------
// 8. splash

#[test]
fn splash_is_outgoing_and_reproducible_from_its_seed() {
    let (topo, rest) = Grid::new(40, 1.0).build();
    let center = DVec3::new(0.1, -0.05, 0.0);
    let weights: Vec<f64> = rest
        .iter()
        .map(|p| {
            let r = (*p - center).length();
            if r < 0.4 { 1.0 - r / 0.4 } else { 0.0 }
        })
        .collect();
    let speed = 2.0;
    let splash = |seed: u64| {
        let mut sim = simulator(
            &topo,
            &rest,
            &rest,
            Conductivity::Isotropic(1e-4),
            ideal(NO_FORCES),
        );
        sim.add_liquid(&weights, 0.0, None).unwrap();
        sim.splash(center, speed, seed, &weights).unwrap();
        sim
    };
    let a = splash(42);
    let u = a.velocity_world();
    let (mut checked, mut min_turn, mut max_turn) = (0, f64::MAX, f64::MIN);
    let (mut min_factor, mut max_factor) = (f64::MAX, f64::MIN);
    for i in 0..rest.len() {
        if weights[i] <= 0.0 {
            assert_eq!(u[i], DVec3::ZERO, "vertex {i} has no weight but moves");
            continue;
        }
        let out = rest[i] - center;
        if out.length() < 1e-12 {
            continue;
        }
        assert!(
            u[i].z.abs() <= 1e-12 * u[i].length(),
            "splash velocity leaves the plane"
        );
        // the turn from the outward direction, and the speed factor
        let turn = out.truncate().angle_to(u[i].truncate());
        let factor = u[i].length() / (speed * weights[i]);
        assert!(
            u[i].dot(out) >= (0.5f64).cos() * u[i].length() * out.length() * (1.0 - 1e-12),
            "vertex {i}: velocity {} turned by {turn} rad from the outward {out}",
            u[i]
        );
        assert!(
            (0.5 - 1e-12..1.5).contains(&factor),
            "vertex {i}: speed factor {factor}"
        );
        min_turn = min_turn.min(turn);
        max_turn = max_turn.max(turn);
        min_factor = min_factor.min(factor);
        max_factor = max_factor.max(factor);
        checked += 1;
    }
    println!(
        "splash: {checked} vertices, turns {min_turn:.3}..{max_turn:.3} rad, speed factors {min_factor:.3}..{max_factor:.3}"
    );
    assert!(checked > 100);
    // the random turns and speeds do fill their ranges
    assert!(min_turn < -0.4 && max_turn > 0.4);
    assert!(min_factor < 0.6 && max_factor > 1.4);
    // reproducible from the seed, different for another
    assert_eq!(bits(&a), bits(&splash(42)));
    let other = splash(43).velocity_world();
    let moved = (0..rest.len()).filter(|&i| weights[i] > 0.0).count();
    let differ = (0..rest.len())
        .filter(|&i| weights[i] > 0.0 && other[i] != u[i])
        .count();
    assert!(
        differ == moved,
        "seed 43 gives the same velocity at {} vertices",
        moved - differ
    );

    // and the liquid does fly outward: its spread grows faster than without the splash
    let spread = |mut sim: Simulator| {
        for _ in 0..6 {
            sim.step(&rest, 1.0 / 24.0, None).unwrap();
        }
        let c = covariance(&sim.fields().free_solvent, &rest);
        c[0] + c[2]
    };
    let still = {
        let mut sim = simulator(
            &topo,
            &rest,
            &rest,
            Conductivity::Isotropic(1e-4),
            ideal(NO_FORCES),
        );
        sim.add_liquid(&weights, 0.0, None).unwrap();
        sim
    };
    let (r_splash, r_still) = (spread(a), spread(still));
    println!("splash: second moment {r_splash:.4} m² vs {r_still:.4} m² without");
    assert!(r_splash > 1.5 * r_still);
}

/// A cloth at rest that is jerked sideways: the liquid, still for two frames, crosses
/// more rings in the jerk's frame than the window planned from the still frame before
/// (one transport sub-cycle) reaches. The frame is tried again on a window that counts
/// its own sub-cycles, so the stain is the whole mesh's; without the retry the liquid
/// would pile up along the window's edge, a straight line of the grid.
#[test]
fn liquid_kicked_farther_than_the_window_reaches_is_the_whole_meshs() {
    let (topo, rest) = Grid::new(60, 1.0).build();
    let dt = 0.04;
    // still for 2 frames, then jerked along −x by 1.2 m in the third (the liquid slides
    // along +x)
    let at = |k: usize| -> Vec<DVec3> {
        let shift = DVec3::new(if k >= 3 { -1.2 } else { 0.0 }, 0.0, 0.0);
        rest.iter().map(|&p| p + shift).collect()
    };
    let run = |active_region: bool| {
        let params = StainParams {
            active_region,
            interaction: no_interaction(),
            ..ideal(ALL_FORCES)
        };
        let mut sim = simulator(&topo, &rest, &rest, Conductivity::Isotropic(1e-4), params);
        let blob = gaussian(&rest, DVec2::new(-0.6, 0.0), 0.003, 1.0);
        sim.add_liquid(&blob, 0.05, None).unwrap();
        for k in 1..=3 {
            sim.step(&at(k), dt, None).unwrap();
        }
        sim
    };
    let (whole, active) = (run(false), run(true));
    let moved = centroid(&active.wetness(), &rest).x + 0.6;
    let (diff, peak) = max_difference(&active.wetness(), &whole.wetness());
    let retries = active.profile().window_retries;
    eprintln!(
        "kicked liquid: moved {moved:.3} m (grid spacing {:.3} m), window vs whole mesh {:.1e} \
         of the peak, {retries} retries",
        2.0 / 60.0,
        diff / peak
    );
    assert!(
        moved > 12.0 * 2.0 / 60.0,
        "the kick moved the liquid {moved} m only"
    );
    assert!(retries >= 1, "no frame was tried again");
    assert!(
        diff <= 1e-9 * peak,
        "max difference {diff:e} of peak {peak:e}"
    );
}
