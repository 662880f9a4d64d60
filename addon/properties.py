"""Madder's settings, stored on the object (so they are saved in the .blend)."""

import bpy
from bpy.props import BoolProperty, FloatProperty, FloatVectorProperty, IntProperty, PointerProperty, StringProperty

# Blender 4.5+ warns when a path property holds a "//" path unless it says it supports them.
_BLEND_RELATIVE = {"options": {"PATH_SUPPORTS_BLEND_RELATIVE"}} if bpy.app.version >= (4, 5, 0) else {}


class MadderObjectSettings(bpy.types.PropertyGroup):
    enabled: BoolProperty(
        name="Madder Stain",
        description="Simulate a stain on this cloth and play it back from the cache",
        default=False,
    )
    source_group: StringProperty(
        name="Source",
        description="Vertex group whose weights give the initial stain (1 = fully wet); "
        "optional when source objects pour liquid on the cloth",
        default="",
    )
    amount: FloatProperty(
        name="Amount",
        description="Liquid per unit area where the Source weight is 1 (1 = just saturated; "
        "more pools and spreads further before it fades)",
        default=1.0,
        min=0.0,
        soft_max=10.0,
    )
    diffusion_rate: FloatProperty(
        name="Diffusion",
        description="How fast the stain spreads through the fabric (diffusion coefficient, m²/s)",
        default=0.002,
        min=0.0,
        soft_max=0.1,
        precision=4,
        step=0.1,
    )
    substeps: IntProperty(
        name="Substeps",
        description="Implicit steps per frame (positions are interpolated between frames)",
        default=1,
        min=1,
        soft_max=8,
    )
    stain_color: FloatVectorProperty(
        name="Color",
        description="Color of the stain where it is fully saturated",
        subtype="COLOR",
        size=3,
        min=0.0,
        max=1.0,
        default=(0.45, 0.02, 0.08),
    )
    motion_file: StringProperty(
        name="Motion File",
        description="Take the cloth's motion from a PC2 or MDD file (object-space positions, "
        "as the Mesh Cache modifier reads them) instead of evaluating the scene",
        subtype="FILE_PATH",
        default="",
        **_BLEND_RELATIVE,
    )
    cache_dir: StringProperty(
        name="Cache Folder",
        description="Folder for the baked stain (relative to the .blend with //)",
        subtype="DIR_PATH",
        default="//madder_cache/",
        **_BLEND_RELATIVE,
    )
    cache_file: StringProperty(
        name="Cache File",
        description="The baked cache this object plays back (set by Bake)",
        subtype="FILE_PATH",
        default="",
        **_BLEND_RELATIVE,
    )


class MadderSourceSettings(bpy.types.PropertyGroup):
    """A brush or a pour: a mesh object that adds liquid to every Madder cloth it touches
    or comes near, frame by frame."""

    is_source: BoolProperty(
        name="Madder Source",
        description="This object adds liquid to the cloths it touches or comes near",
        default=False,
    )
    amount: FloatProperty(
        name="Flow",
        description="Liquid added per unit area per second where the source touches the cloth "
        "(1 = saturates in a second)",
        default=2.0,
        min=0.0,
        soft_max=20.0,
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
        description="Color of this source's liquid",
        subtype="COLOR",
        size=3,
        min=0.0,
        max=1.0,
        default=(0.05, 0.08, 0.35),
    )
    use_frame_range: BoolProperty(
        name="Frame Range",
        description="Pour only between the start and end frames",
        default=False,
    )
    frame_start: IntProperty(name="Start", default=1)
    frame_end: IntProperty(name="End", default=250)


def register():
    bpy.utils.register_class(MadderObjectSettings)
    bpy.utils.register_class(MadderSourceSettings)
    bpy.types.Object.madder = PointerProperty(type=MadderObjectSettings)
    bpy.types.Object.madder_source = PointerProperty(type=MadderSourceSettings)


def unregister():
    del bpy.types.Object.madder_source
    del bpy.types.Object.madder
    bpy.utils.unregister_class(MadderSourceSettings)
    bpy.utils.unregister_class(MadderObjectSettings)
