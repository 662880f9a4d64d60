//! Padding: growing each UV island outward, so that filtering and mip-mapping show no seam.
//!
//! A renderer samples a texture bilinearly (4 texels) and, farther away, from mip levels
//! (each texel the mean of a 2ᵏ × 2ᵏ block): both mix texels just outside an island into its
//! border. Left empty (0), those texels darken every island's outline and draw the UV seams
//! on the cloth. Padding fills them with values continuing the island's border.
//!
//! One pass: every texel not yet covered with at least one covered texel among its 8
//! neighbours takes the mean of those neighbours' values and becomes covered
//! ([`PADDED`]); the neighbours are read as they were *before* the pass, so a pass grows
//! every island by one texel (in the chessboard metric) whatever the order of the texels.
//! `n` passes grow it by `n` texels; 4 (the default, [`DEFAULT_PADDING`]) cover bilinear
//! filtering at mip level 2 (4 × 4 blocks) and, in practice, the levels a cloth seen from a
//! usual distance uses. A field constant over an island stays exactly constant in its
//! padding (a mean of equal values), so a constant field shows no seam at all.
//!
//! Texels are never taken from another island once covered: where two islands' paddings
//! meet, each texel goes to whichever reached it first, and a texel both reach in the same
//! pass takes the mean of both sides.
//!
//! Deterministic: a pass computes every new value from the state before it, each row by
//! one task, the neighbours summed in a fixed order in `f64`; then writes them. The same
//! bits on any number of threads. Cost: the first pass scans the image (a byte per texel,
//! and the neighbours of the empty texels next to an island); each later pass visits only
//! the empty neighbours of the texels the pass before filled: the islands' outlines.

use rayon::prelude::*;

use super::raster::{EMPTY, PADDED, Raster};

/// The padding [`pad`] is usually called with, in texels.
pub const DEFAULT_PADDING: usize = 4;

/// Grows every island of `raster` outward by `texels` texels (see the module doc).
/// Returns the number of texels filled.
pub fn pad(raster: &mut Raster, texels: usize) -> usize {
    pad_to(
        &mut raster.pixels,
        &mut raster.coverage,
        raster.size,
        raster.channels,
        texels,
    )
}

/// [`pad`] on caller-owned buffers laid out as [`Raster`]'s `pixels` and `coverage`
/// (`size × size × channels` and `size × size`).
///
/// # Panics
/// If the buffers do not have those lengths.
pub fn pad_to(
    pixels: &mut [f32],
    coverage: &mut [u8],
    size: usize,
    channels: usize,
    texels: usize,
) -> usize {
    let c = channels;
    assert_eq!(pixels.len(), size * size * c, "pixels length");
    assert_eq!(coverage.len(), size * size, "coverage length");
    let mut filled = 0;
    if size == 0 || c == 0 {
        return 0;
    }
    // per row: the texels filled by the previous pass (None before the first pass)
    let mut last: Option<Vec<(Vec<u32>, Vec<f32>)>> = None;
    for _ in 0..texels {
        let (cov, pix) = (&*coverage, &*pixels);
        // the mean of the covered 8-neighbours of (x, y), if any
        let mean = |x: usize, y: usize, sum: &mut [f64]| -> Option<()> {
            let mut n = 0u32;
            sum.iter_mut().for_each(|s| *s = 0.0);
            for yy in y.saturating_sub(1)..=(y + 1).min(size - 1) {
                for xx in x.saturating_sub(1)..=(x + 1).min(size - 1) {
                    let j = yy * size + xx;
                    if cov[j] != EMPTY {
                        n += 1;
                        for (s, &v) in sum.iter_mut().zip(&pix[j * c..(j + 1) * c]) {
                            *s += f64::from(v);
                        }
                    }
                }
            }
            (n > 0).then(|| sum.iter_mut().for_each(|s| *s /= f64::from(n)))
        };
        // per row: the texels filled this pass and their values
        let new: Vec<(Vec<u32>, Vec<f32>)> = match &last {
            // first pass: every empty texel next to a covered one
            None => (0..size)
                .into_par_iter()
                .map(|y| {
                    let mut xs = Vec::new();
                    let mut vals = Vec::new();
                    let row = &cov[y * size..(y + 1) * size];
                    if !row.contains(&EMPTY) {
                        return (xs, vals);
                    }
                    let (lo, hi) = (y.saturating_sub(1), (y + 1).min(size - 1));
                    // col[x]: some texel of rows lo..=hi in column x is covered
                    let mut col = vec![false; size];
                    for yy in lo..=hi {
                        let r = &cov[yy * size..(yy + 1) * size];
                        for (n, &m) in col.iter_mut().zip(r) {
                            *n |= m != EMPTY;
                        }
                    }
                    let mut sum = vec![0.0f64; c];
                    for x in 0..size {
                        let near = col[x] || (x > 0 && col[x - 1]) || (x + 1 < size && col[x + 1]);
                        if row[x] == EMPTY && near && mean(x, y, &mut sum).is_some() {
                            xs.push(x as u32);
                            vals.extend(sum.iter().map(|&s| s as f32));
                        }
                    }
                    (xs, vals)
                })
                .collect(),
            // later passes: only the empty neighbours of the texels the last pass filled
            Some(prev) => (0..size)
                .into_par_iter()
                .map(|y| {
                    let mut cand: Vec<u32> = Vec::new();
                    for (xs, _) in &prev[y.saturating_sub(1)..=(y + 1).min(size - 1)] {
                        for &x in xs {
                            let x = x as usize;
                            for xx in x.saturating_sub(1)..=(x + 1).min(size - 1) {
                                cand.push(xx as u32);
                            }
                        }
                    }
                    cand.sort_unstable();
                    cand.dedup();
                    let mut xs = Vec::new();
                    let mut vals = Vec::new();
                    let mut sum = vec![0.0f64; c];
                    for x in cand {
                        let xu = x as usize;
                        if cov[y * size + xu] == EMPTY && mean(xu, y, &mut sum).is_some() {
                            xs.push(x);
                            vals.extend(sum.iter().map(|&s| s as f32));
                        }
                    }
                    (xs, vals)
                })
                .collect(),
        };
        let pass: usize = new.iter().map(|(xs, _)| xs.len()).sum();
        if pass == 0 {
            break;
        }
        filled += pass;
        pixels
            .par_chunks_mut(size * c)
            .zip(coverage.par_chunks_mut(size))
            .zip(new.par_iter())
            .for_each(|((pixels, coverage), (xs, vals))| {
                for (i, &x) in xs.iter().enumerate() {
                    let x = x as usize;
                    coverage[x] = PADDED;
                    pixels[x * c..(x + 1) * c].copy_from_slice(&vals[i * c..(i + 1) * c]);
                }
            });
        last = Some(new);
    }
    filled
}
