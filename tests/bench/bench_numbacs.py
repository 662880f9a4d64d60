"""Madder's FTLE against numbacs' (PyPI) on the double gyre, 401×201 grid, T = −10.

Run it with a Python that has numbacs installed and the madder wheel on the path, e.g.

    apt-get install gfortran          # numbalsoda, a numbacs dependency, builds with it
    python -m venv /tmp/numbacs && /tmp/numbacs/bin/pip install numbacs packaging
    PYTHONPATH=.venv/madder-wheel /tmp/numbacs/bin/python tests/bench/bench_numbacs.py

Times are warm (numbacs compiles on its first call), best of `REPEAT`, both tools in the
same run, wall and CPU (all threads; on a shared machine the wall time follows the load).
Accuracy, over the interior vertices (numbacs' `ftle_grid_2D` leaves the border at 0),
as |σ − σ_ref| over the true FTLE's range (mean and 95th percentile), against:

- the true FTLE: numbacs' flow map at rtol 1e-10 on an auxiliary grid (offsets 1e-5);
- each tool's own gradient stencil applied to the exact flow map (numbacs at rtol 1e-10):
  this isolates the integration error. numbacs uses central differences; Madder's
  one-ring least squares over the six neighbours of the triangulated grid is recomputed
  here in numpy (independently of Madder).

Prints figures; asserts nothing.
"""

import os
import time

import numpy as np
from numbacs.diagnostics import C_eig_aux_2D, ftle_from_eig, ftle_grid_2D
from numbacs.flows import get_predefined_flow
from numbacs.integration import flowmap_aux_grid_2D, flowmap_grid_2D

import madder

NX, NY, T0, T = 401, 201, 0.0, -10.0
REPEAT = int(os.environ.get("BENCH_REPEAT", "3"))


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


def one_ring_ftle(fm, dx, dy):
    """Madder's stencil on a flow map `fm` (nx, ny, 2): least squares over the one-ring
    of the triangulated grid (neighbours ±x, ±y, ±(x + y)), interior vertices."""
    offsets = [(1, 0), (-1, 0), (0, 1), (0, -1), (1, 1), (-1, -1)]
    c = fm[1:-1, 1:-1]
    a = np.zeros(c.shape[:2] + (2, 2))
    b = np.zeros(c.shape[:2] + (2, 2))
    for di, dj in offsets:
        d = np.array([di * dx, dj * dy])
        delta = fm[1 + di : fm.shape[0] - 1 + di, 1 + dj : fm.shape[1] - 1 + dj] - c
        a += np.outer(d, d)
        b += delta[..., :, None] * d[None, None, None, :]
    g = b @ np.linalg.inv(a)  # rows: ∂φ_x, ∂φ_y; columns: x, y
    cg = np.swapaxes(g, -1, -2) @ g
    lmax = np.linalg.eigvalsh(cg)[..., -1]
    out = np.zeros(fm.shape[:2])
    out[1:-1, 1:-1] = np.log(lmax) / (2 * abs(T))
    return out


def best(f):
    """Best wall time of `REPEAT` calls, and its CPU time (all threads), as a string."""
    times, out = [], None
    for _ in range(REPEAT):
        t, c = time.perf_counter(), time.process_time()
        out = f()
        times.append((time.perf_counter() - t, time.process_time() - c))
    wall, cpu = min(times)
    return f"{wall:.3f} s (CPU {cpu:.2f} s)", out


def main():
    funcptr, params, _ = get_predefined_flow("double_gyre", int_direction=-1.0)
    x, y = np.linspace(0, 2, NX), np.linspace(0, 1, NY)
    dx, dy = x[1] - x[0], y[1] - y[0]

    def numbacs_ftle(rtol, atol):
        fm = flowmap_grid_2D(funcptr, T0, T, x, y, params, rtol=rtol, atol=atol)
        return ftle_grid_2D(fm, T, dx, dy)

    numbacs_ftle(1e-6, 1e-8)  # compile
    exact_fm = flowmap_grid_2D(funcptr, T0, T, x, y, params, rtol=1e-10, atol=1e-12)
    h_aux = 1e-5
    aux = flowmap_aux_grid_2D(
        funcptr, T0, T, x, y, params, h=h_aux, eig_main=False, rtol=1e-10, atol=1e-12
    )
    eigvals = C_eig_aux_2D(aux, dx, dy, h=h_aux, eig_main=False)[0]
    eigval_max = eigvals.max(axis=-1) if eigvals.ndim == 3 else eigvals
    true = ftle_from_eig(eigval_max, T)  # (nx, ny)
    inner = np.zeros((NX, NY), bool)
    inner[1:-1, 1:-1] = True
    scale = np.ptp(true[inner])
    ref_cd = ftle_grid_2D(exact_fm, T, dx, dy)
    ref_ring = one_ring_ftle(exact_fm, dx, dy)

    def err(s, ref):
        e = np.abs(s - ref)[inner] / scale
        return f"mean {e.mean():.1e} p95 {np.percentile(e, 95):.1e}"

    print(
        f"double gyre {NX}×{NY}, T = {T}, {os.cpu_count()} cores;"
        " errors over interior vertices / range of the true FTLE"
    )
    print(
        f"  stencils on the exact flow map vs true FTLE: central differences {err(ref_cd, true)};"
        f" Madder's one-ring {err(ref_ring, true)}"
    )
    for rtol, atol in [(1e-6, 1e-8), (1e-4, 1e-6), (1e-3, 1e-5)]:
        t, s = best(lambda rtol=rtol, atol=atol: numbacs_ftle(rtol, atol))
        print(
            f"  numbacs flow map + FTLE (dop853 rtol {rtol:g}): {t};"
            f" integration error {err(s, ref_cd)}; vs true {err(s, true)}"
        )

    faces, pos = grid_mesh(x, y)
    runs = [("rk4", 100), ("rk4", 50), ("rk4", 25), ("rk4", 21), ("rk4", 12)]
    runs += [("rk8", 8), ("rk8", 7), ("rk8", 6), ("rk8", 5)]
    for method, steps in runs:
        t, s = best(
            lambda steps=steps, method=method: madder.ftle(
                faces, pos, gyre, T0, T, steps=steps, method=method
            )
        )
        s = s.reshape(NY, NX).T
        t_r, r = best(lambda s=s: madder.ridges(faces, pos, np.ascontiguousarray(s.T).ravel()))
        print(
            f"  madder flow map + FTLE ({method}, {steps} steps, numpy callable): {t};"
            f" integration error {err(s, ref_ring)}; vs true {err(s, true)};"
            f" ridges {t_r} ({len(r['points'])} points)"
        )


if __name__ == "__main__":
    main()
