"""Fabrics: a Madder fabric on each material, and the per-face conductivity of a cloth.

Each material can carry a woven fabric (a built-in weave or a custom cell grid, with the
seed's pair coefficients, ch. 2.2.1). Its effective tensor comes from homogenizing the
tile (Rust, cached there). The tensor gives the *shape* of the spreading (ratio and angle
of its ellipse): it is normalized to mean eigenvalue 1, then scaled by the object's
Diffusion rate and the fabric's relative Speed, so one fabric can spread faster than
another. Every face uses its material's fabric and orients it by its UV layout."""

import math

import bpy
import numpy as np
from bpy.props import BoolProperty, EnumProperty, FloatProperty, IntProperty, PointerProperty, StringProperty

from . import presets
from .errors import FabricSettingsError

WEAVES = [
    ("PLAIN", "Plain", "Over one, under one"),
    ("TWILL21", "Twill 2/1", "Diagonal ribs, weft over two"),
    ("TWILL31", "Twill 3/1", "Denim-like diagonal ribs"),
    ("SATIN5", "Satin (5-harness)", "Long floats, smooth face"),
    ("BASKET", "Basket", "Pairs of threads interlaced"),
    ("CUSTOM", "Custom", "Your own cell grid"),
]
PAIRS = ("gap_gap", "weft_weft", "warp_warp", "gap_weft", "gap_warp", "weft_warp")
# balanced warp and weft (presets.BALANCED: a balanced plain weave spreads isotropically;
# before issue 34 warp_warp 500 vs weft_weft 100 made every weave 1.7–1.9× anisotropic)
PAIR_DEFAULTS = dict(presets.BALANCED)
_writer = presets.PresetWriter()  # a fabric preset's writes must not switch it to Custom


def _fabric_preset_update(self, context):
    values = presets.fabric_preset(self.preset)
    if values is not None:
        _writer.write(self, values)


def _fabric_custom(self, context):
    """A fabric preset's value was edited by hand: the fabric is no longer the preset."""
    if not _writer.writing and self.preset != "CUSTOM":
        self.preset = "CUSTOM"


# Called with the material after a change of its fabric: the shader, which sits above this
# module, registers its re-sync of the material's Madder Weave node here (shading.register)
resync_hooks = []


def _resync(fabric, context):
    """Re-wires the material's Madder Weave node (weave_shader) after a change of its fabric."""
    mat = fabric.id_data
    if isinstance(mat, bpy.types.Material):
        for hook in resync_hooks:
            hook(mat)


def _edited(fabric, context):
    """A fabric value was edited: it leaves its preset, and the material re-syncs."""
    _fabric_custom(fabric, context)
    _resync(fabric, context)


def _coefficient(pair):
    a, b = pair.split("_")
    return FloatProperty(
        name=f"{a.title()}–{b.title()}",
        description=f"Relative permeability between a {a} cell and a {b} cell",
        default=PAIR_DEFAULTS[pair],
        min=0.0,
        soft_max=1000.0,
        update=_fabric_custom,
    )


class MadderFabric(bpy.types.PropertyGroup):
    enabled: BoolProperty(
        name="Madder Fabric",
        description="Faces with this material are woven: the stain spreads along the threads",
        default=False,
    )
    preset: EnumProperty(
        name="Fabric Preset",
        description="A physical fabric: sets the weave, thread count, yarn coefficients, speed and "
        "grain (any change to one of them switches to Custom)",
        items=presets.FABRIC_PRESET_ITEMS,
        default="CUSTOM",
        update=_fabric_preset_update,
    )
    weave: EnumProperty(
        name="Weave",
        description="How the warp and weft threads interlace in the fabric's repeating tile "
        "(it sets how much faster the stain spreads along one direction than across)",
        items=WEAVES,
        default="PLAIN",
        update=_edited,
    )
    gaps: BoolProperty(
        name="Gaps",
        description="Leave gap cells between the yarns of a built-in weave (an open weave)",
        default=True,
        update=_edited,
    )
    grid: StringProperty(
        update=_edited,
        name="Grid",
        description="Custom tile, rows separated by '/', top row first: W/w warp up/down, "
        "F/f weft up/down, . gap (e.g. 'Wf/fW')",
        default="Wf/fW",
    )
    gap_gap: _coefficient("gap_gap")
    weft_weft: _coefficient("weft_weft")
    warp_warp: _coefficient("warp_warp")
    gap_weft: _coefficient("gap_weft")
    gap_warp: _coefficient("gap_warp")
    weft_warp: _coefficient("weft_warp")
    speed: FloatProperty(
        name="Speed",
        description="How fast this fabric spreads relative to the object's Diffusion rate",
        default=1.0,
        min=0.0,
        soft_max=10.0,
        update=_fabric_custom,
    )
    angle: FloatProperty(
        update=_resync,
        name="Weft Angle",
        description="Rotates the weft away from the UV u axis (a fabric cut on the bias)",
        subtype="ANGLE",
        default=0.0,
    )
    irregularity: FloatProperty(
        name="Irregularity",
        description="How uneven the fabric is (0–1): its spreading and soaking rates vary at random "
        "over the cloth, so a stain's outline is ragged instead of round",
        default=0.5,
        min=0.0,
        max=1.0,
        subtype="FACTOR",
        update=_fabric_custom,
    )
    irregularity_length: FloatProperty(
        name="Grain (mm)",
        description="Size of the fabric's uneven patches, in millimetres (the distance over which "
        "the rates vary together); below the Detail spacing it cannot be resolved",
        default=3.0,
        min=0.01,
        soft_max=50.0,
        update=_fabric_custom,
    )
    irregularity_seed: IntProperty(
        name="Seed",
        description="Another seed gives another pattern of uneven patches",
        default=0,
        min=0,
    )
    thread_count: FloatProperty(
        name="Thread Count",
        description="Threads per centimetre (warp and weft). The Image Sequence draws the weave at this "
        "scale into the stain: the threads and gaps take up the deposit differently, and the stain's "
        "gradient is redistributed between them (the homogenization's corrector). 0 = off (a smooth "
        "texture). Vertex Colors are unaffected",
        default=20.0,
        min=0.0,
        soft_max=100.0,
        precision=1,
        update=_edited,
    )
    shader_weave: BoolProperty(
        update=_resync,
        name="Weave in Shader",
        description="Draw the weave in the material (a Madder Weave node: the yarns' light and bump on the "
        "whole cloth, clean or stained, filtered to the pixel) and bake the Image Sequence smooth. Off: the "
        "Image Sequence draws the weave into the stain at the Thread Count, as before",
        default=True,
    )


def fabric_key(fabric):
    """The inputs of the homogenization, as keyword arguments of `madder.fabric_tensor`."""
    grid = fabric.grid.replace("/", "\n") if fabric.weave == "CUSTOM" else None
    return dict(weave=fabric.weave, grid=grid, gaps=fabric.gaps, coefficients=tuple(getattr(fabric, p) for p in PAIRS))


def effective_tensor(fabric):
    """Homogenized tensor `[s11, s12, s22]` (weft, warp basis) of the fabric's tile,
    normalized to mean eigenvalue 1."""
    import madder

    t = np.asarray(madder.fabric_tensor(**fabric_key(fabric)), dtype=np.float64)
    return t / (0.5 * (t[0] + t[2]))


def face_conductivity(obj, rate, face_polygon):
    """Per-triangle tensors (F, 3) in m²/s and weft offsets (F,), or None when no material
    of `obj` has a fabric (the cloth is then isotropic). Raises FabricSettingsError naming
    the material whose fabric is invalid (its `material`)."""
    mesh = obj.data
    slots = [s.material for s in obj.material_slots]
    fabrics = [m.madder_fabric if (m is not None and m.madder_fabric.enabled) else None for m in slots]
    if not any(fabrics):
        return None
    per_slot = np.tile(np.array([rate, 0.0, rate]), (max(len(slots), 1), 1))
    angle = np.zeros(max(len(slots), 1))
    for i, fab in enumerate(fabrics):
        if fab is None:
            continue
        try:
            per_slot[i] = effective_tensor(fab) * rate * fab.speed
        except Exception as e:
            raise FabricSettingsError(f"material '{slots[i].name}': {e}", material=slots[i].name) from e
        angle[i] = fab.angle
    poly_mat = np.empty(len(mesh.polygons), dtype=np.int64)
    mesh.polygons.foreach_get("material_index", poly_mat)
    slot = np.clip(poly_mat[face_polygon], 0, len(per_slot) - 1)
    return per_slot[slot], angle[slot].astype(np.float32)


def face_weave(obj, face_polygon):
    """What the Image Sequence's weave detail needs of `obj`'s fabrics, per material slot:
    `(slots, slot)` with `slots` a list of `(material name, fabric key, threads per metre,
    weft angle)` for each woven slot with a Thread Count (None for the others) and `slot`
    (F,) the slot of each triangle; None when no slot has one."""
    mesh = obj.data
    slots = []
    for s in obj.material_slots:
        m = s.material
        fab = m.madder_fabric if m is not None else None
        if fab is None or not fab.enabled or fab.thread_count <= 0.0 or fab.shader_weave:
            slots.append(None)  # no weave, or the shader draws it (weave_shader)
        else:
            slots.append((m.name, fabric_key(fab), 100.0 * fab.thread_count, fab.angle))
    if not any(slots):
        return None
    poly_mat = np.empty(len(mesh.polygons), dtype=np.int64)
    mesh.polygons.foreach_get("material_index", poly_mat)
    slot = np.clip(poly_mat[face_polygon], 0, len(slots) - 1)
    return slots, slot


def cloth_grain(obj):
    """`(irregularity, length mm, seed)` of the fabric covering most of `obj`'s rest
    surface (presets.dominant_grain; faces without a Madder fabric are the default
    fabric, presets.DEFAULT_FABRIC). The core has one irregularity field per object."""
    mesh = obj.data
    slots = [s.material for s in obj.material_slots]
    grains = [(m.madder_fabric.irregularity, m.madder_fabric.irregularity_length, m.madder_fabric.irregularity_seed)
              if (m is not None and m.madder_fabric.enabled) else None for m in slots]
    if not grains:
        return presets.default_grain()
    n = len(mesh.polygons)
    poly_mat = np.empty(n, dtype=np.int64)
    mesh.polygons.foreach_get("material_index", poly_mat)
    area = np.empty(n, dtype=np.float64)
    mesh.polygons.foreach_get("area", area)
    areas = np.bincount(np.clip(poly_mat, 0, len(grains) - 1), weights=area, minlength=len(grains))
    return presets.dominant_grain(grains, list(areas))


def tile_rows(fabric):
    """The fabric's tile as rows of characters (top row first), for drawing."""
    import madder

    key = fabric_key(fabric)
    del key["coefficients"]  # the tile's layout does not depend on them
    return madder.fabric_tile(**key)


def describe(fabric):
    """`((ratio, angle in degrees), None)` of the fabric's ellipse for the panel, or
    `(None, message)` when the fabric is invalid."""
    import madder

    try:
        ratio, angle = madder.ellipse(effective_tensor(fabric))
    except Exception as e:
        return None, str(e)
    return (ratio, math.degrees(angle)), None


def register():
    bpy.utils.register_class(MadderFabric)
    bpy.types.Material.madder_fabric = PointerProperty(type=MadderFabric)


def unregister():
    del bpy.types.Material.madder_fabric
    bpy.utils.unregister_class(MadderFabric)
