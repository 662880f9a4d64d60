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
//! preconditioner ([`WarmCg::solve_rotated`], module doc of `ops/cg.rs`, "Rotated
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
//! For the velocity's Bochner Laplacian the edge weights are clamped at zero: with
//! negative (non-Delaunay) weights `K_∇` can be indefinite ([`crate::ops::bochner`]),
//! and the velocity diffusion is a viscosity, whose job is smoothing; clamping makes it
//! positive semi-definite on every mesh (the scalar diffusion of the densities keeps the
//! consistent weights).
//!

use faer::Par;
use glam::{DVec2, DVec3};

use super::check::check_range;
use super::state::{Fields, merge_rgb, split_rgb};
use crate::error::{Error, ParamError};
use crate::mesh::geometry::check_positions;
use crate::mesh::{Geometry, RingAdjacency, Topology, Transport};
use crate::ops::cg::Preconditioner;
use crate::ops::cotan::assemble_face_weights;
use crate::ops::{
    CscPattern, PrefactoredSpd, Restriction, VertexPattern, WarmCg, add_lumped_mass,
    anisotropic_stiffness, anisotropic_stiffness_scaled, cotan_stiffness, weft_angles,
};
use crate::weave::Tensor2;

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

/// Wicking (issue 13): a fabric draws liquid in faster where it is wetter, so the rate of
/// the density diffusion grows with the saturation `θ`,
///
/// ```text
/// D(θ) = D₀ θⁿ,    θ = min(σ_liquid / σ_w, 1),
/// ```
///
/// a porous-medium (Richards-type) law: `σ̇ = ∇·(D₀ θⁿ ∇σ)` has a front of finite speed
/// where the liquid meets dry cloth, instead of the Gaussian tail of linear diffusion.
/// `σ_liquid` is the free plus absorbed solvent density, `σ_w` [`Wicking::density`] (θ
/// stops at 1: a puddle above it spreads at `D₀`, and runs by the flow).
///
/// Discretized per face: face `T` diffuses at `D₀ g_T` with `g_T` the mean of `θ_iⁿ` over
/// its corners (the P1 stiffness with a piecewise-constant coefficient), so a face with
/// one wet corner conducts and the front moves into the next ring. The coefficient is
/// **lagged**: taken from the densities at the start of the solve, one linear solve per
/// sub-step as without wicking (the cost of a step stays that of the linear diffusion plus
/// the per-face factors). Lagging errs by `O(h)` in time; Picard iterations would remove
/// it at one more solve each, and on the Barenblatt test the lagged scheme is already
/// within the test's 3 % at the simulator's steps (`tests/wicking.rs`). The system stays
/// symmetric positive definite and conservative (`1ᵀK = 0` face by face, whatever the
/// factors), so mass is exact and the negative-mass repair keeps every density ≥ 0.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Wicking {
    /// `n ≥ 0`; 0 is a constant rate (wicking off: the linear diffusion, bit for bit).
    pub exponent: f64,
    /// `σ_w`, kg/m²: the liquid density at which the rate reaches the fabric's `D₀`.
    pub density: f64,
}

impl Default for Wicking {
    fn default() -> Self {
        Self {
            exponent: 0.0,
            // the default fibres' saturation ([`super::InteractionRates`])
            density: 0.1,
        }
    }
}

impl Wicking {
    /// Whether the rate depends on the saturation at all.
    pub fn is_on(&self) -> bool {
        self.exponent > 0.0
    }

    /// Checks the exponent (finite, 0 to 8) and the density (finite, > 0).
    pub fn validate(&self) -> Result<(), ParamError> {
        check_range(
            "wicking exponent",
            self.exponent,
            (0.0..=8.0).contains(&self.exponent),
            "from 0 to 8",
        )?;
        check_range(
            "wicking density",
            self.density,
            self.density > 0.0,
            "finite and > 0",
        )
    }

    /// The factor `g_T` of every face of `topology` from the liquid densities of its
    /// vertices (module doc of [`Wicking`]).
    pub fn face_factors(&self, topology: &Topology, liquid_density: &[f64]) -> Vec<f64> {
        let theta: Vec<f64> = liquid_density
            .iter()
            .map(|&s| (s / self.density).clamp(0.0, 1.0).powf(self.exponent))
            .collect();
        super::irregular::face_means(topology, &theta)
    }
}

/// How fast the stain diffuses, and in which directions.
#[derive(Debug, Clone, PartialEq)]
pub enum Conductivity {
    /// The same coefficient `D` (m²/s) in every direction.
    Isotropic(f64),
    /// A woven cloth: per face, a tensor (m²/s) in the face's (weft, warp) basis.
    Woven(WovenFaces),
}

impl Default for Conductivity {
    /// Isotropic at [`DEFAULT_DIFFUSION`].
    fn default() -> Self {
        Self::Isotropic(DEFAULT_DIFFUSION)
    }
}

/// Per-face fabric data of a woven cloth.
#[derive(Debug, Clone, PartialEq)]
pub struct WovenFaces {
    /// `[s11, s12, s22]` in the (weft, warp) basis, m²/s; symmetric positive semi-definite.
    pub tensor: Vec<Tensor2>,
    /// UV of each face's three corners; the weft is the UV `u` axis.
    pub uv: Vec<[[f64; 2]; 3]>,
    /// Angle (radians) added to the weft of each face (a fabric cut on the bias).
    pub angle: Vec<f64>,
}

impl Conductivity {
    /// The stiffness `scale · K_S` on `pattern` for this geometry: `D` times the cotan
    /// stiffness, or the anisotropic stiffness with the weft recomputed from the UVs on
    /// the deformed faces; with `face_scale`, face `f`'s rate (or tensor) times
    /// `face_scale[f]` (the wicking factor of [`Wicking`]).
    pub(crate) fn stiffness(
        &self,
        topology: &Topology,
        geometry: &Geometry,
        pattern: &VertexPattern,
        scale: f64,
        face_scale: Option<&[f64]>,
    ) -> Vec<f64> {
        match (self, face_scale) {
            (Conductivity::Isotropic(d), None) => {
                cotan_stiffness(topology, geometry, pattern, scale * d)
            }
            (Conductivity::Isotropic(d), Some(g)) => {
                assemble_face_weights(topology, pattern, |f| {
                    geometry.face_cot[f].map(|c| -0.5 * scale * d * g[f] * c)
                })
            }
            (Conductivity::Woven(w), g) => {
                let (angle, _) = weft_angles(topology, geometry, &w.uv, &w.angle);
                match g {
                    None => {
                        anisotropic_stiffness(topology, geometry, pattern, &angle, &w.tensor, scale)
                    }
                    Some(g) => anisotropic_stiffness_scaled(
                        topology, geometry, pattern, &angle, &w.tensor, scale, g,
                    ),
                }
            }
        }
    }

    /// `M + scale · K_S` restricted to `region` ([`Restriction::scalar_values`] of
    /// [`Self::stiffness`]), bit for bit; for an isotropic cloth assembled on the region's
    /// faces only ([`Restriction::values_from_faces`]), without the whole window's matrix.
    pub(crate) fn restricted_values(
        &self,
        topology: &Topology,
        geometry: &Geometry,
        pattern: &VertexPattern,
        region: &Restriction,
        scale: f64,
        face_scale: Option<&[f64]>,
    ) -> Vec<f64> {
        let area = &geometry.vertex_area;
        match (self, face_scale) {
            (Conductivity::Isotropic(d), None) => {
                // `cotan_stiffness(scale · d)`'s weights
                let s = scale * d;
                region.values_from_faces(topology, area, false, |f| {
                    geometry.face_cot[f].map(|c| -0.5 * s * c)
                })
            }
            (Conductivity::Isotropic(d), Some(g)) => {
                region.values_from_faces(topology, area, false, |f| {
                    geometry.face_cot[f].map(|c| -0.5 * scale * d * g[f] * c)
                })
            }
            (Conductivity::Woven(_), g) => {
                let full = self.stiffness(topology, geometry, pattern, scale, g);
                region.scalar_values(pattern, &full, area, false)
            }
        }
    }

    /// The conductivity of a sub-mesh made of `faces` (indices into this one's faces, in
    /// the sub-mesh's face order).
    pub(crate) fn faces(&self, faces: &[u32]) -> Self {
        match self {
            Conductivity::Isotropic(d) => Conductivity::Isotropic(*d),
            Conductivity::Woven(w) => Conductivity::Woven(WovenFaces {
                tensor: faces.iter().map(|&f| w.tensor[f as usize]).collect(),
                uv: faces.iter().map(|&f| w.uv[f as usize]).collect(),
                angle: faces.iter().map(|&f| w.angle[f as usize]).collect(),
            }),
        }
    }

    /// Faces whose UVs are degenerate (the weft falls back to an edge), at `geometry`.
    pub(crate) fn degenerate_uv_faces(&self, topology: &Topology, geometry: &Geometry) -> usize {
        match self {
            Conductivity::Woven(w) => weft_angles(topology, geometry, &w.uv, &w.angle).1,
            Conductivity::Isotropic(_) => 0,
        }
    }

    /// Checks the rate or the per-face data (lengths, finiteness, tensors PSD).
    pub(crate) fn validate(&self, n_faces: usize) -> Result<(), ParamError> {
        match self {
            Conductivity::Isotropic(d) => {
                check_range("diffusion rate", *d, *d >= 0.0, "finite and ≥ 0")
            }
            Conductivity::Woven(w) => {
                let lengths = [
                    ("face tensors", w.tensor.len()),
                    ("face UVs", w.uv.len()),
                    ("face angles", w.angle.len()),
                ];
                for (name, len) in lengths {
                    if len != n_faces {
                        return Err(ParamError::Length {
                            name,
                            expected: n_faces,
                            got: len,
                        });
                    }
                }
                for (f, &[a, b, c]) in w.tensor.iter().enumerate() {
                    // positive semi-definite: a ≥ 0, c ≥ 0, ac ≥ b² (zero allowed: a barrier)
                    if !(a >= 0.0 && c >= 0.0 && b.is_finite() && a * c >= b * b * (1.0 - 1e-12)) {
                        return Err(ParamError::NotPositiveSemiDefinite {
                            name: "face tensor",
                            index: f,
                        });
                    }
                }
                if let Some(f) =
                    w.uv.iter()
                        .position(|t| t.iter().flatten().any(|x| !x.is_finite()))
                {
                    return Err(ParamError::NonFinite {
                        name: "face UVs",
                        index: f,
                    });
                }
                if let Some(f) = w.angle.iter().position(|x| !x.is_finite()) {
                    return Err(ParamError::NonFinite {
                        name: "face angles",
                        index: f,
                    });
                }
                Ok(())
            }
        }
    }
}

/// Steps a density field by implicit diffusion while the mesh moves.
#[derive(Debug)]
pub struct DiffusionStepper {
    topology: Topology,
    conductivity: Conductivity,
    degenerate_uv_faces: usize,
    solver: PrefactoredSpd,
    positions: Vec<DVec3>,
    vertex_area: Vec<f64>,
    loose: Vec<bool>,
    /// Field-major: `fields[k*n..(k+1)*n]` is field `k`; field 0 is the density, fields
    /// 1–3 (when tinted) the colour mass `σ·(r, g, b)`.
    fields: Vec<f64>,
}

impl DiffusionStepper {
    /// A stepper for `topology`, starting at `positions` with `density` (per unit area).
    pub fn new<P: Copy + Into<DVec3> + Sync>(
        topology: Topology,
        positions: &[P],
        density: Vec<f64>,
        conductivity: Conductivity,
        par: Par,
    ) -> Result<Self, Error> {
        conductivity.validate(topology.n_faces())?;
        let n = topology.n_vertices();
        if density.len() != n {
            return Err(ParamError::Length {
                name: "density",
                expected: n,
                got: density.len(),
            }
            .into());
        }
        if let Some(index) = density.iter().position(|d| !d.is_finite()) {
            return Err(ParamError::NonFinite {
                name: "density",
                index,
            }
            .into());
        }
        let geometry = Geometry::new(&topology, positions)?;
        let solver = PrefactoredSpd::new(VertexPattern::new(&topology), par)?;
        let degenerate_uv_faces = conductivity.degenerate_uv_faces(&topology, &geometry);
        Ok(Self {
            degenerate_uv_faces,
            loose: topology.loose_vertices(),
            positions: positions.iter().map(|&p| p.into()).collect(),
            vertex_area: geometry.vertex_area,
            topology,
            conductivity,
            solver,
            fields: density,
        })
    }

    /// Density per unit area at every vertex.
    pub fn density(&self) -> &[f64] {
        &self.fields[..self.topology.n_vertices()]
    }

    /// Starts tracking the colour of the liquid: `colors[i]` is the RGB of the liquid now at
    /// vertex `i`. Sources added later bring their own colour (see [`Self::add_liquid`]).
    pub fn enable_color(&mut self, colors: &[[f64; 3]]) -> Result<(), ParamError> {
        let n = self.topology.n_vertices();
        if colors.len() != n {
            return Err(ParamError::Length {
                name: "colors",
                expected: n,
                got: colors.len(),
            });
        }
        if let Some(index) = colors.iter().position(|c| c.iter().any(|x| !x.is_finite())) {
            return Err(ParamError::NonFinite {
                name: "colors",
                index,
            });
        }
        self.fields.truncate(n);
        // `k` is the colour channel (inner index of `colors[i]`); clippy's suggested
        // `colors.iter()` would iterate over vertices instead
        #[allow(clippy::needless_range_loop)]
        for k in 0..3 {
            let tint: Vec<f64> = (0..n).map(|i| self.fields[i] * colors[i][k]).collect();
            self.fields.extend(tint);
        }
        Ok(())
    }

    /// `true` once [`Self::enable_color`] was called.
    pub(crate) fn has_color(&self) -> bool {
        self.fields.len() > self.topology.n_vertices()
    }

    /// RGB of the liquid at every vertex (`(σ·c)/σ`; black where there is none), or `None`
    /// when colour is not tracked.
    pub fn color(&self) -> Option<Vec<[f64; 3]>> {
        let n = self.topology.n_vertices();
        self.has_color().then(|| {
            (0..n)
                .map(|i| {
                    let d = self.fields[i];
                    if d > 1e-300 {
                        std::array::from_fn(|k| self.fields[(k + 1) * n + i] / d)
                    } else {
                        [0.0; 3]
                    }
                })
                .collect()
        })
    }

    /// Adds liquid: `delta[i]` more density (per unit area, ≥ 0) at vertex `i`, of colour
    /// `color` (required when colour is tracked, ignored otherwise).
    pub fn add_liquid(&mut self, delta: &[f64], color: Option<[f64; 3]>) -> Result<(), ParamError> {
        let n = self.topology.n_vertices();
        if delta.len() != n {
            return Err(ParamError::Length {
                name: "added liquid",
                expected: n,
                got: delta.len(),
            });
        }
        if let Some(index) = delta.iter().position(|d| !(d.is_finite() && *d >= 0.0)) {
            return Err(ParamError::NonFinite {
                name: "added liquid (finite, ≥ 0)",
                index,
            });
        }
        let tint = match (self.has_color(), color) {
            (false, _) => None,
            (true, Some(c)) if c.iter().all(|x| x.is_finite()) => Some(c),
            (true, _) => {
                return Err(ParamError::NonFinite {
                    name: "liquid colour",
                    index: 0,
                });
            }
        };
        for (i, d) in delta.iter().enumerate() {
            self.fields[i] += d;
            if let Some(c) = tint {
                for (k, ck) in c.iter().enumerate() {
                    self.fields[(k + 1) * n + i] += d * ck;
                }
            }
        }
        Ok(())
    }

    /// Lumped area of every vertex at the current positions.
    pub fn vertex_area(&self) -> &[f64] {
        &self.vertex_area
    }

    /// Faces whose UV triangle is degenerate at the start pose (their weft falls back to an
    /// edge direction; see [`crate::ops::aniso`]).
    pub fn degenerate_uv_faces(&self) -> usize {
        self.degenerate_uv_faces
    }

    /// Total stain mass `Σ A_i σ_i`.
    pub fn total_mass(&self) -> f64 {
        self.vertex_area
            .iter()
            .zip(self.density())
            .map(|(a, s)| a * s)
            .sum()
    }

    /// Moves the mesh to `positions` over `dt` seconds in `substeps` implicit steps,
    /// diffusing along the way (positions are interpolated linearly within the step).
    pub fn step<P: Copy + Into<DVec3> + Sync>(
        &mut self,
        positions: &[P],
        dt: f64,
        substeps: u32,
    ) -> Result<(), Error> {
        check_range("time step", dt, dt > 0.0, "finite and > 0")?;
        check_range("substeps", substeps as f64, substeps >= 1, "≥ 1")?;
        check_positions(&self.topology, positions)?;
        let target: Vec<DVec3> = positions.iter().map(|&p| p.into()).collect();
        let start = std::mem::take(&mut self.positions);
        let h = dt / substeps as f64;
        for s in 1..=substeps {
            let t = s as f64 / substeps as f64;
            let p: Vec<DVec3> = if s == substeps {
                target.clone()
            } else {
                start
                    .iter()
                    .zip(&target)
                    .map(|(a, b)| a.lerp(*b, t))
                    .collect()
            };
            if let Err(e) = self.implicit_step(&p, h) {
                self.positions = start;
                return Err(e);
            }
        }
        self.positions = target;
        Ok(())
    }

    fn implicit_step(&mut self, positions: &[DVec3], h: f64) -> Result<(), Error> {
        let geometry = Geometry::new(&self.topology, positions)?;
        let pattern = self.solver.pattern();
        let mut values = self
            .conductivity
            .stiffness(&self.topology, &geometry, pattern, h, None);
        add_lumped_mass(&geometry, pattern, 1.0, &mut values);
        // one right-hand side per field: the masses carried by the vertices
        let n = self.topology.n_vertices();
        let mut rhs: Vec<f64> = self
            .fields
            .iter()
            .enumerate()
            .map(|(j, x)| self.vertex_area[j % n] * x)
            .collect();
        for (v, _) in self.loose.iter().enumerate().filter(|(_, l)| **l) {
            values[pattern.diag_slot()[v] as usize] = 1.0;
            for k in 0..self.fields.len() / n {
                rhs[k * n + v] = self.fields[k * n + v];
            }
        }
        self.solver.factorize(&values)?;
        self.solver.solve_in_place(&mut rhs);
        self.fields = rhs;
        self.vertex_area = geometry.vertex_area;
        Ok(())
    }
}

/// Warm-started CG solvers of the two restricted systems, the densities' and the
/// velocity's (none for an empty restriction).
pub(super) fn solvers(
    region: &Restriction,
    reuse: Option<(WarmCg, WarmCg)>,
) -> Option<(WarmCg, WarmCg)> {
    // the two analyses are independent (and the velocity's, on 2×2 blocks, the larger);
    // a former window's solvers lend their memory ([`WarmCg::rebuild`])
    (!region.vertices.is_empty()).then(|| {
        let (a, b) = match reuse {
            Some((a, b)) => (Some(a), Some(b)),
            None => (None, None),
        };
        let make = |old: Option<WarmCg>, pattern: &CscPattern, tolerance: f64| match old {
            Some(mut cg) => {
                cg.rebuild(pattern);
                cg.with_tolerance(tolerance)
            }
            None => WarmCg::new(pattern).with_tolerance(tolerance),
        };
        rayon::join(
            || make(a, region.scalar(), DENSITY_TOLERANCE),
            || {
                make(b, region.scalar(), VELOCITY_TOLERANCE)
                    .with_preconditioner(Preconditioner::SymmetricGaussSeidel)
            },
        )
    })
}

/// The operators of a window the diffusion steps read.
pub(super) struct Ops<'a> {
    pub(super) topology: &'a Topology,
    pub(super) adjacency: &'a RingAdjacency,
    pub(super) pattern: &'a VertexPattern,
    pub(super) conductivity: &'a Conductivity,
    pub(super) region: &'a Restriction,
}

/// How the dissolved solute moves in [`diffuse_densities`] (module doc, "Tide lines").
#[derive(Clone, Copy, Debug)]
pub(super) enum SoluteMotion<'a> {
    /// Diffusing with the free solvent's operator (the seed's).
    Diffused,
    /// Carried by the solvents' fluxes; the fibres' solvent on its own operator with these
    /// face scales (a pinned edge) when given, on the free solvent's otherwise.
    Carried { held_scale: Option<&'a [f64]> },
}

/// `(M + h K_A) σ' = m` for every flowing field on the active vertices, Neumann at the
/// region's edge ([`crate::ops::restrict`]), then the exact mass restoration and the non-negativity
/// repair; the masses outside are not touched. Returns the work done.
pub(super) fn diffuse_densities(
    ops: &Ops<'_>,
    cg: &mut WarmCg,
    f: &mut Fields,
    geometry: &Geometry,
    h: f64,
    wicking: Option<&[f64]>,
    solute: SoluteMotion<'_>,
) -> Result<DensityWork, Error> {
    let (carry, held_scale) = match solute {
        SoluteMotion::Diffused => (false, None),
        SoluteMotion::Carried { held_scale } => (true, held_scale),
    };
    let region = ops.region;
    let vertices = &region.vertices;
    let nv = vertices.len();
    let area = &geometry.vertex_area;
    // the whole window's stiffness only when the solute follows its fluxes
    let full = carry.then(|| {
        ops.conductivity
            .stiffness(ops.topology, geometry, ops.pattern, h, wicking)
    });
    let values = match &full {
        Some(full) => region.scalar_values(ops.pattern, full, area, false),
        None => ops.conductivity.restricted_values(
            ops.topology,
            geometry,
            ops.pattern,
            region,
            h,
            wicking,
        ),
    };
    // the fibres' liquid on its own, pinned operator (its faces' scales), when carried
    let held_full = held_scale.map(|g| {
        ops.conductivity
            .stiffness(ops.topology, geometry, ops.pattern, h, Some(g))
    });
    // with the solute carried (issue 13 §2) the two solvents, free and in the fibres,
    // are solved, and the solute moves with their fluxes; otherwise the free solvent, the
    // dissolved solute and its colour diffuse alike
    let before = carry.then(|| (f.free_solvent.clone(), f.absorbed_solvent.clone()));
    let mut color = f.color_free.as_ref().map(|c| split_rgb(c));
    let mut fields: Vec<&mut Vec<f64>> = vec![&mut f.free_solvent];
    if carry {
        fields.push(&mut f.absorbed_solvent);
    } else {
        fields.push(&mut f.solute);
        if let Some(c) = color.as_mut() {
            fields.extend(c.iter_mut());
        }
    }
    let rhs: Vec<f64> = fields
        .iter()
        .flat_map(|m| vertices.iter().map(|&v| m[v as usize]))
        .collect();
    // warm start: the densities the masses have now (after advection) on the new areas —
    // the solution for h → 0, closer than the last step's solution because the liquid has
    // moved since
    let mut sigma: Vec<f64> = rhs
        .iter()
        .enumerate()
        .map(|(k, m)| {
            let a = area[vertices[k % nv] as usize];
            if a > 0.0 { m / a } else { 0.0 }
        })
        .collect();
    let mut work = DensityWork {
        iterations: 0,
        solves: fields.len(),
        carried: 0,
    };
    work.iterations = match &held_full {
        None => {
            cg.solve_chained(&values, &rhs, &mut sigma)?;
            cg.last_iterations
        }
        Some(held) => {
            let held_values = region.scalar_values(ops.pattern, held, area, false);
            cg.solve(&values, &rhs[..nv], &mut sigma[..nv])?;
            let free = cg.last_iterations;
            cg.solve(&held_values, &rhs[nv..], &mut sigma[nv..])?;
            free + cg.last_iterations
        }
    };
    for (k, m) in fields.iter_mut().enumerate() {
        let before: f64 = vertices.iter().map(|&v| m[v as usize]).sum();
        let sigma = &sigma[k * nv..(k + 1) * nv];
        for (j, &v) in vertices.iter().enumerate() {
            m[v as usize] = area[v as usize] * sigma[j];
        }
        repair_negative(ops.adjacency, m, vertices, &region.mask);
        let after: f64 = vertices.iter().map(|&v| m[v as usize]).sum();
        if after > 0.0 && before > 0.0 {
            let scale = before / after;
            vertices.iter().for_each(|&v| m[v as usize] *= scale);
        }
    }
    if let (Some((free, held)), Some(full)) = (&before, &full) {
        // the dissolved solute and its colour with the free solvent
        let mut moves: Vec<(&mut Vec<f64>, Vec<f64>)> = vec![(&mut f.solute, Vec::new())];
        if let Some(c) = color.as_mut() {
            moves.extend(c.iter_mut().map(|c| (c, Vec::new())));
        }
        for (target, movable) in moves.iter_mut() {
            *movable = target.to_vec();
        }
        work.carried += moves.len();
        carry_with_solvent(ops, full, &sigma[..nv], (free, &f.free_solvent), &mut moves);
        // the absorbed solute with the solvent in the fibres; the held colour pool
        // (absorbed + adsorbed) gives up the absorbed solute's share
        let held_color = f.color_held.as_ref().map(|c| split_rgb(c));
        let (sp, sa) = (&f.absorbed_solute, &f.adsorbed);
        let mut held_moves: Vec<(Vec<f64>, Vec<f64>)> = vec![(sp.clone(), sp.clone())];
        if let Some(hc) = &held_color {
            for c in hc {
                let movable = (0..c.len())
                    .map(|v| {
                        let pool = sp[v] + sa[v];
                        if pool > 0.0 {
                            c[v] * (sp[v].max(0.0) / pool)
                        } else {
                            0.0
                        }
                    })
                    .collect();
                held_moves.push((c.clone(), movable));
            }
        }
        let mut refs: Vec<(&mut Vec<f64>, Vec<f64>)> = held_moves
            .iter_mut()
            .map(|(t, m)| (t, std::mem::take(m)))
            .collect();
        work.carried += refs.len();
        carry_with_solvent(
            ops,
            held_full.as_ref().unwrap_or(full),
            &sigma[nv..2 * nv],
            (held, &f.absorbed_solvent),
            &mut refs,
        );
        drop(refs);
        let mut held_moves = held_moves.into_iter();
        f.absorbed_solute = held_moves.next().expect("the absorbed solute").0;
        if let Some(ch) = f.color_held.as_mut() {
            let c: Vec<Vec<f64>> = held_moves.map(|(t, _)| t).collect();
            merge_rgb(&[c[0].clone(), c[1].clone(), c[2].clone()], ch);
        }
    }
    if let (Some(c), Some(cf)) = (color, f.color_free.as_mut()) {
        merge_rgb(&c, cf);
    }
    Ok(work)
}

/// What one density diffusion did (counted for [`crate::stain::Profile`]).
pub(super) struct DensityWork {
    /// CG iterations over all solved fields.
    pub iterations: usize,
    /// Fields solved (one CG solve each).
    pub solves: usize,
    /// Fields carried along the solved solvent's fluxes (the solute and its colour).
    pub carried: usize,
}

/// Most Gauss–Seidel sweeps of the carried solute's concentrations ([`carry_with_solvent`]).
const MAX_CARRY_SWEEPS: usize = 50;

/// Moves the solute (and its colour) with the solvent's diffusive fluxes of the solve
/// just made (issue 13 §2, "Tide lines" in the module doc). Across every edge `a–b` of
/// the region the solvent moved `F_ab = −h K_ab (σ'_a − σ'_b)` (kg, `a → b`), and the
/// solute goes with it at the concentration `c = s/f` of the vertex it leaves, **at the
/// end of the step** (implicit upwind, as the solvent's own step is implicit):
///
/// ```text
/// c'_a (f_a + in_a − out_a) = s_a − c'_a out_a + Σ_{b → a} F_ba c'_b,
/// ```
///
/// `f_a` the solvent before, `in_a`, `out_a` its in- and outflow. Diffusive fluxes run
/// down the solved density, so in order of decreasing `σ'` every inflow comes from a
/// vertex already solved: one sweep solves the system exactly. (A flux uphill, from a
/// negative cotan weight on an obtuse mesh, is taken explicitly at the old
/// concentration, limited to the solvent the vertex held.) Every transfer is between two
/// vertices, so the total is exact; the weights are non-negative, so no mass goes
/// negative; and `c' = c` solves it when `c` is uniform: a solution of one strength keeps
/// it wherever the solvent takes it, however sharp the solvent's front and however
/// long the step. (With the concentration of the start of the step instead, a vertex
/// the front crosses within the step passes on more solvent than it held and its
/// concentration came out 3× wrong.)
///
/// `before` and `after` are the solvent before the solve and now (window numbering; the
/// solute ends at `c'` times the solvent now), `sigma` its solved densities (region
/// order); each move is a mass field and the part of it that moves
/// (the field itself, or the moving solute's share of a colour pool).
fn carry_with_solvent(
    ops: &Ops<'_>,
    stiffness: &[f64],
    sigma: &[f64],
    (before, after): (&[f64], &[f64]),
    moves: &mut [(&mut Vec<f64>, Vec<f64>)],
) {
    let region = ops.region;
    let n = before.len();
    let mut density = vec![0.0; n];
    for (j, &v) in region.vertices.iter().enumerate() {
        density[v as usize] = sigma[j];
    }
    // the sweep order: decreasing solved density (ties by vertex), and each vertex's rank
    let mut order: Vec<u32> = region.vertices.clone();
    order.sort_by(|&a, &b| {
        density[b as usize]
            .total_cmp(&density[a as usize])
            .then(a.cmp(&b))
    });
    let mut rank = vec![u32::MAX; n];
    for (k, &v) in order.iter().enumerate() {
        rank[v as usize] = k as u32;
    }
    let slot = ops.pattern.edge_slot();
    // (upwind, downwind, solvent moved) for every edge inside the region
    let flows: Vec<(usize, usize, f64)> = ops
        .topology
        .edges()
        .iter()
        .enumerate()
        .filter(|(_, e)| region.mask[e[0] as usize] && region.mask[e[1] as usize])
        .filter_map(|(e, &[a, b])| {
            let (a, b) = (a as usize, b as usize);
            let flow = -stiffness[slot[e] as usize] * (density[a] - density[b]);
            match flow.partial_cmp(&0.0) {
                Some(std::cmp::Ordering::Greater) => Some((a, b, flow)),
                Some(std::cmp::Ordering::Less) => Some((b, a, -flow)),
                _ => None,
            }
        })
        .collect();
    let mut inflow = vec![0.0; n];
    let mut incoming: Vec<Vec<(u32, f64)>> = vec![Vec::new(); n];
    let mut uphill = false;
    for &(from, to, amount) in &flows {
        inflow[to] += amount;
        incoming[to].push((from as u32, amount));
        uphill |= rank[from] > rank[to];
    }
    for (target, movable) in moves.iter_mut() {
        // what cannot move stays: a vertex without solvent holds its solute in place
        let mut mobile: Vec<f64> = (0..n)
            .map(|v| {
                if before[v] > 0.0 {
                    movable[v].max(0.0)
                } else {
                    0.0
                }
            })
            .collect();
        for &v in &order {
            target[v as usize] -= mobile[v as usize];
        }
        // c'_a = (s_a + Σ_in F_ba c'_b) / (f_a + in_a): one sweep down the density when
        // every flux runs downhill, Gauss–Seidel sweeps in that order otherwise
        let mut conc = vec![0.0; n];
        for sweep in 0..MAX_CARRY_SWEEPS {
            let mut change: f64 = 0.0;
            let mut size: f64 = 0.0;
            for &v in &order {
                let v = v as usize;
                let gathered: f64 = incoming[v].iter().map(|&(b, f)| f * conc[b as usize]).sum();
                let held = before[v] + inflow[v];
                let c = if held > 0.0 {
                    (mobile[v] + gathered) / held
                } else {
                    0.0
                };
                change = change.max((c - conc[v]).abs());
                size = size.max(c);
                conc[v] = c;
            }
            if !uphill || (sweep > 0 && change <= 1e-13 * size) {
                break;
            }
        }
        // the solute in the solvent as it is now (after the negative-mass repair and the
        // restoration of its total), then the total restored: exact for a uniform
        // solution, and the rounding of the sweep otherwise
        let moving: f64 = order
            .iter()
            .map(|&v| {
                let v = v as usize;
                if before[v] > 0.0 {
                    movable[v].max(0.0)
                } else {
                    0.0
                }
            })
            .sum();
        let mut total = 0.0;
        for &v in &order {
            let v = v as usize;
            mobile[v] = conc[v] * after[v].max(0.0);
            total += mobile[v];
        }
        let scale = if total > 0.0 { moving / total } else { 0.0 };
        for &v in &order {
            let v = v as usize;
            target[v] += mobile[v] * scale;
        }
    }
}

/// Eq. 4.6 on the active vertices with clamped (non-negative) edge weights,
/// `(M ⊗ I + h ν K_∇) u' = (M ⊗ I) u` with `scale = h ν`: the block rows and columns of
/// the active vertices, diagonal blocks `K_ii = Σ_{j active} L_ij`; the velocities
/// outside are not touched. Returns the CG iterations.
pub(super) fn diffuse_velocity(
    ops: &Ops<'_>,
    cg: &mut WarmCg,
    velocity: &mut [DVec2],
    geometry: &Geometry,
    transport: &Transport,
    scale: f64,
) -> Result<usize, Error> {
    let region = ops.region;
    let area = &geometry.vertex_area;
    // `cotan_stiffness(scale)` on the region's faces, clamped
    let scalar = region.values_from_faces(ops.topology, area, true, |f| {
        geometry.face_cot[f].map(|c| -0.5 * scale * c)
    });
    let nv = region.vertices.len();
    let mut rhs = Vec::with_capacity(2 * nv);
    let mut x = Vec::with_capacity(2 * nv);
    for &v in &region.vertices {
        let (a, u) = (area[v as usize], velocity[v as usize]);
        rhs.extend([a * u.x, a * u.y]);
        x.extend([u.x, u.y]);
    }
    cg.solve_rotated(
        &scalar,
        region.entry_edges(),
        transport.edge_cos_sin(),
        &rhs,
        &mut x,
    )?;
    for (j, &v) in region.vertices.iter().enumerate() {
        velocity[v as usize] = DVec2::new(x[2 * j], x[2 * j + 1]);
    }
    Ok(cg.last_iterations)
}

/// Fills negative masses among `vertices` (increasing) from their positive neighbours
/// where `mask` (in proportion to their masses), then from all positive `vertices` if the
/// neighbours cannot cover the deficit; conservative, sequential (deterministic), and a
/// no-op when nothing is negative. The masses outside `mask` are not touched.
fn repair_negative(adjacency: &RingAdjacency, mass: &mut [f64], vertices: &[u32], mask: &[bool]) {
    if !vertices.iter().any(|&v| mass[v as usize] < 0.0) {
        return;
    }
    let inside = |j: usize| mask[j];

    let mut leftover = 0.0;
    for &i in vertices {
        let i = i as usize;
        if mass[i] >= 0.0 {
            continue;
        }
        let deficit = -mass[i];
        mass[i] = 0.0;
        let ring = adjacency.neighbours(i);
        let pool: f64 = ring
            .iter()
            .filter(|&&j| inside(j as usize))
            .map(|&j| mass[j as usize].max(0.0))
            .sum();
        let take = deficit.min(pool);
        if take > 0.0 {
            let frac = take / pool;
            for &j in ring.iter().filter(|&&j| inside(j as usize)) {
                let m = &mut mass[j as usize];
                if *m > 0.0 {
                    *m -= *m * frac;
                }
            }
        }
        leftover += deficit - take;
    }
    if leftover > 0.0 {
        let pool: f64 = vertices
            .iter()
            .map(|&v| mass[v as usize])
            .filter(|m| *m > 0.0)
            .sum();
        if pool > 0.0 {
            let keep = (1.0 - leftover / pool).max(0.0);
            vertices.iter().for_each(|&v| mass[v as usize] *= keep);
        }
    }
}
