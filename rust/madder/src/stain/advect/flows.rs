//! An [`UpwindPlan`](super::UpwindPlan)'s transfers laid out per vertex, and one
//! sub-cycle over them (the fields, and the momentum with them).
//!
//! *Layout (issue 16, speed).* The plan is built in two passes over each vertex's edges,
//! in parallel over runs of vertices laid end to end: the first sums the vertex's outflow
//! and lists the `|Φ|` of the edges with a flux, given and received (the donor read off
//! the flux's sign); once the sub-step count is known from the largest Courant number,
//! the second turns them into fractions. The result is a CSR table per vertex (the
//! fractions it gives; the fraction, donor and edge of what it receives, edges without
//! flux left out), built once per step. Each sub-cycle is then one pass over that table
//! for all fields at once, interleaved per vertex, and with the momentum form (below) the
//! momentum in the same pass; the solvent's transported mass is the momentum's divisor,
//! so it is not transported twice. Each value is computed by the same operations in the
//! same order as the former one-field-at-a-time passes: the outputs are bit-identical.
//! The fluxes ([`dual_fluxes`]) inside the simulator's active region visit only the faces
//! with an active edge. The runs are sized from their vertices' edge counts and their
//! fractions written over the `|Φ|` they replace (no regrowth, one copy into the table);
//! a sub-cycle reads each transfer once for up to five fields (per-field sums kept in
//! transfer order), and with several sub-cycles the momentum's rotations `R_vd` are
//! gathered once per plan in transfer order instead of from the edges in every cycle.
//!
//! [`dual_fluxes`]: super::dual_fluxes

use glam::{DMat2, DVec2};
use rayon::prelude::*;

use super::VERTICES_PER_TASK;
use crate::mesh::Transport;
use crate::runs::carve;

/// An [`UpwindPlan`]'s transfers per vertex: the fractions it gives away, and the
/// `(fraction, donor, edge)` of what it receives, each in the vertex's edge order, without
/// the edges that carry nothing. Built once with the plan (in parallel over runs of
/// vertices, laid end to end: deterministic), read by every sub-cycle.
///
/// [`UpwindPlan`]: super::UpwindPlan
#[derive(Debug, Clone, Default)]
pub(super) struct Flows {
    pub(super) out_ptr: Vec<u32>,
    pub(super) out_fraction: Vec<f64>,
    pub(super) in_ptr: Vec<u32>,
    pub(super) in_from: Vec<(f64, u32, u32)>,
}

/// The rotations `R_vd` of the received transfers, as `(cos, sin)` of `[cos −sin; sin cos]`:
/// a table in [`Flows::received`] order ([`Flows::turns`]), or read off the edges'
/// rotations (transposed where `v > d`) each time.
pub(super) enum Turns<'a> {
    Table(Vec<[f64; 2]>),
    Edges(&'a [[f64; 2]]),
}

impl Flows {
    /// Runs of consecutive vertices' transfers (each with ends relative to its own
    /// start) laid end to end, in place of these flows (their allocations kept).
    pub(super) fn concat(&mut self, n: usize, runs: Vec<Flows>) {
        let given: usize = runs.iter().map(|r| r.out_fraction.len()).sum();
        let received: usize = runs.iter().map(|r| r.in_from.len()).sum();
        let f = self;
        f.out_ptr.clear();
        f.out_fraction.clear();
        f.in_ptr.clear();
        f.in_from.clear();
        // exact: the transfers grow a little every sub-step while the liquid spreads, and
        // the doubling of an amortized reserve would keep up to twice their memory
        f.out_ptr.reserve_exact(n + 1);
        f.out_fraction.reserve_exact(given);
        f.in_ptr.reserve_exact(n + 1);
        f.in_from.reserve_exact(received);
        f.out_ptr.push(0);
        f.in_ptr.push(0);
        for run in runs {
            let (o, i) = (f.out_fraction.len() as u32, f.in_from.len() as u32);
            f.out_ptr.extend(run.out_ptr.iter().map(|x| o + x));
            f.in_ptr.extend(run.in_ptr.iter().map(|x| i + x));
            f.out_fraction.extend(run.out_fraction);
            f.in_from.extend(run.in_from);
        }
    }

    fn given(&self, v: usize) -> &[f64] {
        &self.out_fraction[self.out_ptr[v] as usize..self.out_ptr[v + 1] as usize]
    }

    fn received(&self, v: usize) -> &[(f64, u32, u32)] {
        &self.in_from[self.in_ptr[v] as usize..self.in_ptr[v + 1] as usize]
    }

    /// One sub-cycle of `k` interleaved fields `m` into `next`.
    pub(super) fn cycle(&self, m: &[f64], k: usize, next: &mut [f64]) {
        next.par_chunks_mut(k)
            .enumerate()
            .with_min_len(VERTICES_PER_TASK)
            .for_each(|(v, out)| self.fields_at(v, m, k, out));
    }

    /// The rotation `R_vd` of each received transfer, in [`Flows::received`] order, as
    /// `(cos, sin)` of the matrix `[cos −sin; sin cos]`: the stored rotation of the edge or
    /// its transpose (the sine negated: exact), read once per plan instead of once per
    /// sub-cycle.
    pub(super) fn turns(&self, transport: &Transport) -> Vec<[f64; 2]> {
        let cos_sin = transport.edge_cos_sin();
        let n = self.in_ptr.len() - 1;
        let mut turns = vec![[0.0; 2]; self.in_from.len()];
        // runs of vertices, each filling its own stretch of the table
        let ranges: Vec<_> = (0..n)
            .step_by(VERTICES_PER_TASK)
            .map(|start| start..(start + VERTICES_PER_TASK).min(n))
            .collect();
        let lens = ranges
            .iter()
            .map(|r| (self.in_ptr[r.end] - self.in_ptr[r.start]) as usize);
        let runs = carve(&mut turns, lens);
        ranges
            .into_par_iter()
            .zip(runs)
            .for_each(|(vertices, out)| {
                let base = self.in_ptr[vertices.start] as usize;
                for v in vertices {
                    for t in self.in_ptr[v] as usize..self.in_ptr[v + 1] as usize {
                        let (_, d, e) = self.in_from[t];
                        let [c, s] = cos_sin[e as usize];
                        out[t - base] = if v < d as usize { [c, s] } else { [c, -s] };
                    }
                }
            });
        turns
    }

    /// [`Flows::cycle`], and the momentum `p` into `p_next` in the same pass (`turns` from
    /// [`Flows::turns`]).
    pub(super) fn cycle_with_momentum(
        &self,
        m: &[f64],
        k: usize,
        next: &mut [f64],
        turns: &Turns<'_>,
        p: &[DVec2],
        p_next: &mut [DVec2],
    ) {
        next.par_chunks_mut(k)
            .zip(p_next.par_iter_mut())
            .enumerate()
            .with_min_len(VERTICES_PER_TASK)
            .for_each(|(v, (out, pv))| {
                self.fields_at(v, m, k, out);
                *pv = self.momentum_at(v, turns, p);
            });
    }

    /// Vertex `v`'s fields after one sub-cycle: it gives `fraction · m_v` across each of
    /// its outgoing edges and receives `fraction · m_donor` across each incoming one — the
    /// same product on both sides, so the transfer is conservative to rounding — clamped
    /// at zero against rounding. The transfers are read once for all fields, each field
    /// summed in transfer order (the same sums as one field at a time).
    fn fields_at(&self, v: usize, m: &[f64], k: usize, out: &mut [f64]) {
        match k {
            1 => self.fields_at_k::<1>(v, m, out),
            2 => self.fields_at_k::<2>(v, m, out),
            3 => self.fields_at_k::<3>(v, m, out),
            4 => self.fields_at_k::<4>(v, m, out),
            5 => self.fields_at_k::<5>(v, m, out),
            _ => self.fields_at_one_by_one(v, m, k, out),
        }
    }

    /// [`Flows::fields_at`] for `K` fields.
    fn fields_at_k<const K: usize>(&self, v: usize, m: &[f64], out: &mut [f64]) {
        let mv: [f64; K] = m[v * K..(v + 1) * K].try_into().expect("K fields");
        let mut gone = [0.0; K];
        for &fraction in self.given(v) {
            for c in 0..K {
                gone[c] += fraction * mv[c];
            }
        }
        let mut inflow = [0.0; K];
        for &(fraction, d, _) in self.received(v) {
            let md: [f64; K] = m[d as usize * K..(d as usize + 1) * K]
                .try_into()
                .expect("K fields");
            for c in 0..K {
                inflow[c] += fraction * md[c];
            }
        }
        for c in 0..K {
            out[c] = (mv[c] - gone[c]).max(0.0) + inflow[c];
        }
    }

    /// [`Flows::fields_at`] for more than five fields, one field at a time.
    fn fields_at_one_by_one(&self, v: usize, m: &[f64], k: usize, out: &mut [f64]) {
        for (c, o) in out.iter_mut().enumerate() {
            let mv = m[v * k + c];
            let mut gone = 0.0;
            for &fraction in self.given(v) {
                gone += fraction * mv;
            }
            let mut inflow = 0.0;
            for &(fraction, d, _) in self.received(v) {
                inflow += fraction * m[d as usize * k + c];
            }
            *o = (mv - gone).max(0.0) + inflow;
        }
    }

    /// Vertex `v`'s momentum after one sub-cycle: the same fractions of the donors'
    /// momenta, turned into `F_v` by `R_vd` (from `turns`).
    fn momentum_at(&self, v: usize, turns: &Turns<'_>, p: &[DVec2]) -> DVec2 {
        let (mut out, mut inflow) = (DVec2::ZERO, DVec2::ZERO);
        for &fraction in self.given(v) {
            out += fraction * p[v];
        }
        let (start, end) = (self.in_ptr[v] as usize, self.in_ptr[v + 1] as usize);
        for (t, &(fraction, d, e)) in self.in_from[start..end].iter().enumerate() {
            let [c, s] = match turns {
                Turns::Table(table) => table[start + t],
                Turns::Edges(cos_sin) => {
                    let [c, s] = cos_sin[e as usize];
                    if v < d as usize { [c, s] } else { [c, -s] }
                }
            };
            let r = DMat2::from_cols_array(&[c, s, -s, c]);
            inflow += r * (fraction * p[d as usize]);
        }
        (p[v] - out) + inflow
    }
}
