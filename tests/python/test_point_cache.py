"""PC2 and MDD point caches through the Python API: round trips, the exact bytes (checked
against `struct`/numpy, independent of the Rust writer), and CacheErrors that name the file,
frame and vertex."""

import struct

import numpy as np
import pytest

import madder


def cloth(n_frames, n_points):
    """Deterministic (F, N, 3) float32 positions with varied signs and magnitudes."""
    k = np.arange(n_frames * n_points * 3, dtype=np.float64).reshape(n_frames, n_points, 3)
    return (np.sin(k * 0.37) * 10.0 ** (k % 5 - 2)).astype(np.float32)


def pc2_bytes(frames, start, rate):
    header = struct.pack("<12siiffi", b"POINTCACHE2\0", 1, frames.shape[1], start, rate, len(frames))
    return header + frames.astype("<f4").tobytes()


def mdd_bytes(frames, times):
    header = struct.pack(">2i", len(frames), frames.shape[1])
    return header + np.asarray(times, ">f4").tobytes() + frames.astype(">f4").tobytes()


def test_pc2_round_trip(tmp_path):
    f = cloth(4, 10)
    p = tmp_path / "cloth.pc2"
    madder.write_pc2(p, f, start=5.0, rate=0.5)
    assert p.read_bytes() == pc2_bytes(f, 5.0, 0.5)
    c = madder.PointCache(p)
    assert (c.format, c.n_points, c.n_frames, len(c)) == ("pc2", 10, 4, 4)
    assert (c.time_unit, c.start, c.rate, c.trailing_bytes) == ("frame", 5.0, 0.5, 0)
    assert c.frame_times.dtype == np.float64
    assert c.frame_times.tolist() == [5.0, 5.5, 6.0, 6.5]
    c.check_times()
    for k in reversed(range(4)):
        a = c.read_frame(k)
        assert a.dtype == np.float32 and a.shape == (10, 3) and a.flags.c_contiguous
        np.testing.assert_array_equal(a, f[k])


def test_mdd_round_trip(tmp_path):
    f = cloth(3, 7)
    times = np.arange(3) / 24.0
    p = tmp_path / "cloth.mdd"
    madder.write_mdd(p, f, times)
    assert p.read_bytes() == mdd_bytes(f, times)
    c = madder.PointCache(p)
    assert (c.format, c.n_points, c.n_frames) == ("mdd", 7, 3)
    assert (c.time_unit, c.start, c.rate) == ("second", None, None)
    np.testing.assert_array_equal(c.frame_times, times.astype(np.float32).astype(np.float64))
    for k in [2, 0, 1]:
        np.testing.assert_array_equal(c.read_frame(k), f[k])


def test_files_built_with_struct_read_back(tmp_path):
    f = cloth(2, 5)
    (tmp_path / "a.pc2").write_bytes(pc2_bytes(f, -1.0, 2.0))
    (tmp_path / "a.mdd").write_bytes(mdd_bytes(f, [0.0, 0.25]))
    for name in ["a.pc2", "a.mdd"]:
        c = madder.PointCache(tmp_path / name)
        np.testing.assert_array_equal(c.read_frame(1), f[1])
    assert madder.PointCache(tmp_path / "a.pc2").frame_times.tolist() == [-1.0, 1.0]


@pytest.mark.parametrize("ext", ["pc2", "mdd"])
def test_truncated_file_raises_cache_error_naming_the_frame(tmp_path, ext):
    f = cloth(5, 4)
    p = tmp_path / f"cut.{ext}"
    data = pc2_bytes(f, 1.0, 1.0) if ext == "pc2" else mdd_bytes(f, np.arange(5.0))
    body = 32 if ext == "pc2" else 8 + 4 * 5
    p.write_bytes(data[: body + 2 * 4 * 12 + 7])  # frames 0 and 1 whole, 7 bytes of frame 2
    with pytest.raises(madder.CacheError) as e:
        madder.PointCache(p)
    assert isinstance(e.value, OSError) and isinstance(e.value, madder.MadderError)
    assert "frame 2 is incomplete" in str(e.value) and f"cut.{ext}" in str(e.value)


def test_non_finite_position_names_frame_and_vertex(tmp_path):
    f = cloth(3, 4)
    f[1, 2, 0] = np.nan
    p = tmp_path / "nan.pc2"
    p.write_bytes(pc2_bytes(f, 1.0, 1.0))
    c = madder.PointCache(p)
    c.read_frame(0)
    with pytest.raises(madder.CacheError, match="frame 1, vertex 2"):
        c.read_frame(1)
    with pytest.raises(madder.CacheError, match="frame 1, vertex 2"):
        madder.write_pc2(tmp_path / "out.pc2", f)
    assert not (tmp_path / "out.pc2").exists()


def test_non_increasing_mdd_times_open_but_fail_check_times(tmp_path):
    f = cloth(3, 2)
    p = tmp_path / "back.mdd"
    p.write_bytes(mdd_bytes(f, [0.0, 0.5, 0.25]))
    c = madder.PointCache(p)
    assert c.frame_times.tolist() == [0.0, 0.5, 0.25]
    np.testing.assert_array_equal(c.read_frame(2), f[2])
    with pytest.raises(madder.CacheError, match="frame 2"):
        c.check_times()
    with pytest.raises(madder.CacheError, match="frame 2"):
        madder.write_mdd(tmp_path / "w.mdd", f, [0.0, 0.5, 0.25])


def test_bad_calls(tmp_path):
    f = cloth(2, 3)
    p = tmp_path / "a.pc2"
    madder.write_pc2(p, f)
    c = madder.PointCache(p)
    for k in [2, -1]:
        with pytest.raises(madder.CacheError, match=f"frame {k} is not in the file"):
            c.read_frame(k)
    with pytest.raises(madder.ParameterError):
        madder.write_pc2(p, f[:, :, :2].copy())
    with pytest.raises(madder.ParameterError, match="frames must be a float array"):
        madder.write_pc2(p, f.astype(str))
    with pytest.raises(madder.CacheError, match="1 times for 2 frames"):
        madder.write_mdd(tmp_path / "a.mdd", f, [0.0])
    with pytest.raises(madder.CacheError, match="missing.pc2"):
        madder.PointCache(tmp_path / "missing.pc2")


def test_format_by_signature_name_or_argument(tmp_path):
    f = cloth(2, 3)
    p = tmp_path / "anim.bin"
    p.write_bytes(mdd_bytes(f, [0.0, 1.0]))
    with pytest.raises(madder.CacheError, match="unknown point cache format"):
        madder.PointCache(p)
    assert madder.PointCache(p, format="MDD").format == "mdd"
    with pytest.raises(madder.ParameterError):
        madder.PointCache(p, format="abc")
    p.write_bytes(pc2_bytes(f, 1.0, 1.0))
    assert madder.PointCache(p).format == "pc2"
