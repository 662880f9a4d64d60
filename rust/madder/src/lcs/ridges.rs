//! Ridges of a noisy scalar field on a triangle mesh (§5.4, §5.5.2–§5.5.5), e.g. of the
//! FTLE `σ`: the Lagrangian coherent structures as curves.
//!
//! ## Candidate region (§5.5.2, eq. 5.3)
//! The field may first be smoothed (`field_smoothing`). With
//! `σ0 = 0.75 σ_max + 0.25 σ_min` the indicator is `S(v) = σ(v) > σ0 ? 1000 : 0` (eq. 5.3),
//! smoothed by one implicit diffusion step, the operator of chapter 4 (§4.3.3):
//!
//! ```text
//! (M + h K) S̃ = M S,     h = smoothing × ℓ̄²,
//! ```
//!
//! `K` the cotan stiffness, `M` the lumped mass ([`crate::ops`]), `ℓ̄` the mean edge
//! length, solved by the prefactored Cholesky ([`crate::ops::PrefactoredSpd`]). Vertices
//! with `S̃ > S0` (`s0`, on the 0–1000 scale of `S`) are the candidate region.
//!
//! ## Transverse direction and zero crossings (§5.4, §5.5.3, eq. 5.4)
//! Gradients are least-squares fits over the one-ring in the vertex's tangent frame (as
//! for the flow map, [`super::ftle`](mod@super::ftle)); the Hessian `H = ∇∇ᵀS̃` is the fitted gradient of
//! the gradient field (3-D tangent vectors, so neighbours' frames need no alignment),
//! symmetrized, then smoothed like `S` (its six 3-D components, `hessian_smoothing`).
//! `n_i` is the eigenvector of the smallest eigenvalue of `H_i`: transverse to the ridge.
//! The candidate region keeps only the vertices where `S̃` is curved down across more than
//! it is curved along, `λ_min + |λ_max| < 0` (the seed: "`λ_min` is typically less than
//! 0" there): on the convex flanks of the smoothed band `n_min` turns along the ridge and
//! `n·∇σ` changes sign at random, which drew spurious lines parallel to the ridge two cells
//! away in the tests.
//! An edge `ij` with both ends in the candidate region holds a ridge point when
//!
//! ```text
//! (n_i·∇σ_i)(n_j·∇σ_j)(n_i·n_j) < 0                                   (eq. 5.4)
//! ```
//!
//! (the third factor makes the two eigenvector orientations consistent), at the zero of
//! the linear interpolation of `n·∇σ` along the edge with `n_j` turned to agree with
//! `n_i`: the point `(a_j x_i − a_i x_j)/(a_j − a_i)`, `a = n·∇σ`, which is the seed's
//! formula written with the consistent orientation.
//!
//! ## Marching triangles (§5.5.3)
//! A triangle with two crossed edges gets one ridge edge between their points; with three
//! (impossible for a level set), the two of the three possible edges with the largest
//! angle between them, i.e. the point whose angle in the small triangle of the three points
//! is largest is joined to the other two. One crossed edge gives nothing.
//!
//! ## Joining at local maxima (optional, §5.5.3)
//! A local maximum of `σ` in the candidate region becomes a node; the ridge points on the
//! edges incident to it are replaced by it, so ridges reaching the points on its one-ring
//! boundary meet there (three or more may join). It is then moved to the average of its
//! neighbours in the graph (and located on the nearest of its faces).
//!
//! ## Cleanup (§5.5.4)
//! The graph is cut into chains between nodes of degree other than 2. A chain shorter than
//! `min_branch` edges from a T-junction (degree ≥ 3) to a free end, a loop that leaves a
//! junction and comes back to it, and the longer of two short chains joining the same two
//! junctions are removed (at most one per junction per pass, shortest first, until nothing
//! changes). Then union–find drops every connected component with fewer than `min_edges`
//! edges (20 in the seed).
//!
//! ## Spurious valleys (optional, §5.5.5)
//! With noisy input, eq. 5.4 also fires on valleys. With `remove_valleys`, an edge whose
//! end normals make an angle under 45° with it must have, at both ends, the gradient's
//! projection on the normal pointing into the edge: `((∇σ)_i·n_i)(n_i·e_ij) > 0` and
//! `((∇σ)_j·n_j)(n_j·e_ji) > 0`.
//! The seed's other optional criterion (trying both eigenvectors where `H` has two similar
//! negative eigenvalues) is not built.

use faer::Par;
use glam::{DMat2, DMat3, DVec2, DVec3};
use rayon::prelude::*;

use super::ftle::{one_ring_fit, solve_fit};
use super::trace::Located;
use crate::error::LcsError;
use crate::mesh::geometry::check_positions;
use crate::mesh::{Geometry, OneRings, Topology, VertexFrames};
use crate::ops::{PrefactoredSpd, VertexPattern, add_lumped_mass, cotan_stiffness};

/// Options of [`ridges`] (module doc).
#[derive(Debug, Clone, PartialEq)]
pub struct RidgeOptions {
    /// Implicit diffusion time applied to the field before thresholding, in units of the
    /// mean edge length squared (0: none).
    pub field_smoothing: f64,
    /// Diffusion time for the indicator `S`, in units of the mean edge length squared.
    pub smoothing: f64,
    /// Diffusion time for the Hessian of `S̃`, in the same units.
    pub hessian_smoothing: f64,
    /// Threshold `σ0`; `None` for `0.75 σ_max + 0.25 σ_min` (eq. 5.3).
    pub threshold: Option<f64>,
    /// The candidate region is `S̃ > s0` (S is 0 or 1000).
    pub s0: f64,
    /// Components with fewer edges are removed.
    pub min_edges: usize,
    /// Branches at T-junctions and loops shorter than this (in edges) are removed.
    pub min_branch: usize,
    /// Join ridges at local maxima of the field.
    pub join: bool,
    /// Remove spurious valleys (§5.5.5).
    pub remove_valleys: bool,
}

impl Default for RidgeOptions {
    fn default() -> Self {
        Self {
            field_smoothing: 0.0,
            smoothing: 1.0,
            hessian_smoothing: 1.0,
            threshold: None,
            s0: 100.0,
            min_edges: 20,
            min_branch: 10,
            join: true,
            remove_valleys: false,
        }
    }
}

/// One point of a ridge: where it is on the mesh, and in space.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RidgePoint {
    /// The triangle and barycentric coordinates.
    pub at: Located,
    /// The 3-D position (at the positions given).
    pub position: DVec3,
}

/// Ridges as a graph: points and the edges between them.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Ridges {
    /// The points.
    pub points: Vec<RidgePoint>,
    /// Pairs of indices into `points`.
    pub edges: Vec<[u32; 2]>,
}

/// The height of `S` where `σ > σ0` (eq. 5.3).
const S_HIGH: f64 = 1000.0;

/// Ridges of `field` (one value per vertex) on the mesh `topology` at `positions`.
pub fn ridges(
    topology: &Topology,
    positions: &[DVec3],
    field: &[f64],
    options: &RidgeOptions,
) -> Result<Ridges, LcsError> {
    check_positions(topology, positions)?;
    check_options(options)?;
    let n = topology.n_vertices();
    if field.len() != n {
        return Err(LcsError::Shape {
            name: "field".into(),
            expected: format!("({n},)"),
            got: format!("({},)", field.len()),
        });
    }
    if let Some(vertex) = field.iter().position(|x| !x.is_finite()) {
        return Err(LcsError::NonFiniteField { vertex });
    }
    let geometry = Geometry::new(topology, positions)?;
    let mean_edge =
        geometry.edge_length.iter().sum::<f64>() / geometry.edge_length.len().max(1) as f64;
    let ell2 = mean_edge * mean_edge;
    // the smoother's ordering and first factorization need only the geometry, the
    // one-rings, frames and (unsmoothed) field gradient only the positions: side by side
    let first_h = [
        options.field_smoothing,
        options.smoothing,
        options.hessian_smoothing,
    ]
    .map(|t| t * ell2)
    .into_iter()
    .find(|&h| h != 0.0);
    let (smoother, (rings, frames, grad_field)) = rayon::join(
        || {
            let mut smoother = Smoother::new(topology, &geometry)?;
            if let Some(h) = first_h {
                smoother.prepare(h)?;
            }
            Ok::<_, LcsError>(smoother)
        },
        || {
            let rings = OneRings::new(topology);
            let frames = VertexFrames::new(&rings, positions);
            let grad = match &frames {
                Ok(frames) if options.field_smoothing == 0.0 => Some(
                    FieldOps {
                        rings: &rings,
                        frames,
                        positions,
                    }
                    .gradient(field),
                ),
                _ => None,
            };
            (rings, frames, grad)
        },
    );
    let frames = frames?;
    let mut smoother = smoother?;

    let mut sigma = field.to_vec();
    smoother.smooth(options.field_smoothing * ell2, &mut sigma, 1)?;
    let (lo, hi) = sigma
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| {
            (a.min(x), b.max(x))
        });
    let sigma0 = options.threshold.unwrap_or(0.75 * hi + 0.25 * lo);
    let mut s: Vec<f64> = sigma
        .iter()
        .map(|&x| if x > sigma0 { S_HIGH } else { 0.0 })
        .collect();
    smoother.smooth(options.smoothing * ell2, &mut s, 1)?;

    let field_ops = FieldOps {
        rings: &rings,
        frames: &frames,
        positions,
    };
    // the field's gradient was taken beside the factorization unless it was smoothed
    let grad_sigma = grad_field.unwrap_or_else(|| field_ops.gradient(&sigma));
    let grad_s = field_ops.gradient(&s);
    // Hessian of S̃ as 3-D tangent tensors (six components, column-major blocks)
    let hess = field_ops.hessian3(&grad_s);
    let mut comps = vec![0.0; 6 * n];
    for (v, h) in hess.iter().enumerate() {
        let c = [
            h.x_axis.x, h.y_axis.y, h.z_axis.z, h.y_axis.x, h.z_axis.x, h.z_axis.y,
        ];
        for (m, x) in c.into_iter().enumerate() {
            comps[m * n + v] = x;
        }
    }
    smoother.smooth(options.hessian_smoothing * ell2, &mut comps, 6)?;
    let normal: Vec<(DVec3, f64)> = (0..n)
        .into_par_iter()
        .map(|v| {
            let c = |m: usize| comps[m * n + v];
            let h = DMat3::from_cols(
                DVec3::new(c(0), c(3), c(4)),
                DVec3::new(c(3), c(1), c(5)),
                DVec3::new(c(4), c(5), c(2)),
            );
            let f = &frames.frame[v];
            let (x, y) = (f.x_axis, f.y_axis);
            let h2 = DMat2::from_cols(
                DVec2::new(x.dot(h * x), y.dot(h * x)),
                DVec2::new(x.dot(h * y), y.dot(h * y)),
            );
            let (lmin, lmax, e) = min_eigen(h2);
            (frames.to_world(v, e), lmin + lmax.abs())
        })
        .collect();

    // in the region, and S̃ curved down across more than it is curved along
    let candidate: Vec<bool> = (0..n)
        .map(|v| s[v] > options.s0 && normal[v].1 < 0.0)
        .collect();
    let graph = march(
        topology,
        positions,
        &grad_sigma,
        &normal,
        &candidate,
        options.remove_valleys,
    );
    let graph = if options.join {
        join_at_maxima(topology, &rings, positions, &sigma, &candidate, graph)
    } else {
        graph
    };
    Ok(cleanup(graph, options.min_edges, options.min_branch))
}

fn check_options(o: &RidgeOptions) -> Result<(), LcsError> {
    for (name, value) in [
        ("field_smoothing", o.field_smoothing),
        ("smoothing", o.smoothing),
        ("hessian_smoothing", o.hessian_smoothing),
    ] {
        if !(value >= 0.0 && value.is_finite()) {
            return Err(LcsError::Option {
                name,
                requirement: "finite and >= 0",
                value,
            });
        }
    }
    if !o.s0.is_finite() {
        return Err(LcsError::Option {
            name: "s0",
            requirement: "finite",
            value: o.s0,
        });
    }
    if let Some(t) = o.threshold.filter(|t| !t.is_finite()) {
        return Err(LcsError::Option {
            name: "threshold",
            requirement: "finite",
            value: t,
        });
    }
    Ok(())
}

/// Implicit diffusion `(M + hK) x = M x` (module doc), refactorized only when `h` changes.
struct Smoother<'a> {
    topology: &'a Topology,
    geometry: &'a Geometry,
    pattern: VertexPattern,
    solver: PrefactoredSpd,
    h: f64,
}

impl<'a> Smoother<'a> {
    fn new(topology: &'a Topology, geometry: &'a Geometry) -> Result<Self, LcsError> {
        let pattern = VertexPattern::new(topology);
        let solver = PrefactoredSpd::new(pattern.clone(), Par::Seq)?;
        Ok(Self {
            topology,
            geometry,
            pattern,
            solver,
            h: f64::NAN,
        })
    }

    /// Smooths `cols` fields stored one after the other in `x` (no-op for `h = 0`).
    fn smooth(&mut self, h: f64, x: &mut [f64], cols: usize) -> Result<(), LcsError> {
        if h == 0.0 {
            return Ok(());
        }
        self.prepare(h)?;
        let n = self.geometry.vertex_area.len();
        for c in 0..cols {
            for (xi, &a) in x[c * n..(c + 1) * n]
                .iter_mut()
                .zip(&self.geometry.vertex_area)
            {
                if a > 0.0 {
                    *xi *= a;
                }
            }
        }
        self.solver.solve_in_place(x);
        Ok(())
    }

    /// Factorizes `M + hK` unless it is the last factorization.
    fn prepare(&mut self, h: f64) -> Result<(), LcsError> {
        if h != self.h {
            let mut values = cotan_stiffness(self.topology, self.geometry, &self.pattern, h);
            add_lumped_mass(self.geometry, &self.pattern, 1.0, &mut values);
            // a loose vertex has no mass and no stiffness: keep it as it is
            for (v, &a) in self.geometry.vertex_area.iter().enumerate() {
                if a == 0.0 {
                    values[self.pattern.diag_slot()[v] as usize] = 1.0;
                }
            }
            self.solver.factorize(&values)?;
            self.h = h;
        }
        Ok(())
    }
}

/// Gradients by one-ring least squares in the vertex frames.
struct FieldOps<'a> {
    rings: &'a OneRings,
    frames: &'a VertexFrames,
    positions: &'a [DVec3],
}

impl FieldOps<'_> {
    fn local(&self, i: usize, j: usize) -> DVec2 {
        self.frames
            .to_local(i, self.positions[j] - self.positions[i])
    }

    /// `∇f` per vertex, as a 3-D tangent vector (zero where the fit is singular).
    fn gradient(&self, f: &[f64]) -> Vec<DVec3> {
        (0..f.len())
            .into_par_iter()
            .map(|i| {
                let (a, b) =
                    one_ring_fit(self.rings.spokes(i), |j| (self.local(i, j), f[j] - f[i]));
                solve_fit(a, b).map_or(DVec3::ZERO, |[gx, gy]| {
                    self.frames.to_world(i, DVec2::new(gx, gy))
                })
            })
            .collect()
    }

    /// The symmetrized gradient of a tangent vector field, as a 3-D tensor `Σ H_ab e_a e_bᵀ`
    /// over the frame axes `e = (x_i, y_i)`.
    fn hessian3(&self, g: &[DVec3]) -> Vec<DMat3> {
        (0..g.len())
            .into_par_iter()
            .map(|i| {
                let (a, b) =
                    one_ring_fit(self.rings.spokes(i), |j| (self.local(i, j), g[j] - g[i]));
                let Some([dx, dy]) = solve_fit(a, b) else {
                    return DMat3::ZERO;
                };
                let f = &self.frames.frame[i];
                let (x, y) = (f.x_axis, f.y_axis);
                let hxy = 0.5 * (x.dot(dy) + y.dot(dx));
                let outer = |u: DVec3, v: DVec3| DMat3::from_cols(u * v.x, u * v.y, u * v.z);
                outer(x, x) * x.dot(dx)
                    + (outer(x, y) + outer(y, x)) * hxy
                    + outer(y, y) * y.dot(dy)
            })
            .collect()
    }
}

/// The smallest and largest eigenvalues of a symmetric 2×2 matrix and a unit eigenvector
/// of the smallest.
fn min_eigen(h: DMat2) -> (f64, f64, DVec2) {
    let (a, b, c) = (h.x_axis.x, 0.5 * (h.y_axis.x + h.x_axis.y), h.y_axis.y);
    let r = (0.25 * (a - c) * (a - c) + b * b).sqrt();
    let lmin = 0.5 * (a + c) - r;
    // (H − λ) e = 0: e ∝ (b, λ − a) or (λ − c, b), whichever is longer
    let e1 = DVec2::new(b, lmin - a);
    let e2 = DVec2::new(lmin - c, b);
    let e = if e1.length_squared() >= e2.length_squared() {
        e1
    } else {
        e2
    };
    (lmin, lmin + 2.0 * r, e.normalize_or(DVec2::X))
}

/// A ridge graph before cleanup.
struct Graph {
    points: Vec<RidgePoint>,
    edges: Vec<[u32; 2]>,
    /// The mesh edge of every point (`u32::MAX` for a joined maximum).
    point_edge: Vec<u32>,
}

/// Zero crossings of eq. 5.4 on the edges and marching through the triangles.
fn march(
    topology: &Topology,
    positions: &[DVec3],
    grad: &[DVec3],
    normal: &[(DVec3, f64)],
    candidate: &[bool],
    remove_valleys: bool,
) -> Graph {
    let crossing: Vec<Option<f64>> = topology
        .edges()
        .par_iter()
        .map(|&[i, j]| {
            let (i, j) = (i as usize, j as usize);
            if !(candidate[i] && candidate[j]) {
                return None;
            }
            let (ni, mut nj) = (normal[i].0, normal[j].0);
            if ni.dot(nj) < 0.0 {
                nj = -nj;
            }
            let (ai, aj) = (ni.dot(grad[i]), nj.dot(grad[j]));
            if ai * aj >= 0.0 || ai.is_nan() || aj.is_nan() {
                return None;
            }
            if remove_valleys {
                let e = (positions[j] - positions[i]).normalize_or_zero();
                let along = |n: DVec3| n.dot(e).abs() > std::f64::consts::FRAC_1_SQRT_2;
                let into_i = grad[i].dot(normal[i].0) * normal[i].0.dot(e) > 0.0;
                let into_j = grad[j].dot(normal[j].0) * normal[j].0.dot(-e) > 0.0;
                if along(normal[i].0) && along(normal[j].0) && !(into_i && into_j) {
                    return None;
                }
            }
            Some(ai / (ai - aj))
        })
        .collect();
    let mut edge_point = vec![u32::MAX; topology.n_edges()];
    let mut points = Vec::new();
    let mut point_edge = Vec::new();
    let mut edge_face = vec![u32::MAX; topology.n_edges()];
    for (f, fe) in topology.face_edges().iter().enumerate().rev() {
        for &e in fe {
            edge_face[e as usize] = f as u32;
        }
    }
    for (e, c) in crossing.iter().enumerate() {
        let Some(t) = *c else { continue };
        let [i, j] = topology.edges()[e];
        let f = edge_face[e] as usize;
        let tri = topology.faces()[f];
        let mut bary = DVec3::ZERO;
        for (k, &v) in tri.iter().enumerate() {
            if v == i {
                bary[k] = 1.0 - t;
            } else if v == j {
                bary[k] = t;
            }
        }
        edge_point[e] = points.len() as u32;
        points.push(RidgePoint {
            at: Located {
                face: f as u32,
                bary,
            },
            position: positions[i as usize].lerp(positions[j as usize], t),
        });
        point_edge.push(e as u32);
    }
    let mut edges = Vec::new();
    for fe in topology.face_edges() {
        let p: Vec<u32> = fe
            .iter()
            .map(|&e| edge_point[e as usize])
            .filter(|&p| p != u32::MAX)
            .collect();
        match p.len() {
            2 => edges.push([p[0], p[1]]),
            3 => {
                let x = [p[0], p[1], p[2]].map(|q| points[q as usize].position);
                let angle = |k: usize| {
                    let (a, b) = (x[(k + 1) % 3] - x[k], x[(k + 2) % 3] - x[k]);
                    a.angle_between(b)
                };
                let k = (0..3)
                    .max_by(|&a, &b| angle(a).total_cmp(&angle(b)))
                    .unwrap_or(0);
                edges.push([p[k], p[(k + 1) % 3]]);
                edges.push([p[k], p[(k + 2) % 3]]);
            }
            _ => {}
        }
    }
    Graph {
        points,
        edges,
        point_edge,
    }
}

/// Joins the ridges at the local maxima of `sigma` in the candidate region (module doc).
fn join_at_maxima(
    topology: &Topology,
    rings: &OneRings,
    positions: &[DVec3],
    sigma: &[f64],
    candidate: &[bool],
    mut g: Graph,
) -> Graph {
    let n = topology.n_vertices();
    let maxima: Vec<usize> = (0..n)
        .filter(|&v| {
            let spokes = rings.spokes(v);
            candidate[v]
                && !spokes.is_empty()
                && spokes.iter().all(|&j| sigma[j as usize] < sigma[v])
        })
        .collect();
    if maxima.is_empty() {
        return g;
    }
    // the point on every edge, to find those on a maximum's spokes
    let mut edge_point = vec![u32::MAX; topology.n_edges()];
    for (p, &e) in g.point_edge.iter().enumerate() {
        edge_point[e as usize] = p as u32;
    }
    let mut replace: Vec<u32> = (0..g.points.len() as u32).collect();
    let mut vertex_faces: Vec<Vec<u32>> = vec![Vec::new(); n];
    for (f, tri) in topology.faces().iter().enumerate() {
        for &v in tri {
            vertex_faces[v as usize].push(f as u32);
        }
    }
    let mut max_nodes = Vec::new();
    for &m in &maxima {
        let node = g.points.len() as u32;
        let f = vertex_faces[m][0];
        let mut bary = DVec3::ZERO;
        let corner = topology.faces()[f as usize]
            .iter()
            .position(|&v| v as usize == m)
            .unwrap_or(0);
        bary[corner] = 1.0;
        g.points.push(RidgePoint {
            at: Located { face: f, bary },
            position: positions[m],
        });
        g.point_edge.push(u32::MAX);
        replace.push(node);
        for &j in rings.spokes(m) {
            let e = rings_edge(topology, m, j as usize);
            if let Some(e) = e {
                let p = edge_point[e];
                if p != u32::MAX {
                    replace[p as usize] = node;
                }
            }
        }
        max_nodes.push((m, node));
    }
    let mut edges: Vec<[u32; 2]> = g
        .edges
        .iter()
        .map(|&[a, b]| {
            let (a, b) = (replace[a as usize], replace[b as usize]);
            [a.min(b), a.max(b)]
        })
        .filter(|[a, b]| a != b)
        .collect();
    edges.sort_unstable();
    edges.dedup();
    // move each maximum to the average of its neighbours, located on its nearest face
    for (m, node) in max_nodes {
        let nbrs: Vec<DVec3> = edges
            .iter()
            .filter_map(|&[a, b]| {
                (a == node)
                    .then_some(b)
                    .or((b == node).then_some(a))
                    .map(|o| g.points[o as usize].position)
            })
            .collect();
        if nbrs.is_empty() {
            continue;
        }
        let target = nbrs.iter().sum::<DVec3>() / nbrs.len() as f64;
        let best = vertex_faces[m]
            .iter()
            .map(|&f| {
                let tri = topology.faces()[f as usize].map(|v| positions[v as usize]);
                let b = project_bary(tri, target);
                (b.min_element(), f, b)
            })
            .max_by(|a, b| a.0.total_cmp(&b.0));
        if let Some((_, f, b)) = best {
            let b = b.max(DVec3::ZERO);
            let b = b / b.element_sum().max(f64::MIN_POSITIVE);
            let tri = topology.faces()[f as usize].map(|v| positions[v as usize]);
            g.points[node as usize] = RidgePoint {
                at: Located { face: f, bary: b },
                position: b.x * tri[0] + b.y * tri[1] + b.z * tri[2],
            };
        }
    }
    g.edges = edges;
    g
}

/// The mesh edge between `a` and `b` (binary search in the sorted edge list).
fn rings_edge(topology: &Topology, a: usize, b: usize) -> Option<usize> {
    let key = [a.min(b) as u32, a.max(b) as u32];
    topology.edges().binary_search(&key).ok()
}

/// Barycentric coordinates of the projection of `p` on the plane of `tri`.
fn project_bary(tri: [DVec3; 3], p: DVec3) -> DVec3 {
    let (e1, e2, d) = (tri[1] - tri[0], tri[2] - tri[0], p - tri[0]);
    let (g11, g12, g22) = (e1.dot(e1), e1.dot(e2), e2.dot(e2));
    let det = g11 * g22 - g12 * g12;
    if det <= 0.0 {
        return DVec3::new(1.0, 0.0, 0.0);
    }
    let (r1, r2) = (e1.dot(d), e2.dot(d));
    let b1 = (g22 * r1 - g12 * r2) / det;
    let b2 = (g11 * r2 - g12 * r1) / det;
    DVec3::new(1.0 - b1 - b2, b1, b2)
}

/// A chain of the graph between two nodes of degree other than 2.
struct Chain {
    ends: [u32; 2],
    edges: Vec<u32>,
}

/// Chains between nodes of degree ≠ 2 (closed cycles of degree-2 nodes are left out).
fn chains(n_points: usize, edges: &[[u32; 2]], alive: &[bool]) -> Vec<Chain> {
    let mut adj: Vec<Vec<(u32, u32)>> = vec![Vec::new(); n_points];
    for (e, &[a, b]) in edges.iter().enumerate().filter(|(e, _)| alive[*e]) {
        adj[a as usize].push((b, e as u32));
        adj[b as usize].push((a, e as u32));
    }
    let mut seen = vec![false; edges.len()];
    let mut out = Vec::new();
    for start in 0..n_points {
        if adj[start].len() == 2 || adj[start].is_empty() {
            continue;
        }
        for &(next, e0) in &adj[start] {
            if seen[e0 as usize] {
                continue;
            }
            seen[e0 as usize] = true;
            let mut chain = vec![e0];
            let (mut prev_e, mut at) = (e0, next);
            while adj[at as usize].len() == 2 {
                let &(nx, e) = adj[at as usize]
                    .iter()
                    .find(|&&(_, e)| e != prev_e)
                    .unwrap_or(&adj[at as usize][0]);
                if seen[e as usize] {
                    break;
                }
                seen[e as usize] = true;
                chain.push(e);
                prev_e = e;
                at = nx;
            }
            out.push(Chain {
                ends: [start as u32, at],
                edges: chain,
            });
        }
    }
    out
}

/// Cleanup of §5.5.4 (module doc) and compaction of the points.
fn cleanup(g: Graph, min_edges: usize, min_branch: usize) -> Ridges {
    let np = g.points.len();
    let mut alive = vec![true; g.edges.len()];
    for _pass in 0..16 {
        let mut degree = vec![0usize; np];
        for (&[a, b], _) in g.edges.iter().zip(&alive).filter(|(_, al)| **al) {
            degree[a as usize] += 1;
            degree[b as usize] += 1;
        }
        let junction = |p: u32| degree[p as usize] >= 3;
        let all = chains(np, &g.edges, &alive);
        let mut remove: Vec<(usize, usize)> = Vec::new(); // (length, chain)
        for (c, ch) in all.iter().enumerate() {
            let len = ch.edges.len();
            if len >= min_branch {
                continue;
            }
            let [a, b] = ch.ends;
            let branch = (junction(a) && degree[b as usize] == 1)
                || (junction(b) && degree[a as usize] == 1);
            let loop_ = a == b && junction(a);
            let parallel = a != b
                && junction(a)
                && junction(b)
                && all.iter().enumerate().any(|(d, o)| {
                    d != c
                        && o.edges.len() < min_branch
                        && (o.ends == [a, b] || o.ends == [b, a])
                        && (o.edges.len(), o.edges[0]) < (len, ch.edges[0])
                });
            if branch || loop_ || parallel {
                remove.push((len, c));
            }
        }
        if remove.is_empty() {
            break;
        }
        remove.sort_unstable();
        let mut touched = vec![false; np];
        for (_, c) in remove {
            let ch = &all[c];
            let js: Vec<u32> = ch.ends.into_iter().filter(|&p| junction(p)).collect();
            if js.iter().any(|&p| touched[p as usize]) {
                continue;
            }
            js.iter().for_each(|&p| touched[p as usize] = true);
            ch.edges.iter().for_each(|&e| alive[e as usize] = false);
        }
    }
    // union–find components; drop those under min_edges
    let mut parent: Vec<u32> = (0..np as u32).collect();
    fn find(parent: &mut [u32], mut x: u32) -> u32 {
        while parent[x as usize] != x {
            parent[x as usize] = parent[parent[x as usize] as usize];
            x = parent[x as usize];
        }
        x
    }
    for (&[a, b], _) in g.edges.iter().zip(&alive).filter(|(_, al)| **al) {
        let (ra, rb) = (find(&mut parent, a), find(&mut parent, b));
        if ra != rb {
            parent[ra.max(rb) as usize] = ra.min(rb);
        }
    }
    let mut size = vec![0usize; np];
    for (&[a, _], _) in g.edges.iter().zip(&alive).filter(|(_, al)| **al) {
        size[find(&mut parent, a) as usize] += 1;
    }
    let mut index = vec![u32::MAX; np];
    let mut out = Ridges::default();
    for (&[a, b], _) in g.edges.iter().zip(&alive).filter(|(_, al)| **al) {
        if size[find(&mut parent, a) as usize] < min_edges {
            continue;
        }
        let mut id = |p: u32| {
            if index[p as usize] == u32::MAX {
                index[p as usize] = out.points.len() as u32;
                out.points.push(g.points[p as usize]);
            }
            index[p as usize]
        };
        let e = [id(a), id(b)];
        out.edges.push(e);
    }
    out
}
