"""Coherent Structures in real Blender (issue 14): a short flag bake with Bake Flow, then
the operator. The FTLE attribute equals `madder.ftle` called here on the cache's own
velocities and positions (read field by field, independently of the add-on's reader);
the cache's positions are the evaluated cloth's; the ridge curves lie on the cloth at the
frame computed and at another frame (they follow the deformation); and the requests
that cannot be served fail with a message and leave the scene as it was."""

import bpy
import numpy as np
import pytest
from conftest import make_active

import madder

FRAMES = 12  # a short bake: frames 1–12 of the flag (24 fps)


def bake_flag(open_fixture, flow=True, frames=FRAMES):
    scene = open_fixture("flag.blend")
    scene.frame_end = frames
    flag = make_active(bpy.data.objects["Flag"])
    s = flag.madder
    s.enabled = True
    s.source_group = "stain_source"
    s.bake_flow = flow
    assert bpy.ops.madder.bake() == {"FINISHED"}
    return scene, flag


def faces_of(mesh):
    mesh.calc_loop_triangles()
    t = np.empty(3 * len(mesh.loop_triangles), dtype=np.uint32)
    mesh.loop_triangles.foreach_get("vertices", t)
    return t.reshape(-1, 3)


def world_cloth(obj, frame):
    """The evaluated cloth at `frame`, world space: (N, 3) float64 positions."""
    bpy.context.scene.frame_set(frame)
    ev = obj.evaluated_get(bpy.context.evaluated_depsgraph_get())
    co = np.empty(3 * len(ev.data.vertices))
    ev.data.vertices.foreach_get("co", co)
    m = np.array(ev.matrix_world)
    return co.reshape(-1, 3) @ m[:3, :3].T + m[:3, 3]


def curve_points(obj, frame):
    bpy.context.scene.frame_set(frame)
    ev = obj.evaluated_get(bpy.context.evaluated_depsgraph_get())
    pos = np.empty(3 * len(ev.data.points), dtype=np.float32)
    ev.data.position_data.foreach_get("vector", pos)
    m = np.array(ev.matrix_world)
    return pos.reshape(-1, 3) @ m[:3, :3].T + m[:3, 3]


def ftle_attribute(flag):
    attr = flag.data.attributes["madder_ftle"]
    assert (attr.domain, attr.data_type) == ("POINT", "FLOAT")
    out = np.empty(len(flag.data.vertices), dtype=np.float32)
    attr.data.foreach_get("value", out)
    return out


def test_ftle_attribute_equals_a_direct_call_on_the_baked_flow(open_fixture):
    scene, flag = bake_flag(open_fixture)
    r = madder.CacheReader(bpy.path.abspath(flag.madder.cache_file))
    assert r.version == 2 and r.frame_time == pytest.approx(scene.render.fps_base / scene.render.fps)
    lcs = flag.madder.lcs
    lcs.frame, lcs.span, lcs.direction, lcs.steps_per_frame = 9, 6, "BACKWARD", 3
    assert bpy.ops.madder.coherent_structures() == {"FINISHED"}
    got = ftle_attribute(flag)

    frames = range(3, 10)
    pos = np.array([[r.read(f, f"position_{c}") for c in "xyz"] for f in frames], dtype=np.float64)
    vel = np.array([[r.read(f, f"velocity_{c}") for c in "xyz"] for f in frames], dtype=np.float64)
    pos, vel = pos.transpose(0, 2, 1), vel.transpose(0, 2, 1)
    dt = r.frame_time
    want = madder.ftle(faces_of(flag.data), pos, vel, 9 * dt, -6 * dt, steps=18, times=np.array(frames) * dt)
    assert np.isfinite(got).all()
    np.testing.assert_array_equal(got, want.astype(np.float32))
    assert want.max() > 0.1  # the liquid really moved and stretched
    assert np.abs(vel).max() > 1e-3
    # the cache's positions are the evaluated cloth's (metres, world; Unit Scale 1)
    for k, f in enumerate((3, 9)):
        np.testing.assert_allclose(pos[6 * k], world_cloth(flag, f), atol=2e-6)


def on_cloth(points, cloth_world, faces):
    """Distance of each point to the cloth's triangles (inf beyond 1 cm)."""
    return madder.distances_within(points.astype(np.float32), cloth_world.astype(np.float32), faces, 0.01)


def test_ridge_curves_lie_on_the_cloth_and_follow_it(open_fixture):
    scene, flag = bake_flag(open_fixture)
    lcs = flag.madder.lcs
    lcs.frame, lcs.span, lcs.direction = 4, 8, "FORWARD"
    lcs.min_edges, lcs.min_branch = 3, 0  # the stain is small: keep its short ridges
    assert bpy.ops.madder.coherent_structures() == {"FINISHED"}
    ridge = lcs.ridge_object
    assert ridge is not None and ridge.type == "CURVES"
    assert ridge.modifiers["Madder Ridges"].node_group is not None
    faces = faces_of(flag.data)

    at4 = curve_points(ridge, 4)
    cloth4 = world_cloth(flag, 4)
    assert len(at4) >= 4
    d4 = on_cloth(at4, cloth4, faces)
    assert d4.max() < 1e-5, d4.max()
    # the stored points are where the ridges were computed (the cache's positions at frame 4)
    stored = np.empty(3 * len(ridge.data.points), dtype=np.float32)
    ridge.data.position_data.foreach_get("vector", stored)
    np.testing.assert_allclose(stored.reshape(-1, 3), at4, atol=1e-5)

    at11 = curve_points(ridge, 11)
    cloth11 = world_cloth(flag, 11)
    moved = np.linalg.norm(at11 - at4, axis=1)
    assert moved.max() > 0.01, "the cloth moves between frames 4 and 11, so must the ridges"
    d11 = on_cloth(at11, cloth11, faces)
    assert d11.max() < 1e-5, d11.max()
    print(f"\n{len(at4)} ridge points; on the cloth within {d4.max():.1e} m (frame 4), {d11.max():.1e} m "
          f"(frame 11) after moving up to {moved.max():.3f} m")
    # without the binding, the points would have stayed behind, off the cloth
    assert on_cloth(at4, cloth11, faces).max() > 10 * max(d11.max(), 1e-7)

    # a second run replaces the curves object, it does not pile up
    before = {o.name for o in bpy.data.objects}
    assert bpy.ops.madder.coherent_structures() == {"FINISHED"}
    after = {o.name for o in bpy.data.objects}
    assert len(after) == len(before) and lcs.ridge_object is not None


def scene_state(flag):
    return ({o.name for o in bpy.data.objects}, "madder_ftle" in flag.data.attributes,
            len(bpy.data.node_groups), len(bpy.data.hair_curves))


def test_requests_that_cannot_be_served_say_why_and_change_nothing(open_fixture):
    scene, flag = bake_flag(open_fixture, flow=False, frames=3)
    lcs = flag.madder.lcs
    lcs.frame, lcs.span = 1, 2
    before = scene_state(flag)
    with pytest.raises(RuntimeError, match="'Flag'.*has no velocity.*rebake with velocity"):
        bpy.ops.madder.coherent_structures()
    assert scene_state(flag) == before

    flag.madder.bake_flow = True
    assert bpy.ops.madder.bake() == {"FINISHED"}
    before = scene_state(flag)
    lcs.frame, lcs.span = 40, 2
    with pytest.raises(RuntimeError, match="'Flag'.*frame 40 is outside the bake \\(frames 1–3\\)"):
        bpy.ops.madder.coherent_structures()
    lcs.frame, lcs.span = 2, 0
    with pytest.raises(RuntimeError, match="'Flag'.*span is 0 frames"):
        bpy.ops.madder.coherent_structures()
    lcs.frame, lcs.span, lcs.direction = 2, 2, "FORWARD"
    with pytest.raises(RuntimeError, match="'Flag'.*needs frames 2–4, the bake has 1–3"):
        bpy.ops.madder.coherent_structures()
    assert scene_state(flag) == before
    # and the same request inside the bake works
    lcs.frame, lcs.direction = 3, "BACKWARD"
    assert bpy.ops.madder.coherent_structures() == {"FINISHED"}
    assert "madder_ftle" in flag.data.attributes


class RecordingLayout:
    """Stands in for a panel's UILayout (none exists without a window): records what the
    panel draws and checks each property and operator against the real RNA."""

    def __init__(self, props, operators):
        self.props, self.operators = props, operators
        self.use_property_split = self.active = self.alert = False

    def prop(self, data, name, **_kw):
        assert name in data.bl_rna.properties, f"{type(data).__name__} has no property {name}"
        self.props.append(name)

    def operator(self, idname, **_kw):
        category, name = idname.split(".")
        assert hasattr(getattr(bpy.ops, category), name), idname
        self.operators.append(idname)

    def label(self, **_kw):
        pass

    def column(self, **_kw):
        return self

    row = column


def test_the_panel_draws_every_setting(open_fixture, addon):
    import sys
    from types import SimpleNamespace

    panels = sys.modules[addon + ".panels"]
    open_fixture("flag.blend")
    flag = bpy.data.objects["Flag"]
    props, operators = [], []
    panel = SimpleNamespace(layout=RecordingLayout(props, operators))
    panel.layout_of = lambda context: panels._StainSubPanel.layout_of(panel, context)
    panels.MADDER_PT_stain_lcs.draw(panel, SimpleNamespace(object=flag))
    settings = [p.identifier for p in flag.madder.lcs.bl_rna.properties
                if p.identifier not in ("rna_type", "name", "ridge_object")]
    assert sorted(set(props) - {"bake_flow"}) == sorted(settings) and "bake_flow" in props
    assert operators == ["madder.coherent_structures"]
    assert panels.MADDER_PT_stain_lcs.bl_parent_id == "MADDER_PT_stain"
