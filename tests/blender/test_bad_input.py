"""Bad input gets a clear error naming the object and frame; nothing crashes and no
previous bake is lost."""

import os

import bpy
import numpy as np
import pytest
from conftest import make_active, plain_look, shown


def bake_error():
    with pytest.raises(RuntimeError) as e:
        bpy.ops.madder.bake()
    return str(e.value)


def baked_flag():
    flag = make_active(bpy.data.objects["Flag"])
    flag.madder.enabled = True
    flag.madder.source_group = "stain_source"
    plain_look(flag.madder)  # what is kept is any bake: no need for the fine look's cost
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


def poison_vertex_7_at_frame_5(obj):
    """A shape key that moves vertex 7 to NaN, its value animated from 0 (frame 4) to 1
    (frame 5)."""
    obj.shape_key_add(name="Basis")
    key = obj.shape_key_add(name="Bad")
    key.data[7].co = (float("nan"), 0.0, 0.0)
    key.value = 0.0
    key.keyframe_insert("value", frame=4)
    key.value = 1.0
    key.keyframe_insert("value", frame=5)


def test_nan_positions_name_vertex_and_frame(open_fixture):
    open_fixture("disk.blend")
    disk = make_active(bpy.data.objects["Disk"])
    disk.madder.source_group = "stain_source"
    poison_vertex_7_at_frame_5(disk)
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


def mesh_object(verts, faces, name="Odd"):
    """A mesh object from raw data, with a 'wet' group on every vertex."""
    bpy.ops.wm.read_homefile(use_empty=True)
    me = bpy.data.meshes.new(name)
    me.from_pydata(verts, [], faces)
    me.update()
    obj = bpy.data.objects.new(name, me)
    bpy.context.scene.collection.objects.link(obj)
    make_active(obj)
    obj.vertex_groups.new(name="wet").add([0], 1.0, "REPLACE")
    obj.madder.source_group = "wet"
    obj.madder.cache_dir = bpy.app.tempdir
    # nothing evaporates: the thin film that spreads farthest is kept, not dried away
    obj.madder.evaporation = 0.0
    bpy.context.scene.frame_start, bpy.context.scene.frame_end = 1, 5
    return obj


def baked_liquid(obj):
    """Liquid density (kg/m²) at the last frame."""
    import madder

    r = madder.CacheReader(bpy.path.abspath(obj.madder.cache_file))
    return r.read(r.last_frame, "wetness")


def test_non_manifold_fin_bakes_with_a_warning(capsys):
    # three quads share the edge 0–1
    verts = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (1, -1, 0), (0, -1, 0), (1, 0, 1), (0, 0, 1)]
    obj = mesh_object(verts, [(0, 1, 2, 3), (1, 0, 5, 4), (0, 1, 6, 7)])
    assert bpy.ops.madder.bake() == {"FINISHED"}
    assert "1 non-manifold edges" in capsys.readouterr().out
    d = baked_liquid(obj)
    assert np.isfinite(d).all() and (d[[2, 4, 6]] > 0).all()  # spread into all three sheets


def test_ngons_loose_vertices_and_zero_area_faces_bake_finite():
    # a hexagon n-gon, a quad collapsed to zero area, and a loose vertex (index 10)
    hexagon = [(np.cos(a), np.sin(a), 0.0) for a in np.linspace(0, 2 * np.pi, 7)[:-1]]
    collapsed = [(3, 0, 0), (4, 0, 0), (4, 0, 0), (3, 0, 0)]
    verts = hexagon + collapsed + [(9, 9, 9)]
    obj = mesh_object(verts, [tuple(range(6)), (6, 7, 8, 9), (0, 1, 6)])
    # the weights' own spread (a pool would gather around vertex 0, 1 m from the others,
    # and not reach them in 5 frames)
    obj.madder.spill_shape = "WEIGHTS"
    assert bpy.ops.madder.bake() == {"FINISHED"}
    d = baked_liquid(obj)
    assert np.isfinite(d).all()
    assert (d[1:6] > 0).all()  # spread across the n-gon's triangles
    assert d[10] == 0.0  # the loose vertex carries nothing
    assert "madder_stain" in shown(obj).attributes


def test_missing_cache_folder_is_created():
    obj = mesh_object([(0, 0, 0), (1, 0, 0), (0, 1, 0)], [(0, 1, 2)])
    obj.madder.cache_dir = os.path.join(bpy.app.tempdir, "does", "not", "exist", "yet")
    assert bpy.ops.madder.bake() == {"FINISHED"}
    assert os.path.isfile(bpy.path.abspath(obj.madder.cache_file))


def test_unwritable_cache_folder_names_it_and_keeps_the_previous_bake(tmp_path):
    obj = mesh_object([(0, 0, 0), (1, 0, 0), (0, 1, 0)], [(0, 1, 2)])
    obj.madder.cache_dir = str(tmp_path / "cache")
    assert bpy.ops.madder.bake() == {"FINISHED"}
    path = bpy.path.abspath(obj.madder.cache_file)
    before = open(path, "rb").read()
    # a folder that cannot be created: its parent is a regular file (works even as root,
    # which ignores permission bits)
    blocker = tmp_path / "blocker"
    blocker.write_text("not a folder")
    obj.madder.cache_dir = str(blocker / "cache")
    msg = bake_error()
    assert "cannot create the cache folder" in msg and str(blocker) in msg and obj.name in msg
    assert open(path, "rb").read() == before


@pytest.mark.skipif(os.geteuid() == 0, reason="root ignores folder permissions")
def test_read_only_cache_folder_names_it_and_keeps_the_previous_bake(tmp_path):
    obj = mesh_object([(0, 0, 0), (1, 0, 0), (0, 1, 0)], [(0, 1, 2)])
    folder = tmp_path / "cache"
    obj.madder.cache_dir = str(folder)
    assert bpy.ops.madder.bake() == {"FINISHED"}
    path = bpy.path.abspath(obj.madder.cache_file)
    before = open(path, "rb").read()
    folder.chmod(0o555)
    try:
        msg = bake_error()
    finally:
        folder.chmod(0o755)
    assert str(folder) in msg and obj.name in msg
    assert open(path, "rb").read() == before


def test_parameter_out_of_range_is_named_and_keeps_the_previous_bake(open_fixture):
    """The panel's limits keep parameters in range, but a script, a driver or an old file
    can bypass them (an ID property written directly): the simulator's own check names
    the parameter, and nothing is lost."""
    scene = open_fixture("flag.blend")
    flag, path, before = baked_flag()
    flag.madder["friction"] = -5.0  # bypasses the property's min, as a script could
    msg = bake_error()
    assert "Flag" in msg and "frame 1" in msg and "friction" in msg and "-5" in msg
    assert open(path, "rb").read() == before
    del flag.madder["friction"]
    flag.madder["evaporation_boundary"] = 0.5
    msg = bake_error()
    assert "evaporation boundary" in msg and "≥ 1" in msg
    assert open(path, "rb").read() == before
    del flag.madder["evaporation_boundary"]
    scene.gravity = (0.0, float("nan"), -9.81)  # the scene's gravity, e.g. from a driver
    msg = bake_error()
    assert "Flag" in msg and "gravity" in msg
    assert open(path, "rb").read() == before
    assert scene.frame_current == 1
    assert not [f for f in os.listdir(os.path.dirname(path)) if ".tmp" in f]


def test_bake_errors_carry_the_object_frame_and_vertex(open_fixture, addon):
    """A script driving `BakeJob` gets the object, frame and vertex as attributes of the
    BakeError, not only in its message (the NaN shape key of the test above)."""
    import sys

    bake = sys.modules[addon + ".bake"]
    scene = open_fixture("disk.blend")
    disk = make_active(bpy.data.objects["Disk"])
    disk.madder.source_group = "stain_source"
    poison_vertex_7_at_frame_5(disk)
    with pytest.raises(bake.BakeError) as e:
        bake.bake(scene, disk)
    assert (e.value.object, e.value.frame, e.value.vertex) == ("Disk", 5, 7)
    disk.madder.source_group = "no_such_group"
    with pytest.raises(bake.BakeError) as e:
        bake.BakeJob(scene, disk)
    assert (e.value.object, e.value.frame) == ("Disk", None)


def test_relocating_to_a_missing_file_names_it(open_fixture, addon, tmp_path):
    import sys

    import madder

    handlers = sys.modules[addon + ".handlers"]
    open_fixture("disk.blend")
    disk = bpy.data.objects["Disk"]
    missing = str(tmp_path / "gone.madder")
    with pytest.raises(sys.modules[addon + ".errors"].RelocateError) as e:
        handlers.relocate(disk, missing)
    assert (e.value.object, e.value.filename) == ("Disk", missing)
    assert isinstance(e.value.__cause__, FileNotFoundError) and isinstance(e.value.__cause__, madder.CacheError)
