//! `Topology`: fixed triangle connectivity (core module `mesh`).

use numpy::ndarray::{Ix1, Ix2, Ix3};
use numpy::{Element, PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::prelude::*;

use crate::args;
use crate::errors::{ParameterError, to_py};

/// Triangle topology of a mesh: `faces` is a `(F, 3)` array of vertex indices;
/// `face_polygon` (optional, `(F,)`) maps each triangle to its source polygon (any integer
/// dtype, non-negative).
#[pyclass(module = "madder", frozen)]
pub struct Topology {
    pub inner: madder::mesh::Topology,
}

#[pymethods]
impl Topology {
    #[new]
    #[pyo3(signature = (faces, n_vertices, face_polygon=None, n_polygons=None))]
    fn new(
        faces: &Bound<'_, PyAny>,
        n_vertices: usize,
        face_polygon: Option<&Bound<'_, PyAny>>,
        n_polygons: Option<usize>,
    ) -> PyResult<Self> {
        let faces = args::indices::<Ix2>("faces", faces)?;
        let face_polygon = face_polygon
            .map(|fp| args::indices::<Ix1>("face_polygon", fp))
            .transpose()?;
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

/// The `(N, 3)` rows of float argument `name` read as `T` (any float dtype, see `args`).
/// An `(N, 3)` argument's shape check.
fn check_rows3(name: &str, shape: &[usize]) -> PyResult<()> {
    if shape[1] != 3 {
        return Err(ParameterError::new_err(format!(
            "{name} must have shape (N, 3), got {}",
            args::shape(shape)
        )));
    }
    Ok(())
}

fn rows3<T: Element + Copy>(name: &str, a: &Bound<'_, PyAny>) -> PyResult<Vec<[T; 3]>> {
    let a: PyReadonlyArray2<'_, T> = args::floats(name, a)?;
    check_rows3(name, a.shape())?;
    Ok(a.as_array()
        .rows()
        .into_iter()
        .map(|r| [r[0], r[1], r[2]])
        .collect())
}

/// The `(N, 3)` float argument `name` as float32 points (for the core's float32 meshes).
pub fn points(name: &str, a: &Bound<'_, PyAny>) -> PyResult<Vec<glam::Vec3>> {
    Ok(rows3::<f32>(name, a)?
        .into_iter()
        .map(glam::Vec3::from_array)
        .collect())
}

/// The `(N, 3)` float argument `name` as float64 points: float16 and float32 values
/// exactly, float64 ones keeping their precision (the core works in f64). A float32 array
/// (what the add-on passes every frame) is widened where it lies, in any layout, with no
/// float64 copy made first.
pub fn dpoints(name: &str, a: &Bound<'_, PyAny>) -> PyResult<Vec<glam::DVec3>> {
    if let Ok(a) = a.cast::<PyArray2<f32>>() {
        return widened(name, &a.try_readonly()?);
    }
    widened(name, &args::floats::<f64, Ix2>(name, a)?)
}

fn widened<T: Element + Copy + Into<f64>>(
    name: &str,
    a: &PyReadonlyArray2<'_, T>,
) -> PyResult<Vec<glam::DVec3>> {
    check_rows3(name, a.shape())?;
    Ok(a.as_array()
        .rows()
        .into_iter()
        .map(|r| glam::DVec3::new(r[0].into(), r[1].into(), r[2].into()))
        .collect())
}

/// Weft direction of every triangle at `positions`, as `(F, 3)` float32 unit vectors: the
/// UV u axis on the surface (`face_uv` `(F, 3, 2)`), turned by `face_angle` radians about
/// the face normal. Array arguments take any float dtype.
#[pyfunction]
#[pyo3(signature = (topology, positions, face_uv, face_angle=None))]
pub fn weft_directions<'py>(
    py: Python<'py>,
    topology: &Topology,
    positions: &Bound<'py, PyAny>,
    face_uv: &Bound<'py, PyAny>,
    face_angle: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyArray2<f32>>> {
    let pos = dpoints("positions", positions)?;
    let t = &topology.inner;
    madder::mesh::geometry::check_positions(t, &pos).map_err(to_py)?;
    let face_uv = args::floats::<f64, Ix3>("face_uv", face_uv)?;
    let uv = face_uv.as_array();
    if uv.shape() != [t.n_faces(), 3, 2] {
        return Err(ParameterError::new_err(format!(
            "face_uv must have shape ({}, 3, 2), got {:?}",
            t.n_faces(),
            uv.shape()
        )));
    }
    let uv: Vec<[[f64; 2]; 3]> = (0..t.n_faces())
        .map(|f| std::array::from_fn(|k| [uv[[f, k, 0]], uv[[f, k, 1]]]))
        .collect();
    let angle: Vec<f64> = match face_angle {
        Some(a) => args::floats::<f64, Ix1>("face_angle", a)?
            .as_array()
            .to_vec(),
        None => vec![0.0; t.n_faces()],
    };
    if angle.len() != t.n_faces() {
        return Err(ParameterError::new_err(format!(
            "face_angle must have {} values",
            t.n_faces()
        )));
    }
    let w = py.detach(|| madder::ops::weft_directions(t, &pos, &uv, &angle));
    let flat: Vec<f32> = w
        .iter()
        .flat_map(|v| [v.x as f32, v.y as f32, v.z as f32])
        .collect();
    PyArray1::from_vec(py, flat).reshape([w.len(), 3])
}

/// Distance from each of `points` `(N, 3)` to the triangle mesh (`vertices` `(M, 3)`, any
/// float dtype; `triangles` `(K, 3)`, any integer dtype), as `(N,)` float32; `inf` where it is
/// farther than `cutoff`. For liquid sources: how close the brush is to each cloth vertex.
#[pyfunction]
pub fn distances_within<'py>(
    py: Python<'py>,
    points_: &Bound<'py, PyAny>,
    vertices: &Bound<'py, PyAny>,
    triangles: &Bound<'py, PyAny>,
    cutoff: f64,
) -> PyResult<Bound<'py, PyArray1<f32>>> {
    let p = dpoints("points_", points_)?;
    let v = dpoints("vertices", vertices)?;
    let triangles = args::indices::<Ix2>("triangles", triangles)?;
    if triangles.shape()[1] != 3 {
        return Err(ParameterError::new_err(format!(
            "triangles must have shape (K, 3), got {:?}",
            triangles.shape()
        )));
    }
    let t: Vec<[u32; 3]> = triangles
        .as_array()
        .rows()
        .into_iter()
        .map(|r| [r[0], r[1], r[2]])
        .collect();
    if let Some(bad) = t.iter().flatten().find(|&&i| i as usize >= v.len()) {
        return Err(ParameterError::new_err(format!(
            "triangle vertex {bad} out of range ({} vertices)",
            v.len()
        )));
    }
    let d = py.detach(|| madder::mesh::proximity::distances_within(&p, &v, &t, cutoff));
    Ok(PyArray1::from_vec(
        py,
        d.into_iter().map(|x| x as f32).collect(),
    ))
}

/// The cloth refined for stain Detail (core `mesh::refine`): every triangle of `topology`
/// split into `4**level` on a regular lattice, the fine vertices numbered as the
/// simulator's `fine=True` read-outs (the cloth's vertices first, with their own indices).
/// `Refinement(topology, level)`; refused with the figure beyond 20 M fine vertices.
#[pyclass(module = "madder", frozen)]
pub struct Refinement {
    inner: madder::mesh::Refinement,
}

#[pymethods]
impl Refinement {
    #[new]
    fn new(py: Python<'_>, topology: &Topology, level: u32) -> PyResult<Self> {
        let t = &topology.inner;
        let inner = py
            .detach(|| madder::mesh::Refinement::new(t, level))
            .map_err(to_py)?;
        Ok(Self { inner })
    }

    /// The Detail level.
    #[getter]
    fn level(&self) -> u32 {
        self.inner.level()
    }
    /// Vertices of the refined mesh.
    #[getter]
    fn n_vertices(&self) -> usize {
        self.inner.fine().n_vertices()
    }
    /// Triangles of the refined mesh: `4**level` per cloth triangle, those of cloth
    /// triangle `f` at rows `f·4**level …`.
    #[getter]
    fn n_faces(&self) -> usize {
        self.inner.fine().n_faces()
    }

    /// The refined triangles, `(T, 3)` uint32 fine-vertex indices.
    fn faces<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<u32>> {
        let f = self.inner.fine().faces();
        PyArray1::from_vec(py, f.iter().flatten().copied().collect())
            .reshape([f.len(), 3])
            .expect("3T values reshape to (T, 3)")
    }

    /// The refined triangles' corner UVs, `(T, 3, 2)` float32, from the cloth triangles'
    /// corner UVs `face_uv` `(F, 3, 2)` (any float dtype; the same barycentric combination
    /// that places the fine vertices).
    fn face_uv<'py>(
        &self,
        py: Python<'py>,
        face_uv: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, numpy::PyArray3<f32>>> {
        let n = self.inner.fine().n_faces() / self.inner.faces_per_face();
        let face_uv = args::floats::<f64, Ix3>("face_uv", face_uv)?;
        let uv = face_uv.as_array();
        if uv.shape() != [n, 3, 2] {
            return Err(ParameterError::new_err(format!(
                "face_uv must have shape ({n}, 3, 2), got {:?}",
                uv.shape()
            )));
        }
        let coarse: Vec<[[f64; 2]; 3]> = (0..n)
            .map(|f| std::array::from_fn(|k| [uv[[f, k, 0]], uv[[f, k, 1]]]))
            .collect();
        let fine = py.detach(|| self.inner.face_uv(&coarse));
        let t = fine.len();
        let flat: Vec<f32> = fine
            .into_iter()
            .flat_map(|c| c.into_iter().flat_map(|p| p.map(|x| x as f32)))
            .collect();
        PyArray1::from_vec(py, flat).reshape([t, 3, 2])
    }

    fn __repr__(&self) -> String {
        format!(
            "Refinement(level={}, n_vertices={}, n_faces={})",
            self.level(),
            self.n_vertices(),
            self.n_faces()
        )
    }
}
