//! The particle: a point of the mesh as `(triangle, barycentric coordinates)`, and the
//! tolerances every locating and walking test shares.

use glam::DVec3;

/// Most edges one walk crosses before it stops (only reached by a step of hundreds of
/// edge lengths).
pub(crate) const MAX_CROSSINGS: usize = 1000;

/// Barycentric coordinates above `−BARY_TOLERANCE` count as inside a triangle.
pub(super) const BARY_TOLERANCE: f64 = 1e-12;

/// A point of the mesh: a triangle and barycentric coordinates in it (summing to 1).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Located {
    /// The triangle.
    pub face: u32,
    /// Barycentric coordinates of its corners `0, 1, 2`.
    pub bary: DVec3,
}

/// Barycentric coordinates clamped to `[0, 1]` and renormalized (removes rounding).
pub(crate) fn clamp(b: DVec3) -> DVec3 {
    let c = b.max(DVec3::ZERO);
    let sum = c.element_sum();
    if sum > 0.0 {
        c / sum
    } else {
        DVec3::new(1.0, 0.0, 0.0)
    }
}
