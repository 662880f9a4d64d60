//! One frame from its angles, as both sides compute it: the similarity a frame carries,
//! which frames are keys, and the reconstruction (module doc, "Placement", "Warm-started
//! decoding, keyframes").

use glam::{DMat3, DQuat, DVec3};
use rayon::prelude::*;

use super::format::Decoding;
use super::quant::step;
use crate::angles::encode::{AngleMesh, Angles};
use crate::angles::place::similarity;
use crate::angles::spectral::ReconstructOptions;
use crate::error::AngleError;

/// The similarity of a frame, as stored: scale, unit quaternion (x, y, z, w), translation.
#[derive(Debug, Clone, Copy)]
pub(super) struct Similarity(pub(super) [f32; 8]);

impl Similarity {
    pub(super) fn fit(y: &[DVec3], x: &[DVec3]) -> Self {
        let (s, r, t) = similarity(y, x);
        let q = DQuat::from_mat3(&r).normalize();
        Self([
            s as f32, q.x as f32, q.y as f32, q.z as f32, q.w as f32, t.x as f32, t.y as f32,
            t.z as f32,
        ])
    }
    pub(super) fn check(&self) -> Result<(), String> {
        let v = self.0;
        if !v.iter().all(|c| c.is_finite()) || v[0] <= 0.0 {
            return Err("the placement is not finite or has a non-positive scale".into());
        }
        let n = v[1..5].iter().map(|c| (*c as f64).powi(2)).sum::<f64>();
        if !(0.5..2.0).contains(&n) {
            return Err("the placement's rotation is not a unit quaternion".into());
        }
        Ok(())
    }
    /// `s R y + t`, rounded to `f32` (the decoder's output).
    pub(super) fn apply(&self, y: &[DVec3]) -> Vec<[f32; 3]> {
        let v = self.0.map(f64::from);
        let q = DQuat::from_xyzw(v[1], v[2], v[3], v[4]).normalize();
        let r = DMat3::from_quat(q);
        let t = DVec3::new(v[5], v[6], v[7]);
        y.par_iter()
            .map(|p| {
                let w = v[0] * (r * *p) + t;
                [w.x as f32, w.y as f32, w.z as f32]
            })
            .collect()
    }
}

/// Whether frame `k` is reconstructed cold under keyframe interval `key`.
pub(super) fn is_key(k: usize, key: u32) -> bool {
    key == 0 || k % key as usize == 0
}

/// Whether frame `k` starts from the extrapolation of frames `k − 1` and `k − 2`: both
/// of its chain (neither `k` nor `k − 1` a keyframe; a keyframe's decode and the frame
/// before it are placed differently).
pub(super) fn extrapolates(k: usize, key: u32) -> bool {
    k >= 2 && !is_key(k, key) && !is_key(k - 1, key)
}

/// The decoding shared by encoder and reader: dequantize, reconstruct (normalized), warm
/// from `previous` when given (module docs). Tracked: every frame is the tracked
/// reconstruction started from `previous` (extrapolated to `2 previous − before` when the
/// frame before it is given), or at a keyframe from the sequential walk (or, in files of
/// flag 2 alone, the spectral reconstruction); where it does not settle, the warm spectral
/// reconstruction from `previous` (at a keyframe, the tracked one from the spectral
/// reconstruction, else that reconstruction itself) is used instead.
pub(super) fn reconstruct(
    mesh: &AngleMesh,
    corners: &[i64],
    dihedrals: &[i64],
    (bits, corner_bits): (u32, u32),
    (previous, before): (Option<&[DVec3]>, Option<&[DVec3]>),
    decoding: Decoding,
) -> Result<Vec<DVec3>, AngleError> {
    let (dc, dd) = (step(corner_bits), step(bits));
    let angles = Angles {
        corners: corners
            .par_chunks_exact(3)
            .map(|c| [c[0] as f64 * dc, c[1] as f64 * dc, c[2] as f64 * dc])
            .collect(),
        dihedrals: dihedrals.par_iter().map(|&d| d as f64 * dd).collect(),
    };
    // the rounds may leave a rotation error of a twentieth of the finer step (files of
    // flag 4; older ones settle fully, as they were encoded)
    let options = ReconstructOptions {
        tolerance: match decoding {
            Decoding::Tracked => dc.min(dd) / 20.0,
            _ => 0.0,
        },
        ..Default::default()
    };
    if decoding == Decoding::Spectral {
        return Ok(match previous {
            Some(prev) => mesh.reconstruct_warm(&angles, prev, &options)?,
            None => mesh.reconstruct(&angles, &options)?,
        }
        .positions);
    }
    if let Some(prev) = previous {
        let start: Option<Vec<DVec3>> = before.map(|b| {
            prev.par_iter()
                .zip(b.par_iter())
                .map(|(p, q)| 2.0 * *p - *q)
                .collect()
        });
        let start = start.as_deref().unwrap_or(prev);
        return Ok(mesh
            .reconstruct_following(&angles, start, prev, &options)?
            .positions);
    }
    // a keyframe: rotations composed along a tree are cheap and, on angles a tracked fit
    // can follow, close enough to start it; the spectral reconstruction is the robust start
    match decoding {
        Decoding::Tracked => mesh.reconstruct_cold(&angles, &options),
        _ => mesh.reconstruct_tracked_from_spectral(&angles, &options),
    }
}
