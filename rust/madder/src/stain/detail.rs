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
//!
//! ## Built lazily, as the liquid arrives
//! The refined cloth is never built in full ([`crate::mesh::refine::Partial`]): the
//! simulator runs on the fine faces of the coarse faces built so far, numbered in the
//! order they were built, and every per-vertex array it holds follows the built part.
//! Coarse faces are built
//!
//! - around every cloth vertex that liquid is poured on or splashed from (the support of
//!   its hat: every fine vertex the prolongation gives a positive value lies there, and
//!   its one-ring is complete);
//! - before every frame, when the frame's window ([`super::window`]) has an active or
//!   held vertex whose fine one-ring is not complete: around the coarse corners of all
//!   the window's active and held vertices, grown by [`GROWTH_RINGS`] coarse rings, and
//!   the window is found again on the grown part.
//!
//! So every vertex a frame steps has its whole one-ring, the window is the one the whole
//! refined cloth would give, and a fine vertex whose ring is incomplete holds nothing and
//! was never stepped. Such a vertex (and every new one) is *reset* when faces are added:
//! rest frame from its complete ring, and the state a never-stepped vertex of the whole
//! refined cloth would have — frame at the first positions, velocity zero, stamped time
//! 0, or, after [`Detailed::set_velocity_world`], the frame at that call's positions,
//! that velocity, stamped then. The results are the whole refined cloth's up to the
//! order of sums (vertices are numbered otherwise) and the choice of each vertex's
//! tangent axes (a fan starts at another face), both rounding-level. Splash velocities
//! are drawn per fine vertex index, so a splash is another draw of the same distribution.
//!
//! The simulator needs a mesh, so one coarse face (the first) is built from the start.
//!
//! A growth costs its new part, not the whole built part again (issue 16): vertices and
//! faces are appended, so only the new faces' edges are sorted and merged into the old
//! ones ([`Topology::extended`]), a vertex with no new face keeps its fan
//! ([`OneRings::extended`]), and a vertex that is not reset keeps its rest frame, frame
//! and area; the reset ones get theirs (the area summed over its faces in face order, as
//! [`vertex_areas`] does). The results are those of rebuilding it all, bit for bit. The
//! window a growth drops leaves its solvers to the next one (built in their memory, as a
//! window replacing another is), and the growth, the window build, the placement and the
//! cloth's areas run in the rayon pool, their independent parts side by side (a growth
//! computes the built part's per-vertex and per-face arrays beside its topology).
//!
//! The fine vertices inside one coarse face or on one coarse edge have congruent
//! one-rings moved by the same affine maps, so the window gives them one Kabsch rotation
//! per face and edge (module doc of [`crate::mesh::kabsch`]): at level 2, 5 rotations
//! for the 15 fine vertices around a cloth vertex that are not cloth vertices. It is
//! their own rotation up to rounding (measured on the Detail bench: the stain moves by
//! 4.5e-15 of its peak). The 16 fine faces of a coarse face at level 2 are congruent
//! (translates of one lattice triangle and of its point reflection): they share their
//! tip angles (the transport's `atan2`s) and their median-dual area vectors (the
//! fluxes), computed once per coarse face in the window (the stain moves by 5e-14 of its
//! peak).

use std::borrow::Cow;
use std::time::Instant;

use faer::Par;
use glam::{DMat3, DVec2, DVec3};
use rayon::prelude::*;

use super::check::{check_each_nonnegative, check_each_unit, check_length};
use super::diffuse::{Conductivity, WovenFaces};
use super::pool;
use super::simulate::{Profile, Simulator, StainParams};
use super::state::{Fields, Totals};
use crate::error::{Error, ParamError};
use crate::mesh::geometry::{check_positions, vertex_area, vertex_areas, vertex_areas_par};
use crate::mesh::refine::Partial;
use crate::mesh::{OneRings, RingAdjacency, Topology, VertexFrames};

/// Coarse rings of faces built beyond the corners of a window that reached the edge of
/// the built part (module doc): room for the window to grow a few frames before the next
/// build (each grows the simulator's mesh and costs a window rebuild).
pub(crate) const GROWTH_RINGS: usize = 4;

/// The stain simulator at a Detail level: the cloth's own simulator at level 0, or one on
/// the refined cloth read and driven at the cloth's vertices (module doc).
#[derive(Debug)]
pub struct Detailed {
    sim: Simulator,
    fine: Option<Fine>,
}

/// The part of the refinement built so far and the cloth's state the transfers and the
/// lazy building need (per cloth vertex or face: `O(cloth)`).
#[derive(Debug)]
struct Fine {
    partial: Partial,
    /// Per cloth face: walked against its vertex order in the cloth's harmonized
    /// orientation (fine faces take their cloth face's).
    flipped: Vec<bool>,
    /// The cloth's conductivity (per cloth face).
    conductivity: Conductivity,
    rest: Vec<DVec3>,
    /// The cloth's positions at the start, now, and at the frame before.
    first: Vec<DVec3>,
    current: Vec<DVec3>,
    previous: Option<Vec<DVec3>>,
    /// The last [`Detailed::set_velocity_world`]: the cloth's positions then, the time,
    /// and the world velocities (what vertices built later start from).
    reference: Option<(Vec<DVec3>, f64, Vec<DVec3>)>,
    /// Lumped areas of the cloth's vertices at the current frame.
    area: Vec<f64>,
}

/// What a growth computes per built vertex or face beside the topology ([`Fine::grow`]).
struct Side {
    flipped: Vec<bool>,
    irregular: Option<Vec<f64>>,
    rest: Vec<DVec3>,
    positions: Vec<DVec3>,
    previous: Option<Vec<DVec3>>,
    /// Positions, time and world velocities a never-stepped vertex starts from.
    at: Vec<DVec3>,
    t_ref: f64,
    world: Option<Vec<DVec3>>,
    boundary: Vec<bool>,
    congruent: Vec<u32>,
    face_congruent: Vec<u32>,
    conductivity: Conductivity,
}

impl Fine {
    fn conductivity(&self) -> Conductivity {
        let p = &self.partial;
        match &self.conductivity {
            Conductivity::Isotropic(d) => Conductivity::Isotropic(*d),
            Conductivity::Woven(w) => Conductivity::Woven(WovenFaces {
                tensor: p.face_values(&w.tensor),
                uv: p.face_uv(&w.uv),
                angle: p.face_values(&w.angle),
            }),
        }
    }

    /// Builds the cloth faces `faces` and puts the simulator on the grown part (module
    /// doc): the mesh and everything per vertex rebuilt or extended, the new vertices and
    /// those whose one-ring was incomplete reset, the window dropped.
    fn grow(&mut self, sim: &mut Simulator, faces: &[u32]) -> Result<(), Error> {
        let p = &mut self.partial;
        let old_n = p.n_vertices();
        let mut reset: Vec<usize> = (0..old_n).filter(|&j| !p.is_complete(j)).collect();
        if p.build(faces) == 0 {
            return Ok(());
        }
        let p = &self.partial;
        let n = p.n_vertices();
        reset.extend(old_n..n);
        // only the new faces' topology and the fans that changed (module doc); beside
        // the topology, what does not need it
        let this = &*self;
        let (old, params) = (&sim.cloth, &sim.params);
        let (topology, side) = rayon::join(
            || p.extended_topology(&old.topology),
            || {
                let rest = p.prolong(&this.rest);
                let (at, t_ref, world) = match &this.reference {
                    Some((at, t, u)) => (p.prolong(at), *t, Some(p.prolong(u))),
                    None => (p.prolong(&this.first), 0.0, None),
                };
                Side {
                    flipped: p.face_values(&this.flipped),
                    irregular: params
                        .irregularity
                        .is_on()
                        .then(|| params.irregularity.multiplier(&rest)),
                    rest,
                    positions: p.prolong(&this.current),
                    previous: this.previous.as_ref().map(|q| p.prolong(q)),
                    at,
                    t_ref,
                    world,
                    boundary: p.boundary(),
                    congruent: p.congruence(),
                    face_congruent: p.face_congruence(),
                    conductivity: this.conductivity(),
                }
            },
        );
        let (topology, old_new) = topology?;
        let Side {
            flipped,
            irregular,
            rest,
            positions,
            previous,
            at,
            t_ref,
            world,
            boundary,
            congruent,
            face_congruent,
            conductivity,
        } = side;
        // the fans beside the neighbour lists (independent)
        let (rings, adjacency) = rayon::join(
            || {
                if old_new.is_empty() {
                    OneRings::with_orientation(&topology, flipped)
                } else {
                    OneRings::extended(&old.rings, &topology, flipped, &old_new)
                }
            },
            || RingAdjacency::new(&topology),
        );
        // the rest frames, frames and areas of the reset vertices, in one pass (a vertex not
        // reset had its whole ring: it keeps its own); each area summed over its faces in
        // face order, as `vertex_areas` does
        let faces = topology.faces();
        let reset_state: Vec<(DMat3, DMat3, f64)> = reset
            .par_iter()
            .map(|&j| {
                let rest_frame = VertexFrames::frame_of(&rings, &rest, j);
                let frame = adjacency.rotation(&rest, &at, j) * rest_frame;
                let mut around: Vec<u32> = rings.wedges(j).iter().map(|w| w.face).collect();
                around.sort_unstable();
                let area = vertex_area(around.iter().map(|&f| faces[f as usize]), &positions);
                (rest_frame, frame, area)
            })
            .collect();
        let c = &mut sim.cloth;
        // the rest frames extended in place (the old part's were replaced, not copied)
        let rest_frames = &mut c.rest_frames.frame;
        rest_frames.resize(n, DMat3::IDENTITY);
        for (&j, state) in reset.iter().zip(&reset_state) {
            rest_frames[j] = state.0;
        }
        c.irregular = irregular;
        c.boundary = boundary;
        c.congruent = Some(congruent);
        c.face_congruent = Some(face_congruent);
        c.conductivity = conductivity;
        c.rest = rest;
        c.rings = rings;
        c.adjacency = adjacency;
        sim.loose = topology.loose_vertices();
        c.topology = topology;

        let st = &mut sim.state;
        st.previous = previous;
        st.positions = positions;
        st.frames.frame.resize(n, DMat3::IDENTITY);
        st.stamp.resize(n, t_ref);
        st.vertex_area.resize(n, 0.0);
        st.velocity.resize(n, DVec2::ZERO);
        st.is_stained.resize(n, false);
        let f = &mut st.fields;
        for v in [
            &mut f.free_solvent,
            &mut f.solute,
            &mut f.absorbed_solvent,
            &mut f.absorbed_solute,
            &mut f.adsorbed,
        ] {
            v.resize(n, 0.0);
        }
        for c in [&mut f.color_free, &mut f.color_held].into_iter().flatten() {
            c.resize(n, [0.0; 3]);
        }
        for (j, (_, frame, area)) in reset.into_iter().zip(reset_state) {
            st.frames.frame[j] = frame;
            st.stamp[j] = t_ref;
            let to_local = |w: DVec3| DVec2::new(w.dot(frame.x_axis), w.dot(frame.y_axis));
            st.velocity[j] = world.as_ref().map_or(DVec2::ZERO, |u| to_local(u[j]));
            st.vertex_area[j] = area;
        }
        // the window goes (its mesh is the old part's); its solvers' memory serves the next
        if let Some(cg) = sim.window.take().and_then(|w| w.cg) {
            sim.spare = Some(cg);
        }
        sim.rescan = true;
        sim.prepared = false;
        Ok(())
    }

    /// Builds the faces around the cloth vertices where `values` is positive.
    fn grow_around(
        &mut self,
        sim: &mut Simulator,
        positive: impl Fn(usize) -> bool,
    ) -> Result<(), Error> {
        let n = self.partial.coarse().n_vertices();
        let faces: Vec<u32> = (0..n)
            .filter(|&v| positive(v))
            .flat_map(|v| self.partial.faces_around(v).to_vec())
            .collect();
        self.grow(sim, &faces)
    }

    /// Finds the window of the next frame, building faces until its active and held
    /// vertices all have their whole one-rings (module doc); the window is built once,
    /// on the grown part (a window kept from the last frame was built that way).
    fn prepare(&mut self, sim: &mut Simulator) -> Result<(), Error> {
        let clock = Instant::now();
        loop {
            let plan = sim.plan_window();
            let p = &self.partial;
            let complete = plan.whole().is_none_or(|mut w| w.all(|v| p.is_complete(v)));
            if complete {
                let rebuilt = sim.build_window(plan)?;
                sim.profile.window_rebuilds += usize::from(rebuilt);
                break;
            }
            let whole: Vec<usize> = plan.whole().into_iter().flatten().collect();
            let coarse = p.coarse();
            let mut mark = vec![false; coarse.n_vertices()];
            let mut seeds = Vec::new();
            for &v in &whole {
                for c in p.corners(v) {
                    if !std::mem::replace(&mut mark[c as usize], true) {
                        seeds.push(c);
                    }
                }
            }
            for _ in 0..GROWTH_RINGS {
                let mut next = Vec::new();
                for &v in &seeds {
                    for &e in coarse.vertex_edges(v as usize) {
                        let u = coarse.other_end(e as usize, v as usize);
                        if !std::mem::replace(&mut mark[u as usize], true) {
                            next.push(u);
                        }
                    }
                }
                seeds.extend(next);
            }
            let faces: Vec<u32> = seeds
                .iter()
                .flat_map(|&v| p.faces_around(v as usize).to_vec())
                .collect();
            self.grow(sim, &faces)?;
        }
        sim.prepared = true;
        sim.profile.window += clock.elapsed().as_secs_f64();
        Ok(())
    }
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
        let mut partial = Partial::new(&topology, level)?;
        params.validate()?;
        conductivity.validate(topology.n_faces())?;
        check_positions(&topology, rest)?;
        check_positions(&topology, positions)?;
        // the simulator needs a mesh: the first cloth face until liquid comes (module doc)
        partial.build(&[0]);
        let mut fine = Fine {
            flipped: OneRings::new(&topology).face_flipped().to_vec(),
            conductivity,
            rest: rest.to_vec(),
            first: positions.to_vec(),
            current: positions.to_vec(),
            previous: None,
            reference: None,
            area: vertex_areas(&topology, positions),
            partial,
        };
        let p = &fine.partial;
        let mut sim = Simulator::new(
            p.topology()?,
            &p.prolong(rest),
            &p.prolong(positions),
            fine.conductivity(),
            params,
            solute_color,
            par,
        )?;
        // the fans in the cloth's orientation and the cloth's border: rebuilt on the same part
        fine.partial = Partial::new(&topology, level)?;
        fine.grow(&mut sim, &[0])?;
        Ok(Self {
            sim,
            fine: Some(fine),
        })
    }

    /// The Detail level.
    pub fn level(&self) -> u32 {
        self.fine.as_ref().map_or(0, |f| f.partial.level())
    }
    /// The simulator doing the work (on the part of the refined cloth built so far above
    /// level 0, its vertices numbered in the order they were built).
    pub fn fine(&self) -> &Simulator {
        &self.sim
    }
    /// Vertices of the whole refined cloth (the cloth's at level 0): the length of the
    /// `fine_…` read-outs.
    pub fn n_fine_vertices(&self) -> usize {
        self.fine
            .as_ref()
            .map_or(self.sim.topology().n_vertices(), |f| f.partial.n_full())
    }
    /// Fine vertices built so far (all of the cloth's at level 0).
    pub fn n_built_vertices(&self) -> usize {
        self.sim.topology().n_vertices()
    }
    /// Cloth faces refined so far (all at level 0).
    pub fn n_built_faces(&self) -> usize {
        self.fine
            .as_ref()
            .map_or(self.sim.topology().n_faces(), |f| f.partial.n_built_faces())
    }
    /// The cloth's topology.
    pub fn topology(&self) -> &Topology {
        match &self.fine {
            Some(f) => f.partial.coarse(),
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

    /// [`Simulator::step`] to the cloth's `positions` (and `after`).
    pub fn step(
        &mut self,
        positions: &[DVec3],
        dt: f64,
        after: Option<&[DVec3]>,
    ) -> Result<(), Error> {
        self.step_until(positions, dt, after.map(|a| (a, dt)))
    }

    /// [`Simulator::step_until`] to the cloth's `positions` (and `after`, that many
    /// seconds later).
    pub fn step_until(
        &mut self,
        positions: &[DVec3],
        dt: f64,
        after: Option<(&[DVec3], f64)>,
    ) -> Result<(), Error> {
        let Some(fine) = &mut self.fine else {
            return self.sim.step_until(positions, dt, after);
        };
        check_positions(fine.partial.coarse(), positions)?;
        if let Some((a, h)) = after {
            super::check::check_range("time step after", h, h > 0.0, "finite and > 0")?;
            check_positions(fine.partial.coarse(), a)?;
        }
        super::check::check_range("time step", dt, dt > 0.0, "finite and > 0")?;
        // in the rayon pool, as `Simulator::step` runs its frame: the parallel loops of a
        // growth, a window build and the placement then start from a worker
        let sim = &mut self.sim;
        rayon::scope(|_| {
            // a frame whose liquid outran its window is tried again on a wider one,
            // which may need more of the refined cloth
            loop {
                fine.prepare(sim)?;
                let r = &fine.partial;
                let after = after.map(|(a, h)| (r.prolong(a), h));
                if sim.try_frame(
                    &r.prolong(positions),
                    dt,
                    after.as_ref().map(|(a, h)| (&a[..], *h)),
                )? {
                    break;
                }
            }
            fine.previous = Some(std::mem::replace(&mut fine.current, positions.to_vec()));
            let p = &fine.partial;
            fine.area = vertex_areas_par(p.coarse(), positions, |v| p.faces_around(v));
            Ok(())
        })
    }

    /// [`Simulator::add_liquid`] with `solvent` per cloth vertex (kg/m²), spread over the
    /// fine vertices by mass (module doc).
    pub fn add_liquid(
        &mut self,
        solvent: &[f64],
        concentration: f64,
        color: Option<[f64; 3]>,
    ) -> Result<(), Error> {
        let Some(fine) = &mut self.fine else {
            return Ok(self.sim.add_liquid(solvent, concentration, color)?);
        };
        check_length("added solvent", fine.area.len(), solvent.len())?;
        check_each_nonnegative("added solvent", solvent)?;
        fine.grow_around(&mut self.sim, |v| solvent[v] > 0.0)?;
        let spread = fine.partial.prolong(solvent);
        Ok(self.sim.add_liquid(&spread, concentration, color)?)
    }

    /// Pours a pool: the liquid the cloth's `weights` (in `[0, 1]`) hold at `amount`
    /// kg/m², `M = amount Σ w_i A_i`, laid `amount` deep where they are highest, on the
    /// refined cloth's vertices, its edge free of the cloth's mesh (`pool`'s module doc),
    /// then [`Simulator::add_liquid`] with `concentration` and `color`.
    pub fn add_pool(
        &mut self,
        weights: &[f64],
        amount: f64,
        concentration: f64,
        color: Option<[f64; 3]>,
    ) -> Result<(), Error> {
        check_length("pool weights", self.topology().n_vertices(), weights.len())?;
        check_each_unit("pool weight", weights)?;
        super::check::check_range("pool amount", amount, amount >= 0.0, "finite and ≥ 0")?;
        // where the interpolated weights reach: the cloth's vertices, or the refined
        // cloth's, built around the painted ones first
        let reach = match &mut self.fine {
            None => Cow::Borrowed(weights),
            Some(fine) => {
                fine.grow_around(&mut self.sim, |v| weights[v] > 0.0)?;
                Cow::Owned(fine.partial.prolong(weights))
            }
        };
        let area = pool::areas(&self.sim, &reach);
        let painted = match &self.fine {
            None => pool::Painted {
                at: self.sim.positions(),
                weight: weights,
                area: &area,
            },
            Some(fine) => pool::Painted {
                at: &fine.current,
                weight: weights,
                area: &fine.area,
            },
        };
        let laid = pool::pool(&painted, amount, self.sim.positions(), &reach, &area);
        Ok(self.sim.add_liquid(&laid, concentration, color)?)
    }

    /// [`Simulator::splash`] with `weight` per cloth vertex (interpolated).
    pub fn splash(
        &mut self,
        center: DVec3,
        speed: f64,
        seed: u64,
        weight: &[f64],
    ) -> Result<(), Error> {
        let Some(fine) = &mut self.fine else {
            return Ok(self.sim.splash(center, speed, seed, weight)?);
        };
        check_length("splash weights", fine.area.len(), weight.len())?;
        check_each_nonnegative("splash weight", weight)?;
        fine.grow_around(&mut self.sim, |v| weight[v] > 0.0)?;
        let spread = fine.partial.prolong(weight);
        Ok(self.sim.splash(center, speed, seed, &spread)?)
    }

    /// [`Simulator::set_velocity_world`] with one world vector per cloth vertex
    /// (interpolated; vertices built later start from it, module doc).
    pub fn set_velocity_world(&mut self, velocity: &[DVec3]) -> Result<(), ParamError> {
        let Some(fine) = &mut self.fine else {
            return self.sim.set_velocity_world(velocity);
        };
        check_length("velocity", fine.area.len(), velocity.len())?;
        if let Some(index) = velocity.iter().position(|u| !u.is_finite()) {
            return Err(ParamError::NonFinite {
                name: "velocity",
                index,
            });
        }
        let spread = fine.partial.prolong(velocity);
        self.sim.set_velocity_world(&spread)?;
        fine.reference = Some((fine.current.clone(), self.sim.time(), velocity.to_vec()));
        Ok(())
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
        let r = |m: &[f64]| fine.partial.restrict(m);
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
                divide(&fine.partial.restrict(&wet), &fine.area)
            }
        }
    }

    /// Total solute density (dissolved + absorbed + adsorbed) per cloth vertex, kg/m².
    pub fn solute_density(&self) -> Vec<f64> {
        match &self.fine {
            None => self.sim.solute_density(),
            Some(fine) => divide(
                &fine.partial.restrict(&total_solute(self.sim.fields())),
                &fine.area,
            ),
        }
    }

    /// Adsorbed solute density (the permanent deposit) per cloth vertex, kg/m².
    pub fn deposit(&self) -> Vec<f64> {
        match &self.fine {
            None => self.sim.deposit(),
            Some(fine) => divide(
                &fine.partial.restrict(&self.sim.fields().adsorbed),
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
            return vec![base; fine.area.len()];
        };
        let r = &fine.partial;
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
    /// vertex; one not built yet has the velocity it was set, or none).
    pub fn velocity_world(&self) -> Vec<DVec3> {
        let st = &self.sim.state;
        let Some(fine) = &self.fine else {
            return self.sim.velocity_world();
        };
        let p = &fine.partial;
        (0..fine.area.len())
            .map(|i| match p.at_vertex(i).filter(|&j| p.is_complete(j)) {
                Some(j) => st.frames.to_world(j, st.velocity[j]),
                None => fine.reference.as_ref().map_or(DVec3::ZERO, |r| r.2[i]),
            })
            .collect()
    }

    /// Per vertex of the whole refined cloth (numbered as [`crate::mesh::Refinement`]
    /// numbers it), the fine simulator's `values` of the built vertices, `fill` elsewhere.
    fn fine_values<T: Copy>(&self, values: Vec<T>, fill: T) -> Vec<T> {
        let Some(fine) = &self.fine else {
            return values;
        };
        let mut out = vec![fill; fine.partial.n_full()];
        for (&g, v) in fine.partial.global().iter().zip(values) {
            out[g as usize] = v;
        }
        out
    }
    /// Liquid density per vertex of the whole refined cloth, kg/m² (0 where nothing was
    /// built).
    pub fn fine_wetness(&self) -> Vec<f64> {
        self.fine_values(self.sim.wetness(), 0.0)
    }
    /// Total solute density per vertex of the whole refined cloth, kg/m².
    pub fn fine_solute_density(&self) -> Vec<f64> {
        self.fine_values(self.sim.solute_density(), 0.0)
    }
    /// Deposit density per vertex of the whole refined cloth, kg/m².
    pub fn fine_deposit(&self) -> Vec<f64> {
        self.fine_values(self.sim.deposit(), 0.0)
    }
    /// Solute colour per vertex of the whole refined cloth (the liquid's where there is
    /// none).
    pub fn fine_solute_color(&self) -> Vec<[f64; 3]> {
        self.fine_values(self.sim.solute_color(), self.sim.solute_color)
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
