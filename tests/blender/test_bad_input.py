"""Bad input gets a clear error naming the object and frame; nothing crashes and no
previous bake is lost."""

import os

import bpy
import pytest
from conftest import make_active


def bake_error():
    with pytest.raises(RuntimeError) as e:
        bpy.ops.madder.bake()
    return str(e.value)


def baked_flag():
    flag = make_active(bpy.data.objects["Flag"])
    flag.madder.enabled = True
    flag.madder.source_group = "stain_source"
    assert bpy.ops.madder.bake() == {"FINISHED"}
    path = bpy.path.abspath(flag.madder.cache_file)
    return flag, path, open(path, "rb").read()


def test_object_that_is_not_a_mesh(open_fixture):
    open_fixture("flag.blend")
    cam = make_active(next(o for o in bpy.data.objects if o.type == "CAMERA"))
    msg = bake_error()
    assert cam.name in msg and "camera" in msg


def test_missing_source_group_keeps_the_previous_bake(open_fixture):
    open_fixture("flag.blend")
    flag, path, before = baked_flag()
    flag.madder.source_group = "no_such_group"
    msg = bake_error()
    assert "no_such_group" in msg and "Flag" in msg
    assert open(path, "rb").read() == before


def test_vertex_count_changing_between_frames_names_the_frame(open_fixture):
    scene = open_fixture("flag.blend")
    flag, path, before = baked_flag()
    build = flag.modifiers.new("Build", "BUILD")  # removes faces (and vertices) over time
    build.frame_start, build.frame_duration, build.use_reverse = 20, 10, True
    msg = bake_error()
    assert "Flag" in msg and "frame 21" in msg and "vertices" in msg
    assert open(path, "rb").read() == before
    assert scene.frame_current == 1  # the frame the user was on is restored
    assert not [f for f in os.listdir(os.path.dirname(path)) if ".tmp" in f]


def test_nan_positions_name_vertex_and_frame(open_fixture):
    open_fixture("disk.blend")
    disk = make_active(bpy.data.objects["Disk"])
    disk.madder.source_group = "stain_source"
    # a shape key whose value is animated to NaN at frame 5 poisons every vertex it moves
    disk.shape_key_add(name="Basis")
    key = disk.shape_key_add(name="Bad")
    key.data[7].co = (float("nan"), 0.0, 0.0)
    key.value = 0.0
    key.keyframe_insert("value", frame=4)
    key.value = 1.0
    key.keyframe_insert("value", frame=5)
    msg = bake_error()
    assert "Disk" in msg and "vertex 7" in msg and "frame 5" in msg


def test_unsaved_file_with_relative_cache_folder(addon):
    bpy.ops.wm.read_homefile(use_empty=True)
    bpy.ops.mesh.primitive_plane_add()
    plane = bpy.context.object
    plane.vertex_groups.new(name="wet")
    plane.madder.source_group = "wet"
    msg = bake_error()
    assert "save the .blend" in msg and plane.name in msg
