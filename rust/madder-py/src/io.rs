//! `CacheWriter` and `CacheReader`: the bake cache file (core module `io::cache`).

use std::path::PathBuf;

use numpy::ndarray::Ix1;
use numpy::{PyArray1, PyArrayMethods, PyReadwriteArray1};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

use crate::args;
use crate::errors::{CacheError, to_py};

/// Writes a cache atomically: frames go to a temporary file that replaces `path` only on
/// `finish()`. Dropping or `abort()`-ing an unfinished writer leaves `path` untouched.
/// `frame_time`: seconds between frames, recorded in the header (0: none).
#[pyclass(module = "madder")]
pub struct CacheWriter {
    inner: Option<madder::io::cache::CacheWriter>,
}

#[pymethods]
impl CacheWriter {
    #[new]
    #[pyo3(signature = (path, n_vertices, fields, first_frame, n_frames, frame_time=0.0))]
    fn new(
        path: PathBuf,
        n_vertices: usize,
        fields: Vec<String>,
        first_frame: i32,
        n_frames: u32,
        frame_time: f64,
    ) -> PyResult<Self> {
        let names: Vec<&str> = fields.iter().map(String::as_str).collect();
        let inner = madder::io::cache::CacheWriter::create_timed(
            path,
            n_vertices,
            &names,
            first_frame,
            n_frames,
            frame_time,
        )
        .map_err(to_py)?;
        Ok(Self { inner: Some(inner) })
    }

    /// Appends the next frame; `fields` holds one `(N,)` array per field, in order (any
    /// float dtype, stored as float32).
    fn push_frame(&mut self, py: Python<'_>, fields: Vec<Bound<'_, PyAny>>) -> PyResult<()> {
        let data = fields
            .iter()
            .enumerate()
            .map(|(i, f)| {
                let f = args::floats::<f32, Ix1>(&format!("fields[{i}]"), f)?;
                Ok(f.as_array().to_vec())
            })
            .collect::<PyResult<Vec<Vec<f32>>>>()?;
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

    /// Reads `frame` and fills the playback attributes in place (core `io::attributes`):
    /// `rgba` (4 float32 per vertex: colour × dye amount, dye amount), `wetness` and
    /// `deposit` (float32 per vertex), each density over its reference (solute, liquid,
    /// deposit), wetness and deposit clamped to [0, 1] and the dye amount to
    /// [0, 1 + `DYE_EXCESS_RANGE`]. Given `excess` (float32 per vertex: the images), the
    /// dye amount in `rgba` stays within [0, 1] and `excess` takes the share above 1 over
    /// `DYE_EXCESS_RANGE`, clamped to [0, 1]. With `clamp=False` the values in `rgba`,
    /// `wetness` and `deposit` are only held ≥ 0 (for `rasterize` with the weave's detail
    /// and `clip`). The colour is the cache's `color_r/g/b` fields when it has them, else
    /// `color`. The buffers must be contiguous float32 of the right lengths.
    #[allow(clippy::too_many_arguments)]
    #[pyo3(signature = (frame, references, color, rgba, wetness, deposit, clamp=true, excess=None))]
    fn read_stain(
        &mut self,
        py: Python<'_>,
        frame: i32,
        references: [f32; 3],
        color: [f32; 3],
        mut rgba: PyReadwriteArray1<'_, f32>,
        mut wetness: PyReadwriteArray1<'_, f32>,
        mut deposit: PyReadwriteArray1<'_, f32>,
        clamp: bool,
        mut excess: Option<PyReadwriteArray1<'_, f32>>,
    ) -> PyResult<()> {
        let n = self.inner.n_vertices();
        let (rgba, wetness, deposit) = (
            rgba.as_slice_mut(),
            wetness.as_slice_mut(),
            deposit.as_slice_mut(),
        );
        let excess = excess.as_mut().map(|e| e.as_slice_mut()).transpose();
        let (Ok(rgba), Ok(wetness), Ok(deposit), Ok(excess)) = (rgba, wetness, deposit, excess)
        else {
            return Err(PyValueError::new_err(
                "read_stain: the buffers must be contiguous",
            ));
        };
        if rgba.len() != 4 * n || wetness.len() != n || deposit.len() != n {
            return Err(PyValueError::new_err(format!(
                "read_stain: buffers of {}, {} and {} values for {n} vertices (need {}, {n}, {n})",
                rgba.len(),
                wetness.len(),
                deposit.len(),
                4 * n
            )));
        }
        if let Some(e) = &excess
            && e.len() != n
        {
            return Err(PyValueError::new_err(format!(
                "read_stain: an excess buffer of {} values for {n} vertices",
                e.len()
            )));
        }
        let inner = &mut self.inner;
        py.detach(|| {
            inner.read_stain(
                frame, references, color, clamp, rgba, wetness, deposit, excess,
            )
        })
        .map_err(to_py)
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
    /// The file's format version (1: before frame times were recorded).
    #[getter]
    fn version(&self) -> u32 {
        self.inner.version()
    }
    /// Seconds between frames as the bake recorded them (`None`: not recorded, e.g. a
    /// version-1 file).
    #[getter]
    fn frame_time(&self) -> Option<f64> {
        self.inner.frame_time()
    }
}
