//! The flow-map driver: every vertex's particle stepped by the Runge–Kutta scheme, each
//! stage evaluated for all particles at once and walked in parallel ([`flow_map_with`]).

use glam::{DMat2, DVec2, DVec3};
use rayon::prelude::*;

use super::charts::{Charts, Corners, Orth, bary_step};
use super::located::Located;
use super::planar::flow_map_planar;
use super::time::Motion;
use super::velocity::{Velocity, eval_checked};
use crate::error::LcsError;
use crate::lcs::rk::{Moves, Scheme, two};

/// The particles are reordered by face every this many stage walks (rounded to whole
/// steps: every 4 RK4 steps, every RK8 step, a similar time span of scattering either way).
const SORT_EVERY: usize = 16;

/// Orders the particles by their face (then start vertex, so the order is unique), so that
/// consecutive particles walk through the same faces: the walks are memory-bound, and the
/// particles of a mixing flow scatter over the mesh. Each particle's result is computed on
/// its own, so the order changes no value.
fn sort_by_face(state: &mut [Located], live: &mut [usize]) {
    let mut order: Vec<(u32, usize, Located)> = state
        .iter()
        .zip(live.iter())
        .map(|(l, &v)| (l.face, v, *l))
        .collect();
    order.par_sort_unstable_by_key(|&(f, v, _)| (f, v));
    for (i, (_, v, l)) in order.into_iter().enumerate() {
        live[i] = v;
        state[i] = l;
    }
}

/// Traces one particle from every vertex through `velocity` from `t0` over `span` in
/// `steps` classical RK4 steps (module doc; [`flow_map_with`] for another scheme) and
/// returns where each ends (`None` for a loose vertex).
///
/// `charts` must be built from `motion`'s positions at `t0`. Errors: a velocity that is not
/// finite (naming the particle's start vertex and the time), a time outside the motion's
/// frames, the velocity's own errors.
pub fn flow_map(
    charts: &Charts,
    motion: &Motion,
    velocity: &mut dyn Velocity,
    t0: f64,
    span: f64,
    steps: usize,
) -> Result<Vec<Option<Located>>, LcsError> {
    flow_map_with(charts, motion, velocity, t0, span, Scheme::Rk4, steps)
}

/// [`flow_map`] with the explicit Runge–Kutta scheme `scheme` ([`crate::lcs::rk`]).
pub fn flow_map_with(
    charts: &Charts,
    motion: &Motion,
    velocity: &mut dyn Velocity,
    t0: f64,
    span: f64,
    scheme: Scheme,
    steps: usize,
) -> Result<Vec<Option<Located>>, LcsError> {
    let moves = Moves::new(scheme);
    if let Some(planar) = &charts.planar
        && motion.is_fixed()
    {
        return flow_map_planar(charts, planar, velocity, t0, span, &moves, steps);
    }
    let n = charts.vertex_face.len();
    let start: Vec<Option<Located>> = (0..n).map(|v| charts.at_vertex_here(v)).collect();
    let mut live: Vec<usize> = (0..n).filter(|&v| start[v].is_some()).collect();
    let mut state: Vec<Located> = live.iter().filter_map(|&v| start[v]).collect();
    let m = state.len();
    let h = span / steps.max(1) as f64;
    let fixed = motion.is_fixed();
    // per particle and slot ([`Moves::slot`]): a stage point, the map of its face's chart
    // into the particle's, and the map of a displacement in the particle's chart to
    // barycentric rates there (for the walks from it)
    let slots = moves.slots();
    let mut slot_at = vec![vec![state[0]; m]; slots];
    let mut slot_rot = vec![vec![Orth::IDENTITY; m]; slots];
    let mut slot_bary = vec![vec![DMat2::ZERO; m]; slots];
    // per particle, at the current stage point: its world position and, on a fixed mesh,
    // the rows of `R (u, n̂ × u)ᵀ`, which give the stage velocity in the particle's chart
    // from `w`
    let mut axes = vec![[DVec3::ZERO; 2]; m];
    let mut points = vec![DVec3::ZERO; m];
    let mut outside_at = if velocity.uses_location() {
        vec![state[0]; m]
    } else {
        Vec::new()
    };
    let mut w = vec![DVec3::ZERO; m];
    let stages = moves.stages();
    let mut k: Vec<Vec<DVec2>> = vec![vec![DVec2::ZERO; m]; stages];
    for step in 0..steps.max(1) {
        if step % (SORT_EVERY / stages).max(1) == 0 {
            sort_by_face(&mut state, &mut live);
        }
        for stage in 0..stages {
            let ts = moves.time(stage, t0, step, h);
            let at = motion.at(ts)?;
            let k_ref = &k;
            let stage_point = |c: Corners,
                               l: &mut Located,
                               r: &mut Orth,
                               x: &mut DVec3,
                               tb: &mut DMat2,
                               ax: &mut [DVec3; 2]| {
                let fr = &charts.frame_of(c);
                *x = if fixed {
                    fr.x0 + l.bary.y * fr.e1 + l.bary.z * fr.e2
                } else {
                    charts.world_here(motion, at, l)
                };
                let rm = r.mat();
                *tb = fr.bary_map(rm);
                // rows of R [u v]ᵀ: k = R (u·w, v·w)
                *ax = [
                    rm.x_axis.x * fr.u + rm.y_axis.x * fr.v,
                    rm.x_axis.y * fr.u + rm.y_axis.y * fr.v,
                ];
            };
            let dst = moves.slot(stage);
            if stage == 0 {
                (
                    slot_at[dst].par_chunks_mut(2),
                    slot_rot[dst].par_chunks_mut(2),
                    points.par_chunks_mut(2),
                    slot_bary[dst].par_chunks_mut(2),
                    axes.par_chunks_mut(2),
                    state.par_chunks(2),
                )
                    .into_par_iter()
                    .for_each(|(l, r, x, tb, ax, p)| {
                        l.copy_from_slice(p);
                        r.fill(Orth::IDENTITY);
                        for j in 0..l.len() {
                            let cj = charts.hop[l[j].face as usize].corners;
                            stage_point(
                                cj, &mut l[j], &mut r[j], &mut x[j], &mut tb[j], &mut ax[j],
                            );
                        }
                    });
            } else {
                // each stage point walked on from the earlier one nearest in time (module
                // doc), two particles at a time ([`Charts::walk_pair`])
                let src = moves.slot(moves.source(stage));
                let (from_at, to_at) = two(&mut slot_at, src, dst);
                let (from_rot, to_rot) = two(&mut slot_rot, src, dst);
                let (from_bary, to_bary) = two(&mut slot_bary, src, dst);
                (
                    to_at.par_chunks_mut(2),
                    to_rot.par_chunks_mut(2),
                    points.par_chunks_mut(2),
                    to_bary.par_chunks_mut(2),
                    axes.par_chunks_mut(2),
                    from_at.par_chunks(2),
                    from_rot.par_chunks(2),
                    from_bary.par_chunks(2),
                )
                    .into_par_iter()
                    .enumerate()
                    .for_each(|(c, (l, r, x, tb, ax, l0, r0, tb0))| {
                        let mv = |j: usize| bary_step(tb0[j], moves.to(stage, h, k_ref, 2 * c + j));
                        let mut corners = [None; 2];
                        if l.len() == 2 {
                            let [(la, ra, ca), (lb, rb, cb)] =
                                charts.walk_pair((&l0[0], mv(0)), (&l0[1], mv(1)));
                            (l[0], r[0]) = (la, r0[0].then([ra.a, ra.b], ra.sigma));
                            (l[1], r[1]) = (lb, r0[1].then([rb.a, rb.b], rb.sigma));
                            corners = [Some(ca), Some(cb)];
                        } else {
                            let (e, rw, ce) = charts.walk_bary(&l0[0], mv(0));
                            (l[0], r[0]) = (e, r0[0].then([rw.a, rw.b], rw.sigma));
                            corners[0] = Some(ce);
                        }
                        for j in 0..l.len() {
                            let cj = corners[j]
                                .unwrap_or_else(|| charts.hop[l[j].face as usize].corners);
                            stage_point(
                                cj, &mut l[j], &mut r[j], &mut x[j], &mut tb[j], &mut ax[j],
                            );
                        }
                    });
            }
            let (stage_at, stage_rot) = (&slot_at[dst], &slot_rot[dst]);
            if velocity.uses_location() {
                // the velocity reads the input's faces
                outside_at
                    .par_iter_mut()
                    .zip(stage_at)
                    .for_each(|(o, l)| *o = charts.outside(l));
            }
            eval_checked(velocity, ts, &outside_at, &points, &live, &mut w)?;
            if fixed {
                k[stage]
                    .par_iter_mut()
                    .zip(&axes)
                    .zip(&w)
                    .for_each(|((ki, ax), wi)| *ki = DVec2::new(ax[0].dot(*wi), ax[1].dot(*wi)));
            } else {
                k[stage]
                    .par_iter_mut()
                    .zip(stage_at)
                    .zip(stage_rot)
                    .zip(&w)
                    .for_each(|(((ki, l), r), &wi)| {
                        *ki = r.mat() * charts.chart_velocity(motion, at, l, wi);
                    });
            }
        }
        let last = |i: usize| moves.to(stages, h, &k, i);
        let src = moves.slot(moves.source(stages));
        (
            state.par_chunks_mut(2),
            slot_at[src].par_chunks(2),
            slot_bary[src].par_chunks(2),
        )
            .into_par_iter()
            .enumerate()
            .for_each(|(c, (p, l, tb))| {
                if p.len() == 2 {
                    let d = [0, 1].map(|j| bary_step(tb[j], last(2 * c + j)));
                    let [a, b] = charts.walk_pair((&l[0], d[0]), (&l[1], d[1]));
                    (p[0], p[1]) = (a.0, b.0);
                } else {
                    p[0] = charts.walk_bary(&l[0], bary_step(tb[0], last(2 * c))).0;
                }
            });
    }
    let mut out = vec![None; n];
    for (i, &v) in live.iter().enumerate() {
        out[v] = Some(charts.outside(&state[i]));
    }
    Ok(out)
}
