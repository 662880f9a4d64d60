"""The angle codec's motion files through the Python API (MotionEncoder / MotionCodec):
a round trip within the error the test measures itself against the input, the reader
reproducing the encoder's own reconstruction bit for bit, the .madm header checked with
`struct` (independent of the Rust reader), and errors that name the file and frame."""

import struct

import numpy as np
import pytest

import madder


def grid(nx, ny):
    f = []
    for j in range(ny - 1):
        for i in range(nx - 1):
            a = j * nx + i
            f += [[a, a + 1, a + nx + 1], [a, a + nx + 1, a + nx]]
    return np.array(f, np.uint32)


NX, NY = 21, 13
FACES = grid(NX, NY)
U, V = (a.ravel() for a in np.meshgrid(np.linspace(0, 2, NX), np.linspace(0, 1.2, NY)))


def frame(t):
    """A waving cloth (float64), moving and stretching a little."""
    z = 0.15 * np.sin(3 * U - 2 * t) * U / 2
    return np.stack([U - 0.05 * np.sin(3 * U - 2 * t) ** 2 * U / 2 + 0.1 * t, V + 0.02 * np.sin(t + U), z], 1)


def encode(path, frames, **kw):
    enc = madder.MotionEncoder(path, FACES, **kw)
    outs = [enc.add_frame(x) for x in frames]
    return outs, enc.finish()


@pytest.mark.parametrize("warm", ["tracked", "spectral"])
def test_round_trip_and_reader_reproduces_encoder(tmp_path, warm):
    path = tmp_path / "wave.madm"
    frames = [frame(0.15 * k) for k in range(6)]
    outs, stats = encode(path, frames, start=10.0, rate=0.5, bits=13, keyframe_interval=4, warm=warm)
    # the header's flags byte says which warm decoding the reader must run (2: tracked)
    assert path.read_bytes()[42] == (2 | 4 if warm == "tracked" else 0)
    r = madder.MotionCodec(path)
    assert (r.n_points, r.n_frames, len(r), r.format) == (NX * NY, 6, 6, "madder")
    assert (r.start, r.rate, r.bits) == (10.0, 0.5, (13, 13))
    np.testing.assert_array_equal(r.frame_times, 10.0 + 0.5 * np.arange(6))
    np.testing.assert_array_equal(r.faces, FACES)
    allpos = np.concatenate(frames)
    diag = np.linalg.norm(allpos.max(0) - allpos.min(0))
    errs = []
    for k in [0, 1, 2, 3, 4, 5, 2, 5]:
        y = r.read_frame(k)
        assert y.dtype == np.float32 and y.shape == (NX * NY, 3)
        np.testing.assert_array_equal(y, outs[k])
        errs.append(np.linalg.norm(y - frames[k], axis=1) / diag)
    err = np.concatenate(errs)
    # each angle within half a step π/2^13; the positions then within a few half steps
    assert err.max() < 4 * np.pi / 2**13, err.max()
    assert stats["max_error"] == pytest.approx(err.max(), rel=1e-6)
    assert stats["frames"] == 6 and stats["vertices"] == NX * NY
    assert stats["bytes"] == path.stat().st_size
    assert stats["bits_per_vertex_frame"] == pytest.approx(8 * stats["bytes"] / (6 * NX * NY))
    assert 0 < stats["rms_error"] < stats["max_error"]


def test_header_bytes(tmp_path):
    path = tmp_path / "h.madm"
    encode(path, [frame(0.0), frame(0.1)], start=3.0, rate=2.0, bits=9, corner_bits=11, corners="once")
    data = path.read_bytes()
    magic, version, n, f, frames, start, rate, bits, cbits, flags = struct.unpack_from("<8s4I2d3B", data)
    assert (magic, version, n, f, frames) == (b"MADDERMO", 1, NX * NY, len(FACES), 2)
    # flags: 1 corners once, 2 warm frames tracked (the default), 4 keyframes from the tree
    assert (start, rate, bits, cbits, flags) == (3.0, 2.0, 9, 11, 7)
    np.testing.assert_array_equal(np.frombuffer(data, "<u4", 3 * len(FACES), 48).reshape(-1, 3), FACES)


def test_float32_input_and_abort(tmp_path):
    path = tmp_path / "keep.madm"
    path.write_bytes(b"previous")
    enc = madder.MotionEncoder(path, FACES)
    enc.add_frame(frame(0.0).astype(np.float32))
    enc.abort()
    assert path.read_bytes() == b"previous"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["keep.madm"]
    with pytest.raises(madder.ParameterError, match="finished"):
        enc.add_frame(frame(0.0))


def test_bad_input_names_file_frame_vertex(tmp_path):
    path = tmp_path / "bad.madm"
    enc = madder.MotionEncoder(path, FACES)
    enc.add_frame(frame(0.0))
    x = frame(0.1)
    x[42, 2] = np.nan
    with pytest.raises(madder.MeshError) as e:
        enc.add_frame(x)
    assert (e.value.frame, e.value.vertex) == (1, 42)
    assert e.value.filename == str(path)
    assert "bad.madm: frame 1" in str(e.value)
    with pytest.raises(madder.MeshError) as e:
        enc.add_frame(frame(0.1)[:-1])
    assert (e.value.frame, e.value.expected, e.value.got) == (1, NX * NY, NX * NY - 1)
    with pytest.raises(madder.ParameterError):
        enc.add_frame(np.zeros((NX * NY, 2)))
    with pytest.raises(madder.ParameterError):
        madder.MotionEncoder(tmp_path / "o.madm", FACES, corners="sometimes")
    with pytest.raises(madder.ParameterError, match="warm"):
        madder.MotionEncoder(tmp_path / "o.madm", FACES, warm="lukewarm")
    with pytest.raises(madder.ParameterError, match="bits"):
        madder.MotionEncoder(tmp_path / "o.madm", FACES, bits=30)
    # three faces on one edge: the edge is named
    bad = np.vstack([FACES, [[0, 1, NX * NY - 1]]]).astype(np.uint32)
    with pytest.raises(madder.MeshError, match=r"edge \(0, 1\)") as e:
        madder.MotionEncoder(tmp_path / "m.madm", bad)
    assert e.value.filename == str(tmp_path / "m.madm")


def test_bad_files_name_file_and_frame(tmp_path):
    path = tmp_path / "ok.madm"
    encode(path, [frame(0.1 * k) for k in range(3)], bits=10)
    data = path.read_bytes()
    header = 48 + 12 * len(FACES)
    size0 = struct.unpack_from("<I", data, header)[0]
    frame1 = header + 8 + size0

    cut = tmp_path / "cut.madm"
    cut.write_bytes(data[: frame1 + 30])
    with pytest.raises(madder.CacheError, match="cut.madm: file is truncated at frame 1") as e:
        madder.MotionCodec(cut)
    assert e.value.frame == 1 and e.value.filename == str(cut)

    flip = bytearray(data)
    flip[frame1 + 8 + 50] ^= 0xFF
    bad = tmp_path / "flip.madm"
    bad.write_bytes(bytes(flip))
    r = madder.MotionCodec(bad)
    r.read_frame(0)
    with pytest.raises(madder.CacheError, match="flip.madm: frame 1 is corrupt") as e:
        r.read_frame(1)
    assert e.value.frame == 1

    ver = bytearray(data)
    ver[8] = 7
    (tmp_path / "v.madm").write_bytes(bytes(ver))
    with pytest.raises(madder.CacheError, match="version 7"):
        madder.MotionCodec(tmp_path / "v.madm")
    (tmp_path / "x.madm").write_bytes(b"POINTCACHE2\0" + bytes(60))
    with pytest.raises(madder.CacheError, match="not a Madder motion file"):
        madder.MotionCodec(tmp_path / "x.madm")
    with pytest.raises(madder.CacheNotFoundError):
        madder.MotionCodec(tmp_path / "missing.madm")
    r = madder.MotionCodec(path)
    with pytest.raises(madder.CacheError, match="frame 3 is not in the file") as e:
        r.read_frame(3)
    with pytest.raises(madder.CacheError, match="frame -1"):
        r.read_frame(-1)


def test_position_baseline_against_numpy():
    frames = np.array([frame(0.1 * k) for k in range(4)])
    lo, hi = frames.reshape(-1, 3).min(0), frames.reshape(-1, 3).max(0)
    step = (hi - lo).max() / (2**11 - 1)
    q = np.round((frames - lo) / step) * step + lo
    err = np.linalg.norm(q - frames, axis=2) / np.linalg.norm(hi - lo)
    raw = madder.position_baseline_stats(frames, 11, predict=False)
    assert raw["bits_per_vertex_frame"] == 33
    assert raw["max_error"] == pytest.approx(err.max(), rel=1e-9)
    assert raw["rms_error"] == pytest.approx(np.sqrt((err**2).mean()), rel=1e-9)
    pred = madder.position_baseline_stats(frames, 11)
    assert pred["max_error"] == raw["max_error"] and pred["bits_per_vertex_frame"] < 33
