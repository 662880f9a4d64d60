//! UV textures of per-vertex fields: rasterization, padding, OpenEXR output (issue 12).
//!
//! The stain lives on the vertices of a (possibly refined) cloth mesh; a renderer wants it
//! as an image in the mesh's UV space, so that the stain's detail no longer depends on the
//! cloth's vertex spacing. Three steps, one file each:
//!
//! 1. [`rasterize`] (`raster.rs`): every texel whose centre lies in a triangle of the UV
//!    layout gets the triangle's **barycentric interpolation** of its three vertex values.
//!    With the triangle's corners `a, b, c` in UV and the texel centre
//!    `s = ((x + ½)/size, (y + ½)/size)`,
//!    `λ_b = ((s − a) × (c − a)) / ((b − a) × (c − a))`,
//!    `λ_c = ((b − a) × (s − a)) / ((b − a) × (c − a))`, `λ_a = 1 − λ_b − λ_c`, and the
//!    texel is `λ_a f_a + λ_b f_b + λ_c f_c`: the field, linear over the triangle, sampled
//!    at the centre. Coverage is exact and watertight: a centre on an edge or vertex shared
//!    by several triangles belongs to exactly one of them (the bottom-left rule, on UVs
//!    snapped to 1/256 texel); a centre inside two triangles that do not merely touch
//!    (overlapping UV islands, a fold) is counted in [`Raster::overlapping`] so that the
//!    add-on can warn.
//! 2. [`pad`](mod@pad) (`pad.rs`): each UV island grows outward by a few texels, each new texel the
//!    mean of its covered 8-neighbours, so that bilinear filtering and mip-mapping read
//!    the island's own values across its border and UV seams do not show.
//! 3. [`write_exr`] (`exr.rs`): a half-float OpenEXR file, written atomically.
//!
//! Optionally, [`rasterize_with`] adds the weave's fine scale back while it writes each
//! texel (`weave.rs`: the two-scale expansion `σ0 + ε χ(x/ε)·∇σ0` and the threads' uptake,
//! issue 13 part 4; see [`weave`] for the math and why it runs inside the rasterizer),
//! and [`clip()`] (`clip.rs`) limits the finished image to what the shader reads.
//! [`sharpen`] (`outline.rs`) then draws the stain's outline within a texel where the
//! simulation's front is a few cells wide (issue 34 §2; see [`outline`] for the math), or
//! [`lift`] leaves it to the shader, at the pixel.
//!
//! ## Image layout
//! `size × size × C` `f32`, row-major, **row 0 at the bottom** (`v ∈ [0, 1/size)`), as
//! Blender's `Image.pixels`; texel `(x, y)` covers `[x/size, (x+1)/size) × [y/size,
//! (y+1)/size)` and is sampled at its centre. UVs outside `[0, 1]²` are allowed: what
//! lies outside the image is clipped (no wrapping).
//!
//! ## Integrals over the surface
//! A texel stands for `1/size²` of UV area; triangle `t` maps UV area to surface area by
//! its ratio `r_t = A_world(t) / A_uv(t)`. So `Σ_texels f · r_t / size²` approximates
//! `∫_surface f dA` (to the texels cut by the islands' outlines: an error of the order of
//! the UV perimeter over `size`). To rasterize a per-face quantity such as `f · r_t`, give
//! each triangle its own three vertices (`faces[t] = [3t, 3t+1, 3t+2]`, values per
//! corner): the rasterizer interpolates whatever the face's vertices hold.
//!
//! ## Parallelism
//! [`rasterize`] and [`pad`](fn@pad) run on the current rayon pool (install a pool to cap the
//! threads) and give the same bits on any number of threads; see each module.

pub mod clip;
pub(crate) mod coverage;
pub mod exr;
pub mod outline;
pub mod pad;
pub mod raster;
pub mod weave;

pub use self::clip::{Clip, clip};
pub use self::exr::{Compression, ExrImage, read_exr, write_exr, write_exr_with};
pub use crate::error::TextureError;
pub use outline::{Outline, lift, outline_fields, sharpen};
pub use pad::{DEFAULT_PADDING, pad, pad_to};
pub use raster::{
    MAX_CHANNELS, MAX_SIZE, Raster, rasterize, rasterize_into, rasterize_to, rasterize_to_with,
    rasterize_with,
};
pub use weave::{NO_WEAVE, WeaveDetail};
