//! Error types of the core. Each variant carries the element (vertex, face, frame) that
//! failed, so that the Blender side can say *where* the input is wrong, not only *that* it is.

use std::path::PathBuf;

use crate::io::point_cache::PointCacheError;

/// Bad mesh input: topology or per-frame positions.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MeshError {
    /// The mesh has no triangle.
    #[error("mesh has no triangles")]
    Empty,
    /// A face names a vertex the mesh does not have.
    #[error("face {face} references vertex {vertex}, but the mesh has only {n_vertices} vertices")]
    VertexOutOfRange {
        /// The face (index into the topology's faces).
        face: usize,
        /// The vertex.
        vertex: u32,
        /// How many vertices the mesh has.
        n_vertices: usize,
    },
    /// A face uses one vertex twice (a degenerate triangle by construction).
    #[error("face {face} uses vertex {vertex} more than once")]
    RepeatedVertex {
        /// The face (index into the topology's faces).
        face: usize,
        /// The vertex.
        vertex: u32,
    },
    /// Positions given for another number of vertices.
    #[error("expected {expected} vertex positions, got {got}")]
    VertexCountMismatch {
        /// How many were expected.
        expected: usize,
        /// How many there were.
        got: usize,
    },
    /// A position with a NaN or infinite coordinate.
    #[error("vertex {vertex} has a non-finite position")]
    NonFinitePosition {
        /// The vertex.
        vertex: usize,
    },
    /// A triangle-to-polygon map of the wrong length.
    #[error("polygon map has {got} entries for {expected} triangles")]
    PolygonMapLength {
        /// How many were expected.
        expected: usize,
        /// How many there were.
        got: usize,
    },
    /// A Detail level whose refined surface would have too many vertices.
    #[error(
        "Detail level {level} would refine the cloth to {vertices} vertices, more than the \
         {max} Madder allows: choose a lower Detail level"
    )]
    DetailTooLarge {
        /// The Detail level asked for.
        level: u32,
        /// How many vertices the refined surface would have.
        vertices: usize,
        /// The most Madder allows (`mesh::refine::MAX_FINE_VERTICES`).
        max: usize,
    },
}

/// Parameters out of their valid range.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ParamError {
    /// A scalar parameter outside its range.
    #[error("{name} must be {requirement}, got {value}")]
    OutOfRange {
        /// The parameter (or array).
        name: &'static str,
        /// What it must be.
        requirement: &'static str,
        /// The value given.
        value: f64,
    },
    /// A per-vertex value outside its range.
    #[error("{name} at vertex {index} must be {requirement}, got {value}")]
    OutOfRangeAt {
        /// The parameter (or array).
        name: &'static str,
        /// The vertex or entry at fault.
        index: usize,
        /// What it must be.
        requirement: &'static str,
        /// The value given.
        value: f64,
    },
    /// An array with the wrong number of values.
    #[error("{name} has {got} values, expected {expected}")]
    Length {
        /// The parameter (or array).
        name: &'static str,
        /// How many were expected.
        expected: usize,
        /// How many there were.
        got: usize,
    },
    /// A NaN or infinite value in an array.
    #[error("{name} value {index} is not finite")]
    NonFinite {
        /// The parameter (or array).
        name: &'static str,
        /// The vertex or entry at fault.
        index: usize,
    },
    /// A tensor that is not symmetric positive semi-definite.
    #[error("{name} {index} is not symmetric positive semi-definite")]
    NotPositiveSemiDefinite {
        /// The parameter (or array).
        name: &'static str,
        /// The vertex or entry at fault.
        index: usize,
    },
}

/// A linear solve that failed (the system was not numerically positive definite).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SolveError {
    /// The Cholesky factorization met a non-positive pivot.
    #[error("the system matrix is not positive definite (pivot {pivot} of {n})")]
    NotPositiveDefinite {
        /// The column of the failing pivot.
        pivot: usize,
        /// The dimension of the system.
        n: usize,
    },
    /// The solver could not allocate its workspace.
    #[error("the linear solver ran out of memory")]
    OutOfMemory,
    /// The iterative solver reached its iteration limit.
    #[error(
        "the iterative solver did not converge in {iterations} iterations (relative residual {residual:e})"
    )]
    NotConverged {
        /// Iterations run.
        iterations: usize,
        /// The relative residual reached.
        residual: f64,
    },
}

/// Reading or writing a Madder cache file.
#[derive(Debug, thiserror::Error)]
pub enum CacheError {
    /// The operating system refused a read or a write.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The operating system's error.
        source: std::io::Error,
    },
    /// The file does not start with the Madder magic bytes.
    #[error("{path}: not a Madder cache file (bad magic)")]
    BadMagic {
        /// The file.
        path: PathBuf,
    },
    /// A format version this build cannot read.
    #[error("{path}: cache format version {found} is not supported (this build reads {supported})")]
    Version {
        /// The file.
        path: PathBuf,
        /// The version in the file.
        found: u32,
        /// The version this build reads.
        supported: u32,
    },
    /// A header whose values contradict each other or the file.
    #[error("{path}: corrupt header: {reason}")]
    Header {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// A frame after the point where the file is cut off.
    #[error(
        "{path}: file is truncated at frame {first_cut}: frame {frame} is not in it (the frames before {first_cut} still read)"
    )]
    Truncated {
        /// The file.
        path: PathBuf,
        /// the frame that was read
        frame: i32,
        /// the first frame whose block is cut off
        first_cut: i32,
    },
    /// A frame whose block fails its checksum.
    #[error("{path}: frame {frame} is corrupt (checksum mismatch)")]
    Checksum {
        /// The file.
        path: PathBuf,
        /// The frame.
        frame: i32,
    },
    /// A frame outside the cache's range.
    #[error("{path}: frame {frame} is not in the cache (frames {first}..={last})")]
    FrameMissing {
        /// The file.
        path: PathBuf,
        /// The frame.
        frame: i32,
        /// The first frame in the cache.
        first: i32,
        /// The last frame in the cache.
        last: i32,
    },
    /// A field the cache does not store.
    #[error("{path}: field '{field}' is not in the cache")]
    FieldMissing {
        /// The file.
        path: PathBuf,
        /// The field asked for.
        field: String,
    },
    /// The writer was used out of order (wrong frame count or field lengths).
    #[error("cache writer: {reason}")]
    Usage {
        /// What is wrong.
        reason: String,
    },
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
    /// A tile without cells.
    #[error("the weave tile is empty (it needs at least one row and one column of cells)")]
    EmptyTile,
    /// A tile given with the wrong number of cells.
    #[error("a {width}×{height} weave tile needs {expected} cells, got {got}")]
    CellCount {
        /// Columns of the tile.
        width: usize,
        /// Rows of the tile.
        height: usize,
        /// How many were expected.
        expected: usize,
        /// How many there were.
        got: usize,
    },
    /// A text grid whose lines differ in length.
    #[error(
        "weave grid line {line} has {got} cells, but the lines above have {expected} (every line is one row of the tile)"
    )]
    RaggedRow {
        /// The line of the grid, 1-based from the top.
        line: usize,
        /// How many were expected.
        expected: usize,
        /// How many there were.
        got: usize,
    },
    /// A character of a text grid that is not a cell.
    #[error(
        "weave grid line {line}, character {column}: {ch:?} is not a cell (W warp up, w warp down, F weft up, f weft down, . gap)"
    )]
    UnknownCell {
        /// The line of the grid, 1-based from the top.
        line: usize,
        /// The character in the line, 1-based.
        column: usize,
        /// The character.
        ch: char,
    },
    /// A pair coefficient that is not finite and positive.
    #[error("pair coefficient {pair} must be finite and > 0, got {}", Compact(*.value))]
    NonPositiveCoefficient {
        /// The pair, e.g. `weft–warp`.
        pair: &'static str,
        /// The value given.
        value: f64,
    },
    /// A cell next to a pair whose coefficient is not finite and positive.
    #[error(
        "cell (row {row}, column {col}) borders a {pair} pair, whose coefficient must be finite and > 0, got {}",
        Compact(*.value)
    )]
    CellCoefficient {
        /// The cell's row (0 = bottom).
        row: usize,
        /// The cell's column (0 = left).
        col: usize,
        /// The pair, e.g. `weft–warp`.
        pair: &'static str,
        /// The value given.
        value: f64,
    },
    /// A cell tensor that is not symmetric positive definite.
    #[error(
        "cell (row {row}, column {col}) has diffusion tensor [s11 {}, s12 {}, s22 {}], which is not symmetric positive definite (needs finite entries, s11 > 0 and s11·s22 − s12² > 0)",
        Compact(*.s11), Compact(*.s12), Compact(*.s22)
    )]
    NotPositiveDefinite {
        /// The cell's row (0 = bottom).
        row: usize,
        /// The cell's column (0 = left).
        col: usize,
        /// The tensor's `s11`.
        s11: f64,
        /// The tensor's `s12`.
        s12: f64,
        /// The tensor's `s22`.
        s22: f64,
    },
    /// Cell tensors too far apart for double precision to homogenize.
    #[error(
        "the tile's diffusion tensors span a contrast of {ratio:.3e} (largest over smallest eigenvalue; the smallest is in cell (row {row}, column {col})), beyond the {limit:.0e} that double precision can homogenize"
    )]
    Contrast {
        /// The largest eigenvalue over the smallest.
        ratio: f64,
        /// The largest contrast allowed.
        limit: f64,
        /// The cell's row (0 = bottom).
        row: usize,
        /// The cell's column (0 = left).
        col: usize,
    },
    /// A homogenization option outside its range.
    #[error("homogenization option {name} must be {requirement}, got {}", Compact(*.value))]
    Option {
        /// The parameter (or array).
        name: &'static str,
        /// What it must be.
        requirement: &'static str,
        /// The value given.
        value: f64,
    },
    /// The cell problem's solve failed.
    #[error("homogenization: {0}")]
    Solve(#[from] SolveError),
}

/// Bad input to the UV texture rasterizer, or an image file that could not be written or
/// read (module [`crate::texture`]). Faces and corners are counted from 0 in input order;
/// a file error names the file the caller asked for (the temporary file beside it is an
/// implementation detail).
#[derive(Debug, thiserror::Error)]
pub enum TextureError {
    /// An image size outside `1..=max` texels.
    #[error("{name} {size} is out of range (1..={max} texels)")]
    Size {
        /// `"size"`, `"width"` or `"height"`
        name: &'static str,
        /// The size asked for.
        size: usize,
        /// The largest size allowed.
        max: usize,
    },
    /// A channel count outside `1..=max`.
    #[error("a texture needs 1..={max} channels, got {channels}")]
    Channels {
        /// The channel count asked for.
        channels: usize,
        /// The most allowed.
        max: usize,
    },
    /// An input array of the wrong length.
    #[error("{name} has {got} entries, expected {expected}")]
    Length {
        /// The array.
        name: &'static str,
        /// How many entries were expected.
        expected: usize,
        /// How many there were.
        got: usize,
    },
    /// A value array that is not a whole number of vertices.
    #[error("values has {got} entries, not a whole number of vertices of {channels} channels")]
    ValuesLength {
        /// How many values there were.
        got: usize,
        /// Channels per vertex.
        channels: usize,
    },
    /// A face that names a vertex past the end of the values.
    #[error(
        "face {face} references vertex {vertex}, but the values cover only {n_vertices} vertices"
    )]
    VertexOutOfRange {
        /// The face.
        face: usize,
        /// The vertex it names.
        vertex: u32,
        /// How many vertices the values cover.
        n_vertices: usize,
    },
    /// A UV coordinate that is NaN or infinite.
    #[error("face {face}, corner {corner} has a non-finite UV ({u}, {v})")]
    NonFiniteUv {
        /// The face.
        face: usize,
        /// Its corner (0, 1 or 2).
        corner: usize,
        /// The U coordinate.
        u: f64,
        /// The V coordinate.
        v: f64,
    },
    /// A face whose weave detail input is unusable (module [`crate::texture::weave`]).
    #[error("weave detail of face {face}: {problem}")]
    WeaveFace {
        /// The face.
        face: usize,
        /// What is wrong with its fabric index or its UV-to-thread map.
        problem: String,
    },
    /// An image channel name OpenEXR cannot hold.
    #[error("image channel name {name:?}: {reason}")]
    ChannelName {
        /// The name.
        name: String,
        /// What is wrong with it.
        reason: &'static str,
    },
    /// The image file could not be written or read.
    #[error("{path}: {source}")]
    Io {
        /// The file the caller asked for.
        path: PathBuf,
        /// The operating system's error.
        source: std::io::Error,
    },
    /// A file that is not an OpenEXR image Madder can read.
    #[error("{path}: {reason}")]
    Exr {
        /// The file.
        path: PathBuf,
        /// What is wrong with it.
        reason: String,
    },
}

/// Bad input to the Lagrangian coherent structure tools (module [`crate::lcs`], seed ch. 5).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LcsError {
    /// The mesh has no triangle.
    #[error("the mesh has no triangles (FTLE and ridges need a triangle mesh)")]
    NoTriangles,
    /// A zero (or non-finite) integration time span `T`.
    #[error("the time span T must be finite and non-zero, got {}", Compact(*.span))]
    ZeroSpan {
        /// The span given.
        span: f64,
    },
    /// A velocity with a NaN or infinite component.
    #[error("velocity at {at} at time {} is not finite", Compact(*.time))]
    NonFiniteVelocity {
        /// Where: `vertex 12` for per-vertex velocities, `point 12` for a callable's batch.
        at: String,
        /// The time at which it was evaluated.
        time: f64,
    },
    /// An array or a callable's result of the wrong shape.
    #[error("{name} has shape {got}, expected {expected}")]
    Shape {
        /// The array or the callable.
        name: String,
        /// The shape expected, e.g. `(100, 3)`.
        expected: String,
        /// The shape given.
        got: String,
    },
    /// A time outside the frames given (per-frame positions or velocities).
    #[error(
        "time {} is outside the frames' times [{}, {}] (the flow from t0 over T must stay within them)",
        Compact(*.time), Compact(*.first), Compact(*.last)
    )]
    TimeOutOfRange {
        /// The time asked for.
        time: f64,
        /// The first frame's time.
        first: f64,
        /// The last frame's time.
        last: f64,
    },
    /// Frame times that are not finite and strictly increasing.
    #[error("frame times must be finite and strictly increasing: times[{index}] = {}", Compact(*.value))]
    FrameTimes {
        /// The first bad entry.
        index: usize,
        /// Its value.
        value: f64,
    },
    /// A scalar field value (the field whose ridges are extracted) that is not finite.
    #[error("field value at vertex {vertex} is not finite")]
    NonFiniteField {
        /// The vertex.
        vertex: usize,
    },
    /// An option out of its range.
    #[error("{name} must be {requirement}, got {}", Compact(*.value))]
    Option {
        /// The option.
        name: &'static str,
        /// What it must be.
        requirement: &'static str,
        /// The value given.
        value: f64,
    },
    /// An unknown integration scheme name.
    #[error("method must be \"rk4\" or \"rk8\", got {method:?}")]
    Method {
        /// The name given.
        method: String,
    },
    /// An error raised by a user's velocity callable (its message).
    #[error("the velocity callable failed at time {}: {message}", Compact(*.time))]
    Callable {
        /// The time of the failing call.
        time: f64,
        /// The callable's error.
        message: String,
    },
    /// Bad positions (wrong count, non-finite).
    #[error(transparent)]
    Mesh(#[from] MeshError),
    /// The smoothing solve failed.
    #[error("ridge smoothing: {0}")]
    Solve(#[from] SolveError),
}

/// Bad input to the angle-based surface representation (module [`crate::angles`], seed
/// ch. 3). Edges are named by their two vertices, faces and corners by index.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum AngleError {
    /// Bad topology or positions (count, non-finite, index out of range).
    #[error(transparent)]
    Mesh(#[from] MeshError),
    /// An edge shared by three or more faces.
    #[error(
        "edge ({a}, {b}) is shared by {faces} faces: the angle representation needs a manifold mesh"
    )]
    NonManifoldEdge {
        /// One end.
        a: u32,
        /// The other end.
        b: u32,
        /// How many faces share it.
        faces: usize,
    },
    /// An edge traversed in the same direction by both of its faces.
    #[error(
        "edge ({a}, {b}) runs the same way in faces {face_a} and {face_b}: the faces are not \
         consistently oriented (or the mesh is not orientable)"
    )]
    NotOrientable {
        /// One end.
        a: u32,
        /// The other end.
        b: u32,
        /// One face.
        face_a: usize,
        /// The other face.
        face_b: usize,
    },
    /// A vertex used by no face (its position is not determined by any angle).
    #[error("vertex {vertex} is used by no face (its position is not determined by the angles)")]
    LooseVertex {
        /// The vertex.
        vertex: usize,
    },
    /// A face not reachable from face 0 across interior edges.
    #[error(
        "face {face} is not connected to face 0 across interior edges: reconstruct each \
         connected piece on its own"
    )]
    Disconnected {
        /// The first face not reached.
        face: usize,
    },
    /// A face of zero area (its angles are undefined).
    #[error("face {face} is degenerate (zero area): its angles are undefined")]
    DegenerateFace {
        /// The face.
        face: usize,
    },
    /// Corner angles for another number of faces.
    #[error("expected corner angles for {expected} faces, got {got}")]
    CornerCount {
        /// How many faces the mesh has.
        expected: usize,
        /// How many rows were given.
        got: usize,
    },
    /// Dihedral angles for another number of interior edges.
    #[error("expected {expected} dihedral angles (one per interior edge), got {got}")]
    DihedralCount {
        /// How many interior edges the mesh has.
        expected: usize,
        /// How many were given.
        got: usize,
    },
    /// A corner angle that is NaN or infinite.
    #[error("corner {corner} of face {face} has a non-finite angle")]
    NonFiniteCorner {
        /// The face.
        face: usize,
        /// The corner (0, 1 or 2).
        corner: usize,
    },
    /// A dihedral angle that is NaN or infinite.
    #[error("the dihedral angle of edge ({a}, {b}) (interior edge {edge}) is not finite")]
    NonFiniteDihedral {
        /// Index into the interior edge list.
        edge: usize,
        /// One end.
        a: u32,
        /// The other end.
        b: u32,
    },
    /// A reference face (the rigid placement) that the mesh does not have.
    #[error("reference face {face} is out of range (the mesh has {n_faces} faces)")]
    PlacementFace {
        /// The face.
        face: usize,
        /// How many faces the mesh has.
        n_faces: usize,
    },
    /// Reference positions that are non-finite or a degenerate triangle.
    #[error("the reference triangle's positions are not finite or have zero area")]
    PlacementPositions,
    /// Only one of a reference face and its positions (from the binding).
    #[error("reference_face and reference_positions must be given together")]
    PlacementIncomplete,
    /// A reconstruction method that does not exist (from the binding).
    #[error("method must be 'spectral', 'tracked' or 'sequential', got {method:?}")]
    Method {
        /// The method given.
        method: String,
    },
    /// An array of the wrong shape (from the binding).
    #[error("{name} has shape {got}, expected {expected}")]
    Shape {
        /// The array.
        name: String,
        /// The shape expected, e.g. `(100, 3)`.
        expected: String,
        /// The shape given.
        got: String,
    },
    /// The eigen-solve (sparse Cholesky or subspace iteration) failed.
    #[error("angle reconstruction: {0}")]
    Solve(#[from] SolveError),
}

/// Writing or reading a motion file of the angle codec (module [`crate::angles::codec`]).
/// Every variant names the file; frame-level ones the frame (0-based sample index).
#[derive(Debug, thiserror::Error)]
pub enum CodecError {
    /// The operating system refused a read or a write.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The operating system's error.
        source: std::io::Error,
    },
    /// The file does not start with the motion file's magic bytes.
    #[error("{path}: not a Madder motion file (bad magic)")]
    BadMagic {
        /// The file.
        path: PathBuf,
    },
    /// A format version this build cannot read.
    #[error("{path}: motion file version {found} is not supported (this build reads {supported})")]
    Version {
        /// The file.
        path: PathBuf,
        /// The version in the file.
        found: u32,
        /// The version this build reads.
        supported: u32,
    },
    /// A header (or connectivity) that is damaged or contradicts itself.
    #[error("{path}: corrupt header: {reason}")]
    Header {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// The connectivity stored in (or given for) the file cannot carry angles.
    #[error("{path}: connectivity: {source}")]
    Mesh {
        /// The file.
        path: PathBuf,
        /// What is wrong with it (names the edge, face or vertex).
        source: AngleError,
    },
    /// The file ends inside (or before) a frame the header declares.
    #[error("{path}: file is truncated at frame {frame} (the header declares {n_frames} frames)")]
    Truncated {
        /// The file.
        path: PathBuf,
        /// The first frame that is cut off or missing.
        frame: usize,
        /// Frames the header declares.
        n_frames: usize,
    },
    /// A frame whose block fails its checksum or does not decode.
    #[error("{path}: frame {frame} is corrupt: {reason}")]
    Corrupt {
        /// The file.
        path: PathBuf,
        /// The frame.
        frame: usize,
        /// What is wrong.
        reason: String,
    },
    /// A frame index outside the file.
    #[error("{path}: frame {frame} is not in the file (it holds frames 0..{n_frames})")]
    FrameOutOfRange {
        /// The file.
        path: PathBuf,
        /// The frame asked for.
        frame: i64,
        /// Frames in the file.
        n_frames: usize,
    },
    /// Positions given to the encoder that cannot be encoded (count, NaN, a degenerate face).
    #[error("{path}: frame {frame}: {source}")]
    Input {
        /// The file being written.
        path: PathBuf,
        /// The frame (0-based, in the order given).
        frame: usize,
        /// What is wrong (names the vertex or face).
        source: AngleError,
    },
    /// The reconstruction of a frame failed (an eigen-solve).
    #[error("{path}: frame {frame}: {source}")]
    Reconstruct {
        /// The file.
        path: PathBuf,
        /// The frame.
        frame: usize,
        /// The failure.
        source: AngleError,
    },
    /// An encoder option out of range, or the encoder used out of order.
    #[error("{path}: {reason}")]
    Usage {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
}

/// Any core error. The binding crate maps each variant to a typed Python exception.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// Bad mesh input.
    #[error(transparent)]
    Mesh(#[from] MeshError),
    /// A parameter out of range.
    #[error(transparent)]
    Param(#[from] ParamError),
    /// A failed linear solve.
    #[error(transparent)]
    Solve(#[from] SolveError),
    /// A Madder cache file that cannot be read or written.
    #[error(transparent)]
    Cache(#[from] CacheError),
    /// Bad weave input or a failed homogenization.
    #[error(transparent)]
    Weave(#[from] WeaveError),
    /// A PC2 or MDD file that cannot be read or written.
    #[error(transparent)]
    PointCache(#[from] PointCacheError),
    /// A texture that cannot be rasterized, written or read.
    #[error(transparent)]
    Texture(#[from] TextureError),
    /// Bad input to FTLE or ridge extraction.
    #[error(transparent)]
    Lcs(#[from] LcsError),
    /// Bad input to the angle representation.
    #[error(transparent)]
    Angles(#[from] AngleError),
    /// A motion file of the angle codec that cannot be written or read.
    #[error(transparent)]
    Codec(#[from] CodecError),
}

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
