"""Coherent structures in the scene (bpy side of `lcs`): reads the request from the
object's settings, runs `lcs.compute` on its cache, writes the FTLE as the POINT attribute
`madder_ftle` and the ridges as a curves object that follows the cloth.

Following the cloth: every ridge point is stored on the curves as the three vertices of its
cloth triangle (`madder_v0/1/2`, INT) and its barycentric weights (`madder_bary`), and a
Geometry Nodes modifier ("Madder Ridges") moves each point to `Σ w_k x_k` of the
*evaluated* cloth (Object Info, relative). So the ridge stays at the same place of the
cloth in the viewport, on scrubbing and in renders, with no frame-change handler (which
cannot read the evaluated cloth before it is evaluated, see `handlers`) and no binding
step that a Surface Deform modifier would need (and that only approximates points off its
bind mesh). The stored positions are the ridge at the computed frame, in Blender units."""

import bpy
import numpy as np

from . import bridge, compat, lcs, playback, stored
from .errors import LcsError

NODE_GROUP = "Madder Ridges"
MODIFIER = "Madder Ridges"
INDEX_ATTRS = ("madder_v0", "madder_v1", "madder_v2")
BARY_ATTR = "madder_bary"


def request(obj):
    """`(frame, span, direction, steps_per_frame, ridge keywords)` of `obj`'s settings."""
    s = obj.madder.lcs
    return s.frame, s.span, s.direction, s.steps_per_frame, {k: getattr(s, k) for k in lcs.RIDGE_KEYS}


def open_cache(madder, obj):
    """The cache reader of `obj`'s bake, after the checks playback makes (file, vertex
    count, faces); an `LcsError` naming the object and the file otherwise."""
    name = obj.name
    if obj.type != "MESH":
        raise LcsError(f"'{name}' is a {obj.type.lower()}, not a mesh with a baked stain", object=name)
    if not obj.madder.cache_file:
        raise LcsError(f"'{name}' has no bake: tick Bake Flow and bake the stain first", object=name)
    path = stored.played_path(obj)
    try:
        reader = madder.CacheReader(path)
    except (OSError, madder.MadderError) as e:
        raise LcsError(f"'{name}': cannot read its cache: {e}", object=name, filename=path) from e
    why = playback.mismatch(path, reader, len(obj.data.vertices))
    if why is None and obj.madder.bake_topology and not stored.same_topology(obj.data, obj.madder.bake_topology):
        why = f"the faces of '{name}' changed since the bake of {path}: bake again"
    if why is not None:
        raise LcsError(f"'{name}': {why}", object=name, filename=path)
    return path, reader


def compute(madder, obj, progress=None):
    """`lcs.Structures` of `obj`'s bake with its settings (nothing in the scene changes)."""
    path, reader = open_cache(madder, obj)
    faces, _, _ = bridge.topology_arrays(obj.data)
    frame, span, direction, steps, options = request(obj)
    return lcs.compute(madder, obj.name, path, reader, faces, frame, span, direction, steps, options, progress)


def write_ftle(obj, sigma):
    """`sigma` as the float POINT attribute `madder_ftle` of `obj`'s mesh."""
    attr = bridge._attribute(obj.data, bridge.FTLE_ATTR, "FLOAT", "POINT")
    attr.data.foreach_set("value", np.asarray(sigma, dtype=np.float32))
    obj.data.update()


def remove_ridges(obj):
    """Deletes the curves object of `obj`'s previous run (its data and node group with it
    when nothing else uses them)."""
    old = obj.madder.lcs.ridge_object
    if old is None:
        return
    data = old.data if old.type == "CURVES" else None
    groups = [m.node_group for m in old.modifiers if m.type == "NODES" and m.node_group is not None]
    obj.madder.lcs.ridge_object = None
    bpy.data.objects.remove(old)
    if data is not None and data.users == 0:
        bpy.data.hair_curves.remove(data)
    for g in groups:
        if g.users == 0:
            bpy.data.node_groups.remove(g)


def add_ridges(scene, obj, ridges, unit):
    """A curves object `"<obj> Ridges"` holding `ridges` (a `madder.ridges` dict at the
    cloth's positions, metres) as poly curves bound to `obj`'s triangles; replaces the
    previous one. Returns it (None when there are no ridges)."""
    remove_ridges(obj)
    faces, _, _ = bridge.topology_arrays(obj.data)
    lines = lcs.polylines(len(ridges["points"]), ridges["edges"])
    if not lines:
        return None
    order = np.concatenate([np.asarray(chain, dtype=np.int64) for chain, _ in lines])
    verts, weights = lcs.binding(faces, ridges["triangles"], ridges["barycentric"])
    curves = bpy.data.hair_curves.new(f"{obj.name} Ridges")
    curves.add_curves([len(chain) for chain, _ in lines])
    # poly curves (where Python cannot set them, the node group's Set Spline Type does)
    compat.set_poly(curves)
    pos = (np.asarray(ridges["points"])[order] / unit).astype(np.float32)
    curves.position_data.foreach_set("vector", pos.ravel())
    cyclic = curves.attributes.new("cyclic", "BOOLEAN", "CURVE")
    cyclic.data.foreach_set("value", np.array([c for _, c in lines], dtype=bool))
    radius = curves.attributes.new("radius", "FLOAT", "POINT")
    radius.data.foreach_set("value", np.full(len(order), obj.madder.lcs.radius, dtype=np.float32))
    for k, name in enumerate(INDEX_ATTRS):
        curves.attributes.new(name, "INT", "POINT").data.foreach_set("value", verts[order, k])
    curves.attributes.new(BARY_ATTR, "FLOAT_VECTOR", "POINT").data.foreach_set("vector", weights[order].ravel())
    ridge = bpy.data.objects.new(curves.name, curves)
    collection = next((c for c in obj.users_collection if scene.user_of_id(c)), scene.collection)
    collection.objects.link(ridge)
    modifier = ridge.modifiers.new(MODIFIER, "NODES")
    modifier.node_group = _binding_group(obj)
    obj.madder.lcs.ridge_object = ridge
    return ridge


def _binding_group(cloth):
    """The node group that places each point at `Σ_k madder_bary[k] · position[madder_v{k}]`
    of the evaluated `cloth` (in the curves object's space), as poly curves."""
    g = bpy.data.node_groups.new(f"{NODE_GROUP} ({cloth.name})", "GeometryNodeTree")
    g.interface.new_socket("Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
    g.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    nodes, links = g.nodes, g.links
    gin, gout = nodes.new("NodeGroupInput"), nodes.new("NodeGroupOutput")
    info = nodes.new("GeometryNodeObjectInfo")
    info.transform_space = "RELATIVE"
    info.inputs["Object"].default_value = cloth
    position = nodes.new("GeometryNodeInputPosition")
    bary = nodes.new("GeometryNodeInputNamedAttribute")
    bary.data_type = "FLOAT_VECTOR"
    bary.inputs["Name"].default_value = BARY_ATTR
    weights = nodes.new("ShaderNodeSeparateXYZ")
    links.new(bary.outputs["Attribute"], weights.inputs["Vector"])
    total = None
    for k, name in enumerate(INDEX_ATTRS):
        index = nodes.new("GeometryNodeInputNamedAttribute")
        index.data_type = "INT"
        index.inputs["Name"].default_value = name
        sample = nodes.new("GeometryNodeSampleIndex")
        sample.data_type = "FLOAT_VECTOR"
        sample.domain = "POINT"
        links.new(info.outputs["Geometry"], sample.inputs["Geometry"])
        links.new(position.outputs["Position"], sample.inputs["Value"])
        links.new(index.outputs["Attribute"], sample.inputs["Index"])
        scaled = nodes.new("ShaderNodeVectorMath")
        scaled.operation = "SCALE"
        links.new(sample.outputs["Value"], scaled.inputs[0])
        links.new(weights.outputs[k], scaled.inputs["Scale"])
        if total is None:
            total = scaled
        else:
            add = nodes.new("ShaderNodeVectorMath")
            add.operation = "ADD"
            links.new(total.outputs["Vector"], add.inputs[0])
            links.new(scaled.outputs["Vector"], add.inputs[1])
            total = add
    place = nodes.new("GeometryNodeSetPosition")
    links.new(gin.outputs[0], place.inputs["Geometry"])
    links.new(total.outputs["Vector"], place.inputs["Position"])
    poly = nodes.new("GeometryNodeCurveSplineType")
    poly.spline_type = "POLY"
    links.new(place.outputs["Geometry"], poly.inputs["Curve"])
    links.new(poly.outputs["Curve"], gout.inputs[0])
    return g
