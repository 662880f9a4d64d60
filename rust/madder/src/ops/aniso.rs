//! Anisotropic diffusion stiffness on a woven cloth (seed §4.3.3–4.3.4).
//!
//! Each face carries a symmetric positive definite tensor `S = [s11, s12; s12, s22]` in the
//! basis `(e, e⊥)` of its weft `e` and warp `e⊥` (the fabric issue computes `S` by
//! homogenization, ch. 2). The face's tensor in the surface is `S_T = (e, e⊥) S (e, e⊥)ᵀ`
//! and the P1 stiffness is
//!
//! ```text
//! K_ij = Σ_T ∫_T ∇φ_i · S_T ∇φ_j = Σ_T A_T g_iᵀ S g_j,      g_i = ((∇φ_i·e), (∇φ_i·e⊥)).
//! ```
//!
//! Everything is computed in the face's *intrinsic layout* from its (mollified) edge
//! lengths: corner 0 at the origin, corner 1 on the positive x axis, corner 2 above it.
//! There `∇φ_i = rot₉₀(x_{i+2} − x_{i+1}) / 2A`, and the weft is an angle `θ_T` from the
//! edge 0→1. With `S = I`, `A g_iᵀ g_j = −½ cot θ_k`: the cotan stiffness (§4.3.3).
//!
//! ## Weft from the UV layout
//! The weft of a face is the direction of its UV `u` axis on the surface: with corner UVs
//! `u_k` and layout positions `x_k`, the map `x = x_0 + J (u − u_0)` has
//! `J = [x_1−x_0, x_2−x_0] [u_1−u_0, u_2−u_0]⁻¹` and the weft is `J (1, 0)ᵀ` normalized.
//! It is recomputed every frame from the deformed geometry, so it follows the cloth as it
//! shears. A mirrored UV island (negative `det`) still yields the true `∂x/∂u`.
//! A face whose UV triangle is degenerate (`|det| ≤ ε |u_1−u_0| |u_2−u_0|` with
//! `ε` = [`DEGENERATE_UV_REL`], or not finite)
//! has no defined `u` axis: its weft falls back to the edge 0→1 and it is counted, so the
//! caller can warn. A per-face angle offset (a fabric cut on the bias) is added to `θ_T`.

use glam::{DVec2, DVec3};

use super::VertexPattern;
use super::cotan::assemble_face_weights;
use crate::mesh::{Geometry, Topology};
use crate::weave::Tensor2;

/// Relative size `ε` of the UV determinant below which a face's UV triangle is degenerate
/// (`|det| ≤ ε |u_1−u_0| |u_2−u_0|`: no `u` axis, the weft falls back to the edge 0→1).
/// The add-on counts such faces with the same test, reading this value from Python.
pub const DEGENERATE_UV_REL: f64 = 1e-12;

/// Whether the UV edges `a = u_1 − u_0`, `b = u_2 − u_0` with `det = a × b` define a `u`
/// axis (see [`DEGENERATE_UV_REL`]); a NaN determinant or UV does not.
fn has_uv_axis(a: DVec2, b: DVec2, det: f64) -> bool {
    det.abs() > DEGENERATE_UV_REL * a.length() * b.length()
}

/// Corner positions of face `f` in its intrinsic layout.
fn layout(l: [f64; 3], area: f64) -> [DVec2; 3] {
    // l[k] is opposite corner k: |x1−x0| = l[2], |x2−x0| = l[1]
    let cos0 = (l[1] * l[1] + l[2] * l[2] - l[0] * l[0]) / (2.0 * l[1] * l[2]);
    let sin0 = 2.0 * area / (l[1] * l[2]);
    [
        DVec2::ZERO,
        DVec2::new(l[2], 0.0),
        l[1] * DVec2::new(cos0, sin0),
    ]
}

fn face_lengths(topology: &Topology, geometry: &Geometry, f: usize) -> [f64; 3] {
    topology.face_edges()[f].map(|e| geometry.edge_length[e as usize])
}

/// Weft angle of every face (radians from its edge 0→1, counter-clockwise in its layout)
/// from corner UVs, plus `offset[f]`. Returns the angles and the number of faces whose UVs
/// were degenerate (their weft falls back to edge 0→1).
pub fn weft_angles(
    topology: &Topology,
    geometry: &Geometry,
    uv: &[[[f64; 2]; 3]],
    offset: &[f64],
) -> (Vec<f64>, usize) {
    let mut degenerate = 0;
    let angles = (0..topology.n_faces())
        .map(|f| {
            let x = layout(face_lengths(topology, geometry, f), geometry.face_area[f]);
            let u = uv[f].map(DVec2::from_array);
            let (a, b) = (u[1] - u[0], u[2] - u[0]);
            let det = a.perp_dot(b);
            if !has_uv_axis(a, b, det) {
                degenerate += 1;
                return offset[f];
            }
            // J (1,0)ᵀ = X U⁻¹ (1,0)ᵀ = X (b.y, −a.y) / det
            let w = ((x[1] - x[0]) * b.y - (x[2] - x[0]) * a.y) / det;
            w.y.atan2(w.x) + offset[f]
        })
        .collect();
    (angles, degenerate)
}

/// 3-D weft direction of every face at `positions`, rotated by `offset[f]` about the face
/// normal (unit vectors; the edge 0→1 direction for faces with degenerate UVs). For
/// showing the weft to users.
pub fn weft_directions(
    topology: &Topology,
    positions: &[DVec3],
    uv: &[[[f64; 2]; 3]],
    offset: &[f64],
) -> Vec<DVec3> {
    topology
        .faces()
        .iter()
        .zip(uv)
        .zip(offset)
        .map(|((tri, uv), &angle)| {
            let p = tri.map(|v| positions[v as usize]);
            let u = uv.map(DVec2::from_array);
            let (a, b) = (u[1] - u[0], u[2] - u[0]);
            let det = a.perp_dot(b);
            let w = if has_uv_axis(a, b, det) {
                ((p[1] - p[0]) * b.y - (p[2] - p[0]) * a.y) / det
            } else {
                p[1] - p[0]
            }
            .normalize_or_zero();
            let n = (p[1] - p[0]).cross(p[2] - p[0]).normalize_or_zero();
            let (s, c) = angle.sin_cos();
            c * w + s * n.cross(w)
        })
        .collect()
}

/// The anisotropic stiffness `scale · K_S` of the module doc on `pattern`, each face's
/// tensor in the basis of its weft at `weft_angle[f]` (from [`weft_angles`]).
pub fn anisotropic_stiffness(
    topology: &Topology,
    geometry: &Geometry,
    pattern: &VertexPattern,
    weft_angle: &[f64],
    tensor: &[Tensor2],
    scale: f64,
) -> Vec<f64> {
    assemble_face_weights(topology, pattern, |f| {
        face_weights(topology, geometry, weft_angle[f], tensor[f], f, scale)
    })
}

/// [`anisotropic_stiffness`] with face `f`'s tensor also scaled by `face_scale[f]` (a
/// diffusion rate that varies over the cloth: the wicking of a wet fabric).
pub fn anisotropic_stiffness_scaled(
    topology: &Topology,
    geometry: &Geometry,
    pattern: &VertexPattern,
    weft_angle: &[f64],
    tensor: &[Tensor2],
    scale: f64,
    face_scale: &[f64],
) -> Vec<f64> {
    assemble_face_weights(topology, pattern, |f| {
        face_weights(
            topology,
            geometry,
            weft_angle[f],
            tensor[f],
            f,
            scale * face_scale[f],
        )
    })
}

/// `scale · A_T g_aᵀ S g_b` for the edge opposite each corner of face `f` (module doc).
fn face_weights(
    topology: &Topology,
    geometry: &Geometry,
    weft_angle: f64,
    tensor: Tensor2,
    f: usize,
    scale: f64,
) -> [f64; 3] {
    let area = geometry.face_area[f];
    let x = layout(face_lengths(topology, geometry, f), area);
    let (s, c) = weft_angle.sin_cos();
    let [s11, s12, s22] = tensor;
    // gradient of corner i's hat function, in (weft, warp) coordinates
    let g = |i: usize| {
        let d = x[(i + 2) % 3] - x[(i + 1) % 3];
        let grad = DVec2::new(-d.y, d.x) / (2.0 * area);
        DVec2::new(c * grad.x + s * grad.y, -s * grad.x + c * grad.y)
    };
    let gs = [g(0), g(1), g(2)];
    // weight of the edge opposite corner k, between corners k+1 and k+2
    std::array::from_fn(|k| {
        let (a, b) = (gs[(k + 1) % 3], gs[(k + 2) % 3]);
        scale * area * (a.x * (s11 * b.x + s12 * b.y) + a.y * (s12 * b.x + s22 * b.y))
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ops::cotan_stiffness;

    fn fan() -> (Topology, Vec<DVec3>) {
        // an irregular, non-planar fan around vertex 0
        let p = vec![
            DVec3::new(0.0, 0.0, 0.1),
            DVec3::new(1.0, 0.1, 0.0),
            DVec3::new(0.3, 0.9, 0.2),
            DVec3::new(-0.8, 0.5, 0.0),
            DVec3::new(-0.6, -0.7, -0.1),
            DVec3::new(0.5, -0.9, 0.0),
        ];
        let faces = vec![[0, 1, 2], [0, 2, 3], [0, 3, 4], [0, 4, 5], [0, 5, 1]];
        (Topology::from_triangles(6, faces).unwrap(), p)
    }

    #[test]
    fn identity_tensor_is_the_cotan_stiffness() {
        let (t, p) = fan();
        let g = Geometry::new(&t, &p).unwrap();
        let pat = VertexPattern::new(&t);
        let angles: Vec<f64> = (0..t.n_faces()).map(|f| 0.3 * f as f64).collect();
        let k = anisotropic_stiffness(&t, &g, &pat, &angles, &[[2.0, 0.0, 2.0]; 5], 1.0);
        let c = cotan_stiffness(&t, &g, &pat, 2.0);
        for (a, b) in k.iter().zip(&c) {
            assert!((a - b).abs() < 1e-12, "{a} vs {b}");
        }
    }

    #[test]
    fn flat_plane_energy_matches_the_tensor() {
        // on a flat mesh with UV = (x, y), the weft is +x; for a linear function
        // f = a·x the energy is fᵀKf = aᵀ S a × area
        let (t, mut p) = fan();
        p.iter_mut().for_each(|q| q.z = 0.0);
        let g = Geometry::new(&t, &p).unwrap();
        let uv: Vec<[[f64; 2]; 3]> = t
            .faces()
            .iter()
            .map(|tri| tri.map(|v| [p[v as usize].x, p[v as usize].y]))
            .collect();
        let (ang, bad) = weft_angles(&t, &g, &uv, &[0.0; 5]);
        assert_eq!(bad, 0);
        let s = [3.0, 0.7, 0.5];
        let pat = VertexPattern::new(&t);
        let k = anisotropic_stiffness(&t, &g, &pat, &ang, &[s; 5], 1.0);
        let a = DVec2::new(0.4, -1.3);
        let f: Vec<f64> = p.iter().map(|q| a.x * q.x + a.y * q.y).collect();
        let kf = pat.sym_matvec(&k, &f);
        let energy: f64 = f.iter().zip(&kf).map(|(x, y)| x * y).sum();
        let expect =
            (a.x * (s[0] * a.x + s[1] * a.y) + a.y * (s[1] * a.x + s[2] * a.y)) * g.total_area();
        assert!(
            (energy - expect).abs() < 1e-12 * expect,
            "{energy} vs {expect}"
        );
        // rows sum to zero
        assert!(
            pat.sym_matvec(&k, &[1.0; 6])
                .iter()
                .all(|v| v.abs() < 1e-13)
        );
        // the weft points along +x in 3-D
        for w in weft_directions(&t, &p, &uv, &[0.0; 5]) {
            assert!((w - DVec3::X).length() < 1e-12);
        }
        // a quarter-turn offset turns it to +y (faces are counter-clockwise seen from +z)
        for w in weft_directions(&t, &p, &uv, &[std::f64::consts::FRAC_PI_2; 5]) {
            assert!((w - DVec3::Y).length() < 1e-12);
        }
    }

    #[test]
    fn degenerate_uvs_fall_back_and_are_counted() {
        let (t, p) = fan();
        let g = Geometry::new(&t, &p).unwrap();
        let mut uv = vec![[[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]]; 5];
        uv[2] = [[0.5, 0.5]; 3];
        uv[4] = [[0.0, 0.0], [1.0, 1.0], [2.0, 2.0]];
        let (ang, bad) = weft_angles(&t, &g, &uv, &[0.25; 5]);
        assert_eq!(bad, 2);
        assert_eq!((ang[2], ang[4]), (0.25, 0.25));
        // UV u-axis along edge 0→1 on every healthy face: angle = offset
        assert!((ang[0] - 0.25).abs() < 1e-12);
    }
}
