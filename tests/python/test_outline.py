"""`madder.Outline`, `madder.sharpen_outline` and `madder.lift_outline` (core `texture::outline`, whose
tests/outline.rs checks the drawing against exact fronts): the binding's arguments, its
errors naming them, and the images changed in place as the core changes them."""

import numpy as np
import pytest

import madder


def square(n=8):
    j, i = np.meshgrid(np.arange(n + 1), np.arange(n + 1))
    a = (i[:-1, :-1] * (n + 1) + j[:-1, :-1]).ravel()
    faces = np.concatenate([np.stack([a, a + 1, a + n + 2], 1), np.stack([a, a + n + 2, a + n + 1], 1)])
    uv = np.stack([j.ravel() / n, i.ravel() / n], 1)  # per vertex
    return faces.astype(np.uint32), uv[faces], uv


def test_a_front_is_cut_and_lifted_in_place_and_the_excess_only_cut():
    faces, uv, u = square()
    c = np.clip(0.5 + (0.5 - u[:, 0]) * 4, 0, 1).astype(np.float32)  # a ramp over two cells
    fields = madder.Outline(faces, len(c), rings=2).fields(c)
    assert fields.shape == (len(c), 2) and fields.dtype == np.float32
    img, _ = madder.rasterize(faces, uv, fields, 32, 2)
    stain, _ = madder.rasterize(faces, uv, np.c_[0.5 * c, 0.25 * c, c, c], 32, 2)
    wet, _ = madder.rasterize(faces, uv, np.c_[c, c, 0.5 * c], 32, 2)
    before_stain, before_wet = stain.copy(), wet.copy()
    madder.sharpen_outline(img, stain, wet)
    a = stain[..., 3]
    assert ((a > 0.1) & (a < 0.9)).sum(axis=1).max() <= 1  # one texel a row at most on the edge
    assert (a > before_stain[..., 3] + 1e-3).any() and (a < before_stain[..., 3] - 1e-3).any()
    np.testing.assert_allclose(stain[..., 0], 0.5 * a, atol=1e-6)  # the hue kept
    assert (wet[..., 2] <= before_wet[..., 2]).all() and (wet[..., :2] == before_wet[..., :2]).all()
    # the stain alone, or the wet image alone, changes as with both
    s2, w2 = before_stain.copy(), before_wet.copy()
    madder.sharpen_outline(img, stain=s2)
    madder.sharpen_outline(img, wet=w2, excess=2, threads=1)
    assert np.array_equal(s2, stain) and np.array_equal(w2, wet)


def test_left_to_the_shader_the_stain_is_lifted_and_the_distance_written_in_metres():
    faces, uv, u = square()
    c = np.clip(0.5 + (0.5 - u[:, 0]) * 4, 0, 1).astype(np.float32)  # a ramp over two cells about u = ½
    img, _ = madder.rasterize(faces, uv, madder.Outline(faces, len(c), rings=2).fields(c), 32, 2)
    stain, _ = madder.rasterize(faces, uv, np.c_[0.5 * c, 0.25 * c, c, c], 32, 2)
    wet, _ = madder.rasterize(faces, uv, np.c_[c, c, 0.5 * c, np.zeros_like(c)], 32, 2)
    before = stain.copy()
    texel = (0.2 / 32, 0.1 / 32)  # a 20 × 10 cm cloth on the unit square
    madder.lift_outline(img, texel, stain, wet)  # distance=3
    x = (np.arange(32) + 0.5) / 32
    exact = 0.2 * (0.5 - x)  # metres behind the front, along u
    near = np.abs(exact) < 2 * texel[0]
    np.testing.assert_allclose(wet[:, near, 3], np.broadcast_to(exact[near], (32, near.sum())), atol=0.2 * texel[0])
    assert np.abs(wet[..., 3]).max() <= madder.OUTLINE_DISTANCE_LIMIT
    a = stain[..., 3]
    assert np.all(a[before[..., 3] > 0] > 1 - 1e-5)  # every stained texel lifted to the plateau
    np.testing.assert_allclose(stain[..., 0], 0.5 * a, atol=1e-6)  # the hue kept
    assert np.array_equal(wet[..., :3], madder.rasterize(faces, uv, np.c_[c, c, 0.5 * c], 32, 2)[0])
    with pytest.raises(madder.ParameterError, match="texel must be two positive sizes"):
        madder.lift_outline(img, (0.0, 1.0), stain)
    with pytest.raises(madder.ParameterError, match=r"with channel 3 \(distance\) in it"):
        madder.lift_outline(img, texel, wet=np.zeros((32, 32, 3), np.float32))


def test_bad_arguments_are_errors_naming_them():
    faces, _, _ = square(2)
    with pytest.raises(madder.ParameterError, match="face 0 names vertex 0, but the mesh has 0 vertices"):
        madder.Outline(faces, 0)
    with pytest.raises(madder.ParameterError, match="faces must have shape"):
        madder.Outline(faces[:, :2], 9)
    outline = madder.Outline(faces, 9)
    assert outline.n_vertices == 9
    with pytest.raises(madder.ParameterError, match="coverage has 8 values for 9 vertices"):
        outline.fields(np.zeros(8, np.float32))
    assert not outline.fields(np.zeros(9, np.float32)).any()  # a clean cloth
    fields = np.zeros((4, 4, 2), np.float32)
    with pytest.raises(madder.ParameterError, match=r"fields must have shape \(size, size, 2\)"):
        madder.sharpen_outline(np.zeros((4, 4, 3), np.float32), np.zeros((4, 4, 4), np.float32))
    with pytest.raises(madder.ParameterError, match=r"stain must have shape \(4, 4, 4\)"):
        madder.sharpen_outline(fields, np.zeros((4, 4, 3), np.float32))
    with pytest.raises(madder.ParameterError, match=r"with channel 3 \(excess\) in it"):
        madder.sharpen_outline(fields, wet=np.zeros((4, 4, 3), np.float32), excess=3)
    with pytest.raises(madder.ParameterError, match="stain must be a C-contiguous, writeable float32 array"):
        madder.sharpen_outline(fields, np.zeros((4, 4, 8), np.float32)[..., ::2])
    with pytest.raises(TypeError):
        madder.sharpen_outline(fields, np.zeros((4, 4, 4), np.float64))
