//! A spill laid as a pool (issue 34): the liquid a Spill Group's weights hold, put down as
//! a body of liquid of its own depth, with a sharp edge whose shape owes nothing to the
//! cloth's mesh.
//!
//! The weights `w_i ∈ [0, 1]` are painted on the cloth's vertices `X_i` (lumped areas
//! `A_i`); at a depth `a` (kg/m², the Amount) they hold
//!
//! ```text
//! M = a Σ_i w_i A_i.
//! ```
//!
//! The pool is the region of area `M / a` where the weights are highest, laid at `a` on
//! the vertices of the simulated (refined) cloth in order, the one where the mass runs
//! out filled in part. "Where the weights are highest" needs the weights between the
//! cloth's vertices, and the linear interpolant will not do: its level sets are polygons
//! whose sides follow the cloth's edges (one painted vertex's is the shape of its
//! one-ring), so on a coarse cloth the pool, and the stain it spreads into, would be a
//! rounded square along the grid. The order is instead the weights' Gaussian
//! reconstruction at the cloth's own spacing,
//!
//! ```text
//! s(x) = Σ_i w_i A_i exp(−|x − X_i|² / 2σ²),    σ² = mean of A_i over w_i > 0,
//! ```
//!
//! a smooth field with no imprint of the grid (on a regular grid of spacing `h = σ`, a
//! constant weight's ripple is `exp(−2π²) ≈ 3·10⁻⁹` of it) that rounds the corners of a
//! painted patch at the radius `σ` the painting cannot resolve, where a liquid's surface
//! tension rounds them too. The pool stays inside the weights' reach: it is laid only on
//! vertices where the interpolated weight is positive, which can hold it (`Σ_j w(x_j) a_j
//! = Σ_i w_i A_i` for vertices placed on the cloth's triangles, and `w ≤ 1`). Terms beyond
//! `4σ` (below `e⁻⁸` of a neighbour's) are left out; ties go to the lower index, so the
//! pool is the same on any machine and any number of threads.

use std::collections::HashMap;

use glam::DVec3;
use rayon::prelude::*;

use super::Simulator;

/// The reconstruction's reach, in units of `σ` (module doc).
const CUTOFF: f64 = 4.0;

/// The painted weights: the cloth's vertices, their weights and their lumped areas.
pub(crate) struct Painted<'a> {
    pub(crate) at: &'a [DVec3],
    pub(crate) weight: &'a [f64],
    pub(crate) area: &'a [f64],
}

impl Painted<'_> {
    /// The mass a pool `amount` deep holds, `M = a Σ w_i A_i`, kg.
    pub(crate) fn mass(&self, amount: f64) -> f64 {
        amount
            * self
                .weight
                .iter()
                .zip(self.area)
                .map(|(w, a)| w * a)
                .sum::<f64>()
    }

    /// The reconstruction `s(x)` at `points` (module doc); 0 everywhere without a painted
    /// vertex of positive weight and area.
    fn reconstruction(&self, points: &[DVec3]) -> Vec<f64> {
        let painted: Vec<usize> = (0..self.weight.len())
            .filter(|&i| self.weight[i] > 0.0 && self.area[i] > 0.0)
            .collect();
        if painted.is_empty() {
            return vec![0.0; points.len()];
        }
        let sigma2 = painted.iter().map(|&i| self.area[i]).sum::<f64>() / painted.len() as f64;
        let cell = CUTOFF * sigma2.sqrt();
        let key = |x: DVec3| (x / cell).floor().as_i64vec3().to_array();
        let mut grid: HashMap<[i64; 3], Vec<usize>> = HashMap::new();
        for &i in &painted {
            grid.entry(key(self.at[i])).or_default().push(i);
        }
        points
            .par_iter()
            .map(|&x| {
                let [cx, cy, cz] = key(x);
                let mut s = 0.0;
                for dx in -1..=1 {
                    for dy in -1..=1 {
                        for dz in -1..=1 {
                            for &i in grid.get(&[cx + dx, cy + dy, cz + dz]).into_iter().flatten() {
                                let d2 = (x - self.at[i]).length_squared();
                                if d2 < cell * cell {
                                    s += self.weight[i] * self.area[i] * (-0.5 * d2 / sigma2).exp();
                                }
                            }
                        }
                    }
                }
                s
            })
            .collect()
    }
}

/// The lumped areas at the current frame of `sim`'s vertices where `reach > 0` (0
/// elsewhere): where a pool may be laid ([`Simulator::add_liquid`] takes the same areas).
pub(crate) fn areas(sim: &Simulator, reach: &[f64]) -> Vec<f64> {
    (0..reach.len())
        .map(|v| {
            if reach[v] > 0.0 {
                sim.current_area(v)
            } else {
                0.0
            }
        })
        .collect()
}

/// The pool (kg/m² per point): the mass `painted` holds at `amount` ([`Painted::mass`]),
/// laid `amount` deep on the `points` of areas `area` where `reach > 0` (the interpolated
/// weight), highest reconstruction first (module doc). A point of no area gets nothing;
/// what rounding leaves over goes to the last point laid.
pub(crate) fn pool(
    painted: &Painted<'_>,
    amount: f64,
    points: &[DVec3],
    reach: &[f64],
    area: &[f64],
) -> Vec<f64> {
    let mut out = vec![0.0; points.len()];
    let mass = painted.mass(amount);
    if !(amount > 0.0 && mass > 0.0) {
        return out;
    }
    // the candidates, by their reconstruction (computed for them alone)
    let candidates: Vec<usize> = (0..points.len())
        .filter(|&j| reach[j] > 0.0 && area[j] > 0.0)
        .collect();
    let at: Vec<DVec3> = candidates.iter().map(|&j| points[j]).collect();
    let s = painted.reconstruction(&at);
    let mut ranked: Vec<usize> = (0..candidates.len()).collect();
    ranked.sort_by(|&a, &b| s[b].total_cmp(&s[a]).then(a.cmp(&b)));
    let order: Vec<usize> = ranked.into_iter().map(|k| candidates[k]).collect();
    let mut left = mass;
    for &j in &order {
        let laid = (amount * area[j]).min(left);
        out[j] = laid / area[j];
        left -= laid;
        if left <= 0.0 {
            return out;
        }
    }
    if let Some(&last) = order.last() {
        out[last] += left / area[last];
    }
    out
}
