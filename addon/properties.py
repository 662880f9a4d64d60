"""Madder's settings, stored on the object (so they are saved in the .blend).

Units are SI throughout, as in the Rust core: densities (liquid or solute per unit area
of cloth) in kg/m², rates in 1/s, diffusion and viscosity in m²/s. The defaults are the
core's defaults (`StainParams::default`, `InteractionRates::default`: water on a light
cotton cloth). The presets and the bake references are bpy-free, in `presets`."""

import bpy
from bpy.props import (
    BoolProperty,
    EnumProperty,
    FloatProperty,
    FloatVectorProperty,
    IntProperty,
    IntVectorProperty,
    PointerProperty,
    StringProperty,
)

from . import carrier, compat, handlers, presets, textures
from .splash_props import MadderSplashSettings

# The liquid presets (values and where they come from) and the bake references are plain
# data and functions in `presets` (bpy-free); these names stay here for callers.
LIQUIDS, LIQUID_ITEMS, SOURCE_PRESET_KEYS = presets.LIQUIDS, presets.LIQUID_ITEMS, presets.SOURCE_PRESET_KEYS
references = presets.references

_writer = presets.PresetWriter()  # a liquid preset's writes must not switch it to Custom


def _liquid_update(self, context):
    values = presets.object_preset(self.liquid)
    if values is not None:
        _writer.write(self, values)


def _source_liquid_update(self, context):
    values = presets.source_preset(self.liquid)
    if values is not None:
        _writer.write(self, values)


def _mark_custom(self, context):
    """A preset's value was edited by hand: the liquid is no longer the preset."""
    if not _writer.writing and self.liquid != "CUSTOM":
        self.liquid = "CUSTOM"


def _enabled_update(self, context):
    """Switched off, the cloth shows no stain and its "Madder Stain" modifier costs nothing
    (hidden in viewport and renders, it is not evaluated); switched on again, it shows the
    current frame's stain at once."""
    obj = self.id_data
    if not (isinstance(obj, bpy.types.Object) and obj.type == "MESH"):
        return
    carrier.show(obj, self.enabled)
    if self.enabled and context.scene is not None:
        handlers.on_frame_change(context.scene)


def _output_update(self, context):
    """Switching the output re-wires the stain shader of the object's materials."""
    from . import shading  # needs the properties registered first

    obj = self.id_data
    if isinstance(obj, bpy.types.Object) and obj.type == "MESH":
        shading.sync_object(obj)


def _rate(name, description, default, soft_max, precision=3, step=1.0, preset=False, **kw):
    return FloatProperty(
        name=name,
        description=description,
        default=default,
        min=0.0,
        soft_max=soft_max,
        precision=precision,
        step=step,
        update=_mark_custom if preset else None,
        **kw,
    )


def _splash_speed(what):
    return FloatProperty(
        name="Splash Speed",
        description=f"{what}, with a random jitter (0 = no splash)",
        unit="VELOCITY",
        default=0.0,
        min=0.0,
        soft_max=5.0,
    )


def _splash_seed():
    return IntProperty(
        name="Splash Seed",
        description="Random seed of the splash (the same seed gives the same splash)",
        default=0,
        min=0,
    )


def _preview():
    from . import preview  # needs the properties registered first

    return preview


class MadderLcsSettings(bpy.types.PropertyGroup):
    """Coherent Structures (seed ch. 5): FTLE of the baked flow at a frame, and its ridges."""

    frame: IntProperty(
        name="Frame",
        description="Scene frame the particles start from (t0); the FTLE and the ridges are of the "
        "cloth at this frame",
        default=1,
    )
    span: IntProperty(
        name="Span",
        description="How many frames the particles are traced for (the time span |T|); the span must "
        "lie inside the bake",
        default=12,
        min=0,
        soft_min=1,
    )
    direction: EnumProperty(
        name="Direction",
        description="Trace forward in time (ridges are repelling structures: where the liquid splits) "
        "or backward (attracting structures: where it gathers)",
        items=[
            ("FORWARD", "Forward", "Trace from the frame forward: repelling structures"),
            ("BACKWARD", "Backward", "Trace from the frame backward: attracting structures"),
        ],
        default="FORWARD",
    )
    steps_per_frame: IntProperty(
        name="Steps per Frame",
        description="RK4 steps per frame of the span (the baked velocity is linear between frames)",
        default=4,
        min=1,
        soft_max=16,
        max=256,
    )
    smoothing: FloatProperty(
        name="Smoothing",
        description="Diffusion applied to the thresholded FTLE before the ridge test, in mean edge "
        "lengths squared (more: smoother, fewer ridges)",
        default=1.0,
        min=0.0,
        soft_max=10.0,
    )
    hessian_smoothing: FloatProperty(
        name="Hessian Smoothing",
        description="Diffusion applied to the Hessian that gives the direction across a ridge, in mean "
        "edge lengths squared",
        default=1.0,
        min=0.0,
        soft_max=10.0,
    )
    min_edges: IntProperty(
        name="Minimum Edges",
        description="Cleanup: remove ridge pieces with fewer edges than this",
        default=20,
        min=0,
        soft_max=200,
    )
    min_branch: IntProperty(
        name="Minimum Branch",
        description="Cleanup: remove side branches and loops at junctions shorter than this many edges",
        default=10,
        min=0,
        soft_max=100,
    )
    join: BoolProperty(
        name="Join at Maxima",
        description="Let ridges meet at local maxima of the FTLE (junctions of three or more ridges)",
        default=True,
    )
    remove_valleys: BoolProperty(
        name="Remove Valleys",
        description="Drop crossings where the FTLE slopes away from the ridge (spurious valleys of "
        "noisy fields)",
        default=False,
    )
    radius: FloatProperty(
        name="Curve Radius",
        description="Radius of the ridge curves as they render",
        default=0.005,
        min=0.0,
        soft_max=0.1,
        subtype="DISTANCE",
    )
    ridge_object: PointerProperty(
        name="Ridge Object",
        description="The curves object holding this cloth's ridges (replaced by the next run)",
        type=bpy.types.Object,
        options={"HIDDEN"},
    )


class MadderMotionSettings(bpy.types.PropertyGroup):
    """Compressed motion (issue 15, seed ch. 3): the cloth's evaluated motion written as
    Madder's motion codec (`.madm`), and that file decompressed to PC2 (`codec`)."""

    path: StringProperty(
        name="Compressed Motion",
        description="The .madm file Compress Motion writes and Decompress reads (empty: the object's name "
        "in the Cache Folder). Set it as the Motion File to bake from it",
        subtype="FILE_PATH",
        default="",
        **compat.BLEND_RELATIVE,
    )
    bits: IntProperty(
        name="Bits",
        description="Quantization of the angles: 2^Bits steps per turn. More bits: a smaller error and a "
        "bigger file (each bit halves the angles' rounding); below about 7 the largest error passes 1 % "
        "of the cloth's size. The panel shows both after Compress Motion",
        default=12,
        min=4,
        max=20,
        soft_min=8,
        soft_max=16,
    )
    pc2_path: StringProperty(
        name="PC2 File",
        description="The PC2 file Decompress writes (empty: beside the .madm file, with the extension .pc2); "
        "an existing file there is replaced only once the new one is complete",
        subtype="FILE_PATH",
        default="",
        **compat.BLEND_RELATIVE,
    )
    add_mesh_cache: BoolProperty(
        name="Mesh Cache Modifier",
        description="Decompress also points a Mesh Cache modifier at the PC2 (adding one at the bottom of the "
        "stack if none reads it), timed so that each frame shows the motion that was compressed there",
        default=True,
    )
    figures: FloatVectorProperty(
        name="Compression Figures",
        description="Of the last Compress Motion: bits per vertex per frame, and the largest and RMS vertex "
        "error over the bounding box diagonal (as measured by the encoder decoding its own file)",
        size=3,
        default=(0.0, 0.0, 0.0),
        options={"HIDDEN"},
    )
    report: StringProperty(
        name="Compression Report",
        description="What the last Compress Motion wrote (frames, vertices, size, bits and errors)",
        default="",
        options={"HIDDEN"},
    )


class MadderObjectSettings(bpy.types.PropertyGroup):
    enabled: BoolProperty(
        name="Madder Stain",
        description="Simulate a stain on this cloth and play it back from the cache",
        default=False,
        update=_enabled_update,
    )

    # -- Liquid: what is spilled, and how much
    liquid: EnumProperty(
        name="Liquid",
        description="Preset that sets the solute's color and concentration and how the liquid "
        "soaks in, binds to the fibres and dries",
        items=LIQUID_ITEMS,
        default="CUSTOM",
        update=_liquid_update,
    )
    # the identifier stays `source_group` (saved .blend files and scripts use it); the UI
    # calls it the Spill Group so it is not confused with a Madder Source object
    source_group: StringProperty(
        name="Spill Group",
        description="Vertex group whose weights give where the liquid is spilled (a pool "
        "Amount deep where they are highest, or weight × Amount: Spill Shape); "
        "optional when Madder Source objects pour liquid on the cloth",
        default="",
    )
    spill_shape: EnumProperty(
        name="Spill Shape",
        description="How the Spill Group's weights lay the liquid (the same mass either way)",
        items=[
            ("POOL", "Pool", "The liquid the weights hold, laid Amount deep where the weights are "
             "highest: a spill with a sharp edge, as liquid lands"),
            ("WEIGHTS", "Weights", "Weight × Amount on every vertex: a film graded like the "
             "weights, which stains as a soft disc where a soft brush painted them"),
        ],
        default="POOL",
    )
    amount: FloatProperty(
        name="Amount (kg/m²)",
        description="Liquid spilled per unit area: the pool's depth, or with Spill Shape Weights "
        "where the Spill Group's weight is 1, kg/m² (the fibres hold Saturation; the rest is "
        "free liquid that flows and spreads)",
        default=0.5,
        min=0.0,
        soft_max=5.0,
        precision=3,
    )
    stain_color: FloatVectorProperty(
        name="Color",
        description="Color of the liquid's solute (the stain where it is fully stained)",
        subtype="COLOR",
        size=3,
        min=0.0,
        max=1.0,
        default=(0.45, 0.05, 0.1),
        update=_mark_custom,
    )
    concentration: _rate(
        "Concentration (kg/kg)",
        "Solute (what stains) per kg of solvent, kg/kg: 0 is clear water",
        0.05, 0.2, precision=3, step=0.1, preset=True, max=1.0,
    )
    splash_speed: _splash_speed(
        "Initial outgoing speed of the spilled liquid, away from the centroid of the wet area"
    )
    splash_seed: _splash_seed()
    # a directed splash (volume, throw) instead of the Spill Group's disc: off without a Throw object
    splash: PointerProperty(
        type=MadderSplashSettings,
        name="Directed Splash",
        description="A knocked-over glass instead of the Spill Group's weights: a Volume thrown along a Throw "
        "object's arrow (off without a Throw object)",
    )

    # -- Flow: spreading through the fabric and moving on it
    diffusion_rate: _rate(
        "Diffusion (m²/s)",
        "How fast the liquid spreads through the fabric (diffusion coefficient of the densities, m²/s; "
        "wicking in cotton, about 1 cm in the first second, is 1e-4 to 2e-4)",
        2e-4, 0.05, precision=5, step=0.01,
    )
    viscosity: _rate(
        "Viscosity (m²/s)",
        "Kinematic viscosity of the liquid's flow, m²/s: smooths its velocity",
        1e-4, 1e-2, precision=5, step=0.01,
    )
    friction: _rate(
        "Friction (1/s)",
        "Drag of the fibres on the flowing liquid, 1/s (its speed decays as e^(−friction·t); "
        "0 = frictionless). Terminal speed under gravity g is g/friction. 50 is the drag of "
        "a water film about 0.25 mm thick; thinner films drag more",
        50.0, 500.0, precision=2,
    )

    # -- Forces
    use_gravity: BoolProperty(
        name="Gravity",
        description="The scene's gravity pulls the liquid downhill along the cloth "
        "(also off when the scene's Gravity is off)",
        default=True,
    )
    use_rectilinear: BoolProperty(
        name="Acceleration",
        description="The cloth's acceleration pushes the liquid (rectilinear fictitious force): "
        "a cloth that jerks sideways leaves its liquid behind",
        default=True,
    )
    use_coriolis: BoolProperty(
        name="Coriolis",
        description="The cloth's rotation turns the flowing liquid (Coriolis force): on a spinning "
        "cloth the liquid keeps its straight path in space",
        default=True,
    )
    momentum_advection: BoolProperty(
        name="Momentum Advection",
        description="Carry the velocity with the liquid's momentum (seed §4.3.2), so that where "
        "streams of liquid meet they keep their momentum; off: semi-Lagrangian velocity "
        "(§4.3.1), which loses speed where liquid runs into slower liquid",
        default=True,
    )

    # -- Interactions with the fibres (seed §4.5)
    absorption: _rate(
        "Absorption (1/s)",
        "How fast the fibres soak up free liquid toward Saturation, 1/s",
        2.0, 20.0, preset=True,
    )
    saturation: _rate(
        "Saturation (kg/m²)",
        "Liquid the fibres can hold per unit area, kg/m² (about the fabric's own weight per m²); "
        "a spot holding this much reads as fully wet",
        0.1, 1.0, precision=3,
    )
    adsorption: _rate(
        "Adsorption (1/s)",
        "How fast the solute binds to the fibres toward Capacity, 1/s (Langmuir): the permanent mark",
        0.1, 5.0, preset=True,
    )
    capacity: _rate(
        "Capacity (kg/m²)",
        "Most solute the fibres can bind per unit area, kg/m²",
        2e-3, 0.02, precision=4, step=0.01, preset=True,
    )
    evaporation: _rate(
        "Evaporation (kg/m²/s)",
        "Liquid evaporated per unit area and second, kg/(m²·s) (5e-5: a saturated cotton cloth "
        "dries in about half an hour in room air)",
        5e-5, 1e-3, precision=6, step=0.001, preset=True,
    )
    evaporation_boundary: FloatProperty(
        name="Rim Evaporation",
        description="How many times faster the rim of the wet area evaporates (≥ 1; 1.2 in the "
        "seed): the rim dries first",
        default=1.2,
        min=1.0,
        soft_max=3.0,
        update=_mark_custom,
    )
    # -- The look of the stain (issue 13; the liquid's preset sets Wicking and how it
    # rings, the fabric sets the grain, issue 34)
    grain_from: EnumProperty(
        name="Grain From",
        description="Where the stain's uneven outline comes from",
        items=[
            ("FABRIC", "Fabric", "The Irregularity of the fabric covering most of the cloth (a cloth "
             "without a Madder fabric is plain cotton)", 0),
            ("OBJECT", "Object", "This object's own Irregularity, Grain and Seed below", 1),
        ],
        default="FABRIC",
    )
    wicking: FloatProperty(
        name="Wicking",
        description="How much faster the fabric draws liquid in where it is wetter (the spreading "
        "rate times saturation to this power): 0 spreads with a soft edge; 1–3 give a spill a "
        "sharp front that slows as it thins",
        default=0.0,
        min=0.0,
        max=8.0,
        soft_max=4.0,
        update=_mark_custom,
    )
    wicking_iterations: IntProperty(
        name="Front Iterations",
        description="With Wicking, solves each step again this many times with the rate of its own "
        "solution: without them the front runs slow and takes the mesh's shape (a spill on a "
        "grid dries square); each costs about one more solve of the spreading per step",
        default=0,
        min=0,
        max=64,
        update=_mark_custom,
    )
    front_settles: BoolProperty(
        name="Until Settled",
        description="With Wicking, goes on solving each step until its front stops moving (at most 64 "
        "solves; Front Iterations is then the least number): a long step spreads a round stain "
        "instead of one ring of the mesh per solve, at the price of more solves while it spreads",
        default=False,
        update=_mark_custom,
    )
    irregularity: FloatProperty(
        name="Irregularity",
        description="How uneven the fabric is (0–1): its spreading and soaking rates vary at random "
        "over the cloth, so a stain's outline is ragged instead of round",
        default=0.0,
        min=0.0,
        max=1.0,
        subtype="FACTOR",
    )
    irregularity_length: FloatProperty(
        name="Grain (mm)",
        description="Size of the fabric's uneven patches, in millimetres (the distance over which "
        "the rates vary together); below the Detail spacing it cannot be resolved",
        default=3.0,
        min=0.01,
        soft_max=50.0,
    )
    irregularity_fine: FloatProperty(
        name="Fibre Scale (mm)",
        description="Smallest size of the fabric's unevenness, in millimetres (about one thread "
        "pitch): the variation is self-affine from this scale up to the Grain, so the outline "
        "is rough at every scale in between, as real stains are; 0 gives patches of the Grain "
        "size only (the default: the multi-scale field does not yet give the roughness exponent of "
        "real stains, see ARCHITECTURE.md), and a value at or above the Grain is ignored",
        default=0.0,
        min=0.0,
        soft_max=5.0,
    )
    irregularity_seed: IntProperty(
        name="Seed",
        description="Another seed gives another pattern of uneven patches",
        default=0,
        min=0,
    )
    carry_solute: BoolProperty(
        name="Carry Solute",
        description="The dissolved stain moves with the liquid's flow (and the liquid in the fibres "
        "wicks too) instead of spreading on its own at the liquid's rate",
        default=False,
        update=_mark_custom,
    )
    residual_saturation: FloatProperty(
        name="Residual Saturation",
        description="Pins the wet edge: the fibres' liquid below this fraction of their saturation "
        "neither moves nor lets liquid in, so the patch keeps its outline while it dries (with "
        "Carry Solute; 0 = off)",
        default=0.0,
        min=0.0,
        max=0.95,
        update=_mark_custom,
    )
    carried_fraction: FloatProperty(
        name="Carried Fraction",
        description="Share of the dissolved stain the liquid's flow carries at each step (with Carry "
        "Solute); the rest stays where it is, so the stain moves at this fraction of the liquid's "
        "speed (1 = all of it)",
        default=1.0,
        min=0.01,
        max=1.0,
        update=_mark_custom,
    )
    dispersivity: FloatProperty(
        name="Tide Line Width",
        description="Dispersivity (mm of cloth): the carried stain spreads back against the flow that "
        "brings it, so a tide line is about this wide whatever the mesh's Detail (with Carry "
        "Solute; 0 = off, a ring one cell wide)",
        default=0.0,
        min=0.0,
        soft_max=10.0,
        precision=2,
        update=_mark_custom,
    )
    holdup: FloatProperty(
        name="Run Holdup",
        description="Free liquid (kg/m²) each point of the cloth keeps back from a run: a film the "
        "running liquid fills before it moves on and leaves behind to soak into the fibres "
        "(0 = off)",
        default=0.0,
        min=0.0,
        soft_max=0.2,
        precision=3,
        update=_mark_custom,
    )
    drip_hold: FloatProperty(
        name="Hem Holds (g/m)",
        description="Free liquid a hanging hem holds per metre of the cloth's edge before it drips "
        "off (what drips leaves the cloth; 0 = off: the edge gathers everything that reaches it)",
        default=0.0,
        min=0.0,
        soft_max=20.0,
        precision=1,
        update=_mark_custom,
    )
    capillary_rise: FloatProperty(
        name="Capillary Rise (cm)",
        description="How high the fabric wicks the liquid up from a reservoir: with Carry Solute "
        "the liquid in the fibres drains down a hanging cloth while it wicks and settles no higher "
        "than this (0 = off: the wicking has no weight)",
        default=0.0,
        min=0.0,
        soft_max=30.0,
        precision=1,
        update=_mark_custom,
    )
    vapour_limited: BoolProperty(
        name="Vapour-Limited Drying",
        description="A wet patch dries fastest at its edge, as vapour diffusing into still air does "
        "(in place of Rim Evaporation); with Carry Solute and a Residual Saturation the liquid "
        "flowing to the edge leaves a tide line",
        default=False,
        update=_mark_custom,
    )
    substeps: IntProperty(
        name="Substeps",
        description="Simulation steps per frame, at least (positions are interpolated between "
        "frames); a frame in which the cloth turns fast takes more on its own",
        default=1,
        min=1,
        soft_max=8,
    )
    clock: EnumProperty(
        name="Clock",
        description="How long each frame lasts in the stain's time",
        items=[
            ("SCENE", "Scene Rate", "Every frame lasts the scene's 1/Frame Rate (Frame Rate and Base)"),
            ("FRAME_TIME", "Frame Time", "Each frame lasts the Frame Time at that frame: keyframe it for "
             "real time while the cloth moves and minutes a frame while the stain dries"),
        ],
        default="SCENE",
    )
    frame_time: FloatProperty(
        name="Frame Time",
        description="With the Frame Time clock: how long the step into this frame lasts, in the stain's "
        "time (animatable: the value at each frame is that frame's)",
        default=1.0 / 24.0,
        min=1e-4,
        soft_max=600.0,
        unit="TIME_ABSOLUTE",
        precision=4,
    )
    first_substep: FloatProperty(
        name="First Step (s)",
        description="After liquid is poured, the simulation's steps start this long and double "
        "until they reach the frame's: a fresh spill spreads in steps shorter than the fibres' "
        "uptake even where a frame lasts a minute (0: off, every frame in Substeps equal steps)",
        default=0.25,
        min=0.0,
        soft_max=5.0,
        precision=3,
    )

    # -- Output: the simulation's resolution and what playback and renders read
    detail_auto: BoolProperty(
        name="Auto Detail",
        description="Choose Detail from the cloth's mean edge at the bake: the smallest level whose "
        "refined edge is at most 2.5 mm, kept to at most a million refined vertices",
        default=True,
    )
    detail: IntProperty(
        name="Detail",
        description="Simulate on a finer mesh than the cloth's: each of its triangles split into "
        "4^Detail (0: the cloth's own vertices). The stain's edges get sharper; the image sequence "
        "shows it, the vertex colors keep the cloth's resolution. Each level costs about 4× the time "
        "where the cloth is wet",
        default=0,
        min=0,
        max=3,
    )
    output_vertex_colors: BoolProperty(
        name="Vertex Colors",
        description="Playback writes the stain into the mesh's color attributes every frame "
        "(madder_stain, madder_wetness, madder_deposit), at the cloth's vertices",
        default=True,
        update=_output_update,
    )
    output_images: BoolProperty(
        name="Image Sequence",
        description="The bake also writes the stain as OpenEXR image sequences in UV space, at the "
        "Detail mesh's resolution, next to the cache; the stain shader reads them through the "
        "active UV map. Needs a UV map (on by default: a cloth without one bakes vertex colors only)",
        default=True,
        update=_output_update,
    )
    image_size: EnumProperty(
        name="Size",
        description="Width and height of the images, in pixels (Re-export Textures writes them "
        "again at another size without a bake)",
        # numbered: files saved before Auto store the sizes' positions 0–3
        items=[(str(n), f"{n} px", f"{n} × {n} pixels", i) for i, n in enumerate(textures.SIZES)]
        + [("AUTO", "Auto", "A texel of half the refined mean edge on the cloth (from the UV map's "
            "area and the cloth's), the smallest size reaching it", len(textures.SIZES))],
        default="AUTO",
    )
    sharp_outline: BoolProperty(
        name="Sharp Outline",
        description="Draw the stain's edge sharp where the simulated front is a few cells wide and the "
        "cloth beyond is dry (a stain's edge is sharp at the fibres); off: the images as the Detail mesh "
        "resolves them. Re-export Textures applies a change",
        default=True,
    )
    outline_in_shader: BoolProperty(
        name="In Shader",
        description="The Madder Stain shader draws the sharp edge at the pixel, ragged down to the fibres, "
        "from the front's distance in the wet image's alpha; off: the images draw it within a texel "
        "(for materials of your own that read the images). Re-export Textures applies a change",
        default=True,
    )
    image_baked: BoolProperty(
        name="Images Baked",
        description="The bake (or Re-export Textures) wrote the image sequence beside the cache",
        default=False,
        options={"HIDDEN"},
    )
    image_frames: IntVectorProperty(
        name="Image Frames",
        description="First and last frame of the image sequence, recorded by the bake",
        size=2,
        default=(0, 0),
        options={"HIDDEN"},
    )
    image_baked_size: IntProperty(
        name="Image Size Baked",
        description="Size of the images written, in pixels",
        default=0,
        options={"HIDDEN"},
    )
    image_baked_outline: BoolProperty(
        name="Sharp Outline Baked",
        description="The image sequence was written with Sharp Outline",
        default=False,
        options={"HIDDEN"},
    )
    image_baked_outline_shader: BoolProperty(
        name="Outline in Shader Baked",
        description="The image sequence was written for the shader to draw its outline",
        default=False,
        options={"HIDDEN"},
    )
    image_uv_map: StringProperty(
        name="Image UV Map",
        description="The UV map the images were laid out on (the stain shader reads them through it)",
        default="",
        options={"HIDDEN"},
    )
    bake_detail: IntProperty(
        name="Bake Detail",
        description="The Detail level of the bake (the fine cache's mesh)",
        default=0,
        options={"HIDDEN"},
    )

    # -- Cache
    motion_file: StringProperty(
        name="Motion File",
        description="Take the cloth's motion from a PC2 or MDD file (object-space positions, "
        "as the Mesh Cache modifier reads them) or a compressed .madm file (Compressed Motion) "
        "instead of evaluating the scene",
        subtype="FILE_PATH",
        default="",
        **compat.BLEND_RELATIVE,
    )
    motion: PointerProperty(
        type=MadderMotionSettings,
        name="Compressed Motion",
        description="Settings of Compress Motion and Decompress (the cloth's motion as a .madm file)",
    )
    cache_dir: StringProperty(
        name="Cache Folder",
        description="Folder for the baked stain (relative to the .blend with //)",
        subtype="DIR_PATH",
        default="//madder_cache/",
        **compat.BLEND_RELATIVE,
    )
    cache_file: StringProperty(
        name="Cache File",
        description="The baked cache this object plays back (set by Bake)",
        subtype="FILE_PATH",
        default="",
        **compat.BLEND_RELATIVE,
    )
    bake_references: FloatVectorProperty(
        name="Bake References",
        description="Densities (kg/m²) that read as full in playback, recorded by the bake: "
        "solute (concentration × saturation), liquid (saturation) and deposit (capacity)",
        size=3,
        default=(0.0, 0.0, 0.0),
        options={"HIDDEN"},
    )
    bake_topology: StringProperty(
        name="Bake Topology",
        description="Fingerprint of the mesh's faces at the bake: playback shows no stain on other faces",
        default="",
        options={"HIDDEN"},
    )
    bake_flow: BoolProperty(
        name="Bake Flow",
        description="The bake also stores the liquid's velocity and the cloth's positions every frame "
        "(the cache grows about threefold), which Coherent Structures needs",
        default=False,
    )
    lcs: PointerProperty(
        type=MadderLcsSettings,
        name="Coherent Structures",
        description="Settings of the Coherent Structures tool (FTLE and ridges of the baked flow)",
    )
    # -- Live preview (addon/preview.py)
    live: BoolProperty(
        name="Live",
        description="Simulate the stain as the timeline plays forward from the start frame, without a bake "
        "(each frame shows the newest finished frame, one frame late; going back to the start frame, "
        "a jump forward or a changed setting starts again). Bake from Preview writes it to the cache",
        default=False,
        update=lambda self, context: _preview().live_update(self, context),
    )
    live_memory: FloatProperty(
        name="Live Memory",
        description="Memory (MB) for the previewed frames kept to scrub back and to Bake from Preview; "
        "past it the oldest frames are dropped",
        default=512.0,
        min=0.01,
        soft_max=8192.0,
        precision=1,
        update=lambda self, context: _preview().memory_update(self, context),
    )
    render_without_cache: BoolProperty(
        name="Render Without Stain",
        description="Render frames whose stain cache is missing, damaged or stale without the stain "
        "(the console lists them). Off: such a render stops at the first of these frames with an error",
        default=False,
    )


class MadderSourceSettings(bpy.types.PropertyGroup):
    """A brush or a pour: a mesh object that adds liquid to every Madder cloth it touches
    or comes near, frame by frame."""

    is_source: BoolProperty(
        name="Madder Source",
        description="This object adds liquid to the cloths it touches or comes near",
        default=False,
    )
    liquid: EnumProperty(
        name="Liquid",
        description="Preset that sets this source's color and concentration (how the liquid "
        "interacts with the fibres is set on the cloth)",
        items=LIQUID_ITEMS,
        default="CUSTOM",
        update=_source_liquid_update,
    )
    amount: FloatProperty(
        name="Flow (kg/m²/s)",
        description="Liquid added per unit area per second where the source touches the cloth, "
        "kg/(m²·s) (0.1 fills a cloth of Saturation 0.1 kg/m² in a second)",
        default=0.2,
        min=0.0,
        soft_max=5.0,
        precision=3,
    )
    concentration: _rate(
        "Concentration (kg/kg)",
        "Solute (what stains) per kg of this source's liquid, kg/kg: 0 is clear water",
        0.05, 0.2, precision=3, step=0.1, preset=True, max=1.0,
    )
    distance: FloatProperty(
        name="Distance",
        description="Reach of the source: the flow fades from full at contact to zero at this distance",
        subtype="DISTANCE",
        unit="LENGTH",
        default=0.05,
        min=0.0001,
        soft_max=1.0,
    )
    color: FloatVectorProperty(
        name="Color",
        description="Color of this source's solute",
        subtype="COLOR",
        size=3,
        min=0.0,
        max=1.0,
        default=(0.05, 0.08, 0.35),
        update=_mark_custom,
    )
    splash_speed: _splash_speed("When this source first adds liquid, the liquid leaves it outward at this speed")
    splash_seed: _splash_seed()
    use_frame_range: BoolProperty(
        name="Frame Range",
        description="Pour only between the start and end frames",
        default=False,
    )
    frame_start: IntProperty(
        name="Start",
        description="First frame this source pours on (with Frame Range on)",
        default=1,
    )
    frame_end: IntProperty(
        name="End",
        description="Last frame this source pours on (with Frame Range on)",
        default=250,
    )


def register():
    bpy.utils.register_class(MadderLcsSettings)
    bpy.utils.register_class(MadderMotionSettings)
    bpy.utils.register_class(MadderObjectSettings)
    bpy.utils.register_class(MadderSourceSettings)
    bpy.types.Object.madder = PointerProperty(type=MadderObjectSettings)
    bpy.types.Object.madder_source = PointerProperty(type=MadderSourceSettings)


def unregister():
    del bpy.types.Object.madder_source
    del bpy.types.Object.madder
    bpy.utils.unregister_class(MadderSourceSettings)
    bpy.utils.unregister_class(MadderObjectSettings)
    bpy.utils.unregister_class(MadderMotionSettings)
    bpy.utils.unregister_class(MadderLcsSettings)
