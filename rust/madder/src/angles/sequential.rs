//! The sequential breadth-first construction (the Angle-Analyzer-style baseline of §3.3 and
//! §3.4): the seed face from its corners, then every face reached across an interior edge
//! gets its third vertex from the placed neighbour's normal, the dihedral angle and its own
//! corners (Fig. 3.1 in world coordinates). Errors accumulate along the walk.

use std::collections::VecDeque;

use glam::DVec3;

use super::encode::{AngleMesh, Angles, NONE};
use super::local::{edge_corners, preprocess};
use super::place::Placement;
use super::spectral::normalize;
use crate::error::AngleError;

impl AngleMesh {
    /// Positions from angles by the sequential construction, starting at the placement's
    /// face (face 0 without one). Same preprocessing, checks and placement as
    /// [`AngleMesh::reconstruct`].
    pub fn sequential(
        &self,
        angles: &Angles,
        placement: Option<&Placement>,
    ) -> Result<Vec<DVec3>, AngleError> {
        self.check_angles(angles)?;
        self.check_connected()?;
        if let Some(p) = placement {
            p.check(self.n_faces())?;
        }
        let a = preprocess(angles);
        let faces = self.faces();
        let seed = placement.map_or(0, |p| p.face);
        let mut x = vec![DVec3::ZERO; self.n_vertices()];
        let mut placed = vec![false; self.n_vertices()];
        // the seed face: corner 0 at the origin, corner 1 on +x, counter-clockwise about +z
        let [a0, a1, a2] = a.corners[seed];
        let t = faces[seed];
        let len02 = a1.sin() / a2.sin();
        x[t[1] as usize] = DVec3::X;
        x[t[2] as usize] = len02 * DVec3::new(a0.cos(), a0.sin(), 0.0);
        for &v in &t {
            placed[v as usize] = true;
        }
        let mut visited = vec![false; faces.len()];
        visited[seed] = true;
        let mut queue = VecDeque::from([seed]);
        while let Some(f) = queue.pop_front() {
            for c in 0..3 {
                let ie = self.face_interior()[f][c];
                if ie == NONE {
                    continue;
                }
                let e = self.interior()[ie as usize];
                let (g, gc) = if e.f1 as usize == f {
                    (e.f2 as usize, e.c2 as usize)
                } else {
                    (e.f1 as usize, e.c1 as usize)
                };
                if visited[g] {
                    continue;
                }
                visited[g] = true;
                queue.push_back(g);
                let opp = faces[g][gc] as usize;
                if placed[opp] {
                    continue;
                }
                // the edge runs u → w in the placed face f, w → u in g
                let (u, w) = (
                    faces[f][(c + 1) % 3] as usize,
                    faces[f][(c + 2) % 3] as usize,
                );
                let (s1, s2) = edge_corners(&e, &a.corners);
                // corners of g at u, w and its opposite vertex
                let (bu, bw, bo) = if e.f1 as usize == f {
                    (s2[0], s2[1], s2[2])
                } else {
                    (s1[1], s1[0], s1[2])
                };
                let theta = a.dihedrals[ie as usize];
                let [p0, p1, p2] = faces[f].map(|v| x[v as usize]);
                let n1 = (p1 - p0).cross(p2 - p0).normalize();
                let edge = x[w] - x[u];
                let ex = edge.normalize();
                let ey = n1.cross(ex);
                let len = edge.length() * bw.sin() / bo.sin();
                let (sb, cb) = bu.sin_cos();
                let (st, ct) = theta.sin_cos();
                x[opp] = x[u] + len * (cb * ex - sb * ct * ey - sb * st * n1);
                placed[opp] = true;
            }
        }
        match placement {
            Some(p) => p.apply(faces, &mut x),
            None => normalize(self.edges(), &mut x),
        }
        Ok(x)
    }
}
