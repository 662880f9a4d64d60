//! The stain simulator (seed chapter 4). This first slice is the implicit diffusion of a
//! density on a deforming mesh (§4.3.3); advection, body forces and interactions
//! (§4.3.1, §4.4, §4.5) come with the full simulator.

pub mod diffuse;

pub use diffuse::{Conductivity, DiffusionStepper, WovenFaces};
