//! `Topology`: fixed triangle connectivity (core module `mesh`).

use numpy::{
    PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2, PyUntypedArrayMethods,
};
use pyo3::prelude::*;

use crate::errors::{ParameterError, to_py};

/// Triangle topology of a mesh: `faces` is a `(F, 3)` uint32 array of vertex indices;
/// `face_polygon` (optional, `(F,)` uint32) maps each triangle to its source polygon.
#[pyclass(module = "madder", frozen)]
pub struct Topology {
    pub inner: madder::mesh::Topology,
}

#[pymethods]
impl Topology {
    #[new]
    #[pyo3(signature = (faces, n_vertices, face_polygon=None, n_polygons=None))]
    fn new(
        faces: PyReadonlyArray2<'_, u32>,
        n_vertices: usize,
        face_polygon: Option<PyReadonlyArray1<'_, u32>>,
        n_polygons: Option<usize>,
    ) -> PyResult<Self> {
        if faces.shape()[1] != 3 {
            return Err(ParameterError::new_err(format!(
                "faces must have shape (F, 3), got {:?}",
                faces.shape()
            )));
        }
        let tris: Vec<[u32; 3]> = faces
            .as_array()
            .rows()
            .into_iter()
            .map(|r| [r[0], r[1], r[2]])
            .collect();
        let inner = match face_polygon {
            None => madder::mesh::Topology::from_triangles(n_vertices, tris),
            Some(fp) => {
                let fp = fp.as_array().to_vec();
                let n_poly =
                    n_polygons.unwrap_or_else(|| fp.iter().max().map_or(0, |&m| m as usize + 1));
                madder::mesh::Topology::with_polygons(n_vertices, tris, fp, n_poly)
            }
        }
        .map_err(to_py)?;
        Ok(Self { inner })
    }

    #[getter]
    fn n_vertices(&self) -> usize {
        self.inner.n_vertices()
    }
    #[getter]
    fn n_faces(&self) -> usize {
        self.inner.n_faces()
    }
    #[getter]
    fn n_edges(&self) -> usize {
        self.inner.n_edges()
    }
    #[getter]
    fn n_polygons(&self) -> usize {
        self.inner.n_polygons()
    }

    /// Boundary edges as a `(k, 2)` array of vertex pairs.
    fn boundary_edges<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<u32>> {
        self.edge_array(py, self.inner.boundary_edges())
    }

    /// Edges shared by three or more faces, as a `(k, 2)` array of vertex pairs.
    fn non_manifold_edges<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<u32>> {
        self.edge_array(py, self.inner.non_manifold_edges())
    }

    /// Indices of vertices used by no face.
    fn loose_vertices<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<u32>> {
        let loose = self.inner.loose_vertices();
        let idx: Vec<u32> = (0..loose.len() as u32)
            .filter(|&v| loose[v as usize])
            .collect();
        PyArray1::from_vec(py, idx)
    }

    fn __repr__(&self) -> String {
        format!(
            "Topology(n_vertices={}, n_faces={}, n_edges={})",
            self.n_vertices(),
            self.n_faces(),
            self.n_edges()
        )
    }
}

impl Topology {
    fn edge_array<'py>(&self, py: Python<'py>, edges: Vec<usize>) -> Bound<'py, PyArray2<u32>> {
        let flat: Vec<u32> = edges.iter().flat_map(|&e| self.inner.edges()[e]).collect();
        let n = edges.len();
        PyArray1::from_vec(py, flat)
            .reshape([n, 2])
            .expect("2k values reshape to (k, 2)")
    }
}

/// Copies a `(N, 3)` float32 array into owned points.
pub fn points(a: &PyReadonlyArray2<'_, f32>) -> PyResult<Vec<glam::Vec3>> {
    if a.shape()[1] != 3 {
        return Err(ParameterError::new_err(format!(
            "positions must have shape (N, 3), got {:?}",
            a.shape()
        )));
    }
    Ok(a.as_array()
        .rows()
        .into_iter()
        .map(|r| glam::Vec3::new(r[0], r[1], r[2]))
        .collect())
}
