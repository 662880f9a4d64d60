//! `DiffusionStepper`: implicit diffusion on a deforming mesh (core module `stain`).

use numpy::{PyArray1, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::prelude::*;

use crate::errors::{ParameterError, to_py};
use crate::mesh::{Topology, points};

/// Diffuses a density (per unit area, one value per vertex) while the mesh moves.
///
/// `DiffusionStepper(topology, positions, density, rate, threads=None)`: `positions` is the
/// `(N, 3)` float32 start pose, `density` a `(N,)` float32 array, `rate` the diffusion
/// coefficient in m²/s. `threads` caps the worker threads (results do not depend on it).
#[pyclass(module = "madder")]
pub struct DiffusionStepper {
    inner: madder::stain::DiffusionStepper,
    pool: Option<rayon::ThreadPool>,
}

#[pymethods]
impl DiffusionStepper {
    #[new]
    #[pyo3(signature = (topology, positions, density, rate, threads=None))]
    fn new(
        py: Python<'_>,
        topology: &Topology,
        positions: PyReadonlyArray2<'_, f32>,
        density: PyReadonlyArray1<'_, f32>,
        rate: f64,
        threads: Option<usize>,
    ) -> PyResult<Self> {
        let pos = points(&positions)?;
        let density: Vec<f64> = density.as_array().iter().map(|&d| d as f64).collect();
        let topo = topology.inner.clone();
        let pool = match threads {
            None => None,
            Some(0) => return Err(ParameterError::new_err("threads must be ≥ 1")),
            Some(n) => Some(
                rayon::ThreadPoolBuilder::new()
                    .num_threads(n)
                    .build()
                    .map_err(|e| ParameterError::new_err(e.to_string()))?,
            ),
        };
        let params = madder::stain::DiffusionParams { rate };
        let build =
            || madder::stain::DiffusionStepper::new(topo, &pos, density, params, faer::Par::Seq);
        let inner = py.detach(|| match &pool {
            Some(p) => p.install(build),
            None => build(),
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
        py.detach(|| match pool {
            Some(p) => p.install(|| inner.step(&pos, dt, substeps)),
            None => inner.step(&pos, dt, substeps),
        })
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

    /// Total stain mass `Σ A_i σ_i` (float64).
    fn total_mass(&self) -> f64 {
        self.inner.total_mass()
    }
}
