//! Vertex tangent frames (seed §4.3.1): the per-frame, extrinsic part of the stain's
//! velocity representation.
//!
//! The stain's velocity is one 2-D vector `u_i = (u_iˣ, u_iʸ)` per vertex, expressed in a
//! tangent frame `F_i = (x_i, y_i, z_i)` stored at the vertex. [`VertexFrames`] builds them
//! at every frame's positions from the ordered fans of [`super::rings`]: `z_i` is the
//! area-weighted average of the incident face normals, `y_i = (z_i × e_ik) / |z_i × e_ik|`
//! with `e_ik` the reference spoke, `x_i = y_i × z_i`: so `x_i` is the reference edge
//! projected on the tangent plane and `(x_i, y_i, z_i)` is a right-handed orthonormal
//! frame. [`VertexFrames::rotated`] turns rest frames into the comoving–corotating frames
//! `F_i = U_i F̄_i` of §4.4 (`U_i` from [`super::kabsch`]). Comparing vectors of two frames
//! is the transport's job ([`super::transport`]).
//!
//! ## Degenerate frames
//! If the wedge normals sum to zero (all faces collapsed, or cancelling sheets), `z_i`
//! falls back to a unit vector perpendicular to the first spoke of non-zero length, or `+Z`
//! if there is none. `x_i` uses the first spoke (in fan order) whose angle to `z_i` has a
//! sine above [`SPOKE_MIN_SINE`] (normally spoke 0); if none has, `x_i` is any unit vector
//! perpendicular to `z_i`. A loose vertex gets the identity frame. No NaN is ever produced.

use glam::{DMat3, DVec2, DVec3};
use rayon::prelude::*;

use super::rings::{OneRings, Wedge};
use crate::error::MeshError;

/// Smallest sine of the angle between a spoke and the frame normal for the spoke to define
/// the frame's `x` axis (or, in [`super::Transport`], to measure the frame's offset). Below
/// it the projected direction would carry a relative rounding error above `10⁻¹⁰`.
pub(crate) const SPOKE_MIN_SINE: f64 = 1e-6;

/// Per-vertex orthonormal tangent frames (columns `x, y, z`; `z` the vertex normal).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct VertexFrames {
    /// `F_i` of every vertex, columns `x_i, y_i, z_i`.
    pub frame: Vec<DMat3>,
}

impl VertexFrames {
    /// The frames of §4.3.1 at `positions`: `z_i` the area-weighted vertex normal, `x_i`
    /// the reference spoke projected on the tangent plane (see the module doc for the
    /// degenerate fallbacks). Fails, naming the first bad vertex, on a wrong number of
    /// positions or a non-finite one.
    pub fn new(rings: &OneRings, positions: &[DVec3]) -> Result<Self, MeshError> {
        if positions.len() != rings.n_vertices() {
            return Err(MeshError::VertexCountMismatch {
                expected: rings.n_vertices(),
                got: positions.len(),
            });
        }
        if let Some(vertex) = positions.iter().position(|p| !p.is_finite()) {
            return Err(MeshError::NonFinitePosition { vertex });
        }
        let frame = (0..rings.n_vertices())
            .into_par_iter()
            .map(|v| Self::frame_of(rings, positions, v))
            .collect();
        Ok(Self { frame })
    }

    /// The frame of vertex `v` alone, as [`VertexFrames::new`] makes it (positions
    /// unchecked).
    pub(crate) fn frame_of(rings: &OneRings, positions: &[DVec3], v: usize) -> DMat3 {
        let p = positions[v];
        let spoke: Vec<DVec3> = rings
            .spokes(v)
            .iter()
            .map(|&j| positions[j as usize] - p)
            .collect();
        if spoke.is_empty() {
            return DMat3::IDENTITY;
        }
        let z = vertex_normal(rings.wedges(v), &spoke);
        let x = spoke
            .iter()
            .find_map(|&e| tangent_direction(e, z))
            .unwrap_or_else(|| z.any_orthonormal_vector());
        DMat3::from_cols(x, z.cross(x), z)
    }

    /// Frames `F_i = U_i F̄_i` turned by one rotation per vertex (the comoving–corotating
    /// frames of §4.4, with `U_i` from [`super::kabsch::one_ring_rotations`]).
    pub fn rotated(&self, rotation: &[DMat3]) -> Self {
        assert_eq!(rotation.len(), self.frame.len(), "one rotation per vertex");
        Self {
            frame: self
                .frame
                .iter()
                .zip(rotation)
                .map(|(f, u)| *u * *f)
                .collect(),
        }
    }

    pub(crate) fn len(&self) -> usize {
        self.frame.len()
    }

    /// The 3-D vector `u.x x_i + u.y y_i` of tangent components `u` at vertex `i`.
    pub fn to_world(&self, i: usize, u: DVec2) -> DVec3 {
        let f = &self.frame[i];
        u.x * f.x_axis + u.y * f.y_axis
    }

    /// Tangent components `(w·x_i, w·y_i)` of a 3-D vector `w` at vertex `i` (its normal
    /// part is dropped).
    pub fn to_local(&self, i: usize, w: DVec3) -> DVec2 {
        let f = &self.frame[i];
        DVec2::new(w.dot(f.x_axis), w.dot(f.y_axis))
    }
}

/// Unit normal from the wedge normals as walked (each `e_from × e_to`, twice the face's
/// area times its normal), with the fallbacks of the module doc.
fn vertex_normal(wedges: &[Wedge], spoke: &[DVec3]) -> DVec3 {
    let n = wedges.iter().fold(DVec3::ZERO, |acc, w| {
        acc + spoke[w.from as usize].cross(spoke[w.to as usize])
    });
    let z = n.normalize_or_zero();
    if z != DVec3::ZERO {
        return z;
    }
    spoke
        .iter()
        .map(|e| e.normalize_or_zero())
        .find(|e| *e != DVec3::ZERO)
        .map_or(DVec3::Z, |e| e.any_orthonormal_vector())
}

/// Unit projection of `e` on the plane normal to `z`, if it is well defined.
pub(super) fn tangent_direction(e: DVec3, z: DVec3) -> Option<DVec3> {
    let t = e - e.dot(z) * z;
    let (lt, le) = (t.length(), e.length());
    (le > 0.0 && lt > SPOKE_MIN_SINE * le).then(|| t / lt)
}

#[cfg(test)]
mod tests {
    use super::super::rings::tests::fan;
    use super::*;

    #[test]
    fn flat_fan_frame_is_the_world_frame() {
        let (t, p) = fan(true);
        let f = VertexFrames::new(&OneRings::new(&t), &p).unwrap();
        assert!((f.frame[0].z_axis - DVec3::Z).length() < 1e-15);
        assert!((f.frame[0].x_axis - DVec3::X).length() < 1e-15);
        assert!((f.frame[0].y_axis - DVec3::Y).length() < 1e-15);
    }
}
