//! Error types of the core. Each variant carries the element (vertex, face, frame) that
//! failed, so that the Blender side can say *where* the input is wrong, not only *that* it is.

use std::path::PathBuf;

/// Bad mesh input: topology or per-frame positions.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MeshError {
    #[error("mesh has no triangles")]
    Empty,
    #[error("face {face} references vertex {vertex}, but the mesh has only {n_vertices} vertices")]
    VertexOutOfRange {
        face: usize,
        vertex: u32,
        n_vertices: usize,
    },
    #[error("face {face} uses vertex {vertex} more than once")]
    RepeatedVertex { face: usize, vertex: u32 },
    #[error("expected {expected} vertex positions, got {got}")]
    VertexCountMismatch { expected: usize, got: usize },
    #[error("vertex {vertex} has a non-finite position")]
    NonFinitePosition { vertex: usize },
    #[error("polygon map has {got} entries for {expected} triangles")]
    PolygonMapLength { expected: usize, got: usize },
}

/// Parameters out of their valid range.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ParamError {
    #[error("{name} must be {requirement}, got {value}")]
    OutOfRange {
        name: &'static str,
        requirement: &'static str,
        value: f64,
    },
    #[error("{name} has {got} values, expected {expected}")]
    Length {
        name: &'static str,
        expected: usize,
        got: usize,
    },
    #[error("{name} value {index} is not finite")]
    NonFinite { name: &'static str, index: usize },
    #[error("{name} {index} is not symmetric positive semi-definite")]
    NotPositiveSemiDefinite { name: &'static str, index: usize },
}

/// A linear solve that failed (the system was not numerically positive definite).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SolveError {
    #[error("the system matrix is not positive definite (pivot {pivot} of {n})")]
    NotPositiveDefinite { pivot: usize, n: usize },
    #[error("the linear solver ran out of memory")]
    OutOfMemory,
}

/// Reading or writing a Madder cache file.
#[derive(Debug, thiserror::Error)]
pub enum CacheError {
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}: not a Madder cache file (bad magic)")]
    BadMagic { path: PathBuf },
    #[error("{path}: cache format version {found} is not supported (this build reads {supported})")]
    Version {
        path: PathBuf,
        found: u32,
        supported: u32,
    },
    #[error("{path}: corrupt header: {reason}")]
    Header { path: PathBuf, reason: String },
    #[error("{path}: file is truncated: frame {frame} is incomplete")]
    Truncated { path: PathBuf, frame: i32 },
    #[error("{path}: frame {frame} is corrupt (checksum mismatch)")]
    Checksum { path: PathBuf, frame: i32 },
    #[error("{path}: frame {frame} is not in the cache (frames {first}..={last})")]
    FrameMissing {
        path: PathBuf,
        frame: i32,
        first: i32,
        last: i32,
    },
    #[error("{path}: field '{field}' is not in the cache")]
    FieldMissing { path: PathBuf, field: String },
    #[error("cache writer: {reason}")]
    Usage { reason: String },
}

/// Any core error. The binding crate maps each variant to a typed Python exception.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    #[error(transparent)]
    Mesh(#[from] MeshError),
    #[error(transparent)]
    Param(#[from] ParamError),
    #[error(transparent)]
    Solve(#[from] SolveError),
    #[error(transparent)]
    Cache(#[from] CacheError),
}

pub type Result<T, E = Error> = std::result::Result<T, E>;
