"""UV textures through the Python API: `rasterize` (shapes, the layout Blender's
`Image.pixels` uses, padding, overlaps, threads), `write_exr`/`read_exr` (a linear field
through rasterize + write + read within half-float rounding, the EXR's row order checked
against numpy's own half rounding), and the typed exceptions naming what is wrong."""

import numpy as np
import pytest

import madder


def grid(n):
    """An n × n grid of the unit square: (N, 2) vertex UVs and (F, 3) uint32 faces."""
    ij = np.stack(np.meshgrid(np.arange(n + 1), np.arange(n + 1)), -1).reshape(-1, 2)
    uv = ij.astype(np.float64) / n
    idx = lambda i, j: i * (n + 1) + j  # noqa: E731 (row i along v, column j along u)
    faces = []
    for i in range(n):
        for j in range(n):
            a, b, c, d = idx(i, j), idx(i, j + 1), idx(i + 1, j + 1), idx(i + 1, j)
            faces += [[a, b, c], [a, c, d]]
    return uv, np.asarray(faces, np.uint32)


def centres(size):
    """(size, size, 2) texel centre UVs, row 0 at the bottom: [y, x] = ((x+½)/s, (y+½)/s)."""
    c = (np.arange(size) + 0.5) / size
    u, v = np.meshgrid(c, c)
    return np.stack([u, v], -1)


def linear(uv):
    """Three linear fields of UV, (…, 3)."""
    u, v = uv[..., 0], uv[..., 1]
    return np.stack([0.25 + 1.5 * u - 0.75 * v, 2.0 * v - 1.0, 3.0 - 2.5 * u], -1)


def test_shapes_and_the_layout_of_blender_pixels():
    uv, faces = grid(4)
    values = linear(uv).astype(np.float32)
    image, overlapping = madder.rasterize(faces, uv[faces].astype(np.float32), values, 32)
    assert image.shape == (32, 32, 3) and image.dtype == np.float32
    assert overlapping == 0
    # exact (to float rounding) at every texel centre, row 0 at the bottom
    np.testing.assert_allclose(image, linear(centres(32)), rtol=0, atol=2e-6)
    # one channel as a 1-D array gives a 2-D image
    image1, _ = madder.rasterize(faces, uv[faces], values[:, 1].copy(), 16)
    assert image1.shape == (16, 16)
    np.testing.assert_allclose(image1, linear(centres(16))[..., 1], rtol=0, atol=2e-6)
    # into a reused buffer: the same image, the same array back; a wrong one is refused
    out = np.full((32, 32, 3), 7.0, np.float32)
    again, n = madder.rasterize(faces, uv[faces], values, 32, out=out)
    assert again is out and n == 0 and np.array_equal(out, image)
    with pytest.raises(madder.ParameterError, match="shape"):
        madder.rasterize(faces, uv[faces], values, 32, out=np.zeros((32, 32, 4), np.float32))
    with pytest.raises(madder.ParameterError, match="C-contiguous"):
        madder.rasterize(faces, uv[faces], values, 32, out=np.zeros((32, 64, 3), np.float32)[:, ::2])
    # float64 and float32 UVs, any thread count: the same bits
    a, _ = madder.rasterize(faces, uv[faces], values, 50, threads=1)
    b, _ = madder.rasterize(faces, uv[faces].astype(np.float32), values, 50, threads=2)
    assert np.array_equal(a, b)


def test_padding_grows_islands_and_overlaps_are_counted():
    # one triangle in the middle of the image: unpadded texels outside are 0, padded ones
    # within 4 texels hold the (constant) value
    faces = np.array([[0, 1, 2]], np.uint32)
    tri = np.array([[[0.3, 0.3], [0.7, 0.3], [0.5, 0.7]]], np.float32)
    values = np.full((3, 2), 0.5, np.float32)
    bare, _ = madder.rasterize(faces, tri, values, 64, padding=0)
    padded, _ = madder.rasterize(faces, tri, values, 64)
    inside = bare[..., 0] > 0
    assert 0.07 * 64 * 64 < inside.sum() < 0.09 * 64 * 64  # area 0.08 of the unit square
    grown = padded[..., 0] > 0
    assert (grown & ~inside).sum() > 0
    assert np.all(padded[grown] == 0.5)
    # the 4-texel ring: a texel is filled iff some inside texel is within 4 (chessboard)
    ys, xs = np.nonzero(inside)
    near = np.zeros_like(inside)
    for dy in range(-4, 5):
        for dx in range(-4, 5):
            near[np.clip(ys + dy, 0, 63), np.clip(xs + dx, 0, 63)] = True
    assert np.array_equal(grown, near)
    # the same triangle twice: every covered texel overlaps
    both = np.concatenate([tri, tri[:, ::-1]])
    _, overlapping = madder.rasterize(np.repeat(faces, 2, 0), both, values, 64)
    assert overlapping == inside.sum()


def test_linear_field_round_trip_through_exr(tmp_path):
    uv, faces = grid(6)
    values = np.concatenate([linear(uv), np.ones((len(uv), 1))], 1).astype(np.float32)
    image, _ = madder.rasterize(faces, uv[faces], values, 128)
    path = tmp_path / "linear.exr"
    madder.write_exr(path, image)
    back = madder.read_exr(str(path))
    assert back.shape == (128, 128, 4) and back.dtype == np.float32
    # exactly numpy's half rounding of the image (same rows: bottom first)
    assert np.array_equal(back, image.astype(np.float16).astype(np.float32))
    # and the field itself within half precision (11 bits; values below 6)
    np.testing.assert_allclose(back[..., :3], linear(centres(128)), rtol=0, atol=6 * 2.0**-11)
    assert np.all(back[..., 3] == 1)
    # any channel names; a 2-D image is one channel
    madder.write_exr(tmp_path / "wet.exr", image[..., 0], channels=["Y"])
    wet = madder.read_exr(tmp_path / "wet.exr")
    assert wet.shape == (128, 128, 1)
    assert np.array_equal(wet[..., 0], image[..., 0].astype(np.float16).astype(np.float32))
    # a non-square image, not C-contiguous
    madder.write_exr(tmp_path / "tall.exr", image[:, 10:50], channels=("R", "G", "B", "A"))
    tall = madder.read_exr(tmp_path / "tall.exr")
    assert np.array_equal(tall, image[:, 10:50].astype(np.float16).astype(np.float32))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["linear.exr", "tall.exr", "wet.exr"]


def test_bad_input_raises_typed_errors_naming_what_is_wrong(tmp_path):
    uv, faces = grid(2)
    values = np.zeros((len(uv), 2), np.float32)
    fuv = uv[faces]
    for size in (0, 16385, -3):
        with pytest.raises(madder.ParameterError, match="out of range"):
            madder.rasterize(faces, fuv, values, size)
    with pytest.raises(madder.ParameterError) as e:
        madder.rasterize(faces, fuv, values, 0)
    assert (e.value.name, e.value.value) == ("size", 0)
    with pytest.raises(madder.ParameterError) as e:
        madder.rasterize(faces, fuv[:-1], values, 8)
    assert (e.value.name, e.value.expected, e.value.got) == ("uv", len(faces), len(faces) - 1)
    with pytest.raises(madder.ParameterError, match=r"shape \(T, 3, 2\)"):
        madder.rasterize(faces, fuv[:, :, :1], values, 8)
    with pytest.raises(madder.ParameterError, match="uv must be a float array"):
        madder.rasterize(faces, fuv.astype(np.int32), values, 8)
    bad = fuv.copy()
    bad[5, 1, 0] = np.nan
    with pytest.raises(madder.MeshError, match="face 5, corner 1") as e:
        madder.rasterize(faces, bad, values, 8)
    assert (e.value.face, e.value.corner) == (5, 1)
    with pytest.raises(madder.MeshError) as e:
        madder.rasterize(faces, fuv, values[:4], 8)
    assert e.value.face is not None and e.value.vertex >= 4 and e.value.n_vertices == 4
    assert isinstance(e.value, ValueError)

    with pytest.raises(madder.ParameterError) as e:
        madder.rasterize(faces, fuv, np.zeros((len(uv), 65), np.float32), 8)
    assert (e.value.name, e.value.value, e.value.max) == ("channels", 65, 64)

    image = np.zeros((4, 4, 3), np.float32)
    with pytest.raises(madder.ParameterError, match="3 channels"):
        madder.write_exr(tmp_path / "x.exr", image)
    with pytest.raises(madder.ParameterError) as e:
        madder.write_exr(tmp_path / "x.exr", image, channels=["R", "G", "G"])
    assert e.value.channel == "G"
    missing = tmp_path / "no" / "x.exr"
    with pytest.raises(madder.CacheNotFoundError) as e:
        madder.write_exr(missing, image, channels=["R", "G", "B"])
    assert e.value.filename == str(missing) and str(missing) in str(e.value)
    assert isinstance(e.value, FileNotFoundError)
    (tmp_path / "dir.exr").mkdir()
    with pytest.raises(madder.CacheError) as e:
        madder.write_exr(tmp_path / "dir.exr", image, channels=["R", "G", "B"])
    assert e.value.filename == str(tmp_path / "dir.exr")
    not_exr = tmp_path / "text.exr"
    not_exr.write_text("hello")
    with pytest.raises(madder.CacheError) as e:
        madder.read_exr(not_exr)
    assert e.value.filename == str(not_exr)
    with pytest.raises(madder.CacheNotFoundError):
        madder.read_exr(tmp_path / "nothing.exr")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["dir.exr", "text.exr"]
