//! Stain detail beyond the cloth's vertices (issue 12): the simulator of chapter 4 run on
//! the cloth's triangles each split into `4^L` ([`crate::mesh::refine`]), driven and read
//! at the cloth's own vertices.
//!
//! The cloth's motion comes in as coarse positions; the fine vertices are placed on the
//! coarse triangles every frame (barycentric, the refinement's module doc says why not
//! smoothed), so the comoving frames, the forces, the fabric tensors (each fine face
//! takes its coarse face's tensor, UVs interpolated, so its weft is the coarse face's) and
//! the window of §4.3 all work on the fine mesh unchanged: the cost follows the wet part
//! of the fine surface, not the whole of it.
//!
//! What goes in per cloth vertex is spread over the fine vertices by the refinement's
//! prolongation (poured densities, splash weights and initial velocities interpolated
//! linearly; a poured mass lands exactly on its vertex's hat), and what comes out per
//! cloth vertex is the restriction of the fine masses (`m_i = Σ_j φ_i(x_j) m_j`) divided
//! by the cloth's lumped areas at the current frame: every total is the same read at
//! either level, to rounding. Velocities are read where a fine vertex is a cloth vertex.
//! At level 0 every call goes straight to the simulator: the results are the cloth
//! simulator's, bit for bit.

use std::borrow::Cow;

use faer::Par;
use glam::DVec3;

use super::diffuse::{Conductivity, WovenFaces};
use super::simulate::{Profile, Simulator, StainParams};
use super::sources::{check_each_nonnegative, check_length};
use super::state::{Fields, Totals};
use crate::error::{Error, ParamError};
use crate::mesh::Topology;
use crate::mesh::geometry::{check_positions, vertex_areas};
use crate::mesh::refine::Refinement;

/// The stain simulator at a Detail level: the cloth's own simulator at level 0, or one on
/// the refined cloth read and driven at the cloth's vertices (module doc).
#[derive(Debug)]
pub struct Detailed {
    sim: Simulator,
    fine: Option<Fine>,
}

/// The refinement and the cloth's state the transfers need.
#[derive(Debug)]
struct Fine {
    refinement: Refinement,
    cloth: Topology,
    /// Lumped areas of the cloth's vertices at the current frame.
    area: Vec<f64>,
}

impl Detailed {
    /// A dry cloth at rest, simulated at Detail `level` (0 ..= [`crate::mesh::refine::MAX_LEVEL`]); the other
    /// arguments are [`Simulator::new`]'s, per cloth vertex and face.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        topology: Topology,
        rest: &[DVec3],
        positions: &[DVec3],
        conductivity: Conductivity,
        params: StainParams,
        solute_color: [f64; 3],
        level: u32,
        par: Par,
    ) -> Result<Self, Error> {
        if level == 0 {
            let sim = Simulator::new(
                topology,
                rest,
                positions,
                conductivity,
                params,
                solute_color,
                par,
            )?;
            return Ok(Self { sim, fine: None });
        }
        // the cloth's own checks first, so that errors name the cloth's elements
        let refinement = Refinement::new(&topology, level)?;
        params.validate()?;
        conductivity.validate(topology.n_faces())?;
        check_positions(&topology, rest)?;
        check_positions(&topology, positions)?;
        let conductivity = match conductivity {
            Conductivity::Isotropic(d) => Conductivity::Isotropic(d),
            Conductivity::Woven(w) => Conductivity::Woven(WovenFaces {
                tensor: refinement.face_values(&w.tensor),
                uv: refinement.face_uv(&w.uv),
                angle: refinement.face_values(&w.angle),
            }),
        };
        let sim = Simulator::new(
            refinement.fine().clone(),
            &refinement.prolong(rest),
            &refinement.prolong(positions),
            conductivity,
            params,
            solute_color,
            par,
        )?;
        let area = vertex_areas(&topology, positions);
        Ok(Self {
            sim,
            fine: Some(Fine {
                refinement,
                cloth: topology,
                area,
            }),
        })
    }

    /// The Detail level.
    pub fn level(&self) -> u32 {
        self.fine.as_ref().map_or(0, |f| f.refinement.level())
    }
    /// The simulator doing the work (on the refined cloth above level 0).
    pub fn fine(&self) -> &Simulator {
        &self.sim
    }
    /// The refinement (`None` at level 0).
    pub fn refinement(&self) -> Option<&Refinement> {
        self.fine.as_ref().map(|f| &f.refinement)
    }
    /// The cloth's topology.
    pub fn topology(&self) -> &Topology {
        match &self.fine {
            Some(f) => &f.cloth,
            None => self.sim.topology(),
        }
    }
    /// Time spent per phase so far (on the refined cloth).
    pub fn profile(&self) -> Profile {
        self.sim.profile()
    }
    /// Simulated time since the start, s.
    pub fn time(&self) -> f64 {
        self.sim.time()
    }

    fn check_len(&self, name: &'static str, got: usize) -> Result<(), ParamError> {
        check_length(name, self.topology().n_vertices(), got)
    }

    /// [`Simulator::step`] to the cloth's `positions` (and `after`).
    pub fn step(
        &mut self,
        positions: &[DVec3],
        dt: f64,
        after: Option<&[DVec3]>,
    ) -> Result<(), Error> {
        let Some(fine) = &mut self.fine else {
            return self.sim.step(positions, dt, after);
        };
        check_positions(&fine.cloth, positions)?;
        if let Some(a) = after {
            check_positions(&fine.cloth, a)?;
        }
        let r = &fine.refinement;
        let after = after.map(|a| r.prolong(a));
        self.sim.step(&r.prolong(positions), dt, after.as_deref())?;
        fine.area = vertex_areas(&fine.cloth, positions);
        Ok(())
    }

    /// [`Simulator::add_liquid`] with `solvent` per cloth vertex (kg/m²), spread over the
    /// fine vertices by mass (module doc).
    pub fn add_liquid(
        &mut self,
        solvent: &[f64],
        concentration: f64,
        color: Option<[f64; 3]>,
    ) -> Result<(), ParamError> {
        let Some(fine) = &self.fine else {
            return self.sim.add_liquid(solvent, concentration, color);
        };
        self.check_len("added solvent", solvent.len())?;
        check_each_nonnegative("added solvent", solvent)?;
        let spread = fine.refinement.prolong(solvent);
        self.sim.add_liquid(&spread, concentration, color)
    }

    /// [`Simulator::splash`] with `weight` per cloth vertex (interpolated).
    pub fn splash(
        &mut self,
        center: DVec3,
        speed: f64,
        seed: u64,
        weight: &[f64],
    ) -> Result<(), ParamError> {
        let Some(fine) = &self.fine else {
            return self.sim.splash(center, speed, seed, weight);
        };
        self.check_len("splash weights", weight.len())?;
        check_each_nonnegative("splash weight", weight)?;
        let spread = fine.refinement.prolong(weight);
        self.sim.splash(center, speed, seed, &spread)
    }

    /// [`Simulator::set_velocity_world`] with one world vector per cloth vertex
    /// (interpolated).
    pub fn set_velocity_world(&mut self, velocity: &[DVec3]) -> Result<(), ParamError> {
        let Some(fine) = &self.fine else {
            return self.sim.set_velocity_world(velocity);
        };
        self.check_len("velocity", velocity.len())?;
        if let Some(index) = velocity.iter().position(|u| !u.is_finite()) {
            return Err(ParamError::NonFinite {
                name: "velocity",
                index,
            });
        }
        let spread = fine.refinement.prolong(velocity);
        self.sim.set_velocity_world(&spread)
    }

    /// Lumped areas of the cloth's vertices, m² (at level 0 [`Simulator::vertex_area`];
    /// above it, every vertex's at the current frame).
    pub fn vertex_area(&self) -> &[f64] {
        match &self.fine {
            Some(f) => &f.area,
            None => self.sim.vertex_area(),
        }
    }

    /// Per-cloth-vertex masses, kg (restricted from the fine ones above level 0).
    pub fn fields(&self) -> Cow<'_, Fields> {
        let f = self.sim.fields();
        let Some(fine) = &self.fine else {
            return Cow::Borrowed(f);
        };
        let r = |m: &[f64]| fine.refinement.restrict(m);
        let colors = |c: &Option<Vec<[f64; 3]>>| {
            c.as_ref().map(|c| {
                let k: [Vec<f64>; 3] =
                    std::array::from_fn(|k| r(&c.iter().map(|x| x[k]).collect::<Vec<_>>()));
                (0..k[0].len())
                    .map(|i| [k[0][i], k[1][i], k[2][i]])
                    .collect()
            })
        };
        Cow::Owned(Fields {
            free_solvent: r(&f.free_solvent),
            solute: r(&f.solute),
            absorbed_solvent: r(&f.absorbed_solvent),
            absorbed_solute: r(&f.absorbed_solute),
            adsorbed: r(&f.adsorbed),
            color_free: colors(&f.color_free),
            color_held: colors(&f.color_held),
        })
    }

    /// Density `mass / A_i` of a per-cloth-vertex mass field (0 where a vertex has no
    /// area).
    pub fn density(&self, mass: &[f64]) -> Vec<f64> {
        match &self.fine {
            None => self.sim.density(mass),
            Some(f) => divide(mass, &f.area),
        }
    }

    /// Liquid density (free + absorbed solvent) per cloth vertex, kg/m².
    pub fn wetness(&self) -> Vec<f64> {
        match &self.fine {
            None => self.sim.wetness(),
            Some(fine) => {
                let f = self.sim.fields();
                let wet: Vec<f64> = (0..f.free_solvent.len())
                    .map(|i| f.free_solvent[i] + f.absorbed_solvent[i])
                    .collect();
                divide(&fine.refinement.restrict(&wet), &fine.area)
            }
        }
    }

    /// Total solute density (dissolved + absorbed + adsorbed) per cloth vertex, kg/m².
    pub fn solute_density(&self) -> Vec<f64> {
        match &self.fine {
            None => self.sim.solute_density(),
            Some(fine) => divide(
                &fine.refinement.restrict(&total_solute(self.sim.fields())),
                &fine.area,
            ),
        }
    }

    /// Adsorbed solute density (the permanent deposit) per cloth vertex, kg/m².
    pub fn deposit(&self) -> Vec<f64> {
        match &self.fine {
            None => self.sim.deposit(),
            Some(fine) => divide(
                &fine.refinement.restrict(&self.sim.fields().adsorbed),
                &fine.area,
            ),
        }
    }

    /// Colour of the solute at every cloth vertex: the mass-weighted mix of the fine
    /// vertices' colours over its hat (the liquid's colour where there is no solute).
    pub fn solute_color(&self) -> Vec<[f64; 3]> {
        let Some(fine) = &self.fine else {
            return self.sim.solute_color();
        };
        let f = self.sim.fields();
        let base = self.sim.solute_color;
        let (Some(cf), Some(ch)) = (&f.color_free, &f.color_held) else {
            return vec![base; fine.cloth.n_vertices()];
        };
        let r = &fine.refinement;
        let s = r.restrict(&total_solute(f));
        let c: [Vec<f64>; 3] = std::array::from_fn(|k| {
            r.restrict(
                &(0..cf.len())
                    .map(|i| cf[i][k] + ch[i][k])
                    .collect::<Vec<_>>(),
            )
        });
        (0..s.len())
            .map(|i| {
                if s[i] > 1e-300 {
                    std::array::from_fn(|k| c[k][i] / s[i])
                } else {
                    base
                }
            })
            .collect()
    }

    /// Velocities of the cloth's vertices as world vectors, m/s (a cloth vertex is a fine
    /// vertex of the same index).
    pub fn velocity_world(&self) -> Vec<DVec3> {
        let st = &self.sim.state;
        (0..self.topology().n_vertices())
            .map(|i| st.frames.to_world(i, st.velocity[i]))
            .collect()
    }

    /// Totals over the cloth (the fine sums: the same at either level).
    pub fn totals(&self) -> Totals {
        self.sim.totals()
    }
}

/// Dissolved + absorbed + adsorbed solute mass per vertex.
fn total_solute(f: &Fields) -> Vec<f64> {
    (0..f.solute.len())
        .map(|i| f.solute[i] + f.absorbed_solute[i] + f.adsorbed[i])
        .collect()
}

fn divide(mass: &[f64], area: &[f64]) -> Vec<f64> {
    mass.iter()
        .zip(area)
        .map(|(m, a)| if *a > 0.0 { m / a } else { 0.0 })
        .collect()
}
