"""The "Madder Stain" shader node group, the nodes that feed it, and the one-click
operator that adds them to an object's materials.

The group takes the material's Base Color and Roughness and returns them stained:

    color  = base · (1 − coverage) + stain          (stain: RGB = color × coverage,
                                                     premultiplied "over")
    color *= 1 − darkening · wetness                (wet fabric looks darker)
    color *= 1 − deposit darkening · deposit        (bound dye is a little darker still)
    color *= yarn                                   (the weave's reflectance factor, mean 1:
                                                     the Madder Weave node, weave_shader)
    rough  = mix(roughness, wet roughness, wetness) (and shinier)

`stain`, `coverage`, `wetness` and `deposit` (each in [0, 1]) are inputs of the group,
fed in the material by nodes that `sync_material` places (named "Madder Input: …"):

- *Vertex Colors*: Attribute nodes reading `madder_stain` (Color, Alpha),
  `madder_wetness` and `madder_deposit` (0 where an object has none, so the group is
  harmless on unbaked objects);
- *Image Sequence* (when the object has baked images and wants them): two Image Texture
  nodes on the object's sequences (`images.sequence_image`: non-colour, channel-packed
  alpha, auto refresh, frame start/offset/length so that scene frame f shows file f),
  read through a UV Map node of the UV map they were baked for; the wet image's R and G
  are the wetness and deposit.

A bake, a re-export, Free Bake and switching the output re-run `sync_object`, so a
material that has the group always reads what its object has. A group made by an older
Madder (it read the attributes itself) is upgraded in place: its sockets keep their
identifiers (the material's links stay), it gains the four inputs, and every material
using it gets its input nodes."""

import bpy

from . import compat, images, stored, weave_shader
from .bridge import DEPOSIT_ATTR, STAIN_ATTR, WETNESS_ATTR

GROUP = "Madder Stain"
INPUT_PREFIX = "Madder Input: "
# the group's inputs: name, socket type, default, range
_INPUTS = (
    ("Base Color", "NodeSocketColor", (0.8, 0.8, 0.8, 1.0), None),
    ("Roughness", "NodeSocketFloat", 0.5, (0.0, 1.0)),
    ("Wet Darkening", "NodeSocketFloat", 0.35, (0.0, 1.0)),
    ("Wet Roughness", "NodeSocketFloat", 0.25, (0.0, 1.0)),
    ("Deposit Darkening", "NodeSocketFloat", 0.15, (0.0, 1.0)),
    ("Stain", "NodeSocketColor", (0.0, 0.0, 0.0, 1.0), None),
    ("Coverage", "NodeSocketFloat", 0.0, (0.0, 1.0)),
    ("Wetness", "NodeSocketFloat", 0.0, (0.0, 1.0)),
    ("Deposit", "NodeSocketFloat", 0.0, (0.0, 1.0)),
    ("Yarn", "NodeSocketFloat", 1.0, (0.0, 10.0)),  # the weave's reflectance factor (weave_shader)
)
_OUTPUTS = (("Base Color", "NodeSocketColor"), ("Roughness", "NodeSocketFloat"))


def _sockets(group, in_out):
    return {s.name: s for s in group.interface.items_tree if s.item_type == "SOCKET" and s.in_out == in_out}


def _ensure_sockets(group):
    """Adds the sockets `group` lacks (existing ones keep their identifiers)."""
    have = _sockets(group, "INPUT")
    for name, kind, default, bounds in _INPUTS:
        if name not in have:
            s = group.interface.new_socket(name, in_out="INPUT", socket_type=kind)
            s.default_value = default
            if bounds is not None:
                s.min_value, s.max_value = bounds
    have = _sockets(group, "OUTPUT")
    for name, kind in _OUTPUTS:
        if name not in have:
            group.interface.new_socket(name, in_out="OUTPUT", socket_type=kind)


def _mix(nodes, data_type, blend="MIX"):
    n = nodes.new("ShaderNodeMix")
    n.data_type = data_type
    if data_type == "RGBA":
        n.blend_type = blend
    return n


def _build(group):
    """The group's maths, from its inputs (see the module doc)."""
    _ensure_sockets(group)
    nodes, links = group.nodes, group.links
    nodes.clear()
    gin, gout = nodes.new("NodeGroupInput"), nodes.new("NodeGroupOutput")
    # base · (1 − coverage) + stain
    keep = _mix(nodes, "RGBA")
    keep.inputs["B"].default_value = (0.0, 0.0, 0.0, 1.0)
    links.new(gin.outputs["Coverage"], keep.inputs["Factor"])
    links.new(gin.outputs["Base Color"], keep.inputs["A"])
    over = _mix(nodes, "RGBA", "ADD")
    over.inputs["Factor"].default_value = 1.0
    links.new(keep.outputs["Result"], over.inputs["A"])
    links.new(gin.outputs["Stain"], over.inputs["B"])
    # darken with wetness: multiply by (1 − darkening · wetness)
    amount = nodes.new("ShaderNodeMath")
    amount.operation = "MULTIPLY"
    amount.use_clamp = True
    links.new(gin.outputs["Wet Darkening"], amount.inputs[0])
    links.new(gin.outputs["Wetness"], amount.inputs[1])
    dark = _mix(nodes, "RGBA")
    dark.inputs["B"].default_value = (0.0, 0.0, 0.0, 1.0)
    links.new(amount.outputs["Value"], dark.inputs["Factor"])
    links.new(over.outputs["Result"], dark.inputs["A"])
    # and with the deposit: multiply by (1 − deposit darkening · deposit)
    mark = nodes.new("ShaderNodeMath")
    mark.operation = "MULTIPLY"
    mark.use_clamp = True
    links.new(gin.outputs["Deposit Darkening"], mark.inputs[0])
    links.new(gin.outputs["Deposit"], mark.inputs[1])
    marked = _mix(nodes, "RGBA")
    marked.inputs["B"].default_value = (0.0, 0.0, 0.0, 1.0)
    links.new(mark.outputs["Value"], marked.inputs["Factor"])
    links.new(dark.outputs["Result"], marked.inputs["A"])
    # the weave's local reflectance factor (mean 1 over a tile: weave_shader)
    yarn = _mix(nodes, "RGBA", "MULTIPLY")
    yarn.inputs["Factor"].default_value = 1.0
    links.new(marked.outputs["Result"], yarn.inputs["A"])
    combine = nodes.new("ShaderNodeCombineColor")
    for c in ("Red", "Green", "Blue"):
        links.new(gin.outputs["Yarn"], combine.inputs[c])
    links.new(combine.outputs["Color"], yarn.inputs["B"])
    links.new(yarn.outputs["Result"], gout.inputs["Base Color"])
    # roughness towards the wet roughness
    rough = _mix(nodes, "FLOAT")
    links.new(gin.outputs["Wetness"], rough.inputs["Factor"])
    links.new(gin.outputs["Roughness"], rough.inputs["A"])
    links.new(gin.outputs["Wet Roughness"], rough.inputs["B"])
    links.new(rough.outputs["Result"], gout.inputs["Roughness"])
    for i, n in enumerate((gin, keep, over, amount, dark, mark, marked, combine, yarn, rough, gout)):
        n.location = (200 * i, 0)


def _current(group):
    return set(_sockets(group, "INPUT")) >= {name for name, *_ in _INPUTS}


def stain_group():
    """The node group, created once per file (and upgraded once, when an older Madder
    made it: see the module doc)."""
    group = bpy.data.node_groups.get(GROUP)
    if group is not None and _current(group):
        return group
    if group is None:
        group = bpy.data.node_groups.new(GROUP, "ShaderNodeTree")
        _build(group)
        return group
    _build(group)
    for mat in bpy.data.materials:  # the old group read the attributes itself: feed them now
        if _group_node(mat) is not None:
            sync_material(mat, _owner(mat))
    return group


def _group_node(material):
    nt = material.node_tree
    if nt is None:
        return None
    return next((n for n in nt.nodes if n.type == "GROUP" and n.node_tree and n.node_tree.name == GROUP), None)


def _owner(material):
    """A Madder object using `material` (the first), or None."""
    return next((o for o in bpy.data.objects if o.type == "MESH" and o.madder.enabled
                 and any(s.material == material for s in o.material_slots)), None)


def sync_material(material, obj):
    """Replaces the input nodes of the material's Madder Stain group by those `obj` needs
    (images when it has baked images and wants them, attributes otherwise; attributes for
    no object). Does nothing to a material without the group."""
    node = _group_node(material)
    if node is None:
        return False
    nt = material.node_tree
    kept_normal = weave_shader.user_normal(nt)
    for n in [n for n in nt.nodes if n.name.startswith(INPUT_PREFIX)]:
        nt.nodes.remove(n)
    x, y = node.location.x - 300, node.location.y
    if obj is not None and stored.uses_images(obj):
        _image_inputs(nt, node, obj, x, y)
    else:
        _attribute_inputs(nt, node, x, y)
    weave_shader.place(material, obj, node, INPUT_PREFIX, x, y, kept_normal)
    return True


def _new(nt, kind, name, x, y):
    n = nt.nodes.new(kind)
    n.name = n.label = INPUT_PREFIX + name
    n.location = (x, y)
    n.hide = True
    return n


def _attribute_inputs(nt, node, x, y):
    stain = _new(nt, "ShaderNodeAttribute", "Stain", x, y - 260)
    stain.attribute_name = STAIN_ATTR
    wet = _new(nt, "ShaderNodeAttribute", "Wetness", x, y - 300)
    wet.attribute_name = WETNESS_ATTR
    deposit = _new(nt, "ShaderNodeAttribute", "Deposit", x, y - 340)
    deposit.attribute_name = DEPOSIT_ATTR
    nt.links.new(stain.outputs["Color"], node.inputs["Stain"])
    nt.links.new(stain.outputs["Alpha"], node.inputs["Coverage"])
    nt.links.new(wet.outputs["Fac"], node.inputs["Wetness"])
    nt.links.new(deposit.outputs["Fac"], node.inputs["Deposit"])


def _image_inputs(nt, node, obj, x, y):
    uv = _new(nt, "ShaderNodeUVMap", "UV Map", x - 500, y - 280)
    uv.uv_map = obj.madder.image_uv_map
    textures = {}
    for i, kind in enumerate(("stain", "wet")):
        tex = _new(nt, "ShaderNodeTexImage", f"{kind.capitalize()} Image", x - 250, y - 260 - 40 * i)
        tex.image = images.sequence_image(obj, kind)
        tex.interpolation = "Linear"
        tex.extension = "EXTEND"
        images.set_image_user(tex.image_user, obj)
        nt.links.new(uv.outputs["UV"], tex.inputs["Vector"])
        textures[kind] = tex
    channels = _new(nt, "ShaderNodeSeparateColor", "Wetness and Deposit", x, y - 300)
    nt.links.new(textures["wet"].outputs["Color"], channels.inputs["Color"])
    nt.links.new(textures["stain"].outputs["Color"], node.inputs["Stain"])
    nt.links.new(textures["stain"].outputs["Alpha"], node.inputs["Coverage"])
    nt.links.new(channels.outputs["Red"], node.inputs["Wetness"])
    nt.links.new(channels.outputs["Green"], node.inputs["Deposit"])


def sync_object(obj):
    """`sync_material` for each of `obj`'s materials that has the group; returns their names."""
    done = []
    for slot in obj.material_slots:
        mat = slot.material
        if mat is not None and mat.name not in done and sync_material(mat, obj):
            done.append(mat.name)
    return done


def add_to_material(material, obj=None):
    """Inserts the group in front of the material's Principled BSDF (Base Color and
    Roughness), keeping whatever fed them, and its input nodes for `obj`. Returns False
    when the group was already there (its inputs are synced again) or the material has
    no Principled BSDF."""
    nt = material.node_tree
    if nt is None:
        return False
    bsdf = next((n for n in nt.nodes if n.type == "BSDF_PRINCIPLED"), None)
    if bsdf is None:
        return False
    group = stain_group()
    if _group_node(material) is not None:
        sync_material(material, obj)
        return False
    node = nt.nodes.new("ShaderNodeGroup")
    node.node_tree = group
    node.name = node.label = GROUP
    node.location = (bsdf.location.x - 250, bsdf.location.y)
    for name in ("Base Color", "Roughness"):
        src = bsdf.inputs[name]
        if src.is_linked:
            nt.links.new(src.links[0].from_socket, node.inputs[name])
        else:
            node.inputs[name].default_value = src.default_value
        nt.links.new(node.outputs[name], src)
    sync_material(material, obj)
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
            compat.ensure_node_tree(mat)
            obj.data.materials.append(mat)
            mats = [mat]
        added = [m.name for m in mats if add_to_material(m, obj)]
        source = "its image sequence" if stored.uses_images(obj) else "its vertex colors"
        if added:
            self.report({"INFO"}, f"Madder: stain shader added to {', '.join(added)}, reading {source}")
        else:
            self.report({"INFO"}, f"Madder: the stain shader reads {source} (materials without a "
                        "Principled BSDF are left alone)")
        for mat in mats:
            # images are per object: a material shared with another stained object shows one of them
            other = next((o for o in bpy.data.objects if o != obj and o.type == "MESH" and o.madder.enabled
                          and (stored.uses_images(o) or stored.uses_images(obj))
                          and any(s.material == mat for s in o.material_slots)), None)
            if other is not None:
                self.report({"WARNING"}, f"Madder: material '{mat.name}' is shared with '{other.name}': its "
                            "stain inputs follow one object only; give each object its own material")
        return {"FINISHED"}


def register():
    bpy.utils.register_class(MADDER_OT_add_stain_shader)
    weave_shader.register()


def unregister():
    weave_shader.unregister()
    bpy.utils.unregister_class(MADDER_OT_add_stain_shader)
