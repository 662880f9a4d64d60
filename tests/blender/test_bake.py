"""Baking and playing back stains through the installed extension, in real Blender."""

import os

import bpy
import numpy as np
import pytest
from conftest import make_active

import madder


def setup_flag(scene):
    flag = make_active(bpy.data.objects["Flag"])
    flag.madder.enabled = True
    flag.madder.source_group = "stain_source"
    return flag


def point_attr(mesh, name, prop, width):
    attr = mesh.attributes[name]
    out = np.empty(len(mesh.vertices) * width, dtype=np.float32)
    attr.data.foreach_get(prop, out)
    return attr, out.reshape(-1, width) if width > 1 else out


def lumped_areas(obj_eval):
    """Independent numpy lumped vertex areas of an evaluated mesh, world space."""
    me = obj_eval.data
    me.calc_loop_triangles()
    tris = np.empty(3 * len(me.loop_triangles), dtype=np.int64)
    me.loop_triangles.foreach_get("vertices", tris)
    tris = tris.reshape(-1, 3)
    co = np.empty(3 * len(me.vertices))
    me.vertices.foreach_get("co", co)
    m = np.array(obj_eval.matrix_world)
    p = co.reshape(-1, 3) @ m[:3, :3].T + m[:3, 3]
    area = 0.5 * np.linalg.norm(np.cross(p[tris[:, 1]] - p[tris[:, 0]], p[tris[:, 2]] - p[tris[:, 0]]), axis=1)
    out = np.zeros(len(p))
    for k in range(3):
        np.add.at(out, tris[:, k], area / 3)
    return out


def test_extension_is_installed_with_its_own_wheel(addon):
    assert addon in bpy.context.preferences.addons
    # the native module is the one Blender unpacked from the extension's wheel into this
    # session's fresh user folder, not a copy from the test environment
    wheels = os.path.realpath(bpy.utils.user_resource("EXTENSIONS", path=".local"))
    assert os.path.realpath(madder.__file__).startswith(wheels + os.sep)
    assert hasattr(bpy.ops.madder, "bake") and hasattr(bpy.types.Object, "madder")


def test_bake_writes_point_attributes_that_change_between_frames(open_fixture):
    scene = open_fixture("flag.blend")
    flag = setup_flag(scene)
    assert bpy.ops.madder.bake() == {"FINISHED"}
    path = bpy.path.abspath(flag.madder.cache_file)
    assert os.path.isfile(path) and flag.madder.cache_file.startswith("//")

    frames = {}
    for f in (1, 12, 30, 48):
        scene.frame_set(f)
        attr, stain = point_attr(flag.data, "madder_stain", "color", 4)
        dattr, density = point_attr(flag.data, "madder_density", "value", 1)
        assert attr.domain == "POINT" and attr.data_type == "FLOAT_COLOR"
        assert dattr.domain == "POINT" and dattr.data_type == "FLOAT"
        assert np.all(stain >= 0) and np.all(stain <= 1)
        assert np.all(np.isfinite(density)) and density.min() >= -1e-6
        # madder_stain is the stain colour scaled by the clamped density
        np.testing.assert_allclose(stain[:, 3], np.clip(density, 0, 1), atol=1e-6)
        np.testing.assert_allclose(stain[:, 0], np.clip(density, 0, 1) * flag.madder.stain_color[0], atol=1e-6)
        frames[f] = density
    # the source starts at the vertex group, then spreads: peak drops, footprint grows
    assert frames[1].max() == pytest.approx(1.0)
    assert frames[1].max() > frames[12].max() > frames[48].max()
    assert (frames[48] > 0.05).sum() > (frames[1] > 0.05).sum()


def test_mass_is_conserved_on_the_draping_tablecloth(open_fixture):
    scene = open_fixture("tablecloth.blend")
    cloth = make_active(bpy.data.objects["Tablecloth"])
    cloth.madder.enabled = True
    cloth.madder.source_group = "stain_source"
    cloth.madder.diffusion_rate = 0.01
    assert bpy.ops.madder.bake() == {"FINISHED"}
    reader = madder.CacheReader(bpy.path.abspath(cloth.madder.cache_file))
    masses, areas = [], []
    for f in range(scene.frame_start, scene.frame_end + 1, 6):
        scene.frame_set(f)
        a = lumped_areas(cloth.evaluated_get(bpy.context.evaluated_depsgraph_get()))
        masses.append(a @ reader.read(f, "density").astype(np.float64))
        areas.append(a.sum())
    # the cloth deforms (its area changes), yet the stain mass stays (float32 cache)
    assert max(areas) - min(areas) > 1e-3 * areas[0]
    np.testing.assert_allclose(masses, masses[0], rtol=2e-6)


def test_diffusion_happens_in_world_space(open_fixture, tmp_path):
    """Similarity law: scaling space by k scales diffusion time by k², so a disk turning a
    full circle with object scale 2 and rate 4D must stain exactly like the still, unscaled
    disk with rate D. Fails if the bake ignores the object transform (or if rigid motion
    leaks into the diffusion)."""
    scene = open_fixture("disk.blend")
    disk = make_active(bpy.data.objects["Disk"])
    disk.madder.source_group = "stain_source"
    disk.scale = (2.0, 2.0, 2.0)
    disk.madder.diffusion_rate = 0.04
    assert bpy.ops.madder.bake() == {"FINISHED"}
    moving = madder.CacheReader(bpy.path.abspath(disk.madder.cache_file)).read(scene.frame_end, "density")

    disk.animation_data_clear()
    disk.scale = (1.0, 1.0, 1.0)
    disk.rotation_euler = (0.0, 0.0, 0.0)
    disk.madder.diffusion_rate = 0.01
    disk.madder.cache_dir = str(tmp_path / "still")
    assert bpy.ops.madder.bake() == {"FINISHED"}
    still = madder.CacheReader(bpy.path.abspath(disk.madder.cache_file)).read(scene.frame_end, "density")
    assert still.max() < 0.5  # it spread
    np.testing.assert_allclose(moving, still, atol=2e-5)


def test_settings_survive_save_and_reopen_and_play_back_from_the_cache(open_fixture, tmp_path):
    scene = open_fixture("flag.blend")
    flag = setup_flag(scene)
    flag.madder.diffusion_rate = 0.0123
    flag.madder.amount = 2.5
    flag.madder.stain_color = (0.1, 0.2, 0.7)
    assert bpy.ops.madder.bake() == {"FINISHED"}
    expected = madder.CacheReader(bpy.path.abspath(flag.madder.cache_file)).read(30, "density")
    for name in ("madder_stain", "madder_density"):  # playback must recreate them
        flag.data.attributes.remove(flag.data.attributes[name])
    scene.frame_set(1)
    saved = str(tmp_path / "saved.blend")
    bpy.ops.wm.save_as_mainfile(filepath=saved)

    bpy.ops.wm.open_mainfile(filepath=saved)
    flag = bpy.data.objects["Flag"]
    s = flag.madder
    assert (s.enabled, s.source_group) == (True, "stain_source")
    assert s.diffusion_rate == pytest.approx(0.0123) and s.amount == pytest.approx(2.5)
    assert tuple(s.stain_color) == pytest.approx((0.1, 0.2, 0.7))
    assert s.cache_file == "//madder_cache/Flag.madder"
    bpy.context.scene.frame_set(30)
    _, density = point_attr(flag.data, "madder_density", "value", 1)
    np.testing.assert_array_equal(density, expected)
    _, stain = point_attr(flag.data, "madder_stain", "color", 4)
    np.testing.assert_allclose(stain[:, 2], np.clip(expected, 0, 1) * 0.7, atol=1e-6)


def test_baking_twice_gives_an_identical_cache(open_fixture):
    open_fixture("flag.blend")
    flag = setup_flag(bpy.context.scene)
    assert bpy.ops.madder.bake() == {"FINISHED"}
    path = bpy.path.abspath(flag.madder.cache_file)
    first = open(path, "rb").read()
    assert bpy.ops.madder.bake() == {"FINISHED"}
    assert open(path, "rb").read() == first


def test_free_bake_removes_cache_and_attributes(open_fixture):
    open_fixture("flag.blend")
    flag = setup_flag(bpy.context.scene)
    bpy.ops.madder.bake()
    path = bpy.path.abspath(flag.madder.cache_file)
    assert bpy.ops.madder.free_bake() == {"FINISHED"}
    assert not os.path.exists(path) and flag.madder.cache_file == ""
    assert "madder_stain" not in flag.data.attributes
