//! Small helpers on symmetric 2×2 tensors `[s11, s12, s22]`.

use super::Tensor2;

/// `t · v`.
#[inline]
pub fn apply(t: Tensor2, v: [f64; 2]) -> [f64; 2] {
    [t[0] * v[0] + t[1] * v[1], t[1] * v[0] + t[2] * v[1]]
}

/// Entry `(i, j)`, `i, j ∈ {0, 1}`.
#[inline]
pub fn entry(t: Tensor2, i: usize, j: usize) -> f64 {
    t[i + j]
}

/// `vᵀ t v`.
#[inline]
pub fn quad(t: Tensor2, v: [f64; 2]) -> f64 {
    t[0] * v[0] * v[0] + 2.0 * t[1] * v[0] * v[1] + t[2] * v[1] * v[1]
}

#[inline]
pub fn det(t: Tensor2) -> f64 {
    t[0] * t[2] - t[1] * t[1]
}

/// `t⁻¹`.
#[inline]
pub fn inverse(t: Tensor2) -> Tensor2 {
    let d = det(t);
    [t[2] / d, -t[1] / d, t[0] / d]
}

/// `(1 − s) a + s b`.
#[inline]
pub fn lerp(a: Tensor2, b: Tensor2, s: f64) -> Tensor2 {
    [
        a[0] + s * (b[0] - a[0]),
        a[1] + s * (b[1] - a[1]),
        a[2] + s * (b[2] - a[2]),
    ]
}

/// The Keller dual `Rᵀ t⁻¹ R = t / det t` (`R` the quarter turn): the medium whose
/// potentials are the stream functions of `t`'s fluxes. An involution.
#[inline]
pub fn keller_dual(t: Tensor2) -> Tensor2 {
    let d = det(t);
    [t[0] / d, t[1] / d, t[2] / d]
}

/// Eigenvalues `(λ_min, λ_max)`.
pub fn eigenvalues(t: Tensor2) -> (f64, f64) {
    let m = 0.5 * (t[0] + t[2]);
    let r = (0.5 * (t[0] - t[2])).hypot(t[1]);
    // the smaller one from the determinant avoids cancellation when λ_min ≪ λ_max
    let hi = m + r;
    let lo = if hi > 0.0 { det(t) / hi } else { m - r };
    (lo, hi)
}

/// Whether `t` is positive semidefinite up to `tol`: `λ_min ≥ −tol` (an absolute
/// tolerance; pass a multiple of the size of the tensors being compared).
pub fn is_psd(t: Tensor2, tol: f64) -> bool {
    let m = 0.5 * (t[0] + t[2]);
    let r = (0.5 * (t[0] - t[2])).hypot(t[1]);
    m - r >= -tol
}

/// `t^p` for SPD `t`, through its eigendecomposition `t = λ₁ v vᵀ + λ₂ (I − v vᵀ)`.
pub fn power(t: Tensor2, p: f64) -> Tensor2 {
    let (lo, hi) = eigenvalues(t);
    let (lp, hp) = (lo.powf(p), hi.powf(p));
    if hi == lo {
        return [lp, 0.0, lp];
    }
    // major axis v = (cos θ, sin θ), θ = ½ atan2(2 s12, s11 − s22)
    let th = 0.5 * (2.0 * t[1]).atan2(t[0] - t[2]);
    let (s, c) = th.sin_cos();
    let d = hp - lp;
    [lp + d * c * c, d * c * s, lp + d * s * s]
}

/// `x m x` for symmetric `x`, `m` (a congruence; SPD in, SPD out).
pub fn congruence(x: Tensor2, m: Tensor2) -> Tensor2 {
    // x m = [[p, q], [r, s]]
    let (p, q) = (x[0] * m[0] + x[1] * m[1], x[0] * m[1] + x[1] * m[2]);
    let (r, s) = (x[1] * m[0] + x[2] * m[1], x[1] * m[1] + x[2] * m[2]);
    [
        p * x[0] + q * x[1],
        p * x[1] + q * x[2],
        r * x[1] + s * x[2],
    ]
}

/// The point at parameter `s ∈ [0, 1]` on the geodesic from `a` to `b` in the cone of SPD
/// matrices (the weighted geometric mean `a #ₛ b = a^½ (a^-½ b a^-½)^s a^½`). For
/// commuting `a`, `b` it is `a^{1−s} b^s`; if `b ≤ a` as quadratic forms, every point of
/// the geodesic lies between them, `b ≤ a #ₛ b ≤ a`. Covariant under rotations.
pub fn geodesic(a: Tensor2, b: Tensor2, s: f64) -> Tensor2 {
    let ah = power(a, 0.5);
    let aih = inverse(ah);
    let m = congruence(aih, b);
    let r = congruence(ah, power(m, s));
    // symmetric by construction; r[1] is the only off-diagonal entry stored
    r
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: Tensor2, b: Tensor2, tol: f64) -> bool {
        let s = a.iter().chain(&b).fold(0.0f64, |m, x| m.max(x.abs()));
        a.iter().zip(&b).all(|(x, y)| (x - y).abs() <= tol * s)
    }

    #[test]
    fn power_and_geodesic() {
        let t = [4.0, 1.5, 2.0];
        let h = power(t, 0.5);
        assert!(close(congruence(h, [1.0, 0.0, 1.0]), t, 1e-14));
        assert!(close(power(t, -1.0), inverse(t), 1e-14));
        assert!(close(power(t, 1.0), t, 1e-14));
        // commuting case: diagonal
        let g = geodesic([9.0, 0.0, 1.0], [1.0, 0.0, 4.0], 0.5);
        assert!(close(g, [3.0, 0.0, 2.0], 1e-14));
        // endpoints, and the Keller dual of a geodesic is the geodesic of the duals
        let (a, b) = ([5.0, -1.0, 3.0], [2.0, 0.5, 1.0]);
        assert!(close(geodesic(a, b, 0.0), a, 1e-14));
        assert!(close(geodesic(a, b, 1.0), b, 1e-14));
        let s = 0.3;
        assert!(close(
            keller_dual(geodesic(a, b, s)),
            geodesic(keller_dual(a), keller_dual(b), s),
            1e-13
        ));
        let (lo, hi) = eigenvalues([1e8, 0.0, 1e-8]);
        assert_eq!((lo, hi), (1e-8, 1e8));
    }
}
