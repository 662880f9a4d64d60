//! The tracked reconstruction (`AngleMesh::reconstruct_tracked`, issue 15's fast warm
//! decode): from exact angles and the previous frame's positions it gives the exact shape,
//! on open and closed meshes, whatever the previous frame's placement; on noisy angles it
//! is a least-squares fit as close to the truth as the spectral method's; a start it cannot
//! follow is refused (`None`), never turned into a wrong shape; the bits do not depend on
//! the thread count.

mod angles_common;

use angles_common::*;
use glam::{DMat3, DVec3};
use madder::MeshError;
use madder::angles::{AngleMesh, Placement, ReconstructOptions};
use madder::{AngleError, rng::SplitMix64};

const DT: f64 = 1.0 / 25.0;

fn placed(f: &[[u32; 3]], x: &[DVec3]) -> ReconstructOptions {
    ReconstructOptions {
        placement: Some(Placement::of_face(f, x, f.len() / 2).unwrap()),
        ..Default::default()
    }
}

#[test]
fn exact_angles_follow_a_deforming_cloth() {
    let n = 24;
    let (f, x0) = cloth(n, 0.0);
    let mesh = AngleMesh::new(x0.len(), f.clone()).unwrap();
    let mut previous = x0.clone();
    for k in 1..13 {
        let (_, x) = cloth(n, k as f64 * DT);
        let a = mesh.encode(&x).unwrap();
        let r = mesh
            .reconstruct_tracked(&a, &previous, &placed(&f, &x))
            .unwrap()
            .expect("settles");
        let err = procrustes_rms(&r.positions, &x);
        let placed_err = max_rel(&r.positions, &x);
        println!(
            "frame {k}: rounds {}, RMS {err:.1e}, placed max {placed_err:.1e}",
            r.rounds
        );
        assert!(err <= 1e-10, "frame {k}: relative RMS error {err:e}");
        assert!(placed_err <= 1e-8, "frame {k}: placed error {placed_err:e}");
        assert!(r.rounds <= 5, "frame {k}: {} rounds", r.rounds);
        previous = r.positions;
    }
}

#[test]
fn exact_angles_on_closed_meshes_from_a_bent_start() {
    // the start is the mesh itself turned about an axis by an angle that grows along it (a
    // smooth, non-rigid change of every face's rotation, up to 0.3 rad)
    for (name, (f, x)) in [
        ("blob", blob(3)),
        ("torus", torus(24, 16)),
        ("genus 2", genus2(6)),
    ] {
        let mesh = AngleMesh::new(x.len(), f.clone()).unwrap();
        let start: Vec<DVec3> = x
            .iter()
            .map(|p| DMat3::from_axis_angle(DVec3::new(0.3, 1.0, 0.2).normalize(), 0.3 * p.x) * *p)
            .collect();
        let r = mesh
            .reconstruct_tracked(
                &mesh.encode(&x).unwrap(),
                &start,
                &ReconstructOptions::default(),
            )
            .unwrap()
            .expect("settles");
        let err = procrustes_rms(&r.positions, &x);
        println!("{name}: rounds {}, RMS {err:.1e}", r.rounds);
        assert!(err <= 1e-10, "{name}: relative RMS error {err:e}");
    }
}

#[test]
fn the_previous_frames_placement_does_not_matter() {
    let (f, x0) = cloth(16, 0.2);
    let (_, x) = cloth(16, 0.2 + DT);
    let mesh = AngleMesh::new(x.len(), f.clone()).unwrap();
    let a = noisy(&mesh.encode(&x).unwrap(), 0.5, 0.5, 3);
    let opts = placed(&f, &x);
    let one = mesh.reconstruct_tracked(&a, &x0, &opts).unwrap().unwrap();
    let r = DMat3::from_axis_angle(DVec3::new(1.0, -2.0, 0.5).normalize(), 2.0);
    let moved: Vec<DVec3> = x0
        .iter()
        .map(|p| 3.0 * (r * *p) + DVec3::new(5.0, -1.0, 2.0))
        .collect();
    let two = mesh
        .reconstruct_tracked(&a, &moved, &opts)
        .unwrap()
        .unwrap();
    let gap = max_rel(&one.positions, &two.positions);
    assert!(
        gap <= 1e-9,
        "placement of the start moved the result by {gap:e}"
    );
}

#[test]
fn noisy_angles_are_fitted_as_closely_as_by_the_spectral_method() {
    // quantization-like noise, uniform ±n % of each angle
    for (name, (f, x), (corner, dihedral)) in [
        ("flag", flag(0.4), (0.5, 0.5)),
        ("flag", flag(0.4), (1.0, 1.0)),
        ("blob", blob(3), (0.0, 10.0)),
        ("torus", torus(24, 16), (0.0, 10.0)),
    ] {
        let mesh = AngleMesh::new(x.len(), f.clone()).unwrap();
        let a = noisy(&mesh.encode(&x).unwrap(), corner, dihedral, 7);
        let spectral = mesh
            .reconstruct(&a, &ReconstructOptions::default())
            .unwrap();
        let tracked = mesh
            .reconstruct_tracked(&a, &spectral.positions, &ReconstructOptions::default())
            .unwrap()
            .expect("settles");
        let (es, et) = (
            procrustes_rms(&spectral.positions, &x),
            procrustes_rms(&tracked.positions, &x),
        );
        println!("{name} {corner}/{dihedral} %: spectral {es:.2e}, tracked {et:.2e}");
        assert!(
            et <= 1.5 * es,
            "{name}: tracked {et:e} against spectral {es:e}"
        );
    }
}

#[test]
fn the_cold_start_composes_exact_rotations_along_a_tree() {
    // without a previous frame the rotations start composed along a spanning tree of the
    // faces: exact angles make that start exact, so one round settles on the exact shape
    for (name, (f, x)) in [
        ("cloth", cloth(24, 0.4)),
        ("flag", flag(0.4)),
        ("blob", blob(3)),
        ("torus", torus(24, 16)),
        ("genus 2", genus2(6)),
    ] {
        let mesh = AngleMesh::new(x.len(), f.clone()).unwrap();
        let r = mesh
            .reconstruct_tracked_cold(&mesh.encode(&x).unwrap(), &ReconstructOptions::default())
            .unwrap()
            .expect("settles");
        let err = procrustes_rms(&r.positions, &x);
        println!("{name}: rounds {}, RMS {err:.1e}", r.rounds);
        assert!(err <= 1e-10, "{name}: relative RMS error {err:e}");
        assert_eq!(r.rounds, 1, "{name}: an exact start moves nothing");
    }
}

#[test]
fn the_cold_start_on_noisy_angles_reaches_the_fit_from_the_spectral_start() {
    // quantization-like noise: the rotations composed along the tree drift from the fit,
    // but the rounds bring them to the same least-squares fit the spectral start reaches
    for (name, (f, x), (corner, dihedral)) in [
        ("flag", flag(0.4), (0.5, 0.5)),
        ("cloth", cloth(40, 0.4), (1.0, 2.0)),
        ("torus", torus(24, 16), (0.0, 10.0)),
    ] {
        let mesh = AngleMesh::new(x.len(), f.clone()).unwrap();
        let a = noisy(&mesh.encode(&x).unwrap(), corner, dihedral, 11);
        let o = ReconstructOptions::default();
        let spectral = mesh.reconstruct(&a, &o).unwrap();
        let from_spectral = mesh
            .reconstruct_tracked(&a, &spectral.positions, &o)
            .unwrap()
            .expect("settles");
        let cold = mesh
            .reconstruct_tracked_cold(&a, &o)
            .unwrap()
            .expect("settles");
        let gap = procrustes_rms(&cold.positions, &from_spectral.positions);
        let err = procrustes_rms(&cold.positions, &x);
        println!(
            "{name} {corner}/{dihedral} %: rounds {}, gap to the spectral start's fit {gap:.1e}, \
             error {err:.1e}",
            cold.rounds
        );
        assert!(
            gap <= 1e-3 * err,
            "{name}: gap {gap:e} against error {err:e}"
        );
    }
}

#[test]
fn a_tolerance_saves_rounds_and_costs_a_fraction_of_the_angles_error() {
    // 12-bit-like rounding on every angle of a moving cloth, tracked from the previous
    // frame: a tolerance of a twentieth of the step (the codec's) stops the rounds once
    // the next one would move less than that, and moves the fit by little against its error
    let (f, x0) = cloth(40, 0.0);
    let (_, x) = cloth(40, DT);
    let mesh = AngleMesh::new(x.len(), f.clone()).unwrap();
    let step = std::f64::consts::TAU / 4096.0;
    let round = |a: f64| (a / step).round() * step;
    let exact = mesh.encode(&x).unwrap();
    let a = madder::angles::Angles {
        corners: exact.corners.iter().map(|c| c.map(round)).collect(),
        dihedrals: exact.dihedrals.iter().map(|&d| round(d)).collect(),
    };
    let full = mesh
        .reconstruct_tracked(&a, &x0, &ReconstructOptions::default())
        .unwrap()
        .expect("settles");
    let o = ReconstructOptions {
        tolerance: step / 20.0,
        ..Default::default()
    };
    let early = mesh
        .reconstruct_tracked(&a, &x0, &o)
        .unwrap()
        .expect("settles");
    let err = procrustes_rms(&full.positions, &x);
    let gap = procrustes_rms(&early.positions, &full.positions);
    println!(
        "rounds {} → {}, error {err:.1e}, gap {gap:.1e}",
        full.rounds, early.rounds
    );
    assert!(early.rounds < full.rounds);
    assert!(gap <= 0.05 * err, "gap {gap:e} against error {err:e}");
}

#[test]
fn a_start_it_cannot_follow_is_refused_not_misfitted() {
    // starts far from the shape: random positions, the shape mirrored, everything on a
    // line (degenerate faces); each result is either refused or the exact shape
    let (f, x) = cloth(12, 0.3);
    let mesh = AngleMesh::new(x.len(), f.clone()).unwrap();
    let a = mesh.encode(&x).unwrap();
    let mut rng = SplitMix64::new(5);
    let random: Vec<DVec3> = x
        .iter()
        .map(|_| DVec3::new(rng.unit(), rng.unit(), rng.unit()))
        .collect();
    let mirrored: Vec<DVec3> = x.iter().map(|p| DVec3::new(-p.x, p.y, p.z)).collect();
    let line: Vec<DVec3> = (0..x.len()).map(|i| DVec3::X * i as f64).collect();
    for (name, start) in [("random", random), ("mirrored", mirrored), ("line", line)] {
        match mesh
            .reconstruct_tracked(&a, &start, &ReconstructOptions::default())
            .unwrap()
        {
            None => println!("{name}: refused"),
            Some(r) => {
                let err = procrustes_rms(&r.positions, &x);
                println!("{name}: rounds {}, RMS {err:.1e}", r.rounds);
                assert!(
                    err <= 1e-8,
                    "{name}: a wrong shape ({err:e}) was not refused"
                );
            }
        }
    }
}

#[test]
fn same_bits_whatever_the_thread_count() {
    let (f, x0) = cloth(20, 0.1);
    let (_, x) = cloth(20, 0.1 + DT);
    let mesh = AngleMesh::new(x.len(), f).unwrap();
    let a = noisy(&mesh.encode(&x).unwrap(), 1.0, 1.0, 11);
    let run = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| {
                mesh.clone()
                    .reconstruct_tracked(&a, &x0, &ReconstructOptions::default())
                    .unwrap()
                    .unwrap()
                    .positions
            })
    };
    let one = run(1);
    for t in [2, 3, 4] {
        assert_eq!(run(t), one, "{t} threads");
    }
}

#[test]
fn bad_previous_positions_are_named() {
    let (f, x) = cloth(8, 0.0);
    let mesh = AngleMesh::new(x.len(), f).unwrap();
    let a = mesh.encode(&x).unwrap();
    let mut nan = x.clone();
    nan[17].y = f64::NAN;
    let e = mesh
        .reconstruct_tracked(&a, &nan, &ReconstructOptions::default())
        .unwrap_err();
    assert!(
        matches!(
            e,
            AngleError::Mesh(MeshError::NonFinitePosition { vertex: 17 })
        ),
        "{e:?}"
    );
    let e = mesh
        .reconstruct_tracked(&a, &x[1..], &ReconstructOptions::default())
        .unwrap_err();
    assert!(matches!(e, AngleError::Mesh(_)), "{e:?}");
    let mut short = a.clone();
    short.dihedrals.pop();
    let e = mesh
        .reconstruct_tracked(&short, &x, &ReconstructOptions::default())
        .unwrap_err();
    assert!(matches!(e, AngleError::DihedralCount { .. }), "{e:?}");
}

#[test]
fn the_descent_after_a_tracked_fit_never_raises_the_residual() {
    let (f, x) = flag(0.4);
    let mesh = AngleMesh::new(x.len(), f).unwrap();
    let a = noisy(&mesh.encode(&x).unwrap(), 1.0, 1.0, 5);
    let start = mesh
        .reconstruct(&a, &ReconstructOptions::default())
        .unwrap()
        .positions;
    let plain = mesh
        .reconstruct_tracked(&a, &start, &ReconstructOptions::default())
        .unwrap()
        .unwrap();
    assert!(plain.residual.is_empty());
    let opts = ReconstructOptions {
        refine_iterations: 10,
        ..Default::default()
    };
    let refined = mesh
        .reconstruct_tracked(&a, &start, &opts)
        .unwrap()
        .unwrap();
    let h = &refined.residual;
    assert!(h.len() >= 2, "no descent step taken: {h:?}");
    assert!(h.windows(2).all(|w| w[1] <= w[0]), "residual rose: {h:?}");
    assert!(h.last().unwrap() < &h[0], "{h:?}");
    // the residual before the descent is the tracked fit's own
    let own = mesh.angle_residual(&a, &plain.positions).unwrap();
    assert!((h[0] - own).abs() <= 1e-9 * own, "{} vs {own}", h[0]);
}
