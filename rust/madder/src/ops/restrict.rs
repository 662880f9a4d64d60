//! Operators restricted to a set of vertices, and the `2×2` block expansion of a scalar
//! operator into the connection (Bochner) Laplacian (seed §4.3.3, eq. 4.6).
//!
//! **Restriction.** A stain covers a small part of the cloth, so the simulator solves its
//! diffusions on the *active* vertices only (`crate::stain::window`). The restricted
//! operator `K_A` keeps the stiffness `K_ij` of every edge with both ends active and
//! recomputes each diagonal as minus the sum of its row's kept off-diagonals:
//!
//! ```text
//! (K_A)_ij = K_ij  (i ~ j, both active),      (K_A)_ii = −Σ_{j active} K_ij,
//! ```
//!
//! a Neumann (no-flux) boundary at the region's edge: `1ᵀ K_A = 0`, so the restricted
//! `(M + h K_A) σ' = m` conserves mass exactly like the whole one. [`Restriction`] holds
//! the sub-pattern (fixed while the active set is) and assembles `M + K_A` from the whole
//! mesh's stiffness each step ([`Restriction::scalar_values`]). For the velocity's
//! viscosity the edge weights may be clamped (`K_ij ≤ 0`, i.e. `L_ij ≥ 0`): with negative
//! weights `K_∇` can be indefinite ([`super::bochner`]), and clamped it is positive
//! semi-definite on every mesh.
//!
//! **Block expansion.** The Bochner matrix is the scalar one with every entry a `2×2`
//! block: `(K_∇)_ii = K_ii I₂`, `(K_∇)_ij = K_ij R_ij` (module doc of
//! [`super::bochner`]). [`block_pattern`] expands a lower-triangle scalar pattern
//! (column `j`: its diagonal, then its rows `b > j`) into columns `2j`, `2j+1`, each holding
//! its diagonal then rows `2b, 2b+1` (the diagonal block's zero off-diagonal is not
//! stored), and [`block_values`] fills it from the scalar values and the transport's
//! angle per edge. The whole mesh's [`super::BochnerPattern`] and a restriction use the
//! same two functions, so the operator of eq. 4.6 is assembled in one place.

use std::sync::OnceLock;

use rayon::prelude::*;

use super::{LowerCsc, VertexPattern};
use crate::mesh::{Topology, Transport};

/// A lower-triangle CSC pattern built at run time (a restriction or a block expansion).
#[derive(Debug, Clone)]
pub struct CscPattern {
    n: usize,
    col_ptr: Vec<u32>,
    row_idx: Vec<u32>,
}

impl LowerCsc for CscPattern {
    fn n(&self) -> usize {
        self.n
    }
    fn col_ptr(&self) -> &[u32] {
        &self.col_ptr
    }
    fn row_idx(&self) -> &[u32] {
        &self.row_idx
    }
}

impl CscPattern {
    /// The pattern of the lower-triangle entries `keys`, each `column << 32 | row` with
    /// `row ≥ column` (repeats allowed; the caller includes the diagonal).
    pub(crate) fn from_keys(n: usize, mut keys: Vec<u64>) -> Self {
        keys.par_sort_unstable();
        keys.dedup();
        let mut col_ptr = vec![0u32; n + 1];
        let mut row_idx = Vec::with_capacity(keys.len());
        for &k in &keys {
            col_ptr[(k >> 32) as usize + 1] += 1;
            row_idx.push(k as u32);
        }
        for c in 0..n {
            col_ptr[c + 1] += col_ptr[c];
        }
        Self {
            n,
            col_ptr,
            row_idx,
        }
    }

    /// The column pointers and row indices.
    pub(crate) fn into_parts(self) -> (Vec<u32>, Vec<u32>) {
        (self.col_ptr, self.row_idx)
    }
}

/// Where entry `(r, c)` (`r ≥ c`) is stored in the lower-triangle pattern `col_ptr`,
/// `row_idx`; panics if it is not in it (a programming error).
pub(crate) fn entry_index(col_ptr: &[u32], row_idx: &[u32], r: u32, c: u32) -> usize {
    let (s, e) = (
        col_ptr[c as usize] as usize,
        col_ptr[c as usize + 1] as usize,
    );
    s + row_idx[s..e]
        .binary_search(&r)
        .expect("entry is in the pattern")
}

/// The `2×2` block expansion of the lower-triangle `scalar` pattern whose every column
/// starts with its diagonal (module doc).
pub(crate) fn block_pattern(scalar: &impl LowerCsc) -> CscPattern {
    let (cp, ri) = (scalar.col_ptr(), scalar.row_idx());
    let n = scalar.n();
    let mut col_ptr = Vec::with_capacity(2 * n + 1);
    col_ptr.push(0u32);
    let mut row_idx = Vec::with_capacity(4 * ri.len());
    for j in 0..n {
        for c in 0..2 {
            row_idx.push((2 * j + c) as u32);
            for &r in &ri[cp[j] as usize + 1..cp[j + 1] as usize] {
                row_idx.extend([2 * r, 2 * r + 1]);
            }
            col_ptr.push(row_idx.len() as u32);
        }
    }
    CscPattern {
        n: 2 * n,
        col_ptr,
        row_idx,
    }
}

/// Values of the block expansion ([`block_pattern`]) of the scalar matrix `values` on
/// `scalar`: diagonal blocks `v I₂`, and for the entry of edge `e = entry_edge[s]` the
/// block `(b, a) = K_ab R_abᵀ = K [c s; −s c]` with `[c, s] = cos_sin[e]` (the
/// transport's rotation of that edge). `entry_edge` is ignored on the diagonals.
pub(crate) fn block_values(
    scalar: &impl LowerCsc,
    values: &[f64],
    entry_edge: &[u32],
    cos_sin: &[[f64; 2]],
) -> Vec<f64> {
    let cp = scalar.col_ptr();
    let mut out = Vec::with_capacity(4 * values.len());
    for j in 0..scalar.n() {
        let (lo, hi) = (cp[j] as usize, cp[j + 1] as usize);
        for c in 0..2 {
            out.push(values[lo]);
            for s in lo + 1..hi {
                let k = values[s];
                let [cos, sin] = cos_sin[entry_edge[s] as usize];
                if c == 0 {
                    out.extend([k * cos, -k * sin]);
                } else {
                    out.extend([k * sin, k * cos]);
                }
            }
        }
    }
    out
}

/// The edge of every off-diagonal entry of `pattern` (`u32::MAX` on the diagonal): the
/// inverse of [`VertexPattern::edge_slot`].
pub(crate) fn entry_edges(pattern: &VertexPattern) -> Vec<u32> {
    let mut edge = vec![u32::MAX; pattern.nnz()];
    for (e, &s) in pattern.edge_slot().iter().enumerate() {
        edge[s as usize] = e as u32;
    }
    edge
}

/// A mesh operator restricted to the vertices of a mask, Neumann at its edge (module
/// doc): the sub-pattern of the scalar operator and its block expansion.
#[derive(Debug)]
pub struct Restriction {
    /// The kept vertices, increasing (local vertex `j` is mesh vertex `vertices[j]`).
    pub vertices: Vec<u32>,
    /// Per mesh vertex: kept or not.
    pub mask: Vec<bool>,
    /// Lower triangle of the restricted scalar operator, local numbering.
    scalar: CscPattern,
    /// Per entry of `scalar`: its mesh edge (`u32::MAX` on the diagonal).
    edge: Vec<u32>,
    /// The `2×2` block expansion of `scalar` (the Bochner system), made when first asked
    /// for (the simulator applies the blocks from the scalar values instead).
    bochner: OnceLock<CscPattern>,
    /// Per mesh edge: its entry in `scalar` (`u32::MAX` if an end is not kept).
    edge_entry: Vec<u32>,
}

impl Restriction {
    /// The restriction of `pattern` to the vertices flagged in `mask`: column `j` (mesh
    /// vertex `a`) holds its diagonal, then the edges `(a, b)`, `b > a`, with `b` kept, in
    /// the order of the mesh pattern (local numbers increase with mesh numbers).
    pub fn new(pattern: &VertexPattern, mask: Vec<bool>) -> Self {
        let slot_edge = entry_edges(pattern);
        let vertices: Vec<u32> = (0..mask.len() as u32)
            .filter(|&v| mask[v as usize])
            .collect();
        let nv = vertices.len();
        let mut local = vec![u32::MAX; mask.len()];
        for (j, &v) in vertices.iter().enumerate() {
            local[v as usize] = j as u32;
        }
        let (cp, ri) = (pattern.col_ptr(), pattern.row_idx());
        let mut col_ptr = Vec::with_capacity(nv + 1);
        col_ptr.push(0u32);
        let (mut row_idx, mut edge) = (Vec::new(), Vec::new());
        for (j, &a) in vertices.iter().enumerate() {
            row_idx.push(j as u32);
            edge.push(u32::MAX);
            for s in cp[a as usize] as usize + 1..cp[a as usize + 1] as usize {
                let b = local[ri[s] as usize];
                if b != u32::MAX {
                    row_idx.push(b);
                    edge.push(slot_edge[s]);
                }
            }
            col_ptr.push(row_idx.len() as u32);
        }
        let scalar = CscPattern {
            n: nv,
            col_ptr,
            row_idx,
        };
        let mut edge_entry = vec![u32::MAX; pattern.edge_slot().len()];
        for (s, &e) in edge.iter().enumerate() {
            if e != u32::MAX {
                edge_entry[e as usize] = s as u32;
            }
        }
        Self {
            vertices,
            mask,
            scalar,
            edge,
            bochner: OnceLock::new(),
            edge_entry,
        }
    }

    /// The restricted scalar pattern (local numbering).
    pub fn scalar(&self) -> &CscPattern {
        &self.scalar
    }

    /// Its `2×2` block expansion, the pattern of the restricted Bochner system.
    pub fn bochner(&self) -> &CscPattern {
        self.bochner.get_or_init(|| block_pattern(&self.scalar))
    }

    /// Lower-triangle values of `M + K_A` on the scalar sub-pattern from the mesh
    /// stiffness `full` (on `pattern`, without mass) and the mesh's lumped areas `area`:
    /// the off-diagonals of the edges inside the restriction (clamped at `≤ 0` if
    /// `clamp`), each diagonal `A_i` minus the sum of its row's kept off-diagonals
    /// (Neumann: no flux out, `1ᵀK_A = 0`).
    pub fn scalar_values(
        &self,
        pattern: &VertexPattern,
        full: &[f64],
        area: &[f64],
        clamp: bool,
    ) -> Vec<f64> {
        let cp = &self.scalar.col_ptr;
        let mut values = vec![0.0; self.scalar.row_idx.len()];
        for j in 0..self.vertices.len() {
            for s in cp[j] as usize + 1..cp[j + 1] as usize {
                values[s] = full[pattern.edge_slot()[self.edge[s] as usize] as usize];
            }
        }
        self.close_rows(&mut values, area, clamp);
        values
    }

    /// Given the off-diagonal entries of a restricted system, clamps them (if `clamp`,
    /// positive ones to 0) and sets each diagonal to the vertex's `area` minus its row's
    /// off-diagonal sum (Neumann rows), summed column by column in pattern order.
    fn close_rows(&self, values: &mut [f64], area: &[f64], clamp: bool) {
        let (cp, ri) = (&self.scalar.col_ptr, &self.scalar.row_idx);
        let nv = self.vertices.len();
        let mut row = vec![0.0; nv];
        for j in 0..nv {
            for s in cp[j] as usize + 1..cp[j + 1] as usize {
                let k = &mut values[s];
                if clamp && *k > 0.0 {
                    *k = 0.0;
                }
                row[j] += *k;
                row[ri[s] as usize] += *k;
            }
        }
        for (j, &v) in self.vertices.iter().enumerate() {
            values[cp[j] as usize] = area[v as usize] - row[j];
        }
    }

    /// [`Restriction::scalar_values`] of the stiffness that [`assemble_face_weights`]
    /// (`crate::ops::cotan`) would assemble from `weights` on the whole mesh, without
    /// assembling it: only the faces with an edge inside add, in the same face order,
    /// so every value is the same to the last bit (the whole mesh's diagonal, which the
    /// restriction recomputes, is not formed).
    pub(crate) fn values_from_faces(
        &self,
        topology: &Topology,
        area: &[f64],
        clamp: bool,
        weights: impl Fn(usize) -> [f64; 3],
    ) -> Vec<f64> {
        let mut values = vec![0.0; self.scalar.row_idx.len()];
        for (f, fe) in topology.face_edges().iter().enumerate() {
            let entry = fe.map(|e| self.edge_entry[e as usize]);
            if entry.iter().all(|&s| s == u32::MAX) {
                continue;
            }
            let w = weights(f);
            for k in 0..3 {
                if entry[k] != u32::MAX {
                    values[entry[k] as usize] += w[k];
                }
            }
        }
        self.close_rows(&mut values, area, clamp);
        values
    }

    /// Per entry of [`Restriction::scalar`]: its mesh edge (`u32::MAX` on the diagonal).
    pub(crate) fn entry_edges(&self) -> &[u32] {
        &self.edge
    }

    /// Values of `M ⊗ I₂ + K_∇` on [`Restriction::bochner`] from the scalar values of
    /// [`Restriction::scalar_values`] and the transport ([`block_values`]).
    pub fn bochner_values(&self, scalar: &[f64], transport: &Transport) -> Vec<f64> {
        block_values(&self.scalar, scalar, &self.edge, transport.edge_cos_sin())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::Geometry;
    use crate::ops::cotan::{assemble_face_weights, cotan_stiffness};
    use glam::DVec3;

    /// A jittered, sheared grid (obtuse triangles: positive weights to clamp).
    fn mesh(n: usize) -> (Topology, Vec<DVec3>) {
        let pos = (0..n * n)
            .map(|v| {
                let (i, j) = ((v % n) as f64, (v / n) as f64);
                let jit = ((v * 7) % 5) as f64 * 0.02;
                DVec3::new(0.1 * (i + 0.7 * j) + jit, 0.1 * j, 0.03 * (i * j).sin())
            })
            .collect();
        let mut faces = Vec::new();
        for j in 0..n - 1 {
            for i in 0..n - 1 {
                let v = (j * n + i) as u32;
                let w = v + n as u32;
                faces.extend([[v, v + 1, w + 1], [v, w + 1, w]]);
            }
        }
        (Topology::from_triangles(n * n, faces).unwrap(), pos)
    }

    /// Assembled on the region's faces, the restricted values are those restricted from
    /// the whole mesh's stiffness, to the last bit, with and without the clamp, for the
    /// cotan weights and for per-face scaled ones.
    #[test]
    fn values_from_faces_are_the_restricted_whole_bit_for_bit() {
        let n = 12;
        let (topo, pos) = mesh(n);
        let geom = Geometry::new(&topo, &pos).unwrap();
        let pattern = VertexPattern::new(&topo);
        let mask: Vec<bool> = (0..n * n).map(|v| (v % n) * (v / n) % 5 != 1).collect();
        let region = Restriction::new(&pattern, mask);
        assert!(region.vertices.len() < n * n);
        let area = &geom.vertex_area;
        let scale: Vec<f64> = (0..topo.n_faces()).map(|f| (f % 3) as f64 * 0.5).collect();
        let cot = |f: usize| geom.face_cot[f].map(|c| -0.5 * 0.3 * c);
        let scaled = |f: usize| geom.face_cot[f].map(|c| -0.5 * 0.3 * scale[f] * c);
        let mut positive = 0;
        for clamp in [false, true] {
            let whole = cotan_stiffness(&topo, &geom, &pattern, 0.3);
            positive += whole.iter().filter(|&&k| k > 0.0).count();
            let want = region.scalar_values(&pattern, &whole, area, clamp);
            let got = region.values_from_faces(&topo, area, clamp, cot);
            assert_eq!(got.len(), want.len());
            assert!(
                got.iter()
                    .zip(&want)
                    .all(|(a, b)| a.to_bits() == b.to_bits())
            );
            let whole = assemble_face_weights(&topo, &pattern, scaled);
            let want = region.scalar_values(&pattern, &whole, area, clamp);
            let got = region.values_from_faces(&topo, area, clamp, scaled);
            assert!(
                got.iter()
                    .zip(&want)
                    .all(|(a, b)| a.to_bits() == b.to_bits())
            );
        }
        // the clamp had something to do (off-diagonals are positive on obtuse triangles)
        assert!(positive > 2, "{positive}");
    }
}
