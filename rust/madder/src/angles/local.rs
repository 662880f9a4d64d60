//! Preprocessing of the input angles (§3.3.4), the local four-vertex construction of an
//! interior edge (Fig. 3.1), the face frames (Fig. 3.2) and the transition matrices
//! (eq. 3.2).

use std::f64::consts::PI;

use glam::{DMat3, DVec3};
use rayon::prelude::*;

use super::encode::{AngleMesh, Angles, Interior};

/// The clamping margin `ε` of §3.3.4 (radians).
pub const EPS: f64 = 0.02;

/// Clamps corners to `[ε, π − ε]`, dihedrals to `[−π + ε, π − ε]`, and rescales each face's
/// corners to sum to `π` (eq. 3.1).
pub(crate) fn preprocess(angles: &Angles) -> Angles {
    let corners = angles
        .corners
        .par_iter()
        .map(|c| {
            let c = c.map(|a| a.clamp(EPS, PI - EPS));
            let s = PI / (c[0] + c[1] + c[2]);
            c.map(|a| a * s)
        })
        .collect();
    let dihedrals = angles
        .dihedrals
        .par_iter()
        .map(|d| d.clamp(-PI + EPS, PI - EPS))
        .collect();
    Angles { corners, dihedrals }
}

/// The corners of an interior edge's two faces: `t₁ = (a, b, k)` at `a`, `b`, `k` and
/// `t₂ = (b, a, l)` at `a`, `b`, `l`.
pub(crate) fn edge_corners(e: &Interior, corners: &[[f64; 3]]) -> ([f64; 3], [f64; 3]) {
    let (c1, c2) = (e.c1 as usize, e.c2 as usize);
    let t1 = corners[e.f1 as usize];
    let t2 = corners[e.f2 as usize];
    (
        [t1[(c1 + 1) % 3], t1[(c1 + 2) % 3], t1[c1]],
        [t2[(c2 + 2) % 3], t2[(c2 + 1) % 3], t2[c2]],
    )
}

/// Fig. 3.1: `a = 0`, `b = (1, 0, 0)`, `k` in the `xy`-plane on the `+y` side, `l` on the
/// `−y` side turned about the `x`-axis by `θ`. `s1`, `s2`: corners of `t₁` at `(a, b, k)`
/// and of `t₂` at `(a, b, l)`. Returns `[a, b, k, l]`.
pub(crate) fn four_points(s1: [f64; 3], s2: [f64; 3], theta: f64) -> [DVec3; 4] {
    // law of sines on |ab| = 1: |ak| = sin(∠b) / sin(∠k)
    let ak = s1[1].sin() / s1[2].sin();
    let al = s2[1].sin() / s2[2].sin();
    let k = ak * DVec3::new(s1[0].cos(), s1[0].sin(), 0.0);
    let (sa, ca) = s2[0].sin_cos();
    let (st, ct) = theta.sin_cos();
    let l = al * DVec3::new(ca, -sa * ct, -sa * st);
    [DVec3::ZERO, DVec3::X, k, l]
}

/// The frame `(p₁ − p₀, p₂ − p₀, √A n)` of a triangle (Fig. 3.2).
pub(crate) fn frame(p: [DVec3; 3]) -> DMat3 {
    let (e1, e2) = (p[1] - p[0], p[2] - p[0]);
    let n = e1.cross(e2);
    // √A n = N / √(2|N|) for N = e1 × e2, |N| = 2A
    DMat3::from_cols(e1, e2, n / (2.0 * n.length()).sqrt())
}

/// The frames `F̄₁`, `F̄₂` of the two faces of `e` in the local construction, each in its
/// face's own corner order.
pub(crate) fn local_frames(e: &Interior, corners: &[[f64; 3]], theta: f64) -> (DMat3, DMat3) {
    let (s1, s2) = edge_corners(e, corners);
    let [a, b, k, l] = four_points(s1, s2, theta);
    let (c1, c2) = (e.c1 as usize, e.c2 as usize);
    // f1 = (k, a, b) starting at corner c1; f2 = (l, b, a) starting at corner c2
    let mut p1 = [DVec3::ZERO; 3];
    p1[c1] = k;
    p1[(c1 + 1) % 3] = a;
    p1[(c1 + 2) % 3] = b;
    let mut p2 = [DVec3::ZERO; 3];
    p2[c2] = l;
    p2[(c2 + 1) % 3] = b;
    p2[(c2 + 2) % 3] = a;
    (frame(p1), frame(p2))
}

/// Per interior edge: the local frames `(F̄₁, F̄₂)` and the transition `R = F̄₂⁻¹ F̄₁`
/// (eq. 3.2: `F₁ = F₂ R`), from preprocessed angles.
pub(crate) struct Transitions {
    pub(crate) local: Vec<(DMat3, DMat3)>,
    pub(crate) r: Vec<DMat3>,
}

pub(crate) fn transitions(mesh: &AngleMesh, angles: &Angles) -> Transitions {
    let local: Vec<(DMat3, DMat3)> = mesh
        .interior()
        .par_iter()
        .zip(angles.dihedrals.par_iter())
        .map(|(e, &t)| local_frames(e, &angles.corners, t))
        .collect();
    let r = local
        .par_iter()
        .map(|(f1, f2)| f2.inverse() * *f1)
        .collect();
    Transitions { local, r }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::angles::encode::corner_angle;

    #[test]
    fn four_points_reproduce_their_angles() {
        let s1 = [0.9, 1.1, PI - 2.0];
        let s2 = [0.7, 1.3, PI - 2.0];
        for theta in [-2.5, -0.3, 0.0, 0.4, 2.9] {
            let [a, b, k, l] = four_points(s1, s2, theta);
            assert!((corner_angle(a, b, k) - s1[0]).abs() < 1e-12);
            assert!((corner_angle(b, k, a) - s1[1]).abs() < 1e-12);
            assert!((corner_angle(a, l, b) - s2[0]).abs() < 1e-12);
            assert!((corner_angle(b, a, l) - s2[1]).abs() < 1e-12);
            // t1 = (a, b, k), t2 = (b, a, l): θ from their normals about a → b
            let n1 = (b - a).cross(k - a);
            let n2 = (a - b).cross(l - b);
            let got = n1.cross(n2).dot(DVec3::X).atan2(n1.dot(n2));
            assert!((got - theta).abs() < 1e-12, "{got} vs {theta}");
        }
    }

    #[test]
    fn preprocess_clamps_and_sums_to_pi() {
        let a = Angles {
            corners: vec![[0.0, 3.0, 1.0], [1.0, 1.0, 1.0]],
            dihedrals: vec![4.0, -4.0, 0.5],
        };
        let p = preprocess(&a);
        for c in &p.corners {
            assert!((c.iter().sum::<f64>() - PI).abs() < 1e-14);
            assert!(c.iter().all(|&x| x >= EPS / 3.0));
        }
        assert_eq!(p.dihedrals, vec![PI - EPS, -PI + EPS, 0.5]);
    }
}
