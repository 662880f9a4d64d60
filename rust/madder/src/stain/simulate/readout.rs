//! What is read out of the state ([`crate::stain::state`]): the cache's fields, the
//! densities and colours, the totals.

use glam::{DVec2, DVec3};

use super::Simulator;
use crate::stain::state::{Fields, Totals};

/// What can be read out of the state (the cache's fields, the totals).
impl Simulator {
    /// Lumped vertex areas of the current frame, m² (of every vertex that holds or held
    /// anything; a vertex that never did keeps an older area).
    pub fn vertex_area(&self) -> &[f64] {
        &self.state.vertex_area
    }
    /// The cloth's positions at the current frame, m.
    pub fn positions(&self) -> &[DVec3] {
        &self.state.positions
    }
    /// Per-vertex masses, kg.
    pub fn fields(&self) -> &Fields {
        &self.state.fields
    }
    /// Velocities in the vertex frames, m/s (of each vertex's last step: a vertex outside
    /// the window keeps the value it left it with).
    pub fn velocity(&self) -> &[DVec2] {
        &self.state.velocity
    }
    /// Velocities as world vectors, m/s (as [`Simulator::velocity`], in the frame of each
    /// vertex's last step).
    pub fn velocity_world(&self) -> Vec<DVec3> {
        (0..self.state.velocity.len())
            .map(|i| self.state.frames.to_world(i, self.state.velocity[i]))
            .collect()
    }
    /// Density `mass / A_i` of a mass field (0 where a vertex has no area).
    pub fn density(&self, mass: &[f64]) -> Vec<f64> {
        mass.iter()
            .zip(&self.state.vertex_area)
            .map(|(m, a)| if *a > 0.0 { m / a } else { 0.0 })
            .collect()
    }

    /// Liquid density (free + absorbed solvent), kg/m².
    pub fn wetness(&self) -> Vec<f64> {
        let f = &self.state.fields;
        let wet: Vec<f64> = f
            .free_solvent
            .iter()
            .zip(&f.absorbed_solvent)
            .map(|(a, b)| a + b)
            .collect();
        self.density(&wet)
    }

    /// Total solute density (dissolved + absorbed + adsorbed), kg/m².
    pub fn solute_density(&self) -> Vec<f64> {
        let f = &self.state.fields;
        let s: Vec<f64> = (0..f.solute.len())
            .map(|i| f.solute[i] + f.absorbed_solute[i] + f.adsorbed[i])
            .collect();
        self.density(&s)
    }

    /// Adsorbed solute density (the permanent deposit), kg/m².
    pub fn deposit(&self) -> Vec<f64> {
        self.density(&self.state.fields.adsorbed)
    }

    /// Colour of the solute at every vertex (mass-weighted mix of the liquids poured;
    /// the liquid's colour where there is no solute).
    pub fn solute_color(&self) -> Vec<[f64; 3]> {
        let f = &self.state.fields;
        match (&f.color_free, &f.color_held) {
            (Some(cf), Some(ch)) => (0..f.solute.len())
                .map(|i| {
                    let s = f.solute[i] + f.absorbed_solute[i] + f.adsorbed[i];
                    if s > 1e-300 {
                        std::array::from_fn(|k| (cf[i][k] + ch[i][k]) / s)
                    } else {
                        self.solute_color
                    }
                })
                .collect(),
            _ => vec![self.solute_color; f.solute.len()],
        }
    }

    /// Totals over the mesh (sums in vertex order).
    pub fn totals(&self) -> Totals {
        let f = &self.state.fields;
        Totals {
            solvent: f.total_solvent(),
            solute: f.total_solute(),
            evaporated: self.state.evaporated,
            dripped: self.state.dripped.0,
            dripped_solute: self.state.dripped.1,
        }
    }
}
