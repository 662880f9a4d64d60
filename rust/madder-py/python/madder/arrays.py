"""Array conversion at the Python boundary: the native module takes C-contiguous float32
positions of shape (N, 3) and uint32 faces of shape (F, 3); these helpers convert anything
array-like without copying when it already has that form."""

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
