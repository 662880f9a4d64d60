//! Meshes: the fixed connectivity of a cloth ([`Topology`]) and the quantities that change
//! with every frame of its motion ([`Geometry`]). Keeping them apart is what lets the
//! simulator build sparse patterns and symbolic factorizations once per bake.

pub(crate) mod frames;
pub mod geometry;
pub mod kabsch;
pub mod proximity;
pub(crate) mod rings;
pub(crate) mod topology;
pub(crate) mod transport;

pub use frames::VertexFrames;
pub use geometry::Geometry;
pub use kabsch::one_ring_rotations;
pub(crate) use rings::RingAdjacency;
pub use rings::{FanKind, OneRings, Wedge};
pub(crate) use topology::EdgeKind;
pub use topology::Topology;
pub use transport::Transport;
