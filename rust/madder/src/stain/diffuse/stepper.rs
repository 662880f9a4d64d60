//! The diffusion alone on the whole mesh ([`DiffusionStepper`]): a prefactored
//! `(M + hK)` (module doc, the first slice, kept for the fabric experiments).

use faer::Par;
use glam::DVec3;

use super::Conductivity;
use crate::error::{Error, ParamError};
use crate::mesh::geometry::check_positions;
use crate::mesh::{Geometry, Topology};
use crate::ops::{PrefactoredSpd, VertexPattern, add_lumped_mass};
use crate::stain::check::check_range;

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
