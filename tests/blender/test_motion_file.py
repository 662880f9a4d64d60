"""Motion from PC2/MDD files: a cloth exported from another tool bakes without evaluating
the scene, gives the same stain as the scene it came from, and reads every sample at the
scene frame where Blender's Mesh Cache modifier shows it."""

import re

import bpy
import numpy as np
import pytest
from conftest import make_active, plain_look

import madder


def flag_motion(scene, flag):
    """Object-space positions of every frame of the flag's cloth simulation, (F, N, 3)."""
    out = []
    for f in range(scene.frame_start, scene.frame_end + 1):
        scene.frame_set(f)
        me = flag.evaluated_get(bpy.context.evaluated_depsgraph_get()).data
        co = np.empty(3 * len(me.vertices), dtype=np.float32)
        me.vertices.foreach_get("co", co)
        out.append(co.reshape(-1, 3))
    return np.stack(out)


def last_density(obj):
    """Solute density (kg/m²) at the last frame."""
    r = madder.CacheReader(bpy.path.abspath(obj.madder.cache_file))
    return r.read(r.last_frame, "solute")


@pytest.fixture
def flag_and_motion(open_fixture, tmp_path):
    scene = open_fixture("flag.blend")
    flag = make_active(bpy.data.objects["Flag"])
    flag.madder.source_group = "stain_source"
    plain_look(flag.madder)  # the motion is what is tested, at the cloth's own resolution
    motion = flag_motion(scene, flag)
    assert bpy.ops.madder.bake() == {"FINISHED"}
    from_scene = last_density(flag)
    # without its cloth modifier the scene no longer moves: only the file can
    flag.modifiers.remove(next(m for m in flag.modifiers if m.type == "CLOTH"))
    return scene, flag, motion, from_scene


def mesh_cache(flag, path, fmt="PC2", frame_start=0.0, frame_scale=1.0):
    """The flag's Mesh Cache modifier reading `path` (Time Mode Frame, Play Mode Scene)."""
    m = flag.modifiers.get("Mesh Cache") or flag.modifiers.new("Mesh Cache", "MESH_CACHE")
    m.cache_format, m.filepath = fmt, str(path)
    m.frame_start, m.frame_scale = frame_start, frame_scale
    return m


def test_pc2_and_mdd_motion_bake_like_the_scene(flag_and_motion, tmp_path):
    scene, flag, motion, from_scene = flag_and_motion
    madder.write_pc2(str(tmp_path / "flag.pc2"), motion, start=float(scene.frame_start), rate=1.0)
    madder.write_mdd(str(tmp_path / "flag.mdd"), motion, np.arange(len(motion), dtype=np.float32) / 24.0)
    for name, fmt in (("flag.pc2", "PC2"), ("flag.mdd", "MDD")):
        # sample 0 is the scene's first frame: the modifier shows it there with Frame Start 1
        mesh_cache(flag, tmp_path / name, fmt, frame_start=float(scene.frame_start))
        flag.madder.motion_file = str(tmp_path / name)
        assert bpy.ops.madder.bake() == {"FINISHED"}
        np.testing.assert_allclose(last_density(flag), from_scene, atol=2e-6 * from_scene.max(), err_msg=name)
    # and the still scene alone gives a different stain (the file really drove the motion)
    flag.modifiers.remove(flag.modifiers["Mesh Cache"])
    flag.madder.motion_file = ""
    assert bpy.ops.madder.bake() == {"FINISHED"}
    assert np.abs(last_density(flag) - from_scene).max() > 1e-3 * from_scene.max()


def evaluated(scene, flag, frame):
    """Object-space positions the modifier stack shows at `frame`, (N, 3) float32."""
    scene.frame_set(frame)
    me = flag.evaluated_get(bpy.context.evaluated_depsgraph_get()).data
    co = np.empty(3 * len(me.vertices), dtype=np.float32)
    me.vertices.foreach_get("co", co)
    return co.reshape(-1, 3)


@pytest.mark.parametrize("header_start", [1.0, 5.0])
@pytest.mark.parametrize("frame_start, frame_scale", [(0.0, 1.0), (3.0, 1.0), (0.5, 0.5)])
def test_motion_file_reads_the_samples_the_mesh_cache_modifier_shows(
        flag_and_motion, tmp_path, addon, header_start, frame_start, frame_scale):
    """Whatever start frame the file's header gives, the bake reads at every scene frame
    the positions Blender's Mesh Cache modifier shows there (its Frame Start and Frame
    Scale included; held at the ends), and bakes the stain the modifier's cloth gives."""
    scene, flag, motion, _ = flag_and_motion
    path = tmp_path / "flag.pc2"
    madder.write_pc2(str(path), motion[:40], start=header_start, rate=1.0)
    mesh_cache(flag, path, frame_start=frame_start, frame_scale=frame_scale)
    if (header_start, frame_start, frame_scale) == (5.0, 3.0, 1.0):
        # the whole bake, once: the stain of the file is the stain of the modifier's cloth
        assert bpy.ops.madder.bake() == {"FINISHED"}
        from_modifier = last_density(flag)
        flag.madder.motion_file = str(path)
        assert bpy.ops.madder.bake() == {"FINISHED"}
        np.testing.assert_allclose(last_density(flag), from_modifier, atol=2e-6 * from_modifier.max())
    flag.madder.motion_file = str(path)
    bake = __import__(addon + ".bake", fromlist=["MotionFile"])
    reader = bake.MotionFile(madder, flag)
    for frame in range(scene.frame_start, scene.frame_end + 1):
        np.testing.assert_allclose(
            reader.local(frame), evaluated(scene, flag, frame), atol=1e-6, err_msg=f"frame {frame}"
        )


def test_half_sampled_pc2_is_interpolated(flag_and_motion, tmp_path):
    scene, flag, motion, _ = flag_and_motion
    scene.frame_end = scene.frame_start + 2 * (len(motion[::2]) - 1)

    def bake_with(path):
        flag.madder.motion_file = path
        assert bpy.ops.madder.bake() == {"FINISHED"}
        return last_density(flag).astype(np.float64)

    still = bake_with("")  # no cloth any more: the flag hangs still
    madder.write_pc2(str(tmp_path / "full.pc2"), motion, start=float(scene.frame_start), rate=1.0)
    mesh_cache(flag, tmp_path / "full.pc2", frame_start=float(scene.frame_start))
    full = bake_with(str(tmp_path / "full.pc2"))
    # every other frame only: the modifier's Frame Scale 0.5 reads sample (f − 1)/2 at
    # frame f, so the even frames are interpolated
    madder.write_pc2(str(tmp_path / "half.pc2"), motion[::2], start=float(scene.frame_start), rate=2.0)
    mesh_cache(flag, tmp_path / "half.pc2", frame_start=0.5 * scene.frame_start, frame_scale=0.5)
    half = bake_with(str(tmp_path / "half.pc2"))
    assert np.isfinite(half).all()
    # the interpolated motion is not the full one (its acceleration comes in jolts at the
    # samples, and the liquid feels it), but it is much closer to it than no motion
    err, off = np.abs(half - full).sum(), np.abs(still - full).sum()
    assert err < 0.5 * off, (err, off)


def test_bad_motion_files_are_named_and_keep_the_previous_bake(flag_and_motion, tmp_path):
    scene, flag, motion, _ = flag_and_motion
    before = open(bpy.path.abspath(flag.madder.cache_file), "rb").read()
    path = tmp_path / "cut.pc2"
    madder.write_pc2(str(path), motion, start=float(scene.frame_start))
    data = path.read_bytes()
    path.write_bytes(data[: len(data) - 100])  # the last sample is incomplete
    flag.madder.motion_file = str(path)
    with pytest.raises(RuntimeError) as e:
        bpy.ops.madder.bake()
    assert "cut.pc2" in str(e.value) and f"sample {len(motion) - 1} is incomplete" in str(e.value)
    madder.write_pc2(str(path), motion[:, :10], start=float(scene.frame_start))
    with pytest.raises(RuntimeError, match="10 points"):
        bpy.ops.madder.bake()
    madder.write_pc2(str(path), motion, start=float(scene.frame_start))
    with pytest.raises(RuntimeError, match="Time Mode 'Time'"):
        mesh_cache(flag, path).time_mode = "TIME"
        bpy.ops.madder.bake()
    mesh_cache(flag, path).time_mode = "FRAME"
    flag.modifiers["Mesh Cache"].forward_axis = "NEG_X"
    with pytest.raises(RuntimeError, match=r"changes the file's positions \(Forward/Up Axis\)"):
        bpy.ops.madder.bake()
    flag.modifiers.remove(flag.modifiers["Mesh Cache"])
    assert open(bpy.path.abspath(flag.madder.cache_file), "rb").read() == before


def test_nan_in_a_motion_file_names_one_frame(flag_and_motion, tmp_path):
    """The bake's message names the scene frame, and calls the file's own index a sample."""
    scene, flag, motion, _ = flag_and_motion
    path = tmp_path / "nan.pc2"
    madder.write_pc2(str(path), motion, start=1.0)  # the writer refuses NaN: patch the bytes
    data = bytearray(path.read_bytes())
    offset = 32 + (3 * motion.shape[1] + 7) * 12
    data[offset:offset + 12] = np.full(3, np.nan, "<f4").tobytes()
    path.write_bytes(bytes(data))
    mesh_cache(flag, path, frame_start=2.0)  # scene frame 5 shows sample 3
    flag.madder.motion_file = str(path)
    with pytest.raises(RuntimeError) as e:
        bpy.ops.madder.bake()
    msg = str(e.value)
    assert "sample 3, vertex 7" in msg, msg
    assert re.findall(r"frame (\d+)", msg) == ["5"], msg


def test_frames_past_the_file_hold_its_last_sample_with_a_warning(flag_and_motion, tmp_path, capsys):
    scene, flag, motion, _ = flag_and_motion
    path = tmp_path / "short.pc2"
    madder.write_pc2(str(path), motion[:20], start=float(scene.frame_start))
    flag.madder.motion_file = str(path)  # no modifier: sample f at frame f, 0–19
    assert bpy.ops.madder.bake() == {"FINISHED"}
    out = capsys.readouterr().out
    assert "29 frames (20…48) read past the 20 samples" in out, out
