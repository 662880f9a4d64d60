//! # madder — stain simulation on deforming cloth
//!
//! Pure Rust core (no Python) of the Madder Blender extension. The science follows the
//! dissertation *Fluid animation on deforming surface meshes* (`shared/seed`), one module per
//! seed section:
//!
//! - [`mesh`]: fixed triangle topology and the per-frame geometry of a deforming mesh.
//! - [`ops`]: discrete operators on that geometry (cotan stiffness, lumped mass, §4.3.3)
//!   and a prefactored sparse SPD solver that reuses its symbolic analysis across frames.
//! - [`stain`]: the stain simulator (chapter 4: the split step of §4.3).
//! - [`weave`]: weave patterns (§2.2.1) and their homogenization into one effective 2×2
//!   diffusion tensor per fabric (§2.2.2, eqs. 2.3–2.4).
//! - [`io`]: the Madder cache file, and PC2/MDD point caches (the Mesh Cache modifier's
//!   formats) read and written directly, so exported cloth bakes without a scene.
//! - [`texture`]: per-vertex fields rasterized into UV space, padded past the UV islands,
//!   and written as OpenEXR images.
//!
//! Conventions: `f64` inside solves, `f32` for bulk arrays at the boundary, `u32` indices;
//! every loop that runs in parallel writes disjoint outputs, so results are bit-identical
//! whatever the number of threads.

pub mod error;
pub mod io;
pub mod mesh;
pub mod ops;
pub mod rng;
pub mod stain;
pub mod texture;
pub mod weave;

pub use error::{CacheError, Error, MeshError, ParamError, Result, SolveError, WeaveError};
