"""A directed splash on the tablecloth: a Throw empty turns the Spill Group's disc into a
knocked-over glass (`addon/splash.py`): the cache's first frame holds the Volume's mass, and
the liquid reaches out along the throw."""

import math

import bpy
import numpy as np
from conftest import lumped_areas, make_active

import madder


def world_state(obj):
    """World positions and independent lumped vertex areas of `obj` at the current frame."""
    ev = obj.evaluated_get(bpy.context.evaluated_depsgraph_get())
    me = ev.data
    co = np.empty(3 * len(me.vertices))
    me.vertices.foreach_get("co", co)
    m = np.array(ev.matrix_world)
    pos = co.reshape(-1, 3) @ m[:3, :3].T + m[:3, 3]
    return pos, lumped_areas(me, pos)


def test_a_throw_makes_a_splash_of_the_volumes_mass_along_the_throw(open_fixture):
    scene = open_fixture("tablecloth.blend")
    scene.frame_end = scene.frame_start + 2
    cloth = make_active(bpy.data.objects["Tablecloth"])
    s = cloth.madder
    s.enabled, s.source_group, s.evaporation = True, "stain_source", 0.0
    empty = bpy.data.objects.new("Throw", None)
    scene.collection.objects.link(empty)
    empty.empty_display_type = "SINGLE_ARROW"
    empty.rotation_euler = (0.0, math.radians(90.0), math.radians(30.0))
    s.splash.throw = empty
    s.splash.volume = 125.0
    bpy.context.view_layer.update()
    throw = np.array(empty.matrix_world)[:3, 2]
    np.testing.assert_allclose(throw, (math.cos(math.pi / 6), 0.5, 0.0), atol=1e-6)
    assert bpy.ops.madder.bake() == {"FINISHED"}

    scene.frame_set(scene.frame_start)
    pos, areas = world_state(cloth)
    reader = madder.CacheReader(bpy.path.abspath(s.cache_file))
    liquid = reader.read(scene.frame_start, "wetness").astype(np.float64)
    mass = areas * liquid
    # the Volume's mass, 125 mL of water (float32 cache)
    assert abs(mass.sum() - 0.125) <= 2e-6 * 0.125
    # from the Spill Group's centre, the liquid lies along the throw
    group = cloth.vertex_groups["stain_source"]
    w = np.zeros(len(pos))
    for v in cloth.data.vertices:
        for g in v.groups:
            if g.group == group.index:
                w[v.index] = g.weight
    impact = w @ pos / w.sum()
    shift = mass @ (pos - impact) / mass.sum()
    cos = shift @ throw / np.linalg.norm(shift)
    assert cos >= math.cos(math.radians(10)), f"the liquid's centre moved {shift}, not along {throw}"
    # the tongue reaches the pour's ballistic range, 2 × 0.1 m, beyond the pool, and the
    # farthest drops land ahead of it; nothing lies far behind the impact
    wet = liquid > 1e-6 * liquid.max()
    ahead = (pos[wet] - impact) @ throw
    assert ahead.max() >= 0.25
    assert ahead.min() >= -0.2
