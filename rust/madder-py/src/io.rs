//! `CacheWriter` and `CacheReader`: the bake cache file (core module `io::cache`).

use std::path::PathBuf;

use numpy::{PyArray1, PyArrayMethods, PyReadonlyArray1};
use pyo3::prelude::*;

use crate::errors::{CacheError, to_py};

/// Writes a cache atomically: frames go to a temporary file that replaces `path` only on
/// `finish()`. Dropping or `abort()`-ing an unfinished writer leaves `path` untouched.
#[pyclass(module = "madder")]
pub struct CacheWriter {
    inner: Option<madder::io::cache::CacheWriter>,
}

#[pymethods]
impl CacheWriter {
    #[new]
    fn new(
        path: PathBuf,
        n_vertices: usize,
        fields: Vec<String>,
        first_frame: i32,
        n_frames: u32,
    ) -> PyResult<Self> {
        let names: Vec<&str> = fields.iter().map(String::as_str).collect();
        let inner =
            madder::io::cache::CacheWriter::create(path, n_vertices, &names, first_frame, n_frames)
                .map_err(to_py)?;
        Ok(Self { inner: Some(inner) })
    }

    /// Appends the next frame; `fields` holds one float32 array per field, in order.
    fn push_frame(
        &mut self,
        py: Python<'_>,
        fields: Vec<PyReadonlyArray1<'_, f32>>,
    ) -> PyResult<()> {
        let data: Vec<Vec<f32>> = fields.iter().map(|f| f.as_array().to_vec()).collect();
        let w = self.open()?;
        py.detach(|| {
            let refs: Vec<&[f32]> = data.iter().map(Vec::as_slice).collect();
            w.push_frame(&refs)
        })
        .map_err(to_py)
    }

    /// Syncs the file and moves it over the target; returns the path.
    fn finish(&mut self, py: Python<'_>) -> PyResult<PathBuf> {
        let w = self
            .inner
            .take()
            .ok_or_else(|| CacheError::new_err("cache writer is already closed"))?;
        py.detach(|| w.finish()).map_err(to_py)
    }

    /// Discards the unfinished file; the previous cache (if any) stays.
    fn abort(&mut self) {
        self.inner = None;
    }
}

impl CacheWriter {
    fn open(&mut self) -> PyResult<&mut madder::io::cache::CacheWriter> {
        self.inner
            .as_mut()
            .ok_or_else(|| CacheError::new_err("cache writer is already closed"))
    }
}

/// Reads frames of a cache file; every error names the file and the frame. A truncated
/// file opens: the frames before `truncated_at` read, the later ones raise `CacheError`.
#[pyclass(module = "madder")]
pub struct CacheReader {
    inner: madder::io::cache::CacheReader,
}

#[pymethods]
impl CacheReader {
    #[new]
    fn new(path: PathBuf) -> PyResult<Self> {
        Ok(Self {
            inner: madder::io::cache::CacheReader::open(path).map_err(to_py)?,
        })
    }

    /// Every field of `frame` with one read and checksum, as a `(n_fields, n_vertices)`
    /// float32 array (rows in the order of `fields`).
    fn read_frame<'py>(
        &mut self,
        py: Python<'py>,
        frame: i32,
    ) -> PyResult<Bound<'py, numpy::PyArray2<f32>>> {
        let (k, n) = (self.inner.field_names().len(), self.inner.n_vertices());
        let inner = &mut self.inner;
        let v = py.detach(|| inner.read_frame(frame)).map_err(to_py)?;
        PyArray1::from_vec(py, v).reshape([k, n])
    }

    /// Field `field` at `frame`, as a float32 array of one value per vertex.
    fn read<'py>(
        &mut self,
        py: Python<'py>,
        frame: i32,
        field: &str,
    ) -> PyResult<Bound<'py, PyArray1<f32>>> {
        let inner = &mut self.inner;
        let v = py.detach(|| inner.read(frame, field)).map_err(to_py)?;
        Ok(PyArray1::from_vec(py, v))
    }

    #[getter]
    fn path(&self) -> PathBuf {
        self.inner.path().to_path_buf()
    }
    #[getter]
    fn n_vertices(&self) -> usize {
        self.inner.n_vertices()
    }
    #[getter]
    fn fields(&self) -> Vec<String> {
        self.inner.field_names().to_vec()
    }
    #[getter]
    fn first_frame(&self) -> i32 {
        self.inner.first_frame()
    }
    #[getter]
    fn last_frame(&self) -> i32 {
        self.inner.last_frame()
    }
    /// The first frame whose block is cut off (`None` when the file is whole).
    #[getter]
    fn truncated_at(&self) -> Option<i32> {
        self.inner.truncated_at()
    }
}
