//! UV textures (`madder::texture`) against exact results:
//!
//! - triangulations of the unit square (jittered grids with random diagonals, random point
//!   insertion, grids whose vertices and edges pass exactly through texel centres, one
//!   with corners millions of tiles away) cover every texel centre exactly once, and a
//!   field linear in UV is reproduced to float rounding at every centre;
//! - a cloth cut into two UV islands (one of them mirrored) along a seam: a field linear
//!   on the cloth is exact at every covered texel of both islands; a constant field shows
//!   no seam after padding (bilinear samples at mip levels 0 and 1 across the seam agree
//!   to 1e-3, where unpadded ones do not);
//! - coverage: covered texels × texel area = UV area within the texels the outlines cross;
//! - mass: the texture integrated with each face's world/UV area ratio gives the exact
//!   integral of a piecewise-linear field on a curved cloth within 1 % at 1024 px;
//! - overlapping islands counted exactly, first triangle wins;
//! - the same bits on 1, 2 and 3 threads (rasterize and pad);
//! - EXR round trip equal to the half-rounded image, rows in the right order, atomic
//!   writes; bad input is the typed error naming the face, corner, name or path.

use std::path::{Path, PathBuf};

use half::f16;
use madder::error::TextureError;
use madder::rng::SplitMix64;
use madder::texture::raster::{EMPTY, INSIDE, OVERLAP, PADDED};
use madder::texture::{
    self, Compression, Raster, pad, rasterize, read_exr, write_exr, write_exr_with,
};

type Uv = [[f64; 2]; 3];

/// A triangle mesh in UV: vertex UVs and faces (one UV per vertex: no seam).
struct Mesh {
    uv: Vec<[f64; 2]>,
    faces: Vec<[u32; 3]>,
}

impl Mesh {
    fn face_uv(&self) -> Vec<Uv> {
        self.faces
            .iter()
            .map(|f| f.map(|v| self.uv[v as usize]))
            .collect()
    }
}

fn cross(a: [f64; 2], b: [f64; 2], c: [f64; 2]) -> f64 {
    (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
}

fn area(t: &Uv) -> f64 {
    0.5 * cross(t[0], t[1], t[2]).abs()
}

/// `n × n` quads of the unit square, interior vertices jittered by up to ±`jitter`/2 of
/// the spacing (border vertices slide along the border only), random diagonals.
fn jittered_grid(n: usize, jitter: f64, seed: u64) -> Mesh {
    let mut r = SplitMix64::new(seed);
    let idx = |i: usize, j: usize| (i * (n + 1) + j) as u32;
    let mut uv = Vec::new();
    for i in 0..=n {
        for j in 0..=n {
            let mut x = j as f64 / n as f64;
            let mut y = i as f64 / n as f64;
            if j > 0 && j < n {
                x += (r.unit() - 0.5) * jitter / n as f64;
            }
            if i > 0 && i < n {
                y += (r.unit() - 0.5) * jitter / n as f64;
            }
            uv.push([x, y]);
        }
    }
    let mut faces = Vec::new();
    for i in 0..n {
        for j in 0..n {
            let (a, b, c, d) = (idx(i, j), idx(i, j + 1), idx(i + 1, j + 1), idx(i + 1, j));
            if r.next_u64() & 1 == 0 {
                faces.extend([[a, b, c], [a, c, d]]);
            } else {
                faces.extend([[a, b, d], [b, c, d]]);
            }
        }
    }
    Mesh { uv, faces }
}

/// The unit square split in two, then `n` random points each splitting the triangle that
/// holds it into three (kept only when at least `1e-3` from the triangle's edges, so that
/// snapping to 1/256 texel cannot fold a triangle). Skinny triangles of every orientation.
fn random_insertion(n: usize, seed: u64) -> Mesh {
    let mut r = SplitMix64::new(seed);
    let mut uv = vec![[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]];
    let mut faces: Vec<[u32; 3]> = vec![[0, 1, 2], [0, 2, 3]];
    let mut added = 0;
    while added < n {
        let p = [r.unit(), r.unit()];
        let Some(t) = faces.iter().position(|f| {
            let [a, b, c] = f.map(|v| uv[v as usize]);
            let d = |u: [f64; 2], w: [f64; 2]| cross(u, w, p) / (w[0] - u[0]).hypot(w[1] - u[1]);
            d(a, b) > 1e-3 && d(b, c) > 1e-3 && d(c, a) > 1e-3
        }) else {
            continue;
        };
        let v = uv.len() as u32;
        uv.push(p);
        let [a, b, c] = faces[t];
        faces[t] = [a, b, v];
        faces.extend([[b, c, v], [c, a, v]]);
        added += 1;
    }
    Mesh { uv, faces }
}

/// A grid of the unit square whose interior lines run through texel centres of a
/// `size`-texel image (`size` a power of two: the UVs are exact), `step` texels apart,
/// each interior vertex moved by a random whole number of texels in −1..=1: many centres
/// lie exactly on edges and on vertices shared by up to 8 triangles.
fn texel_aligned(size: usize, step: usize, seed: u64) -> Mesh {
    assert!(size.is_power_of_two() && size % step == 0 && step >= 4);
    let n = size / step;
    let mut r = SplitMix64::new(seed);
    let idx = |i: usize, j: usize| (i * (n + 1) + j) as u32;
    let coord = |k: usize, r: &mut SplitMix64| {
        if k == 0 {
            0.0
        } else if k == n {
            1.0
        } else {
            let d = (r.next_u64() % 3) as f64 - 1.0;
            ((k * step) as f64 + d + 0.5) / size as f64
        }
    };
    let mut uv = Vec::new();
    for i in 0..=n {
        for j in 0..=n {
            let x = coord(j, &mut r);
            let y = coord(i, &mut r);
            uv.push([x, y]);
        }
    }
    let mut faces = Vec::new();
    for i in 0..n {
        for j in 0..n {
            let (a, b, c, d) = (idx(i, j), idx(i, j + 1), idx(i + 1, j + 1), idx(i + 1, j));
            if (i + j) % 2 == 0 {
                faces.extend([[a, b, c], [a, c, d]]);
            } else {
                faces.extend([[a, b, d], [b, c, d]]);
            }
        }
    }
    Mesh { uv, faces }
}

/// Three linear fields of UV, one per channel, at the vertices (as f32).
const LINEAR: [[f64; 3]; 3] = [[0.25, 1.5, -0.75], [-1.0, 0.125, 2.0], [3.0, -2.5, -0.5]];

fn linear(k: usize, u: f64, v: f64) -> f64 {
    LINEAR[k][0] + LINEAR[k][1] * u + LINEAR[k][2] * v
}

fn linear_values(uv: &[[f64; 2]]) -> Vec<f32> {
    uv.iter()
        .flat_map(|&[u, v]| (0..3).map(move |k| linear(k, u, v) as f32))
        .collect()
}

fn centre(x: usize, y: usize, size: usize) -> [f64; 2] {
    [
        (x as f64 + 0.5) / size as f64,
        (y as f64 + 0.5) / size as f64,
    ]
}

/// Every texel of a partition of the unit square is covered once, and the linear fields
/// are exact (to f32 rounding of the vertex values and of the result) at every centre.
fn check_partition(mesh: &Mesh, size: usize, what: &str) {
    let values = linear_values(&mesh.uv);
    let r = rasterize(&mesh.faces, &mesh.face_uv(), &values, 3, size).unwrap();
    assert_eq!(r.overlapping, 0, "{what} at {size}: overlapping texels");
    let mut worst = 0.0f64;
    for y in 0..size {
        for x in 0..size {
            let m = r.coverage[y * size + x];
            assert_eq!(m, INSIDE, "{what} at {size}: texel ({x}, {y}) coverage {m}");
            let [u, v] = centre(x, y, size);
            for k in 0..3 {
                let exact = linear(k, u, v);
                let got = f64::from(r.texel(x, y)[k]);
                worst = worst.max((got - exact).abs());
            }
        }
    }
    // the fields stay below 6 in magnitude: a few f32 ulps there
    let tol = 6.0 * 4.0 * f64::from(f32::EPSILON);
    assert!(worst <= tol, "{what} at {size}: error {worst:e} > {tol:e}");
}

#[test]
fn partitions_cover_each_centre_once_and_reproduce_linear_fields() {
    for seed in 0..4 {
        let grid = jittered_grid(13, 0.6, seed);
        let inserted = random_insertion(150, 100 + seed);
        for size in [64, 100, 257] {
            check_partition(&grid, size, &format!("jittered grid {seed}"));
            check_partition(&inserted, size, &format!("random insertion {seed}"));
        }
    }
    for seed in 0..4 {
        for (size, step) in [(64, 4), (128, 8), (256, 4)] {
            let m = texel_aligned(size, step, seed);
            check_partition(&m, size, &format!("texel-aligned grid {seed}"));
        }
    }
}

#[test]
fn far_corners_take_the_wide_path_and_stay_watertight() {
    // a huge triangle split around an interior point: corners ~1e7 UV away (past ±2^25
    // snapped units, so the edge functions are evaluated in i128)
    let uv = vec![
        [0.3, 0.6],
        [-1.0e7, -1.0e7],
        [1.0e7, -0.9e7],
        [0.1e7, 1.0e7],
    ];
    let mesh = Mesh {
        uv,
        faces: vec![[0, 1, 2], [0, 2, 3], [0, 3, 1]],
    };
    for size in [16, 64, 333] {
        let r = rasterize(&mesh.faces, &mesh.face_uv(), &[1.0; 4], 1, size).unwrap();
        assert_eq!(r.overlapping, 0);
        assert!(r.coverage.iter().all(|&m| m == INSIDE), "size {size}");
        assert!(r.pixels.iter().all(|&p| p == 1.0));
    }
    // each texel goes to the triangle that holds its centre: per-triangle values 1, 2, 3
    // (vertices split) against an independent f64 point-in-triangle test, away from edges
    let faces: Vec<[u32; 3]> = (0..3).map(|t| [3 * t, 3 * t + 1, 3 * t + 2]).collect();
    let values: Vec<f32> = (0..9).map(|i| (i / 3 + 1) as f32).collect();
    let fuv = mesh.face_uv();
    let size = 200;
    let r = rasterize(&faces, &fuv, &values, 1, size).unwrap();
    let mut checked = 0;
    for y in 0..size {
        for x in 0..size {
            let p = centre(x, y, size);
            for (t, tri) in fuv.iter().enumerate() {
                let e = [
                    cross(tri[0], tri[1], p),
                    cross(tri[1], tri[2], p),
                    cross(tri[2], tri[0], p),
                ];
                // the edge functions here are of order 1e7 per unit of distance
                if e.iter().all(|&e| e > 1e3) {
                    assert_eq!(r.texel(x, y)[0], (t + 1) as f32, "texel ({x}, {y})");
                    checked += 1;
                }
            }
        }
    }
    assert!(checked > size * size * 9 / 10, "{checked}");
}

/// A cloth (unit square, `n × n` grid) cut at x = ½ into two UV islands: the left half
/// scaled into [0.05, 0.45] × [0.1, 0.9], the right half mirrored vertically (its
/// triangles turn clockwise in UV) into [0.55, 0.95] × [0.1, 0.9]. Vertices on the seam
/// have a UV on each side.
struct Islands {
    /// cloth positions (x, y) of the vertices
    pos: Vec<[f64; 2]>,
    faces: Vec<[u32; 3]>,
    uv: Vec<Uv>,
}

fn to_uv(p: [f64; 2], right: bool) -> [f64; 2] {
    if right {
        [0.55 + 0.8 * (p[0] - 0.5), 0.9 - 0.8 * p[1]]
    } else {
        [0.05 + 0.8 * p[0], 0.1 + 0.8 * p[1]]
    }
}

/// The cloth point of a UV in island `right`.
fn from_uv(uv: [f64; 2], right: bool) -> [f64; 2] {
    if right {
        [0.5 + (uv[0] - 0.55) / 0.8, (0.9 - uv[1]) / 0.8]
    } else {
        [(uv[0] - 0.05) / 0.8, (uv[1] - 0.1) / 0.8]
    }
}

fn islands(n: usize) -> Islands {
    assert!(n % 2 == 0);
    let idx = |i: usize, j: usize| (i * (n + 1) + j) as u32;
    let pos: Vec<[f64; 2]> = (0..=n)
        .flat_map(|i| (0..=n).map(move |j| [j as f64 / n as f64, i as f64 / n as f64]))
        .collect();
    let mut faces = Vec::new();
    for i in 0..n {
        for j in 0..n {
            let (a, b, c, d) = (idx(i, j), idx(i, j + 1), idx(i + 1, j + 1), idx(i + 1, j));
            faces.extend([[a, b, c], [a, c, d]]);
        }
    }
    let uv = faces
        .iter()
        .map(|f| {
            let p = f.map(|v| pos[v as usize]);
            let right = p.iter().map(|q| q[0]).sum::<f64>() / 3.0 > 0.5;
            p.map(|q| to_uv(q, right))
        })
        .collect();
    Islands { pos, faces, uv }
}

#[test]
fn linear_field_on_a_cloth_with_a_seam_is_exact_on_both_islands() {
    let m = islands(10);
    let field = |p: [f64; 2]| 0.5 + 2.0 * p[0] - 1.25 * p[1];
    let values: Vec<f32> = m.pos.iter().map(|&p| field(p) as f32).collect();
    for size in [64, 200, 512] {
        let r = rasterize(&m.faces, &m.uv, &values, 1, size).unwrap();
        assert_eq!(r.overlapping, 0);
        let mut counts = [0usize; 2];
        for y in 0..size {
            for x in 0..size {
                if r.coverage[y * size + x] == EMPTY {
                    continue;
                }
                let c = centre(x, y, size);
                let right = c[0] > 0.5;
                counts[usize::from(right)] += 1;
                let exact = field(from_uv(c, right));
                let got = f64::from(r.texel(x, y)[0]);
                assert!(
                    (got - exact).abs() <= 3.0 * 4.0 * f64::from(f32::EPSILON),
                    "size {size}, texel ({x}, {y}): {got} vs {exact}"
                );
            }
        }
        // each island is 0.4 × 0.8 of UV; its outline (2.4 long) crosses ≤ 2·2.4·size + 4
        // texels
        for n in counts {
            let expect = 0.32 * (size * size) as f64;
            assert!(
                (n as f64 - expect).abs() <= 4.8 * size as f64 + 4.0,
                "size {size}: {n} texels vs {expect}"
            );
        }
    }
}

/// Bilinear sample of channel 0 of a `size`² image at UV `p` (texel centres at
/// (i + ½)/size, clamped at the image border).
fn bilinear(img: &[f32], size: usize, p: [f64; 2]) -> f64 {
    let fx = p[0] * size as f64 - 0.5;
    let fy = p[1] * size as f64 - 0.5;
    let (x0, y0) = (fx.floor(), fy.floor());
    let (tx, ty) = (fx - x0, fy - y0);
    let at = |x: f64, y: f64| {
        let x = (x.max(0.0) as usize).min(size - 1);
        let y = (y.max(0.0) as usize).min(size - 1);
        f64::from(img[y * size + x])
    };
    (1.0 - ty) * ((1.0 - tx) * at(x0, y0) + tx * at(x0 + 1.0, y0))
        + ty * ((1.0 - tx) * at(x0, y0 + 1.0) + tx * at(x0 + 1.0, y0 + 1.0))
}

/// The next mip level: each texel the mean of a 2 × 2 block.
fn mip(img: &[f32], size: usize) -> Vec<f32> {
    let h = size / 2;
    let mut out = vec![0.0; h * h];
    for y in 0..h {
        for x in 0..h {
            let s = img[2 * y * size + 2 * x]
                + img[2 * y * size + 2 * x + 1]
                + img[(2 * y + 1) * size + 2 * x]
                + img[(2 * y + 1) * size + 2 * x + 1];
            out[y * h + x] = s / 4.0;
        }
    }
    out
}

#[test]
fn constant_field_has_no_seam_after_padding() {
    let m = islands(12);
    let c = 0.7f32;
    let values = vec![c; m.pos.len()];
    let size = 256;
    let bare = rasterize(&m.faces, &m.uv, &values, 1, size).unwrap();
    let mut padded = bare.clone();
    let filled = pad(&mut padded, 4);
    assert!(filled > 0);
    assert_eq!(
        filled,
        padded.coverage.iter().filter(|&&k| k == PADDED).count()
    );

    // every texel within 4 texels (chessboard) of an island is covered, and equals c
    for y in 0..size {
        for x in 0..size {
            let near = (y.saturating_sub(4)..=(y + 4).min(size - 1)).any(|yy| {
                (x.saturating_sub(4)..=(x + 4).min(size - 1))
                    .any(|xx| bare.coverage[yy * size + xx] != EMPTY)
            });
            let i = y * size + x;
            assert_eq!(padded.coverage[i] != EMPTY, near, "texel ({x}, {y})");
            if near {
                assert_eq!(padded.pixels[i], c, "texel ({x}, {y})");
            } else {
                assert_eq!(padded.pixels[i], 0.0);
            }
            // covered texels are untouched
            if bare.coverage[i] != EMPTY {
                assert_eq!(padded.pixels[i], bare.pixels[i]);
                assert_eq!(padded.coverage[i], bare.coverage[i]);
            }
        }
    }

    // across the seam (cloth x = ½) and along every island border: bilinear samples at
    // mip levels 0 and 1 read c on both sides, to 1e-3; without padding they do not
    let level1 = mip(&padded.pixels, size);
    let mut worst_bare = 0.0f64;
    for k in 0..=100 {
        let y = k as f64 / 100.0;
        for right in [false, true] {
            // the seam, the island's outer side, its bottom and top edges
            let (outer, mid) = if right { (1.0, 0.75) } else { (0.0, 0.25) };
            for p in [[0.5, y], [outer, y], [mid, 0.0], [mid, 1.0]] {
                let q = to_uv(p, right);
                let s0 = bilinear(&padded.pixels, size, q);
                let s1 = bilinear(&level1, size / 2, q);
                assert!(
                    (s0 - f64::from(c)).abs() <= 1e-3,
                    "level 0 at {p:?} ({right}): {s0}"
                );
                assert!(
                    (s1 - f64::from(c)).abs() <= 1e-3,
                    "level 1 at {p:?} ({right}): {s1}"
                );
                worst_bare = worst_bare.max((bilinear(&bare.pixels, size, q) - f64::from(c)).abs());
            }
        }
    }
    assert!(
        worst_bare > 0.1,
        "the unpadded image should show its seams ({worst_bare})"
    );
}

#[test]
fn covered_area_matches_the_uv_area_within_the_outline_term() {
    // disjoint random triangles, one per cell of a 6 × 6 grid of the unit square
    let mut r = SplitMix64::new(7);
    let mut uv = Vec::new();
    for i in 0..6 {
        for j in 0..6 {
            let mut corner = || {
                [
                    (j as f64 + 0.05 + 0.9 * r.unit()) / 6.0,
                    (i as f64 + 0.05 + 0.9 * r.unit()) / 6.0,
                ]
            };
            uv.push([corner(), corner(), corner()]);
        }
    }
    let faces: Vec<[u32; 3]> = (0..uv.len() as u32)
        .map(|t| [3 * t, 3 * t + 1, 3 * t + 2])
        .collect();
    let values = vec![1.0f32; 3 * uv.len()];
    for size in [50, 128, 300, 1000] {
        let ras = rasterize(&faces, &uv, &values, 1, size).unwrap();
        assert_eq!(ras.overlapping, 0);
        let s = size as f64;
        let area: f64 = uv.iter().map(area).sum::<f64>() * s * s;
        // each edge crosses at most |Δx| + |Δy| + 1 texels (in texel units)
        let outline: f64 = uv
            .iter()
            .flat_map(|t| {
                (0..3).map(move |k| {
                    let (a, b) = (t[k], t[(k + 1) % 3]);
                    ((b[0] - a[0]).abs() + (b[1] - a[1]).abs()) * s + 1.0
                })
            })
            .sum();
        let n = ras.inside_count() as f64;
        assert!(
            (n - area).abs() <= outline,
            "size {size}: {n} texels, area {area}, outline {outline}"
        );
        // and the relative error shrinks like 1/size
        if size == 1000 {
            assert!((n - area).abs() / area < 0.01, "{n} vs {area}");
        }
    }
}

#[test]
fn texture_integral_with_area_ratios_gives_the_mass() {
    // the two-island cloth, curved in 3-D: each face has its own world/UV area ratio
    let m = islands(24);
    let world = |p: [f64; 2]| [p[0], p[1], 0.3 * (3.0 * p[0]).sin() * (2.0 * p[1]).cos()];
    let tri_area3 = |a: [f64; 3], b: [f64; 3], c: [f64; 3]| {
        let u = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
        let v = [c[0] - a[0], c[1] - a[1], c[2] - a[2]];
        let w = [
            u[1] * v[2] - u[2] * v[1],
            u[2] * v[0] - u[0] * v[2],
            u[0] * v[1] - u[1] * v[0],
        ];
        0.5 * (w[0] * w[0] + w[1] * w[1] + w[2] * w[2]).sqrt()
    };
    // a stain-like field: a Gaussian spot across the seam, piecewise linear on the faces
    let f: Vec<f64> = m
        .pos
        .iter()
        .map(|p| 2.0 * (-((p[0] - 0.45).powi(2) + (p[1] - 0.5).powi(2)) / 0.04).exp())
        .collect();
    let mut exact = 0.0;
    let mut values = Vec::new();
    let mut faces = Vec::new();
    for (t, face) in m.faces.iter().enumerate() {
        let [a, b, c] = face.map(|v| world(m.pos[v as usize]));
        let aw = tri_area3(a, b, c);
        let fv = face.map(|v| f[v as usize]);
        exact += aw * (fv[0] + fv[1] + fv[2]) / 3.0;
        let ratio = aw / area(&m.uv[t]);
        values.extend(fv.map(|x| (x * ratio) as f32));
        let k = 3 * t as u32;
        faces.push([k, k + 1, k + 2]);
    }
    let size = 1024;
    let r = rasterize(&faces, &m.uv, &values, 1, size).unwrap();
    let integral: f64 = r.pixels.iter().map(|&p| f64::from(p)).sum::<f64>() / (size * size) as f64;
    let err = (integral - exact).abs() / exact;
    assert!(
        err < 0.01,
        "texture {integral} vs exact {exact}: {:.3} %",
        100.0 * err
    );
}

#[test]
fn overlapping_islands_are_counted_and_the_first_triangle_wins() {
    let square = |x0: f64, y0: f64, x1: f64, y1: f64| -> [Uv; 2] {
        [
            [[x0, y0], [x1, y0], [x1, y1]],
            [[x0, y0], [x1, y1], [x0, y1]],
        ]
    };
    let mut uv = Vec::new();
    uv.extend(square(0.1, 0.1, 0.5, 0.5));
    uv.extend(square(0.3, 0.3, 0.7, 0.7));
    // island A has value 1 (vertices 0..3), island B value 2 (vertex 3)
    let faces = vec![[0, 1, 2], [0, 2, 1], [3, 3, 3], [3, 3, 3]];
    let values = [1.0f32, 1.0, 1.0, 2.0];
    let size = 100;
    let r = rasterize(&faces, &uv, &values, 1, size).unwrap();
    // centres (x + ½)/100 in [0.3, 0.5]: x = 30..=49 on each axis
    assert_eq!(r.overlapping, 400);
    for y in 0..size {
        for x in 0..size {
            let inside = |lo: usize, hi: usize| (lo..hi).contains(&x) && (lo..hi).contains(&y);
            let i = y * size + x;
            let (a, b) = (inside(10, 50), inside(30, 70));
            let expect = match (a, b) {
                (true, true) => (OVERLAP, 1.0),
                (true, false) => (INSIDE, 1.0),
                (false, true) => (INSIDE, 2.0),
                (false, false) => (EMPTY, 0.0),
            };
            assert_eq!((r.coverage[i], r.pixels[i]), expect, "texel ({x}, {y})");
        }
    }
    // an island and its mirror image on the same UVs (mirrored halves sharing a layout)
    let m = jittered_grid(6, 0.5, 3);
    let mut fuv = m.face_uv();
    let n = fuv.len();
    fuv.extend_from_within(..);
    let mut faces = m.faces.clone();
    faces.extend(m.faces.iter().map(|f| [f[0], f[2], f[1]]));
    for t in &mut fuv[n..] {
        t.swap(1, 2);
    }
    let r = rasterize(&faces, &fuv, &vec![1.0; m.uv.len()], 1, 64).unwrap();
    assert_eq!(r.overlapping, 64 * 64);
}

#[test]
fn same_bits_on_any_number_of_threads() {
    // random triangles, overlapping each other, random values, 2 channels, and padding
    let mut r = SplitMix64::new(11);
    let n = 30_000; // more than one binning chunk
    let uv: Vec<Uv> = (0..n)
        .map(|_| {
            let c = [r.unit() * 1.2 - 0.1, r.unit() * 1.2 - 0.1];
            let s = 0.002 + 0.03 * r.unit();
            let mut k = || [c[0] + s * (r.unit() - 0.5), c[1] + s * (r.unit() - 0.5)];
            [k(), k(), k()]
        })
        .collect();
    let nv = 5000;
    let faces: Vec<[u32; 3]> = (0..n)
        .map(|_| std::array::from_fn(|_| (r.next_u64() % nv) as u32))
        .collect();
    let values: Vec<f32> = (0..2 * nv).map(|_| r.unit() as f32 * 3.0 - 1.0).collect();
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            let mut ras = rasterize(&faces, &uv, &values, 2, 300).unwrap();
            let bare = ras.clone();
            pad(&mut ras, 4);
            (bare, ras)
        })
    };
    let bits = |r: &Raster| r.pixels.iter().map(|p| p.to_bits()).collect::<Vec<_>>();
    let (b1, p1) = run(1);
    assert!(
        b1.overlapping > 1000,
        "the test wants overlaps ({})",
        b1.overlapping
    );
    assert!(b1.coverage.contains(&EMPTY));
    for threads in [2, 3] {
        let (b, p) = run(threads);
        assert_eq!(bits(&b), bits(&b1), "{threads} threads: rasterize");
        assert_eq!(b.coverage, b1.coverage);
        assert_eq!(b.overlapping, b1.overlapping);
        assert_eq!(bits(&p), bits(&p1), "{threads} threads: pad");
        assert_eq!(p.coverage, p1.coverage);
    }
    // rasterize_into a used raster gives the same as a fresh one
    let mut reused = p1.clone();
    texture::rasterize_into(&mut reused, &faces, &uv, &values, 2, 300).unwrap();
    assert_eq!(reused, b1);
}

fn tmpdir(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("madder-texture-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn half_round(x: f32) -> f32 {
    f16::from_f32(x).to_f32()
}

fn files_in(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

#[test]
fn exr_round_trip_is_the_half_rounded_image() {
    let dir = tmpdir("roundtrip");
    let (w, h) = (37, 23);
    let mut r = SplitMix64::new(5);
    // magnitudes across the half range, signs, zeros, subnormal halves, one overflow
    let mut img: Vec<f32> = (0..w * h * 4)
        .map(|i| match i % 7 {
            0 => 0.0,
            1 => (r.unit() * 2.0 - 1.0) as f32,
            2 => r.log_uniform(1e-7, 6e4) as f32,
            3 => -(r.log_uniform(1e-3, 10.0) as f32),
            4 => 1.0,
            _ => r.unit() as f32,
        })
        .collect();
    img[5] = 1e6; // beyond half: +inf
    let expect: Vec<u32> = img.iter().map(|&x| half_round(x).to_bits()).collect();
    assert!(expect.contains(&f32::INFINITY.to_bits()));
    for c in Compression::ALL {
        let path = dir.join(format!("img-{c:?}.exr"));
        write_exr_with(&path, &img, w, h, &["R", "G", "B", "A"], c).unwrap();
        let back = read_exr(&path).unwrap();
        assert_eq!((back.width, back.height), (w, h));
        assert_eq!(back.channels, ["R", "G", "B", "A"]);
        let got: Vec<u32> = back.pixels.iter().map(|x| x.to_bits()).collect();
        assert_eq!(got, expect, "{c:?}");
    }
    // mostly empty, with runs of every length around the encoder's limits (127, 128 and
    // 16-byte steps) and noise: RLE must shrink it, and decode to the same bits
    let (w2, h2) = (300, 40);
    let mut sparse = vec![0.0f32; w2 * h2 * 4];
    for y in 0..h2 {
        let run = [
            1, 2, 3, 15, 16, 17, 31, 32, 33, 126, 127, 128, 129, 200, 255, 256,
        ][y % 16];
        for x in 0..run.min(w2) {
            for k in 0..4 {
                sparse[(y * w2 + x) * 4 + k] = 0.25 * (k + 1) as f32;
            }
        }
        if y % 5 == 0 {
            for x in 100..140 {
                sparse[(y * w2 + x) * 4 + y % 4] = r.unit() as f32;
            }
        }
    }
    for c in Compression::ALL {
        let path = dir.join(format!("sparse-{c:?}.exr"));
        write_exr_with(&path, &sparse, w2, h2, &["R", "G", "B", "A"], c).unwrap();
        let back = read_exr(&path).unwrap();
        let same = back
            .pixels
            .iter()
            .zip(&sparse)
            .all(|(a, b)| a.to_bits() == half_round(*b).to_bits());
        assert!(same, "{c:?}");
        let bytes = std::fs::metadata(&path).unwrap().len() as usize;
        if c != Compression::None {
            assert!(bytes < w2 * h2 * 8 / 5, "{c:?}: {bytes} bytes");
        }
    }
    // rows: the file's first scan line is the image's top row (row h − 1), read directly
    let path = dir.join("img-Rle.exr");
    let file = exr::prelude::read_first_flat_layer_from_file(&path).unwrap();
    let red = file
        .layer_data
        .channel_data
        .list
        .iter()
        .find(|ch| ch.name.to_string() == "R")
        .unwrap();
    for x in 0..w {
        let top = img[((h - 1) * w + x) * 4];
        let got = red.sample_data.value_by_flat_index(x).to_f32();
        assert_eq!(got.to_bits(), half_round(top).to_bits(), "column {x}");
    }
    // any channel names, in the order R, G, B, A first and the rest by name
    let path = dir.join("named.exr");
    let two: Vec<f32> = (0..w * h * 3).map(|i| i as f32 * 0.5).collect();
    write_exr(&path, &two, w, h, &["wet", "A", "R"]).unwrap();
    let back = read_exr(&path).unwrap();
    assert_eq!(back.channels, ["R", "A", "wet"]);
    for i in 0..w * h {
        let src = &two[3 * i..3 * i + 3];
        let got = &back.pixels[3 * i..3 * i + 3];
        assert_eq!(got, [src[2], src[1], src[0]].map(half_round));
    }
    // writing over an existing image replaces it, and leaves no temporary file behind
    write_exr(
        &path,
        &two.iter().map(|x| x + 1.0).collect::<Vec<_>>(),
        w,
        h,
        &["wet", "A", "R"],
    )
    .unwrap();
    assert_eq!(read_exr(&path).unwrap().pixels[0], half_round(two[2] + 1.0));
    let files = files_in(&dir);
    assert!(files.iter().all(|f| f.ends_with(".exr")), "{files:?}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn rasterize_pad_write_read_of_a_linear_field() {
    let dir = tmpdir("pipeline");
    let m = jittered_grid(9, 0.5, 21);
    let values = linear_values(&m.uv);
    let size = 128;
    let mut r = rasterize(&m.faces, &m.face_uv(), &values, 3, size).unwrap();
    pad(&mut r, 4);
    let path = dir.join("linear.exr");
    write_exr(&path, &r.pixels, size, size, &["R", "G", "B"]).unwrap();
    let back = read_exr(&path).unwrap();
    for y in 0..size {
        for x in 0..size {
            let [u, v] = centre(x, y, size);
            for k in 0..3 {
                let exact = linear(k, u, v);
                let got = f64::from(back.pixels[(y * size + x) * 3 + k]);
                // half keeps 11 bits: relative 2^-11, and values here stay below 6
                assert!(
                    (got - exact).abs() <= 6.0 * 2f64.powi(-11),
                    "({x}, {y}, {k})"
                );
            }
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn failed_writes_name_the_path_and_leave_nothing_behind() {
    let dir = tmpdir("fail");
    let img = vec![0.5f32; 4 * 4 * 4];
    let rgba = ["R", "G", "B", "A"];
    // a folder that does not exist
    let missing = dir.join("no-such-folder").join("a.exr");
    match write_exr(&missing, &img, 4, 4, &rgba) {
        Err(TextureError::Io { path, source }) => {
            assert_eq!(path, missing);
            assert_eq!(source.kind(), std::io::ErrorKind::NotFound);
        }
        other => panic!("{other:?}"),
    }
    // the target is a folder: the temporary file is written, the rename fails, and the
    // folder (with what it holds) stays as it was
    let target = dir.join("taken.exr");
    std::fs::create_dir(&target).unwrap();
    std::fs::write(target.join("keep"), b"x").unwrap();
    let err = write_exr(&target, &img, 4, 4, &rgba).unwrap_err();
    assert!(
        matches!(&err, TextureError::Io { path, .. } if *path == target),
        "{err:?}"
    );
    assert!(err.to_string().contains("taken.exr"), "{err}");
    assert_eq!(files_in(&target), ["keep"]);
    // a path under a file
    let file = dir.join("plain");
    std::fs::write(&file, b"x").unwrap();
    let under = file.join("a.exr");
    assert!(
        matches!(write_exr(&under, &img, 4, 4, &rgba), Err(TextureError::Io { path, .. }) if path == under)
    );
    assert_eq!(files_in(&dir), ["plain", "taken.exr"]);
    // reading: a missing file, and a file that is not an EXR image
    let nope = dir.join("nope.exr");
    assert!(matches!(read_exr(&nope), Err(TextureError::Io { path, .. }) if path == nope));
    assert!(matches!(read_exr(&file), Err(TextureError::Exr { path, .. }) if path == file));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn bad_input_is_the_typed_error_naming_the_element() {
    let tri: Vec<Uv> = vec![[[0.1, 0.1], [0.9, 0.1], [0.5, 0.9]]];
    let f = [[0u32, 1, 2]];
    let v = [0.0f32; 3];
    for size in [0, texture::MAX_SIZE + 1] {
        assert!(matches!(
            rasterize(&f, &tri, &v, 1, size),
            Err(TextureError::Size { name: "size", size: s, max: 16384 }) if s == size
        ));
    }
    assert!(matches!(
        rasterize(&f, &tri, &v, 0, 8),
        Err(TextureError::Channels {
            channels: 0,
            max: 64
        })
    ));
    // a huge channel count is refused before anything is allocated
    assert!(matches!(
        rasterize(&[], &[], &[], 1 << 40, 16384),
        Err(TextureError::Channels { max: 64, .. })
    ));
    assert!(matches!(
        rasterize(&f, &[], &v, 1, 8),
        Err(TextureError::Length {
            name: "uv",
            expected: 1,
            got: 0
        })
    ));
    assert!(matches!(
        rasterize(&f, &tri, &v, 2, 8),
        Err(TextureError::ValuesLength {
            got: 3,
            channels: 2
        })
    ));
    // across binning chunks the first bad face is named: vertex out of range at 20000,
    // a NaN at 30000 (corner 2), an infinity at 40000
    let n = 50_000;
    let mut uv = vec![tri[0]; n];
    let mut faces = vec![[0u32, 1, 2]; n];
    uv[40_000][0][1] = f64::INFINITY;
    uv[30_000][2][0] = f64::NAN;
    faces[20_000] = [0, 7, 2];
    let err = rasterize(&faces, &uv, &v, 1, 8).unwrap_err();
    assert!(
        matches!(
            err,
            TextureError::VertexOutOfRange {
                face: 20_000,
                vertex: 7,
                n_vertices: 3
            }
        ),
        "{err:?}"
    );
    assert!(err.to_string().contains("face 20000"), "{err}");
    faces[20_000] = [0, 1, 2];
    let err = rasterize(&faces, &uv, &v, 1, 8).unwrap_err();
    assert!(
        matches!(
            err,
            TextureError::NonFiniteUv {
                face: 30_000,
                corner: 2,
                ..
            }
        ),
        "{err:?}"
    );
    assert!(err.to_string().contains("face 30000, corner 2"), "{err}");
    uv[30_000][2][0] = 0.5;
    let err = rasterize(&faces, &uv, &v, 1, 8).unwrap_err();
    assert!(
        matches!(
            err,
            TextureError::NonFiniteUv {
                face: 40_000,
                corner: 0,
                ..
            }
        ),
        "{err:?}"
    );
    // rasterize_into leaves the raster as it was on error
    let mut r = rasterize(&f, &tri, &v, 1, 8).unwrap();
    let before = r.clone();
    assert!(texture::rasterize_into(&mut r, &faces, &uv, &v, 1, 16).is_err());
    assert_eq!(r, before);
    // rasterize_to checks its buffers
    let (mut px, mut cov) = (vec![0.0; 63], vec![0u8; 64]);
    assert!(matches!(
        texture::rasterize_to(&mut px, &mut cov, &f, &tri, &v, 1, 8),
        Err(TextureError::Length {
            name: "pixels",
            expected: 64,
            got: 63
        })
    ));
    // write_exr: sizes, lengths, names
    let dir = tmpdir("bad");
    let p = dir.join("x.exr");
    let img = vec![0.0f32; 12];
    assert!(matches!(
        write_exr(&p, &img, 0, 4, &["Y"]),
        Err(TextureError::Size { name: "width", .. })
    ));
    assert!(matches!(
        write_exr(&p, &img, 3, 99999, &["Y"]),
        Err(TextureError::Size { name: "height", .. })
    ));
    assert!(matches!(
        write_exr(&p, &img, 3, 3, &["Y"]),
        Err(TextureError::Length {
            name: "image",
            expected: 9,
            got: 12
        })
    ));
    assert!(matches!(
        write_exr(&p, &img, 3, 4, &[]),
        Err(TextureError::Channels {
            channels: 0,
            max: 64
        })
    ));
    assert!(matches!(
        write_exr(&p, &img, 2, 3, &["R", "R"]),
        Err(TextureError::ChannelName { .. })
    ));
    assert!(matches!(
        write_exr(&p, &img, 2, 3, &["R", ""]),
        Err(TextureError::ChannelName { .. })
    ));
    assert!(matches!(
        write_exr(&p, &img, 2, 3, &["R", "é"]),
        Err(TextureError::ChannelName { .. })
    ));
    assert!(files_in(&dir).is_empty());
    let _ = std::fs::remove_dir_all(&dir);
}
