//! Surfaces from angles (seed ch. 3): encoding against closed forms, exact reconstruction
//! up to a similarity (Procrustes computed here), placement, bad input, determinism.

mod angles_common;

use std::f64::consts::PI;

use angles_common::*;
use glam::DVec3;
use madder::AngleError;
use madder::angles::{AngleMesh, Angles, Placement, ReconstructOptions};

fn check_exact(name: &str, (f, x): Mesh) {
    let mesh = AngleMesh::new(x.len(), f.clone()).unwrap();
    let a = mesh.encode(&x).unwrap();
    let r = mesh
        .reconstruct(&a, &ReconstructOptions::default())
        .unwrap();
    let err = procrustes_rms(&r.positions, &x);
    println!(
        "{name}: {} vertices, rel. RMS {err:.2e}, rounds {}, eigenvalues {:?}",
        x.len(),
        r.rounds,
        r.eigenvalues
    );
    assert!(err <= 1e-8, "{name}: relative RMS error {err:e}");
    // the placement of one face puts the mesh back where it was, scale included
    let face = f.len() / 3;
    let placement = Placement::of_face(&f, &x, face).unwrap();
    let opts = ReconstructOptions {
        placement: Some(placement),
        ..Default::default()
    };
    let placed = mesh.reconstruct(&a, &opts).unwrap();
    let landed = max_rel(&placed.positions, &x);
    assert!(landed <= 1e-8, "{name}: placed max error {landed:e}");
    // the baseline is exact on exact angles too
    let seq = mesh.sequential(&a, Some(&placement)).unwrap();
    let s = max_rel(&seq, &x);
    assert!(s <= 1e-8, "{name}: sequential max error {s:e}");
}

#[test]
fn exact_angles_rebuild_an_ellipsoidal_sphere() {
    check_exact("blob", blob(3));
}

#[test]
fn exact_angles_rebuild_a_torus() {
    check_exact("torus", torus(40, 16));
}

#[test]
fn exact_angles_rebuild_a_genus_2_surface() {
    let (f, x) = genus2(3);
    assert_eq!(
        euler(&f, x.len()),
        -2,
        "the slab with two holes has genus 2"
    );
    check_exact("genus2", (f, x));
}

#[test]
fn exact_angles_rebuild_open_sheets() {
    check_exact("sheet", sheet(24));
    for t in [0.0, 0.4, 1.1] {
        check_exact("flag", flag(t));
    }
}

#[test]
fn encoding_matches_closed_forms() {
    // regular tetrahedron, outward: corners π/3, dihedral π − arccos(1/3) on every edge
    let x = vec![
        DVec3::new(1.0, 1.0, 1.0),
        DVec3::new(1.0, -1.0, -1.0),
        DVec3::new(-1.0, 1.0, -1.0),
        DVec3::new(-1.0, -1.0, 1.0),
    ];
    let f = vec![[0, 1, 2], [0, 3, 1], [0, 2, 3], [1, 3, 2]];
    let mesh = AngleMesh::new(4, f).unwrap();
    let a = mesh.encode(&x).unwrap();
    assert_eq!(mesh.n_interior(), 6);
    for c in a.corners.iter().flatten() {
        assert!((c - PI / 3.0).abs() < 1e-14);
    }
    let want = PI - (1.0f64 / 3.0).acos();
    for d in &a.dihedrals {
        assert!((d - want).abs() < 1e-14, "{d} vs {want}");
    }
    // the same tetrahedron turned inside out: dihedrals change sign
    let inv: Vec<[u32; 3]> = mesh.faces().iter().map(|t| [t[0], t[2], t[1]]).collect();
    let a2 = AngleMesh::new(4, inv).unwrap().encode(&x).unwrap();
    for d in &a2.dihedrals {
        assert!((d + want).abs() < 1e-14);
    }
    // a folded pair: θ = the turn between the normals, sign by convexity
    let fold = |h: f64| {
        let x = vec![
            DVec3::ZERO,
            DVec3::X,
            DVec3::new(0.5, 1.0, 0.0),
            DVec3::new(0.5, -1.0, h),
        ];
        let m = AngleMesh::new(4, vec![[0, 1, 2], [1, 0, 3]]).unwrap();
        m.encode(&x).unwrap().dihedrals[0]
    };
    assert!((fold(-1.0) - PI / 4.0).abs() < 1e-14, "{}", fold(-1.0));
    assert!((fold(1.0) + PI / 4.0).abs() < 1e-14);
    assert_eq!(fold(0.0), 0.0);
}

fn pair_mesh() -> (AngleMesh, Angles) {
    let (f, x) = sheet(4);
    let m = AngleMesh::new(x.len(), f).unwrap();
    let a = m.encode(&x).unwrap();
    (m, a)
}

#[test]
fn bad_angles_are_named() {
    let (m, a) = pair_mesh();
    let opts = ReconstructOptions::default();
    let mut bad = a.clone();
    bad.corners[5][2] = f64::NAN;
    assert_eq!(
        m.reconstruct(&bad, &opts).unwrap_err(),
        AngleError::NonFiniteCorner { face: 5, corner: 2 }
    );
    let mut bad = a.clone();
    bad.dihedrals[3] = f64::INFINITY;
    let [ea, eb] = m.interior_edges()[3];
    assert_eq!(
        m.reconstruct(&bad, &opts).unwrap_err(),
        AngleError::NonFiniteDihedral {
            edge: 3,
            a: ea,
            b: eb
        }
    );
    let msg = m.sequential(&bad, None).unwrap_err().to_string();
    assert!(msg.contains(&format!("({ea}, {eb})")), "{msg}");
    let mut bad = a.clone();
    bad.dihedrals.pop();
    assert_eq!(
        m.reconstruct(&bad, &opts).unwrap_err(),
        AngleError::DihedralCount {
            expected: m.n_interior(),
            got: m.n_interior() - 1
        }
    );
    let mut bad = a.clone();
    bad.corners.push([1.0; 3]);
    assert!(matches!(
        m.reconstruct(&bad, &opts).unwrap_err(),
        AngleError::CornerCount { .. }
    ));
    // positions of the wrong count, a non-finite position, a degenerate face
    assert!(matches!(
        m.encode(&[DVec3::ZERO; 3]).unwrap_err(),
        AngleError::Mesh(madder::MeshError::VertexCountMismatch { .. })
    ));
    let m2 = AngleMesh::new(3, vec![[0, 1, 2]]).unwrap();
    assert_eq!(
        m2.encode(&[DVec3::ZERO, DVec3::X, DVec3::X * 2.0])
            .unwrap_err(),
        AngleError::DegenerateFace { face: 0 }
    );
    // a placement face out of range
    let opts = ReconstructOptions {
        placement: Some(Placement {
            face: 10_000,
            positions: [DVec3::ZERO, DVec3::X, DVec3::Y],
        }),
        ..Default::default()
    };
    assert!(matches!(
        m.reconstruct(&a, &opts).unwrap_err(),
        AngleError::PlacementFace { face: 10_000, .. }
    ));
}

#[test]
fn bad_meshes_are_named() {
    // a fin: three faces on edge (0, 1)
    let e = AngleMesh::new(5, vec![[0, 1, 2], [1, 0, 3], [0, 1, 4]]).unwrap_err();
    assert_eq!(
        e,
        AngleError::NonManifoldEdge {
            a: 0,
            b: 1,
            faces: 3
        }
    );
    assert!(e.to_string().contains("edge (0, 1)"));
    // one face of a closed mesh flipped: its edges run the same way as the neighbours'
    let (mut f, x) = blob(1);
    f[7] = [f[7][0], f[7][2], f[7][1]];
    match AngleMesh::new(x.len(), f.clone()).unwrap_err() {
        AngleError::NotOrientable {
            a,
            b,
            face_a,
            face_b,
        } => {
            assert!(face_a == 7 || face_b == 7);
            assert!(f[7].contains(&a) && f[7].contains(&b));
        }
        other => panic!("{other}"),
    }
    // a Möbius strip is not orientable whatever the faces' order
    let n = 12u32;
    let mut mf = Vec::new();
    for i in 0..n {
        let (a, b) = (i, i + n);
        let (c, d) = if i + 1 == n {
            (n, 0)
        } else {
            (i + 1, i + 1 + n)
        };
        mf.push([a, b, d]);
        mf.push([a, d, c]);
    }
    assert!(matches!(
        AngleMesh::new(2 * n as usize, mf).unwrap_err(),
        AngleError::NotOrientable { .. }
    ));
    // a loose vertex, and two pieces not joined by an edge
    assert_eq!(
        AngleMesh::new(4, vec![[0, 1, 2]]).unwrap_err(),
        AngleError::LooseVertex { vertex: 3 }
    );
    let two = AngleMesh::new(6, vec![[0, 1, 2], [3, 4, 5]]).unwrap();
    let a = Angles {
        corners: vec![[PI / 3.0; 3]; 2],
        dihedrals: vec![],
    };
    assert_eq!(
        two.reconstruct(&a, &ReconstructOptions::default())
            .unwrap_err(),
        AngleError::Disconnected { face: 1 }
    );
}

#[test]
fn descent_never_raises_the_residual() {
    let (f, x) = blob(2);
    let m = AngleMesh::new(x.len(), f).unwrap();
    let a = noisy(&m.encode(&x).unwrap(), 0.0, 20.0, 3);
    let opts = ReconstructOptions {
        refine_iterations: 30,
        ..Default::default()
    };
    let r = m.reconstruct(&a, &opts).unwrap();
    assert!(r.residual.len() > 2, "the descent took steps");
    for w in r.residual.windows(2) {
        assert!(w[1] <= w[0], "{:?}", r.residual);
    }
    assert!(r.residual.last().unwrap() < &r.residual[0]);
    // the reported residual is the residual of the positions returned
    let e = m.angle_residual(&a, &r.positions).unwrap();
    assert!((e - r.residual.last().unwrap()).abs() <= 1e-9 * e);
}

#[test]
fn deterministic_across_thread_counts() {
    let (f, x) = torus(24, 10);
    let m = AngleMesh::new(x.len(), f).unwrap();
    let a = noisy(&m.encode(&x).unwrap(), 2.0, 10.0, 9);
    let opts = ReconstructOptions {
        refine_iterations: 5,
        ..Default::default()
    };
    let run = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| {
                let r = m.reconstruct(&a, &opts).unwrap();
                let s = m.sequential(&a, None).unwrap();
                (r.positions, r.residual, s)
            })
    };
    let one = run(1);
    for t in [2, 4] {
        let other = run(t);
        assert!(one == other, "{t} threads differ from 1");
    }
}
