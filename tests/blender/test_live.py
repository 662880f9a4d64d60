"""Live preview (issue 16) in real Blender: the flag played forward with Live on gives a
bake's fields; jumps, scrubbing back, setting edits, the memory limit and Bake from
Preview."""

import os
import shutil
import sys

import bpy
import numpy as np
import pytest
from conftest import make_active, plain_look, shown

import madder

LAST = 8  # a short range: the flag's frames 1–8


def setup_flag(scene, last=LAST):
    scene.frame_end = last
    flag = make_active(bpy.data.objects["Flag"])
    flag.madder.enabled = True
    flag.madder.source_group = "stain_source"
    plain_look(flag.madder)  # Live against a bake of the same settings, not the look
    return flag


def preview_module(addon):
    return sys.modules[f"{addon}.preview"]


def baked_fields(obj, frames):
    reader = madder.CacheReader(bpy.path.abspath(obj.madder.cache_file))
    return reader, {f: [reader.read(f, name) for name in reader.fields] for f in frames}


def attributes(mesh):
    out = []
    for name, prop, width in (("madder_stain", "color", 4), ("madder_wetness", "value", 1),
                              ("madder_deposit", "value", 1)):
        a = np.empty(len(mesh.vertices) * width, dtype=np.float32)
        mesh.attributes[name].data.foreach_get(prop, a)
        out.append(a)
    return out


def baked_attributes(reader, frame, obj):
    """What playback of the bake writes at `frame`: the cache's own normalization (Rust)."""
    n = reader.n_vertices
    rgba, wet, dep = np.empty(4 * n, np.float32), np.empty(n, np.float32), np.empty(n, np.float32)
    reader.read_stain(frame, tuple(obj.madder.bake_references), tuple(obj.madder.stain_color), rgba, wet, dep)
    return [rgba, wet, dep]


def bake_copy(obj, tmp_path, name):
    """Bakes `obj` and keeps a copy of its cache (the next bake replaces the file)."""
    assert bpy.ops.madder.bake() == {"FINISHED"}
    copy = tmp_path / name
    shutil.copyfile(bpy.path.abspath(obj.madder.cache_file), copy)
    return copy


def play(scene, frames):
    for f in frames:
        scene.frame_set(f)


@pytest.mark.parametrize("clock", ["SCENE", "KEYED_FRAME_TIME"])
def test_frames_shown_in_order_give_a_bakes_fields(open_fixture, addon, tmp_path, clock):
    """Also with the Frame Time clock keyed from 1/24 s to 2 s at frame 5: the preview's
    frames carry each frame's own length (and the animated value is no setting change
    that restarts it)."""
    scene = open_fixture("flag.blend")
    flag = setup_flag(scene)
    if clock == "KEYED_FRAME_TIME":
        flag.madder.clock = "FRAME_TIME"
        for frame, seconds in ((4, 1 / 24), (5, 2.0)):
            flag.madder.frame_time = seconds
            flag.keyframe_insert("madder.frame_time", frame=frame)
    bake_copy(flag, tmp_path, "bake.madder")
    reader, baked = baked_fields(flag, range(1, LAST + 1))
    assert not np.array_equal(baked[2][0], baked[LAST][0])  # the stain moves over the range
    # (the keyed clock bakes frames of two lengths: the cache records no single one)
    assert (reader.frame_time is None) == (clock == "KEYED_FRAME_TIME")
    preview = preview_module(addon)
    flag.madder.live = True
    for f in range(1, LAST + 1):
        scene.frame_set(f)
        session = preview.session(flag)
        # finished: every frame up to the one before (the lookahead), the last one too
        done = f if f in (1, LAST) else f - 1
        assert session.store.frames() == list(range(1, done + 1))
        np.testing.assert_array_equal(session.store.get(done)[0], baked[done][0])
        for k in range(3):  # the same fields as the bake, bit for bit
            np.testing.assert_array_equal(session.store.get(done)[k], baked[done][k], err_msg=f"frame {done}")
        # shown: the newest finished frame, as playback of the bake shows it
        for got, want in zip(attributes(shown(flag)), baked_attributes(reader, done, flag), strict=True):
            np.testing.assert_allclose(got, want, rtol=0, atol=1e-7, err_msg=f"frame {f}")
    assert "8 frames held (1–8)" in preview.status(flag)
    session = preview.session(flag)
    scene.frame_set(1)  # looping back: a complete preview is kept and plays like the bake
    assert preview.session(flag) is session and len(session.store) == LAST
    for got, want in zip(attributes(shown(flag)), baked_attributes(reader, 1, flag), strict=True):
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-7)


def test_scrubbing_back_shows_held_frames_and_jumps_reset(open_fixture, addon, tmp_path):
    scene = open_fixture("flag.blend")
    flag = setup_flag(scene)
    bake_copy(flag, tmp_path, "bake.madder")
    reader, _ = baked_fields(flag, ())
    preview = preview_module(addon)
    flag.madder.live = True
    play(scene, range(1, 7))  # finished 1–5
    session = preview.session(flag)
    scene.frame_set(3)  # scrubbing back: frame 3 as simulated, nothing stepped or dropped
    assert preview.session(flag) is session and session.expected == 7
    for got, want in zip(attributes(shown(flag)), baked_attributes(reader, 3, flag), strict=True):
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-7)
    play(scene, (4, 5, 6, 7))  # forward again: 4–6 shown from memory, 7 steps (finishes 6)
    assert session.store.frames() == list(range(1, 7))
    for got, want in zip(attributes(shown(flag)), baked_attributes(reader, 6, flag), strict=True):
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-7)

    scene.frame_set(1)  # jumping back to the start: a new simulation
    fresh = preview.session(flag)
    assert fresh is not session and fresh.store.frames() == [1] and fresh.expected == 2
    scene.frame_set(5)  # a jump forward cannot be simulated: reset, no stain shown
    assert preview.session(flag) is None
    assert not any(a.any() for a in attributes(shown(flag)))

    play(scene, (1, 2, 3))
    assert preview.session(flag).store.frames() == [1, 2]
    flag.madder.amount *= 2.0  # an edited setting resets at the next frame change
    scene.frame_set(4)
    assert preview.session(flag) is None
    flag.madder.amount /= 2.0
    play(scene, (1, 2))
    bpy.ops.wm.save_mainfile()
    bpy.ops.wm.open_mainfile(filepath=bpy.data.filepath)  # a file load ends every session
    scene, flag = bpy.context.scene, bpy.data.objects["Flag"]
    assert flag.madder.live and preview.session(flag) is None
    play(scene, (1, 2))
    flag.madder.live = False  # off: the session ends, the bake plays again
    assert preview.session(flag) is None
    for got, want in zip(attributes(shown(flag)), baked_attributes(reader, 2, flag), strict=True):
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-7)


def read_all(path):
    r = madder.CacheReader(str(path))
    fields = {f: [r.read(f, name) for name in r.fields] for f in range(r.first_frame, r.last_frame + 1)}
    return r, fields


def test_bake_from_preview_writes_a_bakes_cache(open_fixture, addon, tmp_path):
    scene = open_fixture("flag.blend")
    flag = setup_flag(scene)
    bake_copy(flag, tmp_path, "bake.madder")
    ref, baked = read_all(tmp_path / "bake.madder")
    path = bpy.path.abspath(flag.madder.cache_file)
    os.remove(path)  # Bake from Preview must write it anew

    flag.madder.live = True
    play(scene, range(1, 6))  # a partial preview: frames 1–4 finished
    assert bpy.ops.madder.bake_from_preview() == {"FINISHED"}
    got, fields = read_all(path)
    assert (got.first_frame, got.last_frame, got.fields) == (1, 4, ref.fields)
    assert got.frame_time == ref.frame_time
    for f in range(1, 5):
        for a, b in zip(fields[f], baked[f], strict=True):
            np.testing.assert_array_equal(a, b, err_msg=f"frame {f}")
    assert not flag.madder.live  # the cache plays now
    scene.frame_set(3)
    for a, b in zip(attributes(shown(flag)), baked_attributes(got, 3, flag), strict=True):
        np.testing.assert_array_equal(a, b)

    flag.madder.live = True
    play(scene, range(1, LAST + 1))  # the whole range: the whole bake
    assert bpy.ops.madder.bake_from_preview() == {"FINISHED"}
    got, fields = read_all(path)
    assert (got.first_frame, got.last_frame) == (1, LAST)
    with open(path, "rb") as a, open(tmp_path / "bake.madder", "rb") as b:
        assert a.read() == b.read()  # the same file, byte for byte


def test_memory_limit_drops_the_oldest_frames(open_fixture, addon, tmp_path):
    last = 16
    scene = open_fixture("flag.blend")
    flag = setup_flag(scene, last)
    bake_copy(flag, tmp_path, "bake.madder")
    preview = preview_module(addon)
    path = bpy.path.abspath(flag.madder.cache_file)
    before = open(path, "rb").read()
    flag.madder.live_memory = 0.1  # MB
    frame_bytes = 3 * 4 * len(flag.data.vertices)  # solute, wetness, deposit as float32
    kept = int(0.1 * 2**20) // frame_bytes
    assert 1 < kept < last
    flag.madder.live = True
    play(scene, range(1, last + 1))
    store = preview.session(flag).store
    assert store.frames() == list(range(last - kept + 1, last + 1))
    assert store.nbytes == kept * frame_bytes <= 0.1 * 2**20
    assert f"{last - kept} dropped" in preview.status(flag)
    # scrubbed back past what is held: the oldest held state
    scene.frame_set(2)
    _, baked = read_all(tmp_path / "bake.madder")
    wet = attributes(shown(flag))[1]
    np.testing.assert_allclose(wet, np.clip(baked[last - kept + 1][1] / flag.madder.saturation, 0, 1), atol=1e-6)
    # Bake from Preview refuses (the preview no longer starts at the start frame), naming why
    with pytest.raises(RuntimeError, match=f"frames 1–{last - kept} of the preview were dropped by the Live Memory"):
        bpy.ops.madder.bake_from_preview()
    assert open(path, "rb").read() == before  # the previous cache is kept
    # raising the limit keeps what is held; lowering it drops more
    flag.madder.live_memory = 0.05
    assert len(store) == int(0.05 * 2**20) // frame_bytes


def test_live_with_a_moving_brush_and_bake_flow_gives_a_bakes_fields(addon, tmp_path):
    """Pours (a brush coming down, with its splash), colours and the flow fields: the
    sources are read from the frame change's depsgraph as the bake reads them."""
    bpy.ops.wm.read_homefile(use_empty=True)
    scene = bpy.context.scene
    scene.frame_start, scene.frame_end = 1, 10
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=30, y_subdivisions=30, size=2.0)
    cloth = bpy.context.object
    cloth.madder.enabled = True
    plain_look(cloth.madder)
    cloth.madder.cache_dir = str(tmp_path)
    cloth.madder.bake_flow = True
    bpy.ops.mesh.primitive_plane_add(size=0.3, location=(0.3, 0.0, 0.5))
    brush = bpy.context.object
    s = brush.madder_source
    s.is_source, s.amount, s.distance, s.color, s.splash_speed = True, 4.0, 0.06, (0.0, 0.2, 1.0), 0.5
    brush.keyframe_insert("location", frame=1)
    brush.location.z = 0.02
    brush.keyframe_insert("location", frame=6)
    make_active(cloth)
    bake_copy(cloth, tmp_path, "bake.madder")
    ref, baked = read_all(tmp_path / "bake.madder")
    assert len(ref.fields) == 12 and baked[10][0].max() > 0.0  # colours and flow; the brush poured
    preview = preview_module(addon)
    cloth.madder.live = True
    play(scene, range(1, 11))
    store = preview.session(cloth).store
    assert store.frames() == list(range(1, 11))
    for f in range(1, 11):
        for name, a, b in zip(ref.fields, store.get(f), baked[f], strict=True):
            np.testing.assert_array_equal(a, b, err_msg=f"frame {f} {name}")
