"""`CacheReader.read_stain`: the playback attributes of one frame, computed in Rust into
the caller's buffers, against numpy's own normalization of the densities read back."""

import numpy as np
import pytest

import madder

N = 257


def cache(path, colors):
    fields = ["solute", "wetness", "deposit"] + (["color_r", "color_g", "color_b"] if colors else [])
    rng = np.random.default_rng(3)
    w = madder.CacheWriter(str(path), N, fields, 4, 3)
    frames = []
    for _ in range(3):
        values = [rng.uniform(-0.01, 0.3, N).astype(np.float32) for _ in fields]
        w.push_frame(values)
        frames.append(dict(zip(fields, values, strict=True)))
    w.finish()
    return frames


def expected(values, refs, color, split=False):
    """The attributes (rgba, wetness, deposit) and, with `split` (the images), the dye's
    excess: the dye amount solute / reference held in [0, 1 + DYE_EXCESS_RANGE], or in
    [0, 1] with the share above 1 over the range (within [0, 1]) apart."""
    dye = values["solute"] / np.float32(refs[0])
    cov = np.clip(dye, 0, 1 if split else 1 + madder.DYE_EXCESS_RANGE)
    if "color_r" in values:
        tint = np.stack([values[c] for c in ("color_r", "color_g", "color_b")], 1)
    else:
        tint = np.float32(color)
    # the colour premultiplied by the coverage (at most 1), the alpha the dye amount
    rgba = np.concatenate([np.minimum(cov, 1)[:, None] * tint, cov[:, None]], axis=1)
    wet = np.clip(values["wetness"] / np.float32(refs[1]), 0, 1)
    out = rgba.ravel(), wet, np.zeros(N, dtype=np.float32)  # deposit reference 0: no deposit
    return (*out, np.clip((dye - 1) / madder.DYE_EXCESS_RANGE, 0, 1)) if split else out


@pytest.mark.parametrize("colors", [False, True])
def test_read_stain_matches_numpy(tmp_path, colors):
    frames = cache(tmp_path / "c.madder", colors)
    r = madder.CacheReader(str(tmp_path / "c.madder"))
    rgba, wet, dep = np.full(4 * N, 9, np.float32), np.full(N, 9, np.float32), np.full(N, 9, np.float32)
    excess = np.full(N, 9, np.float32)
    # solute up to 0.3 over 0.05: dye amounts up to 6, above a saturated spot's 1
    refs, color = (0.05, 0.1, 0.0), (0.5, 0.25, 1.0)
    for k in range(3):
        r.read_stain(4 + k, refs, color, rgba, wet, dep)
        assert rgba[3::4].max() > 5.0
        for got, want in zip((rgba, wet, dep), expected(frames[k], refs, color), strict=True):
            np.testing.assert_allclose(got, want, rtol=1e-6, atol=0)
        r.read_stain(4 + k, refs, color, rgba, wet, dep, excess=excess)
        for got, want in zip((rgba, wet, dep, excess), expected(frames[k], refs, color, split=True), strict=True):
            np.testing.assert_allclose(got, want, rtol=1e-6, atol=1e-7)


def test_read_stain_checks_buffers_and_names_bad_frames(tmp_path):
    path = tmp_path / "c.madder"
    cache(path, False)
    r = madder.CacheReader(str(path))
    with pytest.raises(ValueError, match=f"for {N} vertices"):
        r.read_stain(4, (1, 1, 1), (1, 1, 1), np.zeros(N, np.float32), np.zeros(N, np.float32), np.zeros(N, np.float32))
    with pytest.raises(ValueError, match="contiguous"):
        r.read_stain(4, (1, 1, 1), (1, 1, 1), np.zeros(8 * N, np.float32)[::2], np.zeros(N, np.float32),
                     np.zeros(N, np.float32))
    with pytest.raises(ValueError, match=f"excess buffer of {N - 1} values for {N} vertices"):
        r.read_stain(4, (1, 1, 1), (1, 1, 1), np.zeros(4 * N, np.float32), np.zeros(N, np.float32),
                     np.zeros(N, np.float32), excess=np.zeros(N - 1, np.float32))
    data = path.read_bytes()
    path.write_bytes(data[:-10])
    r = madder.CacheReader(str(path))
    bufs = np.zeros(4 * N, np.float32), np.zeros(N, np.float32), np.zeros(N, np.float32)
    r.read_stain(5, (1, 1, 1), (1, 1, 1), *bufs)
    with pytest.raises(madder.CacheError, match="truncated at frame 6"):
        r.read_stain(6, (1, 1, 1), (1, 1, 1), *bufs)
