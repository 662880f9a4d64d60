"""A cache that is damaged, missing, moved or stale never shows a wrong stain: the frames
it still holds play, the others show the bare cloth, the panel says why (with the path it
looked at), an animation render stops at the first affected frame unless told to render
anyway, and Relocate Cache points the object at a moved file."""

import os
import shutil

import bpy
import numpy as np
import pytest
from conftest import make_active

import madder

FIELDS = ("solute", "wetness", "deposit")


def handlers(addon):
    import sys

    return sys.modules[addon + ".handlers"]


def baked_flag(last=48):
    scene = bpy.context.scene
    scene.frame_start, scene.frame_end = 1, last
    flag = make_active(bpy.data.objects["Flag"])
    flag.madder.enabled = True
    flag.madder.source_group = "stain_source"
    assert bpy.ops.madder.bake() == {"FINISHED"}
    return flag, bpy.path.abspath(flag.madder.cache_file)


def expected(path, frame):
    r = madder.CacheReader(path)
    return {f: r.read(frame, f) for f in FIELDS}


def shown(obj):
    """The stain attributes playback wrote, as the evaluated cloth shows them: wetness and
    deposit (N,), stain RGBA (N, 4)."""
    me = obj.evaluated_get(bpy.context.evaluated_depsgraph_get()).data
    n = len(me.vertices)
    out = {}
    for name, prop, width in (("madder_wetness", "value", 1), ("madder_deposit", "value", 1),
                              ("madder_stain", "color", 4)):
        a = np.empty(n * width, dtype=np.float32)
        me.attributes[name].data.foreach_get(prop, a)
        out[name] = a.reshape(n, width) if width > 1 else a
    return out


def assert_shows(obj, values):
    s = obj.madder
    got = shown(obj)
    np.testing.assert_allclose(got["madder_wetness"], np.clip(values["wetness"] / s.saturation, 0, 1), atol=1e-6)
    np.testing.assert_allclose(got["madder_deposit"], np.clip(values["deposit"] / s.capacity, 0, 1), atol=1e-6)
    coverage = np.clip(values["solute"] / (s.concentration * s.saturation), 0, 1 + madder.DYE_EXCESS_RANGE)
    np.testing.assert_allclose(got["madder_stain"][:, 3], coverage, atol=1e-6)
    assert got["madder_wetness"].max() > 0.1  # a real stain, not the bare cloth


def assert_bare(obj):
    for name, values in shown(obj).items():
        assert not values.any(), name


def cut_inside(path, frame):
    """Cuts the cache in the middle of `frame`'s block (layout: io/cache.rs)."""
    r = madder.CacheReader(path)
    header = 8 + 5 * 4 + 8 + 32 * len(r.fields) + 4  # version 2: + the frame time (f64)
    block = 4 + 4 * len(r.fields) * r.n_vertices + 4
    data = open(path, "rb").read()
    assert len(data) == header + block * (r.last_frame - r.first_frame + 1)
    cut = header + block * (frame - r.first_frame) + block // 2
    with open(path, "wb") as f:
        f.write(data[:cut])


def test_a_truncated_cache_plays_the_frames_before_the_cut(open_fixture, addon):
    """Issue 10 item 4: a cut inside frame 12 keeps frames 1–11."""
    scene = open_fixture("flag.blend")
    flag, path = baked_flag()
    before = {f: expected(path, f) for f in (5, 11)}
    cut_inside(path, 12)
    for f in (5, 11):
        scene.frame_set(f)
        assert_shows(flag, before[f])
        assert handlers(addon).problem(flag, f) is None
        assert handlers(addon).damage(flag) == "Cache truncated at frame 12: frames 12–48 show no stain (bake again)"
    for f in (12, 30, 48, 60):  # at and after the cut (60 clamps to 48): no stale stain
        scene.frame_set(f)
        assert_bare(flag)
        why = handlers(addon).problem(flag, f)
        assert "truncated at frame 12" in why and path in why and "frames 1–11 play" in why
    scene.frame_set(11)  # and back: it plays again
    assert_shows(flag, before[11])


def test_a_corrupt_frame_shows_no_stain_and_names_the_frame(open_fixture, addon):
    scene = open_fixture("flag.blend")
    flag, path = baked_flag(12)
    r = madder.CacheReader(path)
    block = 4 + 4 * len(r.fields) * r.n_vertices + 4
    header = 8 + 5 * 4 + 8 + 32 * len(r.fields) + 4  # version 2: + the frame time (f64)
    good = expected(path, 9)
    data = bytearray(open(path, "rb").read())
    data[header + 9 * block + 100] ^= 0xFF  # inside frame 10
    open(path, "wb").write(bytes(data))
    scene.frame_set(10)
    assert_bare(flag)
    why = handlers(addon).problem(flag, 10)
    assert "frame 10" in why and "checksum" in why and path in why
    scene.frame_set(9)
    assert_shows(flag, good)


def test_an_animation_render_stops_at_a_corrupt_frame(open_fixture, tmp_path, capfd):
    """The render checks each frame's block before rendering it, not only the file."""
    scene = open_fixture("flag.blend")
    flag, path = baked_flag(12)
    r = madder.CacheReader(path)
    block = 4 + 4 * len(r.fields) * r.n_vertices + 4
    header = 8 + 5 * 4 + 8 + 32 * len(r.fields) + 4  # version 2: + the frame time (f64)
    data = bytearray(open(path, "rb").read())
    data[header + 9 * block + 100] ^= 0xFF  # inside frame 10
    open(path, "wb").write(bytes(data))
    out = str(tmp_path / "render")
    with pytest.raises(RuntimeError, match="Madder stopped the render"):
        render(scene, out, 8, 12)
    assert "render frame 10: 'Flag': Damaged cache" in capfd.readouterr().err
    assert sorted(os.listdir(out)) == ["f0008.png", "f0009.png"]


def test_a_deleted_cache_shows_no_stain_and_the_panel_says_where_it_looked(open_fixture, addon):
    scene = open_fixture("flag.blend")
    flag, path = baked_flag(12)
    scene.frame_set(10)
    assert_shows(flag, expected(path, 10))
    os.remove(path)
    scene.frame_set(11)
    assert_bare(flag)
    assert handlers(addon).problem(flag, 11) == f"Cache not found: {path}"


def test_save_as_into_another_folder_keeps_the_cache(open_fixture, tmp_path):
    scene = open_fixture("flag.blend")
    flag, path = baked_flag(12)
    values = expected(path, 10)
    other = tmp_path / "elsewhere" / "deeper"
    other.mkdir(parents=True)
    bpy.ops.wm.save_as_mainfile(filepath=str(other / "moved.blend"))
    # like an image's path, the relative cache path now leads from the new folder to the file
    assert flag.madder.cache_file == "//../../madder_cache/Flag.madder"
    assert os.path.samefile(bpy.path.abspath(flag.madder.cache_file), path)
    scene.frame_set(10)
    assert_shows(flag, values)
    bpy.ops.wm.open_mainfile(filepath=str(other / "moved.blend"))
    bpy.context.scene.frame_set(10)
    assert_shows(bpy.data.objects["Flag"], values)
    # Save a Copy leaves this session's path alone, and the copy gets its own
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / "copy.blend"), copy=True)
    assert bpy.data.objects["Flag"].madder.cache_file == "//../../madder_cache/Flag.madder"
    bpy.ops.wm.open_mainfile(filepath=str(tmp_path / "copy.blend"))
    assert bpy.data.objects["Flag"].madder.cache_file == "//madder_cache/Flag.madder"


def test_a_moved_blend_shows_no_stain_until_relocated(open_fixture, addon, tmp_path):
    scene = open_fixture("flag.blend")
    flag, path = baked_flag(12)
    scene.frame_set(10)
    values = expected(path, 10)
    bpy.ops.wm.save_mainfile()
    moved = tmp_path / "farm" / "shot.blend"
    moved.parent.mkdir()
    shutil.copyfile(bpy.data.filepath, moved)  # the .blend alone, as a file manager moves it
    bpy.ops.wm.open_mainfile(filepath=str(moved))
    flag = bpy.data.objects["Flag"]
    looked = str(tmp_path / "farm" / "madder_cache" / "Flag.madder")
    # on opening, the stain saved in the .blend is not shown
    assert_bare(flag)
    assert handlers(addon).problem(flag, 10) == f"Cache not found: {looked}"
    make_active(flag)
    wrong = tmp_path / "other.madder"
    w = madder.CacheWriter(str(wrong), 3, list(FIELDS), 1, 1)
    w.push_frame([np.zeros(3, dtype=np.float32)] * 3)
    w.finish()
    with pytest.raises(RuntimeError, match="holds 3 vertices"):
        bpy.ops.madder.relocate_cache(filepath=str(wrong))
    assert flag.madder.cache_file == "//madder_cache/Flag.madder"
    assert bpy.ops.madder.relocate_cache(filepath=path) == {"FINISHED"}
    assert flag.madder.cache_file == "//../madder_cache/Flag.madder"
    assert handlers(addon).problem(flag, 10) is None
    bpy.context.scene.frame_set(10)
    assert_shows(flag, values)


def test_a_mesh_edited_after_the_bake_shows_no_stain(open_fixture, addon):
    import bmesh

    scene = open_fixture("flag.blend")
    flag, path = baked_flag(12)
    scene.frame_set(10)
    values = expected(path, 10)
    # the same counts, other faces: one edge rotated in Edit Mode
    bpy.ops.object.mode_set(mode="EDIT")
    bm = bmesh.from_edit_mesh(flag.data)
    for e in bm.edges:
        e.select_set(False)
    next(e for e in bm.edges if len(e.link_faces) == 2).select_set(True)
    bmesh.update_edit_mesh(flag.data)
    assert bpy.ops.mesh.edge_rotate(use_ccw=False) == {"FINISHED"}
    bpy.ops.object.mode_set(mode="OBJECT")
    assert flag.madder.bake_topology.startswith(f"{len(flag.data.vertices)}:{len(flag.data.edges)}:")
    scene.frame_set(11)
    assert_bare(flag)
    why = handlers(addon).problem(flag, 11)
    assert "faces changed" in why and path in why
    # another vertex count (a vertex deleted, from a script)
    bm = bmesh.new()
    bm.from_mesh(flag.data)
    bm.verts.ensure_lookup_table()
    bmesh.ops.delete(bm, geom=[bm.verts[0]], context="VERTS")
    bm.to_mesh(flag.data)
    bm.free()
    scene.frame_set(12)
    assert_bare(flag)
    assert f"holds {len(values['wetness'])} vertices" in handlers(addon).problem(flag, 12)


def render(scene, out, first, last, movie=False):
    r = scene.render
    r.engine = "BLENDER_WORKBENCH"
    r.resolution_x, r.resolution_y, r.resolution_percentage = 32, 24, 100
    if movie and hasattr(r.image_settings, "media_type"):  # Blender 5.0
        r.image_settings.media_type = "VIDEO"
    elif movie:  # Blender 4.x
        r.image_settings.file_format = "FFMPEG"
    else:
        r.image_settings.file_format = "PNG"
    r.filepath = os.path.join(out, "f####")
    scene.frame_start, scene.frame_end = first, last
    bpy.ops.render.render(animation=True)


def test_an_animation_render_stops_at_the_first_frame_without_its_stain(open_fixture, tmp_path, capfd):
    scene = open_fixture("flag.blend")
    flag, path = baked_flag(6)
    cut_inside(path, 4)
    out = str(tmp_path / "render")
    with pytest.raises(RuntimeError, match="Madder stopped the render"):
        render(scene, out, 1, 6)
    err = capfd.readouterr().err
    assert "'Flag' has no valid stain at frames 4–6 (stops the render)" in err
    assert "render frame 4: 'Flag': Damaged cache" in err and "truncated at frame 4" in err
    assert sorted(os.listdir(out)) == ["f0001.png", "f0002.png", "f0003.png"]  # no wrong picture
    assert scene.render.filepath == os.path.join(out, "f####")  # the user's path is back

    # with Render Without Stain, every frame renders and each affected one is reported
    shutil.rmtree(out)
    flag.madder.render_without_cache = True
    render(scene, out, 1, 6)
    err = capfd.readouterr().err
    assert sorted(os.listdir(out)) == [f"f{f:04d}.png" for f in range(1, 7)]
    for f in (4, 5, 6):
        assert f"render frame {f}: 'Flag': Damaged cache" in err
    assert "render frame 3" not in err


def test_a_frame_change_evaluates_the_cloth_once_with_its_stain(open_fixture):
    """Issue 10 item 10: playback writes before the frame is evaluated, so that one
    evaluation already has the frame's stain. Written after it (frame_change_post), the
    mesh's tag made `frame_set` evaluate the cloth's modifier stack a second time: the
    evaluated mesh seen by later frame_change_post handlers was then replaced."""
    scene = open_fixture("flag.blend")
    flag, path = baked_flag(12)
    scene.frame_set(1)
    seen = {}

    def after_evaluation(scene, depsgraph):
        seen[scene.frame_current] = flag.evaluated_get(depsgraph).data.as_pointer()

    bpy.app.handlers.frame_change_post.append(after_evaluation)  # runs after Madder's
    try:
        for f in range(2, 12):
            scene.frame_set(f)
            evaluated = flag.evaluated_get(bpy.context.evaluated_depsgraph_get()).data
            assert evaluated.as_pointer() == seen[f], f"frame {f} was evaluated again"
            wet = np.empty(len(evaluated.vertices), dtype=np.float32)
            evaluated.attributes["madder_wetness"].data.foreach_get("value", wet)
            np.testing.assert_allclose(wet, np.clip(expected(path, f)["wetness"] / flag.madder.saturation, 0, 1),
                                       atol=1e-6, err_msg=f"frame {f}")
    finally:
        bpy.app.handlers.frame_change_post.remove(after_evaluation)


def test_a_movie_render_reports_the_frames_it_cannot_stop_at(open_fixture, tmp_path, capfd):
    """A movie's file is open from the first frame, so changing the output path cannot stop
    it: the affected frames are listed before it starts, reported as they render, and
    show the bare cloth (never the stale stain)."""
    scene = open_fixture("flag.blend")
    flag, path = baked_flag(6)
    cut_inside(path, 5)
    out = str(tmp_path / "movie")
    render(scene, out, 1, 6, movie=True)
    err = capfd.readouterr().err
    assert "'Flag' has no valid stain at frames 5–6 (renders without its stain)" in err
    assert "a movie cannot be stopped at a frame" in err
    for f in (5, 6):
        assert f"render frame {f}: 'Flag': Damaged cache" in err
    assert len(os.listdir(out)) == 1 and scene.render.filepath == os.path.join(out, "f####")
