//! Gravity in the fibres' liquid (issue 34 §1; beyond the seed, whose wicking has no
//! weight): a hanging wet cloth drains downward while it wicks, so a run on a hanging
//! front spreads down faster than up, and a wet region rises no higher than capillarity
//! can hold it.
//!
//! # The law (Richards' equation, in densities)
//! In an unsaturated porous sheet the liquid's flux is capillary plus gravity,
//! `q = −K(θ)(∇ψ − ĝ)` (Richards 1931; Bear 1972, ch. 9): `K` the conductivity, `ψ` the
//! capillary suction head, `ĝ` the unit body force along the sheet. The wicking is the
//! capillary part written as a diffusion of the density, `D(θ) = D₀ θⁿ`
//! ([`super::Wicking`]: `D = K dψ/dθ` over the sheet's content), so with the suction's
//! scale `dψ/dθ ≈ H` the gravity part is the same conductivity over `H`, and the flux is
//! a diffusion down a potential:
//!
//! ```text
//! j = −D(θ) ∇σ + σ_w D(θ) b_t / (|g| H) = −D(θ) ∇(σ − φ),     φ = σ_w (b·x) / (|g| H),
//! ```
//!
//! with `b` the body force the liquid feels in the cloth's frame (`g − p̈`, as the drips
//! take it, [`super::drip`]; only its part along the sheet enters `∇φ`), `σ_w` the
//! density at which the wicking reaches its full rate ([`super::Wicking::density`]) and
//! `H` the **capillary height** ([`super::StainParams::capillary_height`]): the height a
//! vertical strip of the fabric wicks up from a reservoir (Jurin's `2γ cos θ_c / (ρ g r)`
//! for its pores). Where the flux vanishes, `∇σ = ∇φ`: on a vertical strip at rest
//! `∂θ/∂z = −1/H` whatever `D₀` and `n`, so the liquid settles into a wedge, `θ(z) = θ₀ −
//! z/H` (`tests/drain.rs` measures it). On a level cloth `b_t = 0` and nothing drains; in
//! free fall neither (`b = 0`).
//!
//! # The scheme: the potential inside the implicit diffusion
//! The fibres' liquid is solved by the implicit diffusion ([`super::diffuse`]); with `H`
//! its system becomes `(M + hK)σ' = m + hKφ`, the same matrix (still symmetric positive
//! definite) with a source. `Kφ` is assembled from the potential's **differences along
//! the edges**, `φ_a − φ_b = σ_w b_ab·(x_a − x_b) / (|g| H)` with `b_ab` the mean body
//! force of the edge's ends (so no origin enters where `p̈` varies over the cloth), here
//! ([`edge_steps`]): `(Kφ)_a = Σ_b w_ab (φ_a − φ_b)`, `w_ab = −K_ab`. Each edge's flux is
//! antisymmetric, so the source adds no mass and the system conserves it exactly as
//! before; the pinned edge, the Picard rounds and the halving are the diffusion's own,
//! and the steady state is exact (`σ − φ` constant where the liquid moves), which an
//! explicit drift after the solve, tried first, missed by 20–40 % on the strip at one
//! second a step (the drift moved the liquid by a row's worth each step). A Picard
//! round's trial solves leave the potential out: their factors settle as the wicking's
//! alone and the last solve adds it (with it in every round the rounds and halvings of
//! long steps multiplied, 3.6× the diffusion's time on a hanging sheet in 3-minute frames;
//! without, 1.6×). The solute
//! goes with the solvent's fluxes, now `F_ab = −h K_ab ((σ'_a − φ_a) − (σ'_b − φ_b))`, in
//! the carried solute's sweep, ordered by the solved potential (with the window's mean
//! body force for the order; an edge whose flux runs against it, where `p̈` varies, is
//! taken as the sweep takes any flux uphill). Only the fibres' liquid takes the
//! potential: the free liquid runs by the flow, with the same body force. The fibres'
//! liquid moves only where the solute is carried with the solvent
//! ([`super::StainParams::carry_solute`]), so without that nothing drains, and only in
//! the window's active region, around free liquid (as the wicking: where the cloth holds
//! only absorbed liquid, far from any free liquid, it stays put).
//!
//! **The dry front.** The wicking's face factor is the mean over the face's corners, so a
//! face with one wet corner conducts, and the potential would pull liquid out of its dry
//! upper corner: a negative mass, repaired from the neighbours' solvent without its
//! solute, which on the strip concentrated the wet rows' solute by 1 % in 600 s. So an
//! edge whose upper end holds less than the potential's step along it takes no potential
//! ([`Potential::gated`]): there the front is the wicking's alone, a thin film that
//! creeps above the wedge's end (15 mm at θ < 0.04 on the strip).
//!
//! The cloth's border holds the liquid (no flux leaves there): a hanging hem gathers it,
//! the fibres give it back as free liquid above their saturation ([`super::interact`]),
//! and that drips ([`super::drip`]).
//!
//! `H = 0` (the default) is off: no source, today's result bit for bit.

use glam::DVec3;

use crate::mesh::Topology;

/// The gravity potential of one sub-step, in the window's numbering (module doc).
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Potential {
    /// Per edge `[a, b]` of the topology, `φ_a − φ_b` (kg/m²).
    pub(crate) edge: Vec<f64>,
    /// Per vertex, `φ` with the mean body force (kg/m², up to a constant): the order of
    /// the carried solute's sweep.
    pub(crate) vertex: Vec<f64>,
}

impl Potential {
    /// The potential with the steps zeroed on the edges whose upper end (the one the step
    /// pulls the liquid from) holds less of the fibres' liquid than the step (`absorbed`
    /// densities, kg/m²): the wet front's last vertex gives nothing downhill (module doc,
    /// "The dry front").
    pub(crate) fn gated(&self, topology: &Topology, absorbed: &[f64]) -> Self {
        let edge = topology
            .edges()
            .iter()
            .zip(&self.edge)
            .map(|(&[a, b], &step)| {
                let upper = if step > 0.0 { a } else { b };
                if absorbed[upper as usize] >= step.abs() {
                    step
                } else {
                    0.0
                }
            })
            .collect();
        Self {
            edge,
            vertex: self.vertex.clone(),
        }
    }
}

/// The potential's steps along the edges of `topology` at `positions`, with `body` the
/// body force per vertex (m/s²) and `scale = σ_w / (|g| H)` (module doc); the vertex
/// potential with the mean body force of `among` (the active vertices).
pub(crate) fn edge_steps(
    topology: &Topology,
    positions: &[DVec3],
    body: &[DVec3],
    among: &[u32],
    scale: f64,
) -> Potential {
    let edge = topology
        .edges()
        .iter()
        .map(|&[a, b]| {
            let (a, b) = (a as usize, b as usize);
            scale * (0.5 * (body[a] + body[b])).dot(positions[a] - positions[b])
        })
        .collect();
    let mean = if among.is_empty() {
        DVec3::ZERO
    } else {
        among.iter().map(|&v| body[v as usize]).sum::<DVec3>() / among.len() as f64
    };
    let vertex = positions.iter().map(|&x| scale * mean.dot(x)).collect();
    Potential { edge, vertex }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_steps_are_the_potential_of_a_uniform_body_force_and_ignore_its_normal() {
        // a vertical unit square in the XZ plane, gravity down and a push across it
        let pos = [
            DVec3::new(0.0, 0.0, 0.0),
            DVec3::new(1.0, 0.0, 0.0),
            DVec3::new(1.0, 0.0, 1.0),
            DVec3::new(0.0, 0.0, 1.0),
        ];
        let topo = Topology::from_triangles(4, vec![[0, 1, 2], [0, 2, 3]]).unwrap();
        let body = [DVec3::new(0.0, 3.0, -9.81); 4];
        let p = edge_steps(&topo, &pos, &body, &[0, 1, 2, 3], 0.5);
        for (e, &[a, b]) in topo.edges().iter().enumerate() {
            let want = 0.5 * -9.81 * (pos[a as usize].z - pos[b as usize].z);
            assert!((p.edge[e] - want).abs() < 1e-15, "edge {e}");
            let (va, vb) = (p.vertex[a as usize], p.vertex[b as usize]);
            assert!(
                (va - vb - want).abs() < 1e-15,
                "edge {e}: the vertex potential's step"
            );
        }
        // in free fall (no body force) there is no potential
        let p = edge_steps(&topo, &pos, &[DVec3::ZERO; 4], &[0, 1, 2, 3], 0.5);
        assert!(p.edge.iter().chain(&p.vertex).all(|&x| x == 0.0));
    }
}
