//! A flat mesh's plane and its grid of buckets with their clearances: what proves that a
//! segment stays inside (module doc of [`super::planar`], "Proving a segment stays
//! inside").

use glam::{DMat2, DVec2, DVec3};
use rayon::prelude::*;

use super::located::{Located, clamp};
use crate::mesh::Topology;

/// Vertices farther from the plane than this fraction of the mesh's size: not flat.
pub(super) const FLAT_TOLERANCE: f64 = 1e-12;

/// Halvings of a segment before it is walked.
pub(super) const BISECTIONS: u32 = 5;

/// A flat mesh's plane, its faces in the plane's coordinates, and the bucket grid.
#[derive(Debug, Clone)]
pub(crate) struct Planar {
    pub(super) origin: DVec3,
    pub(super) u: DVec3,
    pub(super) w: DVec3,
    /// The vertices in the plane's coordinates.
    pub(super) xy: Vec<DVec2>,
    /// Per face: corner 0 and the inverse of `[x_1 − x_0, x_2 − x_0]` (barycentric 1, 2).
    pub(super) affine: Vec<(DVec2, DMat2)>,
    pub(super) lo: DVec2,
    pub(super) size: f64,
    pub(super) inv_size: f64,
    pub(super) nx: usize,
    pub(super) ny: usize,
    /// Faces per bucket (CSR: `bucket_faces[start[b]..start[b + 1]]`).
    pub(super) start: Vec<u32>,
    pub(super) bucket_faces: Vec<u32>,
    /// Per bucket: the clearance `(d − 1) s` (module doc), 0 for bad buckets.
    pub(super) clear: Vec<f64>,
}

impl Planar {
    /// The flat structure of the mesh (`None` if it is not flat, has a degenerate face or
    /// faces of both orientations, or two faces on the same side of an edge).
    pub(crate) fn new(topology: &Topology, positions: &[DVec3]) -> Option<Self> {
        let faces = topology.faces();
        let area: DVec3 = faces
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|v| positions[v as usize]);
                (b - a).cross(c - a)
            })
            .sum();
        let n = area.try_normalize()?;
        let origin = positions[faces[0][0] as usize];
        let (lo3, hi3) = positions
            .iter()
            .fold((DVec3::INFINITY, DVec3::NEG_INFINITY), |(l, h), &p| {
                (l.min(p), h.max(p))
            });
        let diameter = (hi3 - lo3).length();
        if positions
            .iter()
            .any(|&p| (p - origin).dot(n).abs() > FLAT_TOLERANCE * diameter)
        {
            return None;
        }
        let u = n.any_orthonormal_vector();
        let w = n.cross(u);
        let xy: Vec<DVec2> = positions
            .par_iter()
            .map(|&p| DVec2::new((p - origin).dot(u), (p - origin).dot(w)))
            .collect();
        // per face (in parallel): its affine map and edge lengths; `None` for a face of
        // non-positive area
        let per_face: Vec<Option<((DVec2, DMat2), f64)>> = faces
            .par_iter()
            .map(|t| {
                let [a, b, c] = t.map(|v| xy[v as usize]);
                let m = DMat2::from_cols(b - a, c - a);
                let (l1, l2) = ((b - a).length(), (c - a).length());
                // positive area, and not degenerate (the charts' own test)
                (m.determinant() > 1e-14 * l1 * l2)
                    .then(|| ((a, m.inverse()), l1 + l2 + (c - b).length()))
            })
            .collect();
        let mut affine = Vec::with_capacity(faces.len());
        // summed in face order, as before: the bucket size does not depend on the threads
        let mut edge_sum = 0.0;
        for f in per_face {
            let (map, edges) = f?;
            edge_sum += edges;
            affine.push(map);
        }
        // border edges (one face or more than two) and interior edges with both faces on
        // one side (the same direction in both)
        // per edge: its first two (face, local edge) and its number of faces
        let mut edge_faces = vec![[(0u32, 0u8); 2]; topology.n_edges()];
        let mut edge_count = vec![0u8; topology.n_edges()];
        for (f, fe) in topology.face_edges().iter().enumerate() {
            for (k, &e) in fe.iter().enumerate() {
                let c = &mut edge_count[e as usize];
                if *c < 2 {
                    edge_faces[e as usize][*c as usize] = (f as u32, k as u8);
                }
                *c = c.saturating_add(1);
            }
        }
        let ends = |(f, k): (u32, u8)| {
            let t = faces[f as usize];
            (t[(k as usize + 1) % 3], t[(k as usize + 2) % 3])
        };
        let mut border = Vec::new();
        for (e, (ef, &count)) in edge_faces.iter().zip(&edge_count).enumerate() {
            if count == 2 {
                if ends(ef[0]) != (ends(ef[1]).1, ends(ef[1]).0) {
                    return None;
                }
            } else {
                border.push(topology.edges()[e]);
            }
        }
        let (lo, hi) = xy
            .iter()
            .fold((DVec2::INFINITY, DVec2::NEG_INFINITY), |(l, h), &p| {
                (l.min(p), h.max(p))
            });
        let extent = hi - lo;
        let mean_edge = edge_sum / (3 * faces.len()) as f64;
        // about one edge per bucket, at most ~4 buckets per face
        let size = mean_edge
            .max((extent.x * extent.y / (4.0 * faces.len() as f64)).sqrt())
            .max(1e-300);
        let nx = (extent.x / size).floor() as usize + 1;
        let ny = (extent.y / size).floor() as usize + 1;
        let mut planar = Self {
            origin,
            u,
            w,
            xy,
            affine,
            lo,
            size,
            inv_size: 1.0 / size,
            nx,
            ny,
            start: Vec::new(),
            bucket_faces: Vec::new(),
            clear: Vec::new(),
        };
        planar.fill_buckets(faces);
        planar.clearances(&border);
        Some(planar)
    }

    /// The buckets `[i0, i1] × [j0, j1]` that the box `[a, b]` meets.
    pub(super) fn bucket_range(&self, a: DVec2, b: DVec2) -> (usize, usize, usize, usize) {
        let cell = |p: DVec2, pad: f64| {
            let c = (p - self.lo) / self.size + DVec2::splat(pad);
            (
                (c.x.floor().max(0.0) as usize).min(self.nx - 1),
                (c.y.floor().max(0.0) as usize).min(self.ny - 1),
            )
        };
        let (i0, j0) = cell(a.min(b), -1e-9);
        let (i1, j1) = cell(a.max(b), 1e-9);
        (i0, i1, j0, j1)
    }

    pub(super) fn fill_buckets(&mut self, faces: &[[u32; 3]]) {
        let n_buckets = self.nx * self.ny;
        let ranges: Vec<_> = faces
            .par_iter()
            .map(|t| {
                let [a, b, c] = t.map(|v| self.xy[v as usize]);
                self.bucket_range(a.min(b).min(c), a.max(b).max(c))
            })
            .collect();
        let mut count = vec![0u32; n_buckets + 1];
        for &(i0, i1, j0, j1) in &ranges {
            for j in j0..=j1 {
                for i in i0..=i1 {
                    count[j * self.nx + i + 1] += 1;
                }
            }
        }
        for b in 0..n_buckets {
            count[b + 1] += count[b];
        }
        let mut fill = count.clone();
        let mut list = vec![0u32; count[n_buckets] as usize];
        for (f, &(i0, i1, j0, j1)) in ranges.iter().enumerate() {
            for j in j0..=j1 {
                for i in i0..=i1 {
                    let b = j * self.nx + i;
                    list[fill[b] as usize] = f as u32;
                    fill[b] += 1;
                }
            }
        }
        self.start = count;
        self.bucket_faces = list;
    }

    /// Bad buckets (border edges, or a test point not covered exactly once), then the
    /// Chebyshev distance transform (two passes) into clearances.
    pub(super) fn clearances(&mut self, border: &[[u32; 2]]) {
        let (nx, ny) = (self.nx, self.ny);
        let mut bad = vec![false; nx * ny];
        for e in border {
            let (a, b) = (self.xy[e[0] as usize], self.xy[e[1] as usize]);
            let (i0, i1, j0, j1) = self.bucket_range(a, b);
            for j in j0..=j1 {
                for i in i0..=i1 {
                    bad[j * nx + i] = true;
                }
            }
        }
        let this = &*self;
        bad.par_chunks_mut(nx).enumerate().for_each(|(j, row)| {
            for (i, bad) in row.iter_mut().enumerate() {
                if *bad {
                    continue;
                }
                // an irrational-ish point of the bucket, unlikely to lie on an edge
                let p = this.lo + this.size * DVec2::new(i as f64 + 0.381966, j as f64 + 0.618034);
                let covering = this
                    .faces_in(j * nx + i)
                    .iter()
                    .filter(|&&f| this.bary(f as usize, p).min_element() > 1e-9)
                    .count();
                *bad = covering != 1;
            }
        });
        let big = (nx + ny) as u32;
        let mut d: Vec<u32> = bad.iter().map(|&x| if x { 0 } else { big }).collect();
        let at = |d: &[u32], i: isize, j: isize| -> u32 {
            if i < 0 || j < 0 || i >= nx as isize || j >= ny as isize {
                0
            } else {
                d[j as usize * nx + i as usize]
            }
        };
        for j in 0..ny as isize {
            for i in 0..nx as isize {
                let m = [(-1, -1), (0, -1), (1, -1), (-1, 0)]
                    .iter()
                    .map(|&(di, dj)| at(&d, i + di, j + dj) + 1)
                    .min()
                    .unwrap_or(big);
                let b = j as usize * nx + i as usize;
                d[b] = d[b].min(m);
            }
        }
        for j in (0..ny as isize).rev() {
            for i in (0..nx as isize).rev() {
                let m = [(1, 1), (0, 1), (-1, 1), (1, 0)]
                    .iter()
                    .map(|&(di, dj)| at(&d, i + di, j + dj) + 1)
                    .min()
                    .unwrap_or(big);
                let b = j as usize * nx + i as usize;
                d[b] = d[b].min(m);
            }
        }
        self.clear = d
            .iter()
            .map(|&d| d.saturating_sub(1) as f64 * self.size)
            .collect();
    }

    pub(super) fn faces_in(&self, b: usize) -> &[u32] {
        &self.bucket_faces[self.start[b] as usize..self.start[b + 1] as usize]
    }

    /// The bucket of `p` (`None` outside the grid).
    pub(super) fn bucket(&self, p: DVec2) -> Option<usize> {
        let c = (p - self.lo) * self.inv_size;
        (c.x >= 0.0 && c.y >= 0.0 && c.x < self.nx as f64 && c.y < self.ny as f64)
            .then(|| c.y as usize * self.nx + c.x as usize)
    }

    /// The clearance of `p` (module doc; 0 outside the grid).
    pub(super) fn clearance(&self, p: DVec2) -> f64 {
        self.bucket(p).map_or(0.0, |b| self.clear[b])
    }

    /// Whether the segment `a → b` provably crosses no border (module doc).
    pub(super) fn segment_clear(&self, a: DVec2, b: DVec2, ca: f64, cb: f64, depth: u32) -> bool {
        if (b - a).abs().max_element() < ca + cb {
            return true;
        }
        if depth == 0 || (ca == 0.0 && cb == 0.0) {
            return false;
        }
        let m = 0.5 * (a + b);
        let cm = self.clearance(m);
        cm > 0.0
            && self.segment_clear(a, m, ca, cm, depth - 1)
            && self.segment_clear(m, b, cm, cb, depth - 1)
    }

    /// Barycentric coordinates of plane point `p` in face `f`.
    pub(super) fn bary(&self, f: usize, p: DVec2) -> DVec3 {
        let (a, inv) = self.affine[f];
        let b = inv * (p - a);
        DVec3::new(1.0 - b.x - b.y, b.x, b.y)
    }

    /// The face of `p` among its bucket's (the one it is deepest inside; `None` if `p` is
    /// outside the grid or its bucket has no face).
    pub(super) fn locate(&self, p: DVec2) -> Option<Located> {
        let b = self.bucket(p)?;
        let (mut best, mut depth) = (None, f64::NEG_INFINITY);
        for &f in self.faces_in(b) {
            let bq = self.bary(f as usize, p);
            if bq.min_element() > depth {
                depth = bq.min_element();
                best = Some(Located { face: f, bary: bq });
            }
        }
        best.map(|l| Located {
            face: l.face,
            bary: clamp(l.bary),
        })
    }

    /// The world point of plane point `p`.
    pub(super) fn world(&self, p: DVec2) -> DVec3 {
        self.origin + p.x * self.u + p.y * self.w
    }

    /// Whether the straight segment `a → b` provably stays inside (module doc).
    pub(super) fn straight(&self, a: DVec2, b: DVec2) -> bool {
        self.segment_clear(a, b, self.clearance(a), self.clearance(b), BISECTIONS)
    }
}
