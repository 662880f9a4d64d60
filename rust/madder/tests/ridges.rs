//! Ridges of FTLE fields (`madder::lcs::ridges`, seed §5.4, §5.5.2–§5.5.5) against
//! references computed here: the steady double gyre's separatrix, and for the periodic
//! double gyre, the quad gyre, the Bickley jet and the octuple gyre on a torus, the ridges
//! of an FTLE computed by plain RK4 and central differences on a regular grid.

mod lcs_common;

use glam::{DVec2, DVec3};
use lcs_common::*;
use madder::lcs::{FnVelocity, Motion, RidgeOptions, Ridges, ftle, ridges};
use madder::mesh::Topology;

fn planar_ftle(
    topo: &Topology,
    p: &[DVec3],
    f: fn(f64, DVec2) -> DVec2,
    t0: f64,
    span: f64,
    steps: usize,
) -> Vec<f64> {
    let mut v = FnVelocity(move |t, x: DVec3| f(t, x.truncate()).extend(0.0));
    ftle(topo, &Motion::fixed(p.to_vec()), &mut v, t0, span, steps).unwrap()
}

/// Connected components of the ridge graph and their edge counts.
fn component_sizes(r: &Ridges) -> Vec<usize> {
    let n = r.points.len();
    let mut parent: Vec<usize> = (0..n).collect();
    fn find(p: &mut [usize], mut x: usize) -> usize {
        while p[x] != x {
            p[x] = p[p[x]];
            x = p[x];
        }
        x
    }
    for &[a, b] in &r.edges {
        let (ra, rb) = (find(&mut parent, a as usize), find(&mut parent, b as usize));
        parent[ra] = rb;
    }
    let mut count = std::collections::BTreeMap::new();
    for &[a, _] in &r.edges {
        *count.entry(find(&mut parent, a as usize)).or_insert(0) += 1;
    }
    count.into_values().collect()
}

#[test]
fn steady_double_gyre_ridge_is_the_separatrix() {
    let (nx, ny) = (200, 100);
    let (topo, p) = rect_grid(nx, ny, [0.0, 2.0], [0.0, 1.0]);
    // T = −5: long enough for the separatrix to stand out, short enough that neighbours do
    // not separate by the whole domain (σ of the grid method saturates at ln(L/dx)/|T|)
    let s = planar_ftle(&topo, &p, steady_gyre, 0.0, -5.0, 50);
    let r = ridges(&topo, &p, &s, &RidgeOptions::default()).unwrap();
    let dx = 2.0 / nx as f64;
    let pts: Vec<DVec2> = r.points.iter().map(|q| q.position.truncate()).collect();
    dump("steady", nx, ny, [0.0, 2.0, 0.0, 1.0], &s, &pts);
    let sizes = component_sizes(&r);
    let interior: Vec<&DVec3> = r
        .points
        .iter()
        .map(|q| &q.position)
        .filter(|q| q.y > 0.1 && q.y < 0.9 && q.x > 0.1 && q.x < 1.9)
        .collect();
    let worst = interior.iter().map(|q| (q.x - 1.0).abs()).fold(0.0, f64::max);
    eprintln!(
        "steady gyre: {} points, {} edges, components {sizes:?}, interior points {}, max |x − 1| = {worst:.4} (dx {dx})",
        r.points.len(),
        r.edges.len(),
        interior.len()
    );
    assert!(worst < dx, "{worst}");
    // and it runs the whole height: a point in every band of 0.05 in y from 0.3 to 0.9 (below 0.3 the backward FTLE over
    // 5 time units is under the threshold σ0: the particles there have not yet reached the
    // upper hyperbolic point)
    for band in 6..18 {
        let y = band as f64 * 0.05;
        assert!(interior.iter().any(|q| q.y >= y && q.y < y + 0.05), "no ridge at y = {y}");
    }
    assert!(sizes.iter().all(|&k| k >= 20));
}
