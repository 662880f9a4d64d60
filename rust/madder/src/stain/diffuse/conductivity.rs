//! The fabric's diffusion ([`Conductivity`]): isotropic, or per woven face a tensor in
//! its weft basis ([`WovenFaces`], seed §4.3.4), and the stiffness `K_S` it gives, whole
//! or restricted to a region.

use super::DEFAULT_DIFFUSION;
use crate::error::ParamError;
use crate::mesh::{Geometry, Topology};
use crate::ops::cotan::assemble_face_weights;
use crate::ops::{
    Restriction, VertexPattern, anisotropic_stiffness, anisotropic_stiffness_scaled,
    cotan_stiffness, weft_angles,
};
use crate::stain::check::check_range;
use crate::weave::Tensor2;

/// How fast the stain diffuses, and in which directions.
#[derive(Debug, Clone, PartialEq)]
pub enum Conductivity {
    /// The same coefficient `D` (m²/s) in every direction.
    Isotropic(f64),
    /// A woven cloth: per face, a tensor (m²/s) in the face's (weft, warp) basis.
    Woven(WovenFaces),
}

impl Default for Conductivity {
    /// Isotropic at [`DEFAULT_DIFFUSION`].
    fn default() -> Self {
        Self::Isotropic(DEFAULT_DIFFUSION)
    }
}

/// Per-face fabric data of a woven cloth.
#[derive(Debug, Clone, PartialEq)]
pub struct WovenFaces {
    /// `[s11, s12, s22]` in the (weft, warp) basis, m²/s; symmetric positive semi-definite.
    pub tensor: Vec<Tensor2>,
    /// UV of each face's three corners; the weft is the UV `u` axis.
    pub uv: Vec<[[f64; 2]; 3]>,
    /// Angle (radians) added to the weft of each face (a fabric cut on the bias).
    pub angle: Vec<f64>,
}

impl Conductivity {
    /// The stiffness `scale · K_S` on `pattern` for this geometry: `D` times the cotan
    /// stiffness, or the anisotropic stiffness with the weft recomputed from the UVs on
    /// the deformed faces; with `face_scale`, face `f`'s rate (or tensor) times
    /// `face_scale[f]` (the wicking factor of [`Wicking`](super::Wicking)).
    pub(crate) fn stiffness(
        &self,
        topology: &Topology,
        geometry: &Geometry,
        pattern: &VertexPattern,
        scale: f64,
        face_scale: Option<&[f64]>,
    ) -> Vec<f64> {
        match (self, face_scale) {
            (Conductivity::Isotropic(d), None) => {
                cotan_stiffness(topology, geometry, pattern, scale * d)
            }
            (Conductivity::Isotropic(d), Some(g)) => {
                assemble_face_weights(topology, pattern, |f| {
                    geometry.face_cot[f].map(|c| -0.5 * scale * d * g[f] * c)
                })
            }
            (Conductivity::Woven(w), g) => {
                let (angle, _) = weft_angles(topology, geometry, &w.uv, &w.angle);
                match g {
                    None => {
                        anisotropic_stiffness(topology, geometry, pattern, &angle, &w.tensor, scale)
                    }
                    Some(g) => anisotropic_stiffness_scaled(
                        topology, geometry, pattern, &angle, &w.tensor, scale, g,
                    ),
                }
            }
        }
    }

    /// `M + scale · K_S` restricted to `region` ([`Restriction::scalar_values`] of
    /// [`Self::stiffness`]), bit for bit; for an isotropic cloth assembled on the region's
    /// faces only ([`Restriction::values_from_faces`]), without the whole window's matrix.
    pub(crate) fn restricted_values(
        &self,
        topology: &Topology,
        geometry: &Geometry,
        pattern: &VertexPattern,
        region: &Restriction,
        scale: f64,
        face_scale: Option<&[f64]>,
    ) -> Vec<f64> {
        let area = &geometry.vertex_area;
        match (self, face_scale) {
            (Conductivity::Isotropic(d), None) => {
                // `cotan_stiffness(scale · d)`'s weights
                let s = scale * d;
                region.values_from_faces(topology, area, false, |f| {
                    geometry.face_cot[f].map(|c| -0.5 * s * c)
                })
            }
            (Conductivity::Isotropic(d), Some(g)) => {
                region.values_from_faces(topology, area, false, |f| {
                    geometry.face_cot[f].map(|c| -0.5 * scale * d * g[f] * c)
                })
            }
            (Conductivity::Woven(_), g) => {
                let full = self.stiffness(topology, geometry, pattern, scale, g);
                region.scalar_values(pattern, &full, area, false)
            }
        }
    }

    /// The conductivity of a sub-mesh made of `faces` (indices into this one's faces, in
    /// the sub-mesh's face order).
    pub(crate) fn faces(&self, faces: &[u32]) -> Self {
        match self {
            Conductivity::Isotropic(d) => Conductivity::Isotropic(*d),
            Conductivity::Woven(w) => Conductivity::Woven(WovenFaces {
                tensor: faces.iter().map(|&f| w.tensor[f as usize]).collect(),
                uv: faces.iter().map(|&f| w.uv[f as usize]).collect(),
                angle: faces.iter().map(|&f| w.angle[f as usize]).collect(),
            }),
        }
    }

    /// Faces whose UVs are degenerate (the weft falls back to an edge), at `geometry`.
    pub(crate) fn degenerate_uv_faces(&self, topology: &Topology, geometry: &Geometry) -> usize {
        match self {
            Conductivity::Woven(w) => weft_angles(topology, geometry, &w.uv, &w.angle).1,
            Conductivity::Isotropic(_) => 0,
        }
    }

    /// Checks the rate or the per-face data (lengths, finiteness, tensors PSD).
    pub(crate) fn validate(&self, n_faces: usize) -> Result<(), ParamError> {
        match self {
            Conductivity::Isotropic(d) => {
                check_range("diffusion rate", *d, *d >= 0.0, "finite and ≥ 0")
            }
            Conductivity::Woven(w) => {
                let lengths = [
                    ("face tensors", w.tensor.len()),
                    ("face UVs", w.uv.len()),
                    ("face angles", w.angle.len()),
                ];
                for (name, len) in lengths {
                    if len != n_faces {
                        return Err(ParamError::Length {
                            name,
                            expected: n_faces,
                            got: len,
                        });
                    }
                }
                for (f, &[a, b, c]) in w.tensor.iter().enumerate() {
                    // positive semi-definite: a ≥ 0, c ≥ 0, ac ≥ b² (zero allowed: a barrier)
                    if !(a >= 0.0 && c >= 0.0 && b.is_finite() && a * c >= b * b * (1.0 - 1e-12)) {
                        return Err(ParamError::NotPositiveSemiDefinite {
                            name: "face tensor",
                            index: f,
                        });
                    }
                }
                if let Some(f) =
                    w.uv.iter()
                        .position(|t| t.iter().flatten().any(|x| !x.is_finite()))
                {
                    return Err(ParamError::NonFinite {
                        name: "face UVs",
                        index: f,
                    });
                }
                if let Some(f) = w.angle.iter().position(|x| !x.is_finite()) {
                    return Err(ParamError::NonFinite {
                        name: "face angles",
                        index: f,
                    });
                }
                Ok(())
            }
        }
    }
}
