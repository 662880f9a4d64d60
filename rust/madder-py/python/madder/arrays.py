"""Array shaping for callers: the native module itself takes any float dtype and layout for
float arguments and any integer dtype for indices (converting once; see `_core.pyi`); these
helpers give the add-on's usual forms, (N, 3) float32 positions and (F, 3) uint32 faces,
C-contiguous, without copying when the array already has that form."""

import numpy as np


def as_positions(a) -> np.ndarray:
    """(N, 3) float32, C-contiguous."""
    arr = np.ascontiguousarray(a, dtype=np.float32)
    return arr.reshape(-1, 3)


def as_faces(a) -> np.ndarray:
    """(F, 3) uint32, C-contiguous; rejects negative indices."""
    arr = np.asarray(a)
    if arr.size and arr.min() < 0:
        raise ValueError("face indices must be non-negative")
    return np.ascontiguousarray(arr, dtype=np.uint32).reshape(-1, 3)
