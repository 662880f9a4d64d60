//! The outline drawn at the texel (`madder::texture::outline`) against exact results: a
//! round stain whose front the simulation smeared over three cells (coverage falling
//! linearly from 1 to 0 across `L` = 3 cells about the true radius `R`):
//!
//! - drawn, every texel between 10 % and 90 % lies within one texel of `R`, at 128 and at
//!   256 px (the edge narrows with the texel, not the cell), where the smeared image's lie
//!   up to `L/2` away;
//! - the stain's mass (Σ coverage) is kept within 1 % and the area above half within 1 %
//!   of `πR²`;
//! - the plateau away from the dry cloth, and a graded field with no dry cloth near, are
//!   left bit for bit; the colour's hue is kept on every texel; the dye above saturation
//!   is cut ahead of the front and never raised;
//! - the same bits on 1 and 3 threads.
//!
//! Left to the shader ([`lift`]), on the same stain:
//! - the distance channel is the true signed distance `R − r` to within a fifth of a texel
//!   wherever the front is within a texel, and `±DISTANCE_LIMIT` outside the zone (on
//!   the stain, on clean cloth);
//! - the lifted stain is the plateau (1, in the colour's hue) wherever the simulation
//!   stained the zone, so the stain a shader draws, `L · step(D)` sampled at the texels,
//!   holds `πR²` to 1 % and the mass of the smeared image to 1 %; away from the dry
//!   cloth the stain is left bit for bit; the same bits on 1 and 3 threads.

mod common;

use common::Grid;
use madder::texture::outline::{
    DEFAULT_RINGS, DISTANCE_LIMIT, FIELDS, lift, outline_fields, sharpen,
};
use madder::texture::rasterize;

const N: usize = 40; // cells across the unit square
const R: f64 = 0.3; // the stain's true radius
const L: f64 = 3.0 / N as f64; // the smeared ramp's width
const CENTRE: [f64; 2] = [0.5, 0.5];
const COLOUR: [f32; 3] = [0.5, 0.25, 1.0];

struct Images {
    size: usize,
    before: Vec<f32>,
    after: Vec<f32>,
    wet_before: Vec<f32>,
    wet_after: Vec<f32>,
    fields: Vec<f32>,
}

type Uv = [[f64; 2]; 3];

/// The grid's faces, their corners' UVs and the vertices' UVs (UV = position).
fn uv_grid() -> (Vec<[u32; 3]>, Vec<Uv>, Vec<[f64; 2]>) {
    let grid = Grid::new(N, 0.5);
    let faces = grid.faces();
    let points: Vec<[f64; 2]> = grid
        .positions(|x, y| glam::DVec3::new(x + 0.5, y + 0.5, 0.0))
        .iter()
        .map(|p| [p.x, p.y])
        .collect();
    let uv = faces
        .iter()
        .map(|f| f.map(|v| points[v as usize]))
        .collect();
    (faces, uv, points)
}

/// Rasterizes the stain `coverage(u, v)` (RGBA premultiplied) and a wet image (wetness 1,
/// deposit 0, excess `excess(u, v)`), and draws the outline, on `threads` threads.
fn draw(
    size: usize,
    coverage: impl Fn(f64, f64) -> f64,
    excess: impl Fn(f64, f64) -> f64,
    threads: usize,
) -> Images {
    let (faces, uv, points) = uv_grid();
    let c: Vec<f32> = points.iter().map(|p| coverage(p[0], p[1]) as f32).collect();
    let rgba: Vec<f32> = c
        .iter()
        .flat_map(|&a| [a * COLOUR[0], a * COLOUR[1], a * COLOUR[2], a])
        .collect();
    let wet: Vec<f32> = points
        .iter()
        .flat_map(|p| [1.0, 0.0, excess(p[0], p[1]) as f32])
        .collect();
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    pool.install(|| {
        let fields = outline_fields(&faces, &c, DEFAULT_RINGS);
        let fields = rasterize(&faces, &uv, &fields, FIELDS, size)
            .unwrap()
            .pixels;
        let before = rasterize(&faces, &uv, &rgba, 4, size).unwrap().pixels;
        let wet_before = rasterize(&faces, &uv, &wet, 3, size).unwrap().pixels;
        let (mut after, mut wet_after) = (before.clone(), wet_before.clone());
        sharpen(
            &fields,
            size,
            Some(&mut after),
            Some((&mut wet_after, 3, 2)),
        );
        Images {
            size,
            before,
            after,
            wet_before,
            wet_after,
            fields,
        }
    })
}

fn smeared(u: f64, v: f64) -> f64 {
    let r = (u - CENTRE[0]).hypot(v - CENTRE[1]);
    (0.5 + (R - r) / L).clamp(0.0, 1.0)
}

/// Each texel's centre's distance from the stain's centre, in texels, and its alpha.
fn profile(img: &Images, pixels: &[f32]) -> Vec<(f64, f32)> {
    let s = img.size;
    (0..s * s)
        .map(|i| {
            let (x, y) = ((i % s) as f64 + 0.5, (i / s) as f64 + 0.5);
            let r = (x - CENTRE[0] * s as f64).hypot(y - CENTRE[1] * s as f64);
            (r, pixels[4 * i + 3])
        })
        .collect()
}

#[test]
fn a_smeared_front_is_drawn_within_a_texel_and_keeps_its_mass() {
    for size in [128, 256] {
        let img = draw(size, smeared, |_, _| 0.0, 2);
        let r_texels = R * size as f64;
        let edge = |pixels: &[f32]| {
            profile(&img, pixels)
                .into_iter()
                .filter(|&(_, a)| a > 0.1 && a < 0.9)
                .map(|(r, _)| (r - r_texels).abs())
                .fold(0.0, f64::max)
        };
        let (smear, drawn) = (edge(&img.before), edge(&img.after));
        println!(
            "{size} px: 10-90 % texels up to {smear:.2} texels from R before, {drawn:.2} after"
        );
        assert!(
            smear > 0.4 * L * size as f64,
            "the smeared ramp spans its cells"
        );
        assert!(
            drawn <= 1.5,
            "drawn edge up to {drawn:.2} texels from R at {size} px"
        );
        let mass = |p: &[f32]| p.chunks(4).map(|t| t[3] as f64).sum::<f64>();
        let (m0, m1) = (mass(&img.before), mass(&img.after));
        assert!((m1 / m0 - 1.0).abs() < 0.01, "mass {m1} against {m0}");
        let half = img.after.chunks(4).filter(|t| t[3] > 0.5).count() as f64;
        let exact = std::f64::consts::PI * r_texels * r_texels;
        assert!(
            (half / exact - 1.0).abs() < 0.01,
            "area above half {half} against πR² {exact}"
        );
        // the hue is the colour's on every texel, and nothing exceeds the plateau
        for t in img.after.chunks(4) {
            assert!(t[3] <= 1.0);
            for k in 0..3 {
                assert!((t[k] - COLOUR[k] * t[3]).abs() <= 1e-6);
            }
        }
        // away from the dry cloth (w = 0 on the texel) the stain is as simulated
        let mut kept = 0;
        for (i, t) in img.after.chunks(4).enumerate() {
            if img.fields[FIELDS * i + 1] == 0.0 {
                assert_eq!(t, &img.before[4 * i..4 * i + 4]);
                kept += 1;
            }
        }
        assert!(
            kept > size * size / 2,
            "the plateau and the dry cloth are left ({kept} texels)"
        );
    }
}

#[test]
fn a_graded_stain_with_no_dry_cloth_near_is_left_bit_for_bit() {
    let img = draw(128, |u, _| 0.3 + 0.5 * u, |_, _| 0.0, 2);
    assert_eq!(img.after, img.before);
    assert_eq!(img.wet_after, img.wet_before);
}

#[test]
fn the_dye_above_saturation_is_cut_ahead_of_the_front_and_never_raised() {
    // a tide line's excess on the smeared front itself
    let img = draw(128, smeared, |u, v| 0.5 * smeared(u, v), 2);
    let mut cut = 0;
    for (i, (a, b)) in img
        .wet_before
        .chunks(3)
        .zip(img.wet_after.chunks(3))
        .enumerate()
    {
        assert_eq!(&a[..2], &b[..2], "wetness and deposit are left");
        assert!(b[2] <= a[2]);
        if img.after[4 * i + 3] == 0.0 && a[2] > 0.0 {
            assert_eq!(b[2], 0.0);
            cut += 1;
        }
    }
    assert!(cut > 0, "some excess lay ahead of the front");
}

#[test]
fn the_same_bits_on_any_number_of_threads() {
    let (one, three) = (
        draw(256, smeared, |_, _| 0.0, 1),
        draw(256, smeared, |_, _| 0.0, 3),
    );
    assert_eq!(one.after, three.after);
    assert_eq!(one.wet_after, three.wet_after);
}

/// Rasterizes the smeared stain as `draw` does and leaves its front to the shader: the
/// smeared image, the lifted one and the distance channel (a wet image of one channel),
/// with a texel `1/size` metres (UV = metres).
fn lifted(size: usize, threads: usize) -> (Images, Vec<f32>) {
    let mut img = draw(size, smeared, |_, _| 0.0, threads);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    img.after = img.before.clone();
    let mut distance = vec![f32::NAN; size * size];
    let texel = 1.0 / size as f32;
    pool.install(|| {
        lift(
            &img.fields,
            size,
            [texel, texel],
            Some(&mut img.after),
            Some((&mut distance, 1, 0)),
        );
    });
    (img, distance)
}

#[test]
fn left_to_the_shader_the_front_is_a_signed_distance_and_the_stain_its_plateau() {
    for size in [128, 256] {
        let (img, distance) = lifted(size, 2);
        let texel = 1.0 / size as f64;
        let mut near = 0;
        for (i, &d) in distance.iter().enumerate() {
            let (u, v) = (
                ((i % size) as f64 + 0.5) * texel,
                ((i / size) as f64 + 0.5) * texel,
            );
            let exact = R - (u - CENTRE[0]).hypot(v - CENTRE[1]);
            let zone = img.fields[FIELDS * i + 1];
            if zone == 0.0 {
                let away = if img.before[4 * i + 3] > 0.0 {
                    DISTANCE_LIMIT
                } else {
                    -DISTANCE_LIMIT
                };
                assert_eq!(d, away, "outside the zone at texel {i}");
                assert_eq!(&img.after[4 * i..4 * i + 4], &img.before[4 * i..4 * i + 4]);
            } else if exact.abs() < texel && zone == 1.0 {
                assert!(
                    (d as f64 - exact).abs() < 0.2 * texel,
                    "distance {d} against {exact} at texel {i} ({size} px)"
                );
                near += 1;
            }
            let t = &img.after[4 * i..4 * i + 4];
            if img.before[4 * i + 3] > 0.0 && zone == 1.0 {
                assert!((t[3] - 1.0).abs() < 1e-5, "lifted to the plateau: {}", t[3]);
            }
            for k in 0..3 {
                assert!((t[k] - COLOUR[k] * t[3]).abs() <= 1e-6, "the colour's hue");
            }
        }
        assert!(near > 100, "{near} texels near the front");
        // the stain as a shader draws it at the texel centres: L where D > 0
        let drawn: f64 = (0..size * size)
            .filter(|&i| distance[i] > 0.0)
            .map(|i| img.after[4 * i + 3] as f64)
            .sum();
        let smeared_mass: f64 = img.before.chunks(4).map(|t| t[3] as f64).sum();
        let exact = std::f64::consts::PI * R * R * (size * size) as f64;
        println!("{size} px: drawn {drawn:.1}, smeared {smeared_mass:.1}, πR² {exact:.1} texels");
        assert!((drawn / exact - 1.0).abs() < 0.01);
        assert!((drawn / smeared_mass - 1.0).abs() < 0.01);
    }
}

#[test]
fn left_to_the_shader_the_same_bits_on_any_number_of_threads() {
    let ((one, d1), (three, d3)) = (lifted(256, 1), lifted(256, 3));
    assert_eq!(one.after, three.after);
    assert_eq!(d1, d3);
}
