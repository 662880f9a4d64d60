//! The window's upkeep between frames ([`crate::stain::window`], module doc): finding
//! the liquid and keeping or rebuilding the window, bringing the velocities of vertices
//! entering it up to date, writing a frame back, and the areas of the stained vertices
//! outside it.

use std::sync::atomic::AtomicU64;
use std::sync::atomic::Ordering::Relaxed;

use glam::{DMat3, DVec2, DVec3};
use rayon::prelude::*;

use super::Simulator;
use crate::error::Error;
use crate::mesh::Wedge;
use crate::mesh::geometry::{face_third, vertex_area};
use crate::runs;
use crate::stain::forces::{frame_angular_velocity, frame_body_acceleration, integrate_velocity};
use crate::stain::state::Local;
use crate::stain::window::{
    ACTIVE_RINGS, ACTIVE_THRESHOLD, WALL_THRESHOLD, WINDOW_SLACK_RINGS, WINDOW_SLACK_VERTICES,
    Window, WindowPlan, find_liquid, grow, grow_on,
};

impl Simulator {
    /// Finds the liquid and keeps or rebuilds the window for the next frame (module
    /// doc). Returns whether it was rebuilt.
    pub(in crate::stain) fn prepare_window(&mut self) -> Result<bool, Error> {
        let plan = self.plan_window();
        self.build_window(plan)
    }

    /// Builds the window `plan` asks for (if any); returns whether it built one.
    pub(in crate::stain) fn build_window(&mut self, plan: WindowPlan) -> Result<bool, Error> {
        match plan {
            WindowPlan::Keep => Ok(false),
            WindowPlan::Build { mask, held } => {
                let reuse = self.window.take().and_then(|w| w.cg);
                let reuse = reuse.or_else(|| self.spare.take());
                self.window = Window::new(&self.cloth, mask, &held, reuse)?;
                Ok(true)
            }
        }
    }

    /// Finds the liquid and decides whether the current window still serves the next
    /// frame or which one to build (module doc), without building it: [`crate::stain::detail`]
    /// first makes sure the refined cloth is built around the new window's vertices.
    pub(in crate::stain) fn plan_window(&mut self) -> WindowPlan {
        let n = self.cloth.topology.n_vertices();
        if !self.params.active_region {
            // the whole mesh, every vertex with a face active, once
            if self.window.is_some() {
                return WindowPlan::Keep;
            }
            let mask = self.loose.iter().map(|l| !l).collect();
            return WindowPlan::Build {
                mask,
                held: vec![false; n],
            };
        }
        // the liquid is inside the window's whole vertices, unless some was poured since
        // (no window and no pour: there is none but dust)
        let scan: Vec<u32> = match (&self.window, self.rescan) {
            (Some(w), false) => w.whole.iter().map(|&j| w.vertices[j as usize]).collect(),
            (None, false) => return WindowPlan::Keep,
            _ => (0..n as u32).collect(),
        };
        let st = &self.state;
        let p = &self.params;
        let mobile_held = if p.carry_solute && p.residual_saturation > 0.0 {
            p.residual_saturation * p.interaction.saturation
        } else {
            f64::INFINITY
        };
        let (flowing, held) =
            find_liquid(&scan, &self.loose, &st.fields, &st.vertex_area, mobile_held);
        // liquid moves at most one ring per transport sub-cycle
        let reach = ACTIVE_RINGS + self.last_frame_cycles + self.spread_rings;
        let (mut mask, mut needed, front) =
            grow(&self.cloth.adjacency, &self.loose, &flowing, reach);
        let fits = self.window.as_ref().is_some_and(|w| {
            needed.iter().all(|&v| w.mask[v as usize])
                && held.iter().all(|&v| w.whole_mask[v as usize])
                && w.region.vertices.len() <= 2 * needed.len() + WINDOW_SLACK_VERTICES
        });
        self.rescan = false;
        if fits {
            return WindowPlan::Keep;
        }
        // room for about two more frames of the same flow: `2 reach + WINDOW_SLACK_RINGS −
        // ACTIVE_RINGS` rings in all, grown on from the needed region's
        grow_on(
            &self.cloth.adjacency,
            &self.loose,
            &mut mask,
            &mut needed,
            front,
            reach + WINDOW_SLACK_RINGS - ACTIVE_RINGS,
        );
        let mut is_held = vec![false; n];
        held.iter().for_each(|&v| is_held[v as usize] = true);
        WindowPlan::Build {
            mask,
            held: is_held,
        }
    }

    /// Whether a frame that took `cycles` transport sub-cycles outran the window it ran
    /// on (module doc, "Window reach"): its reach counted
    /// [`Simulator::last_frame_cycles`], and the liquid it found, grown by `cycles`
    /// instead, no longer fits. The reach then counts `cycles` from now on, so that the
    /// next try plans for them; each try widens it, so the tries end.
    pub(in crate::stain) fn outran(&mut self, cycles: usize) -> bool {
        if !self.params.active_region || cycles <= self.last_frame_cycles {
            return false;
        }
        self.last_frame_cycles = cycles;
        let rescan = std::mem::replace(&mut self.rescan, false);
        let outran = !matches!(self.plan_window(), WindowPlan::Keep);
        self.rescan = rescan;
        outran
    }

    /// Whether the frame's liquid (`local`, on the current window) reached the edge
    /// of its active region, where the no-flux wall held it (module doc of
    /// [`super`], "Window reach"). If so the reach gains rings, doubled until the
    /// window planned for the frame changes, and the frame must run again; never without
    /// an active region, nor once the reach spans the cloth.
    pub(in crate::stain) fn spread_past(&mut self, local: &Local) -> bool {
        let touched = self.window.as_ref().is_some_and(|w| touches_wall(w, local));
        if !self.params.active_region || !touched {
            return false;
        }
        let n = self.cloth.topology.n_vertices();
        while self.spread_rings < n {
            self.spread_rings = (2 * self.spread_rings).max(ACTIVE_RINGS);
            let rescan = std::mem::replace(&mut self.rescan, false);
            let keep = matches!(self.plan_window(), WindowPlan::Keep);
            self.rescan = rescan;
            if !keep {
                return true;
            }
        }
        false
    }

    /// The velocity and frame of vertex `v` at the start of the frame: a vertex that was
    /// outside the window is brought from its last step to now by the exact solution of
    /// its force equation ([`integrate_velocity`]) over the time between, with the body
    /// acceleration of `acceleration` (`p̈`, world) and the frame's mean turn since
    /// (module doc).
    pub(in crate::stain) fn caught_up(&self, v: usize, acceleration: DVec3) -> (DVec2, DMat3) {
        let st = &self.state;
        let (u, f) = (st.velocity[v], st.frames.frame[v]);
        let gap = st.time - st.stamp[v];
        if gap <= 0.0 {
            return (u, f);
        }
        let now = self
            .cloth
            .adjacency
            .rotation(&self.cloth.rest, &st.positions, v)
            * self.cloth.rest_frames.frame[v];
        if self.loose[v] {
            return (DVec2::ZERO, now);
        }
        let p = &self.params;
        let a = frame_body_acceleration(&now, acceleration, p.gravity, p.forces);
        let turn = if p.forces.coriolis {
            frame_angular_velocity(&f, &now, gap).z
        } else {
            0.0
        };
        (integrate_velocity(u, a, turn, p.friction, gap).0, now)
    }

    /// Writes a successful frame on `w` back (module doc): fields of every
    /// window vertex (the halo's are unchanged), velocities, frames and areas of the
    /// active and held vertices, stamped `time`.
    pub(in crate::stain) fn commit(&mut self, w: &Window, local: &Local, time: f64) {
        let st = &mut self.state;
        st.fields.scatter(&w.vertices, &local.fields);
        st.evaporated += local.evaporated;
        st.dripped.0 += local.dripped.0;
        st.dripped.1 += local.dripped.1;
        st.ramp = local.ramp;
        st.longest_substep = local.longest_substep;
        // the active and held vertices' cloth numbers, increasing as `whole` is: each
        // array written in parallel
        let whole: Vec<u32> = w
            .whole
            .par_iter()
            .map(|&j| w.vertices[j as usize])
            .collect();
        let at = |k: usize| w.whole[k] as usize;
        runs::for_each_at(&mut st.velocity, &whole, |k, u| *u = local.velocity[at(k)]);
        runs::for_each_at(&mut st.frames.frame, &whole, |k, f| {
            *f = local.frames.frame[at(k)];
        });
        runs::for_each_at(&mut st.stamp, &whole, |_, t| *t = time);
        runs::for_each_at(&mut st.vertex_area, &whole, |k, a| *a = local.area[at(k)]);
        for &v in &whole {
            if st.fields.is_live(v as usize) || st.fields.adsorbed[v as usize] > 0.0 {
                st.mark_stained(v as usize);
            }
        }
        self.last_frame_cycles = local.cycles;
    }

    /// The lumped area of vertex `v` at the current positions.
    pub(in crate::stain) fn current_area(&self, v: usize) -> f64 {
        let faces = self.cloth.topology.faces();
        vertex_area(
            self.cloth
                .rings
                .wedges(v)
                .iter()
                .map(|w| faces[w.face as usize]),
            &self.state.positions,
        )
    }

    /// Brings the areas of the stained vertices outside the window to the current frame
    /// (the densities read out are their masses over these areas). Dust — a vertex
    /// holding less than [`ACTIVE_THRESHOLD`] of the largest stain density — is dropped
    /// from the list and keeps its last area (its density is 1e-12 of the peak's; a
    /// window that reaches it again puts it back).
    pub(in crate::stain) fn refresh_areas(&mut self) {
        let st = &self.state;
        let f = &st.fields;
        let density = |v: usize| {
            let m = f.free_solvent[v]
                + f.solute[v]
                + f.absorbed_solvent[v]
                + f.absorbed_solute[v]
                + f.adsorbed[v];
            if st.vertex_area[v] > 0.0 {
                m / st.vertex_area[v]
            } else {
                0.0
            }
        };
        // the densities in parallel (the largest is the same in any order); the dust
        // leaves the list, which keeps its order
        let densities: Vec<f64> = st
            .stained
            .par_iter()
            .map(|&v| density(v as usize))
            .collect();
        let floor = ACTIVE_THRESHOLD * densities.par_iter().copied().reduce(|| 0.0, f64::max);
        let whole = self.window.as_ref().map(|w| &w.whole_mask);
        let st = &mut self.state;
        let mut keep = Vec::with_capacity(st.stained.len());
        for (&v, &d) in st.stained.iter().zip(&densities) {
            if d > floor {
                keep.push(v);
            } else {
                st.is_stained[v as usize] = false;
            }
        }
        st.stained = keep;
        // now a vertex is stale iff it is stained and outside the window
        let st = &self.state;
        let stale = |v: u32| st.is_stained[v as usize] && whole.is_none_or(|m| !m[v as usize]);
        let stale_list: Vec<u32> = st
            .stained
            .par_iter()
            .copied()
            .filter(|&v| stale(v))
            .collect();
        if stale_list.is_empty() {
            return;
        }
        // each face around them: its third once, by its lowest-numbered stale corner;
        // then each vertex sums its fan's thirds in wedge order, as `current_area` does
        // (the same operations on the same numbers)
        let (faces, rings) = (self.cloth.topology.faces(), &self.cloth.rings);
        if self.face_thirds.len() != faces.len() {
            self.face_thirds = (0..faces.len()).map(|_| AtomicU64::new(0)).collect();
        }
        let thirds = &self.face_thirds;
        stale_list.par_iter().for_each(|&v| {
            for w in rings.wedges(v as usize) {
                let f = &faces[w.face as usize];
                if f.iter().copied().filter(|&u| stale(u)).min() == Some(v) {
                    let third = face_third(f, &st.positions);
                    thirds[w.face as usize].store(third.to_bits(), Relaxed);
                }
            }
        });
        let area: Vec<f64> = stale_list
            .par_iter()
            .map(|&v| {
                let third = |w: &Wedge| f64::from_bits(thirds[w.face as usize].load(Relaxed));
                rings.wedges(v as usize).iter().map(third).sum()
            })
            .collect();
        let st = &mut self.state;
        for (v, a) in stale_list.into_iter().zip(area) {
            st.vertex_area[v as usize] = a;
        }
    }
}

/// Whether a vertex at the edge of `w`'s active region (one with a neighbour outside it)
/// holds liquid (free and absorbed solvent: the wicking moves the one by the other's
/// saturation, and the fibres take up what arrives) or dissolved solute above
/// [`WALL_THRESHOLD`] of its peak over the region, in the frame's `local` fields.
fn touches_wall(w: &Window, local: &Local) -> bool {
    let (mask, f, area) = (&w.region.mask, &local.fields, &local.area);
    let density = |k: usize, v: usize| {
        let m = match k {
            0 => f.free_solvent[v] + f.absorbed_solvent[v],
            _ => f.solute[v],
        };
        if area[v] > 0.0 { m / area[v] } else { 0.0 }
    };
    let vertices = &w.region.vertices;
    let peak: [f64; 2] = std::array::from_fn(|k| {
        vertices
            .par_iter()
            .map(|&v| density(k, v as usize))
            .reduce(|| 0.0, f64::max)
    });
    vertices.par_iter().any(|&v| {
        let v = v as usize;
        (0..2).any(|k| peak[k] > 0.0 && density(k, v) > WALL_THRESHOLD * peak[k])
            && w.cloth
                .adjacency
                .neighbours(v)
                .iter()
                .any(|&j| !mask[j as usize])
    })
}
