//! The connectivity the angles live on (interior edges with their two faces, checked
//! manifold and consistently oriented) and the encoder: positions → corner and dihedral
//! angles (seed §3.3, eq. 3.1).

use glam::DVec3;
use rayon::prelude::*;

use super::cache::{SolverCache, TrackerCache};
use crate::error::AngleError;
use crate::mesh::Topology;
use crate::mesh::geometry::check_positions;

/// An interior edge `a → b` (`a < b`) of face `f1`, `b → a` of face `f2`; `c1`, `c2` the
/// corners of `f1`, `f2` opposite the edge (so `a` is corner `c1 + 1` of `f1` and corner
/// `c2 + 2` of `f2`, mod 3).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Interior {
    pub(crate) a: u32,
    pub(crate) b: u32,
    pub(crate) f1: u32,
    pub(crate) f2: u32,
    pub(crate) c1: u8,
    pub(crate) c2: u8,
}

/// Marks a boundary edge in [`AngleMesh::face_interior`].
pub(crate) const NONE: u32 = u32::MAX;

/// A triangle mesh's connectivity prepared for the angle representation: manifold,
/// consistently oriented, every vertex used.
#[derive(Debug, Clone)]
pub struct AngleMesh {
    topo: Topology,
    interior: Vec<Interior>,
    /// `face_interior[f][c]`: the interior edge opposite corner `c` of `f`, or [`NONE`].
    face_interior: Vec<[u32; 3]>,
    /// The first face not reachable from face 0 across interior edges, if any.
    unreached: Option<usize>,
    /// Connectivity-only solver state kept between reconstructions.
    solver: SolverCache,
    /// The tracked reconstruction's factorized Laplacians, built on first use.
    tracker: TrackerCache,
}

/// The angles of a mesh: corner angles `corners[f][c]` (radians, at vertex `faces[f][c]`) and
/// one signed dihedral angle per interior edge (radians, in [`AngleMesh::interior_edges`]
/// order).
#[derive(Debug, Clone, PartialEq)]
pub struct Angles {
    /// Corner angles, one row per face.
    pub corners: Vec<[f64; 3]>,
    /// Signed dihedral angles, one per interior edge.
    pub dihedrals: Vec<f64>,
}

impl AngleMesh {
    /// Checks and indexes the connectivity of `n_vertices` vertices and triangles `faces`.
    ///
    /// Errors name the element: a face index out of range or repeating a vertex, an edge
    /// with three or more faces, an edge both of whose faces run it the same way (not
    /// orientable, or not consistently oriented), a vertex used by no face.
    pub fn new(n_vertices: usize, faces: Vec<[u32; 3]>) -> Result<Self, AngleError> {
        let topo = Topology::from_triangles(n_vertices, faces)?;
        let loose = topo.loose_vertices();
        if let Some(vertex) = loose.iter().position(|&l| l) {
            return Err(AngleError::LooseVertex { vertex });
        }
        let n_edges = topo.n_edges();
        // the (face, corner) pairs of every edge, at most two kept
        let mut first = vec![(NONE, 0u8); n_edges];
        let mut second = vec![(NONE, 0u8); n_edges];
        let mut count = vec![0usize; n_edges];
        for (f, fe) in topo.face_edges().iter().enumerate() {
            for (c, &e) in fe.iter().enumerate() {
                let e = e as usize;
                match count[e] {
                    0 => first[e] = (f as u32, c as u8),
                    1 => second[e] = (f as u32, c as u8),
                    _ => {}
                }
                count[e] += 1;
            }
        }
        let faces = topo.faces();
        let mut interior = Vec::new();
        let mut face_interior = vec![[NONE; 3]; faces.len()];
        for e in 0..n_edges {
            let [a, b] = topo.edges()[e];
            if count[e] > 2 {
                return Err(AngleError::NonManifoldEdge {
                    a,
                    b,
                    faces: count[e],
                });
            }
            if count[e] < 2 {
                continue;
            }
            // the start of the edge as face f runs it (opposite corner c)
            let start = |(f, c): (u32, u8)| faces[f as usize][(c as usize + 1) % 3];
            let (x, y) = (first[e], second[e]);
            let (one, two) = match (start(x) == a, start(y) == a) {
                (true, false) => (x, y),
                (false, true) => (y, x),
                _ => {
                    return Err(AngleError::NotOrientable {
                        a,
                        b,
                        face_a: x.0 as usize,
                        face_b: y.0 as usize,
                    });
                }
            };
            let idx = interior.len() as u32;
            face_interior[one.0 as usize][one.1 as usize] = idx;
            face_interior[two.0 as usize][two.1 as usize] = idx;
            interior.push(Interior {
                a,
                b,
                f1: one.0,
                f2: two.0,
                c1: one.1,
                c2: two.1,
            });
        }
        let unreached = first_unreached(&face_interior, &interior);
        Ok(Self {
            topo,
            interior,
            face_interior,
            unreached,
            solver: SolverCache::default(),
            tracker: TrackerCache::default(),
        })
    }

    /// Vertices.
    pub fn n_vertices(&self) -> usize {
        self.topo.n_vertices()
    }
    /// Faces.
    pub fn n_faces(&self) -> usize {
        self.topo.n_faces()
    }
    /// The faces (vertex triples).
    pub fn faces(&self) -> &[[u32; 3]] {
        self.topo.faces()
    }
    /// Interior edges (two faces).
    pub fn n_interior(&self) -> usize {
        self.interior.len()
    }
    /// The interior edges `(a, b)`, `a < b`, in the order of the dihedral angles.
    pub fn interior_edges(&self) -> Vec<[u32; 2]> {
        self.interior.iter().map(|e| [e.a, e.b]).collect()
    }
    /// All edges (boundary ones too), `(a, b)`, `a < b`, sorted.
    pub fn edges(&self) -> &[[u32; 2]] {
        self.topo.edges()
    }

    pub(crate) fn solver_cache(&self) -> &SolverCache {
        &self.solver
    }
    pub(crate) fn tracker_cache(&self) -> &TrackerCache {
        &self.tracker
    }
    pub(crate) fn topology(&self) -> &Topology {
        &self.topo
    }
    pub(crate) fn interior(&self) -> &[Interior] {
        &self.interior
    }
    pub(crate) fn face_interior(&self) -> &[[u32; 3]] {
        &self.face_interior
    }

    /// An error naming the first face the reconstruction cannot reach from face 0.
    pub(crate) fn check_connected(&self) -> Result<(), AngleError> {
        match self.unreached {
            Some(face) => Err(AngleError::Disconnected { face }),
            None => Ok(()),
        }
    }

    /// The corner and dihedral angles of the mesh at `positions` (conventions in the module
    /// docs). Errors: a position count that does not match, a non-finite position, a face
    /// of zero area (named).
    pub fn encode(&self, positions: &[DVec3]) -> Result<Angles, AngleError> {
        check_positions(&self.topo, positions)?;
        let faces = self.faces();
        let corners: Vec<[f64; 3]> = faces
            .par_iter()
            .map(|t| {
                let p = t.map(|v| positions[v as usize]);
                std::array::from_fn(|c| corner_angle(p[c], p[(c + 1) % 3], p[(c + 2) % 3]))
            })
            .collect();
        for (face, t) in faces.iter().enumerate() {
            let p = t.map(|v| positions[v as usize]);
            let n = (p[1] - p[0]).cross(p[2] - p[0]).length();
            let scale = (p[1] - p[0]).length() * (p[2] - p[0]).length();
            if n.is_nan() || n <= 1e-14 * scale {
                return Err(AngleError::DegenerateFace { face });
            }
        }
        let dihedrals = self
            .interior
            .par_iter()
            .map(|e| dihedral(self, e, positions))
            .collect();
        Ok(Angles { corners, dihedrals })
    }

    /// Checks angles against this connectivity: counts, and every value finite.
    pub fn check_angles(&self, angles: &Angles) -> Result<(), AngleError> {
        if angles.corners.len() != self.n_faces() {
            return Err(AngleError::CornerCount {
                expected: self.n_faces(),
                got: angles.corners.len(),
            });
        }
        if angles.dihedrals.len() != self.n_interior() {
            return Err(AngleError::DihedralCount {
                expected: self.n_interior(),
                got: angles.dihedrals.len(),
            });
        }
        for (face, c) in angles.corners.iter().enumerate() {
            if let Some(corner) = c.iter().position(|a| !a.is_finite()) {
                return Err(AngleError::NonFiniteCorner { face, corner });
            }
        }
        if let Some(edge) = angles.dihedrals.iter().position(|d| !d.is_finite()) {
            let e = self.interior[edge];
            return Err(AngleError::NonFiniteDihedral {
                edge,
                a: e.a,
                b: e.b,
            });
        }
        Ok(())
    }
}

/// The angle at `p` between `q − p` and `r − p`.
pub(crate) fn corner_angle(p: DVec3, q: DVec3, r: DVec3) -> f64 {
    let (u, w) = (q - p, r - p);
    u.cross(w).length().atan2(u.dot(w))
}

/// Counter-clockwise (area-weighted, `|N| = 2A`) normal of face `f`.
pub(crate) fn face_normal(faces: &[[u32; 3]], f: usize, x: &[DVec3]) -> DVec3 {
    let [p0, p1, p2] = faces[f].map(|v| x[v as usize]);
    (p1 - p0).cross(p2 - p0)
}

/// The signed dihedral angle of interior edge `e` at positions `x`.
pub(crate) fn dihedral(mesh: &AngleMesh, e: &Interior, x: &[DVec3]) -> f64 {
    let n1 = face_normal(mesh.faces(), e.f1 as usize, x);
    let n2 = face_normal(mesh.faces(), e.f2 as usize, x);
    let edge = (x[e.b as usize] - x[e.a as usize]).normalize_or_zero();
    n1.cross(n2).dot(edge).atan2(n1.dot(n2))
}

/// The first face (in index order) not reached from face 0 across interior edges.
fn first_unreached(face_interior: &[[u32; 3]], interior: &[Interior]) -> Option<usize> {
    let mut seen = vec![false; face_interior.len()];
    let mut stack = vec![0usize];
    seen[0] = true;
    while let Some(f) = stack.pop() {
        for &ie in &face_interior[f] {
            if ie == NONE {
                continue;
            }
            let e = interior[ie as usize];
            let g = if e.f1 as usize == f { e.f2 } else { e.f1 } as usize;
            if !seen[g] {
                seen[g] = true;
                stack.push(g);
            }
        }
    }
    seen.iter().position(|&s| !s)
}
