//! The playback attributes of one baked frame: what Blender's shader reads, computed from
//! the raw densities the cache keeps (kg/m², module [`crate::io::cache`]).
//!
//! Per vertex, with the references the bake recorded (densities that read as full):
//! - coverage `c = clamp(solute / ref_solute, 0, 1)` and the stain colour, RGBA
//!   `(c·r, c·g, c·b, c)` (premultiplied, for an "over" mix); the colour is the bake's one
//!   colour, or the per-vertex mix of the liquids when the bake tracked colours;
//! - wetness `clamp(liquid / ref_liquid, 0, 1)` (1: the fibres are full);
//! - deposit `clamp(adsorbed / ref_deposit, 0, 1)`.
//!
//! Unclamped (`clamp = false`: the texture path with the weave's detail, which multiplies
//! the values by the threads' uptake and clips the finished texel, [`crate::texture::clip`])
//! the fractions keep their excess over 1, so a saturated stain stays saturated on every
//! thread instead of showing pale gaps; they are still ≥ 0.
//!
//! A reference ≤ 0 makes its attribute 0. This runs on every frame change of playback, so
//! it is one pass into the caller's buffers (numpy needed four strided passes and twice
//! the time of everything else the frame change costs).

/// The colour of the stain: one for the whole bake, or per vertex (r, g, b slices).
#[derive(Clone, Copy, Debug)]
pub(crate) enum StainColour<'a> {
    Uniform([f32; 3]),
    PerVertex([&'a [f32]; 3]),
}

/// `x / reference` clamped to [0, `upper`] (0 when `reference` ≤ 0; NaN stays NaN).
#[inline]
fn fraction(x: f32, reference: f32, upper: f32) -> f32 {
    if reference > 0.0 {
        (x / reference).clamp(0.0, upper)
    } else {
        0.0
    }
}

/// Fills `rgba` (4 per vertex), `wetness` and `deposit` from the densities `solute`,
/// `liquid` and `adsorbed` and the `references` (solute, liquid, deposit); with `clamp`
/// false the fractions are not limited to 1 (module doc).
///
/// # Panics
/// When the slices' lengths disagree (the caller checks them).
#[allow(clippy::too_many_arguments)]
pub(crate) fn stain_attributes(
    solute: &[f32],
    liquid: &[f32],
    adsorbed: &[f32],
    colour: StainColour<'_>,
    references: [f32; 3],
    clamp: bool,
    rgba: &mut [f32],
    wetness: &mut [f32],
    deposit: &mut [f32],
) {
    let upper = if clamp { 1.0 } else { f32::INFINITY };
    let n = solute.len();
    assert!(liquid.len() == n && adsorbed.len() == n && rgba.len() == 4 * n);
    assert!(wetness.len() == n && deposit.len() == n);
    let [rs, rl, rd] = references;
    for (i, px) in rgba.chunks_exact_mut(4).enumerate() {
        let c = fraction(solute[i], rs, upper);
        let [r, g, b] = match colour {
            StainColour::Uniform(rgb) => rgb,
            StainColour::PerVertex([r, g, b]) => [r[i], g[i], b[i]],
        };
        px.copy_from_slice(&[c * r, c * g, c * b, c]);
    }
    for (w, &x) in wetness.iter_mut().zip(liquid) {
        *w = fraction(x, rl, upper);
    }
    for (d, &x) in deposit.iter_mut().zip(adsorbed) {
        *d = fraction(x, rd, upper);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clamps_and_premultiplies() {
        let (s, l, a) = ([0.0, 0.5, 2.0, -1.0], [0.1, 0.2, 0.0, 9.0], [1.0; 4]);
        let (mut rgba, mut w, mut d) = ([9.0; 16], [9.0; 4], [9.0; 4]);
        let colour = StainColour::Uniform([0.5, 0.25, 1.0]);
        stain_attributes(
            &s,
            &l,
            &a,
            colour,
            [1.0, 0.2, 0.0],
            true,
            &mut rgba,
            &mut w,
            &mut d,
        );
        assert_eq!(&rgba[4..8], &[0.25, 0.125, 0.5, 0.5]);
        assert_eq!(&rgba[8..12], &[0.5, 0.25, 1.0, 1.0]); // clamped to 1
        assert_eq!(&rgba[12..], &[0.0; 4]); // negative: 0
        assert_eq!(w, [0.5, 1.0, 0.0, 1.0]);
        assert_eq!(d, [0.0; 4]); // reference 0
        let (r, g, b) = ([1.0; 4], [0.0; 4], [0.5; 4]);
        stain_attributes(
            &s,
            &l,
            &a,
            StainColour::PerVertex([&r, &g, &b]),
            [1.0; 3],
            true,
            &mut rgba,
            &mut w,
            &mut d,
        );
        assert_eq!(&rgba[4..8], &[0.5, 0.0, 0.25, 0.5]);
        // unclamped: the excess over 1 is kept, negatives are still 0
        stain_attributes(
            &s,
            &l,
            &a,
            colour,
            [1.0, 0.2, 0.0],
            false,
            &mut rgba,
            &mut w,
            &mut d,
        );
        assert_eq!(&rgba[8..12], &[1.0, 0.5, 2.0, 2.0]);
        assert_eq!(&rgba[12..], &[0.0; 4]);
        assert_eq!(w, [0.5, 1.0, 0.0, 45.0]);
    }
}
