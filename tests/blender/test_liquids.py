"""The full simulator through the add-on: liquid presets, the defaults, body forces
(gravity from the scene), and the splash of the initial wetness."""

import sys

import bpy
import numpy as np
import pytest
from conftest import ADDON, lumped_areas, make_active, shown

import madder

# the tide-line physics (issue 13 §2) with its rim (issue 34 §3): Coffee, Red Wine and Water
# ring, Ink binds its dye at once; every preset sets a wicking front, iterated at least twice
# a step and until it settles, so that it keeps up and takes no shape from the mesh, and a
# run holdup (issue 34)
NO_RING = dict(carry_solute=False, residual_saturation=0.0, vapour_limited=False, carried_fraction=1.0,
               dispersivity=0.0, wicking=2.0, wicking_iterations=2, front_settles=True, holdup=0.05,
               drip_hold=5.0)
RING = dict(carry_solute=True, residual_saturation=0.1, vapour_limited=True, carried_fraction=1.0,
            dispersivity=3.5, wicking=2.0, wicking_iterations=2, front_settles=True, holdup=0.05,
            drip_hold=5.0)
# the documented preset values (addon/presets.py explains where they come from)
PRESETS = {
    "WATER": dict(concentration=1e-3, stain_color=(0.95, 0.92, 0.85), absorption=2.0, adsorption=0.0,
                  capacity=2e-3, evaporation=5e-5, evaporation_boundary=1.2, **RING),
    "RED_WINE": dict(concentration=0.02, stain_color=(0.30, 0.02, 0.07), absorption=2.0, adsorption=0.005,
                     capacity=1e-3, evaporation=6e-5, evaporation_boundary=1.2, **RING),
    "COFFEE": dict(concentration=0.012, stain_color=(0.25, 0.13, 0.05), absorption=2.0, adsorption=0.05,
                   capacity=2e-4, evaporation=5e-5, evaporation_boundary=1.5, **RING),
    "INK": dict(concentration=0.05, stain_color=(0.04, 0.05, 0.15), absorption=3.0, adsorption=1.0,
                capacity=5e-3, evaporation=4e-5, evaporation_boundary=1.2, **NO_RING),
}
# StainParams::default and InteractionRates::default in the Rust core, and the core's
# default isotropic diffusion and solute colour (the constants the binding exports)
RUST_DEFAULTS = dict(diffusion_rate=madder.DEFAULT_DIFFUSION, stain_color=madder.DEFAULT_SOLUTE_COLOR,
                     viscosity=1e-4, friction=50.0, absorption=2.0, saturation=0.1, adsorption=0.1,
                     capacity=2e-3, evaporation=5e-5, evaporation_boundary=1.2, substeps=1)


def assert_values(settings, expected, rel=1e-6):
    for key, value in expected.items():
        got = getattr(settings, key)
        if key in ("stain_color", "color"):
            assert tuple(got) == pytest.approx(value, rel=rel), key
        else:
            assert got == pytest.approx(value, rel=rel), key


def plane(n=24, size=1.0, frames=(1, 24)):
    """A still, flat grid in the XY plane with a round 'wet' group in its middle."""
    bpy.ops.wm.read_homefile(use_empty=True)
    scene = bpy.context.scene
    scene.frame_start, scene.frame_end = frames
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=n, y_subdivisions=n, size=size)
    obj = make_active(bpy.context.object)
    co = np.empty(3 * len(obj.data.vertices))
    obj.data.vertices.foreach_get("co", co)
    co = co.reshape(-1, 3)
    wet = np.flatnonzero(np.hypot(co[:, 0], co[:, 1]) < 0.15 * size)
    obj.vertex_groups.new(name="wet").add(wet.tolist(), 1.0, "REPLACE")
    obj.madder.enabled = True
    obj.madder.source_group = "wet"
    obj.madder.cache_dir = bpy.app.tempdir
    return obj, co


def reader(obj):
    return madder.CacheReader(bpy.path.abspath(obj.madder.cache_file))


@pytest.mark.parametrize("name", PRESETS)
def test_preset_sets_the_documented_values(addon, name):
    bpy.ops.wm.read_homefile(use_empty=True)
    bpy.ops.mesh.primitive_plane_add()
    s = bpy.context.object.madder
    s.friction, s.saturation, s.diffusion_rate = 7.0, 0.3, 0.01  # the cloth's and the flow's: kept
    s.liquid = name
    assert_values(s, PRESETS[name])
    assert (s.friction, s.saturation, s.diffusion_rate) == pytest.approx((7.0, 0.3, 0.01))
    assert s.liquid == name
    s.adsorption += 0.01  # editing a value of the preset makes the liquid Custom
    assert s.liquid == "CUSTOM" and s.concentration == pytest.approx(PRESETS[name]["concentration"])
    # a source's preset sets its colour and concentration
    src = bpy.context.object.madder_source
    src.liquid = name
    assert src.concentration == pytest.approx(PRESETS[name]["concentration"])
    assert tuple(src.color) == pytest.approx(PRESETS[name]["stain_color"])
    src.color = (1.0, 0.0, 0.0)
    assert src.liquid == "CUSTOM"


def test_defaults_are_the_cores_defaults(addon):
    """The panel's defaults are the Rust defaults: the same numbers, and a simulator built
    from the add-on's settings behaves like one built with no settings at all."""
    bake = sys.modules[ADDON + ".bake"]
    obj, co = plane(n=12)
    s = obj.madder
    assert_values(s, RUST_DEFAULTS)
    assert (s.use_gravity, s.use_rectilinear, s.use_coriolis, s.momentum_advection) == (True, True, True, True)
    assert s.liquid == "CUSTOM" and s.splash_speed == 0.0
    faces = bake.bridge.topology_arrays(obj.data)[0]
    rest = co.astype(np.float32)
    tilted = rest.copy()
    tilted[:, 2] += 0.3 * rest[:, 0]  # a slope, so that gravity acts
    kw = bake.simulator_settings(bpy.context.scene, obj)
    kw.pop("color")
    ours = madder.Simulator(faces, rest, rest, diffusion=s.diffusion_rate, **kw)
    # the one setting that is not the core's default: the grain of the default fabric
    # (plain cotton) that a cloth without a Madder Fabric is (issue 34)
    cotton = bake.presets.FABRIC_PRESETS[bake.presets.DEFAULT_FABRIC]
    assert (kw["irregularity"], kw["irregularity_length"], kw["irregularity_seed"]) == pytest.approx(
        (cotton["irregularity"], cotton["irregularity_length"] * 1e-3, 0))
    theirs = madder.Simulator(faces, rest, rest, irregularity=cotton["irregularity"],
                              irregularity_length=cotton["irregularity_length"] * 1e-3)
    wet = (np.hypot(co[:, 0], co[:, 1]) < 0.2).astype(np.float32) * 0.5
    for sim in (ours, theirs):
        sim.add_liquid(wet, s.concentration)
        for _ in range(10):
            sim.step(tilted, 1 / 24)
    a, b = ours.densities(), theirs.densities()
    for k in a:
        np.testing.assert_allclose(a[k], b[k], rtol=1e-5, atol=1e-9 * a[k].max(), err_msg=k)
    assert np.abs(ours.velocity).max() > 0  # the slope did set the liquid moving


def test_liquids_stain_differently(addon):
    """Water's faint solute (its tide line's, issue 34 §3) binds nothing; ink binds the most
    solute in the first second, wine (over minutes) and coffee (a small capacity) little."""
    obj, _ = plane(frames=(1, 24))
    deposit, solute = {}, {}
    for name in PRESETS:
        obj.madder.liquid = name
        assert bpy.ops.madder.bake() == {"FINISHED"}
        r = reader(obj)
        deposit[name] = r.read(r.last_frame, "deposit").max()
        solute[name] = r.read(r.last_frame, "solute").max()
        bpy.context.scene.frame_set(r.last_frame)
        stain = np.empty(4 * len(obj.data.vertices), dtype=np.float32)
        shown(obj).attributes["madder_stain"].data.foreach_get("color", stain)
        wet = np.empty(len(obj.data.vertices), dtype=np.float32)
        shown(obj).attributes["madder_wetness"].data.foreach_get("value", wet)
        assert wet.max() == pytest.approx(1.0)  # the spill is above saturation: fully wet
        # a spot above saturation: at least fully stained, by its whole dye amount (water's
        # solute is read by its own strength too)
        s = obj.madder
        dye = min(solute[name] / (s.concentration * s.saturation), 1 + madder.DYE_EXCESS_RANGE)
        assert stain.reshape(-1, 4)[:, 3].max() == pytest.approx(dye, rel=1e-5) and dye > 1.0
    assert deposit["INK"] > max(deposit["RED_WINE"], deposit["COFFEE"]) > 0.0 == deposit["WATER"]
    assert min(deposit["RED_WINE"], deposit["COFFEE"]) > 0.0


def hanging_flag(open_fixture):
    """The flag fixture without its cloth simulation: a still sheet hanging in the XZ plane."""
    scene = open_fixture("flag.blend")
    flag = make_active(bpy.data.objects["Flag"])
    flag.modifiers.remove(next(m for m in flag.modifiers if m.type == "CLOTH"))
    flag.madder.enabled = True
    flag.madder.source_group = "stain_source"
    scene.frame_end = 24
    return scene, flag


def centroid(obj, frame):
    """Solute-weighted centroid (world; the flag is still, so rest = world) at `frame`."""
    r = reader(obj)
    s = r.read(frame, "solute").astype(np.float64)
    co = np.empty(3 * len(obj.data.vertices))
    obj.data.vertices.foreach_get("co", co)
    co = co.reshape(-1, 3) @ np.array(obj.matrix_world)[:3, :3].T + np.array(obj.matrix_world)[:3, 3]
    return (s @ co) / s.sum()  # a regular grid: equal areas inside, so no area weights needed


@pytest.mark.parametrize(
    "gravity, use_gravity, scene_gravity, expected",
    [
        ((0.0, 0.0, -9.81), True, True, (0.0, 0.0, -1.0)),  # down the hanging flag
        ((4.0, 0.0, 0.0), True, True, (1.0, 0.0, 0.0)),  # the scene's gravity, whatever it is
        ((0.0, 0.0, -9.81), False, True, None),  # the object's Gravity off
        ((0.0, 0.0, -9.81), True, False, None),  # the scene's Gravity off
    ],
)
def test_gravity_moves_the_stain_downhill(open_fixture, gravity, use_gravity, scene_gravity, expected):
    scene, flag = hanging_flag(open_fixture)
    scene.gravity, scene.use_gravity = gravity, scene_gravity
    flag.madder.use_gravity = use_gravity
    assert bpy.ops.madder.bake() == {"FINISHED"}
    moved = centroid(flag, scene.frame_end) - centroid(flag, scene.frame_start)
    if expected is None:
        assert np.abs(moved).max() < 2e-3, moved  # diffusion alone keeps the centroid
    else:
        along = moved @ np.array(expected)
        # centimetres in one second (terminal speed g/friction, 0.2 m/s under 1 g, for
        # the liquid the fibres have not soaked up), 5× the bound without gravity
        assert along > 0.01, moved
        assert np.abs(moved - along * np.array(expected)).max() < 0.1 * along, moved


def test_capillary_rise_drains_the_fibres_liquid_down_a_hanging_cloth(open_fixture):
    """Capillary Rise (with Carry Solute, as the Red Wine preset sets it) gives the fibres'
    liquid its weight: on the still hanging flag, the liquid sits lower after the same four
    minutes (24 frames of 10 s) with it than without (the core's tests/drain.rs checks the
    wedge it settles into and its mass)."""
    low = {}
    for rise in (0.0, 10.0):
        scene, flag = hanging_flag(open_fixture)
        flag.madder.liquid = "RED_WINE"
        flag.madder.clock, flag.madder.frame_time = "FRAME_TIME", 10.0
        flag.madder.capillary_rise = rise
        assert flag.madder.liquid == "CUSTOM"  # a value of the look, edited
        assert bpy.ops.madder.bake() == {"FINISHED"}
        r = reader(flag)
        wet = r.read(scene.frame_end, "wetness").astype(np.float64)
        co = np.empty(3 * len(flag.data.vertices))
        flag.data.vertices.foreach_get("co", co)
        z = (co.reshape(-1, 3) @ np.array(flag.matrix_world)[:3, :3].T)[:, 2]
        low[rise] = (wet @ z / wet.sum(),)
    print(f"liquid's mean height: {low[0.0][0]:.4f} m without, {low[10.0][0]:.4f} m with Capillary Rise 10 cm")
    assert low[10.0][0] < low[0.0][0] - 0.05


def object_splash(seed, speed=2.0):
    obj, co = plane(frames=(1, 12))
    obj.madder.splash_speed, obj.madder.splash_seed = speed, seed
    assert bpy.ops.madder.bake() == {"FINISHED"}
    path = bpy.path.abspath(obj.madder.cache_file)
    r = reader(obj)
    return open(path, "rb").read(), r.read(r.last_frame, "wetness").astype(np.float64), co


def test_splash_of_the_initial_wetness_is_reproducible(addon):
    a, wet_a, co = object_splash(seed=11)
    b, _, _ = object_splash(seed=11)
    c, wet_c, _ = object_splash(seed=12)
    _, still, _ = object_splash(seed=11, speed=0.0)
    assert a == b
    assert a != c and np.abs(wet_a - wet_c).max() > 1e-3 * wet_a.max()

    def radius(w):  # about the centroid of the wet area, the origin
        return np.sqrt((w * (co[:, 0] ** 2 + co[:, 1] ** 2)).sum() / w.sum())

    assert radius(wet_a) > 1.1 * radius(still), (radius(wet_a), radius(still))


def test_semi_lagrangian_velocity_and_substeps_bake_and_conserve(open_fixture):
    """The options change the flow, not the bookkeeping: the solute still runs down the
    flag, and none is lost (the flag is still, so the areas are the rest areas)."""
    scene, flag = hanging_flag(open_fixture)
    s = flag.madder
    assert bpy.ops.madder.bake() == {"FINISHED"}
    plain = reader(flag).read(scene.frame_end, "solute")
    s.momentum_advection, s.substeps = False, 3
    assert bpy.ops.madder.bake() == {"FINISHED"}
    r = reader(flag)
    first, last = r.read(scene.frame_start, "solute"), r.read(scene.frame_end, "solute")
    assert np.abs(last - plain).max() > 1e-3 * plain.max()  # they did change the flow
    assert (centroid(flag, scene.frame_end) - centroid(flag, scene.frame_start))[2] < -0.05
    area = lumped_areas(flag.data)  # the flag is still: its own coordinates
    assert area @ last.astype(np.float64) == pytest.approx(area @ first.astype(np.float64), rel=2e-6)
