//! The triangles' charts at `t0` and their neighbours ([`Charts`]): built once per mesh
//! (the per-face records a walk reads, the faces in a space-filling order), and a point's
//! frame, world position and chart velocity (module doc of [`super`], "The particle and
//! its charts", "Memory").

use glam::{DMat2, DVec2, DVec3};
use rayon::prelude::*;

use super::buckets::Planar;
use super::located::Located;
use super::time::{Lerp, Motion};
use crate::error::MeshError;
use crate::mesh::Topology;
use crate::mesh::geometry::check_positions;

/// A face's chart and neighbours: what the walks' records ([`Hop`]) are built from, and
/// what a walk from a chart displacement ([`Charts::walk`]) reads at its start.
#[derive(Debug, Clone, Copy)]
pub(super) struct FaceChart {
    /// `(c_1.x, c_2.x, c_2.y)` (`c_0` at the origin, `c_1.y = 0`); all zero for a
    /// degenerate face.
    pub(super) chart: [f64; 3],
    /// The corners' vertices.
    pub(super) verts: [u32; 3],
    /// The face across the edge opposite corner `k` (`u32::MAX` on a border or
    /// non-manifold edge) ...
    pub(super) nbr: [u32; 3],
    /// ... and that edge's local index in it.
    pub(super) nbr_edge: [u8; 3],
}

/// How the chart of the face across an edge lies in a face's chart (the unfolding), and
/// which of its corners are the edge's ends (in the face's order `k + 1`, `k + 2`); only
/// while the records [`Hop`] are built.
#[derive(Debug, Clone, Copy)]
pub(super) struct Link {
    pub(super) rot: DMat2,
    pub(super) shift: DVec2,
    pub(super) corners: [u8; 2],
}

/// What a walk reads of a face it crosses into, in one 128-byte record (module doc,
/// "The walk in barycentric coordinates"): per edge `k` (opposite corner `k`) the
/// neighbour's far corner in this face's barycentric coordinates, the orthogonal map of
/// the neighbour's chart into this one, the neighbour and how its corners line up.
#[derive(Debug, Clone, Copy)]
#[repr(C, align(128))]
pub(super) struct Hop {
    /// `(1/γ_k, γ_{k+1}/γ_k)` for the neighbour's far corner `G = Σ_m γ_m c_m` (`γ_k < 0`;
    /// `γ_{k+2}/γ_k = 1/γ_k − 1 − γ_{k+1}/γ_k`).
    pub(super) far: [[f64; 2]; 3],
    /// The first column `(a, b)` of the orthogonal map of the neighbour's chart into this
    /// face's; the second is `σ (−b, a)`, `σ = −1` for a reflection (bit 4 of `code`).
    pub(super) rot: [[f64; 2]; 3],
    /// The neighbour across edge `k` (`NONE`: border, non-manifold edge, or a degenerate
    /// neighbour, where a walk stops).
    pub(super) nbr: [u32; 3],
    /// Bits 0–1: the edge's index `l` in the neighbour (its far corner); bits 2–3: the
    /// neighbour's corner at this face's corner `k + 1`; bit 4: the map is a reflection.
    pub(super) code: [u8; 3],
    /// The face's vertices: what the stage point where a walk ends needs.
    pub(super) corners: Corners,
}

/// A face's vertices and whether it is degenerate (no chart): what its frame in space is
/// computed from ([`Charts::frame_of`]).
#[derive(Debug, Clone, Copy)]
pub(super) struct Corners {
    pub(super) verts: [u32; 3],
    pub(super) degenerate: bool,
}

/// An orthogonal map of the plane `[[a, −σb], [b, σa]]` (a rotation, or a reflection for
/// `σ = −1`), as a walk composes them.
#[derive(Debug, Clone, Copy)]
pub(super) struct Orth {
    pub(super) a: f64,
    pub(super) b: f64,
    pub(super) sigma: f64,
}

impl Orth {
    pub(super) const IDENTITY: Self = Self {
        a: 1.0,
        b: 0.0,
        sigma: 1.0,
    };

    /// `self ∘ (a, b, σ)`.
    pub(super) fn then(self, [a, b]: [f64; 2], sigma: f64) -> Self {
        Self {
            a: self.a * a - self.sigma * self.b * b,
            b: self.b * a + self.sigma * self.a * b,
            sigma: self.sigma * sigma,
        }
    }

    pub(super) fn mat(self) -> DMat2 {
        DMat2::from_cols(
            DVec2::new(self.a, self.b),
            self.sigma * DVec2::new(-self.b, self.a),
        )
    }
}

/// `(k + 1) % 3`, `(k + 2) % 3`.
pub(super) const NEXT: [usize; 3] = [1, 2, 0];
pub(super) const PREV: [usize; 3] = [2, 0, 1];

/// The triangles' charts at `t0` and their neighbours: what the walks need.
#[derive(Debug, Clone)]
pub struct Charts {
    pub(super) face: Vec<FaceChart>,
    /// The input's face of each face here (the faces are stored in a space-filling order,
    /// module doc, "Memory"), and the inverse permutation.
    pub(super) order: Vec<u32>,
    pub(super) rank: Vec<u32>,
    /// Per face, what a walk crossing into it reads.
    pub(super) hop: Vec<Hop>,
    /// A face at every vertex and the vertex's corner in it (`u32::MAX` for a loose vertex).
    pub(super) vertex_face: Vec<(u32, u8)>,
    /// The flat mesh's plane and buckets, if the mesh is flat ([`super::planar`]).
    pub(super) planar: Option<Planar>,
    /// The vertices at `t0`: a fixed mesh's faces in space ([`Self::frame`]).
    pub(super) start: Vec<DVec3>,
}

/// A face at `t0` in space: corner 0, the edges `E_1`, `E_2`, and the chart's axes `u`,
/// `n̂ × u` (unit, in the face's plane). On a fixed mesh the world point of barycentric
/// `b` is `x_0 + b_1 E_1 + b_2 E_2` and the chart velocity of `w` (module doc) is
/// `(u·w, (n̂ × u)·w)`, the tangent projection in the chart's orthonormal axes: the same
/// as the least-squares rates `ḃ` mapped by `c_1, c_2`, without the 2×2 solve.
#[derive(Debug, Clone, Copy)]
pub(super) struct FaceFrame {
    pub(super) x0: DVec3,
    pub(super) e1: DVec3,
    pub(super) e2: DVec3,
    pub(super) u: DVec3,
    pub(super) v: DVec3,
}

impl FaceFrame {
    /// The map of a displacement `d` in a chart that `rot` maps this face's chart into, to
    /// barycentric rates `(ḃ_1, ḃ_2)` here: `ḃ_2 = d'_y / c_{2,y}`,
    /// `ḃ_1 = (d'_x − ḃ_2 c_{2,x}) / c_{1,x}` of `d' = rotᵀ d` (zero on a degenerate face,
    /// where a walk does not move).
    pub(super) fn bary_map(&self, rot: DMat2) -> DMat2 {
        let c1x = self.e1.dot(self.u);
        if c1x == 0.0 {
            return DMat2::ZERO;
        }
        let (c2x, c2y) = (self.e2.dot(self.u), self.e2.dot(self.v));
        let (i1, i2) = (1.0 / c1x, 1.0 / c2y);
        // rows (ḃ_1, ḃ_2) of [[1/c1x, −c2x/(c1x c2y)], [0, 1/c2y]]
        let local = DMat2::from_cols(DVec2::new(i1, 0.0), DVec2::new(-c2x * i1 * i2, i2));
        local * rot.transpose()
    }
}

/// The barycentric displacement `(−ḃ_1 − ḃ_2, ḃ_1, ḃ_2)` of `d` by the map `to_bary`.
pub(super) fn bary_step(to_bary: DMat2, d: DVec2) -> DVec3 {
    let b = to_bary * d;
    DVec3::new(-b.x - b.y, b.x, b.y)
}

/// No neighbour (border or non-manifold edge) / no face (loose vertex).
pub(super) const NONE: u32 = u32::MAX;

impl Charts {
    /// Charts of `topology` at `positions` (the shape at `t0`).
    pub fn new(topology: &Topology, positions: &[DVec3]) -> Result<Self, MeshError> {
        check_positions(topology, positions)?;
        let order = space_filling_order(topology.faces(), positions);
        let mut rank = vec![0u32; order.len()];
        for (i, &f) in order.iter().enumerate() {
            rank[f as usize] = i as u32;
        }
        // the faces in the walks' order (module doc, "Memory")
        let faces: Vec<[u32; 3]> = order
            .iter()
            .map(|&f| topology.faces()[f as usize])
            .collect();
        let faces = &faces[..];
        let chart: Vec<[f64; 3]> = faces
            .par_iter()
            .map(|tri| {
                let [x0, x1, x2] = tri.map(|v| positions[v as usize]);
                let (e1, e2) = (x1 - x0, x2 - x0);
                let (l1, n) = (e1.length(), e1.cross(e2));
                if l1 == 0.0 || n.length() <= 1e-14 * l1 * e2.length() {
                    return [0.0; 3];
                }
                let u = e1 / l1;
                let w = n.normalize().cross(u);
                [l1, e2.dot(u), e2.dot(w)]
            })
            .collect();
        // per edge: its first two (face, local edge) and how many faces it has (flat
        // arrays, not a list per edge: this runs on every call)
        let mut edge_faces = vec![[(NONE, 0u8); 2]; topology.n_edges()];
        let mut edge_count = vec![0u8; topology.n_edges()];
        for (f, fe) in topology.face_edges().iter().enumerate() {
            for (k, &e) in fe.iter().enumerate() {
                let c = &mut edge_count[e as usize];
                if *c < 2 {
                    edge_faces[e as usize][*c as usize] = (rank[f], k as u8);
                }
                *c = c.saturating_add(1);
            }
        }
        let mut neighbour = vec![[(NONE, 0u8); 3]; faces.len()];
        for (pair, _) in edge_faces.iter().zip(&edge_count).filter(|(_, c)| **c == 2) {
            let [(f, k), (g, l)] = *pair;
            neighbour[f as usize][k as usize] = (g, l);
            neighbour[g as usize][l as usize] = (f, k);
        }
        // at each vertex its first face in the input's order (the order changes no result)
        let mut vertex_face = vec![(NONE, 0u8); topology.n_vertices()];
        for (f, tri) in topology.faces().iter().enumerate().rev() {
            for (c, &v) in tri.iter().enumerate() {
                vertex_face[v as usize] = (rank[f], c as u8);
            }
        }
        let face = (0..faces.len())
            .map(|f| FaceChart {
                chart: chart[f],
                verts: faces[f],
                nbr: neighbour[f].map(|n| n.0),
                nbr_edge: neighbour[f].map(|n| n.1),
            })
            .collect();
        let mut charts = Self {
            face,
            order,
            rank,
            hop: Vec::new(),
            vertex_face,
            planar: None,
            start: positions.to_vec(),
        };
        // the hop records and the flat path's buckets are independent: built side by side
        let flat = charts.face.iter().all(|f| f.chart[0] != 0.0);
        let (hop, planar) = rayon::join(
            || {
                (0..faces.len())
                    .into_par_iter()
                    .map(|f| charts.hop_of(f))
                    .collect()
            },
            || flat.then(|| Planar::new(topology, positions)).flatten(),
        );
        charts.hop = hop;
        charts.planar = planar;
        Ok(charts)
    }

    /// The same charts without the flat mesh's fast path: every stage point is walked
    /// (for comparing the two; the results agree up to rounding).
    pub fn walk_everywhere(mut self) -> Self {
        self.planar = None;
        self
    }

    /// Whether the mesh is flat and takes the fast path of [`super::planar`].
    pub fn is_flat(&self) -> bool {
        self.planar.is_some()
    }

    /// The vertices of face `f`.
    pub(crate) fn face_verts(&self, f: usize) -> [u32; 3] {
        self.face[self.rank[f] as usize].verts
    }

    /// The unfolding of the neighbour across edge `k` of face `f` into `f`'s chart.
    pub(super) fn link_across(&self, f: usize, k: usize) -> Link {
        let here = &self.face[f];
        let (g, l) = (here.nbr[k], here.nbr_edge[k] as usize);
        if g == NONE {
            return Link {
                rot: DMat2::IDENTITY,
                shift: DVec2::ZERO,
                corners: [0, 0],
            };
        }
        let (a, b) = (here.verts[(k + 1) % 3], here.verts[(k + 2) % 3]);
        let tg = self.face[g as usize].verts;
        let corner_in_g = |v: u32| (0..3).find(|&m| tg[m] == v).unwrap_or(0);
        let (ga, gb) = (corner_in_g(a), corner_in_g(b));
        let cf = self.corners(f);
        let cg = self.corners(g as usize);
        let (rot, shift) = unfold(
            cf[(k + 1) % 3],
            cf[(k + 2) % 3],
            cf[k],
            cg[ga],
            cg[gb],
            cg[l],
        );
        Link {
            rot,
            shift,
            corners: [ga as u8, gb as u8],
        }
    }

    /// The record [`Hop`] of face `f`, from the unfoldings of its neighbours.
    pub(super) fn hop_of(&self, f: usize) -> Hop {
        let mut hop = Hop {
            far: [[0.0; 2]; 3],
            rot: [[1.0, 0.0]; 3],
            nbr: [NONE; 3],
            code: [0; 3],
            corners: Corners {
                verts: self.face[f].verts,
                degenerate: self.face[f].chart[0] == 0.0,
            },
        };
        for k in 0..3 {
            let here = &self.face[f];
            let (g, l) = (here.nbr[k], here.nbr_edge[k] as usize);
            if g == NONE || here.chart[0] == 0.0 || self.face[g as usize].chart[0] == 0.0 {
                continue;
            }
            let link = self.link_across(f, k);
            let far = link.rot * self.corners(g as usize)[l] + link.shift;
            let Some(gamma) = self.bary(f, far) else {
                continue;
            };
            if gamma[k] >= 0.0 || !gamma.is_finite() {
                // the neighbour folded onto this face: no unfolding to walk through
                continue;
            }
            let r = 1.0 / gamma[k];
            hop.far[k] = [r, gamma[NEXT[k]] * r];
            hop.rot[k] = [link.rot.x_axis.x, link.rot.x_axis.y];
            let reflect = link.rot.determinant() < 0.0;
            hop.nbr[k] = g;
            hop.code[k] = l as u8 | (link.corners[0] << 2) | (u8::from(reflect) << 4);
        }
        hop
    }

    /// Face `f` at `t0` in space ([`FaceFrame`]), from its vertices: computed where it is
    /// needed rather than stored, since a stored frame per face is a cache miss per stage
    /// point while the vertices are few and the walk has just read the face's [`Hop`].
    pub(super) fn frame(&self, f: usize) -> FaceFrame {
        self.frame_of(self.hop[f].corners)
    }

    /// [`Self::frame`] of the face with these corners.
    pub(super) fn frame_of(&self, c: Corners) -> FaceFrame {
        let [x0, x1, x2] = c.verts.map(|v| self.start[v as usize]);
        let (e1, e2) = (x1 - x0, x2 - x0);
        let (u, v) = if c.degenerate {
            (DVec3::ZERO, DVec3::ZERO)
        } else {
            let u = e1 / e1.length();
            (u, e1.cross(e2).normalize().cross(u))
        };
        FaceFrame { x0, e1, e2, u, v }
    }

    /// The corners of face `f` in its chart.
    pub(super) fn corners(&self, f: usize) -> [DVec2; 3] {
        let [a, b, c] = self.face[f].chart;
        [DVec2::ZERO, DVec2::new(a, 0.0), DVec2::new(b, c)]
    }

    /// Barycentric coordinates of chart point `p` in face `f` (`None` if degenerate).
    pub(super) fn bary(&self, f: usize, p: DVec2) -> Option<DVec3> {
        let [a, b, c] = self.face[f].chart;
        if a == 0.0 {
            return None;
        }
        let b2 = p.y / c;
        let b1 = (p.x - b2 * b) / a;
        Some(DVec3::new(1.0 - b1 - b2, b1, b2))
    }

    /// The particle that starts at vertex `v` (`None` for a loose vertex).
    pub fn at_vertex(&self, v: usize) -> Option<Located> {
        self.at_vertex_here(v).map(|l| self.outside(&l))
    }

    /// [`Self::at_vertex`] with the face's index here.
    pub(super) fn at_vertex_here(&self, v: usize) -> Option<Located> {
        let (f, c) = self.vertex_face[v];
        (f != NONE).then(|| {
            let mut bary = DVec3::ZERO;
            bary[c as usize] = 1.0;
            Located { face: f, bary }
        })
    }

    /// The world position of `l` at `at`.
    pub(crate) fn world(&self, motion: &Motion, at: Lerp, l: &Located) -> DVec3 {
        self.world_here(motion, at, &self.here(l))
    }

    /// [`Self::world`] with the face's index here.
    pub(super) fn world_here(&self, motion: &Motion, at: Lerp, l: &Located) -> DVec3 {
        if motion.is_fixed() {
            let f = &self.frame(l.face as usize);
            return f.x0 + l.bary.y * f.e1 + l.bary.z * f.e2;
        }
        let tri = self.face[l.face as usize].verts;
        (0..3)
            .map(|c| l.bary[c] * motion.position(at, tri[c] as usize))
            .sum()
    }

    /// The velocity `w` at `l` (time `at`) in the chart of `l`'s face (module doc).
    pub(super) fn chart_velocity(&self, motion: &Motion, at: Lerp, l: &Located, w: DVec3) -> DVec2 {
        let f = l.face as usize;
        if motion.is_fixed() {
            let fr = &self.frame(f);
            return DVec2::new(fr.u.dot(w), fr.v.dot(w));
        }
        let tri = self.face[f].verts;
        let [x0, x1, x2] = tri.map(|v| motion.position(at, v as usize));
        let (e1, e2) = (x1 - x0, x2 - x0);
        let (g11, g12, g22) = (e1.dot(e1), e1.dot(e2), e2.dot(e2));
        let det = g11 * g22 - g12 * g12;
        if self.face[f].chart[0] == 0.0 || det <= 1e-24 * g11 * g22 {
            return DVec2::ZERO;
        }
        let (r1, r2) = (e1.dot(w), e2.dot(w));
        let b1 = (g22 * r1 - g12 * r2) / det;
        let b2 = (g11 * r2 - g12 * r1) / det;
        let [_, c1, c2] = self.corners(f);
        b1 * c1 + b2 * c2
    }
}

/// The faces in the order of their centroids along a Morton (Z-order) curve through the
/// bounding box (ties by index): faces near each other in space are near in memory, so
/// that a walk's faces, and those of particles walked one after the other, share cache
/// lines (module doc, "Memory"). Any order gives the same results.
pub(super) fn space_filling_order(faces: &[[u32; 3]], positions: &[DVec3]) -> Vec<u32> {
    let (lo, hi) = positions
        .iter()
        .fold((DVec3::INFINITY, DVec3::NEG_INFINITY), |(l, h), &p| {
            (l.min(p), h.max(p))
        });
    let scale = ((1u64 << 21) - 1) as f64 / (hi - lo).max_element().max(1e-300);
    // 21 bits per axis, interleaved
    let spread = |x: u64| {
        let mut x = x & 0x1f_ffff;
        x = (x | (x << 32)) & 0x1f00000000ffff;
        x = (x | (x << 16)) & 0x1f0000ff0000ff;
        x = (x | (x << 8)) & 0x100f00f00f00f00f;
        x = (x | (x << 4)) & 0x10c30c30c30c30c3;
        (x | (x << 2)) & 0x1249249249249249
    };
    let mut keyed: Vec<(u64, u32)> = faces
        .par_iter()
        .enumerate()
        .map(|(f, tri)| {
            let c = tri.iter().map(|&v| positions[v as usize]).sum::<DVec3>() / 3.0;
            let q = ((c - lo) * scale).max(DVec3::ZERO);
            let key = spread(q.x as u64) | (spread(q.y as u64) << 1) | (spread(q.z as u64) << 2);
            (key, f as u32)
        })
        .collect();
    keyed.par_sort_unstable();
    keyed.into_iter().map(|(_, f)| f).collect()
}

/// The orthogonal map `x ↦ R x + t` of a neighbour's chart into the current one that puts
/// the shared edge's ends `ga, gb` on `pa, pb` and the neighbour's far corner `gf` on the
/// other side of the edge from this face's far corner `far`.
pub(super) fn unfold(
    pa: DVec2,
    pb: DVec2,
    far: DVec2,
    ga: DVec2,
    gb: DVec2,
    gf: DVec2,
) -> (DMat2, DVec2) {
    let u = (pb - pa).normalize_or_zero();
    let v = (gb - ga).normalize_or_zero();
    let (cos, sin) = (u.dot(v), v.perp_dot(u));
    let mut rot = DMat2::from_cols(DVec2::new(cos, sin), DVec2::new(-sin, cos));
    let side = |p: DVec2| u.perp_dot(p - pa);
    if side(rot * (gf - ga) + pa) * side(far) > 0.0 {
        // windings disagree: reflect across the edge's line
        let refl = DMat2::from_cols(
            DVec2::new(u.x * u.x - u.y * u.y, 2.0 * u.x * u.y),
            DVec2::new(2.0 * u.x * u.y, u.y * u.y - u.x * u.x),
        );
        rot = refl * rot;
    }
    (rot, pa - rot * ga)
}
