//! Walking a straight segment across edges by unfolding, in barycentric coordinates
//! (module doc of [`super`], "Crossing edges: unfolding", "The walk in barycentric
//! coordinates").

use glam::{DMat2, DVec2, DVec3};

use super::charts::{Charts, Corners, NEXT, NONE, Orth, PREV};
use super::located::{BARY_TOLERANCE, Located, MAX_CROSSINGS, clamp};

impl Charts {
    /// Walks the straight segment `d` (in the chart of `start`'s face) from `start` across
    /// edges (module doc). Returns where it ends and the orthogonal map from the end face's
    /// chart to the start face's chart.
    pub(crate) fn walk(&self, start: &Located, d: DVec2) -> (Located, DMat2) {
        let (end, rot) = self.walk_here(&self.here(start), d);
        (self.outside(&end), rot)
    }

    /// `l` (a face of the input) with the face's index here.
    pub(super) fn here(&self, l: &Located) -> Located {
        Located {
            face: self.rank[l.face as usize],
            bary: l.bary,
        }
    }

    /// `l` with the input's face index.
    pub(super) fn outside(&self, l: &Located) -> Located {
        Located {
            face: self.order[l.face as usize],
            bary: l.bary,
        }
    }

    /// [`Self::walk`] with faces indexed here.
    pub(super) fn walk_here(&self, start: &Located, d: DVec2) -> (Located, DMat2) {
        let [a, b, c] = self.face[start.face as usize].chart;
        if a == 0.0 {
            return (
                Located {
                    face: start.face,
                    bary: clamp(start.bary),
                },
                DMat2::IDENTITY,
            );
        }
        let d2 = d.y / c;
        let d1 = (d.x - d2 * b) / a;
        let (end, rot, _) = self.walk_bary(start, DVec3::new(-d1 - d2, d1, d2));
        (end, rot.mat())
    }

    /// The walk from `start` by the barycentric displacement `delta` (summing to 0), in
    /// barycentric coordinates (module doc): returns where it ends and the orthogonal map
    /// from the end face's chart to the start face's.
    pub(super) fn walk_bary(&self, start: &Located, delta: DVec3) -> (Located, Orth, Corners) {
        match self.walk_start(start, delta) {
            Err(end) => end,
            Ok(mut w) => loop {
                if let Some(end) = self.walk_cross(&mut w) {
                    return end;
                }
            },
        }
    }

    /// Two walks ([`Self::walk_bary`]) taken a crossing each in turn: each crossing waits
    /// for the next face's record, and the two chains of reads overlap (module doc,
    /// "Memory"). The results are those of the walks taken one by one.
    pub(super) fn walk_pair(
        &self,
        (sa, da): (&Located, DVec3),
        (sb, db): (&Located, DVec3),
    ) -> [(Located, Orth, Corners); 2] {
        let mut a = self.walk_start(sa, da);
        let mut b = self.walk_start(sb, db);
        loop {
            match (&mut a, &mut b) {
                (Ok(wa), Ok(wb)) => {
                    let ea = self.walk_cross(wa);
                    let eb = self.walk_cross(wb);
                    if let Some(e) = ea {
                        a = Err(e);
                    }
                    if let Some(e) = eb {
                        b = Err(e);
                    }
                }
                (Ok(w), Err(_)) => {
                    if let Some(e) = self.walk_cross(w) {
                        a = Err(e);
                    }
                }
                (Err(_), Ok(w)) => {
                    if let Some(e) = self.walk_cross(w) {
                        b = Err(e);
                    }
                }
                (Err(ea), Err(eb)) => return [*ea, *eb],
            }
        }
    }

    /// The start of a walk: its end if it stays in the start face, else the walk about to
    /// cross the first edge it meets.
    pub(super) fn walk_start(
        &self,
        start: &Located,
        delta: DVec3,
    ) -> Result<Walk, (Located, Orth, Corners)> {
        let (p, q) = (start.bary, start.bary + delta);
        let corners = self.hop[start.face as usize].corners;
        if q.min_element() >= -BARY_TOLERANCE {
            return Err((
                Located {
                    face: start.face,
                    bary: clamp(q),
                },
                Orth::IDENTITY,
                corners,
            ));
        }
        // exit edge: the first one the line p → q crosses outward, the least
        // `p_k / (p_k − q_k)` over `q_k < 0`, compared without dividing
        let mut k = 3usize;
        for c in 0..3 {
            if q[c] < -BARY_TOLERANCE && (k == 3 || p[c] * (p[k] - q[k]) < p[k] * (p[c] - q[c])) {
                k = c;
            }
        }
        let (k1, k2) = (NEXT[k], PREV[k]);
        Ok(Walk {
            face: start.face as usize,
            k,
            pk: [p[k], p[k1], p[k2]],
            qk: [q[k], q[k1], q[k2]],
            rot: Orth::IDENTITY,
            left: MAX_CROSSINGS,
            corners,
        })
    }

    /// One crossing of walk `w` (over its edge `k`); its end if it ends in the face
    /// entered, at a border, or stops.
    pub(super) fn walk_cross(&self, w: &mut Walk) -> Option<(Located, Orth, Corners)> {
        let k = w.k;
        let (pk, qk) = (w.pk, w.qk);
        let hop = &self.hop[w.face];
        let g = hop.nbr[k];
        if g == NONE || w.left == 0 {
            // a border (or too many crossings): stop where the segment meets the edge
            let t = pk[0] / (pk[0] - qk[0]);
            let cross = [
                0.0,
                pk[1] + t * (qk[1] - pk[1]),
                pk[2] + t * (qk[2] - pk[2]),
            ];
            return Some((
                Located {
                    face: w.face as u32,
                    bary: clamp(unrotate(cross, k)),
                },
                w.rot,
                w.corners,
            ));
        }
        w.left -= 1;
        // read now, used where the walk ends: the read of the next face's record starts
        // while this crossing's arithmetic runs
        w.corners = self.hop[g as usize].corners;
        let code = hop.code[k];
        let l = (code & 3) as usize;
        let [r, ra] = hop.far[k];
        let rb = r - 1.0 - ra;
        let (pa, pb) = (pk[1] - pk[0] * ra, pk[2] - pk[0] * rb);
        let (qa, qb) = (qk[1] - qk[0] * ra, qk[2] - qk[0] * rb);
        // the coordinates at corners l, l + 1, l + 2 of the face entered by its edge l;
        // corner k + 1 here is corner l + 1 there if the windings disagree
        let (px, qx) = if (code >> 2) & 3 == NEXT[l] as u8 {
            ([pk[0] * r, pa, pb], [qk[0] * r, qa, qb])
        } else {
            ([pk[0] * r, pb, pa], [qk[0] * r, qb, qa])
        };
        w.rot = w
            .rot
            .then(hop.rot[k], if code & 16 != 0 { -1.0 } else { 1.0 });
        w.face = g as usize;
        let (in1, in2) = (qx[1] >= -BARY_TOLERANCE, qx[2] >= -BARY_TOLERANCE);
        if in1 && in2 {
            let end = if qx[0] >= -BARY_TOLERANCE {
                qx
            } else {
                // q is behind the entry edge (rounding): stop where the segment entered
                let t = px[0] / (px[0] - qx[0]);
                [
                    0.0,
                    px[1] + t * (qx[1] - px[1]),
                    px[2] + t * (qx[2] - px[2]),
                ]
            };
            return Some((
                Located {
                    face: g,
                    bary: clamp(unrotate(end, l)),
                },
                w.rot,
                w.corners,
            ));
        }
        // the next exit, never the entry edge (0 in this order): edge 2 if it is the only
        // one q is beyond or the line meets it first, else edge 1
        let two = !in2 && (in1 || px[2] * (px[1] - qx[1]) < px[1] * (px[2] - qx[2]));
        (w.k, w.pk, w.qk) = if two {
            (PREV[l], [px[2], px[0], px[1]], [qx[2], qx[0], qx[1]])
        } else {
            (NEXT[l], [px[1], px[2], px[0]], [qx[1], qx[2], qx[0]])
        };
        None
    }
}

/// A walk under way ([`Charts::walk_cross`]): in face `face`, to cross its edge `k` next,
/// with the coordinates of the segment's ends at corners `k, k + 1, k + 2`.
#[derive(Debug, Clone, Copy)]
pub(super) struct Walk {
    pub(super) face: usize,
    pub(super) k: usize,
    pub(super) pk: [f64; 3],
    pub(super) qk: [f64; 3],
    /// The map of this face's chart into the start face's.
    pub(super) rot: Orth,
    /// Crossings left before the walk stops ([`MAX_CROSSINGS`]).
    pub(super) left: usize,
    /// This face's corners.
    pub(super) corners: Corners,
}

/// Barycentric coordinates from those at corners `l, l + 1, l + 2`.
pub(super) fn unrotate(x: [f64; 3], l: usize) -> DVec3 {
    match l {
        0 => DVec3::new(x[0], x[1], x[2]),
        1 => DVec3::new(x[2], x[0], x[1]),
        _ => DVec3::new(x[1], x[2], x[0]),
    }
}
