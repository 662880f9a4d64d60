//! Discrete operators on a mesh with fixed topology and per-frame geometry (seed §4.3.3).
//!
//! Global operators live on a [`VertexPattern`]: the lower triangle (diagonal included) of
//! the `N×N` vertex–vertex sparsity pattern, fixed for the whole bake. An operator is a
//! vector of values on that pattern, so a time-stepper rebuilds only values every frame and
//! the sparse Cholesky factorization ([`PrefactoredSpd`]) reuses its symbolic analysis.
//! A [`Restriction`] is such an operator cut down to a set of vertices (the simulator's
//! active region) with a no-flux diagonal; [`bochner`] and [`restrict`] expand scalar
//! operators into the `2×2` blocks of the Bochner (connection) Laplacian (eq. 4.6) the
//! same way. One file per operator: [`cotan`] (§4.3.3), [`aniso`] (§4.3.4), [`bochner`]
//! (eq. 4.6), [`restrict`]; the solvers in [`solve`] (prefactored Cholesky) and [`cg`]
//! (warm-started CG).

pub(crate) mod aniso;
pub(crate) mod bochner;
pub mod cg;
pub(crate) mod cotan;
pub(crate) mod pattern;
pub(crate) mod restrict;
pub(crate) mod solve;

pub use aniso::{
    DEGENERATE_UV_REL, anisotropic_stiffness, anisotropic_stiffness_scaled, weft_angles,
    weft_directions,
};
pub use bochner::{
    BochnerPattern, BochnerSystem, add_lumped_mass_blocks, bochner_stiffness, diffuse_tangent_field,
};
pub use cg::WarmCg;
pub use cotan::{add_lumped_mass, cotan_stiffness};
pub use pattern::VertexPattern;
pub use restrict::{CscPattern, Restriction};
pub use solve::{LowerCsc, PrefactoredSpd, solve_spd};
