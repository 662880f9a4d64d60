"""Placing the cloth in the world, bpy-free: the scene's Unit Scale, object-space positions
through the object's matrix into metres, and the check that the transform leaves the cloth
an area (tested without Blender in tests/python)."""

import numpy as np

from .errors import BakeError


def unit_scale(system, scale_length):
    """Metres per Blender unit: the scene's Unit Scale (`scale_length`), as Blender applies
    it to every length, velocity and acceleration it shows (not at all with the unit
    `system` None)."""
    return float(scale_length) if system != "NONE" else 1.0


def placed(local, matrix, unit):
    """Object-space positions `local` (N, 3) through the 4×4 `matrix`, in metres, float32."""
    m = np.asarray(matrix, dtype=np.float64)
    return ((np.asarray(local, dtype=np.float64) @ m[:3, :3].T + m[:3, 3]) * unit).astype(np.float32)


def first_non_finite(positions):
    """Index of the first vertex of `positions` (N, 3) with a non-finite coordinate, or None."""
    bad = np.flatnonzero(~np.isfinite(positions).all(axis=1))
    return int(bad[0]) if bad.size else None


def check_transform(name, frame, faces, local, matrix):
    """Refuses (BakeError naming object `name` and `frame`) an object transform that
    collapses the cloth at `frame`: a scale of 0 (or nearly 0) on the axes the cloth spans
    leaves it no area, and the simulation nothing to work on. Compares the world-space
    area of the triangles `faces` with their object-space area times the transform's
    largest stretch squared (1 for any rotation and uniform scale; 0 when the scale
    flattens the cloth to a line or a point) and refuses a ratio of a millionth or less."""
    full = np.asarray(matrix, dtype=np.float64)
    m = full[:3, :3]
    if not np.isfinite(full).all():
        raise BakeError(f"'{name}' at frame {frame}: its object transform is not finite", object=name, frame=frame)
    stretch = np.linalg.svd(m, compute_uv=False)
    if stretch[-1] > 1e-6 * stretch[0]:  # invertible: no area can vanish (the usual case, O(1))
        return
    a, b, c = (local[faces[:, k]] for k in range(3))
    n = np.cross(b - a, c - a)  # twice the object-space area vectors
    area_local = np.linalg.norm(n, axis=1).sum()
    if not area_local > 0.0:  # no area even in object space: not the transform's doing
        return
    # the area vectors map by the cofactor matrix det(M)·M^-T, computed without inverting
    cof = np.cross(m[:, [1, 2, 0]].T, m[:, [2, 0, 1]].T)
    area_world = np.linalg.norm(n @ cof, axis=1).sum()
    if not area_world > 1e-6 * stretch[0] ** 2 * area_local:
        scale = ", ".join(f"{x:g}" for x in np.linalg.norm(m, axis=0))
        raise BakeError(
            f"'{name}' at frame {frame}: its object scale ({scale}) collapses the cloth to no area; "
            "give the object a non-zero scale on every axis the cloth spans (check its scale animation)",
            object=name, frame=frame,
        )
