//! Meshes: the fixed connectivity of a cloth ([`Topology`]) and the quantities that change
//! with every frame of its motion ([`Geometry`]). Keeping them apart is what lets the
//! simulator build sparse patterns and symbolic factorizations once per bake.
//!
//! Files by lifetime:
//! - built once per mesh (topology): [`topology`] ([`Topology`]), [`rings`] (the ordered
//!   one-ring fans [`OneRings`] of §4.3.1 and the adjacency `RingAdjacency` the rotations
//!   of §4.4 sum over);
//! - per frame: [`geometry`] (intrinsic lengths, areas, cotans, §4.3.3), [`frames`] (the
//!   vertex frames `F_i`, §4.3.1), [`transport`] (the transport `R_ij` between them,
//!   eq. 4.4), [`kabsch`] (the one-ring rotations `U_i`, §4.4);
//! - per Detail level: [`refine`] (the cloth's triangles split into 4^L, [`Refinement`]:
//!   the fine topology once, the fine positions every frame);
//! - per query: [`proximity`] (a brush's distance to the cloth).

pub(crate) mod frames;
pub mod geometry;
pub mod kabsch;
pub mod proximity;
pub(crate) mod refine;
pub(crate) mod rings;
pub(crate) mod topology;
pub(crate) mod transport;

pub use frames::VertexFrames;
pub use geometry::Geometry;
pub use kabsch::one_ring_rotations;
pub use refine::{MAX_FINE_VERTICES, MAX_LEVEL, Refinement};
pub use rings::{FanKind, OneRings, Wedge};
pub use topology::{EdgeKind, Topology};
pub use transport::Transport;

pub(crate) use rings::RingAdjacency;
