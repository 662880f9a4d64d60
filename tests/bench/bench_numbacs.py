"""Madder's FTLE against numbacs' (PyPI) on the double gyre, 401×201 grid, T = −10.

Run it with a Python that has numbacs installed and the madder wheel on the path, e.g.

    python -m venv /tmp/numbacs && /tmp/numbacs/bin/pip install numbacs   # needs gfortran
    PYTHONPATH=.venv/madder-wheel /tmp/numbacs/bin/python tests/bench/bench_numbacs.py

Times are warm (numbacs compiles on its first call). Accuracy of both is measured against
one reference: numbacs' flow map at rtol 1e-10 with central differences (the classical
grid FTLE), as |σ − σ_ref| over the reference's range (mean and 95th percentile).
Prints figures; asserts nothing.
"""

import time

import numpy as np
from numbacs.diagnostics import ftle_grid_2D
from numbacs.flows import get_predefined_flow
from numbacs.integration import flowmap_grid_2D

import madder

NX, NY, T0, T = 401, 201, 0.0, -10.0


def grid_mesh(x, y):
    """The grid as a triangle mesh: vertex (j, i) at (x[j], y[i]), row-major in y."""
    xx, yy = np.meshgrid(x, y)
    pos = np.stack([xx.ravel(), yy.ravel(), np.zeros(xx.size)], axis=1)
    nx, ny = len(x) - 1, len(y) - 1
    a = (np.arange(ny)[:, None] * (nx + 1) + np.arange(nx)[None, :]).ravel()
    b, c, d = a + 1, a + nx + 2, a + nx + 1
    faces = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)]).astype(np.uint32)
    return faces, pos


def gyre(t, p, amp=0.1, eps=0.25, omega=0.2 * np.pi):
    a = eps * np.sin(omega * t)
    b = 1.0 - 2.0 * a
    f = a * p[:, 0] ** 2 + b * p[:, 0]
    df = 2.0 * a * p[:, 0] + b
    u = -np.pi * amp * np.sin(np.pi * f) * np.cos(np.pi * p[:, 1])
    v = np.pi * amp * np.cos(np.pi * f) * np.sin(np.pi * p[:, 1]) * df
    return np.stack([u, v, np.zeros_like(u)], axis=1)


def error(s, ref):
    e = np.abs(s - ref) / np.ptp(ref)
    return f"mean {e.mean():.2e}, p95 {np.percentile(e, 95):.2e}"


def main():
    funcptr, params, _ = get_predefined_flow("double_gyre", int_direction=-1.0)
    x, y = np.linspace(0, 2, NX), np.linspace(0, 1, NY)
    dx, dy = x[1] - x[0], y[1] - y[0]

    def numbacs_ftle(rtol, atol):
        fm = flowmap_grid_2D(funcptr, T0, T, x, y, params, rtol=rtol, atol=atol)
        return ftle_grid_2D(fm, T, dx, dy)

    numbacs_ftle(1e-6, 1e-8)  # compile
    ref = numbacs_ftle(1e-10, 1e-12).T.ravel()  # (ny, nx) row-major, like the mesh
    for rtol, atol in [(1e-6, 1e-8), (1e-4, 1e-6)]:
        t = time.perf_counter()
        s = numbacs_ftle(rtol, atol).T.ravel()
        print(f"numbacs flow map + FTLE (dop853 rtol {rtol:g}): {time.perf_counter() - t:.2f} s; error {error(s, ref)}")

    faces, pos = grid_mesh(x, y)
    for steps in (50, 100):
        t = time.perf_counter()
        s = madder.ftle(faces, pos, gyre, T0, T, steps=steps)
        t_ftle = time.perf_counter() - t
        t = time.perf_counter()
        r = madder.ridges(faces, pos, s)
        t_r = time.perf_counter() - t
        print(
            f"madder flow map + FTLE (RK4, {steps} steps, numpy callable): {t_ftle:.2f} s; error {error(s, ref)};"
            f" ridges {t_r:.2f} s ({len(r['points'])} points)"
        )


if __name__ == "__main__":
    main()
