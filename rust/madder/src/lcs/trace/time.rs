//! Time: the frame times, and the mesh's vertex positions over time, linearly
//! interpolated between frames ([`Motion`]).

use glam::DVec3;

use crate::error::LcsError;
use crate::mesh::Topology;
use crate::mesh::geometry::check_positions;

/// Frame times: finite, strictly increasing.
#[derive(Debug, Clone, PartialEq)]
pub struct FrameTimes(Vec<f64>);

impl FrameTimes {
    /// Checks the times, naming the first bad entry.
    pub fn new(times: Vec<f64>) -> Result<Self, LcsError> {
        for (i, &t) in times.iter().enumerate() {
            if !t.is_finite() || (i > 0 && t <= times[i - 1]) {
                return Err(LcsError::FrameTimes { index: i, value: t });
            }
        }
        if times.is_empty() {
            return Err(LcsError::Shape {
                name: "times".into(),
                expected: "at least one frame time".into(),
                got: "(0,)".into(),
            });
        }
        Ok(Self(times))
    }

    /// The times.
    pub fn times(&self) -> &[f64] {
        &self.0
    }

    /// The frame `k` and weight `s` with `t = (1 − s) t_k + s t_{k+1}` (`k + 1` clamped to
    /// the last frame); an error if `t` is outside the frames (beyond rounding).
    pub fn locate(&self, t: f64) -> Result<(usize, f64), LcsError> {
        let ts = &self.0;
        let (first, last) = (ts[0], ts[ts.len() - 1]);
        let slack = 1e-9 * (last - first).abs().max(t.abs()).max(1.0);
        if !(t >= first - slack && t <= last + slack) {
            return Err(LcsError::TimeOutOfRange {
                time: t,
                first,
                last,
            });
        }
        if ts.len() == 1 {
            return Ok((0, 0.0));
        }
        let k = ts.partition_point(|&x| x <= t).clamp(1, ts.len() - 1) - 1;
        let s = ((t - ts[k]) / (ts[k + 1] - ts[k])).clamp(0.0, 1.0);
        Ok((k, s))
    }
}

/// The mesh's vertex positions over time: one frame (a fixed mesh) or frames at given
/// times, linearly interpolated between them.
#[derive(Debug, Clone)]
pub struct Motion {
    pub(super) times: Option<FrameTimes>,
    pub(super) frames: Vec<Vec<DVec3>>,
}

impl Motion {
    /// A mesh that does not move.
    pub fn fixed(positions: Vec<DVec3>) -> Self {
        Self {
            times: None,
            frames: vec![positions],
        }
    }

    /// A deforming mesh: `frames[k]` are the positions at `times[k]`.
    pub fn frames(times: FrameTimes, frames: Vec<Vec<DVec3>>) -> Result<Self, LcsError> {
        if frames.len() != times.times().len() {
            return Err(LcsError::Shape {
                name: "positions".into(),
                expected: format!("{} frames (one per frame time)", times.times().len()),
                got: format!("{} frames", frames.len()),
            });
        }
        Ok(Self {
            times: Some(times),
            frames,
        })
    }

    /// Checks every frame against the topology (count, finiteness; names frame and vertex).
    pub(crate) fn check(&self, topology: &Topology) -> Result<(), LcsError> {
        for frame in &self.frames {
            check_positions(topology, frame)?;
        }
        Ok(())
    }

    /// Where to read the positions at time `t`.
    pub(crate) fn at(&self, t: f64) -> Result<Lerp, LcsError> {
        Ok(match &self.times {
            None => Lerp { k: 0, s: 0.0 },
            Some(times) => {
                let (k, s) = times.locate(t)?;
                Lerp { k, s }
            }
        })
    }

    /// The position of vertex `v` at `at`.
    pub(crate) fn position(&self, at: Lerp, v: usize) -> DVec3 {
        let a = self.frames[at.k][v];
        if at.s == 0.0 {
            return a;
        }
        a.lerp(self.frames[(at.k + 1).min(self.frames.len() - 1)][v], at.s)
    }

    /// Whether the mesh does not move (one frame).
    pub(crate) fn is_fixed(&self) -> bool {
        self.frames.len() == 1
    }

    /// All positions at time `t`.
    pub(crate) fn positions(&self, t: f64) -> Result<Vec<DVec3>, LcsError> {
        let at = self.at(t)?;
        Ok((0..self.frames[0].len())
            .map(|v| self.position(at, v))
            .collect())
    }
}

/// A frame index and the weight of the next frame.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Lerp {
    pub(super) k: usize,
    pub(super) s: f64,
}
