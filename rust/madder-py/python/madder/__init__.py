"""Madder: stain simulation on deforming cloth.

The heavy lifting is in the Rust extension `madder._core`; this package re-exports it and
adds small bpy-free helpers (array conversion) used by the Blender add-on and the tests.
"""

from ._core import (
    CacheReader,
    CacheWriter,
    DiffusionStepper,
    MadderError,
    PointCache,
    Refinement,
    Simulator,
    Topology,
    __version__,
    distances_within,
    ellipse,
    fabric_tensor,
    fabric_tile,
    homogenize,
    rasterize,
    read_exr,
    weft_directions,
    write_exr,
    write_mdd,
    write_pc2,
)
from ._errors import (
    CacheError,
    CacheIsADirectoryError,
    CacheNotADirectoryError,
    CacheNotFoundError,
    CachePermissionError,
    FabricError,
    MeshError,
    ParameterError,
    SolveError,
)
from .arrays import as_faces, as_positions

__all__ = [
    "CacheError",
    "CacheIsADirectoryError",
    "CacheNotADirectoryError",
    "CacheNotFoundError",
    "CachePermissionError",
    "CacheReader",
    "CacheWriter",
    "DiffusionStepper",
    "FabricError",
    "MadderError",
    "MeshError",
    "ParameterError",
    "PointCache",
    "Refinement",
    "Simulator",
    "SolveError",
    "Topology",
    "__version__",
    "as_faces",
    "as_positions",
    "distances_within",
    "ellipse",
    "fabric_tensor",
    "fabric_tile",
    "homogenize",
    "rasterize",
    "read_exr",
    "weft_directions",
    "write_exr",
    "write_mdd",
    "write_pc2",
]
