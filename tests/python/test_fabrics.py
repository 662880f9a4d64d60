"""Woven cloth through the `madder` API: fabric tensors, weft directions from UVs and the
anisotropic stepper, checked against exact results."""

import numpy as np
import pytest
from test_core import blob, grid

import madder


def corner_uv(faces, pos, angle=0.0):
    """UVs = the xy plane rotated by `angle` (so the weft is at −angle on the mesh)."""
    c, s = np.cos(angle), np.sin(angle)
    uv = pos[:, :2] @ np.array([[c, s], [-s, c]], dtype=np.float32)
    return np.ascontiguousarray(uv[faces].astype(np.float32))


def test_identity_tensors_equal_isotropic_diffusion():
    faces, pos = grid(20)
    t = madder.Topology(faces, len(pos))
    d = 0.02
    iso = madder.DiffusionStepper(t, pos, blob(pos), d)
    woven = madder.DiffusionStepper(
        t, pos, blob(pos), face_tensors=np.tile([d, 0.0, d], (len(faces), 1)), face_uv=corner_uv(faces, pos, 0.7)
    )
    for _ in range(5):
        iso.step(pos, 0.04)
        woven.step(pos, 0.04)
    np.testing.assert_allclose(woven.density, iso.density, rtol=1e-5, atol=1e-7)


def test_stepper_needs_rate_or_fabric_and_checks_tensors():
    faces, pos = grid(4)
    t = madder.Topology(faces, len(pos))
    with pytest.raises(madder.ParameterError, match="either rate"):
        madder.DiffusionStepper(t, pos, blob(pos))
    bad = np.tile([1.0, 2.0, 1.0], (len(faces), 1))  # s12² > s11 s22
    with pytest.raises(madder.ParameterError, match="face tensor 0"):
        madder.DiffusionStepper(t, pos, blob(pos), face_tensors=bad, face_uv=corner_uv(faces, pos))


def test_weft_directions_follow_the_uv_u_axis():
    faces, pos = grid(6)
    t = madder.Topology(faces, len(pos))
    w = madder.weft_directions(t, pos, corner_uv(faces, pos, np.radians(30)))
    along = [np.cos(np.radians(-30)), np.sin(np.radians(-30)), 0]
    np.testing.assert_allclose(w, np.tile(along, (len(faces), 1)), atol=1e-6)
    turned = madder.weft_directions(
        t, pos, corner_uv(faces, pos), np.full(len(faces), np.pi / 2, dtype=np.float32)
    )
    np.testing.assert_allclose(turned, np.tile([0, 1, 0], (len(faces), 1)), atol=1e-6)


def test_laminate_fabric_tensor_is_exact():
    # weft rows over gap rows: s11 = (100 + 1)/2 (parallel), s22 = harmonic mean of (10, 10)
    t = madder.fabric_tensor("CUSTOM", grid="FF\n..")
    np.testing.assert_allclose(t, [50.5, 0.0, 10.0], rtol=1e-10, atol=1e-12)
    assert madder.fabric_tile("CUSTOM", grid="FF\n..") == ["FF", ".."]
    ratio, angle = madder.ellipse(t)
    assert ratio == pytest.approx(5.05) and angle == pytest.approx(0.0, abs=1e-12)


def test_custom_grid_of_rectangles_matches_the_change_of_variables():
    # "FFWW/WWFF" with the seed's coefficients has cells F = [150, 0, 200] and
    # W = [350, 0, 200] (worked out by hand: each borders one cell of its own kind and one
    # of the other along x, the other kind above and below), so it is the 2×2
    # checkerboard of F and W stretched twice along x: each cell a 2×1 rectangle.
    # Substituting x = 2x' maps it to the square checkerboard of F⁻¹ a F⁻ᵀ, F = diag(2, 1)
    # (a11 / 4, a12 / 2, a22), whose effective tensor Ã gives A = [4 Ã11, 2 Ã12, Ã22].
    # The old reduction solved the rectangles as squares: 228.1 instead of 237.6 (−4 %).
    t = madder.fabric_tensor("CUSTOM", grid="FFWW\nWWFF")
    f, w = [150.0 / 4, 0.0, 200.0], [350.0 / 4, 0.0, 200.0]
    squeezed = np.array([[f, w], [w, f]])
    via = madder.homogenize(squeezed) * np.array([4.0, 2.0, 1.0])
    np.testing.assert_allclose(t, via, rtol=1e-4, atol=1e-9 * t[0])
    # A e_y = 200 e_y exactly (every cell passes the flux 200 e_y unchanged)
    assert t[2] == pytest.approx(200.0, rel=1e-12) and abs(t[1]) < 1e-9
    # the same cells given as tensors (row 0 at the bottom) agree
    cells = np.array([[[350.0, 0, 200], [350, 0, 200], [150, 0, 200], [150, 0, 200]],
                      [[150.0, 0, 200], [150, 0, 200], [350, 0, 200], [350, 0, 200]]])
    np.testing.assert_allclose(madder.homogenize(cells), t, rtol=1e-12, atol=1e-9)


def test_checkerboard_is_the_geometric_mean():
    k1, k2 = 1.0, 20.0
    cells = np.zeros((64, 64, 3))
    board = (np.add.outer(np.arange(64), np.arange(64)) % 2).astype(bool)
    cells[..., 0] = cells[..., 2] = np.where(board, k2, k1)
    t = madder.homogenize(cells)
    np.testing.assert_allclose(t[[0, 2]], np.sqrt(k1 * k2), rtol=0.01)
    assert abs(t[1]) < 1e-9


@pytest.mark.parametrize("weave", ["PLAIN", "TWILL21", "TWILL31", "SATIN5", "BASKET"])
def test_builtin_weaves_are_spd_and_inside_the_wiener_bounds(weave):
    t = madder.fabric_tensor(weave)
    assert t[0] > 0 and t[2] > 0 and t[0] * t[2] > t[1] ** 2
    rows = madder.fabric_tile(weave)
    assert len(rows) >= 2 and all(len(r) == len(rows[0]) for r in rows)


def test_bad_fabrics_name_the_cell():
    with pytest.raises(madder.MadderError, match="cell"):
        madder.fabric_tensor("CUSTOM", grid="FF\n..", coefficients=(1, 100, 500, 0.0, 50, 200))
    with pytest.raises(madder.MadderError):
        madder.fabric_tensor("CUSTOM", grid="")
    with pytest.raises(madder.MadderError, match="row 1.*col|col.*row 1|cell"):
        madder.homogenize(np.array([[[1.0, 0, 1.0]], [[1.0, 3.0, 1.0]]]))
