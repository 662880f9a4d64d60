//! Drips (issue 34 §1; beyond the seed, whose cloth has no free edge that liquid reaches):
//! liquid that runs down to a hanging hem leaves the cloth there, instead of piling up
//! against the border's no-flux edge and wicking back up the cloth while it dries.
//!
//! The border of the cloth at vertex `i` is its border edges `e ∋ i`, each of length
//! `|e|` with the unit normal `n_e` in its face's plane pointing out of the face. The
//! vertex's share of the border and its outward direction are
//!
//! ```text
//! L_i = Σ_e ½|e|,        b_i = Σ_e ½|e| n_e / |Σ_e ½|e| n_e|.
//! ```
//!
//! A hem *hangs* where the body force the liquid feels in the cloth's frame,
//! `g − p̈_i` (gravity less the cloth's own acceleration, [`crate::stain::forces`]), pulls it
//! out across the border within 60° of `b_i`: `(g − p̈_i)·b_i > ½|g − p̈_i|`. A hanging
//! hem holds at most `λ L_i` of free solvent, `λ` (kg/m) the liquid a hem holds per metre
//! before drops fall ([`super::StainParams::drip_hold`]); the rest drips off, with its
//! share of the free solute and of its colour (the drops carry the liquid as it is).
//! The absorbed liquid stays in the fibres, and the velocity is unchanged (it is per unit
//! of what stays). What drips is counted ([`super::Totals::dripped`] and
//! `dripped_solute`), so the mass is accounted for: on the cloth + evaporated + dripped
//! is what was poured.

use glam::DVec3;

use crate::mesh::Topology;
use crate::mesh::topology::EdgeKind;

use super::state::Fields;

/// Per vertex of `topo` at `positions`: the border's share `L_i` (m; 0 off the border)
/// and its outward unit direction `b_i` (module doc), by one pass over the faces.
pub(crate) fn border_normals(topo: &Topology, positions: &[DVec3]) -> (Vec<f64>, Vec<DVec3>) {
    let n = topo.n_vertices();
    let (mut length, mut out) = (vec![0.0; n], vec![DVec3::ZERO; n]);
    for (tri, edges) in topo.faces().iter().zip(topo.face_edges()) {
        for &e in edges {
            // a border edge of the face: its ends from the edge list, and the third corner
            let e = e as usize;
            if topo.edge_kind(e) != EdgeKind::Boundary {
                continue;
            }
            let [a, b] = topo.edges()[e];
            let c = tri
                .iter()
                .copied()
                .find(|&v| v != a && v != b)
                .expect("a triangle's third corner");
            let (pa, pb, pc) = (
                positions[a as usize],
                positions[b as usize],
                positions[c as usize],
            );
            let edge = pb - pa;
            let len = edge.length();
            if len == 0.0 {
                continue;
            }
            let t = edge / len;
            let d = pa - pc;
            // away from the third corner, in the face's plane, across the edge
            let outward = (d - d.dot(t) * t).normalize_or_zero();
            for v in [a, b] {
                length[v as usize] += 0.5 * len;
                out[v as usize] += 0.5 * len * outward;
            }
        }
    }
    for b in &mut out {
        *b = b.normalize_or_zero();
    }
    (length, out)
}

/// Drips off the hanging hem (module doc) among the vertices `on` of the fields' cloth,
/// whose border is `length`, `outward` ([`border_normals`]) and whose cloth accelerates
/// at `acceleration` under `gravity`; `hold` is `λ`, kg/m. Returns the solvent and solute
/// that dripped, kg.
pub(crate) fn drip(
    fields: &mut Fields,
    on: &[u32],
    length: &[f64],
    outward: &[DVec3],
    acceleration: &[DVec3],
    gravity: DVec3,
    hold: f64,
) -> (f64, f64) {
    let (mut solvent, mut solute) = (0.0, 0.0);
    for &j in on {
        let j = j as usize;
        let (l, f) = (length[j], fields.free_solvent[j]);
        if l == 0.0 || f <= 0.0 {
            continue;
        }
        let body = gravity - acceleration[j];
        if body.dot(outward[j]) <= 0.5 * body.length() {
            continue;
        }
        let cap = hold * l;
        if f <= cap {
            continue;
        }
        let keep = cap / f;
        solvent += f - cap;
        fields.free_solvent[j] = cap;
        let s = fields.solute[j];
        solute += s * (1.0 - keep);
        fields.solute[j] = s * keep;
        if let Some(c) = fields.color_free.as_mut() {
            for x in &mut c[j] {
                *x *= keep;
            }
        }
    }
    (solvent, solute)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A unit square of two triangles in the XZ plane (a hanging sheet), z up.
    fn square() -> (Topology, Vec<DVec3>) {
        let pos = vec![
            DVec3::new(0.0, 0.0, 0.0),
            DVec3::new(1.0, 0.0, 0.0),
            DVec3::new(1.0, 0.0, 1.0),
            DVec3::new(0.0, 0.0, 1.0),
        ];
        (
            Topology::from_triangles(4, vec![[0, 1, 2], [0, 2, 3]]).unwrap(),
            pos,
        )
    }

    #[test]
    fn the_border_points_out_of_the_cloth_and_shares_its_length() {
        let (topo, pos) = square();
        let (length, out) = border_normals(&topo, &pos);
        // each corner has two border edges of 1 m: half of each
        assert_eq!(length, vec![1.0; 4]);
        let s = std::f64::consts::FRAC_1_SQRT_2;
        assert!(
            (out[0] - DVec3::new(-s, 0.0, -s)).length() < 1e-12,
            "{}",
            out[0]
        );
        assert!(
            (out[2] - DVec3::new(s, 0.0, s)).length() < 1e-12,
            "{}",
            out[2]
        );
    }

    #[test]
    fn only_a_hanging_hem_drips_and_it_keeps_what_it_holds() {
        let (topo, pos) = square();
        let (length, out) = border_normals(&topo, &pos);
        let mut fields = Fields::zeros(4);
        fields.free_solvent = vec![2.0; 4];
        fields.solute = vec![0.2; 4];
        let g = DVec3::new(0.0, 0.0, -9.81);
        let still = vec![DVec3::ZERO; 4];
        // the bottom corners' border points 45° down: they drip to 0.5 · 1 m
        let (solvent, solute) = drip(&mut fields, &[0, 1, 2, 3], &length, &out, &still, g, 0.5);
        assert_eq!(fields.free_solvent, vec![0.5, 0.5, 2.0, 2.0]);
        assert!((solvent - 3.0).abs() < 1e-12 && (solute - 0.3).abs() < 1e-12);
        assert!((fields.solute[0] - 0.05).abs() < 1e-12 && fields.solute[2] == 0.2);
        // in free fall nothing pulls the liquid off
        let mut fields = Fields::zeros(4);
        fields.free_solvent = vec![2.0; 4];
        let falling = vec![g; 4];
        assert_eq!(
            drip(&mut fields, &[0, 1, 2, 3], &length, &out, &falling, g, 0.5),
            (0.0, 0.0)
        );
    }
}
