//! The warm-started decoder of a sequence (`AngleMesh::reconstruct_warm`, issue 15
//! "Speed"): decoding frame `k` from the previous frame's reconstruction gives the cold
//! reconstruction of frame `k` (the same eigenproblem, solved to the same tolerance),
//! exactly on exact angles and to 1e-7 of the bounding box on noisy ones, with no more
//! subspace rounds; a poor start (the flat sheet) costs rounds, not accuracy; bad
//! previous positions are named; the result does not depend on the thread count.

mod angles_common;

use angles_common::*;
use glam::DVec3;
use madder::AngleError;
use madder::MeshError;
use madder::angles::{AngleMesh, Placement, ReconstructOptions};

const DT: f64 = 1.0 / 25.0;

#[test]
fn warm_matches_cold_along_a_sequence() {
    let n = 24;
    let (f, x0) = cloth(n, 0.0);
    let mesh = AngleMesh::new(x0.len(), f.clone()).unwrap();
    // the cold decodes on a clone (which starts with no cached solver), so that the warm
    // path sees only its own, older factorizations
    let other = mesh.clone();
    for (label, noise) in [("exact", 0.0), ("1 % noise", 1.0)] {
        let mut previous = mesh
            .reconstruct(&mesh.encode(&x0).unwrap(), &ReconstructOptions::default())
            .unwrap()
            .positions;
        for k in 1..9 {
            let (_, x) = cloth(n, k as f64 * DT);
            let a = noisy(&mesh.encode(&x).unwrap(), noise, noise, k);
            let opts = ReconstructOptions {
                placement: Some(Placement::of_face(&f, &x, f.len() / 2).unwrap()),
                ..Default::default()
            };
            let cold = other.reconstruct(&a, &opts).unwrap();
            let warm = mesh.reconstruct_warm(&a, &previous, &opts).unwrap();
            let gap = max_rel(&warm.positions, &cold.positions);
            let err = procrustes_rms(&warm.positions, &x);
            println!(
                "{label} frame {k}: warm − cold {gap:.1e}, warm rel. RMS {err:.1e}, rounds {} (cold {})",
                warm.rounds, cold.rounds
            );
            assert!(
                gap <= 1e-7,
                "{label} frame {k}: warm differs from cold by {gap:e}"
            );
            if noise == 0.0 {
                assert!(err <= 1e-8, "frame {k}: relative RMS error {err:e}");
            }
            previous = warm.positions;
        }
    }
}

#[test]
fn a_poor_start_costs_rounds_not_accuracy() {
    let (f, x) = cloth(16, 0.5);
    let mesh = AngleMesh::new(x.len(), f.clone()).unwrap();
    let a = mesh.encode(&x).unwrap();
    // the flat sheet, and the sheet squashed to a near-degenerate start
    let flat: Vec<DVec3> = cloth(16, 0.0)
        .1
        .iter()
        .map(|p| DVec3::new(p.x, p.y, 0.0))
        .collect();
    let r = mesh
        .reconstruct_warm(&a, &flat, &ReconstructOptions::default())
        .unwrap();
    let err = procrustes_rms(&r.positions, &x);
    assert!(err <= 1e-8, "relative RMS error {err:e} from a flat start");
}

#[test]
fn bad_previous_positions_are_named() {
    let (f, x) = cloth(6, 0.0);
    let mesh = AngleMesh::new(x.len(), f).unwrap();
    let a = mesh.encode(&x).unwrap();
    let opts = ReconstructOptions::default();
    let short = &x[..x.len() - 1];
    assert!(matches!(
        mesh.reconstruct_warm(&a, short, &opts).unwrap_err(),
        AngleError::Mesh(MeshError::VertexCountMismatch { .. })
    ));
    let mut nan = x.clone();
    nan[5].y = f64::NAN;
    assert_eq!(
        mesh.reconstruct_warm(&a, &nan, &opts).unwrap_err(),
        AngleError::Mesh(MeshError::NonFinitePosition { vertex: 5 })
    );
}

#[test]
fn warm_is_deterministic_across_thread_counts() {
    let (f, x) = cloth(12, 0.2);
    let mesh = AngleMesh::new(x.len(), f).unwrap();
    let a = noisy(&mesh.encode(&x).unwrap(), 1.0, 1.0, 3);
    let previous = cloth(12, 0.2 - DT).1;
    let run = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| {
                mesh.reconstruct_warm(&a, &previous, &ReconstructOptions::default())
                    .unwrap()
                    .positions
            })
    };
    let one = run(1);
    for t in [2, 4] {
        assert!(one == run(t), "{t} threads differ from 1");
    }
}
