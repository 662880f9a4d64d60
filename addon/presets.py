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

- Water: no solute (concentration 0, so it leaves no stain, only wetness), a white-ish
  colour for completeness, no adsorption; the core's default rates (it wicks into thin
  cotton in about 0.5 s, K_p = 2 /s; dries at 5e-5 kg/(m²·s), still room air).
- Red wine: about 2 % dissolved solids by mass (extract: sugars, acids, tannins,
  anthocyanins), deep red (0.30, 0.02, 0.07). Anthocyanins and tannins bind strongly
  to cellulose: fast adsorption (K_d = 0.5 /s), the default capacity. The ethanol
  makes it evaporate a little faster than water (6e-5).
- Coffee: about 1.2 % dissolved solids (a typical brew's TDS), brown (0.25, 0.13, 0.05).
  Its colloids hardly bind to the fibres (K_d = 0.05 /s, capacity 2e-4: a sixth of the
  solute of a saturated spot), so they stay in the liquid until it dries, and it rings:
  the solute is carried by the liquid's flow (carry_solute), the wet edge is pinned
  (residual saturation 0.1: liquid below a tenth of the fibres' saturation stays put)
  and the patch dries fastest at its edge (vapour-limited), so the liquid flows outward
  and leaves its solute in a tide line (ARCHITECTURE.md, "Tide lines").
- The tide-line physics is Coffee's only. Wine and ink bind their dyes within seconds
  to a capacity at or above the solute of a saturated spot, so the dye is fixed where
  the spill put it before the outward flow can move it (no ring to gain, and the drying
  flow costs a second solve per step); water has no solute. They set it off, so that
  switching from Coffee to another liquid switches it off.
- Ink: about 5 % dye, blue-black (0.04, 0.05, 0.15). Surfactants make it wick faster
  (K_p = 3 /s), dyes are made to bind: fast adsorption (K_d = 1 /s) and a high
  capacity (5e-3 kg/m²); humectants (glycols) slow its drying (4e-5)."""

# the drying that makes tide lines (issue 13 §2): Coffee's; the others set it off
TIDE_LINES = dict(carry_solute=True, residual_saturation=0.1, vapour_limited=True)
NO_TIDE_LINES = dict(carry_solute=False, residual_saturation=0.0, vapour_limited=False)

LIQUIDS = {
    "WATER": dict(
        stain_color=(0.90, 0.93, 0.95), concentration=0.0, absorption=2.0, adsorption=0.0,
        capacity=2e-3, evaporation=5e-5, evaporation_boundary=1.2, **NO_TIDE_LINES,
    ),
    "RED_WINE": dict(
        stain_color=(0.30, 0.02, 0.07), concentration=0.02, absorption=2.0, adsorption=0.5,
        capacity=2e-3, evaporation=6e-5, evaporation_boundary=1.2, **NO_TIDE_LINES,
    ),
    "COFFEE": dict(
        stain_color=(0.25, 0.13, 0.05), concentration=0.012, absorption=2.0, adsorption=0.05,
        capacity=2e-4, evaporation=5e-5, evaporation_boundary=1.5, **TIDE_LINES,
    ),
    "INK": dict(
        stain_color=(0.04, 0.05, 0.15), concentration=0.05, absorption=3.0, adsorption=1.0,
        capacity=5e-3, evaporation=4e-5, evaporation_boundary=1.2, **NO_TIDE_LINES,
    ),
}
LIQUID_ITEMS = [
    ("CUSTOM", "Custom", "Your own values (any change to a preset's value switches to Custom)"),
    ("WATER", "Water", "No solute: wets the cloth, leaves no stain"),
    ("RED_WINE", "Red Wine", "Deep red, binds strongly to the fibres"),
    ("COFFEE", "Coffee", "Brown, binds weakly to the fibres, dries faster at the rim"),
    ("INK", "Ink", "Blue-black, concentrated, wicks and binds fast"),
]
# what a source's preset sets (the rates belong to the cloth it pours on)
SOURCE_PRESET_KEYS = ("concentration", "stain_color")


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


def simulator_keywords(s, gravity, scene_gravity, unit):
    """Keyword arguments of `madder.Simulator` from an object's settings `s` (SI units),
    the scene's `gravity` vector (scene units per s², scaled by `unit`, metres per unit,
    like the positions) and whether the scene's gravity is on (`scene_gravity`: the
    liquid feels gravity only when both it and the object's Gravity are on)."""
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
        # the look (issue 13): wicking saturates at the fibres' saturation; the grain is set
        # in millimetres of the cloth's rest surface
        wicking_exponent=s.wicking,
        wicking_density=max(s.saturation, 1e-6),
        irregularity=s.irregularity,
        irregularity_length=s.irregularity_length * 1e-3,
        irregularity_seed=s.irregularity_seed,
        irregularity_fine_length=(
            s.irregularity_fine * 1e-3 if s.irregularity_fine < s.irregularity_length else 0.0
        ),
        carry_solute=bool(s.carry_solute),
        residual_saturation=s.residual_saturation,
        vapour_limited=bool(s.vapour_limited),
        use_gravity=bool(s.use_gravity and scene_gravity),
        use_rectilinear=s.use_rectilinear,
        use_coriolis=s.use_coriolis,
        momentum_advection=s.momentum_advection,
    )
