"""Degenerate transforms and scene units (issue 10, item 7): an object scale that
collapses the cloth is refused naming the object and frame, and a scene modelled in
centimetres (Unit Scale 0.01) bakes the same physics as the same scene in metres."""

import bpy
import numpy as np
import pytest
from conftest import make_active

import madder


def tilted_cloth(tmp_path, scale=1.0, unit=1.0, frames=12):
    """A 1 m square cloth of 17×17 vertices (times `scale` Blender units, in a scene of
    `unit` metres per unit, so always 1 m), tilted 0.5 rad so the liquid runs downhill, with
    a round spill in its middle thrown outward at 0.5 m/s, and a brush resting on one
    corner, pouring blue within 5 cm. Gravity and the speeds are what the UI shows in m/s²
    and m/s, so they are stored in scene units."""
    bpy.ops.wm.read_homefile(use_empty=True)
    scene = bpy.context.scene
    scene.unit_settings.system = "METRIC"
    scene.unit_settings.scale_length = unit
    scene.gravity = (0.0, 0.0, -9.81 / unit)
    scene.frame_start, scene.frame_end = 1, frames
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=16, y_subdivisions=16, size=scale)
    cloth = make_active(bpy.context.object)
    cloth.rotation_euler.x = 0.5
    co = np.array([v.co[:] for v in cloth.data.vertices]) / scale
    wet = cloth.vertex_groups.new(name="wet")
    for i, r in enumerate(np.linalg.norm(co[:, :2], axis=1)):
        if r < 0.2:
            wet.add([i], 1.0 - r / 0.2, "REPLACE")
    s = cloth.madder
    s.enabled, s.source_group, s.cache_dir = True, "wet", str(tmp_path)
    s.splash_speed, s.splash_seed = 0.5 / unit, 7
    s.friction = 10.0
    corner = (0.5 * scale, 0.5 * scale * np.cos(0.5), 0.5 * scale * np.sin(0.5))  # the tilted cloth's
    bpy.ops.mesh.primitive_cube_add(size=0.1 * scale, location=corner)
    brush = bpy.context.object
    b = brush.madder_source
    b.is_source, b.distance, b.amount = True, 0.05 / unit, 0.5
    make_active(cloth)
    return scene, cloth


def baked(cloth, field="solute"):
    r = madder.CacheReader(bpy.path.abspath(cloth.madder.cache_file))
    return np.stack([r.read(f, field) for f in range(r.first_frame, r.last_frame + 1)])


def test_centimetre_scene_bakes_like_the_metre_scene(tmp_path):
    scene, cloth = tilted_cloth(tmp_path / "m")
    assert bpy.ops.madder.bake() == {"FINISHED"}
    metres = baked(cloth)
    moved = np.abs(metres[-1] - metres[0]).max()
    assert moved > 0.1 * metres[0].max()  # the liquid ran, splashed and was poured
    scene, cloth = tilted_cloth(tmp_path / "cm", scale=100.0, unit=0.01)
    assert bpy.ops.madder.bake() == {"FINISHED"}
    centimetres = baked(cloth)
    np.testing.assert_allclose(centimetres, metres, rtol=0, atol=1e-4 * metres.max())


def test_zero_scale_is_refused_naming_object_and_frame(tmp_path):
    scene, cloth = tilted_cloth(tmp_path)
    cloth.scale = (0.0, 0.0, 0.0)
    with pytest.raises(RuntimeError) as e:
        bpy.ops.madder.bake()
    msg = str(e.value)
    assert f"'{cloth.name}' at frame 1" in msg and "scale (0, 0, 0) collapses the cloth" in msg, msg


def test_scale_animated_to_zero_on_one_axis_names_the_frame(tmp_path):
    scene, cloth = tilted_cloth(tmp_path)
    cloth.keyframe_insert("scale", frame=1)
    cloth.scale.y = 0.0  # the grid spans x and y: this flattens it to a line
    cloth.keyframe_insert("scale", frame=8)
    with pytest.raises(RuntimeError) as e:
        bpy.ops.madder.bake()
    msg = str(e.value)
    assert f"'{cloth.name}' at frame 8" in msg and "scale (1, 0, 1) collapses the cloth" in msg, msg
    assert "positive definite" not in msg


def test_nearly_zero_scale_is_refused_too(tmp_path):
    scene, cloth = tilted_cloth(tmp_path)
    cloth.scale.x = 1e-7  # a ten-millionth of its width
    with pytest.raises(RuntimeError, match=r"scale \(1e-07, 1, 1\) collapses the cloth"):
        bpy.ops.madder.bake()
    cloth.scale.x = 1e-3  # a millimetre-wide metre of cloth is odd, but it is still cloth
    assert bpy.ops.madder.bake() == {"FINISHED"}


def test_zero_scale_across_a_flat_cloth_is_harmless(tmp_path):
    """The grid is flat in its own z: a z scale of 0 leaves its area whole."""
    scene, flat = tilted_cloth(tmp_path / "flat")
    flat.scale.z = 0.0
    assert bpy.ops.madder.bake() == {"FINISHED"}
    squashed = baked(flat)
    scene, cloth = tilted_cloth(tmp_path / "plain")
    assert bpy.ops.madder.bake() == {"FINISHED"}
    np.testing.assert_array_equal(squashed, baked(cloth))
