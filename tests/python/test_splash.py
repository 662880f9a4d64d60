"""The splash of a spill with a direction (addon/splash.py), without Blender: the mass is
the volume's, the tongue points along the throw, the drops land ahead of it, and the same
seed gives the same splash."""

import importlib.util
import math
from pathlib import Path

import numpy as np
import pytest

# the module imports nothing of the add-on: loaded from the source, no wheel needed
_SPEC = importlib.util.spec_from_file_location(
    "madder_splash", Path(__file__).resolve().parents[2] / "addon" / "splash.py"
)
splash = importlib.util.module_from_spec(_SPEC)
_SPEC.loader.exec_module(splash)


def grid(n=120, size=2.0, tilt=0.0):
    """A flat n×n grid of `size` metres, turned by `tilt` about the x axis (a cloth that is
    not in the XY plane), and its lumped (one third of each triangle) vertex areas."""
    t = np.linspace(-size / 2, size / 2, n + 1)
    u, v = np.meshgrid(t, t, indexing="ij")
    p = np.stack([u.ravel(), v.ravel(), np.zeros(u.size)], axis=1)
    ct, st = math.cos(tilt), math.sin(tilt)
    p = p @ np.array([[1, 0, 0], [0, ct, st], [0, -st, ct]])
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    faces = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    tri = 0.5 * np.linalg.norm(np.cross(p[faces[:, 1]] - p[faces[:, 0]], p[faces[:, 2]] - p[faces[:, 0]]), axis=1)
    areas = np.zeros(len(p))
    for k in range(3):
        np.add.at(areas, faces[:, k], tri / 3)
    return p, faces, areas


VOLUME = 125e-6  # a glass of wine, m³


def test_the_mass_is_the_volumes_exactly_and_the_densities_give_it_back():
    p, f, a = grid()
    for seed in range(4):
        s = splash.lay_out(p, f, a, (0.0, -0.3, 0.0), (0.0, 1.0, 0.0), VOLUME, seed=seed)
        assert (s.mass >= 0).all()
        assert abs(s.mass.sum() - 1000.0 * VOLUME) <= 1e-12 * 1000.0 * VOLUME
        sigma = splash.densities(s.mass, a)
        assert abs(sigma @ a - 0.125) <= 1e-12
        np.testing.assert_allclose(s.part_masses, (0.075, 0.0375, 0.0125), rtol=1e-12)


def test_the_pool_has_the_puddle_thickness_and_the_tongue_points_along_the_throw():
    p, f, a = grid()
    throw = np.array([math.cos(0.6), math.sin(0.6), 0.0])
    s = splash.lay_out(p, f, a, (-0.3, -0.2, 0.0), throw, VOLUME, seed=1, fractions=(0.6, 0.4, 0.0))
    # puddle thickness 2 l_c sin(45°) for water: l_c = sqrt(0.072 / (1000 g))
    lc = math.sqrt(0.072 / (1000 * 9.81))
    assert s.pool_thickness == pytest.approx(2 * lc * math.sin(math.pi / 4), rel=1e-12)
    assert s.pool_radius == pytest.approx(math.sqrt(0.6 * VOLUME / (math.pi * s.pool_thickness)), rel=1e-12)
    # the tongue reaches the pour's ballistic range 2H beyond the pool
    assert s.tongue_length == pytest.approx(s.pool_radius + 2 * 0.1, rel=1e-12)
    # the wet region's principal axis (mass-weighted covariance) is the throw, and the
    # mass lies ahead of the impact along it
    rel = p - s.impact
    w = s.mass / s.mass.sum()
    mean = w @ rel
    cov = (rel - mean).T @ ((rel - mean) * w[:, None])
    vals, vecs = np.linalg.eigh(cov[:2, :2])
    axis = vecs[:, -1]
    assert abs(axis @ throw[:2]) >= math.cos(math.radians(3))
    assert vals[-1] / vals[0] >= 2.0
    assert mean @ throw > 0.3 * s.tongue_length / 2
    # the farthest wet vertex along the throw is near the tongue's nose
    wet = s.mass > 1e-9 * s.mass.max()
    assert (rel[wet] @ throw).max() == pytest.approx(s.tongue_length, abs=2 * 2.0 / 120 + 0.01)


def test_the_drops_land_ahead_of_the_tongue_with_gamma_sizes():
    p, f, a = grid(n=200, size=3.0)
    throw = np.array([0.0, 1.0, 0.0])
    s = splash.lay_out(p, f, a, (0.0, -1.0, 0.0), throw, VOLUME, seed=3)
    assert len(s.drop_diameters) >= 30
    ahead = (s.drop_centres - s.nose) @ throw
    assert (ahead > 0).all()
    # within ±60° of the throw, and no farther than the largest ballistic range from the nose
    side = np.abs((s.drop_centres - s.nose)[:, 0])
    assert (side <= math.tan(math.radians(60)) * ahead + 1e-12).all()
    # volumes add up to the drops' share, mean diameter near 1.89 l_c (the last drop is
    # the remainder)
    vol = np.pi * s.drop_diameters**3 / 6
    assert vol.sum() == pytest.approx(0.1 * VOLUME, rel=1e-12)
    lc = math.sqrt(0.072 / (1000 * 9.81))
    assert np.mean(s.drop_diameters[:-1]) == pytest.approx(splash.RP_DROP * lc, rel=0.2)
    # the drops' mass lies ahead of the nose (but for the spread of a drop's bump)
    ahead_v = (p - s.nose) @ throw
    dm = s.drop_mass
    assert dm.sum() == pytest.approx(0.1 * 1000 * VOLUME, rel=1e-12)
    assert dm[ahead_v > -0.03].sum() >= 0.99 * dm.sum()


def test_the_same_seed_gives_the_same_splash_and_another_seed_another():
    p, f, a = grid()
    one = splash.lay_out(p, f, a, (0.1, 0.0, 0.0), (1.0, 1.0, 0.0), VOLUME, seed=7)
    two = splash.lay_out(p, f, a, (0.1, 0.0, 0.0), (1.0, 1.0, 0.0), VOLUME, seed=7)
    other = splash.lay_out(p, f, a, (0.1, 0.0, 0.0), (1.0, 1.0, 0.0), VOLUME, seed=8)
    assert np.array_equal(one.mass, two.mass)
    assert not np.array_equal(one.mass, other.mass)


def test_a_tilted_cloth_gets_the_throw_projected_on_it():
    p, f, a = grid(tilt=0.7)
    # a throw with a component along the normal: only its tangential part counts
    n = np.array([0.0, -math.sin(0.7), math.cos(0.7)])
    t = np.array([1.0, 0.0, 0.0])
    s = splash.lay_out(p, f, a, (0.0, 0.0, 0.0), t + 2.0 * n, VOLUME, seed=0)
    np.testing.assert_allclose(abs(s.direction @ t), 1.0, atol=1e-12)
    assert abs(s.mass.sum() - 0.125) <= 1e-12


def test_bad_input_is_named():
    p, f, a = grid(n=10)
    with pytest.raises(splash.SplashError, match="volume"):
        splash.lay_out(p, f, a, (0, 0, 0), (1, 0, 0), 0.0)
    with pytest.raises(splash.SplashError, match="normal"):
        splash.lay_out(p, f, a, (0, 0, 0), (0, 0, 1), VOLUME)
    with pytest.raises(splash.SplashError, match="fractions"):
        splash.lay_out(p, f, a, (0, 0, 0), (1, 0, 0), VOLUME, fractions=(0.5, 0.2, 0.2))
