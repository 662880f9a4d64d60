//! Files: the Madder bake cache (and the playback attributes computed from one of its
//! frames), and the PC2/MDD point caches of Blender's Mesh Cache modifier (positions of a
//! deforming mesh, read per frame).

pub(crate) mod attributes;
pub mod cache;
pub mod point_cache;

pub use attributes::EXCESS_RANGE;
