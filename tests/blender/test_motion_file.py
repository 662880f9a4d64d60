"""Motion from PC2/MDD files: a cloth exported from another tool bakes without evaluating
the scene, and gives the same stain as the scene it came from."""

import bpy
import numpy as np
import pytest
from conftest import make_active

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
    motion = flag_motion(scene, flag)
    assert bpy.ops.madder.bake() == {"FINISHED"}
    from_scene = last_density(flag)
    # without its cloth modifier the scene no longer moves: only the file can
    flag.modifiers.remove(next(m for m in flag.modifiers if m.type == "CLOTH"))
    return scene, flag, motion, from_scene


def test_pc2_and_mdd_motion_bake_like_the_scene(flag_and_motion, tmp_path):
    scene, flag, motion, from_scene = flag_and_motion
    madder.write_pc2(str(tmp_path / "flag.pc2"), motion, start=float(scene.frame_start), rate=1.0)
    madder.write_mdd(str(tmp_path / "flag.mdd"), motion, np.arange(len(motion), dtype=np.float32) / 24.0)
    for name in ("flag.pc2", "flag.mdd"):
        flag.madder.motion_file = str(tmp_path / name)
        assert bpy.ops.madder.bake() == {"FINISHED"}
        np.testing.assert_allclose(last_density(flag), from_scene, atol=2e-6 * from_scene.max(), err_msg=name)
    # and the still scene alone gives a different stain (the file really drove the motion)
    flag.madder.motion_file = ""
    assert bpy.ops.madder.bake() == {"FINISHED"}
    assert np.abs(last_density(flag) - from_scene).max() > 1e-3 * from_scene.max()


def test_half_sampled_pc2_is_interpolated(flag_and_motion, tmp_path):
    scene, flag, motion, _ = flag_and_motion
    scene.frame_end = scene.frame_start + 2 * (len(motion[::2]) - 1)

    def bake_with(path):
        flag.madder.motion_file = path
        assert bpy.ops.madder.bake() == {"FINISHED"}
        return last_density(flag).astype(np.float64)

    still = bake_with("")  # no cloth any more: the flag hangs still
    madder.write_pc2(str(tmp_path / "full.pc2"), motion, start=float(scene.frame_start), rate=1.0)
    full = bake_with(str(tmp_path / "full.pc2"))
    # every other frame only, rate 2: the even frames are interpolated
    madder.write_pc2(str(tmp_path / "half.pc2"), motion[::2], start=float(scene.frame_start), rate=2.0)
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
    path.write_bytes(data[: len(data) - 100])  # the last frame is incomplete
    flag.madder.motion_file = str(path)
    with pytest.raises(RuntimeError) as e:
        bpy.ops.madder.bake()
    assert "cut.pc2" in str(e.value) and "frame" in str(e.value)
    madder.write_pc2(str(path), motion[:, :10], start=float(scene.frame_start))
    with pytest.raises(RuntimeError, match="10 points"):
        bpy.ops.madder.bake()
    madder.write_pc2(str(path), motion[:20], start=float(scene.frame_start))
    with pytest.raises(RuntimeError, match="frame 21 is outside"):
        bpy.ops.madder.bake()
    assert open(bpy.path.abspath(flag.madder.cache_file), "rb").read() == before
