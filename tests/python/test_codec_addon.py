"""The add-on's side of the motion codec, without Blender (`madder.addon.codec`): a
compression checks every frame and writes nothing until it finishes, a decompression
writes the PC2 of the decoded frames, and the timing puts sample k where the Mesh Cache
modifier of that PC2 shows it."""

import os

import numpy as np
import pytest

import madder
from madder.addon import codec, motion
from madder.addon.errors import MotionCodecError


def grid(n=9):
    """A square n×n grid of triangles in the XY plane: positions (N, 3), faces (F, 3)."""
    x, y = np.meshgrid(np.linspace(0.0, 1.0, n), np.linspace(0.0, 1.0, n))
    pos = np.stack([x.ravel(), y.ravel(), np.zeros(n * n)], axis=1)
    faces = []
    for i in range(n - 1):
        for j in range(n - 1):
            a, b, c, d = i * n + j, i * n + j + 1, (i + 1) * n + j, (i + 1) * n + j + 1
            faces += [(a, b, d), (a, d, c)]
    return pos, np.array(faces, dtype=np.uint32)


def bent(pos, t):
    """The grid rolled about the y axis by angle t (an isometry of the plane: a cloth's motion)."""
    if t == 0.0:
        return pos.astype(np.float32)
    r = 1.0 / t
    x = pos[:, 0]
    return np.stack([r * np.sin(x / r), pos[:, 1], r * (1.0 - np.cos(x / r))], axis=1).astype(np.float32)


def files(folder):
    return sorted(os.listdir(folder))


def test_compression_writes_the_motion_on_finish_only(tmp_path):
    pos, faces = grid()
    path = str(tmp_path / "out" / "cloth.madm")
    c = codec.Compression(madder, "Cloth", path, 3, 8, 12)
    assert (c.total, c.done, c.next_frame()) == (6, 0, 3)
    motion = [bent(pos, 0.3 * k) for k in range(6)]
    for k, co in enumerate(motion):
        assert c.add(3 + k, co, faces) == (k < 5)
        assert not os.path.exists(path)  # nothing at the path before finish()
    stats = c.finish()
    assert (stats["frames"], stats["vertices"]) == (6, len(pos))
    assert files(tmp_path / "out") == ["cloth.madm"]
    r = madder.MotionCodec(path)
    assert (r.start, r.rate, r.n_frames) == (3.0, 1.0, 6)
    np.testing.assert_array_equal(r.faces, faces)
    diagonal = np.linalg.norm(np.ptp(np.concatenate(motion), axis=0))
    err = max(np.linalg.norm(r.read_frame(k) - motion[k], axis=1).max() for k in range(6)) / diagonal
    assert err <= stats["max_error"] + 1e-6
    line = codec.summary(stats)
    assert line.startswith(f"6 frames × {len(pos)} vertices in ") and "bits/vertex/frame" in line


def test_compression_refuses_a_changing_mesh_and_keeps_the_earlier_file(tmp_path):
    pos, faces = grid()
    path = tmp_path / "cloth.madm"
    path.write_bytes(b"earlier")

    def started(n=2):
        c = codec.Compression(madder, "Cloth", str(path), 1, 10, 12)
        for k in range(n):
            c.add(1 + k, bent(pos, 0.1 * k), faces)
        return c

    cases = [
        (lambda c: c.add(3, bent(pos, 0.2)[:-1], faces), "'Cloth' has 80 vertices at frame 3 but 81 at frame 1"),
        (lambda c: c.add(3, bent(pos, 0.2), faces[::-1]), "'Cloth' changes its faces at frame 3"),
        (lambda c: c.add(3, bent(pos, 0.2), faces[:-2]), "'Cloth' changes its faces at frame 3 \\(126 triangles"),
        (lambda c: c.add(5, bent(pos, 0.2), faces), "frame 5 given where frame 3 was expected"),
    ]
    for act, message in cases:
        c = started()
        with pytest.raises(MotionCodecError, match=message) as e:
            act(c)
        assert e.value.object == "Cloth"
        assert path.read_bytes() == b"earlier" and files(tmp_path) == ["cloth.madm"], message
    c = started()
    co = bent(pos, 0.2)
    co[7, 1] = np.nan
    with pytest.raises(MotionCodecError, match="'Cloth': vertex 7 has a non-finite position at frame 3") as e:
        c.add(3, co, faces)
    assert (e.value.frame, e.value.vertex) == (3, 7)
    assert path.read_bytes() == b"earlier" and files(tmp_path) == ["cloth.madm"]
    # finishing early, or cancelling, writes nothing either
    c = started()
    with pytest.raises(MotionCodecError, match="before its last frame 10"):
        c.finish()
    started().abort()
    assert path.read_bytes() == b"earlier" and files(tmp_path) == ["cloth.madm"]
    with pytest.raises(MotionCodecError, match="'Cloth' has no faces at frame 1"):
        codec.Compression(madder, "Cloth", str(path), 1, 2, 12).add(1, pos, np.zeros((0, 3), np.uint32))
    with pytest.raises(MotionCodecError, match="must end in .madm"):
        codec.Compression(madder, "Cloth", str(tmp_path / "cloth.pc2"), 1, 2, 12)
    with pytest.raises(MotionCodecError, match="frame range 5-2 is empty"):
        codec.Compression(madder, "Cloth", str(path), 5, 2, 12)


def compressed(tmp_path, start=1.0, rate=1.0, n=5):
    pos, faces = grid()
    path = str(tmp_path / "cloth.madm")
    enc = madder.MotionEncoder(path, faces, start=start, rate=rate, bits=12)
    for k in range(n):
        enc.add_frame(bent(pos, 0.2 * k))
    enc.finish()
    return path


def test_decompression_writes_the_decoded_frames_as_pc2(tmp_path):
    path = compressed(tmp_path, start=-2.0, rate=0.5)
    target = str(tmp_path / "sub" / "cloth.pc2")
    d = codec.Decompression(madder, path, target, "Cloth")
    assert d.total == 5 and d.timing == (-4.0, 2.0)
    assert d.step() and not os.path.exists(target)
    assert d.finish() == target
    r, pc2 = madder.MotionCodec(path), madder.PointCache(target)
    for k in range(5):
        np.testing.assert_array_equal(pc2.read_frame(k), r.read_frame(k))
    np.testing.assert_array_equal(pc2.frame_times, -2.0 + 0.5 * np.arange(5))
    # a sample decodes to the same bits whatever was read before it (a bake that starts in
    # the middle of the file reads what the PC2 holds): in order, backwards, alone
    backwards = madder.MotionCodec(path)
    for k in (4, 2, 3, 0, 1):
        np.testing.assert_array_equal(backwards.read_frame(k), pc2.read_frame(k), err_msg=f"sample {k}")


def test_decompression_errors_name_the_file_and_keep_the_earlier_pc2(tmp_path):
    path = compressed(tmp_path)
    target = tmp_path / "cloth.pc2"
    target.write_bytes(b"earlier")
    data = open(path, "rb").read()
    open(path, "wb").write(data[:-20])
    with pytest.raises(MotionCodecError, match="'Cloth': .*cloth.madm") as e:
        codec.Decompression(madder, path, str(target), "Cloth").finish()
    assert e.value.object == "Cloth"
    assert target.read_bytes() == b"earlier" and files(tmp_path) == ["cloth.madm", "cloth.pc2"]
    with pytest.raises(MotionCodecError, match="cloth.pc2 is not a compressed motion file"):
        codec.Decompression(madder, str(target), str(tmp_path / "x.pc2"))
    with pytest.raises(MotionCodecError, match="must end in .pc2"):
        codec.Decompression(madder, path, str(tmp_path / "x.mdd"))
    assert codec.pc2_path("/a/b.madm") == "/a/b.pc2" and codec.is_compressed("/a/B.MADM")


def test_decompression_streams_and_an_abort_keeps_the_earlier_pc2(tmp_path):
    path = compressed(tmp_path, n=6)
    target = tmp_path / "cloth.pc2"
    target.write_bytes(b"earlier")
    d = codec.Decompression(madder, path, str(target), "Cloth")
    for _ in range(3):
        assert d.step()
    # three frames are on disk beside the target, none in memory; the target is untouched
    partial = [f for f in files(tmp_path) if f not in ("cloth.madm", "cloth.pc2")]
    assert len(partial) == 1 and os.path.getsize(tmp_path / partial[0]) == 32 + 3 * 12 * d.codec.n_points
    assert not hasattr(d, "frames") and target.read_bytes() == b"earlier"
    d.abort()
    assert target.read_bytes() == b"earlier" and files(tmp_path) == ["cloth.madm", "cloth.pc2"]
    # a failure to write names the target and leaves nothing behind
    blocked = tmp_path / "blocked"
    blocked.write_bytes(b"a file where the folder should be")
    with pytest.raises(MotionCodecError, match="'Cloth': .*blocked") as e:
        codec.Decompression(madder, path, str(blocked / "cloth.pc2"), "Cloth").finish()
    assert e.value.filename == str(blocked / "cloth.pc2")
    assert files(tmp_path) == ["blocked", "cloth.madm", "cloth.pc2"]


def test_pc2_writer_streams_what_write_pc2_writes(tmp_path):
    rng = np.random.default_rng(3)
    frames = rng.normal(size=(4, 7, 3)).astype(np.float32)
    madder.write_pc2(str(tmp_path / "whole.pc2"), frames, start=-2.0, rate=0.5)
    w = madder.Pc2Writer(str(tmp_path / "streamed.pc2"), 7, start=-2.0, rate=0.5)
    for f in frames:
        w.add_frame(f)
    assert w.n_frames == 4 and not (tmp_path / "streamed.pc2").exists()
    w.finish()
    assert (tmp_path / "streamed.pc2").read_bytes() == (tmp_path / "whole.pc2").read_bytes()
    w = madder.Pc2Writer(str(tmp_path / "bad.pc2"), 7)
    bad = frames[0].copy()
    bad[5, 1] = np.nan
    with pytest.raises(madder.CacheError, match="frame 0, vertex 5"):
        w.add_frame(bad)
    with pytest.raises(madder.ParameterError, match=r"\(N, 3\)"):
        w.add_frame(frames[0][:, :2].copy())
    w.abort()
    with pytest.raises(madder.CacheError, match="finished or aborted"):
        w.add_frame(frames[0])
    assert files(tmp_path) == ["streamed.pc2", "whole.pc2"]


def test_timing_is_the_mesh_cache_modifiers_in_float32():
    assert codec.modifier_timing(1.0, 1.0) == (1.0, 1.0)
    assert codec.modifier_timing(1.0, 2.0) == (0.5, 0.5)
    start, scale = codec.modifier_timing(1.0, 3.0)
    assert (start, scale) == (float(np.float32(1 / 3)), float(np.float32(1 / 3))) and start != 1 / 3
    # sample k at scene frame start + k·rate, read as the modifier reads it
    m = motion.MotionSamples(None, "Cloth", "x.madm", *codec.modifier_timing(-3.0, 0.5))
    assert [m.sample(f) for f in (-3, -2.5, -1, 2)] == [0.0, 1.0, 4.0, 10.0]
    for rate in (0.0, -1.0, float("nan")):
        with pytest.raises(MotionCodecError, match="x.madm: start 1.0 and rate"):
            codec.modifier_timing(1.0, rate, "x.madm")


class Counted:
    """A point cache whose sample k holds k everywhere, counting reads."""

    n_frames = 6

    def __init__(self):
        self.read = []

    def read_frame(self, k):
        self.read.append(k)
        return np.full((2, 3), float(k), dtype=np.float32)


def test_motion_samples_read_each_sample_once_in_order():
    """Between samples every frame needs two; the one the frame before read too is kept,
    so a .madm file decodes each sample once (warm-started from the one before)."""
    cache = Counted()
    m = motion.MotionSamples(cache, "Cloth", "x.madm", offset=0.5, scale=0.5)
    out = [m.local(f)[0, 0] for f in range(1, 12)]
    np.testing.assert_array_equal(out, 0.5 * np.arange(11))
    assert cache.read == [0, 1, 2, 3, 4, 5]
