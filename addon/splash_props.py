"""The Blender settings of a directed splash (`splash`): one group on the cloth's Madder
settings (`obj.madder.splash`). With no Throw object (the default) a spill is what it
always was, the Spill Group's weights × Amount."""

import bpy
from bpy.props import FloatProperty, PointerProperty


class MadderSplashSettings(bpy.types.PropertyGroup):
    throw: PointerProperty(
        name="Throw",
        description="An object whose local Z axis (a Single Arrow empty's arrow) is the direction a glass is "
        "knocked over in: the spill becomes a splash of Volume at the Spill Group's centre, with a pool, a tongue "
        "along the throw and drops ahead of it (none: the Spill Group's weights × Amount)",
        type=bpy.types.Object,
    )
    volume: FloatProperty(
        name="Volume (mL)",
        description="Liquid the splash holds, millilitres (a knocked-over glass of wine: 100–150)",
        default=125.0,
        min=0.001,
        soft_max=1000.0,
    )
    height: FloatProperty(
        name="Glass Height",
        description="Height the liquid falls from (the glass's): sets the speed of the throw, √(2 g H), "
        "and so the tongue's length and how far the drops fly",
        unit="LENGTH",
        default=0.1,
        min=0.001,
        soft_max=0.5,
    )


def register():
    bpy.utils.register_class(MadderSplashSettings)


def unregister():
    bpy.utils.unregister_class(MadderSplashSettings)
