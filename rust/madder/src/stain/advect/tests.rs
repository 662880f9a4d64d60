use glam::{DMat2, DVec2, DVec3};

use super::flux::face_fluxes;
use super::sector::{SECTOR_MARGIN, in_sector, rough_atan2};
use super::trace::unfolded_turn;
use super::*;
use crate::error::ParamError;
use crate::mesh::transport::wrap_angle;
use crate::mesh::{Geometry, OneRings, Topology, Transport, VertexFrames};

struct Mesh {
    t: Topology,
    p: Vec<DVec3>,
    rings: OneRings,
    geometry: Geometry,
    frames: VertexFrames,
    transport: Transport,
}

fn mesh(n: usize, faces: Vec<[u32; 3]>, p: Vec<DVec3>) -> Mesh {
    let t = Topology::from_triangles(n, faces).unwrap();
    let rings = OneRings::new(&t);
    let geometry = Geometry::new(&t, &p).unwrap();
    let frames = VertexFrames::new(&rings, &p).unwrap();
    let transport = Transport::new(&t, &rings, &geometry, &frames, &p);
    Mesh {
        t,
        p,
        rings,
        geometry,
        frames,
        transport,
    }
}

fn advect(m: &Mesh, u: &[DVec2], h: f64) -> Vec<DVec2> {
    advect_velocity(&m.t, &m.rings, &m.geometry, &m.transport, u, h)
}

#[test]
fn unfolded_turn_is_the_mean_angle() {
    use std::f64::consts::{PI, TAU};
    // against the angles themselves: a_m = arg(to_m) − polar_m, the mean on the
    // shorter arc, over random directions, lengths and polar angles, differences up
    // to nearly π (the fallback below BISECTOR_MIN included)
    let mut s = 0x2545_f491_4f6c_dd1d_u64;
    let mut next = || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 11) as f64 / (1u64 << 53) as f64
    };
    for case in 0..20_000 {
        let (a_r, len_r, len_l) = (TAU * next() - PI, 0.01 + next(), 0.01 + next());
        // the two angles' difference, up to ±(π − 1e-9)
        let gap = if case % 4 == 0 {
            (PI - 1e-9) * (2.0 * next() - 1.0)
        } else {
            0.3 * (2.0 * next() - 1.0)
        };
        let (polar_r, polar_l) = (4.0 * TAU * next() - 2.0 * TAU, TAU * next());
        let dir = |a: f64| DVec2::new(a.cos(), a.sin());
        let to_r = len_r * dir(a_r + polar_r);
        let to_l = len_l * dir(a_r + gap + polar_l);
        let want = DMat2::from_angle(a_r + 0.5 * gap);
        let got = unfolded_turn(to_r, to_l, polar_r, polar_l);
        let err = (got - want)
            .to_cols_array()
            .iter()
            .fold(0.0, |m: f64, x| m.max(x.abs()));
        assert!(err < 1e-12, "{case}: gap {gap}, off by {err:e}");
        assert!((got.determinant() - 1.0).abs() < 1e-14, "a rotation");
    }
}

#[test]
fn congruent_faces_share_their_area_vectors() {
    use crate::mesh::refine::{Partial, folded_grid, tip_shares};
    // folded: each coarse face moves by its own affine map, so its fine faces stay
    // congruent
    let (coarse, _, now) = folded_grid(4, 3);
    for level in 1..=3 {
        let mut part = Partial::new(&coarse, level).unwrap();
        part.build(&(0..coarse.n_faces() as u32).collect::<Vec<_>>());
        let t = part.topology().unwrap();
        let q = part.prolong(&now);
        let share = tip_shares(part.face_congruence().into_iter());
        let frames = VertexFrames::new(&OneRings::new(&t), &q).unwrap();
        let u: Vec<DVec2> = (0..t.n_vertices())
            .map(|v| DVec2::new((v as f64 * 0.7).sin(), (v as f64 * 1.3).cos()))
            .collect();
        // half the vertices active: faces with one active corner get no flux
        let active: Vec<bool> = (0..t.n_vertices()).map(|v| v % 7 != 3).collect();
        let fluxes = |share: Option<&[(u32, u8)]>| {
            let mut flux = Vec::new();
            dual_fluxes_in(&t, &q, &frames, &u, &active, share, &mut flux);
            flux
        };
        let own = fluxes(None);
        let shared = fluxes(Some(&share));
        let peak = own.iter().fold(0.0, |m: f64, x| m.max(x.abs()));
        let worst = own
            .iter()
            .zip(&shared)
            .fold(0.0, |m: f64, (a, b)| m.max((a - b).abs()));
        assert!(
            peak > 0.0 && worst < 1e-13 * peak,
            "level {level}: {worst:e} of {peak:e}"
        );
        for (a, b) in own.iter().zip(&shared) {
            assert_eq!(*a == 0.0, *b == 0.0, "the same edges carry a flux");
        }
        // the orientation matters: without the reflection's sign the fluxes are wrong
        let unsigned: Vec<(u32, u8)> = share.iter().map(|&(r, _)| (r, 0)).collect();
        let wrong = fluxes(Some(&unsigned));
        let off = own
            .iter()
            .zip(&wrong)
            .fold(0.0, |m: f64, (a, b)| m.max((a - b).abs()));
        assert!(
            off > 1e-2 * peak,
            "level {level}: the shift changed nothing"
        );
    }
}

#[test]
fn median_dual_area_vectors_have_two_thirds_of_the_area_along_their_edge() {
    let tri = [0usize, 1, 2];
    let pos = [
        DVec3::new(0.1, -0.2, 0.3),
        DVec3::new(1.3, 0.1, -0.2),
        DVec3::new(-0.4, 0.9, 0.5),
    ];
    let area = 0.5 * (pos[1] - pos[0]).cross(pos[2] - pos[0]).length();
    let centroid = (pos[0] + pos[1] + pos[2]) / 3.0;
    // S of each edge, read off with unit velocities along the axes
    let s: Vec<[f64; 3]> = [DVec3::X, DVec3::Y, DVec3::Z]
        .iter()
        .map(|&w| face_fluxes(tri, &pos, &[w; 3]))
        .collect();
    let [sx, sy, sz] = [&s[0], &s[1], &s[2]];
    for k in 0..3 {
        let sk = DVec3::new(sx[k], sy[k], sz[k]);
        let (a, b) = ((k + 1) % 3, (k + 2) % 3);
        let (a, b) = (a.min(b), a.max(b));
        let e = pos[b] - pos[a];
        let mid = 0.5 * (pos[a] + pos[b]);
        assert!((sk.dot(e) - 2.0 * area / 3.0).abs() < 1e-15, "edge {k}");
        assert!((sk.length() - (centroid - mid).length()).abs() < 1e-15);
        assert!(
            sk.dot(centroid - mid).abs() < 1e-15,
            "normal to the dual face"
        );
    }
    // a collapsed face carries no flux
    let flat = [DVec3::ZERO, DVec3::X, DVec3::new(0.5, 0.0, 0.0)];
    assert_eq!(face_fluxes(tri, &flat, &[DVec3::ONE; 3]), [0.0; 3]);
}

#[test]
fn zero_velocity_and_loose_vertices_keep_their_value() {
    // a fan of 6 around vertex 0, plus a loose vertex 7
    let mut p = vec![DVec3::ZERO];
    for k in 0..6 {
        let a = std::f64::consts::TAU * k as f64 / 6.0;
        p.push(DVec3::new(a.cos(), a.sin(), 0.0));
    }
    p.push(DVec3::new(5.0, 5.0, 0.0));
    let faces = (0..6).map(|k| [0, 1 + k, 1 + (k + 1) % 6]).collect();
    let m = mesh(8, faces, p);
    let mut u = vec![DVec2::new(0.3, -0.1); 8];
    u[0] = DVec2::ZERO;
    u[7] = DVec2::new(1.7, 2.5);
    let out = advect(&m, &u, 0.4);
    assert_eq!(out[0], DVec2::ZERO);
    assert_eq!(out[7], u[7]);
    assert!(out.iter().all(|v| v.is_finite()));
}

#[test]
fn irregular_and_degenerate_meshes_stay_finite() {
    // bow-tie at vertex 0, a fin of three faces on edge 5–6, a collapsed face 5–6–9
    let p = vec![
        DVec3::ZERO,
        DVec3::new(1.0, 0.2, 0.0),
        DVec3::new(0.8, 1.0, 0.0),
        DVec3::new(-1.0, -0.1, 0.0),
        DVec3::new(-0.7, -1.0, 0.0),
        DVec3::new(2.0, 0.0, 0.0),
        DVec3::new(3.0, 0.0, 0.0),
        DVec3::new(2.5, 1.0, 0.0),
        DVec3::new(2.5, -1.0, 0.3),
        DVec3::new(2.5, 0.0, 0.0),
        DVec3::new(2.5, 0.0, 1.0),
    ];
    let faces = vec![
        [0, 1, 2],
        [0, 3, 4],
        [1, 5, 2],
        [5, 6, 7],
        [6, 5, 8],
        [5, 6, 10],
        [5, 9, 7],
        [9, 6, 7],
        [5, 6, 9],
    ];
    let m = mesh(11, faces, p);
    assert_eq!(m.rings.kind(0), crate::mesh::FanKind::Irregular);
    assert_eq!(m.geometry.n_degenerate_faces, 1);
    for (k, h) in [0.1, 1.0, 30.0].into_iter().enumerate() {
        let u: Vec<DVec2> = (0..11)
            .map(|i| DVec2::new((i as f64 + k as f64).sin(), (2.0 * i as f64).cos()))
            .collect();
        let out = advect(&m, &u, h);
        assert!(out.iter().all(|v| v.is_finite()), "h = {h}: {out:?}");
        // interpolation never leaves the range of the (rotated) values
        let umax = u.iter().map(|v| v.length()).fold(0.0, f64::max);
        assert!(out.iter().all(|v| v.length() <= umax * (1.0 + 1e-12)));
        let flux = dual_fluxes(&m.t, &m.p, &m.frames, &u);
        assert!(flux.iter().all(|x| x.is_finite()));
        let plan = UpwindPlan::new(&m.t, &m.geometry.vertex_area, &flux, h).unwrap();
        let mut mass: Vec<f64> = (0..11).map(|i| 1.0 + i as f64).collect();
        let before = mass.clone();
        plan.transport(&m.t, &mut mass);
        assert!(mass.iter().all(|&x| x >= 0.0));
        let (s0, s1): (f64, f64) = (before.iter().sum(), mass.iter().sum());
        assert!((s1 - s0).abs() < 1e-14 * s0);
        let mom = plan.momentum_velocity(&m.t, &m.transport, &before, &u, &out);
        assert!(mom.iter().all(|v| v.is_finite()));
        // several fields at once: bit-identical to one by one
        let mut a: Vec<f64> = (0..11).map(|i| (i as f64 * 0.7).sin().abs()).collect();
        let mut b: Vec<f64> = (0..11).map(|i| 1e-9 * (i * i) as f64).collect();
        let (mut a1, mut b1) = (a.clone(), b.clone());
        plan.transport(&m.t, &mut a1);
        plan.transport(&m.t, &mut b1);
        plan.transport_all(&m.t, &mut [&mut a, &mut b]);
        assert_eq!(
            (a.clone(), b.clone()),
            (a1, b1),
            "h = {h}: transport_all differs from transport"
        );
        // the fields and the momentum in one pass: the same fields, the same velocities
        let mut solvent = before.clone();
        let mut c = b.clone();
        let fused =
            plan.transport_with_momentum(&m.t, &m.transport, &mut [&mut solvent, &mut c], &u, &out);
        let (mut s1, mut c1) = (before.clone(), b.clone());
        plan.transport_all(&m.t, &mut [&mut s1, &mut c1]);
        assert_eq!((solvent, c), (s1, c1), "h = {h}: fused fields");
        assert_eq!(fused, mom, "h = {h}: fused momentum");
    }
}

#[test]
fn bad_plan_parameters_are_named() {
    let t = Topology::from_triangles(3, vec![[0, 1, 2]]).unwrap();
    let area = [1.0; 3];
    let flux = [0.1, -0.2, 0.0];
    assert!(UpwindPlan::new(&t, &area, &flux, 0.1).is_ok());
    assert_eq!(
        UpwindPlan::new(&t, &area[..2], &flux, 0.1).unwrap_err(),
        ParamError::Length {
            name: "vertex_area",
            expected: 3,
            got: 2
        }
    );
    assert_eq!(
        UpwindPlan::new(&t, &area, &flux[..1], 0.1).unwrap_err(),
        ParamError::Length {
            name: "flux",
            expected: 3,
            got: 1
        }
    );
    assert!(matches!(
        UpwindPlan::new(&t, &area, &flux, -1.0),
        Err(ParamError::OutOfRange { name: "h", .. })
    ));
    assert!(matches!(
        UpwindPlan::new(&t, &area, &flux, f64::NAN),
        Err(ParamError::OutOfRange { name: "h", .. })
    ));
    assert_eq!(
        UpwindPlan::new(&t, &area, &[0.0, f64::INFINITY, 0.0], 0.1).unwrap_err(),
        ParamError::NonFinite {
            name: "flux",
            index: 1
        }
    );
    assert!(matches!(
        UpwindPlan::new(&t, &[1.0, -1.0, 1.0], &flux, 0.1),
        Err(ParamError::OutOfRange {
            name: "vertex_area",
            ..
        })
    ));
}

#[test]
fn rough_atan2_is_within_its_bound_and_the_sector_test_keeps_every_containing_wedge() {
    use std::f64::consts::{PI, TAU};
    let mut worst = 0.0f64;
    for k in 0..200_000 {
        let t = -PI + TAU * (k as f64 + 0.5) / 200_000.0;
        for r in [1e-300, 1e-3, 1.0, 7.5e5] {
            let (y, x) = (r * t.sin(), r * t.cos());
            worst = worst.max(wrap_angle(rough_atan2(y, x) - y.atan2(x)).abs());
        }
    }
    assert!(worst < 1e-5, "rough atan2 off by {worst:e}");
    for (y, x) in [(0.0, 1.0), (0.0, -1.0), (1.0, 0.0), (-1.0, 0.0), (1.0, 1.0)] {
        assert!(
            (rough_atan2(y, x) - f64::atan2(y, x)).abs() < 1e-5,
            "({y}, {x})"
        );
    }
    // a direction inside a sector (by an independent test: the turn from a to psi
    // and from psi to b both counter-clockwise and below π) passes, in any turn of
    // the angles; one clearly outside fails
    let ccw = |from: f64, to: f64| {
        let (u, v) = ((from.cos(), from.sin()), (to.cos(), to.sin()));
        u.0 * v.1 - u.1 * v.0 >= 0.0 && u.0 * v.0 + u.1 * v.1 > -1.0
    };
    let (mut inside, mut outside) = (0, 0);
    for a_k in 0..24 {
        let a = -PI + a_k as f64 * 0.55;
        for open_k in 1..12 {
            let b = a + open_k as f64 * 0.27;
            for turn in [-TAU, 0.0, TAU] {
                for psi_k in 0..97 {
                    let psi = wrap_angle(a - 0.4 + psi_k as f64 * 0.041);
                    let inner = ccw(a, psi) && ccw(psi, b) && ccw(a, b);
                    if inner {
                        inside += 1;
                        assert!(in_sector(psi, a + turn, b), "{psi} in ({a}, {b})");
                    }
                    let gap = wrap_angle(psi - a).min(wrap_angle(b - psi));
                    if gap < -2.0 * SECTOR_MARGIN && (b - a) < PI {
                        outside += 1;
                        assert!(!in_sector(psi, a, b + turn), "{psi} not in ({a}, {b})");
                    }
                }
            }
        }
    }
    assert!(inside > 1000 && outside > 1000, "{inside} {outside}");
    assert!(!in_sector(f64::NAN, 0.0, 1.0) && !in_sector(0.5, 0.0, f64::NAN));
}

#[test]
fn a_vertex_without_area_gives_all_it_has() {
    let t = Topology::from_triangles(3, vec![[0, 1, 2]]).unwrap();
    // edges (0,1), (0,2), (1,2): vertex 0 donates on both its edges, 1 to 2
    let plan = UpwindPlan::new(&t, &[0.0, 1.0, 1.0], &[1.0, 3.0, 0.5], 0.1).unwrap();
    assert_eq!(plan.n_limited(), 1);
    assert!(plan.max_courant().is_infinite());
    assert_eq!(plan.substeps(), 1);
    let mut mass = vec![2.0, 1.0, 0.0];
    plan.transport(&t, &mut mass);
    assert_eq!(mass[0], 0.0);
    assert!((mass[1] - (1.0 + 0.5 - 0.05)).abs() < 1e-15);
    assert!((mass[2] - (1.5 + 0.05)).abs() < 1e-15);
}
