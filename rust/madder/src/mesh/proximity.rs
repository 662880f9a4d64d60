//! Distance from points (cloth vertices) to a triangle mesh (a brush), within a cutoff:
//! how liquid sources find the part of the cloth they touch.
//!
//! The brush's triangles go into a uniform grid over its bounding box grown by the cutoff
//! `r`; a triangle is listed in every cell its own box (grown by `r`) overlaps, so a point
//! only tests the triangles of its cell. Cells are at least `r` wide and the grid has at
//! most 64 cells per axis, which bounds the memory whatever the brush. The point–triangle
//! distance is the exact closest point of Ericson (*Real-Time Collision Detection*,
//! §5.1.5), by Voronoi regions of the vertices, edges and face. Points are independent, so
//! the parallel loop gives the same result whatever the thread count.

use glam::DVec3;
use rayon::prelude::*;

const MAX_CELLS_PER_AXIS: usize = 64;

/// Closest point to `p` on the triangle `(a, b, c)`.
pub(crate) fn closest_point_on_triangle(p: DVec3, a: DVec3, b: DVec3, c: DVec3) -> DVec3 {
    let (ab, ac, ap) = (b - a, c - a, p - a);
    let (d1, d2) = (ab.dot(ap), ac.dot(ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return a;
    }
    let bp = p - b;
    let (d3, d4) = (ab.dot(bp), ac.dot(bp));
    if d3 >= 0.0 && d4 <= d3 {
        return b;
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return a + ab * (d1 / (d1 - d3));
    }
    let cp = p - c;
    let (d5, d6) = (ab.dot(cp), ac.dot(cp));
    if d6 >= 0.0 && d5 <= d6 {
        return c;
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return a + ac * (d2 / (d2 - d6));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)));
    }
    let denom = va + vb + vc;
    if denom.abs() < f64::MIN_POSITIVE {
        // a degenerate (zero-area) triangle: the closest of its three edges
        let seg = |u: DVec3, v: DVec3| {
            let d = v - u;
            let t = if d.length_squared() > 0.0 {
                ((p - u).dot(d) / d.length_squared()).clamp(0.0, 1.0)
            } else {
                0.0
            };
            u + d * t
        };
        let cands = [seg(a, b), seg(b, c), seg(c, a)];
        return cands
            .into_iter()
            .min_by(|x, y| x.distance_squared(p).total_cmp(&y.distance_squared(p)))
            .unwrap();
    }
    let (v, w) = (vb / denom, vc / denom);
    a + ab * v + ac * w
}

/// Distance from each point to the nearest of `triangles` (indices into `vertices`), or
/// `f64::INFINITY` where it is farther than `cutoff`.
pub fn distances_within(
    points: &[DVec3],
    vertices: &[DVec3],
    triangles: &[[u32; 3]],
    cutoff: f64,
) -> Vec<f64> {
    let far = vec![f64::INFINITY; points.len()];
    // `!(cutoff >= 0.0)` (not `cutoff < 0.0`) so that a NaN cutoff is rejected too
    #[allow(clippy::neg_cmp_op_on_partial_ord)]
    if triangles.is_empty() || !(cutoff >= 0.0) {
        return far;
    }
    let tri = |t: &[u32; 3]| t.map(|v| vertices[v as usize]);
    let (mut lo, mut hi) = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
    for t in triangles {
        for p in tri(t) {
            lo = lo.min(p);
            hi = hi.max(p);
        }
    }
    let (lo, hi) = (lo - DVec3::splat(cutoff), hi + DVec3::splat(cutoff));
    let extent = hi - lo;
    let h = (extent.max_element() / MAX_CELLS_PER_AXIS as f64)
        .max(cutoff)
        .max(1e-9);
    let dims = (extent / h)
        .ceil()
        .as_uvec3()
        .max(glam::UVec3::ONE)
        .as_usizevec3();
    let cell = |p: DVec3| {
        ((p - lo) / h)
            .floor()
            .as_ivec3()
            .clamp(glam::IVec3::ZERO, dims.as_ivec3() - 1)
            .as_usizevec3()
    };
    let index = |c: glam::USizeVec3| (c.z * dims.y + c.y) * dims.x + c.x;
    let mut cells: Vec<Vec<u32>> = vec![Vec::new(); dims.x * dims.y * dims.z];
    for (k, t) in triangles.iter().enumerate() {
        let [a, b, c] = tri(t);
        let (c0, c1) = (
            cell(a.min(b).min(c) - DVec3::splat(cutoff)),
            cell(a.max(b).max(c) + DVec3::splat(cutoff)),
        );
        for z in c0.z..=c1.z {
            for y in c0.y..=c1.y {
                for x in c0.x..=c1.x {
                    cells[index(glam::USizeVec3::new(x, y, z))].push(k as u32);
                }
            }
        }
    }
    points
        .par_iter()
        .map(|&p| {
            if p.cmplt(lo).any() || p.cmpgt(hi).any() || !p.is_finite() {
                return f64::INFINITY;
            }
            let best = cells[index(cell(p))]
                .iter()
                .map(|&k| {
                    let [a, b, c] = tri(&triangles[k as usize]);
                    closest_point_on_triangle(p, a, b, c).distance(p)
                })
                .fold(f64::INFINITY, f64::min);
            if best <= cutoff { best } else { f64::INFINITY }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rng(seed: u64) -> impl FnMut() -> f64 {
        let mut x = seed;
        move || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x >> 11) as f64 / (1u64 << 53) as f64
        }
    }

    #[test]
    fn closest_point_regions_of_a_right_triangle() {
        let (a, b, c) = (DVec3::ZERO, DVec3::X, DVec3::Y);
        let q = |x, y, z| closest_point_on_triangle(DVec3::new(x, y, z), a, b, c);
        assert!((q(0.2, 0.3, 5.0) - DVec3::new(0.2, 0.3, 0.0)).length() < 1e-15); // face
        assert_eq!(q(-1.0, -1.0, 0.0), a); // vertex regions
        assert_eq!(q(2.0, -0.5, 0.0), b);
        assert_eq!(q(-0.5, 3.0, 1.0), c);
        assert_eq!(q(0.5, -2.0, 0.0), DVec3::new(0.5, 0.0, 0.0)); // edge ab
        assert!((q(1.0, 1.0, 0.0) - DVec3::new(0.5, 0.5, 0.0)).length() < 1e-15); // edge bc
    }

    #[test]
    fn closest_point_is_no_farther_than_any_sample_of_the_triangle() {
        let mut r = rng(7);
        for _ in 0..200 {
            let mut v = || DVec3::new(r() * 2.0 - 1.0, r() * 2.0 - 1.0, r() * 2.0 - 1.0);
            let (a, b, c, p) = (v(), v(), v(), v() * 2.0);
            let d = closest_point_on_triangle(p, a, b, c).distance(p);
            let mut sampled = f64::INFINITY;
            for i in 0..=40 {
                for j in 0..=(40 - i) {
                    let (s, t) = (i as f64 / 40.0, j as f64 / 40.0);
                    sampled = sampled.min((a + (b - a) * s + (c - a) * t).distance(p));
                }
            }
            assert!(d <= sampled + 1e-12, "{d} > {sampled}");
            assert!(
                sampled - d < 0.05 * (b - a).length().max((c - a).length()),
                "{d} vs {sampled}"
            );
        }
    }

    #[test]
    fn grid_query_equals_brute_force() {
        let mut r = rng(3);
        let vertices: Vec<DVec3> = (0..90).map(|_| DVec3::new(r(), r(), r() * 0.3)).collect();
        let triangles: Vec<[u32; 3]> = (0..30).map(|k| [3 * k, 3 * k + 1, 3 * k + 2]).collect();
        let points: Vec<DVec3> = (0..2000)
            .map(|_| DVec3::new(r() * 1.6 - 0.3, r() * 1.6 - 0.3, r() - 0.3))
            .collect();
        for cutoff in [0.01, 0.1, 0.5] {
            let fast = distances_within(&points, &vertices, &triangles, cutoff);
            for (p, d) in points.iter().zip(&fast) {
                let brute = triangles
                    .iter()
                    .map(|t| {
                        closest_point_on_triangle(
                            *p,
                            vertices[t[0] as usize],
                            vertices[t[1] as usize],
                            vertices[t[2] as usize],
                        )
                        .distance(*p)
                    })
                    .fold(f64::INFINITY, f64::min);
                let expect = if brute <= cutoff {
                    brute
                } else {
                    f64::INFINITY
                };
                assert_eq!(*d, expect);
            }
            assert!(fast.iter().any(|d| d.is_finite()) && fast.iter().any(|d| d.is_infinite()));
        }
    }
}
