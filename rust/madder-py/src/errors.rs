//! Typed Python exceptions, mapped from the core error variants in one place.
//!
//! ```text
//! MadderError
//! ├── MeshError       (also a ValueError)  bad topology, positions or UVs; names face/vertex
//! ├── ParameterError  (also a ValueError)  out-of-range parameters; names the parameter
//! │                                        (FTLE/ridges: the array, vertex or time too)
//! ├── FabricError     (also a ValueError)  a weave or cell tensor is invalid; names the cell
//! ├── SolveError                           a linear solve failed
//! └── CacheError      (also an OSError)    cache, PC2/MDD or image file missing, truncated,
//!                                          corrupt or not writable
//!     (+ FileNotFoundError, PermissionError, IsADirectoryError, NotADirectoryError
//!        for the I/O failures of those kinds)
//! ```
//!
//! Every exception carries the fields of its core variant as attributes (`err.vertex`,
//! `err.face`, `err.frame`, `err.cell` = (row, column), `err.name` for a parameter,
//! `err.filename` and `err.errno` for a file...), so that a caller can act on *where*
//! the input is wrong without parsing the message. The message itself is the core's
//! `Display`, unchanged. This file picks the class and the fields; `madder/_errors.py`
//! (`_from_core`) builds the instance and, for an I/O failure, the built-in kind.

use std::path::Path;

use pyo3::exceptions::PyException;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use pyo3::{IntoPyObjectExt, create_exception, import_exception};

create_exception!(
    madder,
    MadderError,
    PyException,
    "Base class of every Madder error."
);

// The subclasses need two bases (MadderError and a builtin), which `create_exception!`
// cannot express, so they are defined in `madder/_errors.py` and imported here.
import_exception!(madder._errors, MeshError);
import_exception!(madder._errors, ParameterError);
import_exception!(madder._errors, SolveError);
import_exception!(madder._errors, CacheError);
import_exception!(madder._errors, FabricError);

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("MadderError", m.py().get_type::<MadderError>())
}

/// The attributes of one exception, in the order they are set.
struct Fields<'py> {
    py: Python<'py>,
    dict: Bound<'py, PyDict>,
    err: Option<PyErr>,
}

impl<'py> Fields<'py> {
    fn new(py: Python<'py>) -> Self {
        Fields {
            py,
            dict: PyDict::new(py),
            err: None,
        }
    }

    fn set<T: IntoPyObjectExt<'py>>(mut self, name: &str, value: T) -> Self {
        if self.err.is_none() {
            let r = value
                .into_bound_py_any(self.py)
                .and_then(|v| self.dict.set_item(name, v));
            self.err = r.err();
        }
        self
    }

    fn path(self, path: &Path) -> Self {
        self.set("filename", path.to_string_lossy().into_owned())
    }

    fn io(self, path: &Path, source: &std::io::Error) -> Self {
        self.path(path)
            .set("errno", source.raw_os_error())
            .set("strerror", source.to_string())
    }

    /// A cell of a weave tile: `cell` = (row, column), and both on their own.
    fn cell(self, row: usize, col: usize) -> Self {
        self.set("cell", (row, col)).set("row", row).set("col", col)
    }
}

/// Converts a core error into the matching Python exception, its fields as attributes.
pub fn to_py(e: impl Into<madder::Error>) -> PyErr {
    let e = e.into();
    Python::attach(|py| build(py, &e).unwrap_or_else(|err| err))
}

fn build(py: Python<'_>, e: &madder::Error) -> PyResult<PyErr> {
    use madder::error::{
        CacheError as C, Error, ParamError as P, TextureError as T, WeaveError as W,
    };
    use madder::io::point_cache::PointCacheError as Pc;
    let f = Fields::new(py);
    let (class, f) = match e {
        Error::Mesh(m) => (py.get_type::<MeshError>(), mesh_fields(f, m)),
        Error::Lcs(l) => lcs_class_fields(py, f, l),
        Error::Angles(a) => angle_class_fields(py, f, a),
        Error::Codec(c) => codec_class_fields(py, f, c),
        Error::Param(p) => (
            py.get_type::<ParameterError>(),
            match p {
                P::OutOfRange {
                    name,
                    requirement,
                    value,
                } => f
                    .set("name", name)
                    .set("requirement", requirement)
                    .set("value", value),
                P::OutOfRangeAt {
                    name,
                    index,
                    requirement,
                    value,
                } => f
                    .set("name", name)
                    .set("index", index)
                    .set("vertex", index)
                    .set("requirement", requirement)
                    .set("value", value),
                P::Length {
                    name,
                    expected,
                    got,
                } => f
                    .set("name", name)
                    .set("expected", expected)
                    .set("got", got),
                P::NonFinite { name, index } | P::NotPositiveSemiDefinite { name, index } => {
                    f.set("name", name).set("index", index)
                }
            },
        ),
        Error::Solve(s) => (py.get_type::<SolveError>(), solve_fields(f, s)),
        Error::Cache(c) => (
            py.get_type::<CacheError>(),
            match c {
                C::Io { path, source } => f.io(path, source),
                C::BadMagic { path } => f.path(path),
                C::Version {
                    path,
                    found,
                    supported,
                } => f.path(path).set("found", found).set("supported", supported),
                C::Header { path, reason } => f.path(path).set("reason", reason),
                C::Truncated {
                    path,
                    frame,
                    first_cut,
                } => f.path(path).set("frame", frame).set("first_cut", first_cut),
                C::Checksum { path, frame } => f.path(path).set("frame", frame),
                C::FrameMissing {
                    path,
                    frame,
                    first,
                    last,
                } => f
                    .path(path)
                    .set("frame", frame)
                    .set("first", first)
                    .set("last", last),
                C::FieldMissing { path, field } => f.path(path).set("field", field),
                C::Usage { reason } => f.set("reason", reason),
            },
        ),
        Error::PointCache(c) => (
            py.get_type::<CacheError>(),
            match c {
                Pc::Io { path, source } => f.io(path, source),
                Pc::UnknownFormat { path } | Pc::BadSignature { path } => f.path(path),
                Pc::Version { path, found } => f.path(path).set("found", found),
                Pc::Header {
                    path,
                    format,
                    reason,
                } => f
                    .path(path)
                    .set("format", format!("{format:?}"))
                    .set("reason", reason),
                Pc::Truncated {
                    path,
                    frame,
                    n_frames,
                    n_points,
                    ..
                } => f
                    .path(path)
                    .set("frame", frame)
                    .set("n_frames", n_frames)
                    .set("n_points", n_points),
                Pc::FrameOutOfRange {
                    path,
                    frame,
                    n_frames,
                } => f.path(path).set("frame", frame).set("n_frames", n_frames),
                Pc::NonFinite {
                    path,
                    frame,
                    vertex,
                    position,
                } => f
                    .path(path)
                    .set("frame", frame)
                    .set("vertex", vertex)
                    .set("position", *position),
                Pc::Time {
                    path,
                    frame,
                    reason,
                } => f.path(path).set("frame", frame).set("reason", reason),
                Pc::Usage { path, reason } => f.path(path).set("reason", reason),
            },
        ),
        Error::Weave(w) => (
            py.get_type::<FabricError>(),
            match w {
                W::EmptyTile => f,
                W::CellCount { expected, got, .. } => f.set("expected", expected).set("got", got),
                W::RaggedRow {
                    line,
                    expected,
                    got,
                } => f
                    .set("line", line)
                    .set("expected", expected)
                    .set("got", got),
                W::UnknownCell { line, column, ch } => f
                    .set("line", line)
                    .set("column", column)
                    .set("char", ch.to_string()),
                W::NonPositiveCoefficient { pair, value } => {
                    f.set("pair", pair).set("value", value)
                }
                W::CellCoefficient {
                    row,
                    col,
                    pair,
                    value,
                } => f.cell(*row, *col).set("pair", pair).set("value", value),
                W::NotPositiveDefinite { row, col, .. } => f.cell(*row, *col),
                W::Contrast {
                    ratio, row, col, ..
                } => f.cell(*row, *col).set("ratio", ratio),
                W::Option {
                    name,
                    requirement,
                    value,
                } => f
                    .set("name", name)
                    .set("requirement", requirement)
                    .set("value", value),
                W::Solve(s) => solve_fields(f, s),
            },
        ),
        Error::Texture(t) => match t {
            T::VertexOutOfRange {
                face,
                vertex,
                n_vertices,
            } => (
                py.get_type::<MeshError>(),
                f.set("face", face)
                    .set("vertex", vertex)
                    .set("n_vertices", n_vertices),
            ),
            T::NonFiniteUv { face, corner, u, v } => (
                py.get_type::<MeshError>(),
                f.set("face", face).set("corner", corner).set("uv", (u, v)),
            ),
            T::WeaveFace { face, problem } => (
                py.get_type::<ParameterError>(),
                f.set("face", face).set("problem", problem),
            ),
            T::Size { name, size, max } => (
                py.get_type::<ParameterError>(),
                f.set("name", name).set("value", size).set("max", max),
            ),
            T::Channels { channels, max } => (
                py.get_type::<ParameterError>(),
                f.set("name", "channels")
                    .set("value", channels)
                    .set("max", max),
            ),
            T::Length {
                name,
                expected,
                got,
            } => (
                py.get_type::<ParameterError>(),
                f.set("name", name)
                    .set("expected", expected)
                    .set("got", got),
            ),
            T::ValuesLength { got, channels } => (
                py.get_type::<ParameterError>(),
                f.set("name", "values")
                    .set("got", got)
                    .set("channels", channels),
            ),
            T::ChannelName { name, reason } => (
                py.get_type::<ParameterError>(),
                f.set("name", "channels")
                    .set("channel", name)
                    .set("reason", reason),
            ),
            T::Io { path, source } => (py.get_type::<CacheError>(), f.io(path, source)),
            T::Exr { path, reason } => (
                py.get_type::<CacheError>(),
                f.path(path).set("reason", reason),
            ),
        },
    };
    if let Some(err) = f.err {
        return Err(err);
    }
    let make = py.import("madder._errors")?.getattr("_from_core")?;
    let value = make.call1((class, e.to_string(), f.dict))?;
    Ok(PyErr::from_value(value))
}

/// A `ParameterError` about the argument `name` (the binding's own check of an array
/// argument, `args.rs`), with `name` set as the core's parameter errors set it (a name
/// followed by what the argument takes, "topology (a Topology or ...)", sets the name).
pub fn argument_error(name: &str, message: String) -> PyErr {
    Python::attach(|py| {
        let f = Fields::new(py).set("name", name.split(" (").next().unwrap_or(name));
        if let Some(err) = f.err {
            return err;
        }
        py.import("madder._errors")
            .and_then(|m| m.getattr("_from_core"))
            .and_then(|make| make.call1((py.get_type::<ParameterError>(), message, f.dict)))
            .map_or_else(|err| err, PyErr::from_value)
    })
}

fn solve_fields<'py>(f: Fields<'py>, s: &madder::error::SolveError) -> Fields<'py> {
    use madder::error::SolveError as S;
    match s {
        S::NotPositiveDefinite { pivot, n } => f.set("pivot", pivot).set("n", n),
        S::OutOfMemory => f,
        S::NotConverged {
            iterations,
            residual,
        } => f.set("iterations", iterations).set("residual", residual),
    }
}

fn mesh_fields<'py>(f: Fields<'py>, m: &madder::error::MeshError) -> Fields<'py> {
    use madder::error::MeshError as M;
    match m {
        M::Empty => f,
        M::VertexOutOfRange {
            face,
            vertex,
            n_vertices,
        } => f
            .set("face", face)
            .set("vertex", vertex)
            .set("n_vertices", n_vertices),
        M::RepeatedVertex { face, vertex } => f.set("face", face).set("vertex", vertex),
        M::VertexCountMismatch { expected, got } => f.set("expected", expected).set("got", got),
        M::NonFinitePosition { vertex } => f.set("vertex", vertex),
        M::PolygonMapLength { expected, got } => f.set("expected", expected).set("got", got),
        M::DetailTooLarge {
            level,
            vertices,
            max,
        } => f
            .set("level", level)
            .set("vertices", vertices)
            .set("max", max),
    }
}

/// The angle representation (`madder.encode_angles`, `madder.decode_angles`): mesh
/// problems are `MeshError`s naming the edge, face or vertex; bad angles, arrays and options
/// `ParameterError`s naming the face corner, the edge or the array.
fn angle_class_fields<'py>(
    py: Python<'py>,
    f: Fields<'py>,
    a: &madder::AngleError,
) -> (Bound<'py, pyo3::types::PyType>, Fields<'py>) {
    use madder::AngleError as A;
    let param = py.get_type::<ParameterError>();
    let mesh = py.get_type::<MeshError>();
    match a {
        A::Mesh(m) => (mesh, mesh_fields(f, m)),
        A::NonManifoldEdge { a, b, faces } => (mesh, f.set("edge", (a, b)).set("faces", faces)),
        A::NotOrientable {
            a,
            b,
            face_a,
            face_b,
        } => (
            mesh,
            f.set("edge", (a, b))
                .set("face", face_a)
                .set("other_face", face_b),
        ),
        A::LooseVertex { vertex } => (mesh, f.set("vertex", vertex)),
        A::Disconnected { face } | A::DegenerateFace { face } => (mesh, f.set("face", face)),
        A::CornerCount { expected, got } => (
            param,
            f.set("name", "corners")
                .set("expected", expected)
                .set("got", got),
        ),
        A::DihedralCount { expected, got } => (
            param,
            f.set("name", "dihedrals")
                .set("expected", expected)
                .set("got", got),
        ),
        A::NonFiniteCorner { face, corner } => (
            param,
            f.set("name", "corners")
                .set("face", face)
                .set("corner", corner),
        ),
        A::NonFiniteDihedral { edge, a, b } => (
            param,
            f.set("name", "dihedrals")
                .set("index", edge)
                .set("edge", (a, b)),
        ),
        A::PlacementFace { face, n_faces } => (
            param,
            f.set("name", "reference_face")
                .set("face", face)
                .set("n_faces", n_faces),
        ),
        A::PlacementPositions => (param, f.set("name", "reference_positions")),
        A::PlacementIncomplete => (param, f.set("name", "reference_face")),
        A::Method { method } => (param, f.set("name", "method").set("value", method)),
        A::Shape {
            name,
            expected,
            got,
        } => (
            param,
            f.set("name", name)
                .set("expected", expected)
                .set("got", got),
        ),
        A::Solve(s) => (py.get_type::<SolveError>(), solve_fields(f, s)),
    }
}

/// Motion files of the angle codec (`madder.MotionEncoder`, `madder.MotionCodec`): file
/// problems are `CacheError`s naming the file (and frame); bad connectivity or positions
/// `MeshError`s naming the file, frame and vertex/face/edge; bad options `ParameterError`s.
fn codec_class_fields<'py>(
    py: Python<'py>,
    f: Fields<'py>,
    c: &madder::CodecError,
) -> (Bound<'py, pyo3::types::PyType>, Fields<'py>) {
    use madder::CodecError as K;
    let cache = py.get_type::<CacheError>();
    match c {
        K::Io { path, source } => (cache, f.io(path, source)),
        K::BadMagic { path } => (cache, f.path(path)),
        K::Version {
            path,
            found,
            supported,
        } => (
            cache,
            f.path(path).set("found", found).set("supported", supported),
        ),
        K::Header { path, reason } => (cache, f.path(path).set("reason", reason)),
        K::Truncated {
            path,
            frame,
            n_frames,
        } => (
            cache,
            f.path(path).set("frame", frame).set("n_frames", n_frames),
        ),
        K::Corrupt {
            path,
            frame,
            reason,
        } => (
            cache,
            f.path(path).set("frame", frame).set("reason", reason),
        ),
        K::FrameOutOfRange {
            path,
            frame,
            n_frames,
        } => (
            cache,
            f.path(path).set("frame", frame).set("n_frames", n_frames),
        ),
        K::Mesh { path, source } => angle_class_fields(py, f.path(path), source),
        K::Input {
            path,
            frame,
            source,
        }
        | K::Reconstruct {
            path,
            frame,
            source,
        } => angle_class_fields(py, f.path(path).set("frame", frame), source),
        K::Usage { path, reason } => (
            py.get_type::<ParameterError>(),
            f.path(path).set("reason", reason),
        ),
    }
}

/// FTLE and ridges (`madder.ftle`, `madder.ridges`): bad arrays, times and options are
/// `ParameterError`s naming the array, the vertex or the time; mesh problems `MeshError`s.
fn lcs_class_fields<'py>(
    py: Python<'py>,
    f: Fields<'py>,
    l: &madder::LcsError,
) -> (Bound<'py, pyo3::types::PyType>, Fields<'py>) {
    use madder::LcsError as L;
    let param = py.get_type::<ParameterError>();
    match l {
        L::NoTriangles => (py.get_type::<MeshError>(), f),
        L::Mesh(m) => (py.get_type::<MeshError>(), mesh_fields(f, m)),
        L::Solve(s) => (py.get_type::<SolveError>(), solve_fields(f, s)),
        L::ZeroSpan { span } => (param, f.set("name", "T").set("value", span)),
        L::NonFiniteVelocity { at, time } => (
            param,
            f.set("name", "velocity").set("at", at).set("time", time),
        ),
        L::Shape {
            name,
            expected,
            got,
        } => (
            param,
            f.set("name", name)
                .set("expected", expected)
                .set("got", got),
        ),
        L::TimeOutOfRange { time, first, last } => (
            param,
            f.set("name", "times")
                .set("time", time)
                .set("first", first)
                .set("last", last),
        ),
        L::FrameTimes { index, value } => (
            param,
            f.set("name", "times")
                .set("index", index)
                .set("value", value),
        ),
        L::NonFiniteField { vertex } => (param, f.set("name", "field").set("vertex", vertex)),
        L::Method { method } => (param, f.set("name", "method").set("value", method)),
        L::Option {
            name,
            requirement,
            value,
        } => (
            param,
            f.set("name", name)
                .set("requirement", requirement)
                .set("value", value),
        ),
        L::Callable { time, message } => (
            param,
            f.set("name", "velocity")
                .set("time", time)
                .set("message", message),
        ),
    }
}
