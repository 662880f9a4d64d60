"""Type stubs of `madder._core`, the native module (the pyo3 binding, `rust/madder-py/src`).

Checked against the binding by `tests/python/test_stubs.py`: every class, method,
property, function and constant here exists there and the other way round, with the same
parameter names and defaults wherever pyo3 gives a signature. A binding change without a
change here fails that test.

Array arguments follow one convention (the binding's `args.rs`): a float argument
(`_Floats`) takes any float dtype (float16, float32, float64) in any layout (C or Fortran
order, strided views) or anything `numpy.asarray` turns into one, converted once (float16
and float32 to float64 exactly, float64 to float32 rounded to nearest where the core reads
float32); an index argument (`_Indices`: faces, face_polygon, ...) takes any integer dtype
and refuses negative indices. Anything else is a `ParameterError` naming the argument.
Returned arrays are numpy arrays of the dtype their annotation says.
"""

from collections.abc import Callable
from os import PathLike
from typing import Any, Final, Literal

import numpy as np
import numpy.typing as npt

_F32 = npt.NDArray[np.float32]
_F64 = npt.NDArray[np.float64]
_U32 = npt.NDArray[np.uint32]
_Floats = npt.ArrayLike
"""A float array argument: any float dtype, any layout (see the module docstring)."""
_Indices = npt.ArrayLike
"""An index array argument: any integer dtype, no negative index (see the module docstring)."""
_Path = str | PathLike[str]
_RGB = tuple[float, float, float]

__version__: Final[str]
DEFAULT_DIFFUSION: Final[float]
"""The default isotropic diffusion rate of the densities, m²/s (the core's)."""
DEFAULT_SOLUTE_COLOR: Final[_RGB]
"""The default colour of the liquid's solute, linear RGB (the core's)."""
DEGENERATE_UV_REL: Final[float]
"""A face's UVs are degenerate when |det| ≤ DEGENERATE_UV_REL·|u1 − u0|·|u2 − u0|."""
DYE_EXCESS_RANGE: Final[float]
"""The dye amount above saturation the playback values carry (up to 1 + this; an image's
excess channel is the amount above 1 over this)."""
NO_WEAVE: Final[int]
"""`WeaveDetail`'s face_fabric value of a face without the weave's detail."""

class MadderError(Exception):
    """Base class of every Madder error (the subclasses are in `madder._errors`)."""

class Topology:
    def __new__(
        cls,
        faces: _Indices,
        n_vertices: int,
        face_polygon: _Indices | None = None,
        n_polygons: int | None = None,
    ) -> Topology: ...
    @property
    def n_vertices(self) -> int: ...
    @property
    def n_faces(self) -> int: ...
    @property
    def n_edges(self) -> int: ...
    @property
    def n_polygons(self) -> int: ...
    def boundary_edges(self) -> _U32: ...
    def non_manifold_edges(self) -> _U32: ...
    def loose_vertices(self) -> _U32: ...
    def __repr__(self) -> str: ...

def ftle(
    faces: _Indices,
    positions: _Floats,
    velocity: Callable[[float, _F64], npt.ArrayLike] | _Floats,
    t0: float,
    T: float,
    *,
    steps: int = 100,
    times: _Floats | None = None,
    method: Literal["rk4", "rk8"] = "rk4",
) -> _F64:
    """FTLE σ = ln √λmax / |T| per vertex (seed §5.2, §5.5.1); positions (N, 3) or (K, N, 3);
    `steps` fixed steps of `method` ("rk4": classical RK4; "rk8": DOP853's 8th-order solution)."""

def ridges(
    faces: _Indices,
    positions: _Floats,
    field: _Floats,
    *,
    smoothing: float = 1.0,
    hessian_smoothing: float = 1.0,
    field_smoothing: float = 0.0,
    threshold: float | None = None,
    s0: float = 100.0,
    min_edges: int = 20,
    min_branch: int = 10,
    join: bool = True,
    remove_valleys: bool = False,
) -> dict[str, npt.NDArray[Any]]:
    """Ridges of a field: triangles (P,), barycentric (P, 3), points (P, 3), edges (E, 2)."""

def encode_angles(faces: _Indices, positions: _Floats) -> tuple[_F64, _F64, _U32]:
    """Corner angles (F, 3), signed dihedral angles (E,) and interior edges (E, 2) (seed ch. 3)."""

def decode_angles(
    faces: _Indices,
    corners: _Floats,
    dihedrals: _Floats,
    *,
    reference_face: int | None = None,
    reference_positions: _Floats | None = None,
    refine_iterations: int = 0,
    method: str = "spectral",
    previous: _Floats | None = None,
) -> _F64:
    """Vertex positions (N, 3) from corner and dihedral angles (spectral, tracked or sequential)."""

def weft_directions(
    topology: Topology,
    positions: _Floats,
    face_uv: _Floats,
    face_angle: _Floats | None = None,
) -> _F32: ...
def distances_within(points_: _Floats, vertices: _Floats, triangles: _Indices, cutoff: float) -> _F32: ...

class DiffusionStepper:
    def __new__(
        cls,
        topology: Topology,
        positions: _Floats,
        density: _Floats,
        rate: float | None = None,
        *,
        face_tensors: _Floats | None = None,
        face_uv: _Floats | None = None,
        face_angle: _Floats | None = None,
        threads: int | None = None,
    ) -> DiffusionStepper: ...
    def step(self, positions: _Floats, dt: float, substeps: int = 1) -> None: ...
    @property
    def density(self) -> _F32: ...
    @property
    def vertex_area(self) -> _F64: ...
    @property
    def degenerate_uv_faces(self) -> int: ...
    def enable_color(self, colors: _Floats) -> None: ...
    def add_liquid(self, delta: _Floats, color: _RGB | None = None) -> None: ...
    @property
    def color(self) -> _F32 | None: ...
    def total_mass(self) -> float: ...

class Simulator:
    def __new__(
        cls,
        topology: Topology | _Indices,
        rest: _Floats,
        positions: _Floats,
        *,
        diffusion: float | None = None,
        face_tensors: _Floats | None = None,
        face_uv: _Floats | None = None,
        face_angle: _Floats | None = None,
        color: _RGB = ...,
        gravity: _RGB = (0.0, 0.0, -9.81),
        viscosity: float | None = None,
        friction: float | None = None,
        absorption: float | None = None,
        saturation: float | None = None,
        adsorption: float | None = None,
        capacity: float | None = None,
        evaporation: float | None = None,
        evaporation_boundary: float | None = None,
        wicking_exponent: float | None = None,
        wicking_density: float | None = None,
        wicking_picard: int = 0,
        wicking_tolerance: float = 0.0,
        irregularity: float | None = None,
        irregularity_length: float | None = None,
        irregularity_seed: int = 0,
        irregularity_fine_length: float | None = None,
        carry_solute: bool = False,
        residual_saturation: float | None = None,
        vapour_limited: bool = False,
        carried_fraction: float | None = None,
        dispersivity: float | None = None,
        holdup: float | None = None,
        film_creep: float | None = None,
        drip_hold: float = 0.0,
        capillary_height: float = 0.0,
        substeps: int = 1,
        first_substep: float = 0.0,
        use_gravity: bool = True,
        use_rectilinear: bool = True,
        use_coriolis: bool = True,
        momentum_advection: bool = True,
        detail: int = 0,
        threads: int | None = None,
    ) -> Simulator: ...
    def step(
        self, positions: _Floats, dt: float, after: _Floats | None = None, after_dt: float | None = None
    ) -> None: ...
    def add_liquid(self, solvent: _Floats, concentration: float = 0.05, color: _RGB | None = None) -> None: ...
    def add_pool(
        self, weights: _Floats, amount: float, concentration: float = 0.05, color: _RGB | None = None
    ) -> None: ...
    def splash(self, center: _RGB, speed: float, seed: int, weights: _Floats) -> None: ...
    def wetness(self, *, fine: bool = False) -> _F32: ...
    def stain(self, *, fine: bool = False) -> _F32: ...
    def deposit(self, *, fine: bool = False) -> _F32: ...
    def solute_color(self, *, fine: bool = False) -> _F32: ...
    def densities(self) -> dict[str, _F64]: ...
    def totals(self) -> dict[str, float]: ...
    @property
    def velocity(self) -> _F32: ...
    @velocity.setter
    def velocity(self, velocity: _Floats) -> None: ...
    @property
    def vertex_area(self) -> _F64: ...
    def profile(self) -> dict[str, float | int]: ...
    @property
    def time(self) -> float: ...
    @property
    def detail(self) -> int: ...
    @property
    def n_fine_vertices(self) -> int: ...

class Refinement:
    def __new__(cls, topology: Topology, level: int) -> Refinement: ...
    @property
    def level(self) -> int: ...
    @property
    def n_vertices(self) -> int: ...
    @property
    def n_faces(self) -> int: ...
    def faces(self) -> _U32: ...
    def face_uv(self, face_uv: _Floats) -> _F32: ...
    def __repr__(self) -> str: ...

def rasterize(
    faces: _Indices,
    uv: _Floats,
    values: _Floats,
    size: int,
    padding: int = 4,
    *,
    out: _F32 | None = None,
    threads: int | None = None,
    weave: WeaveDetail | None = None,
    clip: str | None = None,
) -> tuple[_F32, int]: ...
def sharpen_outline(
    fields: _Floats,
    stain: _F32 | None = None,
    wet: _F32 | None = None,
    *,
    excess: int = 2,
    threads: int | None = None,
) -> None: ...

def lift_outline(
    fields: _Floats,
    texel: tuple[float, float],
    stain: _F32 | None = None,
    wet: _F32 | None = None,
    *,
    distance: int = 3,
    threads: int | None = None,
) -> None: ...

OUTLINE_DISTANCE_LIMIT: Final[float]

class Outline:
    def __new__(cls, faces: _Indices, n_vertices: int, rings: int = 3) -> Outline: ...
    @property
    def n_vertices(self) -> int: ...
    def fields(self, coverage: _Floats, *, threads: int | None = None) -> _F32: ...

class WeaveDetail:
    def __new__(
        cls, correctors: list[Corrector], face_fabric: _Indices, face_map: _Floats, uptake: list[bool]
    ) -> WeaveDetail: ...
    @property
    def n_faces(self) -> int: ...
def write_exr(path: _Path, image: _Floats, channels: list[str] = ...) -> None: ...
def read_exr(path: _Path) -> _F32: ...

class CacheWriter:
    def __new__(
        cls,
        path: _Path,
        n_vertices: int,
        fields: list[str],
        first_frame: int,
        n_frames: int,
        frame_time: float = 0.0,
    ) -> CacheWriter: ...
    def push_frame(self, fields: list[_Floats]) -> None: ...
    def finish(self) -> Any: ...
    def abort(self) -> None: ...

class CacheReader:
    def __new__(cls, path: _Path) -> CacheReader: ...
    def read_frame(self, frame: int) -> _F32: ...
    def read_stain(
        self,
        frame: int,
        references: tuple[float, float, float],
        color: _RGB,
        rgba: _F32,
        wetness: _F32,
        deposit: _F32,
        clamp: bool = True,
        excess: _F32 | None = None,
    ) -> None: ...
    def read(self, frame: int, field: str) -> _F32: ...
    @property
    def path(self) -> Any: ...
    @property
    def n_vertices(self) -> int: ...
    @property
    def fields(self) -> list[str]: ...
    @property
    def first_frame(self) -> int: ...
    @property
    def last_frame(self) -> int: ...
    @property
    def truncated_at(self) -> int | None: ...
    @property
    def version(self) -> int: ...
    @property
    def frame_time(self) -> float | None: ...

def fabric_tile(weave: str, grid: str | None = None, gaps: bool = True) -> list[str]: ...
def fabric_tensor(
    weave: str,
    grid: str | None = None,
    coefficients: tuple[float, float, float, float, float, float] | None = None,
    gaps: bool = True,
) -> _F64: ...
def fabric_corrector(
    weave: str,
    grid: str | None = None,
    coefficients: tuple[float, float, float, float, float, float] | None = None,
    gaps: bool = True,
    filter: float = 0.0,
) -> Corrector: ...

class Corrector:
    @property
    def cells(self) -> tuple[int, int]: ...
    @property
    def threads(self) -> tuple[float, float]: ...
    @property
    def refine(self) -> int: ...
    @property
    def filter(self) -> float: ...
    def samples(self, i: int) -> _F64: ...
    def uptake(self) -> _F64: ...
    @property
    def energy(self) -> list[float]: ...
    def __repr__(self) -> str: ...

def homogenize(tensors: _Floats) -> _F64: ...
def ellipse(tensor: tuple[float, float, float]) -> tuple[float, float]: ...

class PointCache:
    def __new__(cls, path: _Path, format: str | None = None) -> PointCache: ...
    def read_frame(self, k: int) -> _F32: ...
    def check_times(self) -> None: ...
    @property
    def path(self) -> Any: ...
    @property
    def format(self) -> str: ...
    @property
    def n_points(self) -> int: ...
    @property
    def n_frames(self) -> int: ...
    @property
    def frame_times(self) -> _F64: ...
    @property
    def time_unit(self) -> str: ...
    @property
    def start(self) -> float | None: ...
    @property
    def rate(self) -> float | None: ...
    @property
    def trailing_bytes(self) -> int: ...
    def __len__(self) -> int: ...
    def __repr__(self) -> str: ...

class MotionEncoder:
    def __new__(
        cls,
        path: _Path,
        faces: _Indices,
        *,
        start: float = 1.0,
        rate: float = 1.0,
        bits: int = 12,
        corner_bits: int | None = None,
        corners: str = "every",
        keyframe_interval: int = 16,
        warm: str = "tracked",
    ) -> MotionEncoder: ...
    def add_frame(self, positions: _Floats) -> _F32: ...
    def finish(self) -> dict[str, Any]: ...
    def abort(self) -> None: ...
    @property
    def path(self) -> Any: ...
    @property
    def n_points(self) -> int | None: ...
    def __repr__(self) -> str: ...

class MotionCodec:
    def __new__(cls, path: _Path) -> MotionCodec: ...
    def read_frame(self, k: int) -> _F32: ...
    @property
    def path(self) -> Any: ...
    @property
    def format(self) -> str: ...
    @property
    def n_points(self) -> int: ...
    @property
    def n_frames(self) -> int: ...
    @property
    def faces(self) -> _U32: ...
    @property
    def start(self) -> float: ...
    @property
    def rate(self) -> float: ...
    @property
    def bits(self) -> tuple[int, int]: ...
    @property
    def frame_times(self) -> _F64: ...
    def __len__(self) -> int: ...
    def __repr__(self) -> str: ...

def position_baseline_stats(frames: _Floats, bits: int, predict: bool = True) -> dict[str, float]: ...
class Pc2Writer:
    def __new__(cls, path: _Path, n_points: int, start: float = 1.0, rate: float = 1.0) -> Pc2Writer: ...
    def add_frame(self, positions: _Floats) -> None: ...
    def finish(self) -> None: ...
    def abort(self) -> None: ...
    @property
    def n_frames(self) -> int: ...
    @property
    def path(self) -> Any: ...
    def __repr__(self) -> str: ...

def write_pc2(path: _Path, frames: _Floats, start: float = 1.0, rate: float = 1.0) -> None: ...
def write_mdd(path: _Path, frames: _Floats, times: list[float]) -> None: ...
