//! Stain–surface interactions: absorption, adsorption and evaporation (seed §4.5,
//! eqs. 4.7–4.10).
//!
//! Every vertex carries five **masses** (kg), not densities: the density of a field is its
//! mass over the lumped vertex area `A_i` of the current geometry (`σ = m / A`). They are
//!
//! | field | symbol | moves with the flow? |
//! |---|---|---|
//! | free solvent | `f` | yes |
//! | dissolved solute | `s` | yes, with the free solvent |
//! | absorbed solvent | `p` | no, held in the fibres |
//! | absorbed solute | `sp` | no |
//! | adsorbed solute | `sa` | no: the permanent mark |
//!
//! The seed writes every ODE for densities at a fixed point of the surface; multiplying by
//! `A` (constant during the interaction step: the mesh moves in the other sub-steps) gives
//! the same ODE for masses with the capacities scaled by the area. Each process is a
//! linear ODE with constant coefficients over the step `h`, so we integrate it with its
//! **exact** solution instead of the seed's implicit Euler (see *Deviations*).
//!
//! ## Absorption (§4.5)
//! ```text
//! σ̇_p = K_p (σ_sat − σ_p)    ⇒    ṗ = K_p (σ_sat A − p),
//! p(t+h) = σ_sat A − (σ_sat A − p(t)) e^{−K_p h},
//! Δ = (σ_sat A − p) (1 − e^{−K_p h}),     Δ ← min(Δ, f)   (if Δ > 0).
//! ```
//! `1 − e^{−K_p h}` is evaluated once per step as `−expm1(−K_p h)`, accurate for small
//! `K_p h`. The fibres can only take the free solvent there is, so a positive `Δ` is
//! bounded by `f` (the seed's `min(·, σ_f)`). The absorbed solvent takes dissolved solute
//! with it at the free solution's concentration, `σ̇_{s,p} = K_p (σ_sat − σ_p) σ_s/σ_f`:
//! the fraction `r = Δ/f ≤ 1` of `s` moves to `sp`; when `Δ = f` all of `f` and all of `s`
//! move, exactly, so no residue of rounding is left behind.
//!
//! `Δ < 0` happens when the cloth was compressed: the area shrank until the fibres hold
//! more than `σ_sat A`. The excess flows back out as free solvent (it decays exponentially
//! to saturation by the same closed form). Since `0 ≤ σ_sat A < p` and
//! `1 − e^{−K_p h} < 1`, `|Δ| < p`; the solute comes back at the held solution's
//! concentration `sp/p` (fraction `|Δ|/p` of `sp`).
//!
//! ## Adsorption, Langmuir (eq. 4.7)
//! ```text
//! σ̇_{s,a} = K_d (A_d − σ_{s,a})    ⇒    ṡa = K_d (A_d A − sa),
//! Δ = (A_d A − sa) (1 − e^{−K_d h}).
//! ```
//! A positive `Δ` deposits solute out of the available solute — the dissolved `s` and,
//! since "the absorbed solvent and solute go through the same adsorption", the absorbed
//! `sp` — proportionally to each (fraction `r = Δ/(s + sp)`), bounded by `s + sp`: when
//! the supply is short, all of it is deposited, exactly. A negative `Δ` (only when
//! `sa > A_d A ≥ 0`; then `|Δ| < sa`) is desorption: the solute goes back to the absorbed
//! solute `sp`, in the fibres.
//!
//! ## Evaporation (eq. 4.8)
//! ```text
//! σ̇_f = −a_evap K_evap    ⇒    the solvent loses  E = a_evap K_evap A h  per step,
//! ```
//! `a_evap` being the per-vertex `exposure` coefficient (see below). The seed notes that
//! "the amount evaporated in each step is bounded by the total amount left": `E` is taken
//! first from the free solvent, `min(E, f)`, and the rest from the absorbed solvent,
//! `min(E − min(E, f), p)` (the seed's `σ̇_p = −K_evap` once the free liquid is gone).
//! Solute does not evaporate. When the free solvent of a vertex is gone, the dissolved
//! solute left in it **dries in place**: it becomes absorbed solute (with its colour).
//! Otherwise it would keep flowing with no liquid to carry it. The evaporated mass (free
//! plus absorbed, per vertex) is returned, summed in vertex order.
//!
//! ## Combined effect (eqs. 4.9–4.10) and order
//! Eqs. 4.9–4.10 are the sums of the three right-hand sides above. We apply them in
//! sequence within the step (a first-order Lie splitting, like the rest of the seed's
//! split step): **absorption, then adsorption, then evaporation**. Absorption comes first
//! so that the solute it carries into the fibres can be deposited in the same step;
//! evaporation comes last so that the reported mass and the drying of the solute
//! describe the end of the step. Applying the processes one at a time is what lets each
//! bound (`f`, `s + sp`, what is left to evaporate) be enforced exactly.
//!
//! ## Why nothing goes negative and solute is conserved
//! Every transfer moves an amount `d` from one field to another with `0 ≤ d ≤` the source
//! (each bound above), written as `source −= d; target += d`. For `0 ≤ d ≤ x`,
//! `x − d ≥ 0` holds exactly in floating point (the rounded difference of a non-negative
//! exact result is non-negative), and a transfer of "all of it" sets the source to `0`
//! exactly. So no mass becomes negative, the total solute `Σ (s + sp + sa)` changes only
//! by the rounding of the additions, and the total solvent `Σ (f + p)` changes only by the
//! evaporated mass (plus rounding). The tests check both to 1e-13 relative over 10 000
//! random steps.
//!
//! Inputs are expected non-negative. Implicit diffusion on obtuse meshes can undershoot
//! slightly below zero; such a value is treated as **empty**: nothing is drawn from it and
//! it is not clamped (clamping would create mass), so it passes through unchanged.
//! Non-finite values are rejected with [`ParamError::NonFinite`].
//!
//! ## Colour
//! Optionally the simulator carries RGB colour masses (solute mass × colour): `color_free`
//! with the dissolved solute `s`, `color_held` with the immobile solute `sp + sa` (one pool:
//! neither moves). Every solute transfer between dissolved and held moves colour in
//! proportion: from free to held `Δ · color_free/s` (the same fraction `r` of the colour as
//! of `s`, all of it when all of `s` goes), from held to free `Δ · color_held/(sp + sa)`.
//! Transfers between `sp` and `sa` stay inside the held pool and move no colour. So the
//! colour mass is conserved exactly like the solute, and a stain of a single colour `c`
//! keeps `color = c · solute` in both pools.
//!
//! ## Exposure: the boundary coefficient of eq. 4.8
//! The seed makes "boundary cells" evaporate `a_evap` times faster (1.2 in its tests)
//! because their exposed area is larger. [`exposure`] marks a vertex exposed when it is
//! wet (`wet_i > threshold`) and either lies on the border of the mesh or has a dry
//! neighbour (`wet_j ≤ threshold`, neighbours by mesh edge): the rim of the wet region.
//! The rim of a stain therefore dries faster than its middle, and the dissolved solute
//! there dries in place first. That alone makes no halo ring: the deposit of a drying
//! blob falls off from its centre (`tests/tide_lines.rs`), and the rim it marks is one
//! ring of vertices wide, whatever the mesh spacing.
//!
//! ## Vapour-limited evaporation (issue 13 §2)
//! In still air a wet patch on a dry cloth evaporates as fast as its vapour diffuses
//! away. For a flat patch that is the potential problem of a charged disk: the flux is
//! `J(r) = J̄ / (2√(1 − r²/R²))` on a disk of radius `R`, which in terms of the distance
//! `d = R − r` to the edge is `J/J̄ = R / (2√(d(2R − d)))`: half the mean at the centre,
//! an integrable `1/√d` at the edge (Deegan et al. 1997, for a drop of small contact
//! angle). With `vapour_limited` ([`vapour_exposure`]) every wet patch evaporates so, `d`
//! the shortest distance along the mesh to its edge (Dijkstra), `R` its largest, each
//! vertex taking the average of the law over its cell (`ℓ = √A_i` wide: the singularity is
//! integrated, not sampled, so the rim's share converges as the mesh is refined) and each
//! patch scaled so that its mean is exactly 1: `K_evap` stays the mean rate, the law only
//! moves the evaporation to the edge. It replaces `a_evap`. For other shapes than a disk
//! it is the disk's law in the distance to the edge (an approximation: the exact flux
//! would need the patch's capacitance problem solved).
//!
//! ## Deviations from the seed
//! - **Exact exponential integrator** instead of implicit Euler
//!   (`K h/(1 + K h)` → `1 − e^{−K h}`). Both factors lie in `[0, 1)`, so positivity and
//!   the bounds are the same; the exponential one matches the closed form exactly for any
//!   step, and several small steps equal one large step.
//! - **Drying**: dissolved solute at a vertex without free solvent becomes absorbed
//!   solute (the seed leaves it undefined: `σ_s/σ_f` is `0/0`).
//! - **Release** of absorbed solvent when the area shrinks below what is held: the seed's
//!   formula also lowers `σ_p` then, but does not say where the solvent and its solute go;
//!   we return both to the free solution.
//! - **Adsorption draws from `s + sp`** proportionally (the seed's eq. 4.10 shows only
//!   `s`, its text says the absorbed solute adsorbs too); desorption returns to `sp`.
//! - **Order** absorption → adsorption → evaporation, applied one after the other.
//!
//! ## Determinism
//! The vertices are independent: the step is a pure per-vertex map, run in parallel over
//! fixed-size chunks with rayon, and the evaporated mass is summed serially in vertex
//! order. Results are bit-identical for any number of threads.

use rayon::prelude::*;

use super::state::Fields;
use crate::error::ParamError;
use crate::mesh::Topology;

/// Rates and capacities of the stain–surface interactions (seed §4.5). SI units.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct InteractionRates {
    /// `K_p`, 1/s: how fast the fibres soak up free solvent toward saturation.
    pub absorption: f64,
    /// `σ_sat`, kg/m²: the solvent the fibres can hold per unit area.
    pub saturation: f64,
    /// `K_d`, 1/s: Langmuir rate of eq. 4.7.
    pub adsorption: f64,
    /// `A_d`, kg/m²: the maximum adsorbed solute per unit area (eq. 4.7).
    pub capacity: f64,
    /// `K_evap`, kg/(m²·s): solvent evaporated per unit area and time (eq. 4.8).
    pub evaporation: f64,
    /// `a_evap` (≥ 1): evaporation factor of exposed vertices (eq. 4.8; 1.2 in the seed).
    pub evaporation_boundary: f64,
}

/// Water on a light cotton cloth. Only `a_evap = 1.2` comes from the seed, which gives
/// no other values; the rest are order-of-magnitude estimates, meant to be tuned:
/// - `K_p = 2 /s`: the seed assumes a thin cloth that "reaches saturation quickly"; a drop
///   wicks into a thin cotton weave in well under a second (Lucas–Washburn time scale),
///   so the time constant is 0.5 s.
/// - `σ_sat = 0.1 kg/m²`: a 100–150 g/m² cotton fabric holds about its own weight of water
///   in its fibres.
/// - `K_d = 0.1 /s`, `A_d = 2·10⁻³ kg/m²`: solute (dye) uptake of about 2 % of the fibre
///   mass, reached over tens of seconds.
/// - `K_evap = 5·10⁻⁵ kg/(m²·s)` (0.18 kg/m² per hour): water in still room air at about
///   20 °C and 50 % humidity; a saturated cloth dries in about half an hour.
impl Default for InteractionRates {
    fn default() -> Self {
        Self {
            absorption: 2.0,
            saturation: 0.1,
            adsorption: 0.1,
            capacity: 2e-3,
            evaporation: 5e-5,
            evaporation_boundary: 1.2,
        }
    }
}

impl InteractionRates {
    /// Every rate and capacity finite and `≥ 0`; `evaporation_boundary` finite and `≥ 1`.
    /// The error names the parameter.
    pub(crate) fn validate(&self) -> Result<(), ParamError> {
        let nonneg = [
            ("absorption rate", self.absorption),
            ("saturation", self.saturation),
            ("adsorption rate", self.adsorption),
            ("adsorption capacity", self.capacity),
            ("evaporation rate", self.evaporation),
        ];
        for (name, value) in nonneg {
            if !(value.is_finite() && value >= 0.0) {
                return Err(ParamError::OutOfRange {
                    name,
                    requirement: "finite and ≥ 0",
                    value,
                });
            }
        }
        let a = self.evaporation_boundary;
        if !(a.is_finite() && a >= 1.0) {
            return Err(ParamError::OutOfRange {
                name: "evaporation boundary coefficient",
                requirement: "finite and ≥ 1",
                value: a,
            });
        }
        Ok(())
    }
}

/// Evaporation coefficient of every vertex for eq. 4.8: `a_evap` where the vertex is
/// exposed, `1` elsewhere. A vertex is exposed when it is wet (`wet[i] > threshold`) and
/// lies on the mesh border (`boundary[i]`, e.g. [`Topology::boundary_vertices`]) or has a
/// dry neighbour (`wet[j] ≤ threshold`) across a mesh edge. Dry vertices get `1` (they have
/// nothing to evaporate). The rim of a stain thus dries faster (module doc).
///
/// # Panics
/// If `boundary` or `wet` does not have one value per vertex of `topology`.
pub(crate) fn exposure(
    topology: &Topology,
    boundary: &[bool],
    wet: &[f64],
    threshold: f64,
    a_evap: f64,
) -> Vec<f64> {
    let n = topology.n_vertices();
    assert_eq!(boundary.len(), n, "exposure: one boundary flag per vertex");
    assert_eq!(wet.len(), n, "exposure: one wetness value per vertex");
    let is_wet = |i: usize| wet[i] > threshold;
    let mut exposed = boundary.to_vec();
    for &[a, b] in topology.edges() {
        let (a, b) = (a as usize, b as usize);
        match (is_wet(a), is_wet(b)) {
            (true, false) => exposed[a] = true,
            (false, true) => exposed[b] = true,
            _ => {}
        }
    }
    (0..n)
        .map(|i| if is_wet(i) && exposed[i] { a_evap } else { 1.0 })
        .collect()
}

/// Evaporation coefficient of every vertex when the evaporation is limited by the
/// diffusion of vapour into still air (issue 13 §2; module doc, "Vapour-limited
/// evaporation"): on a wet vertex at distance `d` from the edge of its wet patch,
/// `J/J̄ = R / (2 √(d (2R − d)))` averaged over the vertex's cell, `R` the patch's largest
/// distance to its edge, then scaled so that each patch's mean (by area) is exactly 1
/// (`K_evap` stays the mean rate). Dry vertices get 1.
///
/// The edge of a patch lies half-way along every edge from a wet to a dry vertex
/// (`wet > threshold`), and on the cloth's border (`boundary`); `d` is the shortest path
/// along mesh edges (`edge_length`, indexed like [`Topology::edges`]) to it (Dijkstra,
/// deterministic). A vertex's cell is `[d − ℓ/2, d + ℓ/2] ∩ [0, 2R]`, `ℓ = √A_i`. A patch
/// without an edge (a closed cloth wet all over) evaporates uniformly.
///
/// # Panics
/// If a slice does not have one value per vertex (per edge for `edge_length`).
pub(crate) fn vapour_exposure(
    topology: &Topology,
    edge_length: &[f64],
    area: &[f64],
    boundary: &[bool],
    wet: &[f64],
    threshold: f64,
) -> Vec<f64> {
    use std::cmp::Reverse;
    use std::collections::BinaryHeap;
    let n = topology.n_vertices();
    assert_eq!(
        boundary.len(),
        n,
        "vapour exposure: one boundary flag per vertex"
    );
    assert_eq!(
        wet.len(),
        n,
        "vapour exposure: one wetness value per vertex"
    );
    assert_eq!(area.len(), n, "vapour exposure: one area per vertex");
    assert_eq!(
        edge_length.len(),
        topology.n_edges(),
        "vapour exposure: edge lengths"
    );
    let is_wet: Vec<bool> = wet.iter().map(|&w| w > threshold).collect();
    // the wet graph (edges between wet vertices) and the distance to the patch's edge
    let mut start = vec![0u32; n + 1];
    for &[a, b] in topology.edges() {
        if is_wet[a as usize] && is_wet[b as usize] {
            start[a as usize + 1] += 1;
            start[b as usize + 1] += 1;
        }
    }
    for i in 0..n {
        start[i + 1] += start[i];
    }
    let mut next = start.clone();
    let mut link = vec![(0u32, 0.0f64); start[n] as usize];
    let mut d = vec![f64::INFINITY; n];
    for (i, b) in boundary.iter().enumerate() {
        if *b && is_wet[i] {
            d[i] = 0.0;
        }
    }
    for (&[a, b], &len) in topology.edges().iter().zip(edge_length) {
        let (a, b) = (a as usize, b as usize);
        match (is_wet[a], is_wet[b]) {
            (true, true) => {
                link[next[a] as usize] = (b as u32, len);
                next[a] += 1;
                link[next[b] as usize] = (a as u32, len);
                next[b] += 1;
            }
            (true, false) => d[a] = d[a].min(0.5 * len),
            (false, true) => d[b] = d[b].min(0.5 * len),
            _ => {}
        }
    }
    // non-negative distances order like their bits; ties by vertex: deterministic
    let mut heap: BinaryHeap<Reverse<(u64, u32)>> = (0..n)
        .filter(|&i| d[i].is_finite())
        .map(|i| Reverse((d[i].to_bits(), i as u32)))
        .collect();
    while let Some(Reverse((bits, i))) = heap.pop() {
        let (di, i) = (f64::from_bits(bits), i as usize);
        if di > d[i] {
            continue;
        }
        for &(j, len) in &link[start[i] as usize..start[i + 1] as usize] {
            let dj = di + len;
            if dj < d[j as usize] {
                d[j as usize] = dj;
                heap.push(Reverse((dj.to_bits(), j)));
            }
        }
    }
    // the wet patches (connected components of the wet graph), labelled by a search
    let mut patch = vec![u32::MAX; n];
    let mut patches: Vec<Vec<u32>> = Vec::new();
    for s in 0..n {
        if !is_wet[s] || patch[s] != u32::MAX {
            continue;
        }
        let id = patches.len() as u32;
        let mut members = vec![s as u32];
        patch[s] = id;
        let mut k = 0;
        while k < members.len() {
            let i = members[k] as usize;
            for &(j, _) in &link[start[i] as usize..start[i + 1] as usize] {
                if patch[j as usize] == u32::MAX {
                    patch[j as usize] = id;
                    members.push(j);
                }
            }
            k += 1;
        }
        patches.push(members);
    }
    let mut exposure = vec![1.0; n];
    for members in &patches {
        let r = members.iter().map(|&i| d[i as usize]).fold(0.0, f64::max);
        if !(r.is_finite() && r > 0.0) {
            continue; // no edge, or a single vertex on the border: uniform
        }
        // the cell average of R/(2√(x(2R − x))): (R/2)·[asin((x − R)/R)] over the cell
        let primitive = |x: f64| 0.5 * r * ((x - r) / r).clamp(-1.0, 1.0).asin();
        let (mut total, mut weighted) = (0.0, 0.0);
        for &i in members {
            let i = i as usize;
            let half = 0.5 * area[i].max(0.0).sqrt();
            let (lo, hi) = ((d[i] - half).max(0.0), (d[i] + half).min(2.0 * r));
            let w = if hi > lo {
                (primitive(hi) - primitive(lo)) / (hi - lo)
            } else {
                let x = d[i].clamp(1e-9 * r, r);
                r / (2.0 * (x * (2.0 * r - x)).sqrt())
            };
            exposure[i] = w;
            total += area[i];
            weighted += area[i] * w;
        }
        if weighted > 0.0 {
            let scale = total / weighted;
            for &i in members {
                exposure[i as usize] *= scale;
            }
        }
    }
    exposure
}

/// Vertices per parallel work item (a fixed split: the result does not depend on it).
const CHUNK: usize = 1024;

/// One interaction step `h` (s) on every vertex (the simulator calls
/// [`interact_varied`]; this uniform form is what the tests below check): absorption, then adsorption, then
/// evaporation (module doc). `area` holds the lumped vertex areas `A_i` (m²) of the
/// current geometry and `exposure` the per-vertex evaporation coefficient from
/// [`exposure()`] (which takes `rates.evaporation_boundary`; `interact` itself does not read
/// it). Returns the evaporated solvent mass (kg), summed in vertex order.
///
/// Errors: `h` not finite and `> 0` (`"time step"`), invalid `rates`, a length that differs
/// from `area.len()` (a missing colour pool when the other is present counts as length 0),
/// a non-finite value, a negative area or exposure. On error nothing is modified.
#[cfg(test)]
pub(crate) fn interact(
    rates: &InteractionRates,
    area: &[f64],
    exposure: &[f64],
    h: f64,
    fields: &mut Fields,
) -> Result<f64, ParamError> {
    interact_varied(rates, area, exposure, None, h, fields)
}

/// The interaction step with the absorption rate of vertex `i` multiplied by
/// `absorption_scale[i]` (an irregular fabric, [`super::irregular`]); `None` is the
/// uniform fabric (the tests' `interact`).
pub(crate) fn interact_varied(
    rates: &InteractionRates,
    area: &[f64],
    exposure: &[f64],
    absorption_scale: Option<&[f64]>,
    h: f64,
    fields: &mut Fields,
) -> Result<f64, ParamError> {
    if !(h.is_finite() && h > 0.0) {
        return Err(ParamError::OutOfRange {
            name: "time step",
            requirement: "finite and > 0",
            value: h,
        });
    }
    rates.validate()?;
    let n = area.len();
    check_inputs(n, area, exposure, fields)?;

    if let Some(a) = absorption_scale {
        if a.len() != n {
            return Err(ParamError::Length {
                name: "absorption scale",
                expected: n,
                got: a.len(),
            });
        }
    }
    let coeffs = Coefficients {
        absorb: -(-rates.absorption * h).exp_m1(),
        rate_h: rates.absorption * h,
        adsorb: -(-rates.adsorption * h).exp_m1(),
        saturation: rates.saturation,
        capacity: rates.capacity,
        evaporate: rates.evaporation * h,
    };

    let mut evaporated = vec![0.0; n];
    let mut chunks = Vec::with_capacity(n.div_ceil(CHUNK));
    {
        let Fields {
            free_solvent,
            solute,
            absorbed_solvent,
            absorbed_solute,
            adsorbed,
            color_free,
            color_held,
        } = fields;
        let mut f = free_solvent.chunks_mut(CHUNK);
        let mut s = solute.chunks_mut(CHUNK);
        let mut p = absorbed_solvent.chunks_mut(CHUNK);
        let mut sp = absorbed_solute.chunks_mut(CHUNK);
        let mut sa = adsorbed.chunks_mut(CHUNK);
        let mut cf = color_free.as_mut().map(|v| v.chunks_mut(CHUNK));
        let mut ch = color_held.as_mut().map(|v| v.chunks_mut(CHUNK));
        let mut ev = evaporated.chunks_mut(CHUNK);
        let mut scale = absorption_scale.map(|a| a.chunks(CHUNK));
        for (area, exposure) in area.chunks(CHUNK).zip(exposure.chunks(CHUNK)) {
            chunks.push(Chunk {
                area,
                exposure,
                absorption_scale: scale.as_mut().map(|it| it.next().unwrap()),
                f: f.next().unwrap(),
                s: s.next().unwrap(),
                p: p.next().unwrap(),
                sp: sp.next().unwrap(),
                sa: sa.next().unwrap(),
                cf: cf.as_mut().map(|it| it.next().unwrap()),
                ch: ch.as_mut().map(|it| it.next().unwrap()),
                evaporated: ev.next().unwrap(),
            });
        }
    }
    chunks.into_par_iter().for_each(|c| c.run(&coeffs));
    Ok(evaporated.iter().sum())
}

fn check_inputs(
    n: usize,
    area: &[f64],
    exposure: &[f64],
    fields: &Fields,
) -> Result<(), ParamError> {
    let length = |name: &'static str, got: usize| {
        if got == n {
            Ok(())
        } else {
            Err(ParamError::Length {
                name,
                expected: n,
                got,
            })
        }
    };
    let scalars: [(&'static str, &[f64]); 7] = [
        ("vertex areas", area),
        ("exposure", exposure),
        ("free solvent", &fields.free_solvent),
        ("solute", &fields.solute),
        ("absorbed solvent", &fields.absorbed_solvent),
        ("absorbed solute", &fields.absorbed_solute),
        ("adsorbed solute", &fields.adsorbed),
    ];
    for (name, v) in scalars {
        length(name, v.len())?;
    }
    let colors: [(&'static str, Option<&[[f64; 3]]>); 2] = [
        ("free colour", fields.color_free.as_deref()),
        ("held colour", fields.color_held.as_deref()),
    ];
    let with_color = colors.iter().any(|(_, c)| c.is_some());
    for (name, c) in colors {
        match c {
            Some(c) => length(name, c.len())?,
            None if with_color => length(name, 0)?,
            None => {}
        }
    }
    // A fast (branch-free, parallel) all-finite test first; the first bad index is
    // searched only when it fails.
    let all_finite = |v: &[f64]| {
        v.par_chunks(CHUNK)
            .all(|c| c.iter().fold(true, |ok, x| ok & x.is_finite()))
    };
    for (name, v) in scalars {
        if !all_finite(v) {
            let index = v.iter().position(|x| !x.is_finite()).unwrap_or(0);
            return Err(ParamError::NonFinite { name, index });
        }
    }
    for (name, c) in colors {
        if let Some(c) = c.filter(|c| !all_finite(c.as_flattened())) {
            let index = c
                .iter()
                .position(|x| x.iter().any(|y| !y.is_finite()))
                .unwrap_or(0);
            return Err(ParamError::NonFinite { name, index });
        }
    }
    for (name, v) in [("vertex area", area), ("exposure", exposure)] {
        if let Some(&value) = v.iter().find(|&&x| x < 0.0) {
            return Err(ParamError::OutOfRange {
                name,
                requirement: "≥ 0",
                value,
            });
        }
    }
    Ok(())
}

/// Per-step constants, shared by all vertices.
struct Coefficients {
    /// `1 − e^{−K_p h}`.
    absorb: f64,
    /// `K_p h` (a vertex with its own absorption scale `s` takes `1 − e^{−s K_p h}`).
    rate_h: f64,
    /// `1 − e^{−K_d h}`.
    adsorb: f64,
    /// `σ_sat`.
    saturation: f64,
    /// `A_d`.
    capacity: f64,
    /// `K_evap h`.
    evaporate: f64,
}

/// A run of consecutive vertices: disjoint slices of every field.
struct Chunk<'a> {
    area: &'a [f64],
    exposure: &'a [f64],
    absorption_scale: Option<&'a [f64]>,
    f: &'a mut [f64],
    s: &'a mut [f64],
    p: &'a mut [f64],
    sp: &'a mut [f64],
    sa: &'a mut [f64],
    cf: Option<&'a mut [[f64; 3]]>,
    ch: Option<&'a mut [[f64; 3]]>,
    evaporated: &'a mut [f64],
}

impl Chunk<'_> {
    fn run(mut self, c: &Coefficients) {
        for i in 0..self.area.len() {
            let mut v = Vertex {
                f: self.f[i],
                s: self.s[i],
                p: self.p[i],
                sp: self.sp[i],
                sa: self.sa[i],
                cf: self.cf.as_ref().map_or([0.0; 3], |x| x[i]),
                ch: self.ch.as_ref().map_or([0.0; 3], |x| x[i]),
            };
            let area = self.area[i];
            let absorb = match self.absorption_scale {
                None => c.absorb,
                Some(scale) => -(-scale[i] * c.rate_h).exp_m1(),
            };
            v.absorb(c.saturation * area, absorb);
            v.adsorb(c.capacity * area, c.adsorb);
            self.evaporated[i] = v.evaporate(self.exposure[i] * c.evaporate * area);
            self.f[i] = v.f;
            self.s[i] = v.s;
            self.p[i] = v.p;
            self.sp[i] = v.sp;
            self.sa[i] = v.sa;
            if let Some(x) = self.cf.as_mut() {
                x[i] = v.cf;
            }
            if let Some(x) = self.ch.as_mut() {
                x[i] = v.ch;
            }
        }
    }
}

/// The state of one vertex (colour zero when the fields carry none).
#[derive(Debug, Clone, Copy)]
struct Vertex {
    f: f64,
    s: f64,
    p: f64,
    sp: f64,
    sa: f64,
    cf: [f64; 3],
    ch: [f64; 3],
}

/// `from −= from·r; to += from·r` per channel (`0 ≤ r ≤ 1`), all of it when `r == 1`.
fn move_color(from: &mut [f64; 3], to: &mut [f64; 3], r: f64) {
    for k in 0..3 {
        let d = if r >= 1.0 { from[k] } else { from[k] * r };
        from[k] -= d;
        to[k] += d;
    }
}

impl Vertex {
    /// Moves all dissolved solute (and its colour) to the absorbed solute.
    fn solute_to_held_all(&mut self) {
        if self.s > 0.0 {
            self.sp += self.s;
            self.s = 0.0;
            move_color(&mut self.cf, &mut self.ch, 1.0);
        }
    }

    /// Absorption toward `cap = σ_sat A`, with `g = 1 − e^{−K_p h}`.
    fn absorb(&mut self, cap: f64, g: f64) {
        let delta = (cap - self.p) * g;
        if delta > 0.0 {
            if self.f <= 0.0 {
                return;
            }
            if delta >= self.f {
                self.p += self.f;
                self.f = 0.0;
                self.solute_to_held_all();
            } else {
                let r = delta / self.f; // < 1
                self.p += delta;
                self.f -= delta;
                if self.s > 0.0 {
                    let ds = self.s * r;
                    self.s -= ds;
                    self.sp += ds;
                    move_color(&mut self.cf, &mut self.ch, r);
                }
            }
        } else if delta < 0.0 {
            // here p > cap ≥ 0 and |delta| < p
            let d = (-delta).min(self.p);
            let r = (d / self.p).min(1.0);
            let held = self.sp + self.sa;
            self.p -= d;
            self.f += d;
            if self.sp > 0.0 {
                let ds = if r >= 1.0 { self.sp } else { self.sp * r };
                self.sp -= ds;
                self.s += ds;
                if held > 0.0 {
                    move_color(&mut self.ch, &mut self.cf, (ds / held).min(1.0));
                }
            }
        }
    }

    /// Langmuir adsorption toward `cap = A_d A`, with `g = 1 − e^{−K_d h}`.
    fn adsorb(&mut self, cap: f64, g: f64) {
        let delta = (cap - self.sa) * g;
        if delta > 0.0 {
            let s = self.s.max(0.0);
            let sp = self.sp.max(0.0);
            let available = s + sp;
            if available <= 0.0 {
                return;
            }
            if delta >= available {
                if s > 0.0 {
                    self.s = 0.0;
                    move_color(&mut self.cf, &mut self.ch, 1.0);
                }
                if sp > 0.0 {
                    self.sp = 0.0;
                }
                self.sa += available;
            } else {
                let r = delta / available; // < 1
                let ds = s * r;
                let dsp = sp * r;
                self.s -= ds;
                self.sp -= dsp;
                self.sa += ds + dsp;
                if s > 0.0 {
                    move_color(&mut self.cf, &mut self.ch, r);
                }
            }
        } else if delta < 0.0 {
            // desorption: here sa > cap ≥ 0 and |delta| < sa
            let d = (-delta).min(self.sa);
            self.sa -= d;
            self.sp += d;
        }
    }

    /// Evaporates up to `e = a_evap K_evap A h`: free solvent first, then absorbed. Dries
    /// the dissolved solute of a vertex left without free solvent. Returns the mass.
    fn evaporate(&mut self, e: f64) -> f64 {
        // `inf · 0` (an overflowing `K_evap h` on a zero-area vertex) evaporates nothing
        let e = if e > 0.0 { e } else { 0.0 };
        let from_free = e.min(self.f.max(0.0));
        self.f -= from_free;
        let from_held = (e - from_free).min(self.p.max(0.0));
        self.p -= from_held;
        if self.f <= 0.0 {
            self.solute_to_held_all();
        }
        from_free + from_held
    }
}

#[cfg(test)]
mod tests;
