//! Discrete operators on a mesh with fixed topology and per-frame geometry (seed §4.3.3).
//!
//! Global operators live on a [`VertexPattern`]: the lower triangle (diagonal included) of
//! the `N×N` vertex–vertex sparsity pattern, fixed for the whole bake. An operator is a
//! vector of values on that pattern, so a time-stepper rebuilds only values every frame and
//! the sparse Cholesky factorization ([`PrefactoredSpd`]) reuses its symbolic analysis.
//! A [`Restriction`] is such an operator cut down to a set of vertices (the simulator's
//! active region) with a no-flux diagonal; [`connection`] and [`restrict`] expand scalar
//! operators into the `2×2` blocks of the connection Laplacian (eq. 4.6) the same way.

pub mod aniso;
pub mod cg;
pub mod connection;
pub mod cotan;
pub mod pattern;
pub mod restrict;
pub mod solve;

pub use aniso::{
    Tensor2, anisotropic_stiffness, anisotropic_stiffness_scaled, weft_angles, weft_directions,
};
pub use cg::WarmCg;
pub use connection::{
    BochnerPattern, BochnerSystem, add_lumped_mass_blocks, bochner_stiffness, diffuse_tangent_field,
};
pub use cotan::{add_lumped_mass, cotan_stiffness};
pub use pattern::VertexPattern;
pub use restrict::{CscPattern, Restriction, block_pattern, block_values};
pub use solve::{LowerCsc, PrefactoredSpd, solve_spd};
