//! The stain simulator (seed chapter 4) on a deforming mesh, one concept per file:
//!
//! - [`simulate`]: [`Simulator`] and its parameters, the split step of §4.3 — body forces
//!   ([`forces`], §4.4), advection ([`advect`], §4.3.1–4.3.2, with the velocity extended
//!   over the dry cloth by [`extend`]), diffusion ([`diffuse`], §4.3.3–4.3.4) and
//!   stain–surface interactions ([`interact`], §4.5) — and, beside them, drips off a
//!   hanging hem ([`drip`]), gravity in the fibres' liquid ([`drain`]), the window's
//!   upkeep, liquid poured, splashes and initial velocities, and what is read out;
//! - `pool`: a spill laid as a pool of its own depth, its edge free of the mesh;
//! - [`window`]: the active region a frame works on, cut out of the cloth;
//! - `work` (the `roofline` feature): what each phase must move and compute at least, for
//!   the benchmarks;
//! - [`state`]: the per-vertex fields and the simulator's state;
//! - [`check`]: the checks of the parameters, shared by every part;
//! - [`DiffusionStepper`] ([`diffuse`]): the diffusion alone (the first slice, kept for the
//!   fabric experiments).

pub mod advect;
pub(crate) mod check;
pub(crate) mod detail;
pub(crate) mod diffuse;
pub(crate) mod drain;
pub(crate) mod drip;
pub mod extend;
pub(crate) mod forces;
pub(crate) mod interact;
pub(crate) mod irregular;
pub(crate) mod pool;
pub(crate) mod simulate;
pub(crate) mod state;
pub(crate) mod window;
#[cfg(feature = "roofline")]
pub(crate) mod work;

pub use detail::Detailed;
pub use diffuse::{
    Conductivity, DEFAULT_DIFFUSION, DiffusionStepper, MAX_PICARD, Wicking, WovenFaces,
};
pub use forces::Forces;
pub use interact::InteractionRates;
pub use irregular::Irregularity;
pub use simulate::{DEFAULT_SOLUTE_COLOR, FILM_CREEP, Profile, Simulator, StainParams};
pub use state::{Fields, Totals};
#[cfg(feature = "roofline")]
pub use work::{PhaseWork, TRANSCENDENTAL};
