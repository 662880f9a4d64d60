//! The simulator's restricted solves (module doc, "In the simulator"): the densities
//! (with the solute diffused or carried by the solvent's fluxes, "Tide lines") and the
//! velocity by warm-started CG on the window's active vertices, each total restored and
//! any negative mass repaired.

use std::borrow::Cow;

use glam::DVec2;

use super::{Conductivity, DENSITY_TOLERANCE, VELOCITY_TOLERANCE};
use crate::error::Error;
use crate::mesh::{Geometry, RingAdjacency, Topology, Transport};
use crate::ops::cg::Preconditioner;
use crate::ops::{CscPattern, Restriction, VertexPattern, WarmCg};
use crate::stain::drain::Potential;
use crate::stain::state::{Fields, merge_rgb, split_rgb};

/// Warm-started CG solvers of the two restricted systems, the densities' and the
/// velocity's (none for an empty restriction).
pub(in crate::stain) fn solvers(
    region: &Restriction,
    reuse: Option<(WarmCg, WarmCg)>,
) -> Option<(WarmCg, WarmCg)> {
    // the two analyses are independent (and the velocity's, on 2×2 blocks, the larger);
    // a former window's solvers lend their memory ([`WarmCg::rebuild`])
    (!region.vertices.is_empty()).then(|| {
        let (a, b) = match reuse {
            Some((a, b)) => (Some(a), Some(b)),
            None => (None, None),
        };
        let make = |old: Option<WarmCg>, pattern: &CscPattern, tolerance: f64| match old {
            Some(mut cg) => {
                cg.rebuild(pattern);
                cg.with_tolerance(tolerance)
            }
            None => WarmCg::new(pattern).with_tolerance(tolerance),
        };
        rayon::join(
            || make(a, region.scalar(), DENSITY_TOLERANCE),
            || {
                make(b, region.scalar(), VELOCITY_TOLERANCE)
                    .with_preconditioner(Preconditioner::SymmetricGaussSeidel)
            },
        )
    })
}

/// The operators of a window the diffusion steps read.
pub(in crate::stain) struct Ops<'a> {
    pub(in crate::stain) topology: &'a Topology,
    pub(in crate::stain) adjacency: &'a RingAdjacency,
    pub(in crate::stain) pattern: &'a VertexPattern,
    pub(in crate::stain) conductivity: &'a Conductivity,
    pub(in crate::stain) region: &'a Restriction,
}

/// How the dissolved solute moves in [`diffuse_densities`] (module doc, "Tide lines").
#[derive(Clone, Copy, Debug)]
pub(in crate::stain) enum SoluteMotion<'a> {
    /// Diffusing with the free solvent's operator (the seed's).
    Diffused,
    /// Carried by the solvents' fluxes; the fibres' solvent on its own operator with these
    /// face scales (a pinned edge) when given, on the free solvent's otherwise.
    Carried {
        held_scale: Option<&'a [f64]>,
        /// How the sweep carries it: the share carried and the dispersivity.
        carry: Carry,
        /// The gravity potential the fibres' liquid diffuses down ([`crate::stain::drain`]),
        /// if any.
        potential: Option<&'a Potential>,
    },
}

/// How [`carry_with_solvent`] carries the solute: the share `φ` of it the flow carries
/// (the rest stays, a Marangoni recirculation), and the longitudinal dispersivity `α_L`
/// (m) of its mechanical dispersion against the flow (module doc, "Tide lines").
#[derive(Clone, Copy, Debug, PartialEq)]
pub(in crate::stain) struct Carry {
    /// `φ` in (0, 1]; 1 carries it all.
    pub fraction: f64,
    /// `α_L` ≥ 0, m; 0 is off.
    pub dispersivity: f64,
}

/// `(M + h K_A) σ' = m` for every flowing field on the active vertices, Neumann at the
/// region's edge ([`crate::ops::restrict`]), then the exact mass restoration and the non-negativity
/// repair; the masses outside are not touched. Returns the work done.
///
/// `solvent_only` solves the solvent alone and leaves the solute (and its colour) as it
/// is: a Picard iteration's trial solve ([`super::Wicking::picard`]), whose solute the
/// next iteration throws away (the wicking rate depends on the liquid alone).
///
/// `film`, per face, gates the free liquid's operator (a run's pinned film,
/// `stain::simulate`, "Runs"): its faces are scaled by it on top of `wicking`, and the
/// fibres' liquid, carried, keeps the ungated operator (its own when `held_scale` is not
/// given).
#[allow(clippy::too_many_arguments)]
pub(in crate::stain) fn diffuse_densities(
    ops: &Ops<'_>,
    cg: &mut WarmCg,
    f: &mut Fields,
    geometry: &Geometry,
    h: f64,
    wicking: Option<&[f64]>,
    film: Option<&[f64]>,
    solute: SoluteMotion<'_>,
    solvent_only: bool,
) -> Result<DensityWork, Error> {
    let (carry, held_scale, how, potential) = match solute {
        SoluteMotion::Diffused => (false, None, None, None),
        SoluteMotion::Carried {
            held_scale,
            carry,
            potential,
        } => (true, held_scale, Some(carry), potential),
    };
    // the free liquid's faces: the wicking's scale times the film's gate; the fibres'
    // liquid, sharing the free operator without a pinned edge, keeps the wicking's alone
    let gated: Option<Vec<f64>> = film.map(|gate| match wicking {
        Some(w) => w.iter().zip(gate).map(|(w, g)| w * g).collect(),
        None => gate.to_vec(),
    });
    let held_scale = match (&gated, held_scale) {
        (Some(_), None) if carry => Some(wicking.map_or_else(
            || Cow::Owned(vec![1.0; ops.topology.n_faces()]),
            Cow::Borrowed,
        )),
        (_, held) => held.map(Cow::Borrowed),
    };
    let held_scale = held_scale.as_deref();
    let wicking = gated.as_deref().or(wicking);
    // the fibres' liquid down the gravity potential: m + hKφ ([`crate::stain::drain`]),
    // along the edges whose upper end holds at least the step; not in a Picard round's trial
    // solve, whose factors settle as the wicking's alone (the gravity takes the settled
    // factors: with it in every round the rounds and halvings tripled on long steps)
    let potential = potential.filter(|_| !solvent_only).map(|p| {
        let density: Vec<f64> = (f.absorbed_solvent.iter().zip(&geometry.vertex_area))
            .map(|(&m, &a)| if a > 0.0 { m / a } else { 0.0 })
            .collect();
        p.gated(ops.topology, &density)
    });
    let how = how.unwrap_or(Carry {
        fraction: 1.0,
        dispersivity: 0.0,
    });
    let region = ops.region;
    let vertices = &region.vertices;
    let nv = vertices.len();
    let area = &geometry.vertex_area;
    // the whole window's stiffness only when the solute follows its fluxes
    let full = carry.then(|| {
        ops.conductivity
            .stiffness(ops.topology, geometry, ops.pattern, h, wicking)
    });
    let values = match &full {
        Some(full) => region.scalar_values(ops.pattern, full, area, false),
        None => ops.conductivity.restricted_values(
            ops.topology,
            geometry,
            ops.pattern,
            region,
            h,
            wicking,
        ),
    };
    // the fibres' liquid on its own, pinned operator (its faces' scales), when carried
    let held_full = held_scale.map(|g| {
        ops.conductivity
            .stiffness(ops.topology, geometry, ops.pattern, h, Some(g))
    });
    // with the solute carried (issue 13 §2) the two solvents, free and in the fibres,
    // are solved, and the solute moves with their fluxes; otherwise the free solvent, the
    // dissolved solute and its colour diffuse alike
    let before =
        (carry && !solvent_only).then(|| (f.free_solvent.clone(), f.absorbed_solvent.clone()));
    let mut color = if solvent_only {
        None
    } else {
        f.color_free.as_ref().map(|c| split_rgb(c))
    };
    let mut fields: Vec<&mut Vec<f64>> = vec![&mut f.free_solvent];
    if carry {
        fields.push(&mut f.absorbed_solvent);
    } else if !solvent_only {
        fields.push(&mut f.solute);
        if let Some(c) = color.as_mut() {
            fields.extend(c.iter_mut());
        }
    }
    let mut rhs: Vec<f64> = fields
        .iter()
        .flat_map(|m| vertices.iter().map(|&v| m[v as usize]))
        .collect();
    // warm start: the densities the masses have now (after advection) on the new areas —
    // the solution for h → 0, closer than the last step's solution because the liquid has
    // moved since
    let mut sigma: Vec<f64> = rhs
        .iter()
        .enumerate()
        .map(|(k, m)| {
            let a = area[vertices[k % nv] as usize];
            if a > 0.0 { m / a } else { 0.0 }
        })
        .collect();
    // (after the warm start: the masses' own densities are the closer guess)
    if let Some(potential) = &potential {
        let stiffness = held_full
            .as_ref()
            .or(full.as_ref())
            .expect("carried: a stiffness");
        let source = potential_source(ops, stiffness, potential);
        for (j, &v) in vertices.iter().enumerate() {
            rhs[nv + j] += source[v as usize];
        }
    }
    let mut work = DensityWork {
        iterations: 0,
        solves: fields.len(),
        carried: 0,
    };
    work.iterations = match &held_full {
        None => {
            cg.solve_chained(&values, &rhs, &mut sigma)?;
            cg.last_iterations
        }
        Some(held) => {
            let held_values = region.scalar_values(ops.pattern, held, area, false);
            cg.solve(&values, &rhs[..nv], &mut sigma[..nv])?;
            let free = cg.last_iterations;
            cg.solve(&held_values, &rhs[nv..], &mut sigma[nv..])?;
            free + cg.last_iterations
        }
    };
    for (k, m) in fields.iter_mut().enumerate() {
        let before: f64 = vertices.iter().map(|&v| m[v as usize]).sum();
        let sigma = &sigma[k * nv..(k + 1) * nv];
        for (j, &v) in vertices.iter().enumerate() {
            m[v as usize] = area[v as usize] * sigma[j];
        }
        repair_negative(ops.adjacency, m, vertices, &region.mask);
        let after: f64 = vertices.iter().map(|&v| m[v as usize]).sum();
        if after > 0.0 && before > 0.0 {
            let scale = before / after;
            vertices.iter().for_each(|&v| m[v as usize] *= scale);
        }
    }
    if let (Some((free, held)), Some(full)) = (&before, &full) {
        // the dissolved solute and its colour with the free solvent
        let mut moves: Vec<(&mut Vec<f64>, Vec<f64>)> = vec![(&mut f.solute, Vec::new())];
        if let Some(c) = color.as_mut() {
            moves.extend(c.iter_mut().map(|c| (c, Vec::new())));
        }
        for (target, movable) in moves.iter_mut() {
            *movable = target.to_vec();
        }
        work.carried += moves.len();
        carry_with_solvent(
            ops,
            full,
            &sigma[..nv],
            (free, &f.free_solvent),
            &mut moves,
            how,
            &geometry.edge_length,
            None,
        );
        // the absorbed solute with the solvent in the fibres; the held colour pool
        // (absorbed + adsorbed) gives up the absorbed solute's share
        let held_color = f.color_held.as_ref().map(|c| split_rgb(c));
        let (sp, sa) = (&f.absorbed_solute, &f.adsorbed);
        let mut held_moves: Vec<(Vec<f64>, Vec<f64>)> = vec![(sp.clone(), sp.clone())];
        if let Some(hc) = &held_color {
            for c in hc {
                let movable = (0..c.len())
                    .map(|v| {
                        let pool = sp[v] + sa[v];
                        if pool > 0.0 {
                            c[v] * (sp[v].max(0.0) / pool)
                        } else {
                            0.0
                        }
                    })
                    .collect();
                held_moves.push((c.clone(), movable));
            }
        }
        let mut refs: Vec<(&mut Vec<f64>, Vec<f64>)> = held_moves
            .iter_mut()
            .map(|(t, m)| (t, std::mem::take(m)))
            .collect();
        work.carried += refs.len();
        carry_with_solvent(
            ops,
            held_full.as_ref().unwrap_or(full),
            &sigma[nv..2 * nv],
            (held, &f.absorbed_solvent),
            &mut refs,
            how,
            &geometry.edge_length,
            potential.as_ref(),
        );
        drop(refs);
        let mut held_moves = held_moves.into_iter();
        f.absorbed_solute = held_moves.next().expect("the absorbed solute").0;
        if let Some(ch) = f.color_held.as_mut() {
            let c: Vec<Vec<f64>> = held_moves.map(|(t, _)| t).collect();
            merge_rgb(&[c[0].clone(), c[1].clone(), c[2].clone()], ch);
        }
    }
    if let (Some(c), Some(cf)) = (color, f.color_free.as_mut()) {
        merge_rgb(&c, cf);
    }
    Ok(work)
}

/// `hKφ` per window vertex (zero outside the region): `Σ_b w_ab (φ_a − φ_b)` over the
/// region's edges, `w_ab = −K_ab` of the `h`-scaled `stiffness` ([`crate::stain::drain`]).
/// Antisymmetric edge by edge, so it sums to zero: it moves mass and adds none.
fn potential_source(ops: &Ops<'_>, stiffness: &[f64], potential: &Potential) -> Vec<f64> {
    let region = ops.region;
    let slot = ops.pattern.edge_slot();
    let mut source = vec![0.0; region.mask.len()];
    for (e, &[a, b]) in ops.topology.edges().iter().enumerate() {
        let (a, b) = (a as usize, b as usize);
        if region.mask[a] && region.mask[b] {
            let flow = -stiffness[slot[e] as usize] * potential.edge[e];
            source[a] += flow;
            source[b] -= flow;
        }
    }
    source
}

/// What one density diffusion did (counted for [`crate::stain::Profile`]).
#[derive(Default)]
pub(in crate::stain) struct DensityWork {
    /// CG iterations over all solved fields.
    pub iterations: usize,
    /// Fields solved (one CG solve each).
    pub solves: usize,
    /// Fields carried along the solved solvent's fluxes (the solute and its colour).
    pub carried: usize,
}

impl std::ops::AddAssign for DensityWork {
    fn add_assign(&mut self, more: Self) {
        self.iterations += more.iterations;
        self.solves += more.solves;
        self.carried += more.carried;
    }
}

/// Most Gauss–Seidel sweeps of the carried solute's concentrations ([`carry_with_solvent`]).
const MAX_CARRY_SWEEPS: usize = 50;
/// Most symmetric Gauss–Seidel sweeps (each direction counted) with a dispersivity.
const MAX_DISPERSED_SWEEPS: usize = 400;

/// Moves the solute (and its colour) with the solvent's diffusive fluxes of the solve
/// just made (issue 13 §2, "Tide lines" in the module doc). Across every edge `a–b` of
/// the region the solvent moved `F_ab = −h K_ab (σ'_a − σ'_b)` (kg, `a → b`; with the
/// gravity `potential`, `−h K_ab ((σ'_a − φ_a) − (σ'_b − φ_b))`, [`crate::stain::drain`],
/// and the sweep goes down `σ' − φ`), and the
/// solute goes with it at the concentration `c = s/f` of the vertex it leaves, **at the
/// end of the step** (implicit upwind, as the solvent's own step is implicit):
///
/// ```text
/// c'_a (f_a + in_a − out_a) = s_a − c'_a out_a + Σ_{b → a} F_ba c'_b,
/// ```
///
/// `f_a` the solvent before, `in_a`, `out_a` its in- and outflow. Diffusive fluxes run
/// down the solved density, so in order of decreasing `σ'` every inflow comes from a
/// vertex already solved: one sweep solves the system exactly. (A flux uphill, from a
/// negative cotan weight on an obtuse mesh, is taken explicitly at the old
/// concentration, limited to the solvent the vertex held.) Every transfer is between two
/// vertices, so the total is exact; the weights are non-negative, so no mass goes
/// negative; and `c' = c` solves it when `c` is uniform: a solution of one strength keeps
/// it wherever the solvent takes it, however sharp the solvent's front and however
/// long the step. (With the concentration of the start of the step instead, a vertex
/// the front crosses within the step passes on more solvent than it held and its
/// concentration came out 3× wrong.)
///
/// With a carried fraction `φ < 1` ([`Carry`]) only `φ` of the movable solute enters the
/// sweep and the rest stays where it is. With a dispersivity `α_L > 0` the solute also
/// disperses along every edge that carries solvent, mechanical dispersion `j = −α_L |q| ∇c`
/// (Bear 1972) integrated over the step: `D_ab = α_ab |F_ab| / ℓ_ab` (kg) couples
/// `c'_a` and `c'_b` symmetrically,
///
/// ```text
/// c'_a (f_a + in_a + Σ_b D_ab) = s_a + Σ_{b → a} F_ba c'_b + Σ_b D_ab c'_b,
/// ```
///
/// with `α_ab = max(α_L − ℓ_ab/2, 0)`: the upwind sweep already disperses by half an edge,
/// so the total is `α_L` on any mesh finer than `2 α_L`. A solute carried into a pinned
/// edge then piles up as `c ∝ exp(−x/α_L)` behind it (the Péclet balance `u c = D c'`), a
/// ring about `α_L` wide, not one cell. The weights stay non-negative and `c' = c` still
/// solves it for a uniform solution. The dispersion couples every vertex to its upstream
/// neighbours, so one sweep down the density no longer solves it: symmetric Gauss–Seidel
/// (down the density, then back up), started from the concentrations before the step,
/// until the largest change is `10⁻¹³` of the largest concentration. (Plain sweeps down
/// the density from zero, stopped after 50, left the solute behind the liquid on a mesh of
/// 1/3 mm: wine's centre came out twice as dark as on 2/3 mm.)
///
/// `before` and `after` are the solvent before the solve and now (window numbering; the
/// solute ends at `c'` times the solvent now), `sigma` its solved densities (region
/// order); each move is a mass field and the part of it that moves
/// (the field itself, or the moving solute's share of a colour pool); `edge_length` the
/// mesh's edges' lengths.
#[allow(clippy::too_many_arguments)]
pub(super) fn carry_with_solvent(
    ops: &Ops<'_>,
    stiffness: &[f64],
    sigma: &[f64],
    (before, after): (&[f64], &[f64]),
    moves: &mut [(&mut Vec<f64>, Vec<f64>)],
    how: Carry,
    edge_length: &[f64],
    potential: Option<&Potential>,
) {
    let region = ops.region;
    let n = before.len();
    let mut density = vec![0.0; n];
    for (j, &v) in region.vertices.iter().enumerate() {
        density[v as usize] = sigma[j];
    }
    // the sweep order: decreasing solved density, or potential `σ' − φ` with gravity
    // (ties by vertex), and each vertex's rank
    let rank_of = |v: usize| density[v] - potential.map_or(0.0, |p| p.vertex[v]);
    let mut order: Vec<u32> = region.vertices.clone();
    order.sort_by(|&a, &b| {
        rank_of(b as usize)
            .total_cmp(&rank_of(a as usize))
            .then(a.cmp(&b))
    });
    let mut rank = vec![u32::MAX; n];
    for (k, &v) in order.iter().enumerate() {
        rank[v as usize] = k as u32;
    }
    let slot = ops.pattern.edge_slot();
    // (upwind, downwind, solvent moved, edge) for every edge inside the region
    let flows: Vec<(usize, usize, f64, usize)> = ops
        .topology
        .edges()
        .iter()
        .enumerate()
        .filter(|(_, e)| region.mask[e[0] as usize] && region.mask[e[1] as usize])
        .filter_map(|(e, &[a, b])| {
            let (a, b) = (a as usize, b as usize);
            let step = potential.map_or(0.0, |p| p.edge[e]);
            let flow = -stiffness[slot[e] as usize] * (density[a] - density[b] - step);
            match flow.partial_cmp(&0.0) {
                Some(std::cmp::Ordering::Greater) => Some((a, b, flow, e)),
                Some(std::cmp::Ordering::Less) => Some((b, a, -flow, e)),
                _ => None,
            }
        })
        .collect();
    let mut inflow = vec![0.0; n];
    let mut incoming: Vec<Vec<(u32, f64)>> = vec![Vec::new(); n];
    let mut uphill = false;
    for &(from, to, amount, _) in &flows {
        inflow[to] += amount;
        incoming[to].push((from as u32, amount));
        uphill |= rank[from] > rank[to];
    }
    // the dispersion's couplings D_ab, both ways, and their sums
    let mut dispersed: Vec<Vec<(u32, f64)>> = Vec::new();
    let mut dispersion = Vec::new();
    if how.dispersivity > 0.0 {
        dispersed = vec![Vec::new(); n];
        dispersion = vec![0.0; n];
        for &(from, to, amount, e) in &flows {
            let l = edge_length[e];
            let alpha = (how.dispersivity - 0.5 * l).max(0.0);
            if l > 0.0 && alpha > 0.0 {
                let d = alpha * amount / l;
                dispersed[from].push((to as u32, d));
                dispersed[to].push((from as u32, d));
                dispersion[from] += d;
                dispersion[to] += d;
            }
        }
        uphill = true;
    }
    // the vertices the sweep can change: those that hold or receive solvent, or take part
    // in the dispersion (any other comes out 0, as its concentration starts)
    let swept: Vec<u32> = order
        .iter()
        .copied()
        .filter(|&v| {
            let v = v as usize;
            before[v] + inflow[v] + dispersion.get(v).copied().unwrap_or(0.0) > 0.0
        })
        .collect();
    let dispersing = !dispersion.is_empty();
    for (target, movable) in moves.iter_mut() {
        // what cannot move stays: a vertex without solvent holds its solute in place
        let mut mobile: Vec<f64> = (0..n)
            .map(|v| {
                if before[v] > 0.0 {
                    movable[v].max(0.0)
                } else {
                    0.0
                }
            })
            .collect();
        if how.fraction < 1.0 {
            mobile.iter_mut().for_each(|m| *m *= how.fraction);
        }
        for &v in &order {
            target[v as usize] -= mobile[v as usize];
        }
        // c'_a = (s_a + Σ_in F_ba c'_b) / (f_a + in_a): one sweep down the density when
        // every flux runs downhill, Gauss–Seidel sweeps in that order otherwise; with the
        // dispersion, which couples each vertex to its upstream too, symmetric sweeps
        // (down the density, then back up) from the concentrations before the step
        let mut conc = vec![0.0; n];
        if dispersing {
            for &v in &order {
                let v = v as usize;
                if before[v] > 0.0 {
                    conc[v] = mobile[v] / before[v];
                }
            }
        }
        let most = if dispersing {
            MAX_DISPERSED_SWEEPS
        } else {
            MAX_CARRY_SWEEPS
        };
        for sweep in 0..most {
            let mut change: f64 = 0.0;
            let mut size: f64 = 0.0;
            let back = dispersing && sweep % 2 == 1;
            for k in 0..swept.len() {
                let v = swept[if back { swept.len() - 1 - k } else { k }] as usize;
                let mut gathered: f64 =
                    incoming[v].iter().map(|&(b, f)| f * conc[b as usize]).sum();
                let mut held = before[v] + inflow[v];
                if !dispersion.is_empty() {
                    gathered += dispersed[v]
                        .iter()
                        .map(|&(b, d)| d * conc[b as usize])
                        .sum::<f64>();
                    held += dispersion[v];
                }
                let c = if held > 0.0 {
                    (mobile[v] + gathered) / held
                } else {
                    0.0
                };
                change = change.max((c - conc[v]).abs());
                size = size.max(c);
                conc[v] = c;
            }
            if !uphill || (sweep > usize::from(dispersing) && change <= 1e-13 * size) {
                break;
            }
        }
        // the solute in the solvent as it is now (after the negative-mass repair and the
        // restoration of its total), then the total restored: exact for a uniform
        // solution, and the rounding of the sweep otherwise
        let moving: f64 = order
            .iter()
            .map(|&v| {
                let v = v as usize;
                if before[v] > 0.0 {
                    movable[v].max(0.0)
                } else {
                    0.0
                }
            })
            .sum::<f64>()
            * how.fraction;
        let mut total = 0.0;
        for &v in &order {
            let v = v as usize;
            mobile[v] = conc[v] * after[v].max(0.0);
            total += mobile[v];
        }
        let scale = if total > 0.0 { moving / total } else { 0.0 };
        for &v in &order {
            let v = v as usize;
            target[v] += mobile[v] * scale;
        }
    }
}

/// Eq. 4.6 on the active vertices with clamped (non-negative) edge weights,
/// `(M ⊗ I + h ν K_∇) u' = (M ⊗ I) u` with `scale = h ν`: the block rows and columns of
/// the active vertices, diagonal blocks `K_ii = Σ_{j active} L_ij`; the velocities
/// outside are not touched. Returns the CG iterations.
pub(in crate::stain) fn diffuse_velocity(
    ops: &Ops<'_>,
    cg: &mut WarmCg,
    velocity: &mut [DVec2],
    geometry: &Geometry,
    transport: &Transport,
    scale: f64,
) -> Result<usize, Error> {
    let region = ops.region;
    let area = &geometry.vertex_area;
    // `cotan_stiffness(scale)` on the region's faces, clamped
    let scalar = region.values_from_faces(ops.topology, area, true, |f| {
        geometry.face_cot[f].map(|c| -0.5 * scale * c)
    });
    let nv = region.vertices.len();
    let mut rhs = Vec::with_capacity(2 * nv);
    let mut x = Vec::with_capacity(2 * nv);
    for &v in &region.vertices {
        let (a, u) = (area[v as usize], velocity[v as usize]);
        rhs.extend([a * u.x, a * u.y]);
        x.extend([u.x, u.y]);
    }
    cg.solve_rotated(
        &scalar,
        region.entry_edges(),
        transport.edge_cos_sin(),
        &rhs,
        &mut x,
    )?;
    for (j, &v) in region.vertices.iter().enumerate() {
        velocity[v as usize] = DVec2::new(x[2 * j], x[2 * j + 1]);
    }
    Ok(cg.last_iterations)
}

/// Fills negative masses among `vertices` (increasing) from their positive neighbours
/// where `mask` (in proportion to their masses), then from all positive `vertices` if the
/// neighbours cannot cover the deficit; conservative, sequential (deterministic), and a
/// no-op when nothing is negative. The masses outside `mask` are not touched.
fn repair_negative(adjacency: &RingAdjacency, mass: &mut [f64], vertices: &[u32], mask: &[bool]) {
    if !vertices.iter().any(|&v| mass[v as usize] < 0.0) {
        return;
    }
    let inside = |j: usize| mask[j];

    let mut leftover = 0.0;
    for &i in vertices {
        let i = i as usize;
        if mass[i] >= 0.0 {
            continue;
        }
        let deficit = -mass[i];
        mass[i] = 0.0;
        let ring = adjacency.neighbours(i);
        let pool: f64 = ring
            .iter()
            .filter(|&&j| inside(j as usize))
            .map(|&j| mass[j as usize].max(0.0))
            .sum();
        let take = deficit.min(pool);
        if take > 0.0 {
            let frac = take / pool;
            for &j in ring.iter().filter(|&&j| inside(j as usize)) {
                let m = &mut mass[j as usize];
                if *m > 0.0 {
                    *m -= *m * frac;
                }
            }
        }
        leftover += deficit - take;
    }
    if leftover > 0.0 {
        let pool: f64 = vertices
            .iter()
            .map(|&v| mass[v as usize])
            .filter(|m| *m > 0.0)
            .sum();
        if pool > 0.0 {
            let keep = (1.0 - leftover / pool).max(0.0);
            vertices.iter().for_each(|&v| mass[v as usize] *= keep);
        }
    }
}
