"""madder.ftle and madder.ridges (seed ch. 5) through the binding: the callable path
against a numpy RK4 reference computed here, per-vertex arrays, deforming meshes, the
ridge dict, bad input named, and thread-count independence."""

import os
import subprocess
import sys

import numpy as np
import pytest

import madder


def grid(nx, ny, x=(0.0, 2.0), y=(0.0, 1.0)):
    """A regular grid, quads split along a–c, (F, 3) uint32 and (N, 3) float64."""
    j, i = np.meshgrid(np.arange(nx + 1), np.arange(ny + 1))
    xs = x[0] + (x[1] - x[0]) * j.ravel() / nx
    ys = y[0] + (y[1] - y[0]) * i.ravel() / ny
    pos = np.stack([xs, ys, np.zeros(j.size)], axis=1)
    a = (np.arange(ny)[:, None] * (nx + 1) + np.arange(nx)[None, :]).ravel()
    b, c, d = a + 1, a + nx + 2, a + nx + 1
    faces = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)]).astype(np.uint32)
    return faces, pos


def gyre_xy(t, x, y, eps=0.25, amp=0.1, omega=0.2 * np.pi):
    a = eps * np.sin(omega * t)
    b = 1.0 - 2.0 * a
    f = a * x * x + b * x
    df = 2.0 * a * x + b
    u = -np.pi * amp * np.sin(np.pi * f) * np.cos(np.pi * y)
    return u, np.pi * amp * np.cos(np.pi * f) * np.sin(np.pi * y) * df


def gyre(t, points):
    u, v = gyre_xy(t, points[:, 0], points[:, 1])
    return np.stack([u, v, np.zeros_like(u)], axis=1)


def rk4(t0, span, steps, x, y):
    h = span / steps
    for s in range(steps):
        t = t0 + s * h
        k1 = gyre_xy(t, x, y)
        k2 = gyre_xy(t + h / 2, x + h / 2 * k1[0], y + h / 2 * k1[1])
        k3 = gyre_xy(t + h / 2, x + h / 2 * k2[0], y + h / 2 * k2[1])
        k4 = gyre_xy(t + h, x + h * k3[0], y + h * k3[1])
        x = x + h / 6 * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0])
        y = y + h / 6 * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1])
    return x, y


def reference_ftle(pos, t0, span, steps, delta):
    """The classical grid method: RK4 from points at ± delta, central differences."""
    x, y = pos[:, 0], pos[:, 1]
    xp = rk4(t0, span, steps, x + delta, y)
    xm = rk4(t0, span, steps, x - delta, y)
    yp = rk4(t0, span, steps, x, y + delta)
    ym = rk4(t0, span, steps, x, y - delta)
    j = np.empty((len(x), 2, 2))
    j[:, 0, 0] = (xp[0] - xm[0]) / (2 * delta)
    j[:, 1, 0] = (xp[1] - xm[1]) / (2 * delta)
    j[:, 0, 1] = (yp[0] - ym[0]) / (2 * delta)
    j[:, 1, 1] = (yp[1] - ym[1]) / (2 * delta)
    c = np.einsum("nki,nkj->nij", j, j)
    lmax = np.linalg.eigvalsh(c)[:, -1]
    return np.log(lmax) / (2 * abs(span))


def test_double_gyre_callable_matches_a_numpy_rk4_reference():
    faces, pos = grid(200, 100)
    calls = []

    def velocity(t, points):
        calls.append(points.shape)
        return gyre(t, points)

    sigma = madder.ftle(faces, pos, velocity, 0.0, -10.0, steps=50)
    assert sigma.shape == (len(pos),) and sigma.dtype == np.float64
    # one call per RK4 stage, all particles at once
    assert calls == [(len(pos), 3)] * (4 * 50)
    ref = reference_ftle(pos, 0.0, -10.0, 200, 2.0 / 200)
    err = np.abs(sigma - ref) / np.ptp(ref)
    assert err.mean() < 1e-2 and np.percentile(err, 95) < 3e-2, (err.mean(), np.percentile(err, 95))


def test_linear_field_as_per_vertex_array_equals_the_callable():
    # a linear field is exact in the triangles, so the array path and the callable agree
    faces, pos = grid(20, 20, (-1, 1), (-1, 1))

    def saddle(t, p):
        return np.stack([0.8 * p[:, 0], -0.8 * p[:, 1], 0 * p[:, 0]], axis=1)

    a = madder.ftle(faces, pos, saddle, 0.0, 1.0, steps=20)
    b = madder.ftle(faces, pos, saddle(0.0, pos), 0.0, 1.0, steps=20)
    frames = np.stack([saddle(0.0, pos)] * 3)
    c = madder.ftle(faces, pos, frames, 0.0, 1.0, steps=20, times=np.array([0.0, 0.5, 1.0]))
    np.testing.assert_allclose(a, b, atol=1e-9)
    np.testing.assert_allclose(a, c, atol=1e-9)
    inner = np.max(np.abs(pos[:, :2]), axis=1) < 0.35
    np.testing.assert_allclose(a[inner], 0.8, atol=1e-3)


def test_a_translated_mesh_gives_the_same_ftle():
    # per-frame positions: the cloth moves rigidly, the field is relative to it
    faces, pos = grid(40, 20)
    times = np.linspace(0.0, 5.0, 6)
    frames = np.stack([pos + [0.3 * t, 0.1 * t, 0.05 * t] for t in times])

    def relative(t, points):
        shift = np.array([0.3 * t, 0.1 * t, 0.05 * t])
        return gyre(t, points - shift)

    still = madder.ftle(faces, pos, gyre, 0.0, 5.0, steps=25)
    moving = madder.ftle(faces, frames, relative, 0.0, 5.0, steps=25, times=times)
    np.testing.assert_allclose(moving, still, atol=1e-9)


def test_ridges_of_the_steady_gyre_lie_on_the_separatrix():
    faces, pos = grid(200, 100)
    # the steady gyre (ε = 0)
    sigma = madder.ftle(
        faces, pos, lambda t, p: np.stack([*gyre_xy(t, p[:, 0], p[:, 1], eps=0.0), 0 * p[:, 0]], 1), 0.0, -5.0, steps=50
    )
    r = madder.ridges(faces, pos, sigma)
    assert set(r) == {"triangles", "barycentric", "points", "edges"}
    p = len(r["points"])
    assert r["triangles"].shape == (p,) and r["barycentric"].shape == (p, 3) and r["edges"].shape[1] == 2
    # each point is where its triangle and barycentric coordinates say
    corners = pos[faces[r["triangles"]]]
    np.testing.assert_allclose(np.einsum("pk,pkd->pd", r["barycentric"], corners), r["points"], atol=1e-12)
    inner = (r["points"][:, 1] > 0.1) & (r["points"][:, 1] < 0.9)
    assert inner.sum() > 50 and np.abs(r["points"][inner, 0] - 1.0).max() < 0.01
    # no component under 20 edges: union–find over the edges
    parent = np.arange(p)

    def find(i):
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for a, b in r["edges"]:
        parent[find(a)] = find(b)
    roots, counts = np.unique([find(a) for a, _ in r["edges"]], return_counts=True)
    assert len(roots) >= 1 and counts.min() >= 20


def test_bad_input_is_named():
    faces, pos = grid(4, 4)
    with pytest.raises(madder.ParameterError, match="time span T") as e:
        madder.ftle(faces, pos, gyre, 0.0, 0.0)
    assert e.value.name == "T"

    def nan_at_7(t, p):
        out = gyre(t, p)
        out[np.all(p == pos[7], axis=1)] = np.nan
        return out

    with pytest.raises(madder.ParameterError, match="vertex 7") as e:
        madder.ftle(faces, pos, nan_at_7, 0.0, 1.0, steps=2)
    assert e.value.time == 0.0
    with pytest.raises(madder.ParameterError, match=r"velocity callable .*shape \(25, 2\), expected \(25, 3\)"):
        madder.ftle(faces, pos, lambda t, p: p[:, :2], 0.0, 1.0)
    with pytest.raises(madder.MeshError, match="no triangles"):
        madder.ftle(np.zeros((0, 3), np.uint32), pos, gyre, 0.0, 1.0)
    with pytest.raises(madder.ParameterError, match=r"velocity has shape \(2, 24, 3\)"):
        madder.ftle(faces, pos, np.zeros((2, 24, 3)), 0.0, 1.0, times=np.array([0.0, 1.0]))
    bad = np.zeros((2, 25, 3))
    bad[1, 13, 0] = np.nan
    with pytest.raises(madder.ParameterError, match="vertex 13 at time 1"):
        madder.ftle(faces, pos, bad, 0.0, 1.0, times=np.array([0.0, 1.0]))
    with pytest.raises(madder.ParameterError, match="outside the frames"):
        madder.ftle(faces, pos, np.zeros((2, 25, 3)), 0.0, 2.0, times=np.array([0.0, 1.0]))

    def raises(t, p):
        raise KeyError("the user's own bug")

    with pytest.raises(KeyError, match="own bug"):
        madder.ftle(faces, pos, raises, 0.0, 1.0)
    with pytest.raises(madder.ParameterError, match="field value at vertex 3"):
        field = np.zeros(25)
        field[3] = np.inf
        madder.ridges(faces, pos, field)


def test_results_do_not_depend_on_the_thread_count():
    here = os.path.dirname(__file__)
    code = (
        f"import madder, sys; sys.path.insert(0, {here!r}); from test_lcs import grid, gyre; "
        "f, p = grid(60, 30); s = madder.ftle(f, p, gyre, 0.0, -5.0, steps=25); "
        "r = madder.ridges(f, p, s); sys.stdout.write(s.tobytes().hex() + r['points'].tobytes().hex())"
    )

    def run(n):
        env = {**os.environ, "RAYON_NUM_THREADS": str(n)}
        return subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True).stdout

    out = [run(1), run(2)]
    assert out[0] == out[1] and len(out[0]) > 1000
