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
    #[error(
        "Detail level {level} would refine the cloth to {vertices} vertices, more than the \
         {max} Madder allows: choose a lower Detail level"
    )]
    DetailTooLarge {
        level: u32,
        vertices: usize,
        max: usize,
    },
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
    #[error("{name} at vertex {index} must be {requirement}, got {value}")]
    OutOfRangeAt {
        name: &'static str,
        index: usize,
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
    #[error(
        "the iterative solver did not converge in {iterations} iterations (relative residual {residual:e})"
    )]
    NotConverged { iterations: usize, residual: f64 },
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
    #[error(
        "{path}: file is truncated at frame {first_cut}: frame {frame} is not in it (the frames before {first_cut} still read)"
    )]
    Truncated {
        path: PathBuf,
        /// the frame that was read
        frame: i32,
        /// the first frame whose block is cut off
        first_cut: i32,
    },
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

/// Reading or writing a PC2 or MDD point cache (module [`crate::io::point_cache`]). Frames
/// are counted from 0 in file order and vertices from 0, as the file stores them.
#[derive(Debug, thiserror::Error)]
pub enum PointCacheError {
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error(
        "{path}: unknown point cache format: no PC2 signature, and the name does not end in .pc2 or .mdd (MDD files carry no signature; open it as MDD explicitly)"
    )]
    UnknownFormat { path: PathBuf },
    #[error("{path}: not a PC2 file (it does not start with the signature \"POINTCACHE2\\0\")")]
    BadSignature { path: PathBuf },
    #[error("{path}: PC2 file version {found} is not supported (this build reads version 1)")]
    Version { path: PathBuf, found: i32 },
    #[error("{path}: corrupt {format} header: {reason}")]
    Header {
        path: PathBuf,
        format: crate::io::point_cache::Format,
        reason: String,
    },
    #[error(
        "{path}: file is truncated: frame {frame} is incomplete (the header declares {n_frames} frames of {n_points} points, {expected} bytes; the file has {len})"
    )]
    Truncated {
        path: PathBuf,
        frame: usize,
        n_frames: usize,
        n_points: usize,
        expected: u64,
        len: u64,
    },
    #[error("{path}: frame {frame} is not in the file (it holds frames 0..={last})", last = .n_frames.saturating_sub(1))]
    FrameOutOfRange {
        path: PathBuf,
        frame: usize,
        n_frames: usize,
    },
    #[error("{path}: frame {frame}, vertex {vertex} has a non-finite position {position:?}")]
    NonFinite {
        path: PathBuf,
        frame: usize,
        vertex: usize,
        position: [f32; 3],
    },
    #[error("{path}: frame {frame}: {reason}")]
    Time {
        path: PathBuf,
        frame: usize,
        reason: String,
    },
    #[error("{path}: {reason}")]
    Usage { path: PathBuf, reason: String },
}

/// A number in an error message, at most four significant digits: plain from 10⁻³ to
/// below 10⁶ (`1`, `-0.25`, `123.5`), else in scientific notation (`1.000e-170`), so a
/// message never spells out 170 zeros.
struct Compact(f64);

impl std::fmt::Display for Compact {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let x = self.0;
        if x == 0.0 || !x.is_finite() {
            return write!(f, "{x}");
        }
        let sci = format!("{x:.3e}");
        // the exponent after rounding to four digits (9999.7 is 1.000e4)
        let e: i32 = sci[sci.find('e').map_or(0, |i| i + 1)..]
            .parse()
            .unwrap_or(0);
        if !(-3..6).contains(&e) {
            return f.write_str(&sci);
        }
        let plain = format!("{x:.*}", (3 - e).max(0) as usize);
        let plain = if plain.contains('.') {
            plain.trim_end_matches('0').trim_end_matches('.')
        } else {
            &plain
        };
        f.write_str(plain)
    }
}

/// Bad weave input or a failed homogenization (module [`crate::weave`]). Cells are named by
/// tile `row` (0 = bottom, the `y = 0` edge) and `col` (0 = left); lines of a text grid by
/// their 1-based `line` counted from the top, as an editor shows them.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum WeaveError {
    #[error("the weave tile is empty (it needs at least one row and one column of cells)")]
    EmptyTile,
    #[error("a {width}×{height} weave tile needs {expected} cells, got {got}")]
    CellCount {
        width: usize,
        height: usize,
        expected: usize,
        got: usize,
    },
    #[error(
        "weave grid line {line} has {got} cells, but the lines above have {expected} (every line is one row of the tile)"
    )]
    RaggedRow {
        line: usize,
        expected: usize,
        got: usize,
    },
    #[error(
        "weave grid line {line}, character {column}: {ch:?} is not a cell (W warp up, w warp down, F weft up, f weft down, . gap)"
    )]
    UnknownCell {
        line: usize,
        column: usize,
        ch: char,
    },
    #[error("pair coefficient {pair} must be finite and > 0, got {}", Compact(*.value))]
    NonPositiveCoefficient { pair: &'static str, value: f64 },
    #[error(
        "cell (row {row}, column {col}) borders a {pair} pair, whose coefficient must be finite and > 0, got {}",
        Compact(*.value)
    )]
    CellCoefficient {
        row: usize,
        col: usize,
        pair: &'static str,
        value: f64,
    },
    #[error(
        "cell (row {row}, column {col}) has diffusion tensor [s11 {}, s12 {}, s22 {}], which is not symmetric positive definite (needs finite entries, s11 > 0 and s11·s22 − s12² > 0)",
        Compact(*.s11), Compact(*.s12), Compact(*.s22)
    )]
    NotPositiveDefinite {
        row: usize,
        col: usize,
        s11: f64,
        s12: f64,
        s22: f64,
    },
    #[error(
        "the tile's diffusion tensors span a contrast of {ratio:.3e} (largest over smallest eigenvalue; the smallest is in cell (row {row}, column {col})), beyond the {limit:.0e} that double precision can homogenize"
    )]
    Contrast {
        ratio: f64,
        limit: f64,
        row: usize,
        col: usize,
    },
    #[error("homogenization option {name} must be {requirement}, got {}", Compact(*.value))]
    Option {
        name: &'static str,
        requirement: &'static str,
        value: f64,
    },
    #[error("homogenization: {0}")]
    Solve(#[from] SolveError),
}

/// Bad input to the UV texture rasterizer, or an image file that could not be written or
/// read (module [`crate::texture`]). Faces and corners are counted from 0 in input order;
/// a file error names the file the caller asked for (the temporary file beside it is an
/// implementation detail).
#[derive(Debug, thiserror::Error)]
pub enum TextureError {
    #[error("{name} {size} is out of range (1..={max} texels)")]
    Size {
        /// `"size"`, `"width"` or `"height"`
        name: &'static str,
        size: usize,
        max: usize,
    },
    #[error("a texture needs 1..={max} channels, got {channels}")]
    Channels { channels: usize, max: usize },
    #[error("{name} has {got} entries, expected {expected}")]
    Length {
        name: &'static str,
        expected: usize,
        got: usize,
    },
    #[error("values has {got} entries, not a whole number of vertices of {channels} channels")]
    ValuesLength { got: usize, channels: usize },
    #[error(
        "face {face} references vertex {vertex}, but the values cover only {n_vertices} vertices"
    )]
    VertexOutOfRange {
        face: usize,
        vertex: u32,
        n_vertices: usize,
    },
    #[error("face {face}, corner {corner} has a non-finite UV ({u}, {v})")]
    NonFiniteUv {
        face: usize,
        corner: usize,
        u: f64,
        v: f64,
    },
    #[error("image channel name {name:?}: {reason}")]
    ChannelName { name: String, reason: &'static str },
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}: {reason}")]
    Exr { path: PathBuf, reason: String },
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
    #[error(transparent)]
    Weave(#[from] WeaveError),
    #[error(transparent)]
    PointCache(#[from] PointCacheError),
    #[error(transparent)]
    Texture(#[from] TextureError),
}

pub type Result<T, E = Error> = std::result::Result<T, E>;

#[cfg(test)]
mod tests {
    use super::Compact;

    #[test]
    fn compact_numbers() {
        let show = |x: f64| Compact(x).to_string();
        assert_eq!(show(1.0), "1");
        assert_eq!(show(-0.25), "-0.25");
        assert_eq!(show(123.456), "123.5");
        assert_eq!(show(0.1 + 0.2), "0.3");
        assert_eq!(show(123456.0), "123456");
        assert_eq!(show(999999.9), "1.000e6");
        assert_eq!(show(0.001), "0.001");
        assert_eq!(show(0.00099999), "0.001");
        assert_eq!(show(1e-170), "1.000e-170");
        assert_eq!(show(-3.5e160), "-3.500e160");
        assert_eq!(show(0.0), "0");
        assert_eq!(show(f64::NAN), "NaN");
        assert_eq!(show(f64::NEG_INFINITY), "-inf");
    }
}
