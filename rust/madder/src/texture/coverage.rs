//! The limits on an image's shape and the values of the coverage mask: the data the
//! rasterizer ([`raster`](mod@super::raster)), the weave detail, the padding and the
//! OpenEXR I/O share.

/// The largest image side accepted: 16384 texels (a 16384² RGBA float image is 4 GiB).
pub const MAX_SIZE: usize = 16384;

/// The most channels a texture may have (an image holds `size² × channels` floats).
pub const MAX_CHANNELS: usize = 64;

/// Coverage mask value: no triangle covers the texel centre (and no padding reached it).
pub const EMPTY: u8 = 0;
/// Coverage mask value: exactly one triangle covers the texel centre.
pub const INSIDE: u8 = 1;
/// Coverage mask value: two or more triangles cover the texel centre (overlapping UVs); the
/// texel holds the value of the first of them in index order.
pub const OVERLAP: u8 = 2;
/// Coverage mask value: the texel lies outside every triangle and took its value from
/// [`pad`](fn@super::pad).
pub const PADDED: u8 = 3;

/// Coverage mask value while a woven triangle is being scanned: the texels it covers first,
/// waiting for [`super::weave::Texels::shade`], which makes them [`INSIDE`]. Never left in
/// a finished raster.
pub(crate) const CLAIMED: u8 = u8::MAX;
