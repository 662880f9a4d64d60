//! Implicit diffusion of a density on a deforming mesh (seed §4.3.3).
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
//! with `M` the lumped mass and `K` the cotan stiffness of the new geometry (module
//! [`crate::ops::cotan`]). Because `1ᵀK = 0`, `Σ_i A_i^new σ'_i = Σ_i m_i`: mass is
//! conserved exactly, up to the rounding of the solve, on any mesh and any motion.
//! The scheme is unconditionally stable, so `h` can be a whole frame; sub-steps (with
//! positions interpolated linearly between frames) follow fast deformation more closely.
//!
//! The sparsity pattern of `M + hDK` is fixed by the topology: the stepper does the
//! symbolic Cholesky analysis once and only refactorizes numerically each step.
//!
//! A vertex with no incident face has no area and no stiffness; its row would be zero.
//! We put `1` on its diagonal and its own density on the right-hand side, so it keeps its
//! value and carries no mass.

use faer::Par;
use glam::DVec3;

use crate::error::{Error, ParamError};
use crate::mesh::geometry::check_positions;
use crate::mesh::{Geometry, Topology};
use crate::ops::{PrefactoredSpd, VertexPattern, add_lumped_mass, cotan_stiffness};

/// Parameters of isotropic diffusion.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DiffusionParams {
    /// Diffusion coefficient `D`, m²/s.
    pub rate: f64,
}

impl DiffusionParams {
    pub fn validate(&self) -> Result<(), ParamError> {
        check_range(
            "diffusion rate",
            self.rate,
            self.rate >= 0.0,
            "finite and ≥ 0",
        )
    }
}

/// Steps a density field by implicit diffusion while the mesh moves.
#[derive(Debug)]
pub struct DiffusionStepper {
    topology: Topology,
    params: DiffusionParams,
    solver: PrefactoredSpd,
    positions: Vec<DVec3>,
    vertex_area: Vec<f64>,
    loose: Vec<bool>,
    density: Vec<f64>,
}

impl DiffusionStepper {
    /// A stepper for `topology`, starting at `positions` with `density` (per unit area).
    pub fn new<P: Copy + Into<DVec3> + Sync>(
        topology: Topology,
        positions: &[P],
        density: Vec<f64>,
        params: DiffusionParams,
        par: Par,
    ) -> Result<Self, Error> {
        params.validate()?;
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
        Ok(Self {
            loose: topology.loose_vertices(),
            positions: positions.iter().map(|&p| p.into()).collect(),
            vertex_area: geometry.vertex_area,
            topology,
            params,
            solver,
            density,
        })
    }

    pub fn topology(&self) -> &Topology {
        &self.topology
    }

    /// Density per unit area at every vertex.
    pub fn density(&self) -> &[f64] {
        &self.density
    }

    /// Lumped area of every vertex at the current positions.
    pub fn vertex_area(&self) -> &[f64] {
        &self.vertex_area
    }

    /// Total stain mass `Σ A_i σ_i`.
    pub fn total_mass(&self) -> f64 {
        self.vertex_area
            .iter()
            .zip(&self.density)
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
        let mut values = cotan_stiffness(&self.topology, &geometry, pattern, h * self.params.rate);
        add_lumped_mass(&geometry, pattern, 1.0, &mut values);
        let mut rhs: Vec<f64> = self
            .vertex_area
            .iter()
            .zip(&self.density)
            .map(|(a, s)| a * s)
            .collect();
        for (v, _) in self.loose.iter().enumerate().filter(|(_, l)| **l) {
            values[pattern.diag_slot()[v] as usize] = 1.0;
            rhs[v] = self.density[v];
        }
        self.solver.factorize(&values)?;
        self.solver.solve_in_place(&mut rhs);
        self.density = rhs;
        self.vertex_area = geometry.vertex_area;
        Ok(())
    }
}

fn check_range(
    name: &'static str,
    value: f64,
    ok: bool,
    requirement: &'static str,
) -> Result<(), ParamError> {
    if value.is_finite() && ok {
        Ok(())
    } else {
        Err(ParamError::OutOfRange {
            name,
            requirement,
            value,
        })
    }
}
