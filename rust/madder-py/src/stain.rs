//! `DiffusionStepper`: implicit diffusion on a deforming mesh (core module `stain`).

use numpy::ndarray::{Ix1, Ix2, Ix3};
use numpy::{PyArray1, PyArrayMethods, PyUntypedArrayMethods};
use pyo3::prelude::*;

use crate::args;
use crate::errors::{ParameterError, to_py};
use crate::mesh::{Topology, dpoints, points};
use crate::threads::Pool;

/// Diffuses a density (per unit area, one value per vertex) while the mesh moves.
///
/// `DiffusionStepper(topology, positions, density, rate=None, *, face_tensors=None,
/// face_uv=None, face_angle=None, threads=None)`: `positions` is the `(N, 3)` start pose
/// (read as float32), `density` a `(N,)` array. Either `rate`, an isotropic diffusion
/// coefficient in m²/s, or a woven cloth: `face_tensors` `(F, 3)` `[s11, s12, s22]` in m²/s
/// in each face's (weft, warp) basis, `face_uv` `(F, 3, 2)` corner UVs (the weft is the UV
/// u axis) and optionally `face_angle` `(F,)` weft offsets in radians. Array arguments take
/// any float dtype and layout (see `args.rs`).
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
        positions: &Bound<'_, PyAny>,
        density: &Bound<'_, PyAny>,
        rate: Option<f64>,
        face_tensors: Option<&Bound<'_, PyAny>>,
        face_uv: Option<&Bound<'_, PyAny>>,
        face_angle: Option<&Bound<'_, PyAny>>,
        threads: Option<usize>,
    ) -> PyResult<Self> {
        let conductivity = conductivity(rate, face_tensors, face_uv, face_angle)?;
        let pos = points("positions", positions)?;
        let density = args::floats::<f64, Ix1>("density", density)?
            .as_array()
            .to_vec();
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

    /// Moves the mesh to `positions` ((N, 3), read as float32) over `dt` seconds, diffusing in
    /// `substeps` implicit steps. Releases the GIL. On error the state is unchanged.
    #[pyo3(signature = (positions, dt, substeps=1))]
    fn step(
        &mut self,
        py: Python<'_>,
        positions: &Bound<'_, PyAny>,
        dt: f64,
        substeps: u32,
    ) -> PyResult<()> {
        let pos = points("positions", positions)?;
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

    /// Starts tracking the liquid's colour; `colors` `(N, 3)` is the RGB of the
    /// liquid now at each vertex. Colours then mix by mass as the liquid spreads.
    fn enable_color(&mut self, colors: &Bound<'_, PyAny>) -> PyResult<()> {
        let c: Vec<[f64; 3]> = dpoints("colors", colors)?
            .into_iter()
            .map(|v| v.to_array())
            .collect();
        self.inner.enable_color(&c).map_err(to_py)
    }

    /// Adds `delta` `(N,)` liquid per unit area (≥ 0) at every vertex, of colour
    /// `color` (RGB; required once colour is tracked).
    #[pyo3(signature = (delta, color=None))]
    fn add_liquid(&mut self, delta: &Bound<'_, PyAny>, color: Option<[f64; 3]>) -> PyResult<()> {
        let d = args::floats::<f64, Ix1>("delta", delta)?
            .as_array()
            .to_vec();
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
    tensors: Option<&Bound<'_, PyAny>>,
    uv: Option<&Bound<'_, PyAny>>,
    angle: Option<&Bound<'_, PyAny>>,
) -> PyResult<madder::stain::Conductivity> {
    use madder::stain::{Conductivity, WovenFaces};
    let tensors = tensors
        .map(|t| args::floats::<f64, Ix2>("face_tensors", t))
        .transpose()?;
    let uv = uv
        .map(|u| args::floats::<f64, Ix3>("face_uv", u))
        .transpose()?;
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
                .map(|f| std::array::from_fn(|k| [uv[[f, k, 0]], uv[[f, k, 1]]]))
                .collect();
            let angle = match angle {
                Some(a) => args::floats::<f64, Ix1>("face_angle", a)?
                    .as_array()
                    .to_vec(),
                None => vec![0.0; tensor.len()],
            };
            Ok(Conductivity::Woven(WovenFaces { tensor, uv, angle }))
        }
        _ => Err(ParameterError::new_err(
            "give either rate (isotropic) or both face_tensors and face_uv (woven cloth)",
        )),
    }
}
