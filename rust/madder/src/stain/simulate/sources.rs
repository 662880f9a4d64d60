//! What is put on the cloth from outside the simulation: liquid poured on it (with its
//! colour), splashes (seed Fig. 4.3) and initial velocities. Each checks its input and
//! names the first bad vertex or argument; none steps the simulation.
//!
//! Poured liquid adds masses `A_i σ_i` at the vertices' current areas (the state stores
//! masses, [`crate::stain::state`]); a colour different from the liquid's switches on the
//! per-vertex colour masses (solute mass × colour), which every phase then carries. A
//! splash sets velocities; the random numbers come from the seed and the vertex index
//! only ([`crate::rng::SplitMix64`]), so a splash is the same on any number of threads.

use glam::{DMat3, DVec2, DVec3};
use rayon::prelude::*;

use super::Simulator;
use crate::error::ParamError;
use crate::rng::SplitMix64;
use crate::stain::check::{check_each_nonnegative, check_length, check_range};
use crate::stain::forces::corotating_frames_with;

impl Simulator {
    /// Replaces the velocity field by world vectors (projected on each vertex's tangent
    /// plane at the current frame), e.g. an initial condition.
    pub fn set_velocity_world(&mut self, velocity: &[DVec3]) -> Result<(), ParamError> {
        self.check_len("velocity", velocity.len())?;
        if let Some(index) = velocity.iter().position(|u| !u.is_finite()) {
            return Err(ParamError::NonFinite {
                name: "velocity",
                index,
            });
        }
        let st = &mut self.state;
        st.frames = corotating_frames_with(
            &self.cloth.adjacency,
            &self.cloth.rest_frames,
            &self.cloth.rest,
            &st.positions,
        );
        st.velocity = (0..velocity.len())
            .map(|i| st.frames.to_local(i, velocity[i]))
            .collect();
        st.stamp.fill(st.time);
        Ok(())
    }

    pub(in crate::stain) fn check_len(
        &self,
        name: &'static str,
        got: usize,
    ) -> Result<(), ParamError> {
        check_length(name, self.cloth.topology.n_vertices(), got)
    }

    /// Pours liquid: `solvent[i]` kg/m² of solvent at vertex `i`, carrying
    /// `concentration` kg of solute per kg of solvent, of `color` (default: the liquid's).
    /// A colour different from the liquid's switches on per-vertex colour tracking.
    pub fn add_liquid(
        &mut self,
        solvent: &[f64],
        concentration: f64,
        color: Option<[f64; 3]>,
    ) -> Result<(), ParamError> {
        self.check_len("added solvent", solvent.len())?;
        check_each_nonnegative("added solvent", solvent)?;
        check_range(
            "concentration",
            concentration,
            concentration >= 0.0,
            "finite and ≥ 0",
        )?;
        let color = color.unwrap_or(self.solute_color);
        if let Some(index) = color.iter().position(|c| !c.is_finite()) {
            return Err(ParamError::NonFinite {
                name: "liquid colour",
                index,
            });
        }
        if color != self.solute_color {
            self.enable_color();
        }
        for (i, &d) in solvent.iter().enumerate() {
            if d > 0.0 {
                // the area now (a vertex away from the liquid keeps an older one)
                self.state.vertex_area[i] = self.current_area(i);
                self.state.mark_stained(i);
            }
        }
        if self.params.first_substep > 0.0 && solvent.iter().any(|&d| d > 0.0) {
            // short sub-steps while it spreads (module doc, "Sub-steps after a pour")
            self.state.ramp = self.params.first_substep;
        }
        let area = &self.state.vertex_area;
        let f = &mut self.state.fields;
        for (i, &d) in solvent.iter().enumerate() {
            let m = d * area[i];
            f.free_solvent[i] += m;
            f.solute[i] += m * concentration;
            if let Some(cf) = f.color_free.as_mut() {
                for k in 0..3 {
                    cf[i][k] += m * concentration * color[k];
                }
            }
        }
        self.rescan = true;
        Ok(())
    }

    /// Tracks colour per vertex from now on (colour masses = solute × liquid colour).
    fn enable_color(&mut self) {
        let f = &mut self.state.fields;
        if f.color_free.is_some() {
            return;
        }
        let c = self.solute_color;
        f.color_free = Some(f.solute.iter().map(|s| c.map(|x| x * s)).collect());
        f.color_held = Some(
            (0..f.solute.len())
                .map(|i| c.map(|x| x * (f.absorbed_solute[i] + f.adsorbed[i])))
                .collect(),
        );
    }

    /// A splash (seed Fig. 4.3): adds a random outgoing velocity around `center` (world)
    /// to every vertex with `weight > 0`: the tangential direction away from the centre,
    /// turned by a random angle in ±0.5 rad, times `speed · weight` and a random factor in
    /// [0.5, 1.5). Random numbers come from `seed` and the vertex index only, so a splash
    /// is the same on any number of threads and any machine.
    pub fn splash(
        &mut self,
        center: DVec3,
        speed: f64,
        seed: u64,
        weight: &[f64],
    ) -> Result<(), ParamError> {
        self.check_len("splash weights", weight.len())?;
        check_range("splash speed", speed, speed >= 0.0, "finite and ≥ 0")?;
        if !center.is_finite() {
            return Err(ParamError::NonFinite {
                name: "splash centre",
                index: 0,
            });
        }
        check_each_nonnegative("splash weight", weight)?;
        // the splashed vertices' velocities and frames, brought to now
        let splashed: Vec<usize> = (0..weight.len()).filter(|&i| weight[i] > 0.0).collect();
        let now: Vec<(DVec2, DMat3)> = splashed
            .par_iter()
            .map(|&i| self.caught_up(i, DVec3::ZERO))
            .collect();
        let st = &mut self.state;
        for (&i, (u, frame)) in splashed.iter().zip(now) {
            let mut rng = SplitMix64::new(seed ^ (i as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15));
            let (r1, r2, r3) = (rng.unit(), rng.unit(), rng.unit());
            st.frames.frame[i] = frame;
            st.stamp[i] = st.time;
            let out = st.frames.to_local(i, st.positions[i] - center);
            let dir = if out.length() > 0.0 {
                out.normalize()
            } else {
                DVec2::from_angle(std::f64::consts::TAU * r3)
            };
            let turned = DVec2::from_angle(r1 - 0.5).rotate(dir);
            st.velocity[i] = u + turned * (speed * weight[i] * (0.5 + r2));
        }
        Ok(())
    }
}
