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

use glam::{DVec2, DVec3};
use rayon::prelude::*;

use super::buckets::Planar;
use super::charts::Charts;
use super::located::Located;
use super::velocity::{Velocity, eval_checked};
use crate::error::LcsError;
use crate::lcs::rk::{Moves, two};

/// Particles per parallel task, at least.
const MIN_LEN: usize = 512;

impl Planar {
    /// The plane point of `l`.
    fn point(&self, charts: &Charts, l: &Located) -> DVec2 {
        let t = charts.face_verts(l.face as usize);
        l.bary.x * self.xy[t[0] as usize]
            + l.bary.y * self.xy[t[1] as usize]
            + l.bary.z * self.xy[t[2] as usize]
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
