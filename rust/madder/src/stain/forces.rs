//! Body forces on the stain's liquid in comoving–corotating vertex frames (seed §4.4).
//!
//! The velocity `u_i` is stored in a frame `F_i` that moves with vertex `i` and turns with
//! its one-ring, so Newton's law in it picks up fictitious forces. The seed builds
//! `F_i = U_i F̄_i`: the rest frame `F̄_i` ([`VertexFrames::new`] on the rest positions)
//! turned by the rotation `U_i` that best aligns the rest one-ring to the current one
//! (the Kabsch procedure, [`crate::mesh::kabsch::one_ring_rotations`]):
//!
//! ```text
//! U_i = argmin_{R ∈ SO(3)} Σ_j |(v_j − v_i) − R (v̄_j − v̄_i)|².
//! ```
//!
//! A parcel at the frame's origin (`r = 0`, so the centrifugal and Euler terms vanish)
//! with velocity `u` in the frame feels, in frame coordinates,
//!
//! ```text
//! a_inertia = −F_iᵀ p̈_i − 2 ω_i × u,        a_ext = a_inertia + (g − (g·n) n),
//! ```
//!
//! of which the tangential `(x, y)` components act. Each term can be switched off
//! ([`Forces`]), as the seed's Figs. 4.1/4.2 do.
//!
//! - **Rectilinear.** `p̈_i` is the centred second difference of the vertex positions
//!   over frames, `(p^{t+H} − 2p^t + p^{t−H})/H²` ([`frame_acceleration`]). Over the frame
//!   interval `[t_k, t_{k+1}]` the simulator applies `½(p̈_k + p̈_{k+1})` when it is given
//!   the frame after (second order; a rotating disk's centripetal acceleration is then
//!   right from the first frame), else `p̈_k`, and `p̈_0` is the forward difference, or
//!   zero when only two frames are known (the cloth is taken to have moved uniformly
//!   before: liquid spilled on it moves with it).
//! - **Coriolis.** `F^{tᵀ} Ḟ` is antisymmetric; the seed estimates it by antisymmetrizing
//!   `(F^{tᵀ} F^{t+h} − F^{t+hᵀ} F^t)/2h`, whose axial vector is `sin(ϑ)/h` times the axis of
//!   the relative rotation `Q = F^{tᵀ} F^{t+h}` of angle `ϑ`. We rescale it by `ϑ / sin ϑ`,
//!   which makes `ω` exact for a steady rotation at any step (the seed's estimate is off
//!   by `ϑ²/6`) ([`angular_velocity`]). Only the frame-normal component `ω_z` changes a
//!   tangential velocity (`ω_t × u` is normal), and `u̇ = −2 ω_z J u` (`J` the quarter turn)
//!   is integrated exactly, as the rotation of `u` by `−2 ω_z h` ([`apply_coriolis`]):
//!   it turns the velocity without changing its speed, as the Coriolis force does, for
//!   any step size (forward Euler would add energy every step).
//! - **Gravity.** The tangential part of `g`: the `(x, y)` components of `F_iᵀ g` (the
//!   frame's `z` is the rotated rest normal, within the one-ring's bending of the true
//!   normal).

use glam::{DMat3, DVec2, DVec3};
use rayon::prelude::*;

use crate::error::MeshError;
use crate::mesh::{OneRings, RingAdjacency, Topology, VertexFrames, one_ring_rotations};

/// Which body forces act (each can be switched off, as in the seed's Figs. 4.1/4.2).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Forces {
    /// Tangential gravity.
    pub gravity: bool,
    /// The rectilinear fictitious force `−Fᵀp̈` of the frame's acceleration.
    pub rectilinear: bool,
    /// The Coriolis force `−2ω×u` of the frame's rotation.
    pub coriolis: bool,
}

impl Default for Forces {
    fn default() -> Self {
        Self {
            gravity: true,
            rectilinear: true,
            coriolis: true,
        }
    }
}

/// The comoving–corotating frames `F_i = U_i F̄_i` at `current` positions.
pub fn corotating_frames(
    topology: &Topology,
    rest_frames: &VertexFrames,
    rest: &[DVec3],
    current: &[DVec3],
) -> Result<VertexFrames, MeshError> {
    let rotation = one_ring_rotations(topology, rest, current)?;
    Ok(rest_frames.rotated(&rotation))
}

/// [`corotating_frames`] with the adjacency built once per mesh and positions already
/// checked: each frame `U_i F̄_i` in one parallel pass (the same values).
///
/// # Panics
/// If `rest_frames`, `rest` or `current` does not have one entry per vertex.
pub fn corotating_frames_with(
    adjacency: &RingAdjacency,
    rest_frames: &VertexFrames,
    rest: &[DVec3],
    current: &[DVec3],
) -> VertexFrames {
    let n = adjacency.n_vertices();
    assert!(
        rest.len() == n && current.len() == n,
        "one position per vertex"
    );
    assert_eq!(rest_frames.len(), n, "one frame per vertex");
    VertexFrames {
        frame: rest_frames
            .frame
            .par_iter()
            .enumerate()
            .map(|(i, f)| adjacency.rotation(rest, current, i) * *f)
            .collect(),
    }
}

/// The rest frames `F̄_i` (seed §4.3.1 frames of the rest positions).
pub fn rest_frames(rings: &OneRings, rest: &[DVec3]) -> Result<VertexFrames, MeshError> {
    VertexFrames::new(rings, rest)
}

/// Angular velocity `ω_i` of every frame between `before` and `after` (`h` apart), in the
/// coordinates of `before`: the axial vector of the antisymmetrized `F^{tᵀ} Ḟ`, rescaled
/// to be exact for a steady rotation (module doc).
pub fn angular_velocity(before: &VertexFrames, after: &VertexFrames, h: f64) -> Vec<DVec3> {
    assert_eq!(before.len(), after.len(), "frames of different meshes");
    before
        .frame
        .par_iter()
        .zip(&after.frame)
        .map(|(a, b)| frame_angular_velocity(a, b, h))
        .collect()
}

/// `ω` of one frame turning from `a` to `b` in `h` (see [`angular_velocity`]).
pub fn frame_angular_velocity(a: &DMat3, b: &DMat3, h: f64) -> DVec3 {
    let q: DMat3 = a.transpose() * *b;
    // axial vector of (Q − Qᵀ)/2 = sin ϑ · axis
    let s = 0.5
        * DVec3::new(
            q.y_axis.z - q.z_axis.y,
            q.z_axis.x - q.x_axis.z,
            q.x_axis.y - q.y_axis.x,
        );
    let sin = s.length();
    let cos = (0.5 * (q.x_axis.x + q.y_axis.y + q.z_axis.z - 1.0)).clamp(-1.0, 1.0);
    let angle = sin.atan2(cos);
    // ϑ / sin ϑ → 1 as ϑ → 0 (below 1e-8 the ratio is 1 to rounding)
    let scale = if sin > 1e-8 { angle / sin } else { 1.0 };
    s * (scale / h)
}

/// Rotates every velocity by `−2 ω_z h`: the exact solution of `u̇ = −2 ω × u` restricted
/// to the tangent plane over a step `h` (`omega` in frame coordinates).
pub fn apply_coriolis(omega: &[DVec3], h: f64, velocity: &mut [DVec2]) {
    assert_eq!(omega.len(), velocity.len());
    velocity
        .par_iter_mut()
        .zip(omega)
        .for_each(|(u, w)| *u = coriolis_turn(*w, h, *u));
}

/// `u` turned by `−2 ω_z h` (one vertex of [`apply_coriolis`]).
pub fn coriolis_turn(omega: DVec3, h: f64, u: DVec2) -> DVec2 {
    let (sin, cos) = (-2.0 * omega.z * h).sin_cos();
    DVec2::new(cos * u.x - sin * u.y, sin * u.x + cos * u.y)
}

/// Centred second difference `(next − 2 cur + prev) / H²` per vertex (world coordinates).
pub fn frame_acceleration(prev: &[DVec3], cur: &[DVec3], next: &[DVec3], dt: f64) -> Vec<DVec3> {
    let inv = 1.0 / (dt * dt);
    prev.par_iter()
        .zip(cur)
        .zip(next)
        .map(|((a, b), c)| (*c - 2.0 * *b + *a) * inv)
        .collect()
}

/// The tangential body acceleration `(x, y)` components of `F_iᵀ (g − p̈_i)` for the
/// enabled forces (the Coriolis term is applied separately, [`apply_coriolis`]).
pub fn body_acceleration(
    frames: &VertexFrames,
    acceleration: &[DVec3],
    gravity: DVec3,
    forces: Forces,
) -> Vec<DVec2> {
    frames
        .frame
        .par_iter()
        .zip(acceleration)
        .map(|(f, &a)| frame_body_acceleration(f, a, gravity, forces))
        .collect()
}

/// One vertex of [`body_acceleration`]: frame `f`, its acceleration `a` (world).
pub fn frame_body_acceleration(f: &DMat3, a: DVec3, gravity: DVec3, forces: Forces) -> DVec2 {
    let g = if forces.gravity { gravity } else { DVec3::ZERO };
    let world = if forces.rectilinear { g - a } else { g };
    frames_local(f, world)
}

fn frames_local(f: &DMat3, w: DVec3) -> DVec2 {
    DVec2::new(f.x_axis.dot(w), f.y_axis.dot(w))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn turned(frames: &[DMat3], r: DMat3) -> VertexFrames {
        VertexFrames {
            frame: frames.iter().map(|f| r * *f).collect(),
        }
    }

    #[test]
    fn angular_velocity_is_exact_for_a_steady_rotation() {
        let f0 = vec![
            DMat3::IDENTITY,
            DMat3::from_rotation_x(0.7) * DMat3::from_rotation_z(0.2),
        ];
        let axis = DVec3::new(0.3, -0.4, 0.866).normalize();
        let (w, h) = (2.5, 0.1); // ϑ = 0.25 rad per step
        let a = VertexFrames { frame: f0.clone() };
        let b = turned(&f0, DMat3::from_axis_angle(axis, w * h));
        for (k, om) in angular_velocity(&a, &b, h).iter().enumerate() {
            // in body coordinates: Fᵀ axis
            let expect = f0[k].transpose() * axis * w;
            assert!((*om - expect).length() < 1e-12, "{om} vs {expect}");
        }
    }

    #[test]
    fn coriolis_turns_the_velocity_at_twice_the_rate_and_keeps_its_speed() {
        let mut u = vec![DVec2::new(1.0, 0.5)];
        let omega = vec![DVec3::new(0.3, 0.1, 0.8)];
        let h = 0.05;
        for _ in 0..100 {
            apply_coriolis(&omega, h, &mut u);
        }
        // total turn −2·0.8·5 = −8 rad
        let (s, c) = (-8.0f64).sin_cos();
        let expect = DVec2::new(c - s * 0.5, s + c * 0.5);
        assert!((u[0] - expect).length() < 1e-12);
    }

    #[test]
    fn body_acceleration_is_the_tangential_part_of_g_minus_the_frame_acceleration() {
        let f = DMat3::from_rotation_x(0.4);
        let frames = VertexFrames { frame: vec![f] };
        let g = DVec3::new(0.0, 0.0, -9.81);
        let a = DVec3::new(1.0, 2.0, 0.5);
        let all = body_acceleration(&frames, &[a], g, Forces::default())[0];
        let w = g - a;
        assert!((all - DVec2::new(f.x_axis.dot(w), f.y_axis.dot(w))).length() < 1e-15);
        let only_g = body_acceleration(
            &frames,
            &[a],
            g,
            Forces {
                rectilinear: false,
                ..Forces::default()
            },
        )[0];
        assert!((only_g - DVec2::new(0.0, f.y_axis.dot(g))).length() < 1e-15);
        let none = body_acceleration(
            &frames,
            &[a],
            g,
            Forces {
                gravity: false,
                rectilinear: false,
                coriolis: false,
            },
        )[0];
        assert_eq!(none, DVec2::ZERO);
    }

    #[test]
    fn centred_difference_is_exact_for_uniform_acceleration() {
        let acc = DVec3::new(0.3, -1.0, 2.0);
        let p = |t: f64| vec![DVec3::new(1.0, 2.0, 3.0) + DVec3::X * t + 0.5 * acc * t * t];
        let dt = 0.04;
        let a = frame_acceleration(&p(1.0 - dt), &p(1.0), &p(1.0 + dt), dt)[0];
        assert!((a - acc).length() < 1e-9, "{a}");
    }
}
