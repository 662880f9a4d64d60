"""Baking and playing back stains through the installed extension, in real Blender."""

import os

import bpy
import numpy as np
import pytest
from conftest import lumped_areas, make_active, plain_look, shown

import madder


def setup_flag(scene):
    flag = make_active(bpy.data.objects["Flag"])
    flag.madder.enabled = True
    flag.madder.source_group = "stain_source"
    plain_look(flag.madder)  # these tests check the bake against the fields' definitions, not the look
    return flag


def point_attr(mesh, name, prop, width):
    attr = mesh.attributes[name]
    out = np.empty(len(mesh.vertices) * width, dtype=np.float32)
    attr.data.foreach_get(prop, out)
    return attr, out.reshape(-1, width) if width > 1 else out


def group_weights(obj, name="stain_source"):
    """Per vertex, its weight in the vertex group `name` (0 outside it), float32: read from
    bpy here, not by the add-on's `bridge.vertex_group_weights`, so that the checks on the
    spill do not rest on the code they check."""
    weights = np.zeros(len(obj.data.vertices), dtype=np.float32)
    gi = obj.vertex_groups[name].index
    for v in obj.data.vertices:
        for g in v.groups:
            if g.group == gi:
                weights[v.index] = g.weight
    return weights


def world_lumped_areas(obj_eval):
    """Independent numpy lumped vertex areas of an evaluated mesh, world space."""
    me = obj_eval.data
    co = np.empty(3 * len(me.vertices))
    me.vertices.foreach_get("co", co)
    m = np.array(obj_eval.matrix_world)
    return lumped_areas(me, co.reshape(-1, 3) @ m[:3, :3].T + m[:3, 3])


def test_a_spill_lands_as_a_pool_by_default(open_fixture):
    """Spill Shape Pool, the default: frame 1 holds the mass the Spill Group's weights hold at
    Amount (independent lumped areas of the evaluated flag), laid Amount deep on the group's
    highest weights, one vertex at most in part (Weights, weight × Amount, is the test below's,
    through `plain_look`)."""
    scene = open_fixture("flag.blend")
    flag = setup_flag(scene)
    s = flag.madder
    assert s.bl_rna.properties["spill_shape"].default == "POOL"
    s.spill_shape = "POOL"  # (plain_look lays the weights)
    scene.frame_end = scene.frame_start + 1
    assert bpy.ops.madder.bake() == {"FINISHED"}
    wet = cache(flag).read(1, "wetness")
    weights = group_weights(flag).astype(np.float64)
    scene.frame_set(1)
    area = world_lumped_areas(flag.evaluated_get(bpy.context.evaluated_depsgraph_get()))
    assert float(wet @ area) == pytest.approx(s.amount * float(weights @ area), rel=1e-4)
    full = np.isclose(wet, s.amount, rtol=1e-6)
    assert ((wet > 0) & ~full).sum() <= 1
    assert 0 < full.sum() < (weights > 0).sum()  # a pool inside the soft group, not all of it
    assert weights[wet > 0].min() >= weights[(wet == 0) & (weights > 0)].max()


def test_extension_is_installed_with_its_own_wheel(addon):
    assert addon in bpy.context.preferences.addons
    # the native module is the one Blender unpacked from the extension's wheel into this
    # session's fresh user folder, not a copy from the test environment
    wheels = os.path.realpath(bpy.utils.user_resource("EXTENSIONS", path=".local"))
    assert os.path.realpath(madder.__file__).startswith(wheels + os.sep)
    assert hasattr(bpy.ops.madder, "bake") and hasattr(bpy.types.Object, "madder")


def cache(obj):
    return madder.CacheReader(bpy.path.abspath(obj.madder.cache_file))


def test_bake_writes_point_attributes_that_change_between_frames(open_fixture):
    scene = open_fixture("flag.blend")
    flag = setup_flag(scene)
    s = flag.madder
    assert bpy.ops.madder.bake() == {"FINISHED"}
    path = bpy.path.abspath(s.cache_file)
    assert os.path.isfile(path) and s.cache_file.startswith("//")
    reader = cache(flag)
    assert reader.fields == ["solute", "wetness", "deposit"]
    # the references the playback normalizes by, recorded by the bake
    assert tuple(s.bake_references) == pytest.approx((s.concentration * s.saturation, s.saturation, s.capacity))

    solute = {}
    for f in (1, 12, 30, 48):
        scene.frame_set(f)
        raw = {name: reader.read(f, name) for name in reader.fields}
        attr, stain = point_attr(shown(flag), "madder_stain", "color", 4)
        wattr, wet = point_attr(shown(flag), "madder_wetness", "value", 1)
        dattr, deposit = point_attr(shown(flag), "madder_deposit", "value", 1)
        assert attr.domain == "POINT" and attr.data_type == "FLOAT_COLOR"
        assert (wattr.domain, wattr.data_type) == (dattr.domain, dattr.data_type) == ("POINT", "FLOAT")
        for name, v in raw.items():
            assert np.isfinite(v).all() and v.min() >= 0.0, (f, name)
        # the documented normalization of the raw densities (kg/m²)
        coverage = np.clip(raw["solute"] / (s.concentration * s.saturation), 0, 1 + madder.DYE_EXCESS_RANGE)
        np.testing.assert_allclose(stain[:, 3], coverage, atol=1e-6)
        # the colour premultiplied by the coverage (at most 1: never brighter than the liquid)
        np.testing.assert_allclose(stain[:, :3], np.minimum(coverage, 1)[:, None] * np.array(s.stain_color),
                                   atol=1e-6)
        np.testing.assert_allclose(wet, np.clip(raw["wetness"] / s.saturation, 0, 1), atol=1e-6)
        np.testing.assert_allclose(deposit, np.clip(raw["deposit"] / s.capacity, 0, 1), atol=1e-6)
        solute[f] = raw
    # frame 1 is the spill itself: Amount × weight of liquid carrying its solute, nothing bound yet
    weights = group_weights(flag)
    np.testing.assert_allclose(solute[1]["wetness"], s.amount * weights, rtol=1e-6)
    np.testing.assert_allclose(solute[1]["solute"], s.amount * s.concentration * weights, rtol=1e-6)
    assert not solute[1]["deposit"].any()
    # then the liquid flows and spreads, and the solute binds to the fibres
    footprint = {f: (r["solute"] > 0.01 * r["solute"].max()).sum() for f, r in solute.items()}
    assert footprint[1] < footprint[12] < footprint[48], footprint
    assert 0 < solute[12]["deposit"].max() < solute[48]["deposit"].max()
    assert solute[48]["wetness"].max() < solute[1]["wetness"].max()


def test_mass_is_conserved_on_the_draping_tablecloth(open_fixture):
    """Total solute (dissolved + absorbed + adsorbed) and, without evaporation, total
    liquid stay put while the cloth drapes (its area changes) and the liquid flows."""
    scene = open_fixture("tablecloth.blend")
    cloth = make_active(bpy.data.objects["Tablecloth"])
    cloth.madder.enabled = True
    cloth.madder.source_group = "stain_source"
    cloth.madder.diffusion_rate = 0.01
    cloth.madder.evaporation = 0.0
    assert bpy.ops.madder.bake() == {"FINISHED"}
    reader = cache(cloth)
    solute, liquid, areas = [], [], []
    for f in range(scene.frame_start, scene.frame_end + 1, 6):
        scene.frame_set(f)
        a = world_lumped_areas(cloth.evaluated_get(bpy.context.evaluated_depsgraph_get()))
        solute.append(a @ reader.read(f, "solute").astype(np.float64))
        liquid.append(a @ reader.read(f, "wetness").astype(np.float64))
        areas.append(a.sum())
    # the cloth deforms (its area changes), yet the masses stay (float32 cache)
    assert max(areas) - min(areas) > 1e-3 * areas[0]
    assert solute[0] > 0
    np.testing.assert_allclose(solute, solute[0], rtol=2e-6)
    np.testing.assert_allclose(liquid, liquid[0], rtol=2e-6)


def test_diffusion_happens_in_world_space(open_fixture, tmp_path):
    """Similarity law: scaling space by k scales diffusion time by k², so a disk turning a
    full circle with object scale 2 and rate 4D must stain exactly like the still, unscaled
    disk with rate D (the interactions are per unit area, hence scale-free; the inertial
    forces, which do depend on the motion, are off). Fails if the bake ignores the object
    transform (or if rigid motion leaks into the diffusion)."""
    scene = open_fixture("disk.blend")
    disk = make_active(bpy.data.objects["Disk"])
    s = disk.madder
    s.source_group = "stain_source"
    # the law holds for a uniform fabric at a fixed Detail: the grain is a length of its own,
    # and Auto Detail would pick its level from each scale's edge
    plain_look(s)
    s.use_rectilinear = s.use_coriolis = False
    disk.scale = (2.0, 2.0, 2.0)
    s.diffusion_rate = 0.04
    assert bpy.ops.madder.bake() == {"FINISHED"}
    moving = {f: cache(disk).read(scene.frame_end, f) for f in ("solute", "wetness", "deposit")}

    disk.animation_data_clear()
    disk.scale = (1.0, 1.0, 1.0)
    disk.rotation_euler = (0.0, 0.0, 0.0)
    s.diffusion_rate = 0.01
    s.cache_dir = str(tmp_path / "still")
    assert bpy.ops.madder.bake() == {"FINISHED"}
    still = {f: cache(disk).read(scene.frame_end, f) for f in ("solute", "wetness", "deposit")}
    assert still["wetness"].max() < 0.5 * s.amount  # it spread
    for f in still:
        np.testing.assert_allclose(moving[f], still[f], atol=2e-5 * still[f].max(), err_msg=f)


def test_settings_survive_save_and_reopen_and_play_back_from_the_cache(open_fixture, tmp_path):
    scene = open_fixture("flag.blend")
    flag = setup_flag(scene)
    s = flag.madder
    s.liquid = "INK"
    s.diffusion_rate = 0.0123
    s.amount = 2.5
    s.friction = 12.5
    s.use_coriolis = False
    s.splash_speed, s.splash_seed = 0.5, 7
    assert bpy.ops.madder.bake() == {"FINISHED"}
    expected = {f: cache(flag).read(30, f) for f in ("solute", "wetness", "deposit")}
    bpy.data.objects.remove(bpy.data.objects[".madder_stain Flag"])  # playback must recreate it
    scene.frame_set(1)
    saved = str(tmp_path / "saved.blend")
    bpy.ops.wm.save_as_mainfile(filepath=saved)

    bpy.ops.wm.open_mainfile(filepath=saved)
    flag = bpy.data.objects["Flag"]
    s = flag.madder
    assert (s.enabled, s.source_group, s.liquid) == (True, "stain_source", "INK")
    assert s.diffusion_rate == pytest.approx(0.0123) and s.amount == pytest.approx(2.5)
    assert s.friction == pytest.approx(12.5) and not s.use_coriolis
    assert (s.splash_speed, s.splash_seed) == (pytest.approx(0.5), 7)
    assert tuple(s.stain_color) == pytest.approx((0.04, 0.05, 0.15))
    assert s.cache_file == "//madder_cache/Flag.madder"
    bpy.context.scene.frame_set(30)
    _, wet = point_attr(shown(flag), "madder_wetness", "value", 1)
    np.testing.assert_allclose(wet, np.clip(expected["wetness"] / s.saturation, 0, 1), atol=1e-6)
    _, deposit = point_attr(shown(flag), "madder_deposit", "value", 1)
    np.testing.assert_allclose(deposit, np.clip(expected["deposit"] / s.capacity, 0, 1), atol=1e-6)
    _, stain = point_attr(shown(flag), "madder_stain", "color", 4)
    coverage = np.clip(expected["solute"] / (s.concentration * s.saturation), 0, 1 + madder.DYE_EXCESS_RANGE)
    np.testing.assert_allclose(stain[:, 2], np.minimum(coverage, 1) * 0.15, atol=1e-6)


def test_playback_leaves_an_unbaked_cloth_where_it_is(open_fixture):
    """Playback writes each frame's stain into the carrier, not the cloth's mesh. Written
    into the cloth's own mesh (as before carriers), every frame's write was an edit that
    freed the unbaked cloth cache's frames, and the cloth stopped moving: 0.54 m off its
    simulated place by frame 20 on the flag."""
    scene = open_fixture("flag.blend")
    flag = setup_flag(scene)
    cloth_cache = flag.modifiers["Cloth"].point_cache
    with bpy.context.temp_override(point_cache=cloth_cache):
        bpy.ops.ptcache.free_bake()  # simulated in memory, as while the artist works
    assert not cloth_cache.is_baked
    assert bpy.ops.madder.bake() == {"FINISHED"}
    assert [m.name for m in flag.modifiers][:2] == ["Madder Stain", "Cloth"]
    reader = madder.CacheReader(bpy.path.abspath(flag.madder.cache_file))

    def play():
        for f in range(1, 21):
            scene.frame_set(f)
        me = shown(flag)
        co = np.empty(3 * len(me.vertices))
        me.vertices.foreach_get("co", co)
        return co, point_attr(me, "madder_wetness", "value", 1)[1] if "madder_wetness" in me.attributes else None

    co, wet = play()
    np.testing.assert_allclose(wet, np.clip(reader.read(20, "wetness") / flag.madder.saturation, 0, 1), atol=1e-6)
    assert wet.max() > 0.1
    # every played frame kept (the old writes left 2); the count depends on whether this
    # bpy resimulates from the start frame after the bake's own edits (5.0: 20) or not (48)
    assert int(cloth_cache.info.split()[0]) >= 20, cloth_cache.info
    flag.madder.enabled = False  # playback leaves it alone: the cloth as Blender simulates it
    bare, none = play()
    assert none is None  # and shows no stain (its modifier is not evaluated)
    assert np.abs(bare.reshape(-1, 3) - bare.reshape(-1, 3)[0]).max() > 0.1  # the cloth moved
    np.testing.assert_array_equal(co, bare)


def test_a_renamed_cloth_gets_one_carrier_of_its_own(open_fixture):
    """The carrier records the object it serves: a cloth renamed after the bake (here to a
    name too long for Blender to keep the carrier's whole name) gets one new carrier, not
    one per frame, and shows the cache."""
    scene = open_fixture("flag.blend")
    flag = setup_flag(scene)
    assert bpy.ops.madder.bake() == {"FINISHED"}
    reader = madder.CacheReader(bpy.path.abspath(flag.madder.cache_file))
    flag.name = "F" * 60
    for f in range(1, 8):
        scene.frame_set(f)
    owners = [o.get("madder_cloth") for o in bpy.data.objects if o.get("madder_cloth") is not None]
    assert owners.count(flag.name) == 1, owners
    wet = point_attr(shown(flag), "madder_wetness", "value", 1)[1]
    np.testing.assert_allclose(wet, np.clip(reader.read(7, "wetness") / flag.madder.saturation, 0, 1), atol=1e-6)


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
    assert "Madder Stain" not in flag.modifiers and ".madder_stain Flag" not in bpy.data.objects
    for name in ("madder_stain", "madder_wetness", "madder_deposit"):
        assert name not in flag.data.attributes and name not in shown(flag).attributes


def test_switched_off_shows_no_stain_and_costs_no_evaluation(open_fixture, tmp_path):
    """Unticking Madder Stain after playing leaves no stale stain at any frame (the
    carrier held the last played frame's, shown at every frame before), and its modifier
    is not evaluated: hidden in viewport and renders, so the evaluated cloth has no stain
    attribute at all. Ticked again, the current frame's stain shows at once; saved and
    reopened, a switched-off cloth stays bare."""
    scene = open_fixture("flag.blend")
    flag = setup_flag(scene)
    assert bpy.ops.madder.bake() == {"FINISHED"}
    reader = cache(flag)
    for f in range(1, 21):
        scene.frame_set(f)
    assert point_attr(shown(flag), "madder_wetness", "value", 1)[1].max() > 0.1
    flag.madder.enabled = False
    m = flag.modifiers["Madder Stain"]
    assert not m.show_viewport and not m.show_render
    for f in (3, 10, 20):
        scene.frame_set(f)
        assert "madder_stain" not in shown(flag).attributes, f
    # shown by hand (the artist ticks the modifier's eye): the carrier holds nothing stale
    m.show_viewport = True
    scene.frame_set(10)
    assert np.abs(point_attr(shown(flag), "madder_stain", "color", 4)[1]).max() == 0.0
    m.show_viewport = False
    flag.madder.enabled = True
    assert m.show_viewport and m.show_render
    _, wet = point_attr(shown(flag), "madder_wetness", "value", 1)  # frame 10, no frame change
    np.testing.assert_allclose(wet, np.clip(reader.read(10, "wetness") / flag.madder.saturation, 0, 1), atol=1e-6)
    flag.madder.enabled = False
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / "off.blend"))
    bpy.ops.wm.open_mainfile(filepath=str(tmp_path / "off.blend"))
    flag = bpy.data.objects["Flag"]
    assert not flag.modifiers["Madder Stain"].show_viewport
    bpy.context.scene.frame_set(12)
    assert "madder_stain" not in shown(flag).attributes
