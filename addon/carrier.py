"""Where playback puts a frame's stain: on a *carrier* mesh, read by a Geometry Nodes
modifier at the top of the cloth's stack, never on the cloth's own mesh.

Writing attributes into the cloth's mesh (`foreach_set`, with or without `mesh.update()`)
is a user edit of its geometry: Blender marks the Cloth modifier's point cache outdated,
drops every frame it held in memory and simulates the cloth again on every frame that
plays (measured in bpy 5.0.1 on the flag fixture with an unbaked cache: 30 frames held
before playback, 2 after, and the cloth re-simulated per frame). A stain played from a
Madder bake must not throw away the cloth it was baked on.

So each stained object gets a carrier: an object (not linked to any scene, named
`.madder_stain <object>`; the leading dot hides it from Blender's ID lists; the object it
serves is recorded in its `madder_cloth` property, so a renamed or duplicated cloth gets
its own) whose mesh has the cloth's vertex count and nothing else. Playback writes `madder_stain`,
`madder_wetness` and `madder_deposit` there. The cloth's modifier "Madder Stain", first
in its stack, copies them by vertex index onto the cloth (Object Info → Sample Index →
Store Named Attribute, one per field), so they flow through the Cloth modifier and any
modifier below it exactly as attributes of the original mesh did, and the materials'
Attribute nodes read them by the same names. A change of the carrier re-evaluates the
cloth's stack but is not an edit of the cloth: its cache stays valid (30 frames held,
0.2 ms per played frame on the flag).

Carriers and the modifier are made outside renders (at bake start, on file load, when
Live shows its first frame); a render never adds data-blocks mid-frame."""

import bpy
import numpy as np

from . import compat
from .bridge import DEPOSIT_ATTR, STAIN_ATTR, WETNESS_ATTR

MODIFIER = "Madder Stain"
GROUP = ".Madder Stain Attributes"
PREFIX = ".madder_stain "
OWNER = "madder_cloth"  # custom property of a carrier: the name of the object it serves
_VERSION = 1  # of the node group's layout; an older group is rebuilt
# (name, data type, foreach property, floats per vertex)
FIELDS = ((STAIN_ATTR, "FLOAT_COLOR", "color", 4), (WETNESS_ATTR, "FLOAT", "value", 1),
          (DEPOSIT_ATTR, "FLOAT", "value", 1))


def _group():
    """The node group the modifiers share: the carrier's three fields stored on the
    modified geometry's points, sampled by index."""
    ng = bpy.data.node_groups.get(GROUP)
    if ng is not None and ng.get("madder_version") == _VERSION and _socket(ng) is not None:
        return ng
    if ng is None:
        ng = bpy.data.node_groups.new(GROUP, "GeometryNodeTree")
    ng.nodes.clear()
    ng.interface.clear()
    ng.interface.new_socket("Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
    ng.interface.new_socket("Carrier", in_out="INPUT", socket_type="NodeSocketObject")
    ng.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    nodes, links = ng.nodes, ng.links
    group_in, group_out = nodes.new("NodeGroupInput"), nodes.new("NodeGroupOutput")
    info = nodes.new("GeometryNodeObjectInfo")
    links.new(group_in.outputs[1], info.inputs["Object"])
    index = nodes.new("GeometryNodeInputIndex")
    geometry = group_in.outputs[0]
    for name, data_type, _, _ in FIELDS:
        attr = nodes.new("GeometryNodeInputNamedAttribute")
        attr.data_type = data_type
        attr.inputs["Name"].default_value = name
        sample = nodes.new("GeometryNodeSampleIndex")
        sample.data_type, sample.domain = data_type, "POINT"
        links.new(info.outputs["Geometry"], sample.inputs["Geometry"])
        links.new(attr.outputs["Attribute"], sample.inputs["Value"])
        links.new(index.outputs["Index"], sample.inputs["Index"])
        store = nodes.new("GeometryNodeStoreNamedAttribute")
        store.data_type, store.domain = data_type, "POINT"
        store.inputs["Name"].default_value = name
        links.new(geometry, store.inputs["Geometry"])
        links.new(sample.outputs[0], store.inputs["Value"])
        geometry = store.outputs[0]
    links.new(geometry, group_out.inputs[0])
    ng["madder_version"] = _VERSION
    return ng


def _socket(ng):
    """The identifier of the group's Object input (None if someone removed it)."""
    return next((s.identifier for s in ng.interface.items_tree
                 if getattr(s, "in_out", None) == "INPUT" and getattr(s, "socket_type", "") == "NodeSocketObject"),
                None)


def modifier(obj):
    """`obj`'s "Madder Stain" modifier, or None."""
    m = obj.modifiers.get(MODIFIER)
    return m if m is not None and m.type == "NODES" else None


def find(obj):
    """`obj`'s carrier mesh if it has a valid one (its own, with its vertex count), else None."""
    m = modifier(obj)
    carrier = _carrier_of(m) if m is not None else None
    if (carrier is None or carrier.get(OWNER) != obj.name or carrier.type != "MESH"
            or len(carrier.data.vertices) != len(obj.data.vertices)):
        return None
    return carrier.data


def ensure(obj):
    """`obj`'s carrier mesh, made (with the modifier, first in the stack) if missing, stale
    (another vertex count) or another object's (a duplicate or renamed object)."""
    mesh = find(obj)
    if mesh is not None:
        show(obj, True)
        return mesh
    _drop_legacy(obj)
    name = PREFIX + obj.name  # Blender may shorten it: the owner is recorded on the carrier
    new_mesh = bpy.data.meshes.new(name)
    new_mesh.vertices.add(len(obj.data.vertices))
    for attr_name, data_type, _, _ in FIELDS:
        owner = new_mesh.color_attributes if data_type == "FLOAT_COLOR" else new_mesh.attributes
        owner.new(attr_name, data_type, "POINT")
    carrier = bpy.data.objects.new(name, new_mesh)
    carrier[OWNER] = obj.name
    ng = _group()
    m = modifier(obj)
    if m is None:
        m = obj.modifiers.new(MODIFIER, "NODES")
    old = _carrier_of(m)
    m.node_group = ng
    compat.set_modifier_input(m, _socket(ng), carrier)
    at = list(obj.modifiers).index(m)
    if at != 0:
        obj.modifiers.move(at, 0)
    if old is not None and old.get(OWNER) == obj.name and old.users == 0:
        _delete(old)  # this object's stale carrier (another vertex count)
    return new_mesh


def _carrier_of(m):
    """The carrier object modifier `m` reads, if its group is ours."""
    ng = m.node_group
    if ng is None or ng.get("madder_version") != _VERSION:
        return None
    socket = _socket(ng)
    return compat.modifier_input(m, socket) if socket is not None else None


def _delete(carrier):
    mesh = carrier.data
    bpy.data.objects.remove(carrier)
    if mesh is not None and mesh.users == 0:
        bpy.data.meshes.remove(mesh)


def _drop_legacy(obj):
    """Removes stain attributes from the cloth's own mesh, where Madder wrote them before
    carriers (a file saved by an older version): they would show a stale stain."""
    present = [a for a in (obj.data.attributes.get(name) for name, _, _, _ in FIELDS) if a is not None]
    for attr in present:
        obj.data.attributes.remove(attr)
    if present:
        obj.data.update()


def show(obj, on):
    """Shows (`on`) or hides `obj`'s "Madder Stain" modifier in the viewport and in renders: a
    hidden modifier is not evaluated, so a cloth with Madder switched off pays nothing for
    it; its carrier is zeroed too, so nothing stale shows if the modifier is shown by hand."""
    m = modifier(obj)
    if m is None or (m.show_viewport == on and m.show_render == on):
        return
    m.show_viewport = m.show_render = on
    if not on:
        clear(obj)


def clear(obj):
    """Zeros the carrier's fields (the cloth shows bare); makes nothing."""
    mesh = find(obj)
    if mesh is None:
        _drop_legacy(obj)
        return
    zeros = np.zeros(4 * len(mesh.vertices), dtype=np.float32)
    for name, _, prop, width in FIELDS:
        mesh.attributes[name].data.foreach_set(prop, zeros[: width * len(mesh.vertices)])
    mesh.update()


def remove(obj):
    """Removes `obj`'s modifier and its carrier (Free Bake)."""
    m = modifier(obj)
    if m is None:
        return
    carrier = _carrier_of(m)
    compat.remove_nodes_modifier(obj, m)
    if carrier is not None and carrier.get(OWNER) == obj.name and carrier.users == 0:
        _delete(carrier)
