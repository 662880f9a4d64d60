//! The stain's outline drawn at the texel, not the cell (issue 34 §2: the edge of a stain
//! is sharp at the fibre scale, the simulation's is a few cells wide).
//!
//! A liquid front in a fabric stops at a line: behind it the fibres hold the dye, ahead
//! they are dry. The simulation resolves that front to its cells, so the coverage `c` (the
//! dye amount the stain image carries, read within `[0, 1]`: the dye above saturation is
//! graded by the drying flow, not smeared) falls from its plateau to 0 over two to four
//! rings of the mesh, and the barycentric image of it draws a ramp a centimetre wide on a
//! cloth of 6 mm cells. This module reads the ramp as the cell average of a sharp front and
//! draws the front instead, within a texel, where (and only where) the cloth is dry nearby.
//!
//! ## Per vertex ([`Outline::fields`])
//! With `N_k(v)` the vertices within `k` rings of `v` (edges of the mesh, `k` = `rings`):
//! - the plateau `P_v = max_{N_k(v)} c`, the stain's level behind the front;
//! - the fraction `f_v = c_v / P_v` (0 where `P_v` = 0): 1 on the plateau, ½ where a front
//!   smeared symmetrically about its true line crosses it, 0 on the dry cloth;
//! - the zone `w_v = 1` when some vertex of `N_k(v)` is dry, `min_{N_k(v)} c ≤ DRY · P_v`,
//!   else 0. Away from the dry cloth (`w = 0`) the stain is the simulation's, bit for bit:
//!   a graded trail, a tide line or the drying pattern inside are physics, not a smeared
//!   front.
//!
//! ## Per texel ([`sharpen`])
//! The rasterizer interpolates `(f, w)` over the UV triangles like any field. At a texel
//! the front line is `f = ½`, and its signed distance in texels is, to first order,
//! `d = (f − ½) / |∇f|` with `∇f` the central differences of the `f` image (exact inside a
//! triangle, where `f` is linear). A texel straddling a straight front is covered by it in
//! the fraction `s = clamp(½ + d, 0, 1)` (the box filter of the step: the front is
//! anti-aliased, not aliased, and drawn within one texel). The sharp stain is the plateau
//! times that coverage, blended in over the zone:
//!
//! ```text
//! c' = c + w (P s − c) = c · r,   r = 1 + w (s / f − 1)      (P = c / f)
//! ```
//!
//! so every channel of the premultiplied stain texel (colour and coverage alike, the weave's
//! detail already in) is multiplied by the one ratio `r`, and the image's dye above
//! saturation (the wet image's excess) by `min(r, 1)`: the front cuts it, nothing lifts it.
//! A texel whose coverage then exceeds 1 (the weave's detail on a saturated stain) is
//! clipped as the rasterizer clips ([`mod@super::clip`]).
//!
//! **Mass.** For a front smeared symmetrically about its line (a ramp, an error function)
//! the plateau's excess behind the line equals the deficit ahead of it, so `∫ c'` = `∫ c`
//! to the texel: within 1 % on a round stain smeared over three cells (`tests/outline.rs`),
//! +0.8 % on the flag's wine (`tests/blender/test_presets_look.py`). Wider gradations than `k` rings (ink's halo, a run's graded trail)
//! keep `f` near 1 on their plateau side and are cut only at their own half level.
//!
//! The output depends on the texel size only through `|∇f|` in texels: the same front at a
//! finer image is drawn at that image's texel.
//!
//! ## At the pixel ([`lift`])
//! A texel is still a few millimetres on a large cloth, and a thread pitch is a fraction of
//! one. So the front can instead be left to the shader, which draws it at the pixel: the
//! images carry the stain **lifted** to its plateau over the zone, the box filter's `s`
//! taken as 1,
//!
//! ```text
//! L = c · (1 + w (1/f − 1)) = c (1 − w) + w P
//! ```
//!
//! (a texel ahead of the smear, `f` ≈ 0 in the zone, takes the mean of its lifted
//! 4-neighbours, so that the plateau reaches a texel past the last stained one), and a
//! channel of the wet image carries the front's **signed distance** in metres, positive
//! behind it,
//!
//! ```text
//! D = w · clamp((f − ½) / |∇f|, ±DISTANCE_LIMIT) + (1 − w) · (±DISTANCE_LIMIT)
//! ```
//!
//! with `∇f` the central differences over the texel's size in metres along u and v (the
//! UV layout's scale per axis), and outside the zone `+DISTANCE_LIMIT` on the stain
//! (`f` above 0), `−DISTANCE_LIMIT` on clean cloth (no stain within `k` rings, `f` = 0),
//! so that `D` = 0 is the front alone. Bilinear filtering reads `D` linearly at any point,
//! so the shader's `s = clamp(½ + (D + n)/e)` (`n` its roughness, `e` the edge's width;
//! add-on `shading`) places the front to a fraction of a pixel: the stain drawn is
//! `L · s`. Outside the zone `s` is 1 on the stain and 0 on clean cloth: the stain is the
//! simulation's. The dye above saturation is not lifted (the shader multiplies it by `s`
//! too).
//!
//! Every pass is exact per element (max, min and one texel's arithmetic), so the result
//! is the same on any number of threads.

use rayon::prelude::*;

use super::clip::{Clip, clip};

/// Rings of the mesh over which a front is read as smeared (the simulation's fronts span
/// two to four).
pub const DEFAULT_RINGS: usize = 3;
/// A vertex is dry when its coverage is at most this fraction of its plateau.
pub const DRY: f32 = 0.02;
/// Values per vertex of [`outline_fields`]: `f`, `w`.
pub const FIELDS: usize = 2;
/// Below this fraction of its plateau a texel is taken as unstained by [`lift`] (its
/// `1/f` would overflow the colour's channels).
const F_MIN: f32 = 1e-6;
/// The largest distance to the front (metres) that [`lift`]'s channel carries: a texel
/// farther is well behind or ahead of it for the shader (whose roughness is a millimetre
/// or two), and outside the zone the channel is this.
pub const DISTANCE_LIMIT: f32 = 0.02;

/// The vertices' neighbours along the mesh's edges, compressed rows (`offsets`, `nbrs`).
fn neighbours(n_vertices: usize, faces: &[[u32; 3]]) -> (Vec<usize>, Vec<u32>) {
    let mut pairs: Vec<(u32, u32)> = Vec::with_capacity(6 * faces.len());
    for f in faces {
        for k in 0..3 {
            let (a, b) = (f[k], f[(k + 1) % 3]);
            if a != b {
                pairs.push((a, b));
                pairs.push((b, a));
            }
        }
    }
    pairs.par_sort_unstable();
    pairs.dedup();
    let mut offsets = vec![0usize; n_vertices + 1];
    for &(a, _) in &pairs {
        offsets[a as usize + 1] += 1;
    }
    for v in 0..n_vertices {
        offsets[v + 1] += offsets[v];
    }
    (offsets, pairs.into_iter().map(|(_, b)| b).collect())
}

/// `rings` rounds of `op` (max or min) over each vertex and its neighbours.
fn spread(
    values: &[f32],
    offsets: &[usize],
    nbrs: &[u32],
    rings: usize,
    op: fn(f32, f32) -> f32,
) -> Vec<f32> {
    let mut cur = values.to_vec();
    for _ in 0..rings {
        cur = (0..values.len())
            .into_par_iter()
            .map(|v| {
                nbrs[offsets[v]..offsets[v + 1]]
                    .iter()
                    .fold(cur[v], |acc, &u| op(acc, cur[u as usize]))
            })
            .collect();
    }
    cur
}

/// A mesh's rings for [`Outline::fields`]: its vertices' neighbours, built once for a
/// sequence of frames (the fine mesh's edges do not change).
#[derive(Debug, Clone)]
pub struct Outline {
    offsets: Vec<usize>,
    nbrs: Vec<u32>,
    rings: usize,
}

impl Outline {
    /// The rings of the mesh `faces` over `n_vertices` vertices, `rings` deep.
    ///
    /// # Panics
    /// When a face names a vertex beyond `n_vertices`.
    pub fn new(faces: &[[u32; 3]], n_vertices: usize, rings: usize) -> Self {
        assert!(
            faces.iter().flatten().all(|&v| (v as usize) < n_vertices),
            "face vertex out of range"
        );
        let (offsets, nbrs) = neighbours(n_vertices, faces);
        Outline {
            offsets,
            nbrs,
            rings,
        }
    }

    /// Vertices of the mesh.
    pub fn n_vertices(&self) -> usize {
        self.offsets.len() - 1
    }

    /// The per-vertex fields `(f, w)` of the reconstruction (module doc), [`FIELDS`] per
    /// vertex, from each vertex's `coverage`, read within `[0, 1]` (the dye amount up to
    /// saturation; a NaN gives `w` 0 around it, so that the texels keep their value).
    ///
    /// # Panics
    /// When `coverage` does not hold one value per vertex.
    pub fn fields(&self, coverage: &[f32]) -> Vec<f32> {
        let n = self.n_vertices();
        assert_eq!(coverage.len(), n, "one coverage per vertex");
        // the coverage within [0, 1]: a dye amount above saturation (a tide line, a pool's
        // unclamped amount under the weave's detail) is graded physics, not a smeared front
        let c: Vec<f32> = coverage
            .iter()
            .map(|&x| if x.is_nan() { x } else { x.clamp(0.0, 1.0) })
            .collect();
        let mut out = vec![0.0; FIELDS * n];
        if c.iter().all(|&x| x == 0.0) {
            return out; // a clean cloth: nothing to draw
        }
        let (o, nb, k) = (&self.offsets, &self.nbrs, self.rings);
        let plateau = spread(&c, o, nb, k, |a, b| {
            if a.is_nan() || b.is_nan() {
                f32::NAN
            } else {
                a.max(b)
            }
        });
        let lowest = spread(&c, o, nb, k, |a, b| {
            if a.is_nan() || b.is_nan() {
                f32::NAN
            } else {
                a.min(b)
            }
        });
        out.par_chunks_exact_mut(FIELDS)
            .enumerate()
            .for_each(|(v, o)| {
                let p = plateau[v];
                if p > 0.0 {
                    o[0] = c[v] / p;
                    o[1] = if lowest[v] <= DRY * p { 1.0 } else { 0.0 };
                }
            });
        out
    }
}

/// [`Outline::fields`] of `coverage` on the mesh `faces` (one vertex per value), the rings
/// built for this one call.
///
/// # Panics
/// When a face names a vertex beyond `coverage`.
pub fn outline_fields(faces: &[[u32; 3]], coverage: &[f32], rings: usize) -> Vec<f32> {
    Outline::new(faces, coverage.len(), rings).fields(coverage)
}

/// The ratio `r` of one texel (module doc) from its `f`, `w` and the magnitude of `∇f` in
/// texels.
#[inline]
fn ratio(f: f32, w: f32, gradient: f32) -> f32 {
    if !(f.is_finite() && w.is_finite() && gradient.is_finite()) || w <= 0.0 {
        return 1.0;
    }
    let s = if gradient > 1e-9 {
        (0.5 + (f - 0.5) / gradient).clamp(0.0, 1.0)
    } else if f > 0.5 {
        1.0
    } else {
        0.0
    };
    if f <= 1e-6 {
        return 1.0 - w;
    }
    1.0 + w * (s / f - 1.0)
}

/// Draws the outline into finished images (module doc): `fields` is the `size × size ×
/// FIELDS` raster of [`outline_fields`], `stain` optionally the premultiplied RGBA stain
/// image (4 channels), `wet` optionally the wet image, `(pixels, channels, excess)` with
/// channel `excess` the dye above saturation. Row order does not matter (all images
/// alike).
///
/// # Panics
/// When the images' lengths disagree with `size`.
pub fn sharpen(
    fields: &[f32],
    size: usize,
    stain: Option<&mut [f32]>,
    wet: Option<(&mut [f32], usize, usize)>,
) {
    let n = size * size;
    assert!(fields.len() == FIELDS * n, "fields layout");
    let ratios: Vec<f32> = (0..n)
        .into_par_iter()
        .map(|i| {
            let [gx, gy] = gradient(fields, size, i);
            ratio(fields[FIELDS * i], fields[FIELDS * i + 1], gx.hypot(gy))
        })
        .collect();
    scale(&ratios, stain, wet);
}

/// The central differences of the `f` raster at texel `i`, per texel along x and y (one
/// side at the image's border).
#[inline]
fn gradient(fields: &[f32], size: usize, i: usize) -> [f32; 2] {
    let f = |x: usize, y: usize| fields[FIELDS * (y * size + x)];
    let (x, y) = (i % size, i / size);
    let (x0, x1) = (x.saturating_sub(1), (x + 1).min(size - 1));
    let (y0, y1) = (y.saturating_sub(1), (y + 1).min(size - 1));
    let gx = if x1 > x0 {
        (f(x1, y) - f(x0, y)) / (x1 - x0) as f32
    } else {
        0.0
    };
    let gy = if y1 > y0 {
        (f(x, y1) - f(x, y0)) / (y1 - y0) as f32
    } else {
        0.0
    };
    [gx, gy]
}

/// Every channel of each stain texel times its ratio (re-clipped where the coverage then
/// exceeds 1), and the wet image's excess channel times `min(r, 1)`.
fn scale(ratios: &[f32], stain: Option<&mut [f32]>, wet: Option<(&mut [f32], usize, usize)>) {
    let n = ratios.len();
    if let Some(stain) = stain {
        assert!(stain.len() == 4 * n, "stain image layout");
        let over = stain
            .par_chunks_exact_mut(4)
            .zip(ratios.par_iter())
            .map(|(px, &r)| {
                if r == 1.0 {
                    return false;
                }
                px.iter_mut().for_each(|v| *v *= r);
                px[3] > 1.0
            })
            .reduce(|| false, |a, b| a | b);
        if over {
            clip(stain, 4, Clip::Premultiplied);
        }
    }
    if let Some((wet, channels, excess)) = wet {
        assert!(
            wet.len() == channels * n && excess < channels,
            "wet image layout"
        );
        wet.par_chunks_exact_mut(channels)
            .zip(ratios.par_iter())
            .for_each(|(px, &r)| {
                if r < 1.0 {
                    px[excess] *= r;
                }
            });
    }
}

/// Leaves the front to the shader (module doc, "At the pixel"): lifts the stain image to
/// its plateau over the zone, a texel past the smear, and writes the front's signed
/// distance (metres) into channel `distance` of the wet image, `(pixels, channels,
/// distance)`. `fields` is the `size × size × FIELDS` raster of [`outline_fields`] and
/// `texel` a texel's size in metres along x (u) and y (v).
///
/// # Panics
/// When the images' lengths disagree with `size`.
pub fn lift(
    fields: &[f32],
    size: usize,
    texel: [f32; 2],
    stain: Option<&mut [f32]>,
    wet: Option<(&mut [f32], usize, usize)>,
) {
    let n = size * size;
    assert!(fields.len() == FIELDS * n, "fields layout");
    let at = |i: usize| (fields[FIELDS * i], fields[FIELDS * i + 1]);
    let zoned = |f: f32, w: f32| f.is_finite() && w.is_finite() && w > 0.0;
    if let Some(stain) = stain {
        assert!(stain.len() == 4 * n, "stain image layout");
        let ratios: Vec<f32> = (0..n)
            .into_par_iter()
            .map(|i| match at(i) {
                (f, w) if zoned(f, w) && f > F_MIN => 1.0 + w * (1.0 / f - 1.0),
                _ => 1.0,
            })
            .collect();
        scale(&ratios, Some(&mut *stain), None);
        // a zone texel ahead of the smear takes its lifted 4-neighbours' mean
        let lifted: &[f32] = stain;
        let fill: Vec<(usize, [f32; 4])> = (0..n)
            .into_par_iter()
            .filter_map(|i| {
                let (f, w) = at(i);
                if !(zoned(f, w) && f <= F_MIN) {
                    return None;
                }
                let (x, y) = (i % size, i / size);
                let mut sum = [0.0f32; 4];
                let mut count = 0.0f32;
                let mut add = |j: usize| {
                    let (fj, wj) = at(j);
                    if zoned(fj, wj) && fj > F_MIN {
                        for (s, v) in sum.iter_mut().zip(&lifted[4 * j..4 * j + 4]) {
                            *s += v;
                        }
                        count += 1.0;
                    }
                };
                if x > 0 {
                    add(i - 1);
                }
                if x + 1 < size {
                    add(i + 1);
                }
                if y > 0 {
                    add(i - size);
                }
                if y + 1 < size {
                    add(i + size);
                }
                (count > 0.0).then(|| (i, sum.map(|s| s / count)))
            })
            .collect();
        for (i, px) in fill {
            stain[4 * i..4 * i + 4].copy_from_slice(&px);
        }
    }
    if let Some((wet, channels, distance)) = wet {
        assert!(
            wet.len() == channels * n && distance < channels,
            "wet image layout"
        );
        wet.par_chunks_exact_mut(channels)
            .enumerate()
            .for_each(|(i, px)| {
                let (f, w) = at(i);
                // outside the zone: behind the front on the stain, ahead on clean cloth
                let away = if f > 0.0 {
                    DISTANCE_LIMIT
                } else {
                    -DISTANCE_LIMIT
                };
                px[distance] = if zoned(f, w) {
                    let [gx, gy] = gradient(fields, size, i);
                    let slope = (gx / texel[0]).hypot(gy / texel[1]);
                    let d = if slope > 0.0 && slope.is_finite() {
                        ((f - 0.5) / slope).clamp(-DISTANCE_LIMIT, DISTANCE_LIMIT)
                    } else if f > 0.5 {
                        DISTANCE_LIMIT
                    } else {
                        -DISTANCE_LIMIT
                    };
                    let w = w.min(1.0);
                    w * d + (1.0 - w) * away
                } else if f.is_nan() {
                    DISTANCE_LIMIT
                } else {
                    away
                };
            });
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_ratio_cuts_ahead_of_the_half_level_and_lifts_behind_it() {
        // a front one texel wide in f: at f = ½ half covered, the plateau behind, 0 ahead
        assert_eq!(ratio(0.5, 1.0, 1.0) * 0.5, 0.5);
        assert_eq!(ratio(0.9, 1.0, 0.2), 1.0 / 0.9);
        assert_eq!(ratio(0.2, 1.0, 0.2), 0.0);
        // outside the zone, or on bad input, the texel stays
        assert_eq!(ratio(0.2, 0.0, 0.2), 1.0);
        assert_eq!(ratio(f32::NAN, 1.0, 0.2), 1.0);
        // half in the zone: half way
        assert!((ratio(0.2, 0.5, 0.2) - 0.5).abs() < 1e-7);
    }

    #[test]
    fn plateau_and_zone_follow_the_rings() {
        // a path 0 - 1 - 2 - 3 - 4 - 5 - 6 (degenerate triangles make its edges)
        let faces: Vec<[u32; 3]> = (0..6).map(|i| [i, i + 1, i + 1]).collect();
        let c = [1.0, 1.0, 1.0, 1.0, 0.6, 0.2, 0.0];
        let out = outline_fields(&faces, &c, 2);
        let f: Vec<f32> = out.chunks(2).map(|o| o[0]).collect();
        let w: Vec<f32> = out.chunks(2).map(|o| o[1]).collect();
        assert_eq!(w, [0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0]); // dry within 2 rings from 4 on
        assert_eq!(f[4], 0.6); // plateau 1 two rings behind
        assert_eq!(f[5], 0.2); // vertex 3's plateau is within two rings of 5
        assert_eq!(f[6], 0.0);
        // one ring: vertex 5's plateau is vertex 4's 0.6, and 4 is outside the zone
        let out = outline_fields(&faces, &c, 1);
        assert!((out[10] - 0.2 / 0.6).abs() < 1e-7);
        assert_eq!([out[9], out[11]], [0.0, 1.0]);
        // dye above saturation reads as saturated: a graded pool is no front
        let pool = [3.0, 2.5, 2.0, 1.5, 0.6, 0.2, 0.0];
        assert_eq!(
            outline_fields(&faces, &pool, 2),
            outline_fields(&faces, &c, 2)
        );
    }
}
