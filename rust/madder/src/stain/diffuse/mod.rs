//! Implicit diffusion of a density on a deforming mesh (seed §4.3.3–4.3.4).
//!
//! The density `σ` is per unit area and lives on the vertices; the stain *mass* of vertex
//! `i` is `m_i = A_i σ_i` with `A_i` the lumped area. Liquid soaked into cloth moves with
//! the cloth, so when the mesh deforms from one step to the next the masses are carried
//! by the vertices and the density is re-read on the new areas. One backward-Euler step of
//! `σ̇ = ∇·(D ∇σ)` over `h` on the geometry at the end of the step is
//!
//! ```text
//! (M + h D K) σ' = m,        m_i = A_i^old σ_i,
//! ```
//!
//! with `M` the lumped mass and `K` the stiffness of the new geometry: `D` times the cotan
//! stiffness for an isotropic [`Conductivity`], or the anisotropic stiffness of a woven
//! cloth, each face with its fabric tensor in the basis of its weft, the weft recomputed
//! from the UV layout on the deformed face every step ([`crate::ops::aniso`]). For
//! `(M + hDK)` the `D` is inside `K`. Because `1ᵀK = 0`, `Σ_i A_i^new σ'_i = Σ_i m_i`: mass is
//! conserved exactly, up to the rounding of the solve, on any mesh and any motion.
//! The scheme is unconditionally stable, so `h` can be a whole frame; sub-steps (with
//! positions interpolated linearly between frames) follow fast deformation more closely.
//!
//! The sparsity pattern of `M + hDK` is fixed by the topology: the stepper does the
//! symbolic Cholesky analysis once and only refactorizes numerically each step.
//!
//! ## Colour
//! Sources of different colours mix. Diffusion is linear, so the *colour mass* `σ·c`
//! (`c` = RGB of the liquid) obeys the same equation as `σ`; the stepper carries it as
//! three more right-hand sides of the same factorized system, and the colour of the stain
//! is `(σ·c)/σ`. This is exact mixing at the cost of three triangular solves, not three
//! more factorizations.
//!
//! A vertex with no incident face has no area and no stiffness; its row would be zero.
//! We put `1` on its diagonal and its own density on the right-hand side, so it keeps its
//! value and carries no mass.
//!
//! ## In the simulator: the restricted systems
//! The simulator ([`super::simulate`]) solves `(M + h K_A) σ' = m` for every flowing field
//! and the velocity's eq. 4.6 on its window's active vertices only, `K_A` the restriction
//! of the stiffness with a Neumann boundary ([`crate::ops::restrict`]), by warm-started
//! CG ([`crate::ops::WarmCg`]): `diffuse_densities` and `diffuse_velocity`. The stepper
//! above factorizes the whole mesh instead; both take the fabric's stiffness from
//! [`Conductivity::stiffness`].
//!
//! Per sub-step the simulator does no more than the region needs (issue 16): the
//! restricted values are assembled on the faces with an edge inside the region, in the
//! whole mesh's face order, so they are the restriction of the whole window's stiffness
//! to the last bit without forming it ([`Conductivity::restricted_values`]; a woven
//! cloth, and the carried solute, which reads the fluxes of the whole window, still
//! assemble it). The densities are solved with IC(0)-preconditioned CG. The velocity's
//! Bochner system is never expanded into its `2×2` blocks: the scalar values and the
//! edges' rotations are its operator, with symmetric Gauss–Seidel on the blocks as the
//! preconditioner ([`WarmCg::solve_rotated`], module doc of `ops/cg/rotated.rs`, "Rotated
//! blocks"), so no block assembly, gather or factorization remains.
//!
//! ## In the simulator: tolerances
//! The fields are solved together by [`WarmCg::solve_chained`] (each column's warm start
//! first corrected along the previous column's correction: the colour masses, multiples
//! of the solute, then cost nothing). Each solve stops at a relative residual
//! `‖m − (M + hK)σ‖ ≤ τ‖m‖`, [`DENSITY_TOLERANCE`] `τ = 10⁻⁶` for the densities and
//! [`VELOCITY_TOLERANCE`] `10⁻⁵` for the velocity. The totals do not depend on `τ`: they
//! are restored to rounding after every solve (next section). Only the profile does, and
//! since the lumped mass dominates `M + hK` at cloth steps, its relative error is of order
//! `τ`. Below `τ` nothing a picture shows moves: an 8-bit channel resolves `1/255 ≈
//! 3.9·10⁻³` of a field's range. Measured on the 100k Blender flag of
//! `tests/bench/bench_dynamic_paint.py` (positions exported from its cloth bake, 11
//! frames, 20 sub-steps, the bench's pour and colour) against the former 10⁻⁹ / 10⁻⁸,
//! the largest difference of any vertex's wetness or stain over all frames, relative to
//! the peak:
//!
//! | density τ, velocity τ | wetness | stain | density it./sub-step | velocity it. |
//! |---|---|---|---|---|
//! | 1e-9, 1e-8, columns side by side (before; the reference) | — | — | 35.5 | 4.7 |
//! | 1e-9, 1e-8, chained | 0 | 7.5e-8 | 11.4 | 4.7 |
//! | 1e-7, 1e-7 | 1.1e-6 | 1.1e-6 | 7.5 | 4.0 |
//! | **1e-6, 1e-5 (default)** | 6.2e-6 | 4.7e-6 | 5.8 | 2.5 |
//! | 1e-5, 1e-5 | 1.5e-5 | 1.4e-5 | 4.3 | 2.5 |
//! | 1e-4, 1e-4 | 2.1e-4 | 1.8e-4 | 2.6 | 1.9 |
//!
//! (The second row's difference is the chained solve's alone, at the f32 read-out's
//! resolution. The rows other than the default were measured before the chained solve
//! tried the right-hand sides' ratio first; the default row, measured again with it, came
//! out the same.) The error grows about linearly with `τ`, and over the 11 frames it
//! does not build up (last frame alone: 7.2e-6 / 5.4e-6 of that frame's peaks; L2 over
//! all frames 1.4e-6 / 1.1e-6); `10⁻⁶` keeps it 600 times under an 8-bit step and 16 times under the 10⁻⁴ this
//! was asked to stay under, and every validation test (Barenblatt, tide lines, mass,
//! momentum, the rest in `tests/`) passes against its exact reference unchanged. Looser
//! gains little more: at `10⁻⁵` the iterations fall by another 1.5 per sub-step. The
//! simulate benchmark prints the same comparison on its synthetic flag.
//!
//! The velocity's preconditioner went from IC(0) on the expanded blocks to symmetric
//! Gauss–Seidel on the rotated blocks (the densities' solves are unchanged, bit for bit),
//! at the same `10⁻⁵` and the same iteration count on the synthetic flags (1.0 per
//! sub-step). Against the IC(0) build, on the simulate benchmark's synthetic flags
//! (`MADDER_BENCH_DUMP`), the solute density and the wetness differ by at most 9.8e-10 of
//! their peaks at frame 48 of the 10k flag (L2 8.5e-10 of the field's) and 2.7e-8 at
//! frame 12, the last, of the 100k flag (L2 2.6e-8). Jacobi on the rotated blocks was
//! tried: at `10⁻⁵` its one-iteration answers differ from IC(0)'s by ~0.5 % of the
//! viscous change, which moved a window against the whole mesh by 1.1e-9 of the peak in
//! `tests/simulator.rs` (its bound is 1e-9; SGS: 8.8e-12, IC(0): 3.2e-12), and at the
//! `10⁻⁷` that passes it took five times the iterations.
//!
//! ## In the simulator: conservation and sign (why the clamps are safe)
//! The system conserves mass exactly (`1ᵀ(M + hK) = 1ᵀM`) and CG to its tolerance; after
//! each solve the field is rescaled by `Σm / Σm'` so that the total is restored to
//! rounding (a relative correction of the order of the CG tolerance, proportional, so it
//! keeps zeros and signs).
//! The FEM stiffness is not an M-matrix on obtuse triangles or with strongly anisotropic
//! tensors, so implicit diffusion can leave a tiny negative mass just outside a sharp
//! front. Those deficits are filled from the vertex's positive neighbours, in proportion
//! to their masses (a conservative local redistribution), and anything left — only if
//! the neighbours hold less than the deficit — from all positive vertices in proportion.
//! So every density stays `≥ 0` and every total is kept. Advection is non-negative and
//! conservative by construction ([`super::advect`]); so are the interactions.
//!
//! ## Tide lines: the solute carried by the solvent (issue 13 §2)
//! By default the dissolved solute diffuses with the solvent's own operator. Its flux is
//! then `−K∇s = c(−K∇f) − f K∇c`: the solvent's flux carrying the concentration `c = s/f`,
//! plus a diffusion of the concentration itself at the solvent's rate, far faster than
//! any molecular diffusion (~1e-9 m²/s against the fabric's ~1e-4). With `carry_solute`
//! the solute moves with the solvent's flux only: the free solvent and the solvent in
//! the fibres are both solved (the fibres' liquid wicks too: in a fabric the absorbed
//! liquid is what moves by capillarity), and the dissolved and absorbed solute follow
//! their fluxes by an implicit upwind sweep ([`carry_with_solvent`]) that keeps a uniform
//! solution uniform to rounding. The molecular diffusion is left out: the upwind
//! transport's own numerical diffusion is larger.
//!
//! That alone leaves no ring: the fibres' liquid keeps creeping into the dry cloth, so
//! the wet edge is never pinned and recedes as it dries. Deegan's mechanism needs a
//! pinned edge where the evaporation is fastest. **Residual saturation** `θ_r`
//! (`StainParams::residual_saturation`): liquid held below `θ_r σ_sat` is immobile
//! (irreducible saturation: it sits in the fibres' smallest pores), and the fibres'
//! liquid moves across a face only when all three corners hold more than that. The
//! fibres' liquid is then solved on its own operator, every face scaled by 0 or 1 (times
//! the wicking and irregularity factors), a second CG solve per sub-step, and the
//! absorbed solute follows *its* fluxes. In the continuum a front of a liquid whose
//! diffusivity vanishes below `θ_r` cannot advance into dry cloth at all (filling the step
//! `θ_r` needs a finite flux, and the flux at the front is zero), so only the free liquid,
//! absorbed where it arrives, decides how far a spill gets; once it is used up, the edge
//! stays. With the evaporation fastest at that edge (vapour-limited,
//! [`super::interact`]) the fibres' liquid flows outward down its saturation gradient and
//! carries its solute there; when the saturation falls to `θ_r` the rest dries in place.
//! Exact for a uniform solution with the pinned operator too (`tests/tide_lines.rs`).
//!
//! **The rim's width** (issue 34 §3). The upwind sweep's only dispersion is its own,
//! half an edge, so the ring it leaves is one cell wide at any spacing: its mass
//! converges, its width does not. A solute carried through a porous medium spreads along
//! the flow by mechanical dispersion, `D = α_L |u|` with the longitudinal dispersivity
//! `α_L` a length of the medium (Bear 1972, *Dynamics of Fluids in Porous Media*, ch. 10),
//! and against a pinned edge the steady balance of the outward flux `u c` and the
//! dispersive return `α_L |u| ∂c/∂x` gives `c ∝ exp(x/α_L)` whatever the speed: a ring
//! `α_L ln 2` wide at half its height. `StainParams::dispersivity` adds it to the sweep
//! as symmetric couplings `α_ab |F_ab|/ℓ_ab` on the edges that carry solvent, minus the
//! upwind's own half edge ([`carry_with_solvent`]). Measured (`tests/rims.rs`, 0.3 kg/m²
//! within 1 cm, `α_L` = 3.5 mm, meshes of 2/3 and 1/3 mm): Coffee rim/centre 2.52 / 2.78,
//! ring 2.29 / 2.16 mm (3.4 / 6.5 cells, 6 % apart); Red Wine (binding over minutes)
//! 1.30 / 1.42, 2.30 / 2.21 mm; Water (1e-3 solute) 3.93 / 4.34,
//! 2.33 / 2.18 mm. `StainParams::carried_fraction` `φ < 1` carries only that share of
//! the dissolved solute at each transfer: a retardation, not a return flow of the drying
//! alone (wine with `φ = 0.5` dried with a dark centre, rim/centre 0.57).
//!
//! For the velocity's Bochner Laplacian the edge weights are clamped at zero: with
//! negative (non-Delaunay) weights `K_∇` can be indefinite ([`crate::ops::bochner`]),
//! and the velocity diffusion is a viscosity, whose job is smoothing; clamping makes it
//! positive semi-definite on every mesh (the scalar diffusion of the densities keeps the
//! consistent weights).
//!

//!
//! [`WarmCg::solve_chained`]: crate::ops::WarmCg::solve_chained
//! [`WarmCg::solve_rotated`]: crate::ops::WarmCg::solve_rotated
//! [`carry_with_solvent`]: solve::carry_with_solvent
//!
//! ## Files
//! The saturation-dependent rate (`wicking.rs`), the fabric's stiffness, isotropic or
//! woven (`conductivity.rs`), the whole-mesh stepper (`stepper.rs`), and the simulator's
//! restricted solves with the carried solute and the negative-mass repair (`solve.rs`).

mod conductivity;
mod solve;
mod stepper;
mod wicking;

pub use conductivity::{Conductivity, WovenFaces};
pub(super) use solve::{
    Carry, DensityWork, Ops, SoluteMotion, diffuse_densities, diffuse_velocity, solvers,
};
pub use stepper::DiffusionStepper;
pub use wicking::{MAX_PICARD, Wicking};

/// Relative residual `‖m − (M + hK)σ‖ / ‖m‖` at which the density solves stop (module doc,
/// "Tolerances"). The total is restored exactly after each solve, so this only sets the
/// accuracy of the profile; `M` dominates the system, so the relative error of `σ` is of
/// the same order. On the 100k Blender flag over 11 frames the wetness and stain differ
/// from a 1e-9/1e-8 solve by at most 6.2e-6 / 4.7e-6 of their peaks (with 1e-8 velocity),
/// 40× below an 8-bit step (3.9e-3), at 5.8 instead of 11.4 iterations per sub-step (all
/// fields, chained solves). Every validation test passes at this tolerance.
pub(crate) const DENSITY_TOLERANCE: f64 = 1e-6;

/// Relative residual of the velocity's (Bochner) solve. The viscosity only smooths the
/// velocity, which then moves the liquid over one step; 1e-5 of a speed of 0.2 m/s is
/// 2 µm/s, and measured on the flag it moves the densities by less than the density
/// tolerance does (module doc, "Tolerances"). Measured with IC(0); the block
/// Gauss–Seidel that replaced it takes the same iterations here and moves the outputs by
/// at most 2.7e-8 of their peaks (module doc).
pub(crate) const VELOCITY_TOLERANCE: f64 = 1e-5;

/// The default diffusion coefficient of the densities, m²/s (the add-on's and the Python
/// simulator's default rate): wicking in cotton, whose front advances about a centimetre
/// in the first second (`D ≈ L²/2t`).
pub const DEFAULT_DIFFUSION: f64 = 2e-4;
