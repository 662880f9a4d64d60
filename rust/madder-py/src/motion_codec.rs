//! `MotionEncoder`, `MotionCodec`: the angle codec's motion files (core module
//! `angles::codec`). Conversion only; the GIL is released around encoding and decoding.

use std::path::PathBuf;

use glam::DVec3;
use numpy::ndarray::{Ix2, Ix3};
use numpy::{PyArray1, PyArray2, PyArrayMethods, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use madder::CodecError;
use madder::angles::codec::position_baseline;
use madder::angles::{CodecOptions, MotionDecoder, MotionEncoder as CoreEncoder};

use crate::args;
use crate::errors::{ParameterError, to_py};

fn usage(path: &std::path::Path, reason: String) -> PyErr {
    to_py(CodecError::Usage {
        path: path.to_path_buf(),
        reason,
    })
}

/// Writes a `.madm` motion file frame by frame: corner and dihedral angles quantized with
/// closed-loop temporal prediction and range coding, plus a per-frame similarity. Nothing
/// appears at `path` until `finish()`; `abort()` (or dropping the encoder) removes the
/// temporary file next to it. Decoding is warm-started from the previous frame, cold every
/// `keyframe_interval` frames (0: always cold); `warm` picks the warm frames' method:
/// `"tracked"` (the default; fast) or `"spectral"` (the warm-started eigen-solve).
#[pyclass(module = "madder")]
pub struct MotionEncoder {
    path: PathBuf,
    inner: Option<CoreEncoder>,
}

#[pymethods]
impl MotionEncoder {
    #[new]
    #[pyo3(signature = (path, faces, *, start=1.0, rate=1.0, bits=12, corner_bits=None, corners="every", keyframe_interval=16, warm="tracked"))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        py: Python<'_>,
        path: PathBuf,
        faces: &Bound<'_, PyAny>,
        start: f64,
        rate: f64,
        bits: u32,
        corner_bits: Option<u32>,
        corners: &str,
        keyframe_interval: u32,
        warm: &str,
    ) -> PyResult<Self> {
        let faces = args::indices::<Ix2>("faces", faces)?;
        let shape = faces.shape();
        if shape[1] != 3 || shape[0] == 0 {
            return Err(usage(
                &path,
                format!("faces must have shape (F, 3) with F > 0, got {shape:?}"),
            ));
        }
        let corners_once = match corners {
            "every" => false,
            "once" => true,
            other => {
                return Err(ParameterError::new_err(format!(
                    "corners must be 'every' or 'once', got {other:?}"
                )));
            }
        };
        let tracked = match warm {
            "tracked" => true,
            "spectral" => false,
            other => {
                return Err(ParameterError::new_err(format!(
                    "warm must be 'tracked' or 'spectral', got {other:?}"
                )));
            }
        };
        let faces: Vec<[u32; 3]> = faces
            .as_array()
            .rows()
            .into_iter()
            .map(|r| [r[0], r[1], r[2]])
            .collect();
        let options = CodecOptions {
            start,
            rate,
            bits,
            corner_bits: corner_bits.unwrap_or(bits),
            corners_once,
            keyframe_interval,
            tracked,
        };
        let p = path.clone();
        let inner = py
            .detach(move || CoreEncoder::create(&p, faces, options))
            .map_err(to_py)?;
        Ok(Self {
            path,
            inner: Some(inner),
        })
    }

    /// Encodes the next frame: `(N, 3)` object-space positions (any float dtype). Returns
    /// the positions the decoder will produce for it, `(N, 3)` float32. A NaN, a wrong
    /// count or a degenerate face raises `MeshError` naming the file, frame and vertex/face.
    fn add_frame<'py>(
        &mut self,
        py: Python<'py>,
        positions: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyArray2<f32>>> {
        let a = args::floats::<f64, Ix2>("positions", positions)?;
        check_shape(&self.path, a.shape())?;
        let rows: Vec<DVec3> = a
            .as_array()
            .rows()
            .into_iter()
            .map(|r| DVec3::new(r[0], r[1], r[2]))
            .collect();
        let Some(inner) = self.inner.as_mut() else {
            return Err(usage(&self.path, "the encoder is finished".into()));
        };
        let out = py.detach(|| inner.add_frame(&rows)).map_err(to_py)?;
        let n = out.len();
        PyArray1::from_vec(py, out.into_flattened()).reshape([n, 3])
    }

    /// Writes the frame count and renames the file into place. Returns a dict: `frames`,
    /// `vertices`, `bytes`, `bits_per_vertex_frame`, `max_error`, `rms_error` (errors over
    /// the sequence's bounding-box diagonal, measured by the encoder's own decode) and
    /// `diagonal`.
    fn finish<'py>(&mut self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let Some(inner) = self.inner.take() else {
            return Err(usage(&self.path, "the encoder is finished".into()));
        };
        let s = py.detach(move || inner.finish()).map_err(to_py)?;
        let d = PyDict::new(py);
        d.set_item("frames", s.frames)?;
        d.set_item("vertices", s.vertices)?;
        d.set_item("bytes", s.bytes)?;
        d.set_item("bits_per_vertex_frame", s.bits_per_vertex_frame)?;
        d.set_item("max_error", s.max_error)?;
        d.set_item("rms_error", s.rms_error)?;
        d.set_item("diagonal", s.diagonal)?;
        Ok(d)
    }

    /// Removes the temporary file; `path` is untouched. Does nothing after `finish()`.
    fn abort(&mut self) {
        if let Some(inner) = self.inner.take() {
            inner.abort();
        }
    }

    #[getter]
    fn path(&self) -> PathBuf {
        self.path.clone()
    }
    #[getter]
    fn n_points(&self) -> Option<usize> {
        self.inner.as_ref().map(CoreEncoder::n_points)
    }
    fn __repr__(&self) -> String {
        format!(
            "MotionEncoder({:?}, {})",
            self.path.display().to_string(),
            if self.inner.is_some() {
                "open"
            } else {
                "closed"
            }
        )
    }
}

fn check_shape(path: &std::path::Path, shape: &[usize]) -> PyResult<()> {
    if shape[1] != 3 {
        return Err(usage(
            path,
            format!("positions must have shape (N, 3), got {shape:?}"),
        ));
    }
    Ok(())
}

/// Reads a `.madm` motion file like `PointCache`: `read_frame(k)` gives `(N, 3)` float32
/// object-space positions. Opening validates the header, connectivity and frame blocks;
/// every error names the file (and the frame).
#[pyclass(module = "madder")]
pub struct MotionCodec {
    inner: MotionDecoder,
}

#[pymethods]
impl MotionCodec {
    #[new]
    fn new(py: Python<'_>, path: PathBuf) -> PyResult<Self> {
        let inner = py.detach(|| MotionDecoder::open(&path)).map_err(to_py)?;
        Ok(Self { inner })
    }

    /// Positions of frame `k` (0-based) as `(n_points, 3)` float32. Reading `k` after
    /// `k − 1` decodes one frame; a backward jump replays the (cheap) entropy decoding.
    fn read_frame<'py>(&mut self, py: Python<'py>, k: i64) -> PyResult<Bound<'py, PyArray2<f32>>> {
        let Ok(ku) = usize::try_from(k) else {
            return Err(to_py(CodecError::FrameOutOfRange {
                path: self.inner.path().to_path_buf(),
                frame: k,
                n_frames: self.inner.n_frames(),
            }));
        };
        let inner = &mut self.inner;
        let out = py.detach(|| inner.read_frame(ku)).map_err(to_py)?;
        let n = out.len();
        PyArray1::from_vec(py, out.into_flattened()).reshape([n, 3])
    }

    #[getter]
    fn path(&self) -> PathBuf {
        self.inner.path().to_path_buf()
    }
    /// `"madder"`.
    #[getter]
    fn format(&self) -> &'static str {
        "madder"
    }
    #[getter]
    fn n_points(&self) -> usize {
        self.inner.n_points()
    }
    #[getter]
    fn n_frames(&self) -> usize {
        self.inner.n_frames()
    }
    /// `(F, 3)` uint32.
    #[getter]
    fn faces<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<u32>>> {
        let f = self.inner.faces().to_vec();
        let n = f.len();
        PyArray1::from_vec(py, f.into_flattened()).reshape([n, 3])
    }
    /// Scene frame of sample 0 (PC2 meaning).
    #[getter]
    fn start(&self) -> f64 {
        self.inner.start()
    }
    /// Scene frames between samples (PC2 meaning).
    #[getter]
    fn rate(&self) -> f64 {
        self.inner.rate()
    }
    /// `(bits, corner_bits)`: the quantization of the dihedral and corner angles.
    #[getter]
    fn bits(&self) -> (u32, u32) {
        self.inner.bits()
    }
    /// `(n_frames,)` float64 scene frames `start + k·rate`.
    #[getter]
    fn frame_times<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_vec(py, self.inner.frame_times())
    }
    fn __len__(&self) -> usize {
        self.inner.n_frames()
    }
    fn __repr__(&self) -> String {
        format!(
            "MotionCodec({:?}, n_points={}, n_frames={})",
            self.inner.path().display().to_string(),
            self.inner.n_points(),
            self.inner.n_frames()
        )
    }
}

/// The position baseline the codec is compared with: `frames` `(T, N, 3)` (any float dtype)
/// quantized with `bits` bits per coordinate on the bounding cube; `predict=True`: temporal
/// prediction and the codec's range coder, else raw. Returns a dict like
/// `MotionEncoder.finish()`'s: `bits_per_vertex_frame`, `max_error`, `rms_error` (over the
/// bounding-box diagonal).
#[pyfunction]
#[pyo3(signature = (frames, bits, predict=true))]
pub fn position_baseline_stats<'py>(
    py: Python<'py>,
    frames: &Bound<'py, PyAny>,
    bits: u32,
    predict: bool,
) -> PyResult<Bound<'py, PyDict>> {
    let frames = args::floats::<f64, Ix3>("frames", frames)?;
    let shape = frames.shape();
    if shape[0] == 0 || shape[1] == 0 || shape[2] != 3 || !(1..=24).contains(&bits) {
        return Err(ParameterError::new_err(format!(
            "frames must be (T, N, 3) with T, N > 0 and bits in 1..=24, got {shape:?} and {bits}"
        )));
    }
    let a = frames.as_array();
    if a.iter().any(|v| !v.is_finite()) {
        return Err(ParameterError::new_err("frames must be finite"));
    }
    let f: Vec<Vec<DVec3>> = a
        .outer_iter()
        .map(|fr| {
            fr.rows()
                .into_iter()
                .map(|r| DVec3::new(r[0], r[1], r[2]))
                .collect()
        })
        .collect();
    let s = py.detach(|| position_baseline(&f, bits, predict));
    let d = PyDict::new(py);
    d.set_item("bits_per_vertex_frame", s.bits_per_vertex_frame)?;
    d.set_item("max_error", s.max_error)?;
    d.set_item("rms_error", s.rms_error)?;
    Ok(d)
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(position_baseline_stats, m)?)?;
    m.add_class::<MotionEncoder>()?;
    m.add_class::<MotionCodec>()?;
    Ok(())
}
