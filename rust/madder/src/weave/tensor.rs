//! Small helpers on symmetric 2×2 tensors `[s11, s12, s22]`.
//!
//! Homogenization is 1-homogeneous in the tensors (`A(c a) = c A(a)`, seed eq. 2.3 is
//! linear in `a` at a fixed corrector), so tiles are worked on scaled by a power of two
//! ([`scale`], exact) to entries of order 1. [`is_spd`] and [`eigenvalues_at_any_scale`]
//! do the same per tensor, so a tile at 1e-170 or 1e160 is judged as the same tile at 1
//! (its determinant would underflow or overflow unscaled).

use super::Tensor2;

/// `t · v`.
#[inline]
pub(crate) fn apply(t: Tensor2, v: [f64; 2]) -> [f64; 2] {
    [t[0] * v[0] + t[1] * v[1], t[1] * v[0] + t[2] * v[1]]
}

/// Entry `(i, j)`, `i, j ∈ {0, 1}`.
#[inline]
pub(crate) fn entry(t: Tensor2, i: usize, j: usize) -> f64 {
    t[i + j]
}

/// `vᵀ t v`.
#[cfg(test)]
pub(crate) fn quad(t: Tensor2, v: [f64; 2]) -> f64 {
    t[0] * v[0] * v[0] + 2.0 * t[1] * v[0] * v[1] + t[2] * v[1] * v[1]
}

/// The determinant `s11 s22 − s12²`.
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
pub(crate) fn eigenvalues(t: Tensor2) -> (f64, f64) {
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

/// The binary exponent `e` of a finite `x ≠ 0`: `2^e ≤ |x| < 2^(e+1)` (subnormals
/// included). Zero and non-finite values give 0.
pub(crate) fn exponent(x: f64) -> i32 {
    if x == 0.0 || !x.is_finite() {
        return 0;
    }
    let biased = ((x.to_bits() >> 52) & 0x7ff) as i32;
    if biased == 0 {
        // subnormal: 2^64 times it is normal, and the product is exact
        exponent(x * f64::from_bits((1023 + 64) << 52)) - 64
    } else {
        biased - 1023
    }
}

/// `x · 2^k`, exact unless the result leaves the range of normal numbers (then rounded
/// once, to a subnormal, zero or infinity). The steps grow before they shrink, so no
/// intermediate result rounds.
pub(crate) fn ldexp(x: f64, k: i32) -> f64 {
    // 2^j for |j| ≤ 1000, from its bits
    let pow2 = |j: i32| f64::from_bits(((j + 1023) as u64) << 52);
    let (mut x, mut k) = (x, k);
    while k > 1000 {
        x *= pow2(1000);
        k -= 1000;
    }
    if k >= -1000 {
        return x * pow2(k);
    }
    let rest = k % 1000;
    x *= pow2(rest);
    k -= rest;
    while k < 0 {
        x *= pow2(-1000);
        k += 1000;
    }
    x
}

/// `t · 2^k` entry by entry (exact in the normal range; `-0.0` becomes `0.0`).
#[inline]
pub fn scale(t: Tensor2, k: i32) -> Tensor2 {
    t.map(|x| ldexp(x, k) + 0.0)
}

/// Whether `t` is finite and positive definite (`s11 > 0` and `s11 s22 − s12² > 0`),
/// judged on `t` scaled to a largest entry in `[1, 2)`: the same answer at any magnitude.
pub(crate) fn is_spd(t: Tensor2) -> bool {
    if !t.iter().all(|x| x.is_finite()) {
        return false;
    }
    let top = t[0].abs().max(t[1].abs()).max(t[2].abs());
    if top == 0.0 {
        return false;
    }
    let s = scale(t, -exponent(top));
    s[0] > 0.0 && det(s) > 0.0
}

/// [`eigenvalues`] of a finite `t` of any magnitude (computed on `t` scaled to order 1).
pub(crate) fn eigenvalues_at_any_scale(t: Tensor2) -> (f64, f64) {
    let top = t[0].abs().max(t[1].abs()).max(t[2].abs());
    let e = exponent(top);
    let (lo, hi) = eigenvalues(scale(t, -e));
    (ldexp(lo, e), ldexp(hi, e))
}

/// `t^p` for SPD `t`, through its eigendecomposition `t = λ₁ v vᵀ + λ₂ (I − v vᵀ)`.
pub(crate) fn power(t: Tensor2, p: f64) -> Tensor2 {
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
pub(crate) fn congruence(x: Tensor2, m: Tensor2) -> Tensor2 {
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
pub(crate) fn geodesic(a: Tensor2, b: Tensor2, s: f64) -> Tensor2 {
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

    #[test]
    fn exponents_and_exact_scaling() {
        for (x, e) in [
            (1.0, 0),
            (1.5, 0),
            (2.0, 1),
            (0.75, -1),
            (-8.0, 3),
            (f64::MAX, 1023),
            (f64::MIN_POSITIVE, -1022),
            (f64::MIN_POSITIVE / 2.0, -1023),
            (f64::from_bits(1), -1074),
        ] {
            assert_eq!(exponent(x), e, "{x:e}");
        }
        assert_eq!(exponent(1e-170), -565); // 2^-565 ≈ 1.5e-170
        assert_eq!(exponent(1e160), 531); // 2^531 ≈ 1.4e160
        // round trips through the whole range are exact
        for x in [
            1.0,
            3.0,
            -1.2345678901234567,
            1e-170,
            1e160,
            f64::MIN_POSITIVE,
        ] {
            for k in [-1074, -600, -1, 0, 1, 600, 1023] {
                let y = ldexp(x, k);
                if y != 0.0 && y.is_finite() && y.abs() >= f64::MIN_POSITIVE {
                    assert_eq!(ldexp(y, -k), x, "{x:e} by 2^{k}");
                }
            }
        }
        assert_eq!(ldexp(1.0, 1023), 2f64.powi(1023));
        assert_eq!(ldexp(1.0, -1074), f64::from_bits(1));
        assert_eq!(ldexp(1.0, 1024), f64::INFINITY);
        assert_eq!(ldexp(f64::from_bits(1), 1074 + 1023), 2f64.powi(1023));
    }

    #[test]
    fn positive_definiteness_at_any_magnitude() {
        let t = [2.0, 1.5, 3.0];
        for k in [-1000, -565, 0, 531, 1000] {
            let s = scale(t, k);
            assert!(is_spd(s), "2^{k}");
            // unscaled, the determinant underflows to 0 or overflows to inf − inf = NaN
            if k.abs() >= 565 {
                assert!(!(det(s) > 0.0 && det(s).is_finite()), "2^{k}");
            }
            let (lo, hi) = eigenvalues_at_any_scale(s);
            let (l1, h1) = eigenvalues(t);
            assert!((lo / ldexp(l1, k) - 1.0).abs() < 1e-15, "2^{k}");
            assert!((hi / ldexp(h1, k) - 1.0).abs() < 1e-15, "2^{k}");
        }
        for bad in [
            [1.0, 1.0, 1.0],
            [-1.0, 0.0, 1.0],
            [0.0; 3],
            [f64::NAN, 0.0, 1.0],
            [1.0, 0.0, f64::INFINITY],
        ] {
            assert!(!is_spd(bad), "{bad:?}");
            assert!(!is_spd(scale(bad, -565)), "{bad:?}");
        }
    }
}
