"""The weave's fine scale in the image sequence (issue 13 part 4), through the binding and
the add-on's bpy-free half (`madder.addon.textures`), against independent references:

- the detail's 2-D spectrum (numpy FFT) peaks on the tile's reciprocal lattice, in UV,
  at the thread count and weft angle given, and the peak turns with the angle (a plain
  weave's strongest repeat is its thread, the lattice point (2, 0): its uptake repeats
  every thread, and only the corrector carries the tile's own period);
- Thread Count 0 (zero maps) is the plain image bit for bit; the same bits on 1 and 2
  threads;
- `weave_maps` from the faces' world/UV areas and the angle, and the over-one-thread-per-
  texel warning naming the object and fabric."""

import numpy as np
import pytest

import madder
from madder.addon import textures


def square(n):
    """`n × n` quads of the unit square (UV = position), two triangles each."""
    j, i = np.meshgrid(np.arange(n + 1), np.arange(n + 1))
    pos = np.stack([j.ravel() / n, i.ravel() / n], axis=1)
    idx = lambda a, b: a * (n + 1) + b  # noqa: E731
    faces = []
    for a in range(n):
        for b in range(n):
            faces += [[idx(a, b), idx(a, b + 1), idx(a + 1, b + 1)], [idx(a, b), idx(a + 1, b + 1), idx(a + 1, b)]]
    faces = np.array(faces, dtype=np.uint32)
    return faces, pos[faces].astype(np.float64), pos


def stain(pos):
    """A stain with a gradient everywhere: RGBA premultiplied, coverage 0.3–0.7."""
    c = 0.3 + 0.4 * pos[:, 0] * (0.5 + 0.5 * pos[:, 1])
    return np.stack([0.6 * c, 0.1 * c, 0.2 * c, c], axis=1).astype(np.float32)


SIZE = 256
THREADS_PER_UV = 32.0  # plain weave with gaps: 2 threads a tile, so 16 tiles per UV unit


def detail_image(angle, threads=None, k=THREADS_PER_UV, weave="PLAIN"):
    faces, uv, pos = square(8)
    values = stain(pos)
    corr = madder.fabric_corrector(weave, gaps=True)
    # the map as the add-on makes it, on a unit cloth: world area = UV area
    positions = np.c_[pos, np.zeros(len(pos))]
    n = len(faces)
    maps = textures.weave_maps(positions, faces.astype(np.int64), uv, np.full(n, k), np.full(n, angle))
    detail = madder.WeaveDetail([corr], np.zeros(len(faces), np.uint32), np.ascontiguousarray(maps), [True] * 4)
    plain, _ = madder.rasterize(faces, uv, values, SIZE, 0, threads=threads)
    woven, _ = madder.rasterize(faces, uv, values, SIZE, 0, threads=threads, weave=detail)
    return plain, woven, corr


def spectrum_peak(image):
    """The (fu, fv) frequency, cycles per UV unit, of the strongest non-constant component
    of `image` (rows = v)."""
    f = np.abs(np.fft.fft2(image - image.mean()))
    f[0, 0] = 0.0
    # real images: ±f are the same peak; take the one with fu > 0 (or fu = 0, fv > 0)
    iv, iu = np.unravel_index(np.argmax(f), f.shape)
    fu = iu if iu <= SIZE // 2 else iu - SIZE
    fv = iv if iv <= SIZE // 2 else iv - SIZE
    if fu < 0 or (fu == 0 and fv < 0):
        fu, fv = -fu, -fv
    return np.array([fu, fv], dtype=np.float64)


def nearest_lattice(peak, angle, period):
    """The nearest point of the reciprocal lattice of a square tile of `period` UV units
    whose axes are turned by `angle`: (m, n) and its distance in frequency bins."""
    c, s = np.cos(angle), np.sin(angle)
    weft, warp = np.array([c, s]) / period, np.array([-s, c]) / period
    best = None
    for m in range(-4, 5):
        for n in range(-4, 5):
            d = np.linalg.norm(peak - (m * weft + n * warp))
            if best is None or d < best[0]:
                best = (d, (m, n))
    return best


@pytest.mark.parametrize("weave", ["PLAIN", "TWILL21"])
@pytest.mark.parametrize("angle_deg", [0.0, 30.0])
def test_the_spectrum_peaks_on_the_tile_repeat_and_turns_with_the_weft(angle_deg, weave):
    plain, woven, corr = detail_image(np.radians(angle_deg), weave=weave)
    n_threads = {"PLAIN": 2, "TWILL21": 3}[weave]
    assert corr.threads == (n_threads,) * 2 and corr.cells == (2 * n_threads,) * 2
    period = corr.threads[0] / THREADS_PER_UV  # UV length of a tile: 1/16 (plain), 3/32 (twill)
    d = (woven - plain)[..., 3]  # the coverage channel's detail
    assert np.abs(d).max() > 0.05
    peak = spectrum_peak(d)
    dist, (m, n) = nearest_lattice(peak, np.radians(angle_deg), period)
    print(f"{weave} at {angle_deg}°: peak at {peak} cycles/UV, lattice point (m, n) = ({m}, {n}) of the "
          f"{1 / period:g}-per-UV tile, {dist:.2f} bins off")
    # the peak is a repeat of the tile (within the bin rounding), not the constant
    assert (m, n) != (0, 0) and dist <= 0.75
    # and only on the turned lattice: the unturned one misses it by bins
    if angle_deg:
        assert nearest_lattice(peak, 0.0, period)[0] > 2.0


def test_thread_count_zero_is_the_plain_image_bit_for_bit_and_threads_do_not_matter():
    plain, woven, _ = detail_image(0.4, k=0.0)
    assert np.array_equal(plain, woven)
    one = detail_image(0.4, threads=1)[1]
    two = detail_image(0.4, threads=2)[1]
    assert np.array_equal(one, two) and not np.array_equal(one, plain)


def test_weave_maps_use_the_faces_world_scale_and_weft_angle():
    # one triangle: UV legs 0.1, world legs 0.3 m → 3 m per UV unit
    positions = np.array([[0, 0, 0], [0.3, 0, 0], [0, 0.3, 0]], dtype=np.float64)
    faces = np.array([[0, 1, 2]])
    uv = np.array([[[0.2, 0.2], [0.3, 0.2], [0.2, 0.3]]])
    m = textures.weave_maps(positions, faces, uv, np.array([2000.0]), np.array([np.pi / 6]))
    k = 2000.0 * 3.0
    c, s = np.cos(np.pi / 6), np.sin(np.pi / 6)
    np.testing.assert_allclose(m[0], k * np.array([[c, s], [-s, c]]), rtol=1e-12)
    # a weft direction maps to threads along the weft only
    np.testing.assert_allclose(m[0] @ np.array([c, s]), [k, 0.0], atol=1e-9)
    # degenerate UVs: no detail
    flat = textures.weave_maps(positions, faces, np.zeros((1, 3, 2)), np.array([2000.0]), np.array([0.0]))
    assert not flat.any()


def test_more_than_one_thread_per_texel_is_a_warning_naming_object_and_fabric():
    maps = np.array([[[3000.0, 0], [0, 3000.0]], [[500.0, 0], [0, 500.0]]])
    msg = textures.thread_problem("Shirt", "Cotton", maps, 1024)
    assert msg is not None and "'Shirt'" in msg and "'Cotton'" in msg and "2.9 threads" in msg and "50%" in msg
    assert textures.thread_problem("Shirt", "Cotton", maps, 4096) is None
    # the unresolved face is left smooth (zero map), the other kept
    kept = textures.drop_unresolved(maps, 1024)
    assert not kept[0].any() and np.array_equal(kept[1], maps[1])


def test_prefiltered_texels_are_close_to_what_a_texel_sees():
    """At 0.8 cells a texel (a real thread count on a cloth-sized image) a point sample of
    the weave aliases; the prefiltered corrector's sample must be close to the texel's
    area mean, computed independently as the 8 × 8 block mean of the same stain rasterized
    8 times finer (10 texels a cell: resolved). Both measured on the detail alone."""
    coarse, fine, k = 128, 1024, 50.0  # 50 threads per UV unit: 100 cells, 0.78 a texel
    faces, uv, pos = square(8)
    values = stain(pos)
    positions = np.c_[pos, np.zeros(len(pos))]
    n = len(faces)
    maps = np.ascontiguousarray(textures.weave_maps(positions, faces.astype(np.int64), uv, np.full(n, k),
                                                    np.full(n, 0.3)))
    base = madder.fabric_corrector("PLAIN", gaps=True)
    sigma = textures.prefilter_cells(maps, base.cells[0] / base.threads[0], coarse)
    assert np.all(sigma == sigma[0]) and 0.25 < sigma[0] < 0.6, sigma[:3]
    filtered = madder.fabric_corrector("PLAIN", gaps=True, filter=float(sigma[0]))
    assert filtered.filter == sigma[0]

    def image(size, corr):
        d = madder.WeaveDetail([corr], np.zeros(n, np.uint32), maps, [True] * 4)
        plain, _ = madder.rasterize(faces, uv, values, size, 0)
        woven, _ = madder.rasterize(faces, uv, values, size, 0, weave=d)
        return (woven - plain)[..., 3]

    f = image(fine, base)
    truth = f.reshape(coarse, 8, coarse, 8).mean(axis=(1, 3))
    inner = (slice(2, -2), slice(2, -2))  # away from the square's border
    raw = image(coarse, base)
    pre = image(coarse, filtered)
    err_raw = np.sqrt(np.mean((raw - truth)[inner] ** 2))
    err_pre = np.sqrt(np.mean((pre - truth)[inner] ** 2))
    spread = np.sqrt(np.mean(truth[inner] ** 2))
    print(f"detail RMS {spread:.4f}; error against the texel mean: point {err_raw:.4f}, prefiltered {err_pre:.4f}")
    assert err_pre < 0.5 * err_raw
    assert err_pre < spread  # and not by flattening everything: the detail stays


def test_prefilter_widths_follow_the_texel_footprint():
    """`prefilter_cells`: half a texel's footprint in cells, two steps per octave, none on
    faces finer than 1/16 of a cell or without detail."""
    scale = np.array([0.0, 4.0, 40.0, 400.0, 1000.0])  # threads per UV unit
    maps = scale[:, None, None] * np.eye(2)
    s = textures.prefilter_cells(maps, 2.0, 100)
    want = 0.5 * scale / 100 * 2.0  # cells per texel / 2
    assert s[0] == 0.0 and s[1] == 0.0  # no map; 0.04 cells, under 1/16
    for got, w in zip(s[2:], want[2:], strict=True):
        assert abs(np.log2(got) - np.log2(w)) <= 0.25 + 1e-12, (got, w)
        assert abs(2 * np.log2(got) - round(2 * np.log2(got))) < 1e-12  # on the half-octave grid
