//! The velocity fields a particle is traced through: the [`Velocity`] trait, an analytic
//! field ([`FnVelocity`]) and per-vertex values per frame ([`VertexVelocity`]).

use glam::DVec3;
use rayon::prelude::*;

use super::located::Located;
use super::time::FrameTimes;
use crate::error::LcsError;
use crate::mesh::Topology;

/// A velocity field on the mesh: the fluid's 3-D velocity relative to the cloth.
pub trait Velocity {
    /// Writes the velocity at time `t` at every point into `out`: the point on the mesh
    /// `at[i]` whose world position is `points[i]` (`at` may be empty if
    /// [`Self::uses_location`] is `false`).
    fn eval(
        &mut self,
        t: f64,
        at: &[Located],
        points: &[DVec3],
        out: &mut [DVec3],
    ) -> Result<(), LcsError>;

    /// Whether [`Self::eval`] reads `at` (the points' triangles); a velocity of world
    /// points alone returns `false`, which lets a flat mesh skip locating the points
    /// ([`super::planar`]).
    fn uses_location(&self) -> bool {
        true
    }
}

/// [`Velocity::eval`] at the stage points of the particles from vertices `live`, refusing a
/// non-finite value with an error naming the point and its vertex (shared by the walking
/// and the planar tracer).
pub(crate) fn eval_checked(
    velocity: &mut dyn Velocity,
    t: f64,
    at: &[Located],
    points: &[DVec3],
    live: &[usize],
    out: &mut [DVec3],
) -> Result<(), LcsError> {
    velocity.eval(t, at, points, out)?;
    match out.iter().position(|u| !u.is_finite()) {
        None => Ok(()),
        Some(i) => Err(LcsError::NonFiniteVelocity {
            at: format!(
                "point ({}, {}, {}) (the particle from vertex {})",
                points[i].x, points[i].y, points[i].z, live[i]
            ),
            time: t,
        }),
    }
}

/// An analytic velocity `f(t, x)` of world position (evaluated in parallel).
pub struct FnVelocity<F>(pub F);

impl<F: Fn(f64, DVec3) -> DVec3 + Sync> Velocity for FnVelocity<F> {
    fn eval(
        &mut self,
        t: f64,
        _at: &[Located],
        points: &[DVec3],
        out: &mut [DVec3],
    ) -> Result<(), LcsError> {
        out.par_iter_mut()
            .zip(points)
            .for_each(|(o, &x)| *o = (self.0)(t, x));
        Ok(())
    }

    fn uses_location(&self) -> bool {
        false
    }
}

/// Per-vertex velocities per frame, linear in time between frames and linear in each
/// triangle (barycentric interpolation), e.g. the stain simulator's baked velocity.
#[derive(Debug, Clone)]
pub struct VertexVelocity {
    times: FrameTimes,
    frames: Vec<Vec<DVec3>>,
    faces: Vec<[u32; 3]>,
}

impl VertexVelocity {
    /// `frames[k][v]`: the velocity of vertex `v` of `topology` at `times[k]`. Checks the
    /// shape and that every value is finite (naming vertex and frame time).
    pub fn new(
        times: FrameTimes,
        frames: Vec<Vec<DVec3>>,
        topology: &Topology,
    ) -> Result<Self, LcsError> {
        let n_vertices = topology.n_vertices();
        let k = times.times().len();
        if frames.len() != k || frames.iter().any(|f| f.len() != n_vertices) {
            let got = frames.iter().map(Vec::len).find(|&l| l != n_vertices);
            return Err(LcsError::Shape {
                name: "velocity".into(),
                expected: format!("({k}, {n_vertices}, 3)"),
                got: format!("({}, {}, 3)", frames.len(), got.unwrap_or(n_vertices)),
            });
        }
        for (f, frame) in frames.iter().enumerate() {
            if let Some(v) = frame.iter().position(|u| !u.is_finite()) {
                return Err(LcsError::NonFiniteVelocity {
                    at: format!("vertex {v}"),
                    time: times.times()[f],
                });
            }
        }
        Ok(Self {
            times,
            frames,
            faces: topology.faces().to_vec(),
        })
    }
}

impl VertexVelocity {
    /// The frames' times.
    pub fn times(&self) -> &[f64] {
        self.times.times()
    }
}

impl Velocity for VertexVelocity {
    fn eval(
        &mut self,
        t: f64,
        at: &[Located],
        _points: &[DVec3],
        out: &mut [DVec3],
    ) -> Result<(), LcsError> {
        let (k, s) = self.times.locate(t)?;
        let k1 = (k + 1).min(self.frames.len() - 1);
        let (a, b) = (&self.frames[k], &self.frames[k1]);
        out.par_iter_mut().zip(at).for_each(|(o, l)| {
            let tri = self.faces[l.face as usize];
            *o = (0..3)
                .map(|c| l.bary[c] * a[tri[c] as usize].lerp(b[tri[c] as usize], s))
                .sum();
        });
        Ok(())
    }
}
