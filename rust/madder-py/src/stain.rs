//! `DiffusionStepper`: implicit diffusion on a deforming mesh (core module `stain`).

use numpy::{
    PyArray1, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2, PyReadonlyArray3,
    PyUntypedArrayMethods,
};
use pyo3::prelude::*;

use crate::errors::{ParameterError, to_py};
use crate::mesh::{Topology, points};
use crate::threads::Pool;

/// Diffuses a density (per unit area, one value per vertex) while the mesh moves.
///
/// `DiffusionStepper(topology, positions, density, rate=None, *, face_tensors=None,
/// face_uv=None, face_angle=None, threads=None)`: `positions` is the `(N, 3)` float32 start
/// pose, `density` a `(N,)` float32 array. Either `rate`, an isotropic diffusion coefficient
/// in m²/s, or a woven cloth: `face_tensors` `(F, 3)` float64 `[s11, s12, s22]` in m²/s in
/// each face's (weft, warp) basis, `face_uv` `(F, 3, 2)` float32 corner UVs (the weft is the
/// UV u axis) and optionally `face_angle` `(F,)` float32 weft offsets in radians.
/// `threads` caps the worker threads (results do not depend on it).
#[pyclass(module = "madder")]
pub struct DiffusionStepper {
    inner: madder::stain::DiffusionStepper,
    pool: Pool,
}

#[pymethods]
impl DiffusionStepper {
    #[new]
    #[pyo3(signature = (topology, positions, density, rate=None, *, face_tensors=None, face_uv=None, face_angle=None, threads=None))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        py: Python<'_>,
        topology: &Topology,
        positions: PyReadonlyArray2<'_, f32>,
        density: PyReadonlyArray1<'_, f32>,
        rate: Option<f64>,
        face_tensors: Option<PyReadonlyArray2<'_, f64>>,
        face_uv: Option<PyReadonlyArray3<'_, f32>>,
        face_angle: Option<PyReadonlyArray1<'_, f32>>,
        threads: Option<usize>,
    ) -> PyResult<Self> {
        let conductivity = conductivity(rate, face_tensors, face_uv, face_angle)?;
        let pos = points(&positions)?;
        let density: Vec<f64> = density.as_array().iter().map(|&d| d as f64).collect();
        let topo = topology.inner.clone();
        let pool = Pool::new(threads)?;
        let inner = pool.run(py, || {
            madder::stain::DiffusionStepper::new(topo, &pos, density, conductivity, faer::Par::Seq)
        });
        Ok(Self {
            inner: inner.map_err(to_py)?,
            pool,
        })
    }

    /// Moves the mesh to `positions` ((N, 3) float32) over `dt` seconds, diffusing in
    /// `substeps` implicit steps. Releases the GIL. On error the state is unchanged.
    #[pyo3(signature = (positions, dt, substeps=1))]
    fn step(
        &mut self,
        py: Python<'_>,
        positions: PyReadonlyArray2<'_, f32>,
        dt: f64,
        substeps: u32,
    ) -> PyResult<()> {
        let pos = points(&positions)?;
        let Self { inner, pool } = self;
        pool.run(py, || inner.step(&pos, dt, substeps))
            .map_err(to_py)
    }

    /// Density per unit area at every vertex, as a new float32 array.
    #[getter]
    fn density<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f32>> {
        PyArray1::from_vec(py, self.inner.density().iter().map(|&d| d as f32).collect())
    }

    /// Lumped area of every vertex at the current pose, float64.
    #[getter]
    fn vertex_area<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_vec(py, self.inner.vertex_area().to_vec())
    }

    /// Number of faces whose UVs were degenerate (weft fell back to an edge direction).
    #[getter]
    fn degenerate_uv_faces(&self) -> usize {
        self.inner.degenerate_uv_faces()
    }

    /// Starts tracking the liquid's colour; `colors` `(N, 3)` float32 is the RGB of the
    /// liquid now at each vertex. Colours then mix by mass as the liquid spreads.
    fn enable_color(&mut self, colors: PyReadonlyArray2<'_, f32>) -> PyResult<()> {
        let c: Vec<[f64; 3]> = points(&colors)?
            .into_iter()
            .map(|v| v.as_dvec3().to_array())
            .collect();
        self.inner.enable_color(&c).map_err(to_py)
    }

    /// Adds `delta` `(N,)` float32 liquid per unit area (≥ 0) at every vertex, of colour
    /// `color` (RGB; required once colour is tracked).
    #[pyo3(signature = (delta, color=None))]
    fn add_liquid(
        &mut self,
        delta: PyReadonlyArray1<'_, f32>,
        color: Option<[f64; 3]>,
    ) -> PyResult<()> {
        let d: Vec<f64> = delta.as_array().iter().map(|&x| x as f64).collect();
        self.inner.add_liquid(&d, color).map_err(to_py)
    }

    /// RGB of the liquid at each vertex `(N, 3)` float32, or None when colour is not tracked.
    #[getter]
    fn color<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, numpy::PyArray2<f32>>>> {
        let Some(c) = self.inner.color() else {
            return Ok(None);
        };
        let flat: Vec<f32> = c.iter().flatten().map(|&x| x as f32).collect();
        Ok(Some(PyArray1::from_vec(py, flat).reshape([c.len(), 3])?))
    }

    /// Total stain mass `Σ A_i σ_i` (float64).
    fn total_mass(&self) -> f64 {
        self.inner.total_mass()
    }
}

pub(crate) fn conductivity(
    rate: Option<f64>,
    tensors: Option<PyReadonlyArray2<'_, f64>>,
    uv: Option<PyReadonlyArray3<'_, f32>>,
    angle: Option<PyReadonlyArray1<'_, f32>>,
) -> PyResult<madder::stain::Conductivity> {
    use madder::stain::{Conductivity, WovenFaces};
    match (rate, tensors, uv) {
        (Some(d), None, None) => Ok(Conductivity::Isotropic(d)),
        (None, Some(t), Some(uv)) => {
            if t.shape()[1] != 3 || uv.shape()[1..] != [3, 2] {
                return Err(ParameterError::new_err(format!(
                    "face_tensors must be (F, 3) and face_uv (F, 3, 2); got {:?} and {:?}",
                    t.shape(),
                    uv.shape()
                )));
            }
            let tensor: Vec<[f64; 3]> = t
                .as_array()
                .rows()
                .into_iter()
                .map(|r| [r[0], r[1], r[2]])
                .collect();
            let uv = uv.as_array();
            let uv: Vec<[[f64; 2]; 3]> = (0..uv.shape()[0])
                .map(|f| std::array::from_fn(|k| [uv[[f, k, 0]] as f64, uv[[f, k, 1]] as f64]))
                .collect();
            let angle = match angle {
                Some(a) => a.as_array().iter().map(|&x| x as f64).collect(),
                None => vec![0.0; tensor.len()],
            };
            Ok(Conductivity::Woven(WovenFaces { tensor, uv, angle }))
        }
        _ => Err(ParameterError::new_err(
            "give either rate (isotropic) or both face_tensors and face_uv (woven cloth)",
        )),
    }
}
