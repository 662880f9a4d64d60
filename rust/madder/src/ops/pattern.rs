//! The fixed sparsity pattern of vertex–vertex operators: lower triangle of an `N×N`
//! symmetric matrix in compressed sparse column form, with one diagonal entry per vertex
//! and one entry per mesh edge.
//!
//! Column `j` holds its diagonal first, then the rows `b > j` of the edges `(j, b)` in
//! increasing order. Because [`Topology::edges`] are sorted lexicographically, the slot of
//! an edge is computed, not searched: `slot(e = (a, b)) = col_ptr[a] + 1 + (e − first[a])`.

use crate::mesh::Topology;

/// The lower triangle (diagonal included) of the `N×N` vertex–vertex sparsity pattern of
/// a topology, compressed by columns: column `j` holds its diagonal, then the rows `b > j`
/// of its edges `(j, b)` in increasing order. Fixed for a bake (module doc of [`super`]).
#[derive(Debug, Clone)]
pub struct VertexPattern {
    n: usize,
    col_ptr: Vec<u32>,
    row_idx: Vec<u32>,
    diag_slot: Vec<u32>,
    edge_slot: Vec<u32>,
}

impl VertexPattern {
    /// The pattern of `topology`'s vertices and edges.
    pub fn new(topology: &Topology) -> Self {
        let n = topology.n_vertices();
        let edges = topology.edges();
        let mut per_col = vec![1u32; n];
        for &[a, _] in edges {
            per_col[a as usize] += 1;
        }
        let mut col_ptr = Vec::with_capacity(n + 1);
        col_ptr.push(0u32);
        for &c in &per_col {
            col_ptr.push(col_ptr.last().unwrap() + c);
        }
        let mut row_idx = vec![0u32; *col_ptr.last().unwrap() as usize];
        let diag_slot: Vec<u32> = col_ptr[..n].to_vec();
        for (j, &s) in diag_slot.iter().enumerate() {
            row_idx[s as usize] = j as u32;
        }
        let mut next = diag_slot.iter().map(|s| s + 1).collect::<Vec<u32>>();
        let edge_slot = edges
            .iter()
            .map(|&[a, b]| {
                let s = next[a as usize];
                next[a as usize] += 1;
                row_idx[s as usize] = b;
                s
            })
            .collect();
        Self {
            n,
            col_ptr,
            row_idx,
            diag_slot,
            edge_slot,
        }
    }

    /// Matrix dimension `N`.
    pub fn n(&self) -> usize {
        self.n
    }
    /// Number of stored entries (lower triangle with diagonal).
    pub(crate) fn nnz(&self) -> usize {
        self.row_idx.len()
    }
    /// Start of every column in [`Self::row_idx`] (`N + 1` entries).
    pub fn col_ptr(&self) -> &[u32] {
        &self.col_ptr
    }
    /// Row of every stored entry, column after column.
    pub fn row_idx(&self) -> &[u32] {
        &self.row_idx
    }
    /// Slot of the diagonal entry of vertex `v`.
    pub fn diag_slot(&self) -> &[u32] {
        &self.diag_slot
    }
    /// Slot of the entry of edge `e` (row `b`, column `a` for edge `(a, b)`).
    pub fn edge_slot(&self) -> &[u32] {
        &self.edge_slot
    }

    /// `y = A x` for the symmetric matrix whose lower triangle is `values`.
    #[cfg(test)]
    pub(crate) fn sym_matvec(&self, values: &[f64], x: &[f64]) -> Vec<f64> {
        assert_eq!(values.len(), self.nnz());
        let mut y = vec![0.0; self.n];
        for j in 0..self.n {
            let (lo, hi) = (self.col_ptr[j] as usize, self.col_ptr[j + 1] as usize);
            y[j] += values[lo] * x[j];
            for (&i, &v) in self.row_idx[lo + 1..hi].iter().zip(&values[lo + 1..hi]) {
                let i = i as usize;
                y[i] += v * x[j];
                y[j] += v * x[i];
            }
        }
        y
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn slots_point_at_their_rows() {
        let t = Topology::from_triangles(4, vec![[0, 1, 2], [0, 2, 3]]).unwrap();
        let p = VertexPattern::new(&t);
        assert_eq!(p.nnz(), 4 + 5);
        for (e, &[a, b]) in t.edges().iter().enumerate() {
            let s = p.edge_slot()[e] as usize;
            assert_eq!(p.row_idx()[s], b);
            assert!(
                p.col_ptr()[a as usize] as usize <= s && s < p.col_ptr()[a as usize + 1] as usize
            );
        }
        for v in 0..4 {
            assert_eq!(p.row_idx()[p.diag_slot()[v] as usize], v as u32);
        }
    }
}
