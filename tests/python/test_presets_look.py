"""Presets carry the look (issue 34), without Blender: what a liquid preset sets, the
fabric presets and their weave tensors (a balanced plain weave is isotropic, twill and
satin spread faster along their floats), the grain of a cloth of several fabrics, and
the Auto choices of Detail and image size."""

import math

import numpy as np
import pytest

import madder
from madder.addon import presets

LOOK = ("wicking", "wicking_iterations", "front_settles", "carry_solute", "residual_saturation", "vapour_limited",
        "carried_fraction", "dispersivity", "holdup", "drip_hold")


@pytest.mark.parametrize("liquid", sorted(presets.LIQUIDS))
def test_a_liquid_preset_sets_its_whole_look(liquid):
    values = presets.object_preset(liquid)
    for key in LOOK:
        assert key in values, key
    # a sharp front: imbibition's diffusivity rises with saturation, iterated until it settles
    assert values["wicking"] >= 1.0 and values["front_settles"] is True
    # runs leave a film behind
    assert values["holdup"] > 0.0
    # and a hanging hem drips what it cannot hold
    assert values["drip_hold"] > 0.0
    assert {k: values[k] for k in presets.RINGS[liquid]} == presets.RINGS[liquid]


def test_coffee_wine_and_water_dry_to_a_rim_and_ink_does_not():
    """Issue 34 §3 (rust/madder/tests/rims.rs measures the rims these values give): the
    liquids whose solute stays mobile pin their edge, dry fastest there and spread the ring
    over a dispersivity of a few millimetres; ink binds its dye within a second."""
    for name in ("COFFEE", "RED_WINE", "WATER"):
        v = presets.LIQUIDS[name]
        assert v["carry_solute"] and v["residual_saturation"] > 0 and v["vapour_limited"], name
        assert v["dispersivity"] >= 1.0 and 0.0 < v["carried_fraction"] <= 1.0, name
    ink = presets.LIQUIDS["INK"]
    assert ink["residual_saturation"] == 0.0 and not ink["vapour_limited"] and ink["dispersivity"] == 0.0
    # water's faint tide line: a tenth of coffee's solute or less, a pale colour
    assert 0.0 < presets.LIQUIDS["WATER"]["concentration"] <= 0.1 * presets.LIQUIDS["COFFEE"]["concentration"]
    assert min(presets.LIQUIDS["WATER"]["stain_color"]) >= 0.8


def tensor(values):
    pairs = ("gap_gap", "weft_weft", "warp_warp", "gap_weft", "gap_warp", "weft_warp")
    t = np.asarray(madder.fabric_tensor(weave=values["weave"], grid=None, gaps=values["gaps"],
                                        coefficients=tuple(values[p] for p in pairs)), dtype=np.float64)
    return t / (0.5 * (t[0] + t[2]))


@pytest.mark.parametrize("weave", ["PLAIN", "BASKET"])
@pytest.mark.parametrize("gaps", [True, False])
def test_balanced_plain_and_basket_weaves_are_isotropic(weave, gaps):
    """Warp and weft the same yarn, and a tile symmetric under swapping them: the
    homogenized tensor is a multiple of the identity (ellipse ratio 1)."""
    ratio, _ = madder.ellipse(tensor(dict(presets.BALANCED, weave=weave, gaps=gaps)))
    assert ratio == pytest.approx(1.0, abs=1e-9)


@pytest.mark.parametrize("name", ["COTTON_PLAIN", "LINEN_PLAIN", "CANVAS_BASKET"])
def test_balanced_fabric_presets_are_isotropic(name):
    ratio, _ = madder.ellipse(tensor(presets.FABRIC_PRESETS[name]))
    assert ratio == pytest.approx(1.0, abs=1e-9)


@pytest.mark.parametrize("name", ["DENIM_TWILL31", "SATIN"])
def test_twill_and_satin_presets_spread_faster_along_one_direction(name):
    ratio, angle = madder.ellipse(tensor(presets.FABRIC_PRESETS[name]))
    print(f"{name}: aspect {ratio:.3f} along {math.degrees(angle):+.1f} deg from the weft")
    assert ratio >= 1.2


def test_the_default_pair_coefficients_are_balanced():
    b = presets.BALANCED
    assert b["weft_weft"] == b["warp_warp"] and b["gap_weft"] == b["gap_warp"]


def test_fabric_presets_set_weave_count_coefficients_speed_and_grain():
    keys = {"weave", "gaps", "thread_count", "speed", "irregularity", "irregularity_length", *presets.BALANCED}
    items = {i[0] for i in presets.FABRIC_PRESET_ITEMS}
    for name, values in presets.FABRIC_PRESETS.items():
        assert set(values) == keys, name
        assert name in items
        assert 0.0 < values["irregularity"] <= 1.0 and values["irregularity_length"] > 0.0
    assert presets.fabric_preset("CUSTOM") is None
    assert presets.FABRIC_PRESETS[presets.DEFAULT_FABRIC]["weave"] == "PLAIN"


def test_the_grain_is_the_fabric_covering_most_of_the_cloth():
    a, b = (0.2, 1.0, 4), (0.7, 5.0, 9)
    assert presets.dominant_grain([a, b], [1.0, 3.0]) == b
    assert presets.dominant_grain([a, b], [3.0, 1.0]) == a
    # faces without a fabric are the default fabric (plain cotton)
    assert presets.dominant_grain([None, b], [3.0, 1.0]) == presets.default_grain()
    assert presets.dominant_grain([], []) == presets.default_grain()
    cotton = presets.FABRIC_PRESETS["COTTON_PLAIN"]
    assert presets.default_grain() == (cotton["irregularity"], cotton["irregularity_length"], 0)


def test_simulator_keywords_take_the_grain_given():
    s = presets.object_preset("RED_WINE")
    s.update(irregularity_fine=0.0, holdup=0.0)
    s.update(viscosity=1e-4, friction=50.0, saturation=0.1, substeps=1, first_substep=0.25, irregularity=0.0,
             irregularity_length=3.0, irregularity_seed=0, use_gravity=True, use_rectilinear=True, use_coriolis=True,
             momentum_advection=True, capillary_rise=0.0)
    from types import SimpleNamespace

    s = SimpleNamespace(**s)
    kw = presets.simulator_keywords(s, (0, 0, -9.81), True, 1.0, grain=(0.5, 6.0, 3))
    assert (kw["irregularity"], kw["irregularity_length"], kw["irregularity_seed"]) == (0.5, 6e-3, 3)
    kw = presets.simulator_keywords(s, (0, 0, -9.81), True, 1.0)
    assert (kw["irregularity"], kw["irregularity_length"], kw["irregularity_seed"]) == (0.0, 3e-3, 0)
    assert kw["wicking_exponent"] == 2.0 and kw["carry_solute"] is True


@pytest.mark.parametrize("edge, vertices, level", [
    (2e-3, 10_000, 0),  # already fine enough
    (4e-3, 10_000, 1),  # 2 mm after one split
    (11e-3, 21_025, 2),  # the demo's tablecloth: 2.75 mm at level 2 (336k vertices)
    (20e-3, 1_000, 3),  # the level cap: 2.5 mm at 3
    (40e-3, 1_000, 3),  # coarser still: the cap
    (11e-3, 100_000, 1),  # the budget: level 2 would be 1.6 M vertices
    (11e-3, 2_000_000, 0),  # already over the budget
])
def test_auto_detail_reaches_the_target_edge_within_the_budget(edge, vertices, level):
    assert presets.auto_detail(edge, vertices) == level
    got = presets.auto_detail(edge, vertices)
    assert got == 0 or vertices * 4**got <= presets.DETAIL_BUDGET
    if got < presets.MAX_DETAIL and vertices * 4 ** (got + 1) <= presets.DETAIL_BUDGET:
        assert edge / 2**got <= presets.DETAIL_TARGET  # a finer level was not needed


def test_auto_detail_refuses_a_degenerate_cloth():
    with pytest.raises(ValueError, match="mean edge"):
        presets.auto_detail(0.0, 10)


def test_auto_detail_applies_unless_a_file_set_its_level():
    assert presets.use_auto_detail(True, False, False)
    assert not presets.use_auto_detail(True, False, True)  # an old file's own Detail
    assert presets.use_auto_detail(True, True, True)  # the user ticked Auto
    assert not presets.use_auto_detail(False, True, False)


def test_auto_image_size_gives_a_texel_of_half_the_refined_edge():
    # a 1 m² cloth over the whole UV square, 2 mm refined edge: 1 mm texels, 1000 px -> 1024
    assert presets.auto_image_size(1.0, 1.0, 2e-3) == 1024
    # half the UV square: a UV unit spans sqrt(2) m -> 1414 px -> 2048
    assert presets.auto_image_size(1.0, 0.5, 2e-3) == 2048
    assert presets.auto_image_size(0.0256, 1.0, 2e-3) == 512  # a 16 cm square
    assert presets.auto_image_size(4.0, 1.0, 1e-3) == 4096  # the cap
    with pytest.raises(ValueError, match="areas"):
        presets.auto_image_size(1.0, 0.0, 1e-3)


def test_a_preset_writer_is_writing_only_while_it_writes_and_after_a_failure_stops():
    writer = presets.PresetWriter()
    seen = []

    class Settings:
        def __setattr__(self, key, value):
            if value == "bad":
                raise ValueError(key)
            seen.append((key, writer.writing))

    writer.write(Settings(), {"wicking": 2.0, "carry_solute": True})
    assert seen == [("wicking", True), ("carry_solute", True)] and not writer.writing
    with pytest.raises(ValueError):
        writer.write(Settings(), {"wicking": "bad"})
    assert not writer.writing
