"""The add-on's bpy-free logic, without Blender: the modules the wheel carries as
`madder.addon.<name>` that never import bpy, directly or through another add-on module
(`bpy_free_modules` finds them from the source), and what they compute (presets and
references, placement in the world, motion-file sampling, pours, the frame schedule, the
add-on's typed errors)."""

import argparse
import ast
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from madder.addon import errors, frames, motion, placement, playback, pour, presets, schedule

ADDON = Path(__file__).resolve().parents[2] / "addon"


def bpy_free_modules():
    """The add-on modules that import bpy neither themselves (anywhere in the file) nor
    through another add-on module, found from their source."""
    imports = {}
    for path in ADDON.glob("*.py"):
        names = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                names |= {a.name.split(".")[0] for a in node.names}
            elif isinstance(node, ast.ImportFrom) and node.level == 0:
                names.add(node.module.split(".")[0])
            elif isinstance(node, ast.ImportFrom) and node.level == 1:  # ".x": the add-on's module x
                targets = [a.name for a in node.names] if node.module is None else [node.module.split(".")[0]]
                names |= {"." + t for t in targets}
        imports[path.stem] = names

    def uses_bpy(name, seen=()):
        own = imports[name]
        return "bpy" in own or any(n[1:] not in seen and uses_bpy(n[1:], (*seen, name))
                                   for n in own if n.startswith(".") and n[1:] in imports)

    return sorted(m for m in imports if m != "__init__" and not uses_bpy(m))


BPY_FREE = bpy_free_modules()


def test_the_logic_modules_import_without_bpy():
    # the list is found from the source; these are the ones the add-on's design relies on
    assert {"bridge", "errors", "lcs", "live", "motion", "placement", "playback", "pour", "presets", "schedule",
            "textures"} <= set(BPY_FREE)
    assert not {"bake", "handlers", "images", "stored", "shading", "reexport"} & set(BPY_FREE)
    code = (
        "import sys; sys.modules['bpy'] = None\n"  # any `import bpy` now raises ImportError
        + "".join(f"import madder.addon.{m}\n" for m in BPY_FREE)
        + "assert not [m for m in sys.modules if m.startswith('bpy') and sys.modules[m] is not None]\n"
    )
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    # and the guard does catch a module that imports bpy
    run = subprocess.run([sys.executable, "-c", "import sys; sys.modules['bpy'] = None\nimport madder.addon.bake"],
                         capture_output=True, text=True)
    assert run.returncode != 0 and "bpy" in run.stderr


# -- presets


def test_presets_write_the_liquid_and_a_source_its_colour_and_concentration():
    assert presets.object_preset("CUSTOM") is None and presets.source_preset("CUSTOM") is None
    ink = presets.object_preset("INK")
    assert ink == presets.LIQUIDS["INK"] and ink is not presets.LIQUIDS["INK"]
    assert presets.source_preset("RED_WINE") == {"concentration": 0.02, "color": (0.30, 0.02, 0.07)}
    assert [i[0] for i in presets.LIQUID_ITEMS] == ["CUSTOM", *presets.LIQUIDS]
    with pytest.raises(KeyError):
        presets.object_preset("MILK")


def test_references_use_the_strongest_liquid_of_the_bake():
    cloth = SimpleNamespace(concentration=0.02, saturation=0.1, capacity=2e-3)
    ink, water = SimpleNamespace(concentration=0.05), SimpleNamespace(concentration=0.0)
    assert presets.references(cloth) == (0.1 * 0.02, 0.1, 2e-3)
    assert presets.references(cloth, [ink, water]) == (0.1 * 0.05, 0.1, 2e-3)
    assert presets.references(cloth, [water], spill=False) == (0.0, 0.1, 2e-3)
    assert presets.references(cloth, [], spill=False) == (0.0, 0.1, 2e-3)


def test_simulator_keywords_scale_gravity_and_need_both_switches():
    s = SimpleNamespace(
        stain_color=[0.1, 0.2, 0.3], viscosity=1e-4, friction=50.0, absorption=2.0, saturation=0.1,
        adsorption=0.1, capacity=2e-3, evaporation=5e-5, evaporation_boundary=1.2, substeps=2,
        use_gravity=True, use_rectilinear=False, use_coriolis=True, momentum_advection=False,
        wicking=2.0, irregularity=0.5, irregularity_length=4.0, irregularity_seed=7, carry_solute=True,
        residual_saturation=0.1, vapour_limited=1, irregularity_fine=0.5, holdup=0.05, drip_hold=5.0,
        capillary_rise=10.0,
        carried_fraction=0.7, dispersivity=3.5, wicking_iterations=2, front_settles=True, first_substep=0.25,
    )
    kw = presets.simulator_keywords(s, (0.0, 0.0, -981.0), True, 0.01)
    # the ramp after a pour in seconds (time is not scaled by the Unit Scale)
    assert kw["first_substep"] == 0.25
    # the fibre scale in metres while below the grain, else off; the run holdup as it is
    assert kw["irregularity_fine_length"] == pytest.approx(5e-4) and kw["holdup"] == 0.05
    # what a hem holds from grams to kilograms per metre
    assert kw["drip_hold"] == pytest.approx(5e-3)
    # the capillary rise from centimetres to metres
    assert kw["capillary_height"] == pytest.approx(0.1)
    # the front iterated until it settles: the core's tolerance, 0 (a fixed count) when off
    assert kw["wicking_picard"] == 2 and kw["wicking_tolerance"] == presets.FRONT_TOLERANCE > 0
    s.front_settles = False
    assert presets.simulator_keywords(s, (0.0, 0.0, -981.0), True, 0.01)["wicking_tolerance"] == 0.0
    # the rim: the carried fraction as it is, the dispersivity from millimetres to metres
    assert kw["carried_fraction"] == 0.7 and kw["dispersivity"] == pytest.approx(3.5e-3)
    s.irregularity_fine = 4.0
    assert presets.simulator_keywords(s, (0.0, 0.0, -981.0), True, 0.01)["irregularity_fine_length"] == 0.0
    # the look: the grain from millimetres to metres, wicking saturating at the fibres'
    assert kw["irregularity_length"] == pytest.approx(4e-3) and kw["wicking_density"] == 0.1
    assert (kw["wicking_exponent"], kw["irregularity"], kw["irregularity_seed"], kw["carry_solute"]) == (
        2.0, 0.5, 7, True)
    assert (kw["residual_saturation"], kw["vapour_limited"]) == (0.1, True)
    assert kw["wicking_picard"] == 2
    assert kw["gravity"] == (0.0, 0.0, -981.0 * 0.01) and kw["color"] == (0.1, 0.2, 0.3)
    assert kw["use_gravity"] is True and kw["use_rectilinear"] is False and kw["substeps"] == 2
    assert presets.simulator_keywords(s, (0, 0, -9.81), False, 1.0)["use_gravity"] is False
    s.use_gravity = False
    assert presets.simulator_keywords(s, (0, 0, -9.81), True, 1.0)["use_gravity"] is False


# -- placement


def test_unit_scale_applies_unless_the_unit_system_is_none():
    assert placement.unit_scale("METRIC", 0.01) == 0.01
    assert placement.unit_scale("IMPERIAL", 0.3048) == 0.3048
    assert placement.unit_scale("NONE", 0.01) == 1.0


def test_placed_transforms_then_scales_to_metres():
    m = np.array([[0, -2, 0, 1], [2, 0, 0, 2], [0, 0, 2, 3], [0, 0, 0, 1]], dtype=float)  # turn 90°, scale 2
    got = placement.placed([[1.0, 0, 0], [0, 1.0, 0.5]], m, 0.5)
    assert got.dtype == np.float32
    np.testing.assert_array_equal(got, [[0.5, 2.0, 1.5], [-0.5, 1.0, 2.0]])


def test_a_transform_that_collapses_the_cloth_is_refused_with_object_and_frame():
    local = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], dtype=float)  # in the xy plane
    faces = np.array([[0, 1, 2], [0, 2, 3]])
    placement.check_transform("Flag", 3, faces, local, np.diag([1.0, 1.0, 0.0, 1.0]))  # z: keeps its area
    placement.check_transform("Flag", 3, faces, local, np.diag([2.0, 3.0, 4.0, 1.0]))
    with pytest.raises(errors.BakeError, match=r"'Flag' at frame 7: its object scale \(1, 0, 1\)") as e:
        placement.check_transform("Flag", 7, faces, local, np.diag([1.0, 0.0, 1.0, 1.0]))
    assert (e.value.object, e.value.frame) == ("Flag", 7)
    bad = np.eye(4)
    bad[0, 3] = np.nan
    with pytest.raises(errors.BakeError, match="not finite") as e:
        placement.check_transform("Flag", -2, faces, local, bad)
    assert e.value.frame == -2
    assert placement.first_non_finite(local) is None
    local[2, 1] = np.inf
    assert placement.first_non_finite(local) == 2


# -- motion files


class Samples:
    """A point cache whose sample k holds k everywhere (2 points)."""

    n_frames = 5

    def __init__(self, broken=None):
        self.broken, self.read = broken, []

    def read_frame(self, k):
        self.read.append(k)
        if k == self.broken:
            raise OSError(f"x.pc2: frame {k} is corrupt")
        return np.full((2, 3), float(k), dtype=np.float32)


def test_motion_samples_follow_the_mesh_cache_modifier():
    m = motion.MotionSamples(Samples(), "Flag", "/tmp/x.pc2", offset=0.5, scale=0.5)
    assert [m.sample(f) for f in (1, 2, 5)] == [0.0, 0.5, 2.0]
    np.testing.assert_array_equal(m.local(4), np.full((2, 3), 1.5))  # between samples 1 and 2
    np.testing.assert_array_equal(m.local(5), np.full((2, 3), 2.0))
    np.testing.assert_array_equal(m.local(-7), np.zeros((2, 3)))  # held at the first sample
    np.testing.assert_array_equal(m.local(40), np.full((2, 3), 4.0))  # and the last
    assert m.outside(1, 9) is None
    msg = m.outside(-1, 12)
    assert msg.startswith("5 frames (-1…12) read past the 5 samples of its motion file x.pc2")


def test_a_bad_sample_is_a_bake_error_naming_the_scene_frame():
    m = motion.MotionSamples(Samples(broken=3), "Flag", "/tmp/x.pc2")
    m.local(2)
    with pytest.raises(errors.BakeError) as e:
        m.local(3)
    assert str(e.value) == "'Flag' at frame 3: x.pc2: sample 3 is corrupt"
    assert (e.value.object, e.value.frame) == ("Flag", 3)


def modifier(**kw):
    defaults = dict(name="MeshCache", time_mode="FRAME", play_mode="SCENE", forward_axis="POS_Y",
                    up_axis="POS_Z", flip_axis=(False, False, False), factor=1.0, vertex_group="",
                    deform_mode="OVERWRITE", interpolation="LINEAR", frame_start=2.0, frame_scale=0.5)
    return SimpleNamespace(**{**defaults, **kw})


def test_the_mesh_cache_modifier_gives_the_timing_or_is_refused():
    assert motion.modifier_timing("Flag", modifier()) == (2.0, 0.5)
    assert motion.modifier_timing("Flag", modifier(flip_axis=set())) == (2.0, 0.5)  # Blender < 5.0
    with pytest.raises(errors.BakeError, match="Time Mode 'Time' and Play Mode 'Scene'") as e:
        motion.modifier_timing("Flag", modifier(time_mode="TIME"))
    assert e.value.object == "Flag" and e.value.frame is None
    with pytest.raises(errors.BakeError, match=r"\(Flip Axis, Influence\)"):
        motion.modifier_timing("Flag", modifier(flip_axis={"X"}, vertex_group="pin"))


# -- pours


def test_pour_falls_off_linearly_to_the_reach():
    w = pour.falloff(np.array([0.0, 0.01, 0.02, 0.03, np.inf], dtype=np.float32), 0.02)
    assert w.dtype == np.float32
    np.testing.assert_allclose(w, [1.0, 0.5, 0.0, 0.0, 0.0], rtol=1e-7)
    np.testing.assert_array_equal(pour.poured(0.2, 0.5, np.float32([1.0, 0.5])), np.float32([0.1, 0.05]))
    np.testing.assert_array_equal(pour.spilled(np.float32([1.0, 0.25]), 2.0), np.float32([2.0, 0.5]))
    assert [pour.pours_at(f, True, 2, 4) for f in (1, 2, 4, 5)] == [False, True, True, False]
    assert pour.pours_at(-100, False, 2, 4)


def test_the_splash_starts_at_the_weighted_centroid():
    pos = np.float32([[0, 0, 0], [4, 0, 0], [0, 8, 0]])
    assert pour.centroid(np.float32([1, 1, 0]), pos) == (2.0, 0.0, 0.0)
    assert pour.centroid(np.float32([1, 0, 3]), pos) == (0.0, 6.0, 0.0)


# -- the frame schedule


def test_every_frame_is_visited_once_in_order_with_one_frame_lookahead():
    visits = []

    def visit(f):
        visits.append(f)
        return f * 10

    walk, first, last = schedule.Lookahead(visit), 3, 7
    steps = []
    for f in range(first + 1, last + 1):  # as BakeJob.step does after the first frame
        now = walk.take(f)
        after = walk.peek(f + 1) if f < last else None
        steps.append((now, after))
    assert visits == [4, 5, 6, 7]
    assert steps == [(40, 50), (50, 60), (60, 70), (70, None)]
    assert walk.take(9) == 90 and walk.take(9) == 90 and visits[-2:] == [9, 9]  # not kept once taken


def test_addon_errors_carry_their_fields():
    e = errors.BakeError("'Cloth' at frame 4: boom", object="Cloth", frame=4, vertex=17)
    assert (str(e), e.object, e.frame, e.vertex) == ("'Cloth' at frame 4: boom", "Cloth", 4, 17)
    assert errors.BakeError("no object").object is None
    assert errors.RelocateError("x", object="A", filename="/c.madder").filename == "/c.madder"
    assert not issubclass(errors.BakeError, ValueError)


# -- frame numbers


@pytest.mark.parametrize("text, want", [("7", (7, 7)), ("1-250", (1, 250)), ("-5-3", (-5, 3)),
                                        ("-5--1", (-5, -1)), (" 2 - 4 ", (2, 4))])
def test_frame_ranges_parse_with_negative_frames(text, want):
    assert frames.parse_range(text) == want


@pytest.mark.parametrize("text", ["", "a-b", "5-3", "1-2-3", "1..4"])
def test_bad_frame_ranges_are_usage_errors(text):
    with pytest.raises(argparse.ArgumentTypeError):
        frames.parse_range(text)


def test_negative_frame_arguments_are_joined_and_frame_lists_shortened():
    assert frames.join_frames(["bake", "--frames", "-5-3", "--all"]) == ["bake", "--frames=-5-3", "--all"]
    assert frames.join_frames(["--frames"]) == ["--frames"]
    assert frames.ranges([1, 2, 3, 7, 9, 10]) == "1–3, 7, 9–10"
    assert frames.ranges([-2]) == "-2" and frames.ranges([]) == ""


# -- playback


def reader(cut=None, n=4, fields=("solute", "wetness", "deposit")):
    return SimpleNamespace(n_vertices=n, fields=list(fields), first_frame=3, last_frame=9, truncated_at=cut)


def test_playback_refuses_a_cache_of_another_mesh():
    assert playback.mismatch("/c.madder", reader(), 4) is None
    assert playback.mismatch("/c.madder", reader(), 5) == (
        "Stale cache: /c.madder holds 4 vertices, the mesh has 5 (edited after the bake?): bake again")
    assert "has no 'deposit' field" in playback.mismatch("/c.madder", reader(fields=("solute", "wetness")), 4)


def test_playback_clamps_the_frame_and_never_reads_past_damage():
    whole = reader()
    assert [playback.frame_to_read("/c", whole, f, {}) for f in (1, 3, 6, 9, 20)] == [
        (None, 3), (None, 3), (None, 6), (None, 9), (None, 9)]
    cut = reader(cut=7)
    assert playback.frame_to_read("/c", cut, 6, {}) == (None, 6)
    why, at = playback.frame_to_read("/c", cut, 12, {})
    assert at is None and why == "Damaged cache: /c is truncated at frame 7 (frames 3–6 play): bake again"
    why, at = playback.frame_to_read("/c", whole, 5, {5: "/c: frame 5 is corrupt"})
    assert (why, at) == ("Damaged cache: /c: frame 5 is corrupt: bake again", None)
    assert playback.truncation(whole) is None
    assert playback.truncation(cut) == "Cache truncated at frame 7: frames 7–9 show no stain (bake again)"
