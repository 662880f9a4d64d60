//! `PointCache`, `Pc2Writer`, `write_pc2`, `write_mdd`: the PC2/MDD files of Blender's
//! Mesh Cache modifier (core module `io::point_cache`).

use std::path::PathBuf;

use numpy::ndarray::{Ix2, Ix3};
use numpy::{PyArray1, PyArray2, PyArrayMethods, PyUntypedArrayMethods};
use pyo3::prelude::*;

use crate::args;
use crate::errors::{CacheError, ParameterError, to_py};
use madder::io::point_cache::{self as core, Format, Timing};

fn format_arg(name: Option<&str>) -> PyResult<Option<Format>> {
    match name.map(str::to_ascii_lowercase).as_deref() {
        None => Ok(None),
        Some("pc2") => Ok(Some(Format::Pc2)),
        Some("mdd") => Ok(Some(Format::Mdd)),
        Some(other) => Err(ParameterError::new_err(format!(
            "unknown point cache format '{other}' (pc2 or mdd)"
        ))),
    }
}

/// Reads frames of a PC2 or MDD file, one at a time. The format is told by the PC2
/// signature, else by the `.mdd`/`.pc2` name; `format="mdd"` or `"pc2"` forces it. Every
/// error is a `CacheError` naming the file (and the frame and vertex where it applies).
#[pyclass(module = "madder")]
pub struct PointCache {
    inner: core::PointCache,
}

#[pymethods]
impl PointCache {
    #[new]
    #[pyo3(signature = (path, format=None))]
    fn new(py: Python<'_>, path: PathBuf, format: Option<&str>) -> PyResult<Self> {
        let format = format_arg(format)?;
        let inner = py
            .detach(|| match format {
                None => core::PointCache::open(&path),
                Some(f) => core::PointCache::open_as(&path, f),
            })
            .map_err(to_py)?;
        Ok(Self { inner })
    }

    /// Positions of frame `k` (0-based, file order) as an `(n_points, 3)` float32 array.
    /// A NaN or infinite coordinate raises `CacheError` naming frame and vertex.
    fn read_frame<'py>(&mut self, py: Python<'py>, k: i64) -> PyResult<Bound<'py, PyArray2<f32>>> {
        let Ok(k) = usize::try_from(k) else {
            return Err(CacheError::new_err(format!(
                "{}: frame {k} is not in the file (it holds frames 0..={})",
                self.inner.path().display(),
                self.inner.n_frames() - 1
            )));
        };
        let inner = &mut self.inner;
        let frame = py.detach(|| inner.read_frame(k)).map_err(to_py)?;
        let n = frame.len();
        PyArray1::from_vec(py, frame.into_flattened()).reshape([n, 3])
    }

    /// Raises `CacheError` naming the first frame whose time is not finite or not after the
    /// previous one (PC2: a non-finite start, or a rate that is not finite and > 0).
    fn check_times(&self) -> PyResult<()> {
        self.inner.check_times().map_err(to_py)
    }

    #[getter]
    fn path(&self) -> PathBuf {
        self.inner.path().to_path_buf()
    }
    /// `"pc2"` or `"mdd"`.
    #[getter]
    fn format(&self) -> &'static str {
        match self.inner.format() {
            Format::Pc2 => "pc2",
            Format::Mdd => "mdd",
        }
    }
    #[getter]
    fn n_points(&self) -> usize {
        self.inner.n_points()
    }
    #[getter]
    fn n_frames(&self) -> usize {
        self.inner.n_frames()
    }
    /// Time of every frame as float64, in `time_unit`: scene frames (PC2, `start + k·rate`)
    /// or seconds (MDD), exactly as the file states them.
    #[getter]
    fn frame_times<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_vec(py, self.inner.frame_times())
    }
    /// `"frame"` (PC2) or `"second"` (MDD).
    #[getter]
    fn time_unit(&self) -> &'static str {
        match self.inner.timing() {
            Timing::Frames { .. } => "frame",
            Timing::Seconds(_) => "second",
        }
    }
    /// PC2 start frame; `None` for MDD.
    #[getter]
    fn start(&self) -> Option<f32> {
        match self.inner.timing() {
            Timing::Frames { start, .. } => Some(*start),
            Timing::Seconds(_) => None,
        }
    }
    /// PC2 frames between samples; `None` for MDD.
    #[getter]
    fn rate(&self) -> Option<f32> {
        match self.inner.timing() {
            Timing::Frames { rate, .. } => Some(*rate),
            Timing::Seconds(_) => None,
        }
    }
    /// Bytes after the last declared frame (accepted, as Blender does).
    #[getter]
    fn trailing_bytes(&self) -> u64 {
        self.inner.trailing_bytes()
    }

    fn __len__(&self) -> usize {
        self.inner.n_frames()
    }

    fn __repr__(&self) -> String {
        format!(
            "PointCache({:?}, format={:?}, n_points={}, n_frames={})",
            self.inner.path().display().to_string(),
            self.format(),
            self.inner.n_points(),
            self.inner.n_frames()
        )
    }
}

/// The `(F, N, 3)` float argument `frames` as float32 frames (any float dtype, see `args`).
fn frames(a: &Bound<'_, PyAny>) -> PyResult<Vec<Vec<[f32; 3]>>> {
    let a = args::floats::<f32, Ix3>("frames", a)?;
    let shape = a.shape();
    if shape[2] != 3 {
        return Err(ParameterError::new_err(format!(
            "frames must have shape (F, N, 3), got {shape:?}"
        )));
    }
    let a = a.as_array();
    Ok(a.outer_iter()
        .map(|f| f.rows().into_iter().map(|r| [r[0], r[1], r[2]]).collect())
        .collect())
}

/// Writes `frames` (`(F, N, 3)`, any float dtype, stored as float32) to a PC2 file, frame
/// `k` at scene frame `start + k·rate`. Atomic: `path` is replaced only once the whole file is on disk.
#[pyfunction]
#[pyo3(signature = (path, frames, start=1.0, rate=1.0))]
pub fn write_pc2(
    py: Python<'_>,
    path: PathBuf,
    frames: &Bound<'_, PyAny>,
    start: f32,
    rate: f32,
) -> PyResult<()> {
    let frames = self::frames(frames)?;
    py.detach(|| core::write_pc2(&path, start, rate, &frames))
        .map_err(to_py)
}

/// Writes `frames` (`(F, N, 3)`, any float dtype, stored as float32) to an MDD file, frame
/// `k` at `times[k]` seconds (stored as float32; strictly increasing). Atomic like `write_pc2`.
#[pyfunction]
pub fn write_mdd(
    py: Python<'_>,
    path: PathBuf,
    frames: &Bound<'_, PyAny>,
    times: Vec<f64>,
) -> PyResult<()> {
    let frames = self::frames(frames)?;
    let times: Vec<f32> = times.iter().map(|&t| t as f32).collect();
    py.detach(|| core::write_mdd(&path, &times, &frames))
        .map_err(to_py)
}

/// Writes a PC2 file a frame at a time (`add_frame`), for sequences too long to hold in
/// memory; `finish()` puts it in place atomically, as `write_pc2` does. Until then `path`
/// keeps what it held, and `abort()` (or dropping the writer) removes the partial file.
/// Errors are `CacheError`s naming the file (and the frame and vertex of a bad position).
#[pyclass(module = "madder")]
pub struct Pc2Writer {
    path: PathBuf,
    inner: Option<core::Pc2Writer>,
    n_frames: usize,
}

#[pymethods]
impl Pc2Writer {
    #[new]
    #[pyo3(signature = (path, n_points, start=1.0, rate=1.0))]
    fn new(
        py: Python<'_>,
        path: PathBuf,
        n_points: usize,
        start: f32,
        rate: f32,
    ) -> PyResult<Self> {
        let inner = py
            .detach(|| core::Pc2Writer::create(&path, n_points, start, rate))
            .map_err(to_py)?;
        Ok(Self {
            path,
            inner: Some(inner),
            n_frames: 0,
        })
    }

    /// Appends the next frame: `(N, 3)` positions (any float dtype, stored as float32).
    fn add_frame(&mut self, py: Python<'_>, positions: &Bound<'_, PyAny>) -> PyResult<()> {
        let positions = args::floats::<f32, Ix2>("positions", positions)?;
        let shape = positions.shape();
        if shape[1] != 3 {
            return Err(ParameterError::new_err(format!(
                "positions must have shape (N, 3), got {shape:?}"
            )));
        }
        let rows: Vec<[f32; 3]> = positions
            .as_array()
            .rows()
            .into_iter()
            .map(|r| [r[0], r[1], r[2]])
            .collect();
        let Some(inner) = self.inner.as_mut() else {
            return Err(CacheError::new_err(format!(
                "{}: the writer is finished or aborted",
                self.path.display()
            )));
        };
        py.detach(|| inner.add_frame(&rows)).map_err(to_py)?;
        self.n_frames = inner.n_frames();
        Ok(())
    }

    /// Writes the frame count and renames the file into place.
    fn finish(&mut self, py: Python<'_>) -> PyResult<()> {
        let Some(inner) = self.inner.take() else {
            return Err(CacheError::new_err(format!(
                "{}: the writer is finished or aborted",
                self.path.display()
            )));
        };
        py.detach(move || inner.finish()).map_err(to_py)
    }

    /// Removes the partial file; `path` is untouched. Does nothing after `finish()`.
    fn abort(&mut self) {
        if let Some(inner) = self.inner.take() {
            inner.abort();
        }
    }

    /// Frames written so far.
    #[getter]
    fn n_frames(&self) -> usize {
        self.n_frames
    }

    #[getter]
    fn path(&self) -> PathBuf {
        self.path.clone()
    }

    fn __repr__(&self) -> String {
        format!(
            "Pc2Writer({:?}, n_frames={}{})",
            self.path.display().to_string(),
            self.n_frames,
            if self.inner.is_some() { "" } else { ", closed" }
        )
    }
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PointCache>()?;
    m.add_class::<Pc2Writer>()?;
    m.add_function(wrap_pyfunction!(write_pc2, m)?)?;
    m.add_function(wrap_pyfunction!(write_mdd, m)?)
}
