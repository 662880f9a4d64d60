//! The state of the stain simulator (seed §4.3, §4.5): the per-vertex fields it steps and
//! their totals.
//!
//! State per vertex: the tangent velocity `u_i` (in the comoving–corotating frame `F_i`,
//! [`super::forces`]), the free solvent `σ_f` and the solute dissolved in it `σ_s` (which
//! flow), the absorbed solvent `σ_p` and absorbed solute (held in the fibres), and the
//! adsorbed solute (the permanent deposit). Densities are per unit area; the simulator
//! stores **masses** `m_i = A_i σ_i` (`A_i` the lumped vertex area) because the liquid in
//! a cloth moves with the cloth: when the mesh stretches, the masses ride on the
//! vertices and the densities are re-read on the new areas. Total solute is then a plain
//! sum that only rounding can change.
//!
//!
//! [`Fields`] are the five masses of §4.5 (and the optional colour masses), the ones the
//! interactions ([`super::interact`]) exchange. The simulator's `State` adds the velocity,
//! the vertex frames and the areas, with the bookkeeping of the window
//! ([`super::window`]): when each vertex was last stepped and which ever held liquid. A
//! frame works on a `Local` copy of its window's part and commits it only when the whole
//! frame succeeded (module doc of [`super::simulate`], "Failure").

use glam::{DVec2, DVec3};

use crate::mesh::VertexFrames;
use crate::runs;

/// The interacting fields of every vertex (masses in kg; colour masses optional).
///
/// Colour masses are solute mass × RGB colour: `color_free` accompanies `solute`,
/// `color_held` accompanies `absorbed_solute + adsorbed`. Give both or neither.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Fields {
    /// Free solvent `f` (flows).
    pub free_solvent: Vec<f64>,
    /// Dissolved solute `s` (flows with the free solvent).
    pub solute: Vec<f64>,
    /// Absorbed solvent `p` (held in the fibres).
    pub absorbed_solvent: Vec<f64>,
    /// Absorbed solute `sp` (held in the fibres).
    pub absorbed_solute: Vec<f64>,
    /// Adsorbed solute `sa` (deposited: the permanent mark).
    pub adsorbed: Vec<f64>,
    /// Colour mass of the dissolved solute.
    pub color_free: Option<Vec<[f64; 3]>>,
    /// Colour mass of the held solute `sp + sa`.
    pub color_held: Option<Vec<[f64; 3]>>,
}

impl Fields {
    /// `n` dry, clean vertices, without colour.
    pub(crate) fn zeros(n: usize) -> Self {
        Self {
            free_solvent: vec![0.0; n],
            solute: vec![0.0; n],
            absorbed_solvent: vec![0.0; n],
            absorbed_solute: vec![0.0; n],
            adsorbed: vec![0.0; n],
            color_free: None,
            color_held: None,
        }
    }

    /// The fields of the vertices `index` (in that order).
    pub(crate) fn gather(&self, index: &[u32]) -> Self {
        let mut out = Self::default();
        self.gather_into(index, &mut out);
        out
    }

    /// [`Fields::gather`] into `out` (its arrays' allocations kept), in parallel.
    pub(crate) fn gather_into(&self, index: &[u32], out: &mut Self) {
        use runs::gather_into as pick;
        pick(&self.free_solvent, index, &mut out.free_solvent);
        pick(&self.solute, index, &mut out.solute);
        pick(&self.absorbed_solvent, index, &mut out.absorbed_solvent);
        pick(&self.absorbed_solute, index, &mut out.absorbed_solute);
        pick(&self.adsorbed, index, &mut out.adsorbed);
        for (from, to) in [
            (&self.color_free, &mut out.color_free),
            (&self.color_held, &mut out.color_held),
        ] {
            match from {
                Some(from) => pick(from, index, to.get_or_insert_with(Vec::new)),
                None => *to = None,
            }
        }
    }

    /// Writes `part` (the fields of the vertices `index`, increasing, as
    /// [`Fields::gather`] gives them) back into these fields, in parallel.
    ///
    /// # Panics
    /// If `part` tracks colour and these fields do not, the lengths differ, or `index`
    /// is not increasing ([`runs::scatter_at`]).
    pub(crate) fn scatter(&mut self, index: &[u32], part: &Fields) {
        use runs::scatter_at as put;
        put(&mut self.free_solvent, index, &part.free_solvent);
        put(&mut self.solute, index, &part.solute);
        put(&mut self.absorbed_solvent, index, &part.absorbed_solvent);
        put(&mut self.absorbed_solute, index, &part.absorbed_solute);
        put(&mut self.adsorbed, index, &part.adsorbed);
        for (to, from) in [
            (&mut self.color_free, &part.color_free),
            (&mut self.color_held, &part.color_held),
        ] {
            if let Some(from) = from {
                put(
                    to.as_mut().expect("colour tracked in the part only"),
                    index,
                    from,
                );
            }
        }
    }

    /// Whether vertex `i` holds liquid or solute that can still change (anything but
    /// the adsorbed deposit).
    pub(crate) fn is_live(&self, i: usize) -> bool {
        self.free_solvent[i] > 0.0
            || self.solute[i] > 0.0
            || self.absorbed_solvent[i] > 0.0
            || self.absorbed_solute[i] > 0.0
    }

    /// `Σ_i (s_i + sp_i + sa_i)`, in vertex order.
    pub(crate) fn total_solute(&self) -> f64 {
        self.solute
            .iter()
            .zip(&self.absorbed_solute)
            .zip(&self.adsorbed)
            .fold(0.0, |acc, ((s, sp), sa)| acc + (s + sp + sa))
    }

    /// `Σ_i (f_i + p_i)`, in vertex order.
    pub(crate) fn total_solvent(&self) -> f64 {
        self.free_solvent
            .iter()
            .zip(&self.absorbed_solvent)
            .fold(0.0, |acc, (f, p)| acc + (f + p))
    }
}

/// Everything that changes during a bake (committed frame by frame).
#[derive(Debug, Clone)]
pub(super) struct State {
    pub(super) positions: Vec<DVec3>,
    pub(super) previous: Option<Vec<DVec3>>,
    /// How long the frame from `previous` to `positions` lasted, s (0 before the first).
    pub(super) previous_dt: f64,
    /// The frame of every vertex at `stamp`, the time its velocity was last stepped
    /// (vertices outside the window are not stepped: [`super::window`]).
    pub(super) frames: VertexFrames,
    pub(super) stamp: Vec<f64>,
    /// Lumped areas at the current frame of every vertex that holds anything (and of the
    /// window's vertices); other vertices keep the area they had when last needed.
    pub(super) vertex_area: Vec<f64>,
    pub(super) velocity: Vec<DVec2>,
    pub(super) fields: Fields,
    pub(super) evaporated: f64,
    /// Solvent and solute dripped off the hems since the start.
    pub(super) dripped: (f64, f64),
    pub(super) time: f64,
    /// The next sub-step's length while a ramp after a pour runs (`simulate`'s module
    /// doc, "Sub-steps after a pour"); 0 when none does.
    pub(super) ramp: f64,
    /// The last frame's longest sub-step, s (0 before the first): where a ramp starts
    /// when the frames lengthen (`simulate`'s module doc, "Sub-steps after a pour").
    pub(super) longest_substep: f64,
    /// Vertices that have ever held liquid or solute (their areas are kept current).
    pub(super) stained: Vec<u32>,
    pub(super) is_stained: Vec<bool>,
}

impl State {
    /// Adds vertex `v` to the vertices that have held liquid (once).
    pub(super) fn mark_stained(&mut self, v: usize) {
        if !self.is_stained[v] {
            self.is_stained[v] = true;
            self.stained.push(v as u32);
        }
    }
}

/// Totals over the mesh (kg), for conservation checks and reports.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Totals {
    /// Free + absorbed solvent.
    pub solvent: f64,
    /// Dissolved + absorbed + adsorbed solute.
    pub solute: f64,
    /// Solvent evaporated since the start.
    pub evaporated: f64,
    /// Solvent dripped off the cloth's hems since the start
    /// ([`super::StainParams::drip_hold`]).
    pub dripped: f64,
    /// Solute dripped off with it.
    pub dripped_solute: f64,
}

/// One frame's work on a window, committed when the whole frame succeeded.
#[derive(Debug, Default)]
pub(super) struct Local {
    pub(super) velocity: Vec<DVec2>,
    pub(super) frames: VertexFrames,
    pub(super) fields: Fields,
    pub(super) area: Vec<f64>,
    pub(super) evaporated: f64,
    /// Solvent and solute dripped during the frame.
    pub(super) dripped: (f64, f64),
    /// Transport sub-cycles of the frame's sub-steps, all together.
    pub(super) cycles: usize,
    /// What the ramp after a pour is after the frame ([`State::ramp`]).
    pub(super) ramp: f64,
    /// The frame's longest sub-step, s ([`State::longest_substep`]).
    pub(super) longest_substep: f64,
}

/// The colour masses `[r, g, b]` per vertex as three fields (what the solves take).
pub(super) fn split_rgb(c: &[[f64; 3]]) -> [Vec<f64>; 3] {
    std::array::from_fn(|k| c.iter().map(|x| x[k]).collect())
}

/// The inverse of [`split_rgb`], into `out`.
pub(super) fn merge_rgb(c: &[Vec<f64>; 3], out: &mut [[f64; 3]]) {
    for (i, o) in out.iter_mut().enumerate() {
        *o = [c[0][i], c[1][i], c[2][i]];
    }
}
