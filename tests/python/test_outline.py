"""`madder.Outline` and `madder.sharpen_outline` (core `texture::outline`, whose
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
    with pytest.raises(madder.ParameterError, match="with channel 3 in it"):
        madder.sharpen_outline(fields, wet=np.zeros((4, 4, 3), np.float32), excess=3)
    with pytest.raises(madder.ParameterError, match="stain must be a C-contiguous, writeable float32 array"):
        madder.sharpen_outline(fields, np.zeros((4, 4, 8), np.float32)[..., ::2])
    with pytest.raises(TypeError):
        madder.sharpen_outline(fields, np.zeros((4, 4, 4), np.float64))
