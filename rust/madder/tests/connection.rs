//! Validation of the vertex frames, the discrete connection (seed §4.3.1, eq. 4.4), the
//! one-ring rotations (§4.4, Kabsch) and the connection Laplacian (§4.3.3, eq. 4.6)
//! against exact and independent results:
//!
//! - a flat cloth has a trivial connection: a constant field is transported exactly,
//!   borders, corners and stray flipped faces included, in any in-plane frames;
//! - the holonomy around the one-ring of a cone (or saddle) apex is its angle defect,
//!   computed independently from the 3-D positions;
//! - face holonomies add up to `2πχ` (discrete Gauss–Bonnet) on a sphere and a torus;
//! - Kabsch recovers known rotations, is translation invariant, always returns a proper
//!   rotation, and agrees with a Kabsch built on faer's SVD;
//! - `K_∇` kills constant fields on a flat mesh, its energy is `Σ L_ij |u_i − R_ij u_j|²`,
//!   vector diffusion on a flat mesh is two scalar diffusions, and on the unit sphere
//!   Killing fields have Rayleigh quotient 1 (`∇*∇ = Δ_Hodge − Ric`);
//! - the operators restricted to a set of vertices (`ops::restrict`) are the whole ones
//!   when every vertex is kept, have no flux out (`(M + K_A) 1 = A`), keep exactly the
//!   inside edges' weights, and their block expansion kills constant fields on a flat
//!   mesh.

use std::collections::HashMap;
use std::f64::consts::{PI, TAU};

use faer::Par;
use glam::{DMat2, DMat3, DQuat, DVec2, DVec3};
use madder::mesh::kabsch::{best_rotation, rotation_from_covariance, svd3};
use madder::mesh::{FanKind, Geometry, Topology, Transport, VertexFrames, one_ring_rotations};
use madder::ops::{
    BochnerPattern, BochnerSystem, LowerCsc, Restriction, VertexPattern, add_lumped_mass,
    bochner_stiffness, cotan_stiffness, diffuse_tangent_field, solve_spd,
};

mod common;
use common::{Built, Grid, build, hash};

// ---------------------------------------------------------------------------------------
// meshes and helpers

/// Unit icosphere, `levels` times subdivided; faces counter-clockwise seen from outside.
fn icosphere(levels: usize) -> (Topology, Vec<DVec3>) {
    let t = (1.0 + 5f64.sqrt()) / 2.0;
    let mut pos: Vec<DVec3> = [
        (-1.0, t, 0.0),
        (1.0, t, 0.0),
        (-1.0, -t, 0.0),
        (1.0, -t, 0.0),
        (0.0, -1.0, t),
        (0.0, 1.0, t),
        (0.0, -1.0, -t),
        (0.0, 1.0, -t),
        (t, 0.0, -1.0),
        (t, 0.0, 1.0),
        (-t, 0.0, -1.0),
        (-t, 0.0, 1.0),
    ]
    .iter()
    .map(|&(x, y, z)| DVec3::new(x, y, z).normalize())
    .collect();
    let mut faces: Vec<[u32; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    for _ in 0..levels {
        let mut mid: HashMap<(u32, u32), u32> = HashMap::new();
        let mut midpoint = |a: u32, b: u32, pos: &mut Vec<DVec3>| {
            *mid.entry((a.min(b), a.max(b))).or_insert_with(|| {
                pos.push(((pos[a as usize] + pos[b as usize]) / 2.0).normalize());
                (pos.len() - 1) as u32
            })
        };
        let mut next = Vec::with_capacity(4 * faces.len());
        for &[a, b, c] in &faces {
            let ab = midpoint(a, b, &mut pos);
            let bc = midpoint(b, c, &mut pos);
            let ca = midpoint(c, a, &mut pos);
            next.extend([[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
        }
        faces = next;
    }
    (Topology::from_triangles(pos.len(), faces).unwrap(), pos)
}

/// Torus of radii `big`, `small`, `nu × nv` quads, outward-oriented.
fn torus(nu: usize, nv: usize, big: f64, small: f64) -> (Topology, Vec<DVec3>) {
    let idx = |i: usize, j: usize| ((i % nu) * nv + (j % nv)) as u32;
    let mut faces = Vec::new();
    for i in 0..nu {
        for j in 0..nv {
            let (a, b, c, d) = (idx(i, j), idx(i + 1, j), idx(i + 1, j + 1), idx(i, j + 1));
            faces.extend([[a, b, c], [a, c, d]]);
        }
    }
    let mut pos = Vec::new();
    for i in 0..nu {
        for j in 0..nv {
            let (u, v) = (TAU * i as f64 / nu as f64, TAU * j as f64 / nv as f64);
            let r = big + small * v.cos();
            pos.push(DVec3::new(r * u.cos(), r * u.sin(), small * v.sin()));
        }
    }
    (Topology::from_triangles(nu * nv, faces).unwrap(), pos)
}

/// Apex 0 and a ring of `ring.len()` base vertices; faces `(0, k, k+1)` around the apex,
/// counter-clockwise seen from +z.
fn pyramid(apex: DVec3, ring: &[DVec3]) -> (Topology, Vec<DVec3>) {
    let k = ring.len() as u32;
    let faces = (0..k).map(|i| [0, 1 + i, 1 + (i + 1) % k]).collect();
    let mut pos = vec![apex];
    pos.extend_from_slice(ring);
    (
        Topology::from_triangles(1 + ring.len(), faces).unwrap(),
        pos,
    )
}

/// Rotation angle of a 2×2 rotation matrix, in (−π, π].
fn angle_of(r: DMat2) -> f64 {
    r.x_axis.y.atan2(r.x_axis.x)
}

fn wrap(a: f64) -> f64 {
    (a + PI).rem_euclid(TAU) - PI
}

/// Largest deviation of a frame from a right-handed orthonormal basis.
fn frame_error(f: &DMat3) -> f64 {
    let e = (f.transpose() * *f - DMat3::IDENTITY).to_cols_array();
    e.iter()
        .fold((f.determinant() - 1.0).abs(), |m, x| m.max(x.abs()))
}

fn random_rotation(k: usize) -> DMat3 {
    let q = DQuat::from_xyzw(hash(k, 11), hash(k, 12), hash(k, 13), hash(k, 14)).normalize();
    DMat3::from_quat(q)
}

fn mat_err(a: DMat3, b: DMat3) -> f64 {
    (a - b)
        .to_cols_array()
        .iter()
        .fold(0.0f64, |m, x| m.max(x.abs()))
}

// ---------------------------------------------------------------------------------------
// frames and connection

/// Checks `R_ij u_j = u_i` for the in-plane constant vector `w` on every directed edge;
/// returns the largest error.
fn flat_transport_error(t: &Topology, b: &Built, frames: &VertexFrames, w: DVec3) -> f64 {
    let mut worst = 0.0f64;
    for &[i, j] in t.edges() {
        let (i, j) = (i as usize, j as usize);
        let (ui, uj) = (frames.to_local(i, w), frames.to_local(j, w));
        for (a, b_, ua, ub) in [(i, j, ui, uj), (j, i, uj, ui)] {
            let moved = b.transport.transport(a, b_, ub).unwrap();
            worst = worst.max((moved - ua).length());
        }
    }
    worst
}

#[test]
fn flat_cloth_transports_a_constant_field_exactly() {
    let (t, p) = Grid::new(12, 1.0).jitter(0.5).build();
    let b = build(&t, &p);
    let boundary = t.boundary_vertices();
    for v in 0..t.n_vertices() {
        let want = if boundary[v] {
            FanKind::Boundary
        } else {
            FanKind::Interior
        };
        assert_eq!(b.rings.kind(v), want, "vertex {v}");
        assert!((b.frames.frame[v].z_axis - DVec3::Z).length() < 1e-15);
        assert!(frame_error(&b.frames.frame[v]) < 1e-15);
        // x is the reference spoke's direction
        let e = p[b.rings.spokes(v)[0] as usize] - p[v];
        assert!((b.frames.frame[v].x_axis - e.normalize()).length() < 1e-15);
        assert!(b.transport.frame_offset(v).abs() < 1e-15);
    }
    let w = DVec3::new(0.8, -0.35, 0.0);
    let err = flat_transport_error(&t, &b, &b.frames, w);
    eprintln!("flat jittered grid: max |R_ij u_j − u_i| = {err:.2e}");
    assert!(err < 1e-12, "flat transport error {err}");
    // corners have tip-angle sum π/2, straight borders π: no rescaling keeps them exact
    assert!((b.transport.angle_sum(0) - PI / 2.0).abs() < 1e-14);
    assert!((b.transport.angle_sum(3) - PI).abs() < 1e-13);
}

#[test]
fn flipped_faces_are_harmonized() {
    let (t0, p) = Grid::new(8, 1.0).jitter(0.4).build();
    let mut faces = t0.faces().to_vec();
    // flip an interior face, a border face and the face at a corner
    for f in [37usize, 3, 0] {
        faces[f].swap(1, 2);
    }
    let t = Topology::from_triangles(t0.n_vertices(), faces).unwrap();
    let b = build(&t, &p);
    assert!(b.rings.orientation_reversing_edges().is_empty());
    let boundary = t.boundary_vertices();
    for (v, &on_boundary) in boundary.iter().enumerate() {
        assert_eq!(b.rings.kind(v) == FanKind::Boundary, on_boundary);
        assert!(
            (b.frames.frame[v].z_axis - DVec3::Z).length() < 1e-15,
            "vertex {v}"
        );
    }
    let flipped_corners = (0..t.n_vertices())
        .flat_map(|v| b.rings.wedges(v).iter().filter(|w| !w.forward))
        .count();
    assert_eq!(
        flipped_corners, 9,
        "3 faces × 3 corners walked against their order"
    );
    let err = flat_transport_error(&t, &b, &b.frames, DVec3::new(-0.2, 1.1, 0.0));
    eprintln!("flat grid with 3 flipped faces: max |R_ij u_j − u_i| = {err:.2e}");
    assert!(err < 1e-12);
}

#[test]
fn any_in_plane_frames_keep_the_flat_transport_exact() {
    // turn every frame about its normal by a different angle: the connection measures
    // the offset and stays exact
    let (t, p) = Grid::new(10, 1.0).jitter(0.5).build();
    let b = build(&t, &p);
    let turns: Vec<DMat3> = (0..t.n_vertices())
        .map(|v| DMat3::from_rotation_z(TAU * hash(v, 5)))
        .collect();
    let frames = b.frames.rotated(&turns);
    let transport = Transport::new(&t, &b.rings, &b.geometry, &frames, &p);
    let b2 = Built {
        rings: b.rings.clone(),
        geometry: b.geometry.clone(),
        frames: frames.clone(),
        transport,
    };
    for v in 0..t.n_vertices() {
        let d = wrap(b2.transport.frame_offset(v) + TAU * hash(v, 5));
        assert!(d.abs() < 1e-13, "vertex {v}: offset off by {d}");
    }
    let err = flat_transport_error(&t, &b2, &frames, DVec3::new(0.3, 0.9, 0.0));
    eprintln!("flat grid, randomly turned frames: max |R_ij u_j − u_i| = {err:.2e}");
    assert!(err < 1e-12);
}

/// Angle defect `2π − Σ` tip angles at vertex 0, from 3-D positions (independent of
/// [`Geometry`]).
fn apex_defect(t: &Topology, p: &[DVec3]) -> f64 {
    let sum: f64 = t
        .faces()
        .iter()
        .map(|&[a, b, c]| {
            assert_eq!(a, 0);
            let (u, v) = (p[b as usize] - p[0], p[c as usize] - p[0]);
            u.angle_between(v)
        })
        .sum();
    TAU - sum
}

/// Holonomy `R_{j1 jk} ⋯ R_{j3 j2} R_{j2 j1}` around the apex's ring, counter-clockwise.
fn ring_holonomy(c: &Transport, k: usize) -> DMat2 {
    let mut h = DMat2::IDENTITY;
    for m in 0..k {
        let (from, to) = (1 + m, 1 + (m + 1) % k);
        h = c.rotation(to, from).unwrap() * h;
    }
    h
}

#[test]
fn cone_apex_holonomy_is_the_angle_defect() {
    let k = 7;
    let ring: Vec<DVec3> = (0..k)
        .map(|m| {
            let a = TAU * (m as f64 + 0.3 * hash(m, 3)) / k as f64;
            let r = 1.0 + 0.3 * hash(m, 4);
            DVec3::new(r * a.cos(), r * a.sin(), 0.1 * hash(m, 6))
        })
        .collect();
    for height in [0.4, 1.5, -0.8] {
        let (t, p) = pyramid(DVec3::new(0.05, -0.02, height), &ring);
        let b = build(&t, &p);
        assert_eq!(b.rings.kind(0), FanKind::Interior);
        let d = apex_defect(&t, &p);
        assert!(d > 0.05, "a cone has positive defect ({d})");
        let h = angle_of(ring_holonomy(&b.transport, k));
        eprintln!(
            "cone height {height}: holonomy {h:.15}, angle defect {d:.15}, diff {:.2e}",
            (h - d).abs()
        );
        assert!((h - d).abs() < 1e-12, "holonomy {h} vs defect {d}");
        // the interior apex is rescaled; its polar angles end at 2π
        assert!((b.transport.angle_sum(0) - (TAU - d)).abs() < 1e-12);
        // that rescaling gives each face around the apex the share φ/γ of the defect (the
        // ring's border corners, not rescaled, add nothing): loop j_m → j_m+1 → apex → j_m
        for m in 0..k {
            let (a, bb) = (1 + m, 1 + (m + 1) % k);
            let h = b.transport.rotation(a, 0).unwrap()
                * b.transport.rotation(0, bb).unwrap()
                * b.transport.rotation(bb, a).unwrap();
            let phi = (p[a] - p[0]).angle_between(p[bb] - p[0]);
            let share = d * phi / (TAU - d);
            assert!(
                (angle_of(h) - share).abs() < 1e-12,
                "face {m}: {} vs {share}",
                angle_of(h)
            );
        }
    }
}

#[test]
fn saddle_apex_holonomy_is_the_negative_angle_defect() {
    let k = 6;
    let ring: Vec<DVec3> = (0..k)
        .map(|m| {
            let a = TAU * m as f64 / k as f64 + 0.1 * hash(m, 7);
            let z = if m % 2 == 0 { 0.5 } else { -0.5 };
            DVec3::new(a.cos(), a.sin(), z)
        })
        .collect();
    let (t, p) = pyramid(DVec3::ZERO, &ring);
    let b = build(&t, &p);
    let d = apex_defect(&t, &p);
    assert!(d < -0.5, "a monkey saddle has negative defect ({d})");
    let h = angle_of(ring_holonomy(&b.transport, k));
    eprintln!(
        "saddle: holonomy {h:.15}, angle defect {d:.15}, diff {:.2e}",
        (h - wrap(d)).abs()
    );
    assert!((h - wrap(d)).abs() < 1e-12);
}

/// Sum over faces of the holonomy around each face, counter-clockwise.
fn total_face_holonomy(t: &Topology, c: &Transport) -> (f64, f64) {
    let mut sum = 0.0;
    let mut largest = 0.0f64;
    for &[a, b, cc] in t.faces() {
        let (a, b, cc) = (a as usize, b as usize, cc as usize);
        let h = c.rotation(a, cc).unwrap() * c.rotation(cc, b).unwrap() * c.rotation(b, a).unwrap();
        let x = angle_of(h);
        largest = largest.max(x.abs());
        sum += x;
    }
    (sum, largest)
}

#[test]
fn face_holonomies_obey_gauss_bonnet() {
    let (t, p) = icosphere(3);
    let b = build(&t, &p);
    let (sum, largest) = total_face_holonomy(&t, &b.transport);
    eprintln!(
        "icosphere(3): Σ face holonomies = {sum:.14} (4π = {:.14}), largest face {largest:.3e}",
        4.0 * PI
    );
    assert!(largest < 0.1);
    assert!((sum - 4.0 * PI).abs() < 1e-10);

    let (t, p) = torus(32, 16, 1.0, 0.35);
    let b = build(&t, &p);
    let (sum, largest) = total_face_holonomy(&t, &b.transport);
    eprintln!("torus: Σ face holonomies = {sum:.3e} (χ = 0), largest face {largest:.3e}");
    assert!(largest < 0.1);
    assert!(sum.abs() < 1e-10);
}

#[test]
fn reverse_rotation_is_the_transpose_and_matches_the_polar_angles() {
    let (t, p) = Grid::new(10, 1.0)
        .jitter(0.4)
        .build_with(|x, y| DVec3::new(x, y, 0.3 * (2.0 * x).sin() * (1.5 * y).cos()));
    let b = build(&t, &p);
    let c = &b.transport;
    // angle of spoke j in the frame of i, from the stored polar angles and offsets
    let polar = |i: usize, j: usize| {
        let k = b
            .rings
            .spokes(i)
            .iter()
            .position(|&s| s as usize == j)
            .unwrap();
        c.polar_angles(i)[k] + c.frame_offset(i)
    };
    let mut worst = 0.0f64;
    for &[i, j] in t.edges() {
        let (i, j) = (i as usize, j as usize);
        let (rij, rji) = (c.rotation(i, j).unwrap(), c.rotation(j, i).unwrap());
        assert_eq!(rji, rij.transpose(), "R_ji must be exactly R_ijᵀ");
        assert_eq!(c.angle(j, i).unwrap(), -c.angle(i, j).unwrap());
        let id = (rji * rij - DMat2::IDENTITY).to_cols_array();
        assert!(id.iter().all(|x| x.abs() < 1e-15));
        // θ_ij = α_ij − α_ji + π and θ_ji = α_ji − α_ij + π
        worst = worst.max(wrap(c.angle(i, j).unwrap() - (polar(i, j) - polar(j, i) + PI)).abs());
        worst = worst.max(wrap(c.angle(j, i).unwrap() - (polar(j, i) - polar(i, j) + PI)).abs());
    }
    assert!(worst < 1e-14, "θ vs polar angles: {worst}");
    // a curved surface does have a non-trivial connection
    let (_, largest) = total_face_holonomy(&t, c);
    assert!(largest > 1e-3, "largest face holonomy {largest}");
}

#[test]
fn frames_on_a_sphere_are_orthonormal_and_normal() {
    let (t, p) = icosphere(3);
    let b = build(&t, &p);
    assert_eq!(p.len(), t.n_vertices());
    for (v, &pv) in p.iter().enumerate() {
        assert_eq!(b.rings.kind(v), FanKind::Interior);
        let f = &b.frames.frame[v];
        assert!(frame_error(f) < 1e-14);
        assert!(f.z_axis.dot(pv) > 0.999, "vertex {v}: normal {}", f.z_axis);
        // interior: polar angles span [0, 2π)
        let a = b.transport.polar_angles(v);
        assert_eq!(a[0], 0.0);
        assert!(a.iter().all(|&x| (0.0..TAU).contains(&x)));
    }
}

#[test]
fn comoving_frames_follow_a_rigid_motion() {
    // rest frames turned by the Kabsch rotations of a rigidly moved mesh give the same
    // connection as the rest mesh, and as the frames rebuilt on the moved mesh
    let (t, rest) = Grid::new(8, 1.0)
        .jitter(0.4)
        .build_with(|x, y| DVec3::new(x, y, 0.2 * (x * y + x * x)));
    let q = random_rotation(3);
    let shift = DVec3::new(0.5, -2.0, 7.0);
    let moved: Vec<DVec3> = rest.iter().map(|&x| q * x + shift).collect();
    let b0 = build(&t, &rest);
    let u = one_ring_rotations(&t, &rest, &moved).unwrap();
    let frames = b0.frames.rotated(&u);
    let g1 = Geometry::new(&t, &moved).unwrap();
    let c1 = Transport::new(&t, &b0.rings, &g1, &frames, &moved);
    let b1 = build(&t, &moved);
    let mut worst = 0.0f64;
    for e in 0..t.n_edges() {
        let th = c1.edge_angles()[e];
        worst = worst
            .max(wrap(th - b0.transport.edge_angles()[e]).abs())
            .max(wrap(th - b1.transport.edge_angles()[e]).abs());
    }
    eprintln!("rigid motion: comoving vs rest connection angles differ by {worst:.2e}");
    assert!(worst < 1e-12);
    for v in 0..t.n_vertices() {
        assert!(mat_err(frames.frame[v], b1.frames.frame[v]) < 1e-12);
    }
}

#[test]
fn irregular_fans_stay_finite() {
    // bow-tie: two triangles sharing only vertex 0; fin: three faces on edge 5–6;
    // vertex 9 loose; vertices 10..13 a collapsed triangle fan (all at one point)
    let faces = vec![
        [0, 1, 2],
        [0, 3, 4],
        [5, 6, 7],
        [6, 5, 8],
        [5, 6, 4],
        [10, 11, 12],
        [10, 12, 13],
    ];
    let t = Topology::from_triangles(14, faces).unwrap();
    let mut p: Vec<DVec3> = (0..14)
        .map(|k| DVec3::new(hash(k, 1), hash(k, 2), hash(k, 3)))
        .collect();
    p[10..14].fill(DVec3::new(3.0, 3.0, 3.0));
    let b = build(&t, &p);
    assert_eq!(b.rings.kind(0), FanKind::Irregular);
    assert_eq!(b.rings.kind(5), FanKind::Irregular);
    assert_eq!(b.rings.kind(6), FanKind::Irregular);
    assert_eq!(b.rings.kind(9), FanKind::Loose);
    assert_eq!(b.rings.kind(10), FanKind::Boundary);
    assert_eq!(b.rings.spokes(0).len(), 4);
    assert_eq!(b.frames.frame[9], DMat3::IDENTITY);
    for v in 0..14 {
        assert!(frame_error(&b.frames.frame[v]) < 1e-14, "vertex {v}");
        assert!(b.transport.polar_angles(v).iter().all(|a| a.is_finite()));
        assert!(b.transport.frame_offset(v).is_finite());
    }
    assert!(b.transport.edge_angles().iter().all(|a| a.is_finite()));
    // the bow-tie's fans are laid side by side: its angles add up
    let g = b.transport.angle_sum(0);
    let a = b.transport.polar_angles(0);
    assert!((a.iter().cloned().fold(0.0, f64::max) - g).abs() < 1e-14);
}

#[test]
fn mobius_strip_has_orientation_reversing_edges() {
    // strip of n quads; closing it straight gives an annulus, with a half twist a Möbius band
    let strip = |twist: bool| {
        let n = 16;
        let idx = |i: usize, s: usize| (2 * (i % n) + s) as u32;
        let mut faces = Vec::new();
        for i in 0..n {
            let (a, b) = (idx(i, 0), idx(i, 1));
            let (c, d) = if twist && i == n - 1 {
                (idx(i + 1, 1), idx(i + 1, 0))
            } else {
                (idx(i + 1, 0), idx(i + 1, 1))
            };
            faces.extend([[a, c, d], [a, d, b]]);
        }
        let mut pos = Vec::new();
        for i in 0..n {
            let u = TAU * i as f64 / n as f64;
            let half = if twist { u / 2.0 } else { 0.0 };
            let centre = DVec3::new(u.cos(), u.sin(), 0.0);
            let across = half.cos() * centre * 0.3 + half.sin() * DVec3::Z * 0.3;
            pos.push(centre - across);
            pos.push(centre + across);
        }
        (Topology::from_triangles(2 * n, faces).unwrap(), pos)
    };
    let (t, p) = strip(false);
    let b = build(&t, &p);
    assert!(b.rings.orientation_reversing_edges().is_empty());
    let (t, p) = strip(true);
    let b = build(&t, &p);
    let rev = b.rings.orientation_reversing_edges();
    eprintln!("Möbius band: {} orientation-reversing edges", rev.len());
    assert!(!rev.is_empty());
    assert!(b.transport.edge_angles().iter().all(|a| a.is_finite()));
}

#[test]
fn connection_is_bit_identical_across_thread_counts() {
    let (t, p) = icosphere(3);
    let run = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| {
                let b = build(&t, &p);
                let u = one_ring_rotations(&t, &p, &p.iter().map(|x| 2.0 * *x).collect::<Vec<_>>())
                    .unwrap();
                (b.transport.edge_angles().to_vec(), b.frames.frame, u)
            })
    };
    assert_eq!(run(1), run(3));
}

// ---------------------------------------------------------------------------------------
// Kabsch

fn irregular_ring() -> (DVec3, Vec<DVec3>) {
    let centre = DVec3::new(0.3, -0.1, 0.2);
    let ring = (0..6)
        .map(|m| {
            let a = TAU * m as f64 / 6.0 + 0.2 * hash(m, 8);
            centre
                + DVec3::new(
                    (1.0 + 0.3 * hash(m, 9)) * a.cos(),
                    a.sin(),
                    0.4 * hash(m, 10),
                )
        })
        .collect();
    (centre, ring)
}

#[test]
fn kabsch_recovers_rotations_exactly_and_ignores_translation() {
    let (c, ring) = irregular_ring();
    let rest: Vec<DVec3> = ring.iter().map(|x| *x - c).collect();
    let mut worst = 0.0f64;
    for k in 0..50 {
        let r = random_rotation(k);
        let shift = DVec3::new(hash(k, 20), hash(k, 21), hash(k, 22)) * 100.0;
        // the moved one-ring, relative to the moved centre
        let cur: Vec<DVec3> = ring
            .iter()
            .map(|x| (r * *x + shift) - (r * c + shift))
            .collect();
        let u = best_rotation(&rest, &cur);
        worst = worst.max(mat_err(u, r));
    }
    eprintln!("Kabsch on 50 random rotations of a one-ring: max |U − R| = {worst:.2e}");
    assert!(worst < 1e-12);
}

#[test]
fn planar_mirror_image_is_reached_by_a_proper_rotation() {
    // a planar one-ring and its mirror image in the plane (x → −x): the best proper
    // rotation is the half-turn about y, with zero residual; a naive U Vᵀ could be the
    // mirror itself (det −1)
    let rest: Vec<DVec3> = (0..5)
        .map(|m| {
            let a = TAU * m as f64 / 5.0 + 0.3 * hash(m, 30);
            DVec3::new(a.cos(), (1.0 + 0.2 * hash(m, 31)) * a.sin(), 0.0)
        })
        .collect();
    let mirrored: Vec<DVec3> = rest.iter().map(|x| DVec3::new(-x.x, x.y, 0.0)).collect();
    let u = best_rotation(&rest, &mirrored);
    assert!((u.determinant() - 1.0).abs() < 1e-14);
    let err = mat_err(u, DMat3::from_rotation_y(PI));
    eprintln!("planar mirror: |U − R_y(π)| = {err:.2e}");
    assert!(err < 1e-14);
    for (p, q) in rest.iter().zip(&mirrored) {
        assert!((u * *p - *q).length() < 1e-14);
    }
    // a planar ring rotated in 3-D: the rank-2 covariance still gives the rotation
    let r = random_rotation(77);
    let turned: Vec<DVec3> = rest.iter().map(|x| r * *x).collect();
    assert!(mat_err(best_rotation(&rest, &turned), r) < 1e-13);
}

/// Kabsch built on faer's dense SVD (independent implementation).
fn faer_kabsch(h: DMat3) -> (DMat3, [f64; 3]) {
    let m = faer::Mat::<f64>::from_fn(3, 3, |i, j| h.col(j)[i]);
    let svd = m.svd().unwrap();
    let (u, v) = (svd.U(), svd.V());
    let to = |a: faer::MatRef<'_, f64>| {
        DMat3::from_cols_array(&std::array::from_fn(|k| a[(k % 3, k / 3)]))
    };
    let (u, v) = (to(u), to(v));
    let d = (u * v.transpose()).determinant().signum();
    let s = svd.S().column_vector();
    (
        u * DMat3::from_diagonal(DVec3::new(1.0, 1.0, d)) * v.transpose(),
        [s[0], s[1], s[2]],
    )
}

#[test]
fn kabsch_agrees_with_faer_svd_including_reflections() {
    let mut worst_r = 0.0f64;
    let mut worst_s = 0.0f64;
    let mut n_reflecting = 0;
    for k in 0..200 {
        let h = DMat3::from_cols_array(&std::array::from_fn(|i| hash(k, 40 + i as u64)));
        n_reflecting += usize::from(h.determinant() < 0.0);
        let r = rotation_from_covariance(h);
        assert!((r.determinant() - 1.0).abs() < 1e-14);
        assert!(mat_err(r.transpose() * r, DMat3::IDENTITY) < 1e-14);
        let (rf, sf) = faer_kabsch(h);
        // the rotation is unique when σ₂ + σ₃ (d = −1) or σ₃ (d = +1) stays away from 0
        worst_r = worst_r.max(mat_err(r, rf));
        let s = svd3(h).sigma;
        worst_s = worst_s.max((s - DVec3::from(sf)).abs().max_element() / sf[0]);
    }
    eprintln!(
        "Kabsch vs faer SVD on 200 random H ({n_reflecting} with det < 0): \
         max |ΔU| = {worst_r:.2e}, max relative Δσ = {worst_s:.2e}"
    );
    assert!(n_reflecting > 50);
    assert!(worst_r < 1e-11);
    assert!(worst_s < 1e-14);
}

#[test]
fn one_ring_rotations_of_a_rigid_motion_are_the_motion() {
    let q = random_rotation(9);
    for (name, (t, p)) in [
        (
            "flat grid (rank-2 covariances)",
            Grid::new(6, 1.0).jitter(0.4).build(),
        ),
        ("icosphere", icosphere(2)),
    ] {
        let moved: Vec<DVec3> = p
            .iter()
            .map(|&x| q * x + DVec3::new(3.0, -1.0, 0.5))
            .collect();
        let u = one_ring_rotations(&t, &p, &moved).unwrap();
        let err = u.iter().map(|&r| mat_err(r, q)).fold(0.0, f64::max);
        eprintln!("{name}: max |U_i − Q| = {err:.2e}");
        assert!(err < 1e-12);
    }
    // wrong lengths are reported
    let (t, p) = Grid::new(2, 1.0).build();
    assert!(one_ring_rotations(&t, &p, &p[..3]).is_err());
}

// ---------------------------------------------------------------------------------------
// connection Laplacian

/// Interleaves a tangent field for the `2N` system.
fn flat(u: &[DVec2]) -> Vec<f64> {
    u.iter().flat_map(|v| [v.x, v.y]).collect()
}

#[test]
fn constant_field_is_in_the_kernel_on_a_flat_mesh() {
    let (t, p) = Grid::new(12, 1.0).jitter(0.5).build();
    let b = build(&t, &p);
    let sp = VertexPattern::new(&t);
    let bp = BochnerPattern::new(&sp);
    let k = cotan_stiffness(&t, &b.geometry, &sp, 1.0);
    let kv = bochner_stiffness(&sp, &bp, &k, &b.transport);
    let w = DVec3::new(1.3, -0.4, 0.0);
    let u: Vec<DVec2> = (0..t.n_vertices())
        .map(|v| b.frames.to_local(v, w))
        .collect();
    let r = bp.sym_matvec(&kv, &flat(&u));
    let err = r.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    let scale = k.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    eprintln!("flat grid: max |K_∇ u| = {err:.2e} (max |K_ij| = {scale:.2})");
    assert!(err < 1e-12);
    // a non-constant field is not in the kernel (the test can fail)
    let u2: Vec<DVec2> = (0..t.n_vertices())
        .map(|v| b.frames.to_local(v, DVec3::new(p[v].y, 0.0, 0.0)))
        .collect();
    let r2 = bp.sym_matvec(&kv, &flat(&u2));
    assert!(r2.iter().fold(0.0f64, |m, x| m.max(x.abs())) > 1e-3);
}

#[test]
fn flat_vector_diffusion_is_two_scalar_diffusions() {
    let (t, p) = Grid::new(16, 1.0).jitter(0.5).build();
    let b = build(&t, &p);
    let n = t.n_vertices();
    // a smooth field with swirl and shear, in the global basis
    let w: Vec<DVec3> = p
        .iter()
        .map(|x| DVec3::new((3.0 * x.y).sin() + x.x, (2.0 * x.x).cos() * x.y, 0.0))
        .collect();
    let (nu, h) = (0.7, 0.05);
    let sp = VertexPattern::new(&t);
    let k = cotan_stiffness(&t, &b.geometry, &sp, nu);
    let u: Vec<DVec2> = (0..n).map(|v| b.frames.to_local(v, w[v])).collect();
    let u1 = diffuse_tangent_field(&t, &b.geometry, &k, &b.transport, h, &u).unwrap();
    // independent: scalar (M + h ν K) c' = M c for each global component
    let mut a = cotan_stiffness(&t, &b.geometry, &sp, h * nu);
    add_lumped_mass(&b.geometry, &sp, 1.0, &mut a);
    let comp = |f: fn(&DVec3) -> f64| {
        let rhs: Vec<f64> = w
            .iter()
            .zip(&b.geometry.vertex_area)
            .map(|(x, m)| m * f(x))
            .collect();
        solve_spd(&sp, &a, &rhs).unwrap()
    };
    let (cx, cy) = (comp(|x| x.x), comp(|x| x.y));
    let mut worst = 0.0f64;
    let mut change = 0.0f64;
    for v in 0..n {
        let got = b.frames.to_world(v, u1[v]);
        worst = worst.max((got - DVec3::new(cx[v], cy[v], 0.0)).length());
        change = change.max((got - w[v]).length());
    }
    eprintln!(
        "flat grid: vector vs two scalar diffusions differ by {worst:.2e} (field moved by {change:.2e})"
    );
    assert!(change > 1e-2, "the step must actually diffuse");
    assert!(worst < 1e-10);
}

/// `Σ_edges L_ij |u_i − R_ij u_j|²` with `L_ij = −K_ij`.
fn edge_energy(t: &Topology, sp: &VertexPattern, k: &[f64], c: &Transport, u: &[DVec2]) -> f64 {
    t.edges()
        .iter()
        .enumerate()
        .map(|(e, &[i, j])| {
            let (i, j) = (i as usize, j as usize);
            let l = -k[sp.edge_slot()[e] as usize];
            l * (u[i] - c.transport(i, j, u[j]).unwrap()).length_squared()
        })
        .sum()
}

#[test]
fn energy_is_the_sum_of_transport_residuals_and_nonnegative() {
    for (name, (t, p)) in [
        ("icosphere(3)", icosphere(3)),
        (
            "bumpy grid",
            Grid::new(14, 1.0)
                .build_with(|x, y| DVec3::new(x, y, 0.25 * (2.5 * x).sin() * (2.0 * y).cos())),
        ),
    ] {
        let b = build(&t, &p);
        let sp = VertexPattern::new(&t);
        let bp = BochnerPattern::new(&sp);
        let k = cotan_stiffness(&t, &b.geometry, &sp, 1.0);
        let kv = bochner_stiffness(&sp, &bp, &k, &b.transport);
        let delaunay = sp.edge_slot().iter().all(|&s| k[s as usize] <= 1e-14);
        let mut worst = 0.0f64;
        let mut least = f64::INFINITY;
        for trial in 0..20 {
            let u: Vec<DVec2> = (0..t.n_vertices())
                .map(|v| DVec2::new(hash(v, 100 + trial), hash(v, 200 + trial)))
                .collect();
            let x = flat(&u);
            let e: f64 = x
                .iter()
                .zip(bp.sym_matvec(&kv, &x))
                .map(|(a, b)| a * b)
                .sum();
            let ee = edge_energy(&t, &sp, &k, &b.transport, &u);
            worst = worst.max((e - ee).abs() / ee.abs());
            least = least.min(e);
        }
        eprintln!(
            "{name}: uᵀK_∇u vs Σ L|u_i − R u_j|²: rel. diff {worst:.2e}, least energy {least:.3e}, Delaunay {delaunay}"
        );
        assert!(worst < 1e-12);
        assert!(delaunay || !name.starts_with("icosphere"));
        if delaunay {
            assert!(least > 0.0);
        }
    }
}

#[test]
fn killing_fields_on_the_unit_sphere_have_rayleigh_quotient_one() {
    // on the unit sphere ∇*∇ = Δ_Hodge − Ric; rotation fields ω × x are Hodge eigenfields
    // with eigenvalue 2, so uᵀK_∇u / uᵀMu → 1 under refinement. Comparing the fields as
    // 3-D vectors instead (each component a degree-1 harmonic) would give 2.
    let mut prev = f64::INFINITY;
    for level in [2, 3, 4] {
        let (t, p) = icosphere(level);
        let b = build(&t, &p);
        let sp = VertexPattern::new(&t);
        let bp = BochnerPattern::new(&sp);
        let k = cotan_stiffness(&t, &b.geometry, &sp, 1.0);
        let kv = bochner_stiffness(&sp, &bp, &k, &b.transport);
        let mut worst = 0.0f64;
        for omega in [DVec3::Z, DVec3::new(0.3, -0.8, 0.5).normalize()] {
            let u: Vec<DVec2> = (0..t.n_vertices())
                .map(|v| b.frames.to_local(v, omega.cross(p[v])))
                .collect();
            let x = flat(&u);
            let e: f64 = x
                .iter()
                .zip(bp.sym_matvec(&kv, &x))
                .map(|(a, b)| a * b)
                .sum();
            let m: f64 = u
                .iter()
                .zip(&b.geometry.vertex_area)
                .map(|(u, a)| a * u.length_squared())
                .sum();
            worst = worst.max((e / m - 1.0).abs());
        }
        eprintln!("icosphere({level}): |Rayleigh quotient − 1| = {worst:.3e}");
        assert!(worst < prev, "converges under refinement");
        prev = worst;
    }
    assert!(prev < 1e-4);
}

#[test]
fn system_is_spd_on_curved_meshes_and_reuses_its_factorization() {
    let (t, p) = icosphere(3);
    let n = t.n_vertices();
    let mut sys = BochnerSystem::new(&t, Par::Seq).unwrap();
    assert_eq!(sys.pattern().n(), 2 * n);
    let u0: Vec<DVec2> = (0..n).map(|v| DVec2::new(hash(v, 1), hash(v, 2))).collect();
    for (step, (scale, h)) in [(1.0, 1e-3), (1.3, 1.0), (0.8, 1e4)]
        .into_iter()
        .enumerate()
    {
        // the sphere breathes: new geometry, same pattern
        let q: Vec<DVec3> = p.iter().map(|x| *x * scale).collect();
        let b = build(&t, &q);
        let k = cotan_stiffness(&t, &b.geometry, sys.scalar_pattern(), 0.5);
        let mut u = u0.clone();
        sys.diffuse(&b.geometry, &k, &b.transport, h, &mut u)
            .unwrap();
        // residual of (M ⊗ I + h K_∇) u' = (M ⊗ I) u
        let kv = bochner_stiffness(sys.scalar_pattern(), sys.pattern(), &k, &b.transport);
        let ku = sys.pattern().sym_matvec(&kv, &flat(&u));
        let mut res = 0.0f64;
        let mut rhs = 0.0f64;
        for v in 0..n {
            let a = b.geometry.vertex_area[v];
            let r = a * (u[v] - u0[v]) + h * DVec2::new(ku[2 * v], ku[2 * v + 1]);
            res = res.max(r.length());
            rhs = rhs.max((a * u0[v]).length());
        }
        eprintln!(
            "step {step}: h = {h:e}, relative residual {:.2e}",
            res / rhs
        );
        assert!(res < 1e-10 * rhs);
        // the one-shot form gives the same bits
        let once = diffuse_tangent_field(&t, &b.geometry, &k, &b.transport, h, &u0).unwrap();
        assert_eq!(once, u);
        // no field on a sphere is parallel: diffusion strictly loses energy
        let norm = |u: &[DVec2]| -> f64 {
            u.iter()
                .zip(&b.geometry.vertex_area)
                .map(|(u, a)| a * u.length_squared())
                .sum()
        };
        assert!(norm(&u) < norm(&u0));
    }
}

#[test]
fn loose_vertex_keeps_its_velocity_and_bad_input_is_reported() {
    let (t0, p0) = Grid::new(3, 1.0).build();
    let mut p = p0.clone();
    p.push(DVec3::new(5.0, 5.0, 5.0));
    let t = Topology::from_triangles(p.len(), t0.faces().to_vec()).unwrap();
    let b = build(&t, &p);
    let mut sys = BochnerSystem::new(&t, Par::Seq).unwrap();
    let k = cotan_stiffness(&t, &b.geometry, sys.scalar_pattern(), 1.0);
    let mut u = vec![DVec2::new(1.0, 0.0); p.len()];
    u[16] = DVec2::new(-2.0, 3.0);
    sys.diffuse(&b.geometry, &k, &b.transport, 0.1, &mut u)
        .unwrap();
    assert_eq!(u[16], DVec2::new(-2.0, 3.0));
    assert!(u.iter().all(|v| v.is_finite()));
    let before = u.clone();
    assert!(
        sys.diffuse(&b.geometry, &k, &b.transport, -1.0, &mut u)
            .is_err()
    );
    assert!(
        sys.diffuse(&b.geometry, &k[1..], &b.transport, 0.1, &mut u)
            .is_err()
    );
    u[2].x = f64::NAN;
    assert!(
        sys.diffuse(&b.geometry, &k, &b.transport, 0.1, &mut u)
            .is_err()
    );
    u[2] = before[2];
    assert_eq!(u, before);
}

// ---------------------------------------------------------------------------------------
// the restriction to a set of vertices (ops::restrict): Neumann diagonal, block expansion

/// `y = A x` for the symmetric matrix whose lower triangle `values` is on `p`.
fn lower_matvec(p: &impl LowerCsc, values: &[f64], x: &[f64]) -> Vec<f64> {
    let (cp, ri) = (p.col_ptr(), p.row_idx());
    let mut y = vec![0.0; p.n()];
    for j in 0..p.n() {
        for s in cp[j] as usize..cp[j + 1] as usize {
            let i = ri[s] as usize;
            y[i] += values[s] * x[j];
            if i != j {
                y[j] += values[s] * x[i];
            }
        }
    }
    y
}

#[test]
fn restriction_to_every_vertex_is_the_whole_operator() {
    let (t, p) = Grid::new(10, 1.0).jitter(0.5).build();
    let b = build(&t, &p);
    let sp = VertexPattern::new(&t);
    let bp = BochnerPattern::new(&sp);
    let k = cotan_stiffness(&t, &b.geometry, &sp, 0.3);
    let area = &b.geometry.vertex_area;
    let r = Restriction::new(&sp, vec![true; t.n_vertices()]);
    assert_eq!(r.scalar().col_ptr(), sp.col_ptr());
    assert_eq!(r.scalar().row_idx(), sp.row_idx());
    assert_eq!(r.bochner().col_ptr(), bp.col_ptr());
    assert_eq!(r.bochner().row_idx(), bp.row_idx());
    // M + K: the off-diagonals are K's; the diagonals A_i + K_ii to rounding (the
    // Neumann diagonal recomputes K_ii = −Σ_j K_ij, which the whole mesh has face by face)
    let mut whole = k.clone();
    add_lumped_mass(&b.geometry, &sp, 1.0, &mut whole);
    let scalar = r.scalar_values(&sp, &k, area, false);
    for (s, (&got, &want)) in scalar.iter().zip(&whole).enumerate() {
        if sp.diag_slot().contains(&(s as u32)) {
            assert!(
                (got - want).abs() < 1e-13 * want.abs(),
                "{s}: {got} vs {want}"
            );
        } else {
            assert_eq!(got, want, "entry {s}");
        }
    }
    // the block values of the same matrix are bochner_stiffness's (+ M ⊗ I₂)
    let mut blocks = bochner_stiffness(&sp, &bp, &whole, &b.transport);
    let restricted = r.bochner_values(&scalar, &b.transport);
    assert_eq!(restricted.len(), blocks.len());
    for d in bp.diag_slot() {
        for &s in d {
            let (got, want) = (restricted[s as usize], blocks[s as usize]);
            assert!(
                (got - want).abs() < 1e-13 * want.abs(),
                "{s}: {got} vs {want}"
            );
            blocks[s as usize] = got;
        }
    }
    assert_eq!(restricted, blocks);
}

#[test]
fn restriction_is_neumann_and_keeps_only_the_inside_edges() {
    let (t, p) = Grid::new(14, 1.0).jitter(0.5).build();
    let b = build(&t, &p);
    let sp = VertexPattern::new(&t);
    let k = cotan_stiffness(&t, &b.geometry, &sp, 1.0);
    let area = &b.geometry.vertex_area;
    // a disk of vertices away from the border
    let mask: Vec<bool> = p.iter().map(|q| q.truncate().length() < 0.55).collect();
    let kept: Vec<usize> = (0..t.n_vertices()).filter(|&v| mask[v]).collect();
    assert!(kept.len() > 20 && kept.len() < t.n_vertices() / 2);
    let r = Restriction::new(&sp, mask.clone());
    assert_eq!(
        r.vertices,
        kept.iter().map(|&v| v as u32).collect::<Vec<_>>()
    );
    let inside = t
        .edges()
        .iter()
        .filter(|&&[a, b]| mask[a as usize] && mask[b as usize])
        .count();
    assert_eq!(r.scalar().nnz(), kept.len() + inside);
    for clamp in [false, true] {
        let values = r.scalar_values(&sp, &k, area, clamp);
        // no flux out: (M + K_A) 1 = the areas of the kept vertices
        let ones = lower_matvec(r.scalar(), &values, &vec![1.0; kept.len()]);
        for (j, &v) in kept.iter().enumerate() {
            assert!(
                (ones[j] - area[v]).abs() < 1e-14,
                "{v}: {} vs {}",
                ones[j],
                area[v]
            );
        }
        // every kept edge has the mesh's weight (clamped: the non-negative ones zeroed)
        let local = |v: u32| kept.iter().position(|&w| w as u32 == v).unwrap() as u32;
        let (cp, ri) = (r.scalar().col_ptr(), r.scalar().row_idx());
        for (e, &[a, bb]) in t.edges().iter().enumerate() {
            if !(mask[a as usize] && mask[bb as usize]) {
                continue;
            }
            let (ja, jb) = (local(a), local(bb));
            let s = (cp[ja as usize]..cp[ja as usize + 1])
                .find(|&s| ri[s as usize] == jb)
                .unwrap();
            let full = k[sp.edge_slot()[e] as usize];
            let want = if clamp { full.min(0.0) } else { full };
            assert_eq!(values[s as usize], want, "edge {e}");
        }
        // the block system kills a constant field on a flat mesh whatever the cut:
        // (M ⊗ I₂ + K_∇A) u = A u
        let w = DVec3::new(0.7, 1.1, 0.0);
        let u: Vec<DVec2> = kept.iter().map(|&v| b.frames.to_local(v, w)).collect();
        let blocks = r.bochner_values(&values, &b.transport);
        let y = lower_matvec(r.bochner(), &blocks, &flat(&u));
        for (j, &v) in kept.iter().enumerate() {
            let got = DVec2::new(y[2 * j], y[2 * j + 1]);
            assert!(
                (got - area[v] * u[j]).length() < 1e-13,
                "{v}: {got} vs {}",
                area[v] * u[j]
            );
        }
        // a field that is not constant is not (the check can fail)
        let u2: Vec<DVec2> = kept
            .iter()
            .map(|&v| b.frames.to_local(v, DVec3::new(p[v].y, 0.0, 0.0)))
            .collect();
        let y2 = lower_matvec(r.bochner(), &blocks, &flat(&u2));
        let off = kept
            .iter()
            .enumerate()
            .map(|(j, &v)| (DVec2::new(y2[2 * j], y2[2 * j + 1]) - area[v] * u2[j]).length())
            .fold(0.0, f64::max);
        assert!(off > 1e-3, "{off}");
    }
}
