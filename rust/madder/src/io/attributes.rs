//! The playback attributes of one baked frame: what Blender's shader reads, computed from
//! the raw densities the cache keeps (kg/m², module [`crate::io::cache`]).
//!
//! Per vertex, with the references the bake recorded (densities that read as full):
//! - the dye amount `a = solute / ref_solute` (1: the fibres saturated with the liquid)
//!   and the stain colour, RGBA `(s·r, s·g, s·b, a)` with `s = min(a, 1)` the coverage
//!   (premultiplied, for an "over" mix: the colour never brightens past the liquid's own,
//!   where Blender's Solid view shows the attribute as it is);
//!   the colour is the bake's one colour, or the per-vertex mix of the liquids when the
//!   bake tracked colours;
//! - wetness `clamp(liquid / ref_liquid, 0, 1)` (1: the fibres are full);
//! - deposit `clamp(adsorbed / ref_deposit, 0, 1)`.
//!
//! **The dye above saturation.** A drying stain carries its solute to the edge, so a
//! tide line holds two to six times the dye of a saturated spot, and the shader darkens
//! by the dye amount without limit (Kubelka–Munk: K/S grows linearly with the dye, the
//! add-on's `shading`). So the amount is not clamped at 1, only held in
//! `[0, 1 + EXCESS_RANGE]`: a dried ring reaches 3–6, a standing pool of the liquid more,
//! and at 17 the dark liquids' colours are within a few per cent of black (the range only
//! bounds what an image channel carries as a fraction). How it is carried depends on the
//! output:
//! - the vertex attributes (`excess` absent) carry the whole amount in the alpha;
//! - the images (`excess` given) keep the alpha in `[0, 1]`, as the weave's detail needs
//!   (below), and write the share above 1 as `excess = clamp((a − 1) / EXCESS_RANGE, 0,
//!   1)`, a fraction, into a channel of the wet image; the material adds it back. The
//!   excess carries no weave (the threads' uptake): the first saturation follows the
//!   threads, what the drying flow piles on top of it lies over them evenly.
//!
//! Unclamped (`clamp = false`: the texture path with the weave's detail, which multiplies
//! the values by the threads' uptake and clips the finished texel, [`crate::texture::clip`])
//! the fractions keep their excess over 1, so a saturated stain stays saturated on every
//! thread instead of showing pale gaps; they are still ≥ 0. The excess is the same either
//! way.
//!
//! A reference ≤ 0 makes its attribute 0. This runs on every frame change of playback, so
//! it is one pass into the caller's buffers (numpy needed four strided passes and twice
//! the time of everything else the frame change costs).

/// The dye amount above saturation the outputs carry (module doc): amounts are held in
/// `[0, 1 + EXCESS_RANGE]`, and an image's excess channel is `(a − 1) / EXCESS_RANGE`.
pub const EXCESS_RANGE: f32 = 16.0;

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
/// `liquid` and `adsorbed` and the `references` (solute, liquid, deposit), and `excess`
/// when given (the images' share of the dye above saturation; the alpha then stays within
/// 1); with `clamp` false the fractions are not limited to 1 (module doc).
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
    mut excess: Option<&mut [f32]>,
) {
    let upper = if clamp { 1.0 } else { f32::INFINITY };
    // the dye amount's limit: the whole of it in the vertex alpha, within 1 in an image's
    let dye_upper = match (&excess, clamp) {
        (_, false) => f32::INFINITY,
        (Some(_), true) => 1.0,
        (None, true) => 1.0 + EXCESS_RANGE,
    };
    let n = solute.len();
    assert!(liquid.len() == n && adsorbed.len() == n && rgba.len() == 4 * n);
    assert!(wetness.len() == n && deposit.len() == n);
    assert!(excess.as_ref().is_none_or(|e| e.len() == n));
    let [rs, rl, rd] = references;
    for (i, px) in rgba.chunks_exact_mut(4).enumerate() {
        let a = fraction(solute[i], rs, f32::INFINITY);
        let c = a.clamp(0.0, dye_upper); // (a NaN stays NaN)
        let [r, g, b] = match colour {
            StainColour::Uniform(rgb) => rgb,
            StainColour::PerVertex([r, g, b]) => [r[i], g[i], b[i]],
        };
        // the colour premultiplied by the coverage (within 1 where the amount is clamped;
        // the unclamped texture path keeps `c` and clips the texel after the detail)
        let s = if clamp { c.min(1.0) } else { c };
        px.copy_from_slice(&[s * r, s * g, s * b, c]);
        if let Some(e) = excess.as_deref_mut() {
            e[i] = ((a - 1.0) / EXCESS_RANGE).clamp(0.0, 1.0);
        }
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

    /// `stain_attributes` into fresh buffers: (rgba, wetness, deposit, excess).
    fn attributes(
        s: &[f32],
        colour: StainColour<'_>,
        references: [f32; 3],
        clamp: bool,
        with_excess: bool,
    ) -> (Vec<f32>, Vec<f32>, Vec<f32>, Option<Vec<f32>>) {
        let (l, a) = ([0.1, 0.2, 0.0, 9.0, 0.0], [1.0; 5]);
        let (mut rgba, mut w, mut d, mut e) =
            (vec![9.0; 20], vec![9.0; 5], vec![9.0; 5], vec![9.0; 5]);
        let excess = with_excess.then_some(&mut e[..]);
        stain_attributes(
            s, &l, &a, colour, references, clamp, &mut rgba, &mut w, &mut d, excess,
        );
        (rgba, w, d, with_excess.then_some(e))
    }

    #[test]
    fn dye_amount_is_kept_above_one_and_the_rest_clamped() {
        let s = [0.0, 0.5, 2.0, -1.0, 40.0];
        let colour = StainColour::Uniform([0.5, 0.25, 1.0]);
        // the vertex attributes: the whole dye amount, within 1 + EXCESS_RANGE
        let (rgba, w, d, _) = attributes(&s, colour, [1.0, 0.2, 0.0], true, false);
        assert_eq!(&rgba[4..8], &[0.25, 0.125, 0.5, 0.5]);
        // twice saturated: twice the dye, the colour premultiplied by the coverage, 1
        assert_eq!(&rgba[8..12], &[0.5, 0.25, 1.0, 2.0]);
        assert_eq!(&rgba[12..16], &[0.0; 4]); // negative: 0
        // a pool beyond the range: held at its top
        assert_eq!(&rgba[16..], &[0.5, 0.25, 1.0, 1.0 + EXCESS_RANGE]);
        assert_eq!(w, [0.5, 1.0, 0.0, 1.0, 0.0]);
        assert_eq!(d, [0.0; 5]); // reference 0
        // the images: the alpha within 1, the share above it as a fraction of the range
        let (rgba, _, _, e) = attributes(&s, colour, [1.0, 0.2, 0.0], true, true);
        assert_eq!(&rgba[8..12], &[0.5, 0.25, 1.0, 1.0]);
        assert_eq!(&rgba[16..], &[0.5, 0.25, 1.0, 1.0]);
        assert_eq!(e.unwrap(), [0.0, 0.0, 1.0 / EXCESS_RANGE, 0.0, 1.0]);
        let (r, g, b) = ([1.0; 5], [0.0; 5], [0.5; 5]);
        let (rgba, ..) = attributes(
            &s,
            StainColour::PerVertex([&r, &g, &b]),
            [1.0; 3],
            true,
            false,
        );
        assert_eq!(&rgba[4..8], &[0.5, 0.0, 0.25, 0.5]);
        // unclamped: every excess over 1 is kept, negatives are still 0; the excess as clamped
        let (rgba, w, _, e) = attributes(&s, colour, [1.0, 0.2, 0.0], false, true);
        assert_eq!(&rgba[8..12], &[1.0, 0.5, 2.0, 2.0]);
        assert_eq!(&rgba[12..16], &[0.0; 4]);
        assert_eq!(rgba[19], 40.0);
        assert_eq!(w, [0.5, 1.0, 0.0, 45.0, 0.0]);
        assert_eq!(e.unwrap(), [0.0, 0.0, 1.0 / EXCESS_RANGE, 0.0, 1.0]);
        // a NaN density stays NaN, in the alpha and in the excess
        let (rgba, _, _, e) = attributes(&[f32::NAN; 5], colour, [1.0; 3], true, true);
        assert!(rgba[3].is_nan() && e.unwrap()[0].is_nan());
    }
}
