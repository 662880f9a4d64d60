//! Rigid placement and scale, which the angles do not carry: one reference face and its
//! three positions; a reconstruction is mapped by the similarity that takes that face onto
//! them (Umeyama 1991 on three points, proper rotation).

use glam::{DMat3, DVec3};

use crate::error::AngleError;
use crate::mesh::kabsch::rotation_from_covariance;

/// Where a reconstructed mesh goes: face `face` lands on `positions` (its corners in the
/// face's order).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Placement {
    /// The reference face.
    pub face: usize,
    /// Its three positions.
    pub positions: [DVec3; 3],
}

impl Placement {
    /// The placement that puts face `face` where it is in `positions` (the mesh's vertex
    /// positions, `faces` its triangles).
    pub fn of_face(
        faces: &[[u32; 3]],
        positions: &[DVec3],
        face: usize,
    ) -> Result<Self, AngleError> {
        let t = faces.get(face).ok_or(AngleError::PlacementFace {
            face,
            n_faces: faces.len(),
        })?;
        let mut p = [DVec3::ZERO; 3];
        for (c, &v) in t.iter().enumerate() {
            p[c] = *positions
                .get(v as usize)
                .ok_or(AngleError::PlacementPositions)?;
        }
        let pl = Self { face, positions: p };
        pl.check(faces.len())?;
        Ok(pl)
    }

    pub(crate) fn check(&self, n_faces: usize) -> Result<(), AngleError> {
        if self.face >= n_faces {
            return Err(AngleError::PlacementFace {
                face: self.face,
                n_faces,
            });
        }
        let [p0, p1, p2] = self.positions;
        let n = (p1 - p0).cross(p2 - p0).length();
        if !self.positions.iter().all(|p| p.is_finite()) || n.is_nan() || n <= 0.0 {
            return Err(AngleError::PlacementPositions);
        }
        Ok(())
    }

    /// Maps `x` (all vertices) by the similarity taking face `self.face` of `faces` onto
    /// the reference positions.
    pub(crate) fn apply(&self, faces: &[[u32; 3]], x: &mut [DVec3]) {
        let src = faces[self.face].map(|v| x[v as usize]);
        let (s, r, t) = similarity(&src, &self.positions);
        for p in x.iter_mut() {
            *p = s * (r * *p) + t;
        }
    }
}

/// The similarity `y ≈ s R x + t` (proper rotation `R`, `s > 0`) best matching `src` onto
/// `dst` in least squares (Umeyama).
pub(crate) fn similarity(src: &[DVec3], dst: &[DVec3]) -> (f64, DMat3, DVec3) {
    let n = src.len() as f64;
    let cs = src.iter().copied().sum::<DVec3>() / n;
    let cd = dst.iter().copied().sum::<DVec3>() / n;
    let h = src.iter().zip(dst).fold(DMat3::ZERO, |h, (p, q)| {
        let (p, q) = (*p - cs, *q - cd);
        h + DMat3::from_cols(q * p.x, q * p.y, q * p.z)
    });
    let r = rotation_from_covariance(h);
    let num: f64 = src
        .iter()
        .zip(dst)
        .map(|(p, q)| (*q - cd).dot(r * (*p - cs)))
        .sum();
    let den: f64 = src.iter().map(|p| (*p - cs).length_squared()).sum();
    let s = if den > 0.0 { num / den } else { 1.0 };
    (s, r, cd - s * (r * cs))
}
