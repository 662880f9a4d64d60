"""The compatibility module (`addon/compat.py`) on the Blender it runs in: each function
checked on real data, with the side it took asserted against what this Blender offers, so
that the version matrix (tests/bpy-versions.txt) exercises both sides of each difference."""

import importlib

import bpy
import pytest


@pytest.fixture
def compat(addon):
    return importlib.import_module(addon + ".compat")


@pytest.fixture
def plane():
    bpy.ops.wm.read_homefile(use_empty=True)
    mesh = bpy.data.meshes.new("plane")
    mesh.from_pydata([(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)], [], [(0, 1, 2, 3)])
    obj = bpy.data.objects.new("plane", mesh)
    bpy.context.scene.collection.objects.link(obj)
    return obj


def _nodes_modifier(obj):
    """A Geometry Nodes modifier whose group passes the geometry through, with an Object
    and a Float input; returns it and the two inputs' identifiers."""
    ng = bpy.data.node_groups.new("compat", "GeometryNodeTree")
    ng.interface.new_socket("Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
    target = ng.interface.new_socket("Target", in_out="INPUT", socket_type="NodeSocketObject")
    amount = ng.interface.new_socket("Amount", in_out="INPUT", socket_type="NodeSocketFloat")
    ng.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    gin, gout = ng.nodes.new("NodeGroupInput"), ng.nodes.new("NodeGroupOutput")
    ng.links.new(gin.outputs[0], gout.inputs[0])
    m = obj.modifiers.new("compat", "NODES")
    m.node_group = ng
    return m, target.identifier, amount.identifier


def test_nodes_modifier_inputs_round_trip_on_the_path_this_blender_has(compat, plane):
    m, target, amount = _nodes_modifier(plane)
    rna = getattr(getattr(m, "properties", None), "inputs", None) is not None
    assert compat.modifier_inputs_are_rna(m) == rna
    if rna:  # 5.2+: the modifier holds no ID properties any more
        with pytest.raises(TypeError):
            m.keys()
    else:
        assert target in m.keys()
    other = bpy.data.objects.new("other", None)
    assert compat.modifier_input(m, target) is None
    compat.set_modifier_input(m, target, other)
    compat.set_modifier_input(m, amount, 2.5)
    assert compat.modifier_input(m, target) == other
    assert compat.modifier_input(m, amount) == pytest.approx(2.5)
    # written where Blender itself reads it
    if rna:
        assert getattr(m.properties.inputs, target).value == other
    else:
        assert m[target] == other
    assert compat.modifier_input(m, "Socket_99") is None
    with pytest.raises(KeyError, match="Socket_99"):
        compat.set_modifier_input(m, "Socket_99", 1.0)


def test_a_removed_nodes_modifier_releases_the_object_it_held(compat, plane):
    """The carrier's Free Bake: once the modifier is gone, the object its input held has no
    user left (on 5.2+ a plain `modifiers.remove` leaves it one), so it can be deleted."""
    m, target, _ = _nodes_modifier(plane)
    held = bpy.data.objects.new("held", None)
    compat.set_modifier_input(m, target, held)
    assert held.users == 1
    compat.remove_nodes_modifier(plane, m)
    assert "compat" not in plane.modifiers
    assert held.users == 0 and not bpy.data.user_map(subset=[held])[held]


def test_an_object_input_set_through_compat_drives_the_evaluation(compat, plane):
    """The carrier's case: the modifier samples another object's mesh through its Object
    input; set through compat, the evaluated mesh follows that object's data (a write that
    did not tag the object would leave the old evaluation)."""
    ng = bpy.data.node_groups.new("copy", "GeometryNodeTree")
    ng.interface.new_socket("Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
    source = ng.interface.new_socket("Source", in_out="INPUT", socket_type="NodeSocketObject")
    ng.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    gin, gout = ng.nodes.new("NodeGroupInput"), ng.nodes.new("NodeGroupOutput")
    info = ng.nodes.new("GeometryNodeObjectInfo")
    ng.links.new(gin.outputs[1], info.inputs["Object"])
    ng.links.new(info.outputs["Geometry"], gout.inputs[0])
    m = plane.modifiers.new("copy", "NODES")
    m.node_group = ng
    tri = bpy.data.meshes.new("tri")
    tri.from_pydata([(0, 0, 0), (1, 0, 0), (0, 1, 0)], [], [(0, 1, 2)])
    donor = bpy.data.objects.new("donor", tri)  # in no scene, as the carriers are
    depsgraph = bpy.context.evaluated_depsgraph_get()
    assert len(plane.evaluated_get(depsgraph).data.vertices) == 0  # no source yet: empty
    compat.set_modifier_input(m, source.identifier, donor)
    depsgraph = bpy.context.evaluated_depsgraph_get()
    assert len(plane.evaluated_get(depsgraph).data.vertices) == 3
    tri.vertices.add(2)  # the donor's data changes: the evaluation follows it
    tri.update()
    depsgraph = bpy.context.evaluated_depsgraph_get()
    assert len(plane.evaluated_get(depsgraph).data.vertices) == 5


def test_mesh_cache_flip_none_matches_the_property_kind(compat, plane):
    m = plane.modifiers.new("cache", "MESH_CACHE")
    none = compat.mesh_cache_flip_none(m)
    if isinstance(m.flip_axis, set):  # to 4.5: an enum set
        assert none == set()
    else:  # 5.0+: one boolean per axis
        assert none == (False, False, False)
    m.flip_axis = none
    assert not any(m.flip_axis) if not isinstance(m.flip_axis, set) else m.flip_axis == set()


def test_set_poly_makes_poly_curves_where_python_can(compat):
    curves = bpy.data.hair_curves.new("c")
    curves.add_curves([3, 2])
    done = compat.set_poly(curves)
    assert done == hasattr(curves, "set_types")
    if done:  # the built-in curve_type attribute, CURVE_TYPE_POLY = 1
        types = [v.value for v in curves.attributes["curve_type"].data]
        assert types == [1, 1]


def test_ensure_node_tree_gives_a_new_material_its_tree(compat):
    mat = bpy.data.materials.new("m")
    tree = compat.ensure_node_tree(mat)
    assert tree is not None and tree == mat.node_tree
    assert any(n.type == "BSDF_PRINCIPLED" for n in tree.nodes)


def test_blend_relative_option_is_offered_where_blender_knows_it(compat):
    """Registering a class is where Blender checks the option (4.2 refuses the class)."""

    class Probe(bpy.types.PropertyGroup):
        path: bpy.props.StringProperty(subtype="FILE_PATH", options={"PATH_SUPPORTS_BLEND_RELATIVE"})

    try:
        bpy.utils.register_class(Probe)
        known = True
        bpy.utils.unregister_class(Probe)
    except (ValueError, RuntimeError):
        known = False
    assert bool(compat.BLEND_RELATIVE) == known
    # the settings that hold `//` paths say so, where Blender can tell
    prop = bpy.types.Object.bl_rna.properties["madder"].fixed_type.properties["cache_file"]
    if hasattr(prop, "is_path_supports_blend_relative"):
        assert prop.is_path_supports_blend_relative == known
