//! Meshes: the fixed connectivity of a cloth ([`Topology`]) and the quantities that change
//! with every frame of its motion ([`Geometry`]). Keeping them apart is what lets the
//! simulator build sparse patterns and symbolic factorizations once per bake.

pub mod geometry;
pub mod topology;

pub use geometry::Geometry;
pub use topology::{EdgeKind, Topology};
