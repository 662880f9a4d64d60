//! Clipping a finished image into the range the shader reads (issue 13: the weave's detail
//! on a saturated stain).
//!
//! With the weave's detail the rasterizer multiplies the stain by the threads' uptake `U`
//! (mean 1 over a tile, module [`super::weave`]). Done on fractions already clamped to 1,
//! a saturated stain would come out as `U` itself: threads at `U > 1` clipped to 1 by the
//! shader and gaps at `U < 1` pale, a weave pattern where the dye has saturated every
//! fibre. So the texture path reads the fractions unclamped ([`crate::io::attributes`]),
//! adds the detail, and clips only the finished texel:
//!
//! - [`Clip::Unit`]: every channel to `[0, 1]` (the wetness and deposit image);
//! - [`Clip::Premultiplied`]: a premultiplied RGBA texel `(c·r, c·g, c·b, c)` with its
//!   coverage `c` last: a texel with `c > 1` is scaled by `1/c` (colour kept, coverage
//!   1), one with `c ≤ 0` becomes 0, and the colour channels are then held in `[0, c]`.
//!   For the one colour of a bake this is `min(c, 1)` times the colour, what clamping
//!   after the detail means; for mixed colours it keeps the mix's hue.
//!
//! Where no value exceeds 1 and none is negative both leave the image as it is, bit for
//! bit. Each texel is clipped on its own, so the result does not depend on the thread
//! count.

use rayon::prelude::*;

/// How [`clip`] limits a texel (module doc).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Clip {
    /// Every channel into `[0, 1]`.
    Unit,
    /// Premultiplied colour with its coverage in the last channel.
    Premultiplied,
}

/// Clips `pixels`, texels of `channels` values each, in place (module doc). A texel with
/// a NaN keeps it.
///
/// # Panics
/// When `channels` is 0 or does not divide `pixels.len()`.
pub fn clip(pixels: &mut [f32], channels: usize, mode: Clip) {
    assert!(channels > 0 && pixels.len() % channels == 0, "texel layout");
    let texels_per_chunk = 1 << 14;
    pixels
        .par_chunks_mut(channels * texels_per_chunk)
        .for_each(|chunk| match mode {
            Clip::Unit => chunk.iter_mut().for_each(|v| *v = v.clamp(0.0, 1.0)),
            Clip::Premultiplied => chunk.chunks_exact_mut(channels).for_each(premultiplied),
        });
}

#[inline]
fn premultiplied(texel: &mut [f32]) {
    let (colour, coverage) = texel.split_at_mut(texel.len() - 1);
    let c = coverage[0];
    if c > 1.0 {
        let s = 1.0 / c;
        colour.iter_mut().for_each(|v| *v *= s);
        coverage[0] = 1.0;
    } else if c <= 0.0 {
        colour.iter_mut().for_each(|v| *v = 0.0);
        coverage[0] = 0.0;
    }
    let c = coverage[0];
    if c.is_nan() {
        return;
    }
    colour.iter_mut().for_each(|v| *v = v.clamp(0.0, c));
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clips_premultiplied_texels_by_their_coverage() {
        let mut px = [
            0.5, 0.25, 1.0, 1.0, // in range: unchanged
            1.0, 0.5, 2.0, 2.0, // coverage 2: halved
            -0.1, 0.1, 0.0, -0.2, // negative coverage: 0
            0.3, -0.01, 0.6, 0.5, // colour below 0 / above the coverage: held in [0, c]
        ];
        clip(&mut px, 4, Clip::Premultiplied);
        assert_eq!(px[..4], [0.5, 0.25, 1.0, 1.0]);
        assert_eq!(px[4..8], [0.5, 0.25, 1.0, 1.0]);
        assert_eq!(px[8..12], [0.0; 4]);
        assert_eq!(px[12..], [0.3, 0.0, 0.5, 0.5]);
        let mut nan = [0.5, 0.5, 0.5, f32::NAN];
        clip(&mut nan, 4, Clip::Premultiplied);
        assert!(nan[3].is_nan() && nan[..3] == [0.5; 3]);
        let mut wet = [-0.5, 0.25, 1.5, f32::NAN];
        clip(&mut wet, 2, Clip::Unit);
        assert_eq!(wet[..3], [0.0, 0.25, 1.0]);
        assert!(wet[3].is_nan());
    }
}
