//! `rasterize`, `write_exr`, `read_exr`: per-vertex fields as UV textures and half-float
//! OpenEXR images (core module `texture`).

use std::path::PathBuf;

use std::sync::Arc;

use numpy::ndarray::{Ix1, Ix2, Ix3, IxDyn};
use numpy::{PyArray1, PyArrayDyn, PyArrayMethods, PyReadonlyArrayDyn, PyUntypedArrayMethods};
use pyo3::prelude::*;

use crate::args;
use crate::errors::{ParameterError, to_py};
use crate::threads::Pool;
use crate::weave::Corrector;
use madder::texture as core;

/// The `(T, 3, 2)` UVs (any float dtype) as owned `f64` triples.
fn uv_arg(a: &Bound<'_, PyAny>) -> PyResult<Vec<[[f64; 2]; 3]>> {
    let a = args::floats::<f64, Ix3>("uv", a)?;
    let shape = a.shape();
    if shape[1] != 3 || shape[2] != 2 {
        return Err(ParameterError::new_err(format!(
            "uv must have shape (T, 3, 2), got {shape:?}"
        )));
    }
    let a = a.as_array();
    Ok(a.outer_iter()
        .map(|t| std::array::from_fn(|k| [t[[k, 0]], t[[k, 1]]]))
        .collect())
}

/// The `(T, 3)` faces (any integer dtype) as `u32` triples.
fn faces_arg(a: &Bound<'_, PyAny>) -> PyResult<Vec<[u32; 3]>> {
    let faces = args::indices::<Ix2>("faces", a)?;
    if faces.shape()[1] != 3 {
        return Err(ParameterError::new_err(format!(
            "faces must have shape (T, 3), got {:?}",
            faces.shape()
        )));
    }
    Ok(args::triples(&faces))
}

/// The float32 values of `a` (converted by `args`) with one of `ndim` dimensions, copied in
/// C order.
fn flat(name: &str, a: &PyReadonlyArrayDyn<'_, f32>, ndim: &[usize]) -> PyResult<Vec<f32>> {
    if !ndim.contains(&a.ndim()) {
        return Err(ParameterError::new_err(format!(
            "{name} must have {} dimensions, got shape {:?}",
            ndim.iter()
                .map(|d| d.to_string())
                .collect::<Vec<_>>()
                .join(" or "),
            a.shape()
        )));
    }
    // ndarray's `as_slice` is C order only (numpy's would also give a Fortran-order
    // array's memory, which is not the values in C order)
    let view = a.as_array();
    Ok(match view.as_slice() {
        Some(s) => s.to_vec(),
        None => view.iter().copied().collect(),
    })
}

fn size_arg(name: &str, size: i64) -> PyResult<usize> {
    match usize::try_from(size) {
        Ok(s) => Ok(s),
        Err(_) => Err(ParameterError::new_err(format!(
            "{name} {size} is out of range (1..={} texels)",
            core::MAX_SIZE
        ))),
    }
}

/// The weave's fine scale for `rasterize(..., weave=)` (core `texture::WeaveDetail`).
///
/// `WeaveDetail(correctors, face_fabric, face_map, uptake)`: `correctors` a list of
/// `Corrector`s (`fabric_corrector`); `face_fabric` `(T,)` (any integer dtype), per
/// triangle its corrector's index or `NO_WEAVE`; `face_map` `(T, 2, 2)` floats, per triangle the map
/// from UV to threads along the weft (row 0) and the warp (row 1), zero for none;
/// `uptake`, per image channel, whether the threads' uptake applies (the deposit) or only
/// the corrector (wetness). Checked against the faces by `rasterize`.
#[pyclass(module = "madder", frozen)]
pub struct WeaveDetail {
    correctors: Vec<Arc<madder::weave::Corrector>>,
    face_fabric: Vec<u32>,
    face_map: Vec<[f64; 4]>,
    uptake: Vec<bool>,
}

#[pymethods]
impl WeaveDetail {
    #[new]
    fn new(
        correctors: Vec<PyRef<'_, Corrector>>,
        face_fabric: &Bound<'_, PyAny>,
        face_map: &Bound<'_, PyAny>,
        uptake: Vec<bool>,
    ) -> PyResult<Self> {
        let face_fabric = args::indices::<Ix1>("face_fabric", face_fabric)?;
        let face_map = args::floats::<f64, Ix3>("face_map", face_map)?;
        let m = face_map.as_array();
        if m.shape()[1..] != [2, 2] {
            return Err(ParameterError::new_err(format!(
                "face_map must have shape (T, 2, 2), got {:?}",
                m.shape()
            )));
        }
        Ok(Self {
            correctors: correctors.iter().map(|c| c.inner.clone()).collect(),
            face_fabric: face_fabric.as_array().to_vec(),
            face_map: m
                .outer_iter()
                .map(|t| [t[[0, 0]], t[[0, 1]], t[[1, 0]], t[[1, 1]]])
                .collect(),
            uptake,
        })
    }

    /// Triangles the detail covers (woven or not).
    #[getter]
    fn n_faces(&self) -> usize {
        self.face_fabric.len()
    }
}

/// Rasterizes a per-vertex field into a `size × size` UV texture and pads its UV islands.
///
/// `rasterize(faces, uv, values, size, padding=4, *, out=None, threads=None, weave=None)
/// -> (image, overlapping_texels)`
///
/// `faces` `(T, 3)` (any integer dtype): the vertices whose values triangle `t`
/// interpolates; `uv` `(T, 3, 2)` (any float dtype, read as float64): its corners' UVs (one
/// triple per triangle, so a vertex on a UV seam has a UV on each side); `values` `(N, C)`
/// (any float dtype, read as float32; or `(N,)`, one channel). The image is `(size, size, C)` float32 (`(size, size)` for 1-D values),
/// row 0 at the bottom (`v ∈ [0, 1/size)`), as Blender's `Image.pixels`: each texel whose
/// centre lies in a triangle holds the barycentric interpolation of its vertex values
/// there, each island is then grown by `padding` texels (each new texel the mean of its
/// covered neighbours), and the rest is 0. `overlapping_texels` counts texel centres
/// inside two or more triangles (overlapping UV islands): worth a warning. The GIL is
/// released; `threads` caps the worker threads (the result does not depend on it).
/// `out`, a C-contiguous float32 array of the image's shape, is filled and returned
/// instead of a new array: a sequence of frames then reuses one buffer (a fresh 2048²
/// RGBA image is 64 MB of new memory per frame). `weave`, a `WeaveDetail`, adds the
/// weave's fine scale back on its woven triangles (issue 13 part 4); `None` changes no bit.
/// `clip`, `"unit"` (each channel into [0, 1]) or `"premultiplied"` (premultiplied colour,
/// coverage last: a texel over 1 is scaled by its coverage), limits the finished image
/// (core `texture::clip`): values read unclamped, the detail added, then clipped.
///
/// Raises `ParameterError` for a size out of 1..=16384 or mismatched lengths, `MeshError`
/// naming the face (and corner) for a vertex index past the values or a non-finite UV.
#[pyfunction]
#[pyo3(signature = (faces, uv, values, size, padding=4, *, out=None, threads=None, weave=None, clip=None))]
#[allow(clippy::type_complexity, clippy::too_many_arguments)]
pub fn rasterize<'py>(
    py: Python<'py>,
    faces: &Bound<'py, PyAny>,
    uv: &Bound<'py, PyAny>,
    values: &Bound<'py, PyAny>,
    size: i64,
    padding: i64,
    out: Option<Bound<'py, PyArrayDyn<f32>>>,
    threads: Option<usize>,
    weave: Option<PyRef<'py, WeaveDetail>>,
    clip: Option<&str>,
) -> PyResult<(Bound<'py, PyArrayDyn<f32>>, usize)> {
    let clip = match clip {
        None => None,
        Some("unit") => Some(core::Clip::Unit),
        Some("premultiplied") => Some(core::Clip::Premultiplied),
        Some(other) => {
            return Err(ParameterError::new_err(format!(
                "clip must be None, 'unit' or 'premultiplied', got {other:?}"
            )));
        }
    };
    let refs: Vec<&madder::weave::Corrector> = weave.as_ref().map_or(Vec::new(), |w| {
        w.correctors.iter().map(|c| c.as_ref()).collect()
    });
    let detail = weave.as_ref().map(|w| core::WeaveDetail {
        correctors: &refs,
        face_fabric: &w.face_fabric,
        face_map: &w.face_map,
        uptake: &w.uptake,
    });
    let detail = detail.as_ref();
    let size = size_arg("size", size)?;
    let padding = usize::try_from(padding)
        .map_err(|_| ParameterError::new_err(format!("padding must be ≥ 0, got {padding}")))?;
    let faces = faces_arg(faces)?;
    let uv = uv_arg(uv)?;
    let values = args::floats::<f32, IxDyn>("values", values)?;
    let one = values.ndim() == 1;
    let channels = if one { 1 } else { values.shape()[1] };
    let values = flat("values", &values, &[1, 2])?;
    let pool = Pool::new(threads)?;
    let shape: Vec<usize> = if one {
        vec![size, size]
    } else {
        vec![size, size, channels]
    };
    if let Some(out) = out {
        if !out.is_c_contiguous() {
            // numpy's `as_slice_mut` would also give a Fortran-order array's memory
            return Err(ParameterError::new_err(
                "out must be a C-contiguous, writeable float32 array",
            ));
        }
        if out.shape() != shape.as_slice() {
            return Err(ParameterError::new_err(format!(
                "out must have shape {shape:?}, got {:?}",
                out.shape()
            )));
        }
        let overlapping = {
            let mut guard = out.try_readwrite()?;
            let pixels = guard.as_slice_mut().map_err(|_| {
                ParameterError::new_err("out must be a C-contiguous, writeable float32 array")
            })?;
            let mut coverage = vec![0u8; size * size];
            pool.run(py, || {
                let n = core::rasterize_to_with(
                    pixels,
                    &mut coverage,
                    &faces,
                    &uv,
                    &values,
                    channels,
                    size,
                    detail,
                )?;
                core::pad_to(pixels, &mut coverage, size, channels, padding);
                if let Some(mode) = clip {
                    core::clip(pixels, channels, mode);
                }
                Ok::<_, madder::error::TextureError>(n)
            })
            .map_err(to_py)?
        };
        return Ok((out, overlapping));
    }
    let raster = pool
        .run(py, || {
            let mut r = core::rasterize_with(&faces, &uv, &values, channels, size, detail)?;
            core::pad(&mut r, padding);
            if let Some(mode) = clip {
                core::clip(&mut r.pixels, channels, mode);
            }
            Ok::<_, madder::error::TextureError>(r)
        })
        .map_err(to_py)?;
    let image = PyArray1::from_vec(py, raster.pixels).reshape(shape)?;
    Ok((image, raster.overlapping))
}

/// Writes an image as a half-float OpenEXR file, atomically.
///
/// `write_exr(path, image, channels=("R", "G", "B", "A"))`: `image` `(H, W, C)` (any float
/// dtype; or `(H, W)` with one channel name), row 0 at the bottom as `rasterize` returns it
/// (EXR stores the top row first: rows are flipped in the file); `channels` one name per
/// channel. RLE-compressed. The file is written beside `path` and renamed over it, so a
/// failure never leaves a partial file there (and keeps a previous one). Raises
/// `ParameterError` for mismatched channels or bad names, a `CacheError` naming the file
/// (the built-in kind for an I/O failure: `FileNotFoundError`, `PermissionError`...).
#[pyfunction]
#[pyo3(signature = (path, image, channels=vec!["R".to_string(), "G".to_string(), "B".to_string(), "A".to_string()]))]
pub fn write_exr(
    py: Python<'_>,
    path: PathBuf,
    image: &Bound<'_, PyAny>,
    channels: Vec<String>,
) -> PyResult<()> {
    let image = args::floats::<f32, IxDyn>("image", image)?;
    let shape = image.shape().to_vec();
    let c = if shape.len() == 3 { shape[2] } else { 1 };
    let pixels = flat("image", &image, &[2, 3])?;
    if c != channels.len() {
        return Err(ParameterError::new_err(format!(
            "image has {c} channels (shape {shape:?}), but {} channel names were given: {channels:?}",
            channels.len()
        )));
    }
    let (height, width) = (shape[0], shape[1]);
    py.detach(|| {
        let names: Vec<&str> = channels.iter().map(String::as_str).collect();
        core::write_exr(&path, &pixels, width, height, &names)
    })
    .map_err(to_py)
}

/// Reads an OpenEXR image (its first layer) as an `(H, W, C)` float32 array, row 0 at the
/// bottom (as `write_exr` takes it), channels in the order R, G, B, A (those present) then
/// the others by name. Raises a `CacheError` naming the file.
#[pyfunction]
pub fn read_exr<'py>(py: Python<'py>, path: PathBuf) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
    let image = py.detach(|| core::read_exr(&path)).map_err(to_py)?;
    let shape = vec![image.height, image.width, image.channels.len()];
    PyArray1::from_vec(py, image.pixels).reshape(shape)
}

/// The rings of a mesh for the outline drawn at the texel (core `texture::Outline`).
///
/// `Outline(faces, n_vertices, rings=3)`: `faces` `(T, 3)` (any integer dtype), the mesh
/// the stain is rasterized from; its vertices' neighbours are built once, for every frame.
/// `fields(coverage, *, threads=None) -> (N, 2) float32`: per vertex `f = c / P`, with `P`
/// the highest coverage (the dye amount, read within [0, 1]) within `rings` rings, and the
/// zone `w` (1 where a vertex within `rings` rings is dry). Rasterize them like the stain
/// and give the image to `sharpen_outline`.
#[pyclass(module = "madder", frozen)]
pub struct Outline {
    inner: core::Outline,
}

#[pymethods]
impl Outline {
    #[new]
    #[pyo3(signature = (faces, n_vertices, rings=core::outline::DEFAULT_RINGS))]
    fn new(
        py: Python<'_>,
        faces: &Bound<'_, PyAny>,
        n_vertices: usize,
        rings: usize,
    ) -> PyResult<Self> {
        let faces = faces_arg(faces)?;
        if let Some((t, v)) = faces.iter().enumerate().find_map(|(t, f)| {
            f.iter()
                .find(|&&v| v as usize >= n_vertices)
                .map(|&v| (t, v))
        }) {
            return Err(ParameterError::new_err(format!(
                "face {t} names vertex {v}, but the mesh has {n_vertices} vertices"
            )));
        }
        let inner = py.detach(|| core::Outline::new(&faces, n_vertices, rings));
        Ok(Self { inner })
    }

    /// Vertices of the mesh.
    #[getter]
    fn n_vertices(&self) -> usize {
        self.inner.n_vertices()
    }

    #[pyo3(signature = (coverage, *, threads=None))]
    fn fields<'py>(
        &self,
        py: Python<'py>,
        coverage: &Bound<'py, PyAny>,
        threads: Option<usize>,
    ) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
        let coverage = args::floats::<f32, IxDyn>("coverage", coverage)?;
        let coverage = flat("coverage", &coverage, &[1])?;
        let n = self.inner.n_vertices();
        if coverage.len() != n {
            return Err(ParameterError::new_err(format!(
                "coverage has {} values for {n} vertices",
                coverage.len()
            )));
        }
        let pool = Pool::new(threads)?;
        let fields = pool.run(py, || self.inner.fields(&coverage));
        PyArray1::from_vec(py, fields).reshape(vec![n, core::outline::FIELDS])
    }
}

/// A C-contiguous float32 array's values, writeable, or a `ParameterError` naming it.
fn writeable<'a>(
    name: &str,
    guard: &'a mut numpy::PyReadwriteArrayDyn<'_, f32>,
) -> PyResult<&'a mut [f32]> {
    guard.as_slice_mut().map_err(|_| {
        ParameterError::new_err(format!(
            "{name} must be a C-contiguous, writeable float32 array"
        ))
    })
}

/// Draws the stain's outline within a texel, in place (core `texture::outline`).
///
/// `sharpen_outline(fields, stain=None, wet=None, *, excess=2, threads=None)`: `fields`
/// the `(size, size, 2)` raster of `Outline.fields`; `stain` the `(size, size, 4)`
/// premultiplied RGBA stain image (float32, C-contiguous), each texel scaled by the front's ratio (and
/// clipped to coverage 1 where the weave's detail then exceeds it); `wet` optionally the
/// `(size, size, C)` wet image, whose channel `excess` (the dye above saturation) is cut
/// ahead of the front. The GIL is released; the result does not depend on `threads`.
#[pyfunction]
#[pyo3(signature = (fields, stain=None, wet=None, *, excess=2, threads=None))]
pub fn sharpen_outline<'py>(
    py: Python<'py>,
    fields: &Bound<'py, PyAny>,
    stain: Option<Bound<'py, PyArrayDyn<f32>>>,
    wet: Option<Bound<'py, PyArrayDyn<f32>>>,
    excess: usize,
    threads: Option<usize>,
) -> PyResult<()> {
    outline_pass(
        py,
        fields,
        stain,
        wet,
        ("excess", excess),
        threads,
        core::sharpen,
    )
}

/// Leaves the stain's outline to the shader, in place (core `texture::outline`, "At the
/// pixel").
///
/// `lift_outline(fields, texel, stain=None, wet=None, *, distance=3, threads=None)`:
/// `fields` as for `sharpen_outline`; `texel` a texel's size in metres along u and v;
/// `stain` the premultiplied RGBA stain image, lifted to its plateau over the front's
/// zone; `wet` the `(size, size, C)` wet image, whose channel `distance` gets the front's
/// signed distance in metres (positive behind it, `±DISTANCE_LIMIT` far behind or ahead). The GIL
/// is released; the result does not depend on `threads`.
#[pyfunction]
#[pyo3(signature = (fields, texel, stain=None, wet=None, *, distance=3, threads=None))]
pub fn lift_outline<'py>(
    py: Python<'py>,
    fields: &Bound<'py, PyAny>,
    texel: (f32, f32),
    stain: Option<Bound<'py, PyArrayDyn<f32>>>,
    wet: Option<Bound<'py, PyArrayDyn<f32>>>,
    distance: usize,
    threads: Option<usize>,
) -> PyResult<()> {
    if !(texel.0 > 0.0 && texel.1 > 0.0 && texel.0.is_finite() && texel.1.is_finite()) {
        return Err(ParameterError::new_err(format!(
            "texel must be two positive sizes in metres, got {texel:?}"
        )));
    }
    outline_pass(
        py,
        fields,
        stain,
        wet,
        ("distance", distance),
        threads,
        |f, size, stain, wet| core::lift(f, size, [texel.0, texel.1], stain, wet),
    )
}

type WetImage<'a> = Option<(&'a mut [f32], usize, usize)>;

/// Checks an outline pass's images against `fields` (the `(size, size, FIELDS)` raster)
/// and runs `pass` on them: the wet image's channel `channel` (its name, its index) must
/// exist.
fn outline_pass<'py>(
    py: Python<'py>,
    fields: &Bound<'py, PyAny>,
    stain: Option<Bound<'py, PyArrayDyn<f32>>>,
    wet: Option<Bound<'py, PyArrayDyn<f32>>>,
    channel: (&str, usize),
    threads: Option<usize>,
    pass: impl FnOnce(&[f32], usize, Option<&mut [f32]>, WetImage<'_>) + Send,
) -> PyResult<()> {
    let fields = args::floats::<f32, IxDyn>("fields", fields)?;
    let fshape = fields.shape().to_vec();
    let fields = flat("fields", &fields, &[3])?;
    let size = fshape[0];
    if fshape != [size, size, core::outline::FIELDS] {
        return Err(ParameterError::new_err(format!(
            "fields must have shape (size, size, {}), got {fshape:?}",
            core::outline::FIELDS
        )));
    }
    if let Some(stain) = stain.as_ref().filter(|s| s.shape() != [size, size, 4]) {
        return Err(ParameterError::new_err(format!(
            "stain must have shape ({size}, {size}, 4) as the fields, got {:?}",
            stain.shape()
        )));
    }
    let (name, index) = channel;
    let channels = match &wet {
        Some(w) if w.ndim() != 3 || w.shape()[..2] != [size, size] || index >= w.shape()[2] => {
            return Err(ParameterError::new_err(format!(
                "wet must have shape ({size}, {size}, C) with channel {index} ({name}) in it, got {:?}",
                w.shape()
            )));
        }
        Some(w) => w.shape()[2],
        None => 0,
    };
    let pool = Pool::new(threads)?;
    let mut stain_guard = stain.as_ref().map(|s| s.try_readwrite()).transpose()?;
    let stain = match stain_guard.as_mut() {
        Some(g) => Some(writeable("stain", g)?),
        None => None,
    };
    let mut wet_guard = wet.as_ref().map(|w| w.try_readwrite()).transpose()?;
    let wet = match wet_guard.as_mut() {
        Some(g) => Some((writeable("wet", g)?, channels, index)),
        None => None,
    };
    pool.run(py, || pass(&fields, size, stain, wet));
    Ok(())
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(rasterize, m)?)?;
    m.add_class::<Outline>()?;
    m.add_function(wrap_pyfunction!(sharpen_outline, m)?)?;
    m.add_function(wrap_pyfunction!(lift_outline, m)?)?;
    m.add("OUTLINE_DISTANCE_LIMIT", core::outline::DISTANCE_LIMIT)?;
    m.add_class::<WeaveDetail>()?;
    m.add("NO_WEAVE", core::NO_WEAVE)?;
    m.add_function(wrap_pyfunction!(write_exr, m)?)?;
    m.add_function(wrap_pyfunction!(read_exr, m)?)?;
    Ok(())
}
