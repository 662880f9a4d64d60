//! # madder — stain simulation on deforming cloth
//!
//! Pure Rust core (no Python) of the Madder Blender extension. The science is the
//! dissertation *Fluid animation on deforming surface meshes* (`shared/seed`); every module
//! doc cites the sections and equations it implements. The map, seed section by section:
//!
//! ## Chapter 2: homogenization — [`weave`]
//! | seed | what | where |
//! |---|---|---|
//! | §2.2, eq. 2.1–2.2 | a weave's rapidly varying tensor replaced by one effective tensor | [`weave`] (overview), [`weave::Tensor2`] |
//! | §2.2.1 | the input tensors: a tile of warp/weft/gap cells, pair coefficients, per-cell tensors | [`weave::Tile`], [`weave::PairCoefficients`], [`weave::cell_tensors`] |
//! | §2.2.2, eq. 2.4 | the periodic cell problem, P1 on the torus: rigorous upper and lower bounds | [`weave::Grid`], [`weave::Bounds`] (`weave/cell_problem.rs`) |
//! | §2.2.2, eq. 2.3 | the effective tensor: tile reduction, levels, primal–dual extrapolation; memoized | [`weave::homogenize()`], [`weave::homogenize_cached`] |
//!
//! ## Chapter 3: angle-based surface representation — [`angles`]
//! | seed | what | where |
//! |---|---|---|
//! | §3.3, eq. 3.1 | corner and signed dihedral angles of a manifold, oriented mesh | [`angles::AngleMesh::encode`] (`angles/encode.rs`) |
//! | §3.3.4 | preprocessing: clamp with ε = 0.02, corners rescaled to sum to π | `angles/local.rs` |
//! | §3.3.1, eq. 3.2, Figs. 3.1–3.2 | local four-vertex constructions, face frames, transition matrices | `angles/local.rs` |
//! | §3.3.1–§3.3.2, eq. 3.3 | the quadratic form, its lowest eigenvectors (shift-invert subspace iteration), voting with polar decomposition | [`angles::AngleMesh::reconstruct`] (`angles/spectral.rs`) |
//! | §3.3.3 | descent in the 12-D space with analytic angle derivatives | `angles/refine.rs` |
//! | §3.3, §3.4 | the sequential breadth-first construction (baseline) | [`angles::AngleMesh::sequential`] (`angles/sequential.rs`) |
//! | — | rigid placement and scale kept apart: a reference triangle | [`angles::Placement`] (`angles/place.rs`) |
//! | §3.1 (the proposed use) | a motion codec: quantized angles, closed-loop temporal prediction, range coding, `.madm` files | [`angles::MotionEncoder`], [`angles::MotionDecoder`] (`angles/codec/`) |
//!
//! ## Chapter 4: fluid simulation on a deforming surface — [`mesh`], [`ops`], [`stain`]
//! | seed | what | where |
//! |---|---|---|
//! | §4.3, eqs. 4.1–4.3, Fig. 1.3 | the split step: forces, advection, diffusion, interactions | [`stain::Simulator`] (`stain/simulate/`: a frame, the sub-step's phases, the read-outs), its state [`stain::Fields`] (`stain/state.rs`), the active region it steps (`stain/window.rs`), poured liquid and splashes (`stain/simulate/sources.rs`) |
//! | §4.3.1 | the fixed connectivity, and the one-ring fans the frames and the polar map walk | [`mesh::Topology`], [`mesh::OneRings`] and the adjacency `RingAdjacency` (`mesh/topology.rs`, `mesh/rings.rs`) |
//! | §4.3.1 | the vertex frames `F_i` | [`mesh::VertexFrames`] (`mesh/frames.rs`) |
//! | §4.3.1, eq. 4.4 | the geodesic polar map and the transport `R_ij` | [`mesh::Transport`] (`mesh/transport.rs`) |
//! | §4.3.1, eq. 4.5 | semi-Lagrangian velocity; finite-volume densities with cotan weights | [`stain::advect`] |
//! | §4.3.2 | momentum advection | [`stain::advect::UpwindPlan::momentum_velocity`] |
//! | §4.3.3 | per-frame geometry (lengths, areas, cotans), cotan stiffness, lumped mass | [`mesh::Geometry`], [`ops::cotan_stiffness`], [`ops::add_lumped_mass`] |
//! | §4.3.3 | implicit diffusion `(M + hL_S) σ' = M σ`, prefactored or warm-started CG | [`stain::DiffusionStepper`] (`stain/diffuse/`), [`ops::PrefactoredSpd`], [`ops::WarmCg`] (`ops/cg/`) |
//! | §4.3.3, eq. 4.6 | the Bochner (connection) Laplacian of the velocity | [`ops::BochnerSystem`] (`ops/bochner.rs`), restricted to the active region by [`ops::Restriction`] |
//! | §4.3.4 | anisotropic stiffness of a woven face, weft from the UVs | [`ops::weft_directions`], [`stain::Conductivity`] (`ops/aniso.rs`) |
//! | §4.4 | comoving–corotating frames by Kabsch, fictitious forces | [`mesh::kabsch`], [`stain::Forces`] (`stain/forces.rs`) |
//! | §4.5, eqs. 4.7–4.10 | absorption, adsorption, evaporation | [`stain::InteractionRates`] (`stain/interact.rs`) |
//! | §4.5, Fig. 4.6 | the look: saturation-dependent wicking (porous-medium law), solute carried by the solvent's flux, tide lines (a residual saturation pinning the wet edge, vapour-limited evaporation fastest there), an irregular fabric | [`stain::Wicking`] (`stain/diffuse/wicking.rs`), `carry_solute`, `residual_saturation`, `vapour_limited` in [`stain::StainParams`] (`stain/diffuse/solve.rs`, `stain/interact.rs`), [`stain::Irregularity`] (`stain/irregular.rs`) |
//!
//! Beyond the seed, for the same chapter: the velocity extended over the dry cloth
//! ([`stain::extend`]), the distance from a brush to the cloth ([`mesh::proximity`]), and
//! Detail: the simulation on the cloth's triangles split into 4^L
//! ([`mesh::Refinement`], [`stain::Detailed`]).
//!
//! ## Chapter 5: Lagrangian coherent structures — [`lcs`]
//! | seed | what | where |
//! |---|---|---|
//! | §5.2, §5.5.1 | particles traced through a time-dependent tangent velocity on a (deforming) mesh, RK4 with edge crossings | [`lcs::flow_map`] (`lcs/trace/`) |
//! | §5.2 | flow-map gradient, Cauchy–Green, FTLE `σ` | [`lcs::ftle()`] (`lcs/ftle.rs`) |
//! | §5.4, §5.5.2–§5.5.5, eqs. 5.3–5.4 | ridges: threshold, smoothing, Hessian, zero crossings, marching triangles, joining, cleanup | [`lcs::ridges()`] (`lcs/ridges.rs`) |
//!
//! ## Around the science
//! - [`io`]: the Madder cache file and the playback attributes read from it; PC2/MDD point
//!   caches (the Mesh Cache modifier's formats), so exported cloth bakes without a scene.
//! - [`error`]: one enum per kind of failure, each variant naming the element that failed.
//! - [`texture`]: per-vertex fields rasterized into UV space, padded past the UV islands,
//!   and written and read as OpenEXR images.
//! - [`rng`]: a seeded generator for splashes and randomized tests.
//!
//! Conventions: `f64` inside solves, `f32` for bulk arrays at the boundary, `u32` indices;
//! every loop that runs in parallel writes disjoint outputs, so results are bit-identical
//! whatever the number of threads.
//!
//! The public surface is what the binding (`rust/madder-py`), the tests, the benches and
//! the fuzz targets use; the rest is `pub(crate)`. The module docs still link the internal
//! modules and items they explain: `cargo doc --document-private-items` follows them.

#![warn(missing_docs)]
#![warn(unreachable_pub)]
#![allow(rustdoc::private_intra_doc_links)]

pub mod angles;
pub mod error;
pub mod io;
pub mod lcs;
pub mod mesh;
pub mod ops;
pub mod rng;
pub(crate) mod runs;
pub mod stain;
pub mod texture;
pub mod weave;

pub use error::{
    AngleError, CacheError, CodecError, Error, LcsError, MeshError, ParamError, SolveError,
    TextureError, WeaveError,
};
pub use io::point_cache::PointCacheError;
