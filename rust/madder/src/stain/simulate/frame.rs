//! One frame: its checks, the window, the sub-step count (module doc, "Fast rotation")
//! and the sub-steps on the window's copy of the state, committed when all succeeded
//! ("Failure").

use glam::DVec3;
use rayon::prelude::*;

#[cfg(doc)]
use super::StainParams;
use super::profile::{Laps, Profile};
use super::scratch::StepScratch;
use super::{MAX_AUTO_SUBSTEPS, MAX_TURN, Simulator};
use crate::error::Error;
use crate::mesh::VertexFrames;
use crate::mesh::geometry::check_positions;
use crate::stain::check::check_range;
use crate::stain::forces::{frame_angular_velocity, second_difference};
use crate::stain::state::Local;
use crate::stain::window::{Window, pick_into};

impl Simulator {
    /// Advances one frame to `positions` over `dt` seconds in `params.substeps`
    /// sub-steps. `after`, if known, is the frame after `positions` (one more `dt`
    /// later): the rectilinear force then uses the frame interval's mean acceleration
    /// `½(p̈_k + p̈_{k+1})` (second order) instead of `p̈_k`, and the first frame gets its
    /// acceleration from the motion instead of assuming none. On error the simulator
    /// stays at the previous frame.
    pub fn step(
        &mut self,
        positions: &[DVec3],
        dt: f64,
        after: Option<&[DVec3]>,
    ) -> Result<(), Error> {
        self.step_until(positions, dt, after.map(|a| (a, dt)))
    }

    /// [`Self::step`] where the frame after comes `after.1` seconds after `positions`, and
    /// this frame's `dt` may differ from the one before it (a Frame Time that changes):
    /// the accelerations are then the divided differences over the uneven frames
    /// ([`crate::stain::forces`]). With even frames it is [`Self::step`], bit for bit.
    pub fn step_until(
        &mut self,
        positions: &[DVec3],
        dt: f64,
        after: Option<(&[DVec3], f64)>,
    ) -> Result<(), Error> {
        // run the frame on a thread of the rayon pool: the many short parallel loops of a
        // step then start from a worker (work stealing) instead of each handing its work
        // over from outside the pool and blocking the caller until it is done
        rayon::scope(|_| self.step_in_pool(positions, dt, after))
    }

    fn step_in_pool(
        &mut self,
        positions: &[DVec3],
        dt: f64,
        after: Option<(&[DVec3], f64)>,
    ) -> Result<(), Error> {
        check_range("time step", dt, dt > 0.0, "finite and > 0")?;
        check_positions(&self.cloth.topology, positions)?;
        if let Some((a, h)) = after {
            check_range("time step after", h, h > 0.0, "finite and > 0")?;
            check_positions(&self.cloth.topology, a)?;
        }
        while !self.try_frame(positions, dt, after)? {}
        Ok(())
    }

    /// One try at a frame on checked input: prepares the window (unless
    /// [`super::detail`] did) and runs the frame on it. Returns whether the frame was
    /// committed; `false` when its liquid outran the window (module doc, "Window
    /// reach"): nothing was written, the reach now counts the frame's own transport
    /// sub-cycles, and the caller prepares a wider window and tries again.
    pub(in crate::stain) fn try_frame(
        &mut self,
        positions: &[DVec3],
        dt: f64,
        after: Option<(&[DVec3], f64)>,
    ) -> Result<bool, Error> {
        let mut laps = Laps::start();
        let rebuilt = !std::mem::take(&mut self.prepared) && self.prepare_window()?;
        self.profile.window_rebuilds += usize::from(rebuilt);
        laps.lap(&mut self.profile.window);
        let t_end = self.state.time + dt;
        if let Some(mut w) = self.window.take() {
            let mut scratch = std::mem::take(&mut self.scratch);
            let mut prof = self.profile;
            let result = self.run_frame(&mut w, positions, dt, after, &mut prof, &mut scratch);
            self.window = Some(w);
            self.profile = prof;
            // nothing is written before the whole frame succeeded (module doc, "Failure"),
            // nor when its liquid outran the window
            let local = match result {
                Ok(local) => local,
                Err(e) => {
                    self.scratch = scratch;
                    return Err(e);
                }
            };
            let fits = !self.outran(local.cycles) && !self.spread_past(&local);
            if fits {
                let w = self.window.take().expect("the frame's window");
                self.commit(&w, &local, t_end);
                self.window = Some(w);
            }
            scratch.local = Some(local);
            self.scratch = scratch;
            if !fits {
                self.profile.window_retries += 1;
                return Ok(false);
            }
        }
        self.profile.frames += 1;
        let st = &mut self.state;
        st.time = t_end;
        let mut buffer = st.previous.take().unwrap_or_default();
        buffer.clear();
        buffer.extend_from_slice(positions);
        st.previous = Some(std::mem::replace(&mut st.positions, buffer));
        st.previous_dt = dt;
        self.refresh_areas();
        Ok(true)
    }

    /// One frame on the window `w`, on copies of its state: nothing in `self` changes
    /// (but the kept arrays of `scratch`).
    fn run_frame(
        &self,
        w: &mut Window,
        positions: &[DVec3],
        dt: f64,
        after: Option<(&[DVec3], f64)>,
        prof: &mut Profile,
        scratch: &mut StepScratch,
    ) -> Result<Local, Error> {
        let mut laps = Laps::start();
        let (p, st) = (&self.params, &self.state);
        scratch.fit(w.vertices.len());
        let StepScratch {
            cur,
            next,
            between,
            acceleration,
            omega,
            end_frames,
            local,
            sub,
            ..
        } = scratch;
        pick_into(&w.vertices, &st.positions, cur);
        pick_into(&w.vertices, positions, next);
        // p̈ over the frame interval: the mean of the centred differences at its two ends
        // when the frame after is known (module doc of `forces`)
        if p.forces.rectilinear {
            w.vertices
                .par_iter()
                .map(|&v| {
                    let v = v as usize;
                    let (c, x) = (st.positions[v], positions[v]);
                    let start = match (&st.previous, after) {
                        (Some(prev), _) => second_difference(prev[v], c, x, st.previous_dt, dt),
                        (None, Some((a, h))) => second_difference(c, x, a[v], dt, h),
                        (None, None) => DVec3::ZERO,
                    };
                    match after {
                        Some((a, h)) => 0.5 * (start + second_difference(c, x, a[v], dt, h)),
                        None => start,
                    }
                })
                .collect_into_vec(acceleration);
        } else {
            acceleration.clear();
            acceleration.resize(w.vertices.len(), DVec3::ZERO);
        }
        let mut local = local.take().unwrap_or_default();
        w.vertices
            .par_iter()
            .zip(&*acceleration)
            .map(|(&v, &a)| self.caught_up(v as usize, a))
            .unzip_into_vecs(&mut local.velocity, &mut local.frames.frame);
        st.fields.gather_into(&w.vertices, &mut local.fields);
        pick_into(&w.vertices, &st.vertex_area, &mut local.area);
        local.evaporated = 0.0;
        local.dripped = (0.0, 0.0);
        local.cycles = 0;
        laps.lap(&mut prof.forces);
        // the frames at the frame's end: the sub-step count reads them, and the last
        // sub-step's frames are these (the same formula at the same positions)
        w.corotating_frames_into(next, &mut sub.frames);
        let (turn_count, omega) = self.substeps(w, &sub.frames, &local.frames, dt, omega);
        // the sub-steps' lengths and the fractions of the frame at their ends
        // a ramp after a pour, or one because the frames lengthened (module doc, "Sub-steps
        // after a pour")
        let lengthened =
            p.first_substep > 0.0 && st.previous.is_some() && dt > 2.0 * st.previous_dt;
        let ramp_in = if st.ramp == 0.0 && lengthened {
            2.0 * st.longest_substep
        } else {
            st.ramp
        };
        let (schedule, ramp) = substep_schedule(turn_count, ramp_in, dt);
        local.ramp = ramp;
        local.longest_substep = schedule.iter().map(|x| x.0).fold(0.0, f64::max);
        let s_count = schedule.len();
        // several sub-steps: the end's frames wait for the last one
        if s_count > 1 {
            std::mem::swap(&mut sub.frames, end_frames);
        }
        // one sub-step: its turn is the frame's, just computed
        let omega = omega.filter(|_| s_count == 1);
        laps.lap(&mut prof.geometry);
        for (s, &(h, t)) in schedule.iter().enumerate() {
            let last = s + 1 == s_count;
            if last && s_count > 1 {
                std::mem::swap(&mut sub.frames, end_frames);
            } else if !last {
                between.clear();
                between.extend(cur.iter().zip(&*next).map(|(a, b)| a.lerp(*b, t)));
            }
            let q = if last { &next[..] } else { &between[..] };
            let turns = if last { omega } else { None };
            self.substep(w, &mut local, q, last, turns, h, acceleration, prof, sub)?;
        }
        Ok(local)
    }

    /// Sub-steps of a frame of `dt` on the window `w` from the vertex frames `start` to the
    /// frames `end` at the frame's positions (window order): the user's
    /// [`StainParams::substeps`], or more so that the frames of the active vertices turn
    /// (about their normals) by at most [`MAX_TURN`] per sub-step (module doc, "Fast
    /// rotation").
    ///
    /// Also returns, with the Coriolis force on, every window vertex's `ω_z` over the
    /// whole frame: with one sub-step it is the sub-step's own, which the forces then
    /// take instead of computing it again (the same call on the same frames and `h = dt`).
    /// `omega` is filled (its allocation kept) and returned.
    fn substeps<'a>(
        &self,
        w: &Window,
        end: &VertexFrames,
        start: &VertexFrames,
        dt: f64,
        omega: &'a mut Vec<f64>,
    ) -> (usize, Option<&'a [f64]>) {
        let asked = self.params.substeps as usize;
        if !self.params.forces.coriolis {
            return (asked, None);
        }
        (0..w.vertices.len())
            .into_par_iter()
            .map(|j| frame_angular_velocity(&start.frame[j], &end.frame[j], dt).z)
            .collect_into_vec(omega);
        let turn = w
            .region
            .vertices
            .par_iter()
            .map(|&j| omega[j as usize].abs() * dt)
            .reduce(|| 0.0, f64::max);
        // a NaN turn (never from finite positions) keeps the user's count
        let needed = (turn / MAX_TURN).ceil();
        let count = if needed > asked as f64 {
            (needed as usize).min(MAX_AUTO_SUBSTEPS)
        } else {
            asked
        };
        (count, Some(omega))
    }
}

/// The sub-steps of a frame of `dt`: `(length, fraction of the frame at its end)` each,
/// and the ramp after the frame (module doc of `simulate`, "Sub-steps after a pour").
/// Without a ramp shorter than the frame, `count` equal sub-steps (the turn's count) and
/// no ramp after. With one, the ramp's pieces `h, 2h, 4h, …` while they fit, the rest of
/// the frame last, each piece cut into equal parts no longer than `dt / count`; the ramp
/// after is the first piece that did not fit.
fn substep_schedule(count: usize, ramp: f64, dt: f64) -> (Vec<(f64, f64)>, f64) {
    if !(ramp > 0.0 && ramp < dt) {
        let h = dt / count as f64;
        let equal = (1..=count).map(|s| (h, s as f64 / count as f64)).collect();
        return (equal, 0.0);
    }
    let longest = dt / count as f64;
    let mut out = Vec::new();
    // the piece `[start, start + piece]` in equal parts no longer than the turn's
    let cut = |start: f64, piece: f64, out: &mut Vec<(f64, f64)>| {
        let parts = (piece / longest).ceil().max(1.0) as usize;
        for k in 1..=parts {
            let end = start + piece * k as f64 / parts as f64;
            out.push((piece / parts as f64, end / dt));
        }
    };
    let (mut t, mut h) = (0.0, ramp);
    while t + h < dt {
        cut(t, h, &mut out);
        t += h;
        h *= 2.0;
    }
    cut(t, dt - t, &mut out);
    // the last sub-step ends on the frame's positions exactly
    if let Some(last) = out.last_mut() {
        last.1 = 1.0;
    }
    (out, h)
}

#[cfg(test)]
mod tests {
    use super::substep_schedule;

    #[test]
    fn a_ramp_doubles_its_sub_steps_until_the_frame_and_covers_it_exactly() {
        // no ramp, or one as long as the frame: the turn's equal sub-steps, as before
        for ramp in [0.0, 60.0, 100.0] {
            let (s, after) = substep_schedule(3, ramp, 60.0);
            assert_eq!(s, vec![(20.0, 1.0 / 3.0), (20.0, 2.0 / 3.0), (20.0, 1.0)]);
            assert_eq!(after, 0.0);
        }
        // 0.25 s doubling in a minute: 0.25 … 16 (31.75 s; with 32 more it would pass 60),
        // then the rest, 28.25 s; the ramp goes on at 32 s
        let (s, after) = substep_schedule(1, 0.25, 60.0);
        let lengths: Vec<f64> = s.iter().map(|x| x.0).collect();
        assert_eq!(lengths, vec![0.25, 0.5, 1.0, 2.0, 4.0, 8.0, 16.0, 28.25]);
        assert_eq!(after, 32.0);
        assert_eq!(s.last().unwrap().1, 1.0);
        assert!((lengths.iter().sum::<f64>() - 60.0).abs() < 1e-12);
        // the ramp carries on into the next frame, and a turn splits the long pieces
        let (s, after) = substep_schedule(4, 2.0, 10.0);
        let lengths: Vec<f64> = s.iter().map(|x| x.0).collect();
        assert_eq!(lengths, vec![2.0, 2.0, 2.0, 2.0, 2.0]); // 2, 4 = 2 + 2, rest 4 = 2 + 2
        assert_eq!(after, 8.0);
        let ends: Vec<f64> = s.iter().map(|x| x.1).collect();
        assert_eq!(ends, vec![0.2, 0.4, 0.6, 0.8, 1.0]);
    }
}
