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
//!   over frames, `(p^{t+H} − 2p^t + p^{t−H})/H²` ([`second_difference`]; the divided
//!   difference `2/(h₋+h₊)·((p^{t+h₊} − p^t)/h₊ − (p^t − p^{t−h₋})/h₋)` when the frames
//!   before and after last `h₋ ≠ h₊`, a Frame Time that changes). Over the frame
//!   interval `[t_k, t_{k+1}]` the simulator applies `½(p̈_k + p̈_{k+1})` when it is given
//!   the frame after (second order; a rotating disk's centripetal acceleration is then
//!   right from the first frame), else `p̈_k`, and `p̈_0` is the forward difference, or
//!   zero when only two frames are known (the cloth is taken to have moved uniformly
//!   before: liquid spilled on it moves with it).
//! - **Coriolis.** `F^{tᵀ} Ḟ` is antisymmetric; the seed estimates it by antisymmetrizing
//!   `(F^{tᵀ} F^{t+h} − F^{t+hᵀ} F^t)/2h`, whose axial vector is `sin(ϑ)/h` times the axis of
//!   the relative rotation `Q = F^{tᵀ} F^{t+h}` of angle `ϑ`. We rescale it by `ϑ / sin ϑ`,
//!   which makes `ω` exact for a steady rotation at any step (the seed's estimate is off
//!   by `ϑ²/6`) ([`frame_angular_velocity`]). Only the frame-normal component `ω_z` changes a
//!   tangential velocity (`ω_t × u` is normal), and `u̇ = −2 ω_z J u` (`J` the quarter turn)
//!   is integrated exactly, as the rotation of `u` by `−2 ω_z h` (within [`integrate_velocity`]):
//!   it turns the velocity without changing its speed, as the Coriolis force does, for
//!   any step size (forward Euler would add energy every step).
//! - **Gravity.** The tangential part of `g`: the `(x, y)` components of `F_iᵀ g` (the
//!   frame's `z` is the rotated rest normal, within the one-ring's bending of the true
//!   normal).
//! - **All together.** The simulator does not apply these one after the other: with the
//!   fibres' friction `−k u` they make the linear equation `u̇ = a − k u − 2ω_z J u`,
//!   which [`integrate_velocity`] solves exactly over a step for constant `a` and `ω`
//!   (its doc says why splitting it is wrong at cloth frictions).

use faer::c64;
use glam::{DMat3, DVec2, DVec3};
use rayon::prelude::*;

use crate::error::MeshError;
use crate::mesh::{OneRings, RingAdjacency, VertexFrames};

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

/// The comoving–corotating frames `F_i = U_i F̄_i` at `current` positions, `U_i` the
/// Kabsch rotation of vertex `i`'s one-ring from `rest` (module doc), with the adjacency
/// built once per mesh and positions already checked; one parallel pass.
///
/// # Panics
/// If `rest_frames`, `rest` or `current` does not have one entry per vertex.
pub(crate) fn corotating_frames_with(
    adjacency: &RingAdjacency,
    rest_frames: &VertexFrames,
    rest: &[DVec3],
    current: &[DVec3],
) -> VertexFrames {
    let mut frames = VertexFrames::default();
    corotating_frames_into(adjacency, rest_frames, rest, current, &mut frames);
    frames
}

/// [`corotating_frames_with`] into `out`'s array (its allocation kept).
pub(crate) fn corotating_frames_into(
    adjacency: &RingAdjacency,
    rest_frames: &VertexFrames,
    rest: &[DVec3],
    current: &[DVec3],
    out: &mut VertexFrames,
) {
    let n = adjacency.n_vertices();
    assert!(
        rest.len() == n && current.len() == n,
        "one position per vertex"
    );
    assert_eq!(rest_frames.len(), n, "one frame per vertex");
    rest_frames
        .frame
        .par_iter()
        .enumerate()
        .map(|(i, f)| adjacency.rotation(rest, current, i) * *f)
        .collect_into_vec(&mut out.frame);
}

/// The rest frames `F̄_i` (seed §4.3.1 frames of the rest positions).
pub(crate) fn rest_frames(rings: &OneRings, rest: &[DVec3]) -> Result<VertexFrames, MeshError> {
    VertexFrames::new(rings, rest)
}

/// Angular velocity `ω` of a frame turning from `a` to `b` in `h`, in the coordinates of
/// `a`: the axial vector of the antisymmetrized `F^{tᵀ} Ḟ`, rescaled to be exact for a
/// steady rotation (module doc).
pub(crate) fn frame_angular_velocity(a: &DMat3, b: &DMat3, h: f64) -> DVec3 {
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

/// The exact solution over `h` of the velocity equation of one vertex,
///
/// ```text
/// u̇ = a − k u − 2 ω_z J u        (J the quarter turn, a and ω_z constant over the step),
/// ```
///
/// the tangential body force `a`, friction `k ≥ 0` and Coriolis rotation together.
/// Returns the velocity at the end of the step and its mean over the step. In complex
/// form (`u = x + i y`, `λ = −(k + 2iω_z)`): `u(h) = e^{λh} u₀ + h φ₁(λh) a` and
/// `ū = φ₁(λh) u₀ + h φ₂(λh) a`, with `φ₁(z) = (e^z − 1)/z`, `φ₂(z) = (e^z − 1 − z)/z²`.
///
/// Why not split it: a kick `h a` followed by the friction factor `e^{−kh}` relaxes to
/// `h a e^{−kh}/(1 − e^{−kh})` instead of the terminal velocity `a/k` — at a cloth's
/// friction (`k = 50/s`) and a 24 fps frame (`kh ≈ 2`) that is 30 % of it. The exact
/// solution has the right terminal velocity, transient and Coriolis turn at any step;
/// without friction and rotation it is the plain `u₀ + h a` (mean `u₀ + h a/2`).
pub(crate) fn integrate_velocity(
    u: DVec2,
    a: DVec2,
    omega_z: f64,
    friction: f64,
    h: f64,
) -> (DVec2, DVec2) {
    VelocityStep::new(omega_z, friction, h).apply(u, a)
}

/// The propagator of [`integrate_velocity`] for one `(ω_z, k, h)`: `e^{λh}`, `φ₁(λh)` and
/// `φ₂(λh)`, computed once and applied to any `(u₀, a)`. The simulator's two half kicks
/// of a vertex share one (the same `ω_z`, `k` and `h/2`), and the decay `e^{−kh}`, the
/// real part of every vertex's `e^{λh}`, is computed once per step
/// ([`Self::with_decay`]): the same operations on the same numbers, so the same bits as
/// separate calls of [`integrate_velocity`].
#[derive(Debug, Clone, Copy)]
pub(crate) struct VelocityStep {
    e: c64,
    phi1: c64,
    phi2: c64,
    h: f64,
}

impl VelocityStep {
    /// The propagator over `h` for the rotation `omega_z` and friction `friction`.
    pub(crate) fn new(omega_z: f64, friction: f64, h: f64) -> Self {
        Self::with_decay(Self::decay(friction, h), omega_z, friction, h)
    }

    /// `e^{−kh}`, the modulus of `e^{λh}` whatever `ω_z` (the argument of
    /// [`Self::with_decay`]).
    pub(crate) fn decay(friction: f64, h: f64) -> f64 {
        (-friction * h).exp()
    }

    /// [`Self::new`] with `decay` = [`Self::decay`]`(friction, h)` computed by the caller
    /// (once for many vertices).
    pub(crate) fn with_decay(decay: f64, omega_z: f64, friction: f64, h: f64) -> Self {
        let (e, phi1, phi2) = phi(decay, c64::new(-friction * h, -2.0 * omega_z * h));
        Self { e, phi1, phi2, h }
    }

    /// The velocity at the end of the step from `u` under the constant force `a`, and its
    /// mean over the step ([`integrate_velocity`]).
    pub(crate) fn apply(&self, u: DVec2, a: DVec2) -> (DVec2, DVec2) {
        let (e, phi1, phi2, h) = (self.e, self.phi1, self.phi2, self.h);
        let (u, a) = (c64::new(u.x, u.y), c64::new(a.x, a.y));
        let end = e * u + phi1 * a * h;
        let mean = phi1 * u + phi2 * a * h;
        (DVec2::new(end.re, end.im), DVec2::new(mean.re, mean.im))
    }

    /// The velocity at the end of the step alone (the first of [`Self::apply`]).
    pub(crate) fn end(&self, u: DVec2, a: DVec2) -> DVec2 {
        let (u, a) = (c64::new(u.x, u.y), c64::new(a.x, a.y));
        let end = self.e * u + self.phi1 * a * self.h;
        DVec2::new(end.re, end.im)
    }

    /// The mean velocity over the step alone (the second of [`Self::apply`]).
    pub(crate) fn mean(&self, u: DVec2, a: DVec2) -> DVec2 {
        let (u, a) = (c64::new(u.x, u.y), c64::new(a.x, a.y));
        let mean = self.phi1 * u + self.phi2 * a * self.h;
        DVec2::new(mean.re, mean.im)
    }
}

/// `1/k!` for `k = 0..=7`: the Taylor coefficients of [`phi`]'s series (each factorial an
/// exact integer in `f64`, so `1.0 / k!` is the correctly rounded reciprocal, as the
/// product computed on the fly gave).
const INV_FACTORIAL: [f64; 8] = [
    1.0,
    1.0,
    1.0 / 2.0,
    1.0 / 6.0,
    1.0 / 24.0,
    1.0 / 120.0,
    1.0 / 720.0,
    1.0 / 5040.0,
];

/// `(e^z, φ₁(z), φ₂(z))` with `r = e^{Re z}` given; by their Taylor series for small `|z|`,
/// where the closed forms cancel (six terms: the error is below `|z|⁶/5040 ≤ 2e-22` for
/// `|z| ≤ 0.05`).
fn phi(r: f64, z: c64) -> (c64, c64, c64) {
    let (sin, cos) = z.im.sin_cos();
    let e = c64::new(r * cos, r * sin);
    if z.re.hypot(z.im) > 0.05 {
        let phi1 = c64::new(e.re - 1.0, e.im) / z;
        let phi2 = c64::new(phi1.re - 1.0, phi1.im) / z;
        return (e, phi1, phi2);
    }
    // φ₁ = Σ z^k/(k+1)!, φ₂ = Σ z^k/(k+2)!, k = 0..5 (Horner)
    let horner = |first: usize| {
        let mut acc = c64::new(0.0, 0.0);
        for k in (0..6).rev() {
            acc = acc * z + c64::new(INV_FACTORIAL[k + first], 0.0);
        }
        acc
    };
    (e, horner(1), horner(2))
}

/// Second difference of one vertex (world coordinates) at `cur`, `before` s after `prev`
/// and `after` s before `next`: the centred `(next − 2 cur + prev) / H²` when both are `H`,
/// else the divided difference `2/(h₋ + h₊) · ((next − cur)/h₊ − (cur − prev)/h₋)`, exact
/// for a uniform acceleration either way (a scene whose Frame Time changes).
pub(crate) fn second_difference(
    prev: DVec3,
    cur: DVec3,
    next: DVec3,
    before: f64,
    after: f64,
) -> DVec3 {
    if before == after {
        return (next - 2.0 * cur + prev) * (1.0 / (after * after));
    }
    ((next - cur) / after - (cur - prev) / before) * (2.0 / (before + after))
}

/// The tangential body acceleration: the `(x, y)` components of `fᵀ (g − a)` for frame
/// `f` and its acceleration `a` (world), for the enabled forces (the Coriolis term is
/// [`integrate_velocity`]'s).
pub(crate) fn frame_body_acceleration(
    f: &DMat3,
    a: DVec3,
    gravity: DVec3,
    forces: Forces,
) -> DVec2 {
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

    /// `u̇ = a − k u − 2ω J u` by classical RK4 with `steps` steps over `h`, and the
    /// trapezoid-rule mean of the samples (an independent reference).
    fn rk4(u: DVec2, a: DVec2, w: f64, k: f64, h: f64, steps: usize) -> (DVec2, DVec2) {
        let f = |u: DVec2| a - k * u - 2.0 * w * u.perp();
        let dt = h / steps as f64;
        let (mut u, mut sum) = (u, 0.5 * u);
        for s in 0..steps {
            let k1 = f(u);
            let k2 = f(u + 0.5 * dt * k1);
            let k3 = f(u + 0.5 * dt * k2);
            let k4 = f(u + dt * k3);
            u += dt / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4);
            sum += if s + 1 == steps { 0.5 * u } else { u };
        }
        (u, sum / steps as f64)
    }

    #[test]
    fn integrate_velocity_matches_a_fine_reference_and_the_closed_forms() {
        let (u0, a) = (DVec2::new(0.3, -0.2), DVec2::new(-1.5, 4.0));
        // small and large |z| (the series and the closed form), with and without friction
        for (w, k, h) in [
            (0.0, 50.0, 1.0 / 24.0),
            (3.0, 50.0, 1.0 / 24.0),
            (0.7, 0.0, 0.5),
            (1e-4, 1e-3, 0.01),
            (0.2, 0.1, 0.1),
        ] {
            let (end, mean) = integrate_velocity(u0, a, w, k, h);
            let (re, rm) = rk4(u0, a, w, k, h, 20_000);
            let scale = u0.length() + a.length() * h;
            assert!(
                (end - re).length() < 1e-9 * scale,
                "{w} {k} {h}: {end} vs {re}"
            );
            assert!(
                (mean - rm).length() < 1e-8 * scale,
                "{w} {k} {h}: {mean} vs {rm}"
            );
        }
        // no friction, no turn: u₀ + h a exactly, and the mean is the midpoint
        let (end, mean) = integrate_velocity(u0, a, 0.0, 0.0, 0.25);
        assert_eq!(end, u0 + 0.25 * a);
        assert!((mean - (u0 + 0.125 * a)).length() < 1e-15);
        // friction: the terminal velocity a/k whatever the step (the split kick + decay
        // relaxes to h a e^{-kh}/(1 - e^{-kh}), 30 % of it at kh = 2)
        let mut u = DVec2::ZERO;
        for _ in 0..40 {
            u = integrate_velocity(u, a, 0.0, 50.0, 1.0 / 24.0).0;
        }
        assert!((u - a / 50.0).length() < 1e-14, "{u} vs {}", a / 50.0);
        // pure rotation keeps the speed and turns by −2ωh
        let (end, _) = integrate_velocity(u0, DVec2::ZERO, 0.8, 0.0, 0.3);
        let (sin, cos) = (-2.0f64 * 0.8 * 0.3).sin_cos();
        let turned = DVec2::new(cos * u0.x - sin * u0.y, sin * u0.x + cos * u0.y);
        assert!((end - turned).length() < 1e-15);
    }

    #[test]
    fn angular_velocity_is_exact_for_a_steady_rotation() {
        let f0 = vec![
            DMat3::IDENTITY,
            DMat3::from_rotation_x(0.7) * DMat3::from_rotation_z(0.2),
        ];
        let axis = DVec3::new(0.3, -0.4, 0.866).normalize();
        let (w, h) = (2.5, 0.1); // ϑ = 0.25 rad per step
        let turn = DMat3::from_axis_angle(axis, w * h);
        for f in &f0 {
            let om = frame_angular_velocity(f, &(turn * *f), h);
            // in body coordinates: Fᵀ axis
            let expect = f.transpose() * axis * w;
            assert!((om - expect).length() < 1e-12, "{om} vs {expect}");
        }
    }

    #[test]
    fn coriolis_turns_the_velocity_at_twice_the_rate_and_keeps_its_speed() {
        // no force, no friction: the Coriolis turn alone, ω_z = 0.8
        let mut u = DVec2::new(1.0, 0.5);
        let h = 0.05;
        for _ in 0..100 {
            u = integrate_velocity(u, DVec2::ZERO, 0.8, 0.0, h).0;
        }
        // total turn −2·0.8·5 = −8 rad
        let (s, c) = (-8.0f64).sin_cos();
        let expect = DVec2::new(c - s * 0.5, s + c * 0.5);
        assert!((u - expect).length() < 1e-12);
    }

    #[test]
    fn body_acceleration_is_the_tangential_part_of_g_minus_the_frame_acceleration() {
        let f = DMat3::from_rotation_x(0.4);
        let g = DVec3::new(0.0, 0.0, -9.81);
        let a = DVec3::new(1.0, 2.0, 0.5);
        let all = frame_body_acceleration(&f, a, g, Forces::default());
        let w = g - a;
        assert!((all - DVec2::new(f.x_axis.dot(w), f.y_axis.dot(w))).length() < 1e-15);
        let only_g = frame_body_acceleration(
            &f,
            a,
            g,
            Forces {
                rectilinear: false,
                ..Forces::default()
            },
        );
        assert!((only_g - DVec2::new(0.0, f.y_axis.dot(g))).length() < 1e-15);
        let none = frame_body_acceleration(
            &f,
            a,
            g,
            Forces {
                gravity: false,
                rectilinear: false,
                coriolis: false,
            },
        );
        assert_eq!(none, DVec2::ZERO);
    }

    #[test]
    fn centred_difference_is_exact_for_uniform_acceleration() {
        let acc = DVec3::new(0.3, -1.0, 2.0);
        let p = |t: f64| DVec3::new(1.0, 2.0, 3.0) + DVec3::X * t + 0.5 * acc * t * t;
        let dt = 0.04;
        let a = second_difference(p(1.0 - dt), p(1.0), p(1.0 + dt), dt, dt);
        assert!((a - acc).length() < 1e-9, "{a}");
    }

    #[test]
    fn uneven_difference_is_exact_for_uniform_acceleration() {
        // a frame of 1/24 s before and of a minute after (a Frame Time keyed up)
        let acc = DVec3::new(0.3, -1.0, 2.0);
        let p = |t: f64| DVec3::new(1.0, 2.0, 3.0) + DVec3::X * t + 0.5 * acc * t * t;
        let (before, after) = (1.0 / 24.0, 60.0);
        let a = second_difference(p(1.0 - before), p(1.0), p(1.0 + after), before, after);
        assert!((a - acc).length() < 1e-6, "{a}");
        // and not what the centred formula with either length gives
        let centred = second_difference(p(1.0 - before), p(1.0), p(1.0 + after), after, after);
        assert!((centred - acc).length() > 0.1, "{centred}");
    }
}
