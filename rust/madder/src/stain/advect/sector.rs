//! The back-trace's pre-test of its first wedge (`trace.rs`): whether the foot's
//! direction may lie in a wedge's polar sector, from a cheap `atan2`.
//!
//! *First wedge.* Placing a spoke costs a `sin_cos`, and the wedge is searched in fan
//! order. A pre-test skips, without placing their spokes, the wedges whose polar sector
//! `[α_ij + δ_i, α_ik + δ_i]` (counter-clockwise, any turn) is more than 10⁻³ rad away
//! from the foot's direction, measured by a polynomial `atan2` good to 10⁻⁵: the exact
//! test of the back-trace can only pass inside the sector (up to rounding and
//! [`SIDE_TOLERANCE`], below 10⁻¹¹), so the same wedge is found with the same placed
//! spokes, and about two `sin_cos` are done instead of one per wedge passed.
//!
//! [`SIDE_TOLERANCE`]: super::trace::SIDE_TOLERANCE

/// Margin (radians) of the first wedge's angular pre-test, [`in_sector`]: far above the
/// error of [`rough_atan2`] (below `10⁻⁵`) and the rounding of the polar angles and of
/// [`SIDE_TOLERANCE`] (below `10⁻¹¹`), far below a wedge's opening.
///
/// [`SIDE_TOLERANCE`]: super::trace::SIDE_TOLERANCE
pub(super) const SECTOR_MARGIN: f64 = 1e-3;

/// Whether the direction of polar angle `psi` may lie in the counter-clockwise sector from
/// angle `a` to angle `b` (any real angles), [`SECTOR_MARGIN`] included on both sides. A
/// wedge that passes the exact test of the back-trace (`P_a` right of the foot's line,
/// `P_b` on or left of it, `P_a × P_b > 0`) contains the direction of the foot up to
/// rounding, so it always passes this one; a sector of nearly `2π` lets everything pass.
/// `false` for NaN angles.
pub(super) fn in_sector(psi: f64, a: f64, b: f64) -> bool {
    use std::f64::consts::TAU;
    // psi − a into [−margin, 2π − margin), b − a into [0, 2π); the angles are polar
    // angles within a few turns of each other, so the loops run at most a few times
    let (mut d, mut w) = (psi - a, b - a);
    if !(d.is_finite() && w.is_finite()) {
        return false;
    }
    while d < -SECTOR_MARGIN {
        d += TAU;
    }
    while d >= TAU - SECTOR_MARGIN {
        d -= TAU;
    }
    while w < 0.0 {
        w += TAU;
    }
    while w >= TAU {
        w -= TAU;
    }
    d <= w + SECTOR_MARGIN
}

/// `atan2(y, x)` to within `10⁻⁵` radians, without the library call: a pre-test only
/// ([`in_sector`]), never a value the results depend on. An odd minimax polynomial for
/// `atan` on `[0, 1]`, extended to the plane by the octant's symmetries.
pub(super) fn rough_atan2(y: f64, x: f64) -> f64 {
    use std::f64::consts::{FRAC_PI_2, PI};
    let (ax, ay) = (x.abs(), y.abs());
    let (lo, hi) = (ax.min(ay), ax.max(ay));
    if hi == 0.0 || !hi.is_finite() {
        return y.atan2(x);
    }
    let t = lo / hi;
    let t2 = t * t;
    let mut a = t
        * (0.999_977_26
            + t2 * (-0.332_623_47
                + t2 * (0.193_543_46
                    + t2 * (-0.116_432_87 + t2 * (0.052_653_32 + t2 * -0.011_721_20)))));
    if ay > ax {
        a = FRAC_PI_2 - a;
    }
    if x < 0.0 {
        a = PI - a;
    }
    if y < 0.0 { -a } else { a }
}
