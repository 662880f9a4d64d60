//! One sub-step of the window, phase by phase (module doc, steps 1–5): the geometry at
//! the sub-step's end, the first half kick of the forces, the advection, the second half
//! kick, the diffusion and the interactions; each phase's seconds go into its
//! [`Profile`] time.

use glam::{DVec2, DVec3};
use rayon::prelude::*;

use super::profile::{Laps, Profile};
use super::scratch::SubstepScratch;
use super::{DRY_DENSITY, Simulator, StainParams};
use crate::error::Error;
use crate::mesh::Geometry;
use crate::stain::advect::{UpwindPlan, advect_velocity_in, dual_fluxes_in};
use crate::stain::diffuse::{
    Carry, DensityWork, MAX_PICARD, Ops, SoluteMotion, diffuse_densities, diffuse_velocity,
};
use crate::stain::drain::{Potential, edge_steps};
use crate::stain::drip;
use crate::stain::extend::{extend_velocity, wet_vertices};
use crate::stain::forces::{VelocityStep, frame_angular_velocity, frame_body_acceleration};
use crate::stain::interact::{exposure, interact_varied, vapour_exposure};
use crate::stain::irregular::face_means;
use crate::stain::state::{Fields, Local, merge_rgb, split_rgb};
use crate::stain::window::{Cloth, Window, pick};

impl Simulator {
    /// One sub-step `h` of the window to positions `q` (window order), whose vertex frames
    /// are in `sub.frames` if `frames_ready` and whose frames' turns `ω_z` over the
    /// sub-step are `turns` if the caller has them; in `sub`'s arrays.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn substep(
        &self,
        w: &mut Window,
        loc: &mut Local,
        q: &[DVec3],
        frames_ready: bool,
        turns: Option<&[f64]>,
        h: f64,
        acceleration: &[DVec3],
        prof: &mut Profile,
        sub: &mut SubstepScratch,
    ) -> Result<(), Error> {
        let mut laps = Laps::start();
        Self::geometry_phase(w, q, frames_ready, sub)?;
        let topo = &w.cloth.topology;
        prof.active_vertices += w.region.vertices.len();
        prof.window_vertices += w.vertices.len();
        prof.window_edges += topo.n_edges();
        prof.window_faces += topo.n_faces();
        laps.lap(&mut prof.geometry);

        self.first_half_kick(w, loc, turns, h, acceleration, sub);
        laps.lap(&mut prof.forces);

        self.advection_phase(w, loc, q, h, prof, sub)?;
        self.drip_phase(w, loc, q, acceleration);
        laps.lap(&mut prof.advection);

        self.second_half_kick(loc, sub);
        laps.lap(&mut prof.forces);

        self.diffusion_phase(w, loc, q, acceleration, h, prof, sub)?;
        laps.lap(&mut prof.diffusion);

        self.interaction_phase(w, loc, h, sub)?;
        std::mem::swap(&mut loc.frames, &mut sub.frames);
        std::mem::swap(&mut loc.area, &mut sub.geometry.vertex_area);
        laps.lap(&mut prof.interaction);
        prof.substeps += 1;
        Ok(())
    }

    /// The geometry at positions `q` into `sub`: lengths, areas and cotangents, the vertex
    /// frames (unless `frames_ready`) and the transport `R_ij`.
    fn geometry_phase(
        w: &Window,
        q: &[DVec3],
        frames_ready: bool,
        sub: &mut SubstepScratch,
    ) -> Result<(), Error> {
        let topo = &w.cloth.topology;
        sub.geometry.renew(topo, q)?;
        if !frames_ready {
            w.corotating_frames_into(q, &mut sub.frames);
        }
        sub.transport.renew(
            topo,
            &w.cloth.rings,
            &sub.geometry,
            &sub.frames,
            q,
            w.tip_share.as_deref(),
        );
        Ok(())
    }

    /// Step 1 of the module doc, body forces (§4.4): the first half kick into
    /// `sub.forced` and the sub-step's mean velocity under them into `sub.mean`, both
    /// extended over the dry cloth.
    fn first_half_kick(
        &self,
        w: &Window,
        loc: &Local,
        turns: Option<&[f64]>,
        h: f64,
        acceleration: &[DVec3],
        sub: &mut SubstepScratch,
    ) {
        let p = &self.params;
        let n = w.vertices.len();
        let topo = &w.cloth.topology;
        let (geometry, frames, transport) = (&sub.geometry, &sub.frames, &sub.transport);
        // body forces (§4.4), friction and the Coriolis turn, exactly over half the
        // sub-step at the vertex the liquid leaves (kick–drift–kick, module doc); the
        // densities drift with the exact mean velocity of a whole sub-step under them
        // — each vertex's half kick is the same propagator before and after the
        // advection (the same turn, friction and h/2), and the decay e^{-kh} is every
        // vertex's: both computed once (`VelocityStep`, the same bits as separate calls)
        let (decay_half, decay_full) = (
            VelocityStep::decay(p.friction, 0.5 * h),
            VelocityStep::decay(p.friction, h),
        );
        (0..n)
            .into_par_iter()
            .map(|j| {
                let f = &frames.frame[j];
                let a = frame_body_acceleration(f, acceleration[j], p.gravity, p.forces);
                let turn = match turns {
                    Some(t) => t[j],
                    None if p.forces.coriolis => {
                        frame_angular_velocity(&loc.frames.frame[j], f, h).z
                    }
                    None => 0.0,
                };
                let half = VelocityStep::with_decay(decay_half, turn, p.friction, 0.5 * h);
                (a, turn, half)
            })
            .collect_into_vec(&mut sub.force);
        let force = &sub.force;
        let (forced, mean) = (&mut sub.forced, &mut sub.mean);
        force
            .par_iter()
            .zip(&loc.velocity)
            .map(|(&(a, turn, half), &u)| {
                let full = VelocityStep::with_decay(decay_full, turn, p.friction, h);
                (half.end(u, a), full.mean(u, a))
            })
            .unzip_into_vecs(forced, mean);
        // the velocity is the liquid's: on the dry cloth it is the wet region's, extended
        let wet = wet_vertices(
            &loc.fields.free_solvent,
            &geometry.vertex_area,
            &w.region.mask,
        );
        extend_velocity(topo, transport, &wet, &mut [forced, mean]);
    }

    /// Step 2 of the module doc: advection (§4.3.1–4.3.2), closed inside the active region:
    /// the velocity (`sub.advected`, semi-Lagrangian), the dual fluxes of the sub-step's
    /// centred velocity and their upwind plan, then the densities (and with the momentum
    /// form the solvent's momentum, into `sub.arrived`).
    fn advection_phase(
        &self,
        w: &Window,
        loc: &mut Local,
        q: &[DVec3],
        h: f64,
        prof: &mut Profile,
        sub: &mut SubstepScratch,
    ) -> Result<(), Error> {
        let p = &self.params;
        let n = w.vertices.len();
        let topo = &w.cloth.topology;
        let SubstepScratch {
            geometry,
            frames,
            transport,
            forced,
            mean,
            advected,
            centred,
            arrived,
            flux,
            plan,
            ..
        } = sub;
        let (forced, mean) = (&*forced, &*mean);
        let active = &w.region.mask;
        let mut part = Laps::start();
        advect_velocity_in(
            topo,
            &w.cloth.rings,
            geometry,
            transport,
            forced,
            h,
            active,
            advected,
        );
        let advected = &*advected;
        part.lap(&mut prof.advection_trace);
        // the densities move with the sub-step's mean velocity: the exact mean under the
        // forces, plus half the change the advection made at its end (module doc)
        (0..n)
            .into_par_iter()
            .map(|j| {
                if active[j] {
                    mean[j] + 0.5 * (advected[j] - forced[j])
                } else {
                    DVec2::ZERO
                }
            })
            .collect_into_vec(centred);
        dual_fluxes_in(
            topo,
            q,
            frames,
            centred,
            active,
            w.tip_share.as_deref(),
            flux,
        );
        let plan = plan.get_or_insert_with(UpwindPlan::empty);
        plan.renew(topo, &geometry.vertex_area, flux, h)?;
        let plan = &*plan;
        prof.transport_cycles += plan.substeps();
        loc.cycles += plan.substeps();
        part.lap(&mut prof.advection_plan);
        // the densities, and with the momentum form the solvent's momentum alongside
        let f = &mut loc.fields;
        let mut color = f.color_free.as_ref().map(|c| split_rgb(c));
        let mut fields: Vec<&mut [f64]> = vec![&mut f.free_solvent, &mut f.solute];
        if let Some(c) = color.as_mut() {
            fields.extend(c.iter_mut().map(|v| v.as_mut_slice()));
        }
        // the run's holdup (module doc, "Runs"): the pinned film stays out of the transport
        let held = (p.holdup > 0.0).then(|| {
            let irregular = w.cloth.irregular.as_deref();
            hold_back(
                &mut fields,
                &geometry.vertex_area,
                active,
                p.holdup,
                irregular,
            )
        });
        prof.transport_passes += plan.substeps() * fields.len();
        if p.momentum_advection {
            plan.transport_with_momentum_into(
                topo,
                transport,
                &mut fields,
                forced,
                advected,
                arrived,
            );
        } else {
            plan.transport_all(topo, &mut fields);
        }
        if let Some(held) = held {
            for (field, kept) in fields.iter_mut().zip(&held) {
                for (m, k) in field.iter_mut().zip(kept) {
                    *m += k;
                }
            }
        }
        if let (Some(c), Some(cf)) = (color, f.color_free.as_mut()) {
            merge_rgb(&c, cf);
        }
        part.lap(&mut prof.advection_apply);
        Ok(())
    }

    /// After the transport: what reached a hanging hem beyond what it holds drips off
    /// ([`crate::stain::drip`]), at the window's whole vertices on the cloth's border.
    fn drip_phase(&self, w: &Window, loc: &mut Local, q: &[DVec3], acceleration: &[DVec3]) {
        let p = &self.params;
        if p.drip_hold <= 0.0 {
            return;
        }
        let on: Vec<u32> = w
            .whole
            .iter()
            .copied()
            .filter(|&j| w.cloth.boundary[j as usize])
            .collect();
        if on.is_empty() {
            return;
        }
        let (length, outward) = drip::border_normals(&w.cloth.topology, q);
        let gravity = if p.forces.gravity {
            p.gravity
        } else {
            DVec3::ZERO
        };
        let (solvent, solute) = drip::drip(
            &mut loc.fields,
            &on,
            &length,
            &outward,
            acceleration,
            gravity,
            p.drip_hold,
        );
        loc.dripped.0 += solvent;
        loc.dripped.1 += solute;
    }

    /// Step 3 of the module doc: forces, the second half kick, at the vertex the liquid
    /// arrived at (the velocity the advection gave: `sub.arrived` with the momentum form,
    /// else `sub.advected`), which becomes the frame's velocity.
    fn second_half_kick(&self, loc: &mut Local, sub: &mut SubstepScratch) {
        let arrived = if self.params.momentum_advection {
            &mut sub.arrived
        } else {
            &mut sub.advected
        };
        // the second half of the forces, at the vertex the liquid arrived at
        arrived
            .par_iter_mut()
            .zip(&sub.force)
            .for_each(|(u, (a, _, half))| *u = half.end(*u, *a));
        std::mem::swap(&mut loc.velocity, arrived);
    }

    /// Step 4 of the module doc: diffusion (§4.3.3–4.3.4, eq. 4.6): the densities and the
    /// velocity, solved side by side ([`crate::stain::diffuse`]).
    #[allow(clippy::too_many_arguments)]
    fn diffusion_phase(
        &self,
        w: &mut Window,
        loc: &mut Local,
        q: &[DVec3],
        acceleration: &[DVec3],
        h: f64,
        prof: &mut Profile,
        sub: &SubstepScratch,
    ) -> Result<(), Error> {
        let p = &self.params;
        let potential = self.potential(w, q, acceleration);
        let potential = potential.as_ref();
        let topo = &w.cloth.topology;
        let (geometry, transport) = (&sub.geometry, &sub.transport);
        // the densities and the velocity are independent systems, solved side by side
        let ops = Ops {
            topology: topo,
            adjacency: &w.cloth.adjacency,
            pattern: &w.pattern,
            conductivity: &w.cloth.conductivity,
            region: &w.region,
        };
        // the wicking factor of every face, from the liquid before the solve (lagged),
        // times the irregular fabric's; the mobile faces from the same liquid
        let cloth = &w.cloth;
        // (the irregular fabric's factors and the mobile faces stay over the sub-step)
        let irregular = cloth.irregular.as_ref().map(|m| face_means(topo, m));
        let mobile = self.mobile_faces(cloth, &loc.fields, geometry);
        let face_scale = self.face_scale(cloth, &loc.fields, geometry, irregular.as_deref());
        let held_scale = mobile
            .as_deref()
            .map(|m| held_faces(m, face_scale.as_deref()));
        // the run's pinned film out of the free liquid's spreading (module doc, "Runs"),
        // from the liquid before the solve, over the sub-step
        let film = self.film_gate(cloth, &loc.fields, geometry, &sub.force);
        let film = film.as_deref();
        // Picard iterations (`Wicking::picard`) solve again from the step's start
        let picard = if p.wicking.is_on() {
            p.wicking.picard
        } else {
            0
        };
        // a tolerance iterates until the front stops, `picard` rounds at least
        let converge = p.wicking.is_on() && p.wicking.tolerance > 0.0;
        let iterate = picard > 0 || converge;
        let (fields, velocity) = (&mut loc.fields, &mut loc.velocity);
        let (densities, viscous) = match w.cg.as_mut() {
            None => (
                Ok(DensityWork {
                    iterations: 0,
                    solves: 0,
                    carried: 0,
                }),
                Ok(0),
            ),
            Some((scalar_cg, vector_cg)) => {
                scalar_cg.set_tolerance(self.tolerances[0]);
                vector_cg.set_tolerance(self.tolerances[1]);
                rayon::join(
                    || {
                        // one piece of the step: the lagged solve (a trial when Picard
                        // rounds follow), then the rounds; whether its factors settled,
                        // and the fields it started from (kept for the rounds anyway, so
                        // a piece cut in halves needs no copy of its own)
                        let mut piece =
                            |fields: &mut Fields,
                             hp: f64,
                             g0: Option<&[f64]>,
                             held0: Option<&[f64]>|
                             -> Result<(DensityWork, bool, Option<Fields>), Error> {
                                let start = iterate.then(|| fields.clone());
                                let mut work = diffuse_densities(
                                    &ops,
                                    scalar_cg,
                                    fields,
                                    geometry,
                                    hp,
                                    g0,
                                    film,
                                    solute_motion(p, held0, potential),
                                    start.is_some(),
                                )?;
                                let Some(start) = start else {
                                    return Ok((work, true, None));
                                };
                                // the piece again from its start with the factors `g` (the
                                // solute moves once, with the last solve's fluxes)
                                let mut again = |fields: &mut Fields, g: Option<&[f64]>, trial| {
                                    fields.clone_from(&start);
                                    let held = mobile.as_deref().map(|m| held_faces(m, g));
                                    diffuse_densities(
                                        &ops,
                                        scalar_cg,
                                        fields,
                                        geometry,
                                        hp,
                                        g,
                                        film,
                                        solute_motion(p, held.as_deref(), potential),
                                        trial,
                                    )
                                };
                                let mut last = g0.map(<[f64]>::to_vec);
                                let mut settled = true;
                                for round in 1.. {
                                    // the factors of the last solution; with a tolerance on
                                    // until they settle (`Wicking::tolerance`)
                                    let g = self.face_scale(
                                        cloth,
                                        fields,
                                        geometry,
                                        irregular.as_deref(),
                                    );
                                    let done = if converge {
                                        let stops = round >= picard
                                            && factors_settled(
                                                last.as_deref(),
                                                g.as_deref(),
                                                p.wicking.tolerance,
                                            );
                                        settled = stops;
                                        stops || round >= MAX_PICARD
                                    } else {
                                        round >= picard
                                    };
                                    work += again(fields, g.as_deref(), !done)?;
                                    if done {
                                        break;
                                    }
                                    last = g;
                                }
                                Ok((work, settled, Some(start)))
                            };
                        // the step, cut in halves where a piece's front does not settle in
                        // MAX_PICARD rounds ("Long steps" in `Wicking`'s doc): a stack of
                        // pieces, each (length, halvings), the next at the top
                        let mut work = DensityWork::default();
                        let mut pieces = vec![(h, 0u32)];
                        let mut first = true;
                        while let Some((hp, halvings)) = pieces.pop() {
                            let (more, settled, start) = if first {
                                piece(fields, hp, face_scale.as_deref(), held_scale.as_deref())?
                            } else {
                                let g =
                                    self.face_scale(cloth, fields, geometry, irregular.as_deref());
                                let held = mobile.as_deref().map(|m| held_faces(m, g.as_deref()));
                                piece(fields, hp, g.as_deref(), held.as_deref())?
                            };
                            work += more;
                            match start {
                                Some(start) if converge && !settled && halvings < MAX_HALVINGS => {
                                    // the piece again, as two halves from its start
                                    *fields = start;
                                    pieces.push((0.5 * hp, halvings + 1));
                                    pieces.push((0.5 * hp, halvings + 1));
                                }
                                _ => {}
                            }
                            first = false;
                        }
                        Ok::<_, Error>(work)
                    },
                    || {
                        if p.viscosity > 0.0 {
                            let scale = h * p.viscosity;
                            diffuse_velocity(&ops, vector_cg, velocity, geometry, transport, scale)
                        } else {
                            Ok(0)
                        }
                    },
                )
            }
        };
        let densities = densities?;
        prof.density_iterations += densities.iterations;
        prof.density_solves += densities.solves;
        prof.carried_fields += densities.carried;
        prof.velocity_iterations += viscous?;
        Ok(())
    }

    /// The gravity potential the fibres' liquid diffuses down this sub-step
    /// ([`crate::stain::drain`]): with `StainParams::capillary_height` and the solute
    /// carried (the fibres' liquid moves only then), from the body force `g − p̈` at the
    /// window's positions `q`; None otherwise.
    fn potential(&self, w: &Window, q: &[DVec3], acceleration: &[DVec3]) -> Option<Potential> {
        let p = &self.params;
        let g = p.gravity.length();
        let density = p.wicking.density;
        if p.capillary_height <= 0.0 || !p.carry_solute || g <= 0.0 || density <= 0.0 {
            return None;
        }
        let gravity = if p.forces.gravity {
            p.gravity
        } else {
            DVec3::ZERO
        };
        let body: Vec<DVec3> = acceleration.iter().map(|&a| gravity - a).collect();
        let scale = density / (g * p.capillary_height);
        Some(edge_steps(
            &w.cloth.topology,
            q,
            &body,
            &w.region.vertices,
            scale,
        ))
    }

    /// The per-face scale of the density diffusion: the wicking factor of every face from
    /// the liquid of `fields` ([`crate::stain::Wicking`]), times the irregular fabric's
    /// `irregular`; None when neither is on.
    fn face_scale(
        &self,
        cloth: &Cloth,
        fields: &Fields,
        geometry: &Geometry,
        irregular: Option<&[f64]>,
    ) -> Option<Vec<f64>> {
        let p = &self.params;
        let wicking = p.wicking.is_on().then(|| {
            let liquid: Vec<f64> = (0..cloth.topology.n_vertices())
                .map(|j| {
                    let a = geometry.vertex_area[j];
                    let m = fields.free_solvent[j] + fields.absorbed_solvent[j];
                    if a > 0.0 { m / a } else { 0.0 }
                })
                .collect();
            p.wicking.face_factors(&cloth.topology, &liquid)
        });
        match (wicking, irregular) {
            (Some(g), Some(r)) => Some(g.iter().zip(r).map(|(g, r)| g * r).collect()),
            (g, r) => g.or_else(|| r.map(<[f64]>::to_vec)),
        }
    }

    /// The run's holdup in the free liquid's spreading (module doc, "Runs"): per face, 1
    /// where the film its corners hold (their free solvent over their lumped areas) stands
    /// above the pinned film `s h_r`, the creep `κ` where it does not; `s = |g_t| / g` the
    /// slope (the tangential body force of the first half kick, `force`, over gravity)
    /// times the irregular fabric's multiplier, the corners' mean. A face that the slope
    /// holds nothing on (a level pool's) stays open, so a level pool spreads as without
    /// the holdup (bit for bit where the fibres' liquid has its own operator, a residual
    /// saturation; without one it is solved apart from the free liquid's, the same to the
    /// solver's tolerance).
    /// None without a holdup, without gravity or with `κ = 1`.
    fn film_gate(
        &self,
        cloth: &Cloth,
        fields: &Fields,
        geometry: &Geometry,
        force: &[(DVec2, f64, VelocityStep)],
    ) -> Option<Vec<f64>> {
        let p = &self.params;
        let g = p.gravity.length();
        if p.holdup <= 0.0 || g <= 0.0 || p.film_creep >= 1.0 {
            return None;
        }
        let creep = p.film_creep;
        let irregular = cloth.irregular.as_deref();
        let pinned = |j: usize| {
            let s = (force[j].0.length() / g).min(1.0);
            p.holdup * s * irregular.map_or(1.0, |m| m[j])
        };
        let area = &geometry.vertex_area;
        let free = &fields.free_solvent;
        Some(
            cloth
                .topology
                .faces()
                .par_iter()
                .map(|c| {
                    let c = c.map(|v| v as usize);
                    let threshold = (pinned(c[0]) + pinned(c[1]) + pinned(c[2])) / 3.0;
                    let (mass, a) = c
                        .iter()
                        .fold((0.0, 0.0), |(m, s), &v| (m + free[v], s + area[v]));
                    if threshold <= 0.0 || mass > threshold * a {
                        1.0
                    } else {
                        creep
                    }
                })
                .collect(),
        )
    }

    /// The faces through which the fibres' liquid moves: those whose corners all hold it
    /// above the residual saturation in `fields` (a pinned edge, "Tide lines" in
    /// `diffuse`); None unless the solute is carried with a residual saturation.
    fn mobile_faces(
        &self,
        cloth: &Cloth,
        fields: &Fields,
        geometry: &Geometry,
    ) -> Option<Vec<bool>> {
        let p = &self.params;
        (p.carry_solute && p.residual_saturation > 0.0).then(|| {
            let floor = p.residual_saturation * p.interaction.saturation;
            let mobile: Vec<bool> = (0..cloth.topology.n_vertices())
                .map(|j| {
                    let a = geometry.vertex_area[j];
                    a > 0.0 && fields.absorbed_solvent[j] > floor * a
                })
                .collect();
            cloth
                .topology
                .faces()
                .iter()
                .map(|c| c.iter().all(|&v| mobile[v as usize]))
                .collect()
        })
    }

    /// Step 5 of the module doc: interactions (§4.5) on the active and held vertices, the
    /// evaporation faster on the wet patch's rim ([`crate::stain::interact`]).
    fn interaction_phase(
        &self,
        w: &Window,
        loc: &mut Local,
        h: f64,
        sub: &SubstepScratch,
    ) -> Result<(), Error> {
        let p = &self.params;
        let n = w.vertices.len();
        let topo = &w.cloth.topology;
        let geometry = &sub.geometry;
        let irregular = w.cloth.irregular.as_ref();
        // on the active and held vertices (the halo's areas are partial; it holds nothing
        // that can change)
        let wet: Vec<f64> = (0..n)
            .map(|j| {
                let a = geometry.vertex_area[j];
                let m = loc.fields.free_solvent[j] + loc.fields.absorbed_solvent[j];
                if a > 0.0 { m / a } else { 0.0 }
            })
            .collect();
        let exposed = if p.vapour_limited {
            vapour_exposure(
                topo,
                &geometry.edge_length,
                &geometry.vertex_area,
                &w.cloth.boundary,
                &wet,
                DRY_DENSITY,
            )
        } else {
            exposure(
                topo,
                &w.cloth.boundary,
                &wet,
                DRY_DENSITY,
                p.interaction.evaporation_boundary,
            )
        };
        let mut part = loc.fields.gather(&w.whole);
        let absorption_scale = irregular.map(|m| pick(&w.whole, m));
        loc.evaporated += interact_varied(
            &p.interaction,
            &pick(&w.whole, &geometry.vertex_area),
            &pick(&w.whole, &exposed),
            absorption_scale.as_deref(),
            h,
            &mut part,
        )?;
        loc.fields.scatter(&w.whole, &part);
        Ok(())
    }
}

/// The run's holdup (module doc, "Runs"): on the active vertices, takes
/// `min(f, h_r m_i A_i)` of the free solvent `fields[0]` (`m_i` the irregular fabric's
/// multiplier, 1 without) and the same fraction of every other field out of `fields`,
/// and returns what it took, per field, to be added back after the transport.
fn hold_back(
    fields: &mut [&mut [f64]],
    area: &[f64],
    active: &[bool],
    holdup: f64,
    irregular: Option<&[f64]>,
) -> Vec<Vec<f64>> {
    let n = area.len();
    let fraction: Vec<f64> = (0..n)
        .map(|j| {
            let f = fields[0][j];
            if !active[j] || f <= 0.0 {
                return 0.0;
            }
            let cap = holdup * irregular.map_or(1.0, |m| m[j]) * area[j];
            if f <= cap { 1.0 } else { cap / f }
        })
        .collect();
    fields
        .iter_mut()
        .map(|field| {
            field
                .iter_mut()
                .zip(&fraction)
                .map(|(m, &r)| {
                    // all of it where all is held, so nothing is left to round
                    let k = if r >= 1.0 { *m } else { *m * r };
                    *m -= k;
                    k
                })
                .collect()
        })
        .collect()
}

/// Most halvings of a sub-step's density diffusion whose wicking front does not settle
/// within [`MAX_PICARD`] rounds (`Wicking`'s "Long steps"): up to 8 pieces, a front of
/// 8 · 64 rings a sub-step.
const MAX_HALVINGS: u32 = 3;

/// Whether the wicking factors `g` of a Picard round are those of the round before,
/// `last`, to `tolerance` times their largest on every face (`Wicking::tolerance`);
/// without factors there is nothing to iterate.
fn factors_settled(last: Option<&[f64]>, g: Option<&[f64]>, tolerance: f64) -> bool {
    let (Some(last), Some(g)) = (last, g) else {
        return true;
    };
    let top = g.par_iter().copied().reduce(|| 0.0, f64::max);
    let change = g
        .par_iter()
        .zip(last)
        .map(|(a, b)| (a - b).abs())
        .reduce(|| 0.0, f64::max);
    change <= tolerance * top
}

/// The fibres' liquid's face scale: `face_scale` (1 without one) on the `mobile` faces, 0
/// elsewhere.
fn held_faces(mobile: &[bool], face_scale: Option<&[f64]>) -> Vec<f64> {
    mobile
        .iter()
        .enumerate()
        .map(|(t, &m)| {
            if m {
                face_scale.map_or(1.0, |g| g[t])
            } else {
                0.0
            }
        })
        .collect()
}

/// How the solute moves in the density diffusion: carried by the solvents' fluxes (the
/// fibres' liquid through the faces of `held`), or diffused with them.
fn solute_motion<'a>(
    p: &StainParams,
    held: Option<&'a [f64]>,
    potential: Option<&'a Potential>,
) -> SoluteMotion<'a> {
    if p.carry_solute {
        SoluteMotion::Carried {
            held_scale: held,
            carry: Carry {
                fraction: p.carried_fraction,
                dispersivity: p.dispersivity,
            },
            potential,
        }
    } else {
        SoluteMotion::Diffused
    }
}
