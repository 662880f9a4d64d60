//! `ftle` and `ridges`: Lagrangian coherent structures (core module `lcs`, seed ch. 5).
//!
//! Conversion only: numpy arrays in and out, a Python velocity callable wrapped as a core
//! `Velocity` (called once per Runge–Kutta stage with every live particle, the GIL taken back for
//! each call), the GIL released for everything else.

use glam::DVec3;
use numpy::ndarray::{Ix1, Ix2, IxDyn};
use numpy::{
    PyArray1, PyArrayDyn, PyArrayMethods, PyReadonlyArray2, PyReadonlyArrayDyn,
    PyUntypedArrayMethods,
};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use madder::LcsError;
use madder::lcs::{FrameTimes, Located, Motion, RidgeOptions, Scheme, Velocity, VertexVelocity};

use crate::args;
use crate::errors::to_py;

/// The topology of `faces` (`(F, 3)`, any integer dtype), an error naming a mesh without
/// triangles.
fn topology(faces: &Bound<'_, PyAny>, n: usize) -> PyResult<madder::mesh::Topology> {
    let faces: PyReadonlyArray2<'_, u32> = args::indices("faces", faces)?;
    let shape = faces.shape();
    if shape[1] != 3 {
        return Err(to_py(shape_error("faces", "(F, 3)", shape)));
    }
    if shape[0] == 0 {
        return Err(to_py(LcsError::NoTriangles));
    }
    let a = faces.as_array();
    // the usual C-contiguous array read as one slice rather than row by row
    let tris = match a.as_slice() {
        Some(s) => s.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect(),
        None => a.rows().into_iter().map(|r| [r[0], r[1], r[2]]).collect(),
    };
    madder::mesh::Topology::from_triangles(n, tris).map_err(to_py)
}

fn shape_error(name: &str, expected: &str, got: &[usize]) -> LcsError {
    LcsError::Shape {
        name: name.into(),
        expected: expected.into(),
        got: format!("{got:?}").replace('[', "(").replace(']', ")"),
    }
}

/// `(..., 3)` float64 rows as points.
fn rows3(a: &numpy::ndarray::ArrayViewD<'_, f64>) -> Vec<DVec3> {
    a.as_slice().map_or_else(
        || {
            let v: Vec<f64> = a.iter().copied().collect();
            v.chunks_exact(3)
                .map(|c| DVec3::new(c[0], c[1], c[2]))
                .collect()
        },
        |s| {
            s.chunks_exact(3)
                .map(|c| DVec3::new(c[0], c[1], c[2]))
                .collect()
        },
    )
}

/// Per-frame `(K, N, 3)` or single `(N, 3)` positions: `(frames, n_vertices)`.
fn frames(name: &str, a: &PyReadonlyArrayDyn<'_, f64>) -> PyResult<(Vec<Vec<DVec3>>, usize)> {
    let shape = a.shape().to_vec();
    let view = a.as_array();
    match shape.as_slice() {
        [n, 3] => Ok((vec![rows3(&view)], *n)),
        [k, n, 3] => {
            let all = rows3(&view);
            Ok((
                (0..*k).map(|f| all[f * n..(f + 1) * n].to_vec()).collect(),
                *n,
            ))
        }
        _ => Err(to_py(shape_error(name, "(N, 3) or (K, N, 3)", &shape))),
    }
}

/// A Python callable `f(t, points (M, 3)) -> (M, 3)` as a core velocity.
struct PyVelocity<'a> {
    f: &'a Py<PyAny>,
    /// The callable's own exception, raised as it is.
    raised: Option<PyErr>,
}

impl Velocity for PyVelocity<'_> {
    fn eval(
        &mut self,
        t: f64,
        _at: &[Located],
        points: &[DVec3],
        out: &mut [DVec3],
    ) -> Result<(), LcsError> {
        Python::attach(|py| {
            let flat: Vec<f64> = points.iter().flat_map(|p| p.to_array()).collect();
            let m = points.len();
            let result = PyArray1::from_vec(py, flat)
                .reshape([m, 3])
                .and_then(|arr| self.f.call1(py, (t, arr)))
                .and_then(|r| {
                    py.import("numpy")?
                        .getattr("asarray")?
                        .call1((r, "float64"))
                });
            let r = match result {
                Ok(r) => r,
                Err(e) => {
                    let message = e.to_string();
                    self.raised = Some(e);
                    return Err(LcsError::Callable { time: t, message });
                }
            };
            let name = || {
                let repr = self.f.bind(py).repr().map_or("?".into(), |r| r.to_string());
                format!("the result of the velocity callable {repr} at time {t}")
            };
            let arr = r
                .cast_into::<PyArrayDyn<f64>>()
                .map_err(|_| shape_error(&name(), "a float array", &[]))?;
            let ro = arr.readonly();
            if ro.shape() != [m, 3] {
                return Err(shape_error(&name(), &format!("({m}, 3)"), ro.shape()));
            }
            let view = ro.as_array();
            match view.as_slice() {
                // the usual C-contiguous result: copied straight into `out`
                Some(s) => {
                    for (o, c) in out.iter_mut().zip(s.chunks_exact(3)) {
                        *o = DVec3::new(c[0], c[1], c[2]);
                    }
                }
                None => {
                    for (o, p) in out.iter_mut().zip(rows3(&view)) {
                        *o = p;
                    }
                }
            }
            Ok(())
        })
    }

    fn uses_location(&self) -> bool {
        false
    }
}

/// Finite-time Lyapunov exponent `σ = ln √λ_max / |T|` at every vertex (seed §5.2, §5.5.1).
///
/// `faces` `(F, 3)` (any integer dtype); `positions` `(N, 3)` for a fixed mesh or `(K, N, 3)`
/// per frame (at `times`, `(K,)` increasing); `velocity` a callable
/// `f(t, points (M, 3)) -> (M, 3)` of world points (called once per Runge–Kutta stage with
/// all particles) or a `(K, N, 3)` array of per-vertex velocities at `times` (`(N, 3)`:
/// constant), relative to the cloth, projected on each triangle. Particles start at the
/// vertices at `t0` and are traced over `T` (negative: backward) in `steps` fixed steps of
/// `method`: `"rk4"` (classical, 4 stages) or `"rk8"` (DOP853's eighth-order solution, 12
/// stages). Array arguments take any float dtype (converted to float64). Returns `(N,)`
/// float64.
#[pyfunction]
#[pyo3(signature = (faces, positions, velocity, t0, T, *, steps=100, times=None, method="rk4"))]
#[allow(non_snake_case, clippy::too_many_arguments)]
pub fn ftle<'py>(
    py: Python<'py>,
    faces: &Bound<'py, PyAny>,
    positions: &Bound<'py, PyAny>,
    velocity: Bound<'py, PyAny>,
    t0: f64,
    T: f64,
    steps: usize,
    times: Option<&Bound<'py, PyAny>>,
    method: &str,
) -> PyResult<Bound<'py, PyArray1<f64>>> {
    let scheme = Scheme::from_name(method).ok_or_else(|| {
        to_py(LcsError::Method {
            method: method.into(),
        })
    })?;
    let positions = args::floats::<f64, IxDyn>("positions", positions)?;
    let (pos_frames, n) = frames("positions", &positions)?;
    let topo = topology(faces, n)?;
    let times = match times {
        Some(t) => {
            let t = args::floats::<f64, Ix1>("times", t)?.as_array().to_vec();
            Some(FrameTimes::new(t).map_err(to_py)?)
        }
        None => None,
    };
    let need_times = |what: &str, k: usize| -> PyResult<FrameTimes> {
        match &times {
            Some(t) if t.times().len() == k => Ok(t.clone()),
            Some(t) => Err(to_py(shape_error(
                "times",
                &format!("({k},), one per frame of {what}"),
                &[t.times().len()],
            ))),
            None => Err(to_py(shape_error(
                "times",
                &format!("({k},) for the {k} frames of {what}"),
                &[],
            ))),
        }
    };
    let motion = if pos_frames.len() == 1 && positions.ndim() == 2 {
        Motion::fixed(pos_frames.into_iter().next().unwrap_or_default())
    } else {
        let k = pos_frames.len();
        Motion::frames(need_times("positions", k)?, pos_frames).map_err(to_py)?
    };
    let sigma = if velocity.is_callable() {
        let f: Py<PyAny> = velocity.unbind();
        let mut v = PyVelocity {
            f: &f,
            raised: None,
        };
        let r = py.detach(|| madder::lcs::ftle_with(&topo, &motion, &mut v, t0, T, scheme, steps));
        match (r, v.raised.take()) {
            (Ok(s), _) => s,
            (Err(LcsError::Callable { .. }), Some(e)) => return Err(e),
            (Err(e), _) => return Err(to_py(e)),
        }
    } else {
        let arr: PyReadonlyArrayDyn<'py, f64> =
            args::floats("velocity (a callable f(t, points) or an array)", &velocity)?;
        let (vel_frames, nv) = frames("velocity", &arr)?;
        if nv != n {
            return Err(to_py(shape_error(
                "velocity",
                &format!("({}, {n}, 3)", vel_frames.len()),
                arr.shape(),
            )));
        }
        let ft = if arr.ndim() == 2 {
            FrameTimes::new(vec![t0]).map_err(to_py)?
        } else {
            need_times("velocity", vel_frames.len())?
        };
        let constant = arr.ndim() == 2;
        let mut v = VertexVelocity::new(ft, vel_frames, &topo).map_err(to_py)?;
        if constant {
            let mut c = Constant(v);
            py.detach(|| madder::lcs::ftle_with(&topo, &motion, &mut c, t0, T, scheme, steps))
        } else {
            py.detach(|| madder::lcs::ftle_with(&topo, &motion, &mut v, t0, T, scheme, steps))
        }
        .map_err(to_py)?
    };
    Ok(PyArray1::from_vec(py, sigma))
}

/// Per-vertex velocities of one frame, the same at every time.
struct Constant(VertexVelocity);

impl Velocity for Constant {
    fn eval(
        &mut self,
        _t: f64,
        at: &[Located],
        points: &[DVec3],
        out: &mut [DVec3],
    ) -> Result<(), LcsError> {
        let t = self.0.times()[0];
        self.0.eval(t, at, points, out)
    }
}

/// Ridges of a scalar `field` `(N,)` on a triangle mesh (seed §5.4, §5.5.2–§5.5.5):
/// a dict with `triangles` `(P,)` uint32 and `barycentric` `(P, 3)` float64 (where each
/// point is on the mesh), `points` `(P, 3)` float64 (at `positions`) and `edges` `(E, 2)`
/// uint32 (pairs of points). `smoothing`, `hessian_smoothing` and `field_smoothing` are
/// implicit diffusion times in units of the mean edge length squared; `threshold` is
/// `σ0` (default `0.75 max + 0.25 min`); `s0` the candidate level of the smoothed
/// indicator (0–1000); components under `min_edges` edges and T-junction branches and
/// loops under `min_branch` edges are removed. Array arguments as for `ftle`.
#[pyfunction]
#[pyo3(signature = (faces, positions, field, *, smoothing=1.0, hessian_smoothing=1.0, field_smoothing=0.0, threshold=None, s0=100.0, min_edges=20, min_branch=10, join=true, remove_valleys=false))]
#[allow(clippy::too_many_arguments)]
pub fn ridges<'py>(
    py: Python<'py>,
    faces: &Bound<'py, PyAny>,
    positions: &Bound<'py, PyAny>,
    field: &Bound<'py, PyAny>,
    smoothing: f64,
    hessian_smoothing: f64,
    field_smoothing: f64,
    threshold: Option<f64>,
    s0: f64,
    min_edges: usize,
    min_branch: usize,
    join: bool,
    remove_valleys: bool,
) -> PyResult<Bound<'py, PyDict>> {
    let positions = args::floats::<f64, Ix2>("positions", positions)?;
    if positions.shape()[1] != 3 {
        return Err(to_py(shape_error("positions", "(N, 3)", positions.shape())));
    }
    let pos = rows3(&positions.as_array().into_dyn());
    let topo = topology(faces, pos.len())?;
    let field = args::floats::<f64, Ix1>("field", field)?
        .as_array()
        .to_vec();
    let options = RidgeOptions {
        field_smoothing,
        smoothing,
        hessian_smoothing,
        threshold,
        s0,
        min_edges,
        min_branch,
        join,
        remove_valleys,
    };
    let r = py
        .detach(|| madder::lcs::ridges(&topo, &pos, &field, &options))
        .map_err(to_py)?;
    let p = r.points.len();
    let d = PyDict::new(py);
    let tri: Vec<u32> = r.points.iter().map(|q| q.at.face).collect();
    let bary: Vec<f64> = r.points.iter().flat_map(|q| q.at.bary.to_array()).collect();
    let xyz: Vec<f64> = r
        .points
        .iter()
        .flat_map(|q| q.position.to_array())
        .collect();
    let edges: Vec<u32> = r.edges.iter().flatten().copied().collect();
    d.set_item("triangles", PyArray1::from_vec(py, tri))?;
    d.set_item("barycentric", PyArray1::from_vec(py, bary).reshape([p, 3])?)?;
    d.set_item("points", PyArray1::from_vec(py, xyz).reshape([p, 3])?)?;
    d.set_item(
        "edges",
        PyArray1::from_vec(py, edges).reshape([r.edges.len(), 2])?,
    )?;
    Ok(d)
}
