//! The flow map on a flat, fixed mesh without walking (§5.5.1, a fast path of
//! [`super::trace`]).
//!
//! ## Why a flat mesh needs no walk
//! When every vertex lies in one plane and every face has the same orientation in it
//! (positive area in the plane's coordinates `(U, W)`, `U × W = n`, and the two faces of
//! every interior edge on opposite sides of it), every unfolding of [`super::trace`] is the
//! identity of the plane: the charts of all faces are pieces of one chart, the plane. A walk
//! from `a` by `d` then ends at `a + d` unless the segment meets a border edge, and the
//! chart velocity of every face is the same projection `(U·w, W·w)` of the 3-D velocity.
//! The Runge–Kutta scheme then runs in the plane's coordinates, with no triangle to find
//! per stage; the only question is whether a segment `a → b` reaches a border (any
//! segment: RK8's moves between stage points have no fixed length or direction, and each
//! is tested as RK4's are).
//!
//! ## Proving a segment stays inside
//! A grid of square buckets (side `s`, about one mean edge length) over the bounding box
//! lists the faces whose bounding box meets each bucket. A bucket is *bad* if a border edge
//! (one face, or more than two) meets its box, or if a test point in it is not covered by
//! exactly one face. The number of faces covering a point (all positively oriented) changes
//! only across border edges, so a square block of good buckets is covered exactly once and
//! contains no border. With `d` the Chebyshev distance (in buckets) of a point's bucket to
//! the nearest bad bucket (outside the grid counts as bad), every point within
//! `c = (d − 1) s` (max-norm) of the point lies in that block; `c` is the point's
//! *clearance*. A segment `a → b` with `|b − a|_∞ < c_a + c_b` is covered by the two
//! blocks (the part within `c_a` of `a` and the part within `c_b` of `b` overlap), so a
//! walk along it crosses only interior edges and ends at `b` exactly (up to rounding).
//! Longer segments are bisected a few times (each half tested the same way); a segment
//! that still fails (it passes within about a bucket of the border) is walked by
//! [`Charts::walk`] from its start, which stops at the border as in the general path. The
//! results are those of the general path up to rounding (`tests/ftle.rs` compares both,
//! on a grid with a hole and a flow that pushes particles against its border).
//!
//! Particles that are not walked are located (to give the final `(triangle, barycentric)`
//! and, if the velocity asks for it, each stage's) by testing the faces of their bucket.

use glam::{DMat2, DVec2, DVec3};
use rayon::prelude::*;

use super::rk::{Moves, two};
use super::trace::{Charts, Located, Velocity, clamp, eval_checked};
use crate::error::LcsError;
use crate::mesh::Topology;

/// Vertices farther from the plane than this fraction of the mesh's size: not flat.
const FLAT_TOLERANCE: f64 = 1e-12;

/// Particles per parallel task, at least.
const MIN_LEN: usize = 512;

/// Halvings of a segment before it is walked.
const BISECTIONS: u32 = 5;

/// A flat mesh's plane, its faces in the plane's coordinates, and the bucket grid.
#[derive(Debug, Clone)]
pub(crate) struct Planar {
    origin: DVec3,
    u: DVec3,
    w: DVec3,
    /// The vertices in the plane's coordinates.
    xy: Vec<DVec2>,
    /// Per face: corner 0 and the inverse of `[x_1 − x_0, x_2 − x_0]` (barycentric 1, 2).
    affine: Vec<(DVec2, DMat2)>,
    lo: DVec2,
    size: f64,
    inv_size: f64,
    nx: usize,
    ny: usize,
    /// Faces per bucket (CSR: `bucket_faces[start[b]..start[b + 1]]`).
    start: Vec<u32>,
    bucket_faces: Vec<u32>,
    /// Per bucket: the clearance `(d − 1) s` (module doc), 0 for bad buckets.
    clear: Vec<f64>,
}

impl Planar {
    /// The flat structure of the mesh (`None` if it is not flat, has a degenerate face or
    /// faces of both orientations, or two faces on the same side of an edge).
    pub(crate) fn new(topology: &Topology, positions: &[DVec3]) -> Option<Self> {
        let faces = topology.faces();
        let area: DVec3 = faces
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|v| positions[v as usize]);
                (b - a).cross(c - a)
            })
            .sum();
        let n = area.try_normalize()?;
        let origin = positions[faces[0][0] as usize];
        let (lo3, hi3) = positions
            .iter()
            .fold((DVec3::INFINITY, DVec3::NEG_INFINITY), |(l, h), &p| {
                (l.min(p), h.max(p))
            });
        let diameter = (hi3 - lo3).length();
        if positions
            .iter()
            .any(|&p| (p - origin).dot(n).abs() > FLAT_TOLERANCE * diameter)
        {
            return None;
        }
        let u = n.any_orthonormal_vector();
        let w = n.cross(u);
        let xy: Vec<DVec2> = positions
            .par_iter()
            .map(|&p| DVec2::new((p - origin).dot(u), (p - origin).dot(w)))
            .collect();
        // per face (in parallel): its affine map and edge lengths; `None` for a face of
        // non-positive area
        let per_face: Vec<Option<((DVec2, DMat2), f64)>> = faces
            .par_iter()
            .map(|t| {
                let [a, b, c] = t.map(|v| xy[v as usize]);
                let m = DMat2::from_cols(b - a, c - a);
                let (l1, l2) = ((b - a).length(), (c - a).length());
                // positive area, and not degenerate (the charts' own test)
                (m.determinant() > 1e-14 * l1 * l2)
                    .then(|| ((a, m.inverse()), l1 + l2 + (c - b).length()))
            })
            .collect();
        let mut affine = Vec::with_capacity(faces.len());
        // summed in face order, as before: the bucket size does not depend on the threads
        let mut edge_sum = 0.0;
        for f in per_face {
            let (map, edges) = f?;
            edge_sum += edges;
            affine.push(map);
        }
        // border edges (one face or more than two) and interior edges with both faces on
        // one side (the same direction in both)
        // per edge: its first two (face, local edge) and its number of faces
        let mut edge_faces = vec![[(0u32, 0u8); 2]; topology.n_edges()];
        let mut edge_count = vec![0u8; topology.n_edges()];
        for (f, fe) in topology.face_edges().iter().enumerate() {
            for (k, &e) in fe.iter().enumerate() {
                let c = &mut edge_count[e as usize];
                if *c < 2 {
                    edge_faces[e as usize][*c as usize] = (f as u32, k as u8);
                }
                *c = c.saturating_add(1);
            }
        }
        let ends = |(f, k): (u32, u8)| {
            let t = faces[f as usize];
            (t[(k as usize + 1) % 3], t[(k as usize + 2) % 3])
        };
        let mut border = Vec::new();
        for (e, (ef, &count)) in edge_faces.iter().zip(&edge_count).enumerate() {
            if count == 2 {
                if ends(ef[0]) != (ends(ef[1]).1, ends(ef[1]).0) {
                    return None;
                }
            } else {
                border.push(topology.edges()[e]);
            }
        }
        let (lo, hi) = xy
            .iter()
            .fold((DVec2::INFINITY, DVec2::NEG_INFINITY), |(l, h), &p| {
                (l.min(p), h.max(p))
            });
        let extent = hi - lo;
        let mean_edge = edge_sum / (3 * faces.len()) as f64;
        // about one edge per bucket, at most ~4 buckets per face
        let size = mean_edge
            .max((extent.x * extent.y / (4.0 * faces.len() as f64)).sqrt())
            .max(1e-300);
        let nx = (extent.x / size).floor() as usize + 1;
        let ny = (extent.y / size).floor() as usize + 1;
        let mut planar = Self {
            origin,
            u,
            w,
            xy,
            affine,
            lo,
            size,
            inv_size: 1.0 / size,
            nx,
            ny,
            start: Vec::new(),
            bucket_faces: Vec::new(),
            clear: Vec::new(),
        };
        planar.fill_buckets(faces);
        planar.clearances(&border);
        Some(planar)
    }

    /// The buckets `[i0, i1] × [j0, j1]` that the box `[a, b]` meets.
    fn bucket_range(&self, a: DVec2, b: DVec2) -> (usize, usize, usize, usize) {
        let cell = |p: DVec2, pad: f64| {
            let c = (p - self.lo) / self.size + DVec2::splat(pad);
            (
                (c.x.floor().max(0.0) as usize).min(self.nx - 1),
                (c.y.floor().max(0.0) as usize).min(self.ny - 1),
            )
        };
        let (i0, j0) = cell(a.min(b), -1e-9);
        let (i1, j1) = cell(a.max(b), 1e-9);
        (i0, i1, j0, j1)
    }

    fn fill_buckets(&mut self, faces: &[[u32; 3]]) {
        let n_buckets = self.nx * self.ny;
        let ranges: Vec<_> = faces
            .par_iter()
            .map(|t| {
                let [a, b, c] = t.map(|v| self.xy[v as usize]);
                self.bucket_range(a.min(b).min(c), a.max(b).max(c))
            })
            .collect();
        let mut count = vec![0u32; n_buckets + 1];
        for &(i0, i1, j0, j1) in &ranges {
            for j in j0..=j1 {
                for i in i0..=i1 {
                    count[j * self.nx + i + 1] += 1;
                }
            }
        }
        for b in 0..n_buckets {
            count[b + 1] += count[b];
        }
        let mut fill = count.clone();
        let mut list = vec![0u32; count[n_buckets] as usize];
        for (f, &(i0, i1, j0, j1)) in ranges.iter().enumerate() {
            for j in j0..=j1 {
                for i in i0..=i1 {
                    let b = j * self.nx + i;
                    list[fill[b] as usize] = f as u32;
                    fill[b] += 1;
                }
            }
        }
        self.start = count;
        self.bucket_faces = list;
    }

    /// Bad buckets (border edges, or a test point not covered exactly once), then the
    /// Chebyshev distance transform (two passes) into clearances.
    fn clearances(&mut self, border: &[[u32; 2]]) {
        let (nx, ny) = (self.nx, self.ny);
        let mut bad = vec![false; nx * ny];
        for e in border {
            let (a, b) = (self.xy[e[0] as usize], self.xy[e[1] as usize]);
            let (i0, i1, j0, j1) = self.bucket_range(a, b);
            for j in j0..=j1 {
                for i in i0..=i1 {
                    bad[j * nx + i] = true;
                }
            }
        }
        let this = &*self;
        bad.par_chunks_mut(nx).enumerate().for_each(|(j, row)| {
            for (i, bad) in row.iter_mut().enumerate() {
                if *bad {
                    continue;
                }
                // an irrational-ish point of the bucket, unlikely to lie on an edge
                let p = this.lo + this.size * DVec2::new(i as f64 + 0.381966, j as f64 + 0.618034);
                let covering = this
                    .faces_in(j * nx + i)
                    .iter()
                    .filter(|&&f| this.bary(f as usize, p).min_element() > 1e-9)
                    .count();
                *bad = covering != 1;
            }
        });
        let big = (nx + ny) as u32;
        let mut d: Vec<u32> = bad.iter().map(|&x| if x { 0 } else { big }).collect();
        let at = |d: &[u32], i: isize, j: isize| -> u32 {
            if i < 0 || j < 0 || i >= nx as isize || j >= ny as isize {
                0
            } else {
                d[j as usize * nx + i as usize]
            }
        };
        for j in 0..ny as isize {
            for i in 0..nx as isize {
                let m = [(-1, -1), (0, -1), (1, -1), (-1, 0)]
                    .iter()
                    .map(|&(di, dj)| at(&d, i + di, j + dj) + 1)
                    .min()
                    .unwrap_or(big);
                let b = j as usize * nx + i as usize;
                d[b] = d[b].min(m);
            }
        }
        for j in (0..ny as isize).rev() {
            for i in (0..nx as isize).rev() {
                let m = [(1, 1), (0, 1), (-1, 1), (1, 0)]
                    .iter()
                    .map(|&(di, dj)| at(&d, i + di, j + dj) + 1)
                    .min()
                    .unwrap_or(big);
                let b = j as usize * nx + i as usize;
                d[b] = d[b].min(m);
            }
        }
        self.clear = d
            .iter()
            .map(|&d| d.saturating_sub(1) as f64 * self.size)
            .collect();
    }

    fn faces_in(&self, b: usize) -> &[u32] {
        &self.bucket_faces[self.start[b] as usize..self.start[b + 1] as usize]
    }

    /// The bucket of `p` (`None` outside the grid).
    fn bucket(&self, p: DVec2) -> Option<usize> {
        let c = (p - self.lo) * self.inv_size;
        (c.x >= 0.0 && c.y >= 0.0 && c.x < self.nx as f64 && c.y < self.ny as f64)
            .then(|| c.y as usize * self.nx + c.x as usize)
    }

    /// The clearance of `p` (module doc; 0 outside the grid).
    fn clearance(&self, p: DVec2) -> f64 {
        self.bucket(p).map_or(0.0, |b| self.clear[b])
    }

    /// Whether the segment `a → b` provably crosses no border (module doc).
    fn segment_clear(&self, a: DVec2, b: DVec2, ca: f64, cb: f64, depth: u32) -> bool {
        if (b - a).abs().max_element() < ca + cb {
            return true;
        }
        if depth == 0 || (ca == 0.0 && cb == 0.0) {
            return false;
        }
        let m = 0.5 * (a + b);
        let cm = self.clearance(m);
        cm > 0.0
            && self.segment_clear(a, m, ca, cm, depth - 1)
            && self.segment_clear(m, b, cm, cb, depth - 1)
    }

    /// Barycentric coordinates of plane point `p` in face `f`.
    fn bary(&self, f: usize, p: DVec2) -> DVec3 {
        let (a, inv) = self.affine[f];
        let b = inv * (p - a);
        DVec3::new(1.0 - b.x - b.y, b.x, b.y)
    }

    /// The face of `p` among its bucket's (the one it is deepest inside; `None` if `p` is
    /// outside the grid or its bucket has no face).
    fn locate(&self, p: DVec2) -> Option<Located> {
        let b = self.bucket(p)?;
        let (mut best, mut depth) = (None, f64::NEG_INFINITY);
        for &f in self.faces_in(b) {
            let bq = self.bary(f as usize, p);
            if bq.min_element() > depth {
                depth = bq.min_element();
                best = Some(Located { face: f, bary: bq });
            }
        }
        best.map(|l| Located {
            face: l.face,
            bary: clamp(l.bary),
        })
    }

    /// The plane point of `l`.
    fn point(&self, charts: &Charts, l: &Located) -> DVec2 {
        let t = charts.face_verts(l.face as usize);
        l.bary.x * self.xy[t[0] as usize]
            + l.bary.y * self.xy[t[1] as usize]
            + l.bary.z * self.xy[t[2] as usize]
    }

    /// The world point of plane point `p`.
    fn world(&self, p: DVec2) -> DVec3 {
        self.origin + p.x * self.u + p.y * self.w
    }

    /// Whether the straight segment `a → b` provably stays inside (module doc).
    fn straight(&self, a: DVec2, b: DVec2) -> bool {
        self.segment_clear(a, b, self.clearance(a), self.clearance(b), BISECTIONS)
    }
}

/// A walk from `l` (at plane point `a`) to plane point `b` by [`Charts::walk`]; returns
/// where it ends, located and in the plane.
fn walk_plane(
    charts: &Charts,
    planar: &Planar,
    l: &Located,
    a: DVec2,
    b: DVec2,
) -> (Located, DVec2) {
    let t = charts.face_verts(l.face as usize);
    // the face's chart axes in the plane: corner 1 on +x, the normal's turn gives +y
    let g1 = (planar.xy[t[1] as usize] - planar.xy[t[0] as usize]).normalize();
    let local = DVec2::new(g1.dot(b - a), g1.perp().dot(b - a));
    let (end, _) = charts.walk(l, local);
    (end, planar.point(charts, &end))
}

/// The next point of a particle: from `a` (located `a_at` if known) to `b`, straight if
/// provably inside, else walked (stopping at a border). `anchor` is the last point where
/// the particle was located, from which a point the buckets cannot place is walked to.
fn advance(
    charts: &Charts,
    planar: &Planar,
    (a, a_at): (DVec2, Option<Located>),
    b: DVec2,
    (anchor, anchor_p): &(Located, DVec2),
) -> (DVec2, Option<Located>) {
    if planar.straight(a, b) {
        return (b, None);
    }
    let from = a_at
        .or_else(|| planar.locate(a))
        .unwrap_or_else(|| walk_plane(charts, planar, anchor, *anchor_p, a).0);
    let (end, e) = walk_plane(charts, planar, &from, a, b);
    (e, Some(end))
}

/// [`super::flow_map`] on a flat fixed mesh (module doc); the same arguments and errors.
pub(crate) fn flow_map_planar(
    charts: &Charts,
    planar: &Planar,
    velocity: &mut dyn Velocity,
    t0: f64,
    span: f64,
    moves: &Moves,
    steps: usize,
) -> Result<Vec<Option<Located>>, LcsError> {
    let n = planar.xy.len();
    let live: Vec<usize> = (0..n).filter(|&v| charts.at_vertex(v).is_some()).collect();
    let mut p: Vec<DVec2> = live.iter().map(|&v| planar.xy[v]).collect();
    // each particle's start of step, located if a walk ended there; and the last point
    // where it was located, from which a point the buckets cannot place (not expected:
    // rounding at a bucket's edge) is reached by a walk
    let mut anchor: Vec<(Located, DVec2)> = live
        .iter()
        .filter_map(|&v| Some((charts.at_vertex(v)?, planar.xy[v])))
        .collect();
    let mut p_at: Vec<Option<Located>> = anchor.iter().map(|a| Some(a.0)).collect();
    let m = p.len();
    let h = span / steps.max(1) as f64;
    let with_at = velocity.uses_location();
    // per particle and slot ([`Moves::slot`]): a stage point, located if a walk ended there
    let slots = moves.slots();
    let mut slot_q = vec![vec![DVec2::ZERO; m]; slots];
    let mut slot_at: Vec<Vec<Option<Located>>> = vec![vec![None; m]; slots];
    let mut stage_at: Vec<Located> = Vec::new();
    let mut points = vec![DVec3::ZERO; m];
    let mut w = vec![DVec3::ZERO; m];
    let stages = moves.stages();
    let mut k: Vec<Vec<DVec2>> = vec![vec![DVec2::ZERO; m]; stages];
    for step in 0..steps.max(1) {
        for stage in 0..stages {
            let ts = moves.time(stage, t0, step, h);
            let k_ref = &k;
            let (p_ref, p_at_ref, anchor_ref) = (&p, &p_at, &anchor);
            let dst = moves.slot(stage);
            if stage == 0 {
                (&mut slot_q[dst], &mut slot_at[dst], &mut points)
                    .into_par_iter()
                    .with_min_len(MIN_LEN)
                    .enumerate()
                    .for_each(|(i, (qi, qa, x))| {
                        (*qi, *qa) = (p_ref[i], p_at_ref[i]);
                        *x = planar.world(*qi);
                    });
            } else {
                // each stage point walked on from the earlier one nearest in time, by the
                // same displacements as trace.rs (the same points when no walk stopped at
                // a border)
                let src = moves.slot(moves.source(stage));
                let (from_q, to_q) = two(&mut slot_q, src, dst);
                let (from_at, to_at) = two(&mut slot_at, src, dst);
                (to_q, to_at, &mut points[..], from_q, from_at)
                    .into_par_iter()
                    .with_min_len(MIN_LEN)
                    .enumerate()
                    .for_each(|(i, (qi, qa, x, &q0, &a0))| {
                        let target = q0 + moves.to(stage, h, k_ref, i);
                        (*qi, *qa) = advance(charts, planar, (q0, a0), target, &anchor_ref[i]);
                        *x = planar.world(*qi);
                    });
            }
            if with_at {
                stage_at = (&slot_q[dst], &slot_at[dst], &anchor)
                    .into_par_iter()
                    .with_min_len(MIN_LEN)
                    .map(|(&x, &xa, (a, ap))| {
                        xa.or_else(|| planar.locate(x))
                            .unwrap_or_else(|| walk_plane(charts, planar, a, *ap, x).0)
                    })
                    .collect();
            }
            eval_checked(velocity, ts, &stage_at, &points, &live, &mut w)?;
            k[stage]
                .par_iter_mut()
                .zip(&w)
                .for_each(|(ki, wi)| *ki = DVec2::new(planar.u.dot(*wi), planar.w.dot(*wi)));
        }
        let k_ref = &k;
        let src = moves.slot(moves.source(stages));
        (&mut p, &mut p_at, &mut anchor, &slot_q[src], &slot_at[src])
            .into_par_iter()
            .with_min_len(MIN_LEN)
            .enumerate()
            .for_each(|(i, (pi, pa, an, &a, &a_at))| {
                let target = a + moves.to(stages, h, k_ref, i);
                (*pi, *pa) = advance(charts, planar, (a, a_at), target, an);
                if let Some(l) = *pa {
                    *an = (l, *pi);
                }
            });
    }
    let ends: Vec<Located> = (&p, &p_at, &anchor)
        .into_par_iter()
        .map(|(&x, &xa, (a, ap))| {
            xa.or_else(|| planar.locate(x))
                .unwrap_or_else(|| walk_plane(charts, planar, a, *ap, x).0)
        })
        .collect();
    let mut out = vec![None; n];
    for (i, &v) in live.iter().enumerate() {
        out[v] = Some(ends[i]);
    }
    Ok(out)
}
