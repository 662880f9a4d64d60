"""madder.ftle(method="rk8"), the eighth-order scheme (seed §5.5.1), through the binding:
the double gyre against the numpy RK4 reference of test_lcs.py with a fifth of the
evaluations, the stage calls, the linear saddle in two steps (closed form σ = λ), and an
unknown method named."""

import numpy as np
import pytest
from test_lcs import grid, gyre, reference_ftle

import madder


def test_rk8_double_gyre_matches_the_reference_with_fewer_calls():
    faces, pos = grid(200, 100)
    calls = []

    def velocity(t, points):
        calls.append((t, points.shape))
        return gyre(t, points)

    sigma = madder.ftle(faces, pos, velocity, 0.0, -10.0, steps=8, method="rk8")
    # 12 stages per step, all particles at once, times within the span
    assert [c[1] for c in calls] == [(len(pos), 3)] * (12 * 8)
    assert all(-10.0 <= c[0] <= 0.0 for c in calls)
    ref = reference_ftle(pos, 0.0, -10.0, 200, 2.0 / 200)
    err = np.abs(sigma - ref) / np.ptp(ref)
    assert err.mean() < 1e-2 and np.percentile(err, 95) < 3e-2, (err.mean(), np.percentile(err, 95))
    # and it is RK4's FTLE at many steps up to the integration error of either
    rk4 = madder.ftle(faces, pos, gyre, 0.0, -10.0, steps=100)
    assert np.mean(np.abs(sigma - rk4)) / np.ptp(ref) < 1e-4


def test_rk8_linear_saddle_in_two_steps():
    faces, pos = grid(40, 40, (-1, 1), (-1, 1))

    def saddle(t, p):
        return np.stack([0.8 * p[:, 0], -0.8 * p[:, 1], 0 * p[:, 0]], axis=1)

    inner = np.max(np.abs(pos[:, :2]), axis=1) < 0.35
    s8 = madder.ftle(faces, pos, saddle, 0.0, 1.0, steps=2, method="rk8")
    s4 = madder.ftle(faces, pos, saddle, 0.0, 1.0, steps=2, method="rk4")
    assert np.abs(s8[inner] - 0.8).max() < 1e-8
    assert np.abs(s4[inner] - 0.8).max() > 1e-5


def test_unknown_method_is_named():
    faces, pos = grid(4, 4)
    with pytest.raises(madder.ParameterError, match='method must be "rk4" or "rk8", got "rk5"') as e:
        madder.ftle(faces, pos, gyre, 0.0, 1.0, steps=2, method="rk5")
    assert e.value.name == "method" and e.value.value == "rk5"
