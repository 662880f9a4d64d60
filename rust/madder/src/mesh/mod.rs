//! Meshes: the fixed connectivity of a cloth ([`Topology`]) and the quantities that change
//! with every frame of its motion ([`Geometry`]). Keeping them apart is what lets the
//! simulator build sparse patterns and symbolic factorizations once per bake.

pub mod frames;
pub mod geometry;
pub mod kabsch;
pub mod proximity;
pub mod refine;
pub mod topology;

pub use frames::{Connection, FanKind, OneRings, VertexFrames, Wedge};
pub use geometry::Geometry;
pub use kabsch::{RingAdjacency, one_ring_rotations};
pub use refine::Refinement;
pub use topology::{EdgeKind, Topology};
