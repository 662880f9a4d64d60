//! The stain simulator (seed chapter 4): the split step of §4.3 — body forces (§4.4),
//! advection (§4.3.1–4.3.2), diffusion (§4.3.3–4.3.4) and stain–surface interactions
//! (§4.5) — on a deforming mesh. [`Simulator`] runs it; [`DiffusionStepper`] is the
//! diffusion alone (the first slice, kept for the fabric experiments).

pub mod advect;
pub mod diffuse;
pub mod extend;
pub mod forces;
pub mod interact;
pub mod simulate;
pub mod state;
pub mod window;

pub use diffuse::{Conductivity, DiffusionStepper, WovenFaces};
pub use forces::Forces;
pub use interact::InteractionRates;
pub use simulate::{Profile, Simulator, StainParams};
pub use state::{Fields, Totals};
