"""The "Madder Stain" shader node group and the one-click operator that adds it to an
object's materials.

The group takes the material's Base Color and Roughness and returns them stained:

    color  = base · (1 − coverage) + stain          (madder_stain: RGB = color × coverage,
                                                     alpha = coverage: premultiplied "over")
    color *= 1 − darkening · wetness                (wet fabric looks darker)
    color *= 1 − deposit darkening · deposit        (bound dye is a little darker still)
    rough  = mix(roughness, wet roughness, wetness) (and shinier)

with `coverage`, `wetness` and `deposit` read from the `madder_stain`, `madder_wetness`
and `madder_deposit` attributes (each in [0, 1]; 0 where an object has none, so the
group is harmless on unbaked objects)."""

import bpy

from .bridge import DEPOSIT_ATTR, STAIN_ATTR, WETNESS_ATTR

GROUP = "Madder Stain"


def _socket(group, name, in_out, kind, default=None, lo=None, hi=None):
    s = group.interface.new_socket(name, in_out=in_out, socket_type=kind)
    if default is not None:
        s.default_value = default
    if lo is not None:
        s.min_value, s.max_value = lo, hi
    return s


def _mix(nodes, data_type, blend="MIX"):
    n = nodes.new("ShaderNodeMix")
    n.data_type = data_type
    if data_type == "RGBA":
        n.blend_type = blend
    return n


def stain_group():
    """The node group, created once per file."""
    group = bpy.data.node_groups.get(GROUP)
    if group is not None:
        return group
    group = bpy.data.node_groups.new(GROUP, "ShaderNodeTree")
    _socket(group, "Base Color", "INPUT", "NodeSocketColor", (0.8, 0.8, 0.8, 1.0))
    _socket(group, "Roughness", "INPUT", "NodeSocketFloat", 0.5, 0.0, 1.0)
    _socket(group, "Wet Darkening", "INPUT", "NodeSocketFloat", 0.35, 0.0, 1.0)
    _socket(group, "Wet Roughness", "INPUT", "NodeSocketFloat", 0.25, 0.0, 1.0)
    _socket(group, "Deposit Darkening", "INPUT", "NodeSocketFloat", 0.15, 0.0, 1.0)
    _socket(group, "Base Color", "OUTPUT", "NodeSocketColor")
    _socket(group, "Roughness", "OUTPUT", "NodeSocketFloat")
    nodes, links = group.nodes, group.links
    gin, gout = nodes.new("NodeGroupInput"), nodes.new("NodeGroupOutput")
    stain = nodes.new("ShaderNodeAttribute")
    stain.attribute_name = STAIN_ATTR
    wet = nodes.new("ShaderNodeAttribute")
    wet.attribute_name = WETNESS_ATTR
    deposit = nodes.new("ShaderNodeAttribute")
    deposit.attribute_name = DEPOSIT_ATTR
    # base · (1 − coverage) + stain
    keep = _mix(nodes, "RGBA")
    keep.inputs["B"].default_value = (0.0, 0.0, 0.0, 1.0)
    links.new(stain.outputs["Alpha"], keep.inputs["Factor"])
    links.new(gin.outputs["Base Color"], keep.inputs["A"])
    over = _mix(nodes, "RGBA", "ADD")
    over.inputs["Factor"].default_value = 1.0
    links.new(keep.outputs["Result"], over.inputs["A"])
    links.new(stain.outputs["Color"], over.inputs["B"])
    # darken with wetness: multiply by (1 − darkening · wetness)
    amount = nodes.new("ShaderNodeMath")
    amount.operation = "MULTIPLY"
    amount.use_clamp = True
    links.new(gin.outputs["Wet Darkening"], amount.inputs[0])
    links.new(wet.outputs["Fac"], amount.inputs[1])
    dark = _mix(nodes, "RGBA")
    dark.inputs["B"].default_value = (0.0, 0.0, 0.0, 1.0)
    links.new(amount.outputs["Value"], dark.inputs["Factor"])
    links.new(over.outputs["Result"], dark.inputs["A"])
    # and with the deposit: multiply by (1 − deposit darkening · deposit)
    mark = nodes.new("ShaderNodeMath")
    mark.operation = "MULTIPLY"
    mark.use_clamp = True
    links.new(gin.outputs["Deposit Darkening"], mark.inputs[0])
    links.new(deposit.outputs["Fac"], mark.inputs[1])
    marked = _mix(nodes, "RGBA")
    marked.inputs["B"].default_value = (0.0, 0.0, 0.0, 1.0)
    links.new(mark.outputs["Value"], marked.inputs["Factor"])
    links.new(dark.outputs["Result"], marked.inputs["A"])
    links.new(marked.outputs["Result"], gout.inputs["Base Color"])
    # roughness towards the wet roughness
    rough = _mix(nodes, "FLOAT")
    links.new(wet.outputs["Fac"], rough.inputs["Factor"])
    links.new(gin.outputs["Roughness"], rough.inputs["A"])
    links.new(gin.outputs["Wet Roughness"], rough.inputs["B"])
    links.new(rough.outputs["Result"], gout.inputs["Roughness"])
    for i, n in enumerate((gin, stain, wet, deposit, keep, over, amount, dark, mark, marked, rough, gout)):
        n.location = (200 * i, 0)
    return group


def add_to_material(material):
    """Inserts the group in front of the material's Principled BSDF (Base Color and
    Roughness), keeping whatever fed them. Returns False when there is nothing to do
    (no Principled BSDF, or the group is already there)."""
    nt = material.node_tree
    if nt is None:
        return False
    bsdf = next((n for n in nt.nodes if n.type == "BSDF_PRINCIPLED"), None)
    if bsdf is None:
        return False
    if any(n.type == "GROUP" and n.node_tree and n.node_tree.name == GROUP for n in nt.nodes):
        return False
    node = nt.nodes.new("ShaderNodeGroup")
    node.node_tree = stain_group()
    node.label = GROUP
    node.location = (bsdf.location.x - 250, bsdf.location.y)
    for name in ("Base Color", "Roughness"):
        src = bsdf.inputs[name]
        if src.is_linked:
            nt.links.new(src.links[0].from_socket, node.inputs[name])
        else:
            node.inputs[name].default_value = src.default_value
        nt.links.new(node.outputs[name], src)
    return True


class MADDER_OT_add_stain_shader(bpy.types.Operator):
    """Add the Madder Stain node group to every material of the active object"""

    bl_idname = "madder.add_stain_shader"
    bl_label = "Add Stain Shader"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        return context.object is not None and context.object.type == "MESH"

    def execute(self, context):
        obj = context.object
        mats = [s.material for s in obj.material_slots if s.material is not None]
        if not mats:
            mat = bpy.data.materials.new(f"{obj.name} Cloth")
            mat.use_nodes = True
            obj.data.materials.append(mat)
            mats = [mat]
        added = [m.name for m in mats if add_to_material(m)]
        if added:
            self.report({"INFO"}, f"Madder: stain shader added to {', '.join(added)}")
        else:
            self.report({"INFO"}, "Madder: every material already has the stain shader (or no Principled BSDF)")
        return {"FINISHED"}


def register():
    bpy.utils.register_class(MADDER_OT_add_stain_shader)


def unregister():
    bpy.utils.unregister_class(MADDER_OT_add_stain_shader)
