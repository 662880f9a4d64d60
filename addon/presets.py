"""The liquid presets, the references playback normalizes by, and the simulator's keyword
arguments: plain data and functions of the settings, bpy-free (tested without Blender in
tests/python). `properties.py` turns them into Blender properties.

Units are SI throughout, as in the Rust core: densities in kg/m², rates in 1/s,
diffusion and viscosity in m²/s.

Liquid presets. Order-of-magnitude estimates, not measurements (the seed gives only the
evaporation boundary coefficient, 1.2); they make the four liquids behave differently
in the ways one expects, and are meant to be tuned. What a preset sets is the liquid:
its solute (colour, concentration) and how that solute and its solvent interact with
the fibres. The cloth's own properties (saturation, friction) and the flow
(diffusion, viscosity) are left alone.

- Water: a trace of solute, 1e-3 (a twelfth of coffee's) of a pale brown (0.95, 0.92,
  0.85): even pure water leaves a faint brown tide line on cellulose, from the fibres'
  water-soluble degradation products (and soil) it carries to the drying edge (Hutchins
  1983, "Water-stained cellulosics: a literature review", JAIC 22(2): 57–61); no
  adsorption; the core's default rates (it wicks into thin cotton in about 0.5 s,
  K_p = 2 /s; dries at 5e-5 kg/(m²·s), still room air). A saturated spot of it is a
  barely visible tint; its ring, a few times the centre's solute, a faint line.
- Red wine: about 2 % dissolved solids by mass (extract: sugars, acids, tannins,
  anthocyanins), deep red (0.30, 0.02, 0.07). Its pigments bind to cotton over minutes,
  not seconds (a fresh wine stain still rinses out; it sets as it dries), and only part
  of the extract binds at all (the sugars and acids do not): adsorption K_d = 0.005 /s,
  capacity 1e-3 kg/m² (half the solute of a saturated spot). Both are tuned, within those
  orders of magnitude, to the modest rim of issue 34 (rim/centre 1.1–1.6,
  rust/madder/tests/rims.rs), not measured. The ethanol makes it evaporate a little
  faster than water (6e-5).
- Coffee: about 1.2 % dissolved solids (a typical brew's TDS), brown (0.25, 0.13, 0.05).
  Its colloids hardly bind to the fibres (K_d = 0.05 /s, capacity 2e-4: a sixth of the
  solute of a saturated spot), so they stay in the liquid until it dries, and it rings:
  the solute is carried by the liquid's flow (carry_solute), the wet edge is pinned
  (residual saturation 0.1: liquid below a tenth of the fibres' saturation stays put)
  and the patch dries fastest at its edge (vapour-limited), so the liquid flows outward
  and leaves its solute in a tide line (ARCHITECTURE.md, "Tide lines").
- The rim (issue 34 §3): Coffee, Red Wine and Water dry the same way (TIDE_LINES), and
  differ by how much of their solute is still mobile when the edge dries (coffee's
  colloids almost all, wine's pigments the part not yet bound). The carried solute
  spreads back against the flow over a dispersivity of 3.5 mm (mechanical dispersion,
  Bear 1972: of the order of the medium's heterogeneity, here a few yarn spacings), so
  the ring is about 2 mm wide at any Detail instead of one cell; the carried fraction is
  1 (all of the dissolved solute moves with the liquid). Ink binds its dye within a
  second to a capacity above the solute of a saturated spot, so it does not ring.
- Ink: about 5 % dye, blue-black (0.04, 0.05, 0.15). Surfactants make it wick faster
  (K_p = 3 /s), dyes are made to bind: fast adsorption (K_d = 1 /s) and a high
  capacity (5e-3 kg/m²); humectants (glycols) slow its drying (4e-5).

A preset carries the whole look of its liquid (issue 34), not only its solute:

- Wicking 2 for every liquid: the fibres draw liquid in at the spreading rate times
  saturation², so a spill has a sharp front that slows as it thins. Capillary imbibition
  in a porous sheet is a nonlinear diffusion whose diffusivity rises steeply with the
  saturation (Richards' equation with a power-law D(S), e.g. Brutsaert 1979: exponents of
  2 to 8); 2 is the gentlest that gives the front (physics.md, "Wicking").
- Front Iterations 2 for every liquid, Until Settled: each step is solved again with the
  rate of its own solution, at least twice and on until the front stops moving. With the
  rate of the step's start the front crosses one ring of faces per step, so it runs about
  9 % slow and takes the mesh's shape (a spot on a structured grid dried a rounded
  square, 4-fold term 3.4 %); with 2 the term is 0.5 % at short steps, but a long step
  still held the front to three rings (the demo's 45-s frames: the table-top patch
  stopped at a straight edge); iterated until settled it spreads as far as the step
  takes it (rust/madder/tests/outlines.rs, docs/physics.md "Wicking"), for about 1.8
  times the demo's bake.
- How it rings, kept together per liquid in `RINGS`: Coffee, Red Wine and Water ring
  (see above, rims.rs measures them); Ink does not.
- How it runs (issue 34 §1): a Run Holdup of 0.05 kg/m² for every liquid, a film of
  50 µm pinned in the weave's pores that a run fills before it moves on and leaves
  behind to soak in and stain the path, so a run stops when its excess over the film
  (and over what the fibres take) is used up instead of trickling on forever (the
  static holdup of packed and trickle-bed flow; the value is an estimate, not measured;
  rust/madder/tests/runs.rs measures a fed run with it); and a hanging hem that holds
  5 g of free liquid per metre before it drips (Hem Holds; what drips leaves the cloth),
  about a pendant drop's 46 mg (Tate's law, `2π r γ / g` at r = 1 mm, γ = 0.072 N/m) per
  centimetre of hem (an estimate): without it a hem gathers all that runs down to it, and
  that pile wicks back up the cloth while it dries. The weight of the fibres' liquid
  (Capillary Rise) is left off: Jurin's `2γ / (ρ g r)` for the yarns' pores (r ≈ 0.15 mm,
  an estimate) gives about 10 cm for water and 7 for wine, but with it the demo's hanging
  run drains down the front and siphons the table-top patch's liquid over the rim, which
  then dries without the tide line along its edge; whether a draped tablecloth does that
  is not yet checked against references (ARCHITECTURE.md, Open questions). The flow's
  viscosity and the
  fibres' friction are the cloth's and the flow's (left alone), so the four liquids run
  alike.
- Sub-steps: none of the four needs more than the automatic choice (the core adds steps
  where the cloth turns fast), so a preset leaves Substeps alone.

Fabric presets (`FABRICS`, what `fabrics.py`'s Fabric Preset writes) are in
`FABRIC_PRESETS` below, with their sources."""

import math

# the drying that makes tide lines (issue 13 §2) and its rim (issue 34 §3): the solute
# carried by the flow to a pinned edge that dries fastest, spread back against the flow
# over the dispersivity (mm); every liquid with a solute that stays mobile rings
TIDE_LINES = dict(carry_solute=True, residual_saturation=0.1, vapour_limited=True, carried_fraction=1.0,
                  dispersivity=3.5)
NO_TIDE_LINES = dict(carry_solute=False, residual_saturation=0.0, vapour_limited=False, carried_fraction=1.0,
                     dispersivity=0.0)
# how each liquid rings, kept together so that a rim model can tune them per liquid
RINGS = {
    "WATER": TIDE_LINES,
    "RED_WINE": TIDE_LINES,
    "COFFEE": TIDE_LINES,
    "INK": NO_TIDE_LINES,
}
# the front: the fibres draw liquid in at the spreading rate × saturation^wicking, the
# rate taken from each step's own solution after that many extra solves
WICKING = {"WATER": 2.0, "RED_WINE": 2.0, "COFFEE": 2.0, "INK": 2.0}
FRONT_ITERATIONS = 2
# ... and on until the front settles: no face's rate changes by more than this share of
# the largest between two solves (the core's `Wicking::tolerance`)
FRONT_SETTLES = True
FRONT_TOLERANCE = 1e-3
# how it runs: the film (kg/m²) a run leaves behind in the weave's pores
HOLDUP = {"WATER": 0.05, "RED_WINE": 0.05, "COFFEE": 0.05, "INK": 0.05}
# ... and what a hanging hem holds before it drips, g/m
DRIP = {"WATER": 5.0, "RED_WINE": 5.0, "COFFEE": 5.0, "INK": 5.0}

LIQUIDS = {
    "WATER": dict(
        stain_color=(0.95, 0.92, 0.85), concentration=1e-3, absorption=2.0, adsorption=0.0,
        capacity=2e-3, evaporation=5e-5, evaporation_boundary=1.2, **RINGS["WATER"], wicking=WICKING["WATER"],
        wicking_iterations=FRONT_ITERATIONS,
        front_settles=FRONT_SETTLES, holdup=HOLDUP["WATER"], drip_hold=DRIP["WATER"],
    ),
    "RED_WINE": dict(
        stain_color=(0.30, 0.02, 0.07), concentration=0.02, absorption=2.0, adsorption=0.005,
        capacity=1e-3, evaporation=6e-5, evaporation_boundary=1.2, **RINGS["RED_WINE"],
        wicking=WICKING["RED_WINE"],
        wicking_iterations=FRONT_ITERATIONS,
        front_settles=FRONT_SETTLES, holdup=HOLDUP["RED_WINE"], drip_hold=DRIP["RED_WINE"],
    ),
    "COFFEE": dict(
        stain_color=(0.25, 0.13, 0.05), concentration=0.012, absorption=2.0, adsorption=0.05,
        capacity=2e-4, evaporation=5e-5, evaporation_boundary=1.5, **RINGS["COFFEE"], wicking=WICKING["COFFEE"],
        wicking_iterations=FRONT_ITERATIONS,
        front_settles=FRONT_SETTLES, holdup=HOLDUP["COFFEE"], drip_hold=DRIP["COFFEE"],
    ),
    "INK": dict(
        stain_color=(0.04, 0.05, 0.15), concentration=0.05, absorption=3.0, adsorption=1.0,
        capacity=5e-3, evaporation=4e-5, evaporation_boundary=1.2, **RINGS["INK"], wicking=WICKING["INK"],
        wicking_iterations=FRONT_ITERATIONS,
        front_settles=FRONT_SETTLES, holdup=HOLDUP["INK"], drip_hold=DRIP["INK"],
    ),
}
LIQUID_ITEMS = [
    ("CUSTOM", "Custom", "Your own values (any change to a preset's value switches to Custom)"),
    ("WATER", "Water", "Wets the cloth and dries to a faint brown tide line"),
    ("RED_WINE", "Red Wine", "Deep red, binds to the fibres over minutes, a modest rim"),
    ("COFFEE", "Coffee", "Brown, binds weakly to the fibres, dries faster at the rim"),
    ("INK", "Ink", "Blue-black, concentrated, wicks and binds fast"),
]
# what a source's preset sets (the rates belong to the cloth it pours on)
SOURCE_PRESET_KEYS = ("concentration", "stain_color")


class PresetWriter:
    """Writes a preset's values to a block of settings. While it writes, `writing` is True,
    so the settings' update callbacks can tell a preset's write from a user's edit (which
    switches the preset to Custom). One writer per kind of preset (liquid, fabric)."""

    def __init__(self):
        self.writing = False

    def write(self, settings, values):
        self.writing = True
        try:
            for key, value in values.items():
                setattr(settings, key, value)
        finally:
            self.writing = False


def object_preset(liquid):
    """The settings a cloth's preset `liquid` writes (None for CUSTOM: nothing)."""
    return None if liquid == "CUSTOM" else dict(LIQUIDS[liquid])


def source_preset(liquid):
    """The settings a source's preset `liquid` writes, by the source's property names (its
    colour is `color`), or None for CUSTOM."""
    if liquid == "CUSTOM":
        return None
    values = LIQUIDS[liquid]
    return {("color" if k == "stain_color" else k): values[k] for k in SOURCE_PRESET_KEYS}


def references(settings, sources=(), spill=True):
    """The densities (kg/m²) that playback reads as full, `(solute, liquid, deposit)`, for
    an object's `settings` and the `sources` (their `madder_source` settings) of a bake:

    - solute: `saturation × c`, `c` the largest concentration among the liquids of the
      bake (the object's own spill if `spill`, and each source's): a spot whose fibres are
      saturated with the strongest liquid reads as fully stained. 0 when no liquid has
      any solute (then nothing can stain).
    - liquid: `saturation`: fibres holding all the liquid they can read as fully wet.
    - deposit: `capacity`: fibres that bound all the solute they can read as fully marked.
    """
    c = max([settings.concentration] * bool(spill) + [s.concentration for s in sources], default=0.0)
    return (settings.saturation * c, settings.saturation, settings.capacity)


def simulator_keywords(s, gravity, scene_gravity, unit, grain=None):
    """Keyword arguments of `madder.Simulator` from an object's settings `s` (SI units),
    the scene's `gravity` vector (scene units per s², scaled by `unit`, metres per unit,
    like the positions) and whether the scene's gravity is on (`scene_gravity`: the
    liquid feels gravity only when both it and the object's Gravity are on). `grain` is
    `(irregularity, length in mm, seed)`, the cloth's fabric's (`dominant_grain`); None
    takes the object's own Irregularity settings."""
    if grain is None:
        grain = (s.irregularity, s.irregularity_length, s.irregularity_seed)
    return dict(
        color=tuple(s.stain_color),
        gravity=tuple(g * unit for g in gravity),
        viscosity=s.viscosity,
        friction=s.friction,
        absorption=s.absorption,
        saturation=s.saturation,
        adsorption=s.adsorption,
        capacity=s.capacity,
        evaporation=s.evaporation,
        evaporation_boundary=s.evaporation_boundary,
        substeps=s.substeps,
        first_substep=s.first_substep,
        # the look (issue 13): wicking saturates at the fibres' saturation; the grain is set
        # in millimetres of the cloth's rest surface
        wicking_exponent=s.wicking,
        wicking_density=max(s.saturation, 1e-6),
        wicking_picard=s.wicking_iterations,
        wicking_tolerance=FRONT_TOLERANCE if s.front_settles else 0.0,
        irregularity=grain[0],
        irregularity_length=grain[1] * 1e-3,
        irregularity_seed=grain[2],
        irregularity_fine_length=(
            s.irregularity_fine * 1e-3 if 0.0 < s.irregularity_fine < grain[1] else 0.0
        ),
        carry_solute=bool(s.carry_solute),
        residual_saturation=s.residual_saturation,
        vapour_limited=bool(s.vapour_limited),
        # the rim (issue 34 §3): the dispersivity is set in millimetres of cloth
        carried_fraction=s.carried_fraction,
        dispersivity=s.dispersivity * 1e-3,
        holdup=s.holdup,
        # the hem (issue 34 §1): from grams to kilograms per metre of cloth
        drip_hold=s.drip_hold * 1e-3,
        # the weight of the fibres' liquid: from centimetres of cloth to metres
        capillary_height=s.capillary_rise * 1e-2,
        use_gravity=bool(s.use_gravity and scene_gravity),
        use_rectilinear=s.use_rectilinear,
        use_coriolis=s.use_coriolis,
        momentum_advection=s.momentum_advection,
    )


# -- Fabric presets (issue 34): what a Fabric Preset writes on a material's Madder fabric.
#
# Thread counts are typical of the cloths named (ends and picks per centimetre: a cotton
# percale/sheeting of 100–140 threads per inch summed over warp and weft, so about 25/cm
# each way; a household linen of 12–20/cm; denim 3/1 twill about 25 ends × 18 picks/cm;
# a 5-harness cotton sateen 40/cm; canvas duck about 10/cm of plied yarn) — Kadolph,
# *Textiles* (11th ed., 2010), ch. 11–12 (weaves and their thread counts).
#
# Pair coefficients (the seed's ch. 2.2.1 relative permeabilities between cells): a
# yarn conducts along itself best (its fibres lie along it: 300), liquid passes from a
# warp yarn to a weft yarn only through their contact at a crossing (100, a third), and
# a gap hardly conducts (30 next to a yarn, 1 between gaps). Warp and weft of the same
# fibre are the same yarn, so every preset is balanced (warp_warp = weft_weft, gap_warp
# = gap_weft): a balanced plain or basket weave is then isotropic (its tile is symmetric
# under swapping warp and weft), and a twill or a satin is anisotropic through its
# floats alone, the yarn runs that cross several yarns of the other set without an
# interlacing (aspect 1.35 for twill 2/1, 1.58 for 3/1, 1.72 for the 5-harness satin,
# nearly along the warp; tests/python/test_presets_look.py). In-plane wicking does differ
# between warp and weft when their yarns differ in count, twist or packing (Kissa,
# "Wetting and wicking", Textile Res. J. 66, 1996; Nyoni & Brook, J. Textile Inst. 97,
# 2006: wicking falls as yarn twist rises), which a user can set per direction; the
# presets have no measured ratio for it and leave warp and weft equal. The values are
# relative (the fabric's tensor is normalized to mean eigenvalue 1 and scaled by the
# cloth's Diffusion and the fabric's Speed).
#
# Grain: how uneven the fabric is (the random field of the core's irregularity: an
# amplitude 0–1 and a correlation length), a few thread pitches to a few millimetres,
# longer for linen's slubbed yarns, shorter for a smooth satin.
BALANCED = dict(gap_gap=1.0, weft_weft=300.0, warp_warp=300.0, gap_weft=30.0, gap_warp=30.0, weft_warp=100.0)
FABRIC_PRESETS = {
    "COTTON_PLAIN": dict(weave="PLAIN", gaps=True, thread_count=25.0, speed=1.0, **BALANCED,
                         irregularity=0.5, irregularity_length=3.0),
    "LINEN_PLAIN": dict(weave="PLAIN", gaps=True, thread_count=15.0, speed=1.3, **BALANCED,
                        irregularity=0.6, irregularity_length=6.0),
    "DENIM_TWILL31": dict(weave="TWILL31", gaps=True, thread_count=25.0, speed=0.8, **BALANCED,
                          irregularity=0.5, irregularity_length=4.0),
    "SATIN": dict(weave="SATIN5", gaps=True, thread_count=40.0, speed=1.0, **BALANCED,
                  irregularity=0.3, irregularity_length=2.0),
    "CANVAS_BASKET": dict(weave="BASKET", gaps=True, thread_count=10.0, speed=0.9, **BALANCED,
                          irregularity=0.5, irregularity_length=5.0),
}
FABRIC_PRESET_ITEMS = [
    ("CUSTOM", "Custom", "Your own weave and values"),
    ("COTTON_PLAIN", "Cotton (plain)", "Plain-weave cotton sheeting, 25 threads/cm, balanced"),
    ("LINEN_PLAIN", "Linen (plain)", "Plain-weave linen, 15 threads/cm, balanced, slubby grain"),
    ("DENIM_TWILL31", "Denim (twill 3/1)", "3/1 twill, 25 threads/cm: spreads faster along its floats"),
    ("SATIN", "Satin (5-harness)", "5-harness satin, 40 threads/cm, smooth"),
    ("CANVAS_BASKET", "Canvas (basket)", "2/2 basket weave, 10 threads/cm of plied yarn"),
]
# a cloth whose faces have no Madder fabric is this cloth (its grain; a balanced plain
# weave spreads isotropically, so no tensor is needed)
DEFAULT_FABRIC = "COTTON_PLAIN"


def fabric_preset(name):
    """The values a fabric preset `name` writes (None for CUSTOM)."""
    return None if name == "CUSTOM" else dict(FABRIC_PRESETS[name])


def default_grain():
    """`(amplitude, length in mm, seed)` of the default fabric."""
    f = FABRIC_PRESETS[DEFAULT_FABRIC]
    return (f["irregularity"], f["irregularity_length"], 0)


def dominant_grain(grains, areas):
    """The grain of the fabric covering most of the cloth: `grains` a list of
    `(amplitude, length mm, seed)` per material slot (None: no fabric there, the default
    fabric's grain), `areas` the cloth's rest area per slot. The core has one
    irregularity field per object, so a cloth of several fabrics takes the largest one's."""
    if not grains:
        return default_grain()
    best = max(range(len(grains)), key=lambda i: (areas[i] if i < len(areas) else 0.0, -i))
    return grains[best] if grains[best] is not None else default_grain()


# -- Detail and image size chosen from the cloth (issue 34)
DETAIL_TARGET = 2.5e-3  # m: the refined mean edge the stain should reach (millimetre features)
DETAIL_BUDGET = 1_000_000  # refined vertices at most (about 0.5 GB of simulator state and cache buffers)
MAX_DETAIL = 3


def auto_detail(mean_edge, n_vertices, target=DETAIL_TARGET, budget=DETAIL_BUDGET, max_level=MAX_DETAIL):
    """The smallest Detail level whose refined mean edge `mean_edge / 2^L` is ≤ `target`
    (metres), lowered until the refined mesh's vertices (about `n_vertices · 4^L`) are
    ≤ `budget`; within 0..`max_level`."""
    if not (mean_edge > 0.0) or n_vertices <= 0:
        raise ValueError(f"auto detail needs a positive mean edge and vertex count (got {mean_edge}, {n_vertices})")
    level = 0
    while level < max_level and mean_edge / 2**level > target:
        level += 1
    while level > 0 and n_vertices * 4**level > budget:
        level -= 1
    return level


def use_auto_detail(detail_auto, auto_set, detail_set):
    """Whether the bake chooses Detail itself: the Auto switch when the user set it,
    else Auto unless the file set a Detail level by hand (files saved before Auto keep
    their level)."""
    return bool(detail_auto) if auto_set else not detail_set


def auto_image_size(surface_area, uv_area, refined_edge, sizes=(512, 1024, 2048, 4096)):
    """The image size (px) whose texel is at most half the refined mean edge on the cloth:
    the cloth's `surface_area` (m²) covers `uv_area` of the unit UV square, so one UV
    unit spans `sqrt(surface_area / uv_area)` metres; the smallest of `sizes` reaching
    that texel, else the largest."""
    if not (surface_area > 0.0 and uv_area > 0.0 and refined_edge > 0.0):
        raise ValueError(f"auto image size needs positive areas and edge (got {surface_area}, {uv_area}, "
                         f"{refined_edge})")
    need = math.sqrt(surface_area / uv_area) / (0.5 * refined_edge)
    for n in sizes:
        if n >= need:
            return n
    return sizes[-1]
