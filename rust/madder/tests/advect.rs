//! Validation of the advection step (seed §4.3.1–4.3.2, module `stain::advect`) against
//! exact and independent results:
//!
//! - semi-Lagrangian velocity: constant fields are kept, linear fields on a flat mesh are
//!   interpolated exactly at the foot `x − h u(x)` (in the one-ring and along the strip),
//!   the trace stops on the border, and on a developable cylinder linear fields of the
//!   development (parallel fields included) are advected exactly;
//! - median-dual fluxes agree with an independent 2-D formula, close the cells of
//!   interior vertices for a constant velocity, and the upwind transport conserves mass,
//!   stays non-negative (where the seed's cotan flux does not), keeps a uniform density
//!   uniform, moves a blob's centroid at the right speed, and sub-cycles at huge steps;
//! - momentum advection keeps uniform fields uniform and conserves the world momentum;
//! - everything is bit-identical with 1 and 2 threads.

use std::collections::VecDeque;
use std::f64::consts::PI;

use glam::{DMat2, DMat3, DVec2, DVec3};
use madder::mesh::{Geometry, OneRings, Topology, VertexFrames};
use madder::stain::advect::{UpwindPlan, advect_velocity, dual_fluxes};

mod common;
use common::{Built, Grid, build, build_with};

// ---------------------------------------------------------------------------------------
// meshes and helpers

/// Grid placement `(x + shear · y, y, 0)`: a shear that makes the triangles obtuse.
fn sheared(shear: f64) -> impl Fn(f64, f64) -> DVec3 {
    move |x, y| DVec3::new(x + shear * y, y, 0.0)
}

fn xy(p: DVec3) -> DVec2 {
    DVec2::new(p.x, p.y)
}

fn to_local(b: &Built, i: usize, w: DVec2) -> DVec2 {
    b.frames.to_local(i, w.extend(0.0))
}

fn to_world(b: &Built, i: usize, u: DVec2) -> DVec2 {
    xy(b.frames.to_world(i, u))
}

/// Graph distance (in edges) of every vertex from the border.
fn border_distance(t: &Topology) -> Vec<usize> {
    let n = t.n_vertices();
    let mut adj = vec![Vec::new(); n];
    for &[a, b] in t.edges() {
        adj[a as usize].push(b as usize);
        adj[b as usize].push(a as usize);
    }
    let mut dist = vec![usize::MAX; n];
    let mut queue = VecDeque::new();
    for (v, &on) in t.boundary_vertices().iter().enumerate() {
        if on {
            dist[v] = 0;
            queue.push_back(v);
        }
    }
    while let Some(v) = queue.pop_front() {
        for &w in &adj[v] {
            if dist[w] == usize::MAX {
                dist[w] = dist[v] + 1;
                queue.push_back(w);
            }
        }
    }
    dist
}

/// Parameter in [0, 1] where the segment `x → x + d` leaves the square [−1, 1]².
fn exit_parameter(x: DVec2, d: DVec2) -> f64 {
    let mut t: f64 = 1.0;
    for (xc, dc) in [(x.x, d.x), (x.y, d.y)] {
        if dc > 0.0 {
            t = t.min((1.0 - xc) / dc);
        } else if dc < 0.0 {
            t = t.min((-1.0 - xc) / dc);
        }
    }
    t.max(0.0)
}

/// Mean edge length.
fn mean_edge(b: &Built) -> f64 {
    b.geometry.edge_length.iter().sum::<f64>() / b.geometry.edge_length.len() as f64
}

// ---------------------------------------------------------------------------------------
// semi-Lagrangian velocity

#[test]
fn constant_velocity_is_advected_unchanged() {
    let (t, p) = Grid::new(20, 1.0).jitter(0.4).build();
    let b = build(&t, &p);
    let w = DVec2::new(0.3, -0.2);
    let u: Vec<DVec2> = (0..p.len()).map(|i| to_local(&b, i, w)).collect();
    let ell = mean_edge(&b);
    // feet at 0.3, 1.5 and 4.5 mean edge lengths: one-ring, and strips of several triangles
    for reach in [0.3, 1.5, 4.5] {
        let h = reach * ell / w.length();
        let out = advect_velocity(&t, &b.rings, &b.geometry, &b.transport, &u, h);
        let err = (0..p.len())
            .map(|i| (to_world(&b, i, out[i]) - w).length())
            .fold(0.0, f64::max);
        println!("constant field, reach {reach} edges: max error {err:.2e}");
        assert!(err < 1e-12, "reach {reach}: {err}");
    }
}

/// `u(x) = A x + c`.
fn linear(x: DVec2) -> DVec2 {
    DMat2::from_cols(DVec2::new(0.3, 0.4), DVec2::new(-0.5, 0.1)) * x + DVec2::new(0.2, 0.1)
}

/// Max error of the semi-Lagrangian velocity against `linear` at its foot, stopped at the
/// border, over all vertices; and the number of vertices whose foot is inside the square.
fn linear_field_error(b: &Built, t: &Topology, p: &[DVec3], h: f64) -> (f64, usize, f64) {
    let u: Vec<DVec2> = (0..p.len())
        .map(|i| to_local(b, i, linear(xy(p[i]))))
        .collect();
    let out = advect_velocity(t, &b.rings, &b.geometry, &b.transport, &u, h);
    let (mut err, mut inside, mut reach) = (0.0f64, 0, 0.0f64);
    for i in 0..p.len() {
        let x = xy(p[i]);
        let d = -h * linear(x);
        let s = exit_parameter(x, d);
        if s == 1.0 {
            inside += 1;
            reach = reach.max(d.length());
        }
        let expected = linear(x + s * d);
        let e = (to_world(b, i, out[i]) - expected).length();
        if e > 1e-10 {
            println!(
                "  vertex {i} at {x:?}, d {d:?}, s {s}, kind {:?}: err {e:.2e}",
                b.rings.kind(i)
            );
        }
        err = err.max(e);
    }
    (err, inside, reach)
}

#[test]
fn linear_field_is_exact_in_the_one_ring_along_the_strip_and_at_the_border() {
    let (t, p) = Grid::new(16, 1.0).jitter(0.4).build();
    let n = p.len();
    // polar frames (x along the reference spoke) and frames aligned with the world axes
    let polar = build(&t, &p);
    let rings = OneRings::new(&t);
    let aligned = build_with(
        &t,
        &p,
        rings,
        VertexFrames {
            frame: vec![DMat3::IDENTITY; n],
        },
    );
    let ell = mean_edge(&polar);
    for (name, b) in [("polar frames", &polar), ("world frames", &aligned)] {
        // |u| ≤ 1.2 on the square: reach up to 0.25, 2 and 6 edge lengths
        for reach in [0.25, 2.0, 6.0] {
            let h = reach * ell / 1.2;
            let (err, inside, longest) = linear_field_error(b, &t, &p, h);
            println!(
                "linear field, {name}, h = {h:.3}: max error {err:.2e} ({inside} feet inside, \
                 longest {:.2} edges)",
                longest / ell
            );
            assert!(inside > n / 4);
            assert!(err < 1e-10, "{name}, h = {h}: {err}");
        }
    }
}

#[test]
fn back_trace_leaving_the_cloth_stops_on_the_border() {
    // uniform wind towards +x: vertices within h|u| of the left border trace back past it
    let (t, p) = Grid::new(12, 1.0).jitter(0.3).build();
    let b = build(&t, &p);
    let field = |x: DVec2| DVec2::new(1.0 + 0.3 * x.y, 0.2 * x.x);
    let u: Vec<DVec2> = (0..p.len())
        .map(|i| to_local(&b, i, field(xy(p[i]))))
        .collect();
    let h = 0.5;
    let out = advect_velocity(&t, &b.rings, &b.geometry, &b.transport, &u, h);
    let (mut err, mut stopped) = (0.0f64, 0);
    for i in 0..p.len() {
        let x = xy(p[i]);
        let d = -h * field(x);
        let s = exit_parameter(x, d);
        if s < 1.0 {
            stopped += 1;
        }
        err = err.max((to_world(&b, i, out[i]) - field(x + s * d)).length());
    }
    println!("border: {stopped} traces stopped on the border, max error {err:.2e}");
    assert!(stopped > 30);
    assert!(err < 1e-10, "{err}");
}

/// Ruled half-cylinder of radius 1: `nz` rows of `nphi` quads, alternating diagonals. Also
/// returns the development coordinates `(s, z)` of every vertex (`s` along the polygonal
/// ring, in chord lengths).
fn cylinder(nphi: usize, nz: usize) -> (Topology, Vec<DVec3>, Vec<DVec2>) {
    let idx = |i: usize, j: usize| (i * (nphi + 1) + j) as u32;
    let mut faces = Vec::new();
    for i in 0..nz {
        for j in 0..nphi {
            let (a, b, c, d) = (idx(i, j), idx(i, j + 1), idx(i + 1, j + 1), idx(i + 1, j));
            if (i + j) % 2 == 0 {
                faces.extend([[a, b, c], [a, c, d]]);
            } else {
                faces.extend([[a, b, d], [b, c, d]]);
            }
        }
    }
    let dphi = PI / nphi as f64;
    let chord = 2.0 * (dphi / 2.0).sin();
    let dz = 0.1;
    let (mut pos, mut dev) = (Vec::new(), Vec::new());
    for i in 0..=nz {
        for j in 0..=nphi {
            let phi = j as f64 * dphi;
            pos.push(DVec3::new(phi.cos(), phi.sin(), i as f64 * dz));
            dev.push(DVec2::new(j as f64 * chord, i as f64 * dz));
        }
    }
    let t = Topology::from_triangles((nz + 1) * (nphi + 1), faces).unwrap();
    (t, pos, dev)
}

/// Unit direction, in `F_i`, of the development direction `+axis` at vertex `i`: the polar
/// direction of the spoke to the grid neighbour one step along `axis` (or the opposite of
/// the one behind, on the last row or column).
fn development_axis(b: &Built, dev: &[DVec2], i: usize, axis: usize) -> DVec2 {
    let spokes = b.rings.spokes(i);
    let alpha = b.transport.polar_angles(i);
    let delta = b.transport.frame_offset(i);
    for sign in [1.0, -1.0] {
        for (k, &j) in spokes.iter().enumerate() {
            let d = dev[j as usize] - dev[i];
            let (along, across) = if axis == 0 { (d.x, d.y) } else { (d.y, d.x) };
            if across.abs() < 1e-9 && along * sign > 0.0 {
                let a = alpha[k] + delta;
                return sign * DVec2::new(a.cos(), a.sin());
            }
        }
    }
    unreachable!("every grid vertex has a neighbour along each axis")
}

#[test]
fn linear_fields_of_the_development_are_exact_on_a_cylinder() {
    let (t, p, dev) = cylinder(24, 20);
    let b = build(&t, &p);
    let n = p.len();
    let basis: Vec<(DVec2, DVec2)> = (0..n)
        .map(|i| {
            (
                development_axis(&b, &dev, i, 0),
                development_axis(&b, &dev, i, 1),
            )
        })
        .collect();
    // the development axes are orthogonal in every vertex's polar map
    for (i, &(es, ez)) in basis.iter().enumerate() {
        assert!(es.dot(ez).abs() < 1e-12, "vertex {i}");
    }
    let to_frame = |i: usize, w: DVec2| basis[i].0 * w.x + basis[i].1 * w.y;
    let from_frame = |i: usize, u: DVec2| DVec2::new(u.dot(basis[i].0), u.dot(basis[i].1));
    let (smax, zmax) = (dev[n - 1].x, dev[n - 1].y);
    let inside = |x: DVec2| x.x > 1e-9 && x.x < smax - 1e-9 && x.y > 1e-9 && x.y < zmax - 1e-9;

    type Field = Box<dyn Fn(DVec2) -> DVec2>;
    let fields: [(&str, Field); 4] = [
        (
            "parallel, along the generator",
            Box::new(|_| DVec2::new(0.0, 1.0)),
        ),
        ("parallel, oblique", Box::new(|_| DVec2::new(0.8, -0.6))),
        (
            "along the generator, linear in z",
            Box::new(|x: DVec2| DVec2::new(0.0, 0.4 + 0.5 * x.y)),
        ),
        (
            "general linear",
            Box::new(|x: DVec2| {
                DVec2::new(0.3 + 0.2 * x.x - 0.1 * x.y, -0.5 + 0.15 * x.x + 0.25 * x.y)
            }),
        ),
    ];
    for (name, field) in &fields {
        let u: Vec<DVec2> = (0..n).map(|i| to_frame(i, field(dev[i]))).collect();
        for h in [0.05, 0.5, 1.0] {
            let out = advect_velocity(&t, &b.rings, &b.geometry, &b.transport, &u, h);
            let (mut err, mut count, mut reach) = (0.0f64, 0, 0.0f64);
            for i in 0..n {
                let foot = dev[i] - h * field(dev[i]);
                if !inside(foot) {
                    continue;
                }
                count += 1;
                reach = reach.max((foot - dev[i]).length());
                err = err.max((from_frame(i, out[i]) - field(foot)).length());
            }
            println!(
                "cylinder, {name}, h = {h}: max error {err:.2e} over {count} feet \
                 (longest trace {reach:.2})"
            );
            assert!(count > 40, "{name}: {count}");
            assert!(err < 1e-10, "{name}, h = {h}: {err}");
        }
    }
}

// ---------------------------------------------------------------------------------------
// median-dual fluxes and upwind transport

/// Independent 2-D median-dual flux of a constant velocity `w` across every edge: the dual
/// face of edge `a → b` runs from the centroid of the face on its right to that on its
/// left (through the edge midpoint); its area vector is that segment turned clockwise.
fn independent_fluxes(t: &Topology, p: &[DVec3], w: DVec2) -> Vec<f64> {
    let mut flux = vec![0.0; t.n_edges()];
    for (tri, fe) in t.faces().iter().zip(t.face_edges()) {
        let q = tri.map(|v| xy(p[v as usize]));
        let ccw = (q[1] - q[0]).perp_dot(q[2] - q[0]) > 0.0;
        let c = (q[0] + q[1] + q[2]) / 3.0;
        for k in 0..3 {
            let (ka, kb) = ((k + 1) % 3, (k + 2) % 3);
            let (a, b) = (tri[ka], tri[kb]);
            // this face is on the left of a → b iff the face is counter-clockwise
            let (lo, hi, left) = if a < b {
                (q[ka], q[kb], ccw)
            } else {
                (q[kb], q[ka], !ccw)
            };
            let m = 0.5 * (lo + hi);
            // left face contributes the segment m → c, right face c → m
            let seg = if left { c - m } else { m - c };
            let s = DVec2::new(seg.y, -seg.x);
            flux[fe[k] as usize] += w.dot(s);
        }
    }
    flux
}

#[test]
fn dual_fluxes_match_an_independent_formula_and_close_interior_cells() {
    for (name, shear) in [("jittered", 0.0), ("obtuse", 0.8)] {
        let (t, p) = Grid::new(14, 1.0).jitter(0.4).build_with(sheared(shear));
        let b = build(&t, &p);
        let w = DVec2::new(0.7, -0.4);
        let u: Vec<DVec2> = (0..p.len()).map(|i| to_local(&b, i, w)).collect();
        let flux = dual_fluxes(&t, &p, &b.frames, &u);
        let reference = independent_fluxes(&t, &p, w);
        let scale = w.length() * mean_edge(&b);
        let err = flux
            .iter()
            .zip(&reference)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        // net outflow of every interior vertex
        let mut net = vec![0.0; p.len()];
        for (e, &[a, c]) in t.edges().iter().enumerate() {
            net[a as usize] += flux[e];
            net[c as usize] -= flux[e];
        }
        let on_border = t.boundary_vertices();
        let closure = (0..p.len())
            .filter(|&v| !on_border[v])
            .map(|v| net[v].abs())
            .fold(0.0, f64::max);
        println!(
            "{name}: flux vs independent {:.2e}, interior net flux {:.2e} (relative to |u| ℓ)",
            err / scale,
            closure / scale
        );
        assert!(err < 1e-14 * scale, "{name}: {err}");
        assert!(closure < 1e-14 * scale, "{name}: {closure}");
    }
}

/// Rotating field `ω (−y, x)` in the frames of `b`.
fn rotating(b: &Built, p: &[DVec3]) -> Vec<DVec2> {
    (0..p.len())
        .map(|i| to_local(b, i, DVec2::new(-p[i].y, p[i].x)))
        .collect()
}

/// A Gaussian blob of mass (kg per vertex = density × area).
// Local, not `common::gaussian`: `exp(−r²/radius²)` (no factor 2) on a base level, times area.
fn blob(b: &Built, p: &[DVec3], centre: DVec2, radius: f64, base: f64) -> Vec<f64> {
    (0..p.len())
        .map(|i| {
            let r2 = (xy(p[i]) - centre).length_squared() / (radius * radius);
            (base + (-r2).exp()) * b.geometry.vertex_area[i]
        })
        .collect()
}

/// Cotan weight `½ (cot α + cot β)` of every edge.
fn cotan_weights(t: &Topology, g: &Geometry) -> Vec<f64> {
    let mut w = vec![0.0; t.n_edges()];
    for (fe, cot) in t.face_edges().iter().zip(&g.face_cot) {
        for k in 0..3 {
            w[fe[k] as usize] += 0.5 * cot[k];
        }
    }
    w
}

#[test]
fn upwind_transport_conserves_mass_and_stays_non_negative_on_obtuse_triangles() {
    let (t, p) = Grid::new(20, 1.0).jitter(0.2).build_with(sheared(0.8));
    let b = build(&t, &p);
    let weights = cotan_weights(&t, &b.geometry);
    let n_negative = weights.iter().filter(|&&w| w < 0.0).count();
    assert!(n_negative > 50, "the mesh has negative cotan weights");
    let u = rotating(&b, &p);
    let h = 0.03;
    let flux = dual_fluxes(&t, &p, &b.frames, &u);
    let plan = UpwindPlan::new(&t, &b.geometry.vertex_area, &flux, h).unwrap();
    let mut mass = blob(&b, &p, DVec2::new(0.4, 0.0), 0.2, 0.0);
    let total0: f64 = mass.iter().sum();
    let (mut drift, mut min) = (0.0f64, f64::INFINITY);
    for _ in 0..200 {
        plan.transport(&t, &mut mass);
        let total: f64 = mass.iter().sum();
        drift = drift.max((total - total0).abs() / total0);
        min = min.min(mass.iter().copied().fold(f64::INFINITY, f64::min));
    }
    println!(
        "obtuse grid ({n_negative} negative cotan weights), 200 steps, Courant {:.2}, {} \
         sub-step(s): mass drift {drift:.2e}, min mass {min:.2e}",
        plan.max_courant(),
        plan.substeps()
    );
    assert!(drift < 1e-13, "{drift}");
    assert!(min >= 0.0, "{min}");

    // the seed's Voronoi flux F_ij = σ↑ (u_ij·e_ij) w_ij goes negative on the same mesh
    let mut sigma: Vec<f64> = blob(&b, &p, DVec2::new(0.4, 0.0), 0.2, 0.0)
        .iter()
        .zip(&b.geometry.vertex_area)
        .map(|(m, a)| m / a)
        .collect();
    let area = &b.geometry.vertex_area;
    let mut seed_min = f64::INFINITY;
    for _ in 0..200 {
        let mut next = sigma.clone();
        for (e, &[i, j]) in t.edges().iter().enumerate() {
            let (i, j) = (i as usize, j as usize);
            let uij = 0.5 * (b.frames.to_world(i, u[i]) + b.frames.to_world(j, u[j]));
            let along = uij.dot(p[j] - p[i]);
            let up = if along > 0.0 { sigma[i] } else { sigma[j] };
            let f = up * along * weights[e];
            next[i] -= h * f / area[i];
            next[j] += h * f / area[j];
        }
        sigma = next;
        seed_min = seed_min.min(sigma.iter().copied().fold(f64::INFINITY, f64::min));
    }
    println!("the seed's cotan flux on the same run: min density {seed_min:.2e}");
    assert!(seed_min < 0.0);
}

#[test]
fn uniform_density_under_a_constant_velocity_stays_uniform_inside() {
    let (t, p) = Grid::new(30, 1.0).jitter(0.4).build();
    let b = build(&t, &p);
    let w = DVec2::new(0.6, 0.35);
    let u: Vec<DVec2> = (0..p.len()).map(|i| to_local(&b, i, w)).collect();
    let flux = dual_fluxes(&t, &p, &b.frames, &u);
    let plan = UpwindPlan::new(&t, &b.geometry.vertex_area, &flux, 0.02).unwrap();
    let area = &b.geometry.vertex_area;
    let mut mass = area.clone();
    let steps = 4;
    for _ in 0..steps {
        plan.transport(&t, &mut mass);
    }
    let dist = border_distance(&t);
    let (mut err, mut count) = (0.0f64, 0);
    for v in 0..p.len() {
        if dist[v] > steps * plan.substeps() {
            count += 1;
            err = err.max((mass[v] / area[v] - 1.0).abs());
        }
    }
    println!(
        "uniform density, {steps} steps (Courant {:.2}): max deviation {err:.2e} over {count} \
         interior vertices",
        plan.max_courant()
    );
    assert!(count > 100);
    assert!(err < 1e-13, "{err}");
}

#[test]
fn blob_centroid_moves_with_the_velocity() {
    let (t, p) = Grid::new(40, 1.0).jitter(0.4).build();
    let b = build(&t, &p);
    let w = DVec2::new(0.5, 0.2);
    let u: Vec<DVec2> = (0..p.len()).map(|i| to_local(&b, i, w)).collect();
    let flux = dual_fluxes(&t, &p, &b.frames, &u);
    let (h, steps) = (0.01, 80);
    let plan = UpwindPlan::new(&t, &b.geometry.vertex_area, &flux, h).unwrap();
    let mut mass = blob(&b, &p, DVec2::new(-0.3, -0.1), 0.12, 0.0);
    let before = common::centroid(&mass, &p).truncate();
    for _ in 0..steps {
        plan.transport(&t, &mut mass);
    }
    let moved = common::centroid(&mass, &p).truncate() - before;
    let expected = w * h * steps as f64;
    let rel = (moved - expected).length() / expected.length();
    println!("blob centroid moved {moved:?}, expected {expected:?}: relative error {rel:.2e}");
    assert!(rel < 0.03, "{rel}");
}

#[test]
fn huge_steps_sub_cycle_and_limit_keeping_masses_non_negative() {
    let (t, p) = Grid::new(16, 1.0).jitter(0.4).build_with(sheared(0.5));
    let b = build(&t, &p);
    let u = rotating(&b, &p);
    let flux = dual_fluxes(&t, &p, &b.frames, &u);
    let area = &b.geometry.vertex_area;
    for h in [0.3, 5.0, 200.0] {
        let plan = UpwindPlan::new(&t, area, &flux, h).unwrap();
        let expected = ((plan.max_courant() / 0.9).ceil() as usize).clamp(1, 64);
        assert_eq!(plan.substeps(), expected);
        let mut mass = blob(&b, &p, DVec2::new(0.3, 0.2), 0.25, 0.01);
        let total0: f64 = mass.iter().sum();
        let mut min = f64::INFINITY;
        for _ in 0..20 {
            plan.transport(&t, &mut mass);
            min = min.min(mass.iter().copied().fold(f64::INFINITY, f64::min));
        }
        let drift = (mass.iter().sum::<f64>() - total0).abs() / total0;
        println!(
            "h = {h}: Courant {:.1}, {} sub-steps, {} limited vertices; min mass {min:.2e}, \
             drift {drift:.2e}",
            plan.max_courant(),
            plan.substeps(),
            plan.n_limited()
        );
        assert!(min >= 0.0);
        assert!(drift < 1e-13, "{drift}");
        if h >= 5.0 {
            assert!(plan.substeps() > 1);
        }
        if h >= 200.0 {
            assert_eq!(plan.substeps(), 64);
            assert!(plan.n_limited() > 0);
        }
    }
}

#[test]
fn solute_moves_with_the_solvent() {
    let (t, p) = Grid::new(16, 1.0).jitter(0.4).build_with(sheared(0.8));
    let b = build(&t, &p);
    let u = rotating(&b, &p);
    let flux = dual_fluxes(&t, &p, &b.frames, &u);
    let plan = UpwindPlan::new(&t, &b.geometry.vertex_area, &flux, 0.2).unwrap();
    let mut solvent = blob(&b, &p, DVec2::new(0.3, 0.0), 0.3, 0.0);
    let mut solute: Vec<f64> = solvent.iter().map(|m| 0.25 * m).collect();
    let mut alone = solvent.clone();
    for _ in 0..20 {
        plan.transport_all(&t, &mut [&mut solvent, &mut solute]);
        plan.transport(&t, &mut alone);
    }
    assert_eq!(
        solvent, alone,
        "transport_all moves each field as transport does"
    );
    let err = solvent
        .iter()
        .zip(&solute)
        .filter(|(m, _)| **m > 1e-200)
        .map(|(m, s)| (s / m - 0.25).abs())
        .fold(0.0, f64::max);
    println!("solute/solvent concentration stays 0.25 to {err:.2e}");
    assert!(err < 1e-14, "{err}");
}

// ---------------------------------------------------------------------------------------
// momentum advection

#[test]
fn momentum_advection_keeps_uniform_fields_and_conserves_momentum() {
    let (t, p) = Grid::new(18, 1.0).jitter(0.4).build();
    let b = build(&t, &p);
    let area = &b.geometry.vertex_area;
    let world_momentum = |mass: &[f64], u: &[DVec2]| {
        (0..p.len()).fold(DVec2::ZERO, |acc, i| acc + mass[i] * to_world(&b, i, u[i]))
    };

    // uniform velocity and density
    let w = DVec2::new(-0.4, 0.7);
    let u: Vec<DVec2> = (0..p.len()).map(|i| to_local(&b, i, w)).collect();
    let flux = dual_fluxes(&t, &p, &b.frames, &u);
    let plan = UpwindPlan::new(&t, area, &flux, 0.1).unwrap();
    let before = area.clone();
    let fallback = vec![DVec2::splat(f64::NAN); p.len()];
    let out = plan.momentum_velocity(&t, &b.transport, &before, &u, &fallback);
    let mut after = before.clone();
    plan.transport(&t, &mut after);
    let err_u = (0..p.len())
        .map(|i| (to_world(&b, i, out[i]) - w).length())
        .fold(0.0, f64::max);
    let dist = border_distance(&t);
    let err_sigma = (0..p.len())
        .filter(|&v| dist[v] > plan.substeps())
        .map(|v| (after[v] / area[v] - 1.0).abs())
        .fold(0.0, f64::max);
    println!("momentum, uniform: velocity error {err_u:.2e}, interior density {err_sigma:.2e}");
    assert!(err_u < 1e-13, "{err_u}");
    assert!(err_sigma < 1e-13, "{err_sigma}");

    // rotating velocity and a blob: world momentum conserved over several steps
    let mut u = rotating(&b, &p);
    let mut mass = blob(&b, &p, DVec2::new(0.2, -0.1), 0.3, 0.05);
    let m0 = world_momentum(&mass, &u);
    let (mut drift, mut substeps) = (0.0f64, 0);
    for _ in 0..10 {
        let flux = dual_fluxes(&t, &p, &b.frames, &u);
        let plan = UpwindPlan::new(&t, area, &flux, 0.15).unwrap();
        substeps = substeps.max(plan.substeps());
        let next = plan.momentum_velocity(&t, &b.transport, &mass, &u, &fallback);
        plan.transport(&t, &mut mass);
        u = next;
        assert!(u.iter().all(|v| v.is_finite()), "no fallback was needed");
        drift = drift.max((world_momentum(&mass, &u) - m0).length() / m0.length());
    }
    println!(
        "momentum, rotating blob, 10 steps (up to {substeps} sub-steps): world momentum drift \
         {drift:.2e}"
    );
    assert!(substeps > 1, "the steps sub-cycle");
    assert!(drift < 1e-13, "{drift}");
}

#[test]
fn dry_vertices_take_the_fallback_velocity() {
    let (t, p) = Grid::new(10, 1.0).jitter(0.3).build();
    let b = build(&t, &p);
    let u = rotating(&b, &p);
    let flux = dual_fluxes(&t, &p, &b.frames, &u);
    let plan = UpwindPlan::new(&t, &b.geometry.vertex_area, &flux, 0.05).unwrap();
    let mut mass = vec![0.0; p.len()];
    let wet = p.len() / 2 + 3;
    mass[wet] = 1e-3;
    let fallback: Vec<DVec2> = (0..p.len()).map(|i| DVec2::new(i as f64, -1.0)).collect();
    let out = plan.momentum_velocity(&t, &b.transport, &mass, &u, &fallback);
    let mut after = mass.clone();
    plan.transport(&t, &mut after);
    for i in 0..p.len() {
        if after[i] == 0.0 {
            assert_eq!(out[i], fallback[i]);
        } else {
            // a single donor: its velocity, turned into the receiver's frame
            let expected = b.transport.transport(i, wet, u[wet]).unwrap();
            assert!((out[i] - expected).length() < 1e-12, "vertex {i}");
        }
    }
}

// ---------------------------------------------------------------------------------------
// determinism

#[test]
fn results_are_bit_identical_with_one_and_two_threads() {
    let (t, p) = Grid::new(40, 1.0).jitter(0.4).build_with(sheared(0.6));
    let b = build(&t, &p);
    let u = rotating(&b, &p);
    let run = || {
        let adv = advect_velocity(&t, &b.rings, &b.geometry, &b.transport, &u, 0.2);
        let flux = dual_fluxes(&t, &p, &b.frames, &u);
        let plan = UpwindPlan::new(&t, &b.geometry.vertex_area, &flux, 0.5).unwrap();
        let before = blob(&b, &p, DVec2::new(0.1, 0.2), 0.3, 0.01);
        let mut mass = before.clone();
        plan.transport(&t, &mut mass);
        let mom = plan.momentum_velocity(&t, &b.transport, &before, &u, &adv);
        let mut bits: Vec<u64> = Vec::new();
        bits.extend(adv.iter().flat_map(|v| [v.x.to_bits(), v.y.to_bits()]));
        bits.extend(flux.iter().map(|x| x.to_bits()));
        bits.extend(mass.iter().map(|x| x.to_bits()));
        bits.extend(mom.iter().flat_map(|v| [v.x.to_bits(), v.y.to_bits()]));
        (bits, plan.substeps())
    };
    let pool = |k: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(k)
            .build()
            .unwrap()
    };
    let (one, s1) = pool(1).install(run);
    let (two, s2) = pool(2).install(run);
    assert!(s1 > 1, "the run sub-cycles");
    assert_eq!(s1, s2);
    assert!(one == two, "results differ between 1 and 2 threads");
}
