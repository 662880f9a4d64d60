"""The Blender APIs that differ between the versions Madder supports (4.2 LTS to the newest),
each behind one function that picks its path by *feature*, never by version number: a
Blender that back-ports a change, or a future one that drops an old path, takes the right
branch without an edit here. Every other module goes through these functions; the Blender
suite runs on each version of the matrix (tests/bpy-versions.txt), and
`tests/blender/test_compat.py` checks each function on real data, asserting which side it
took, so both sides of each difference are exercised somewhere in the matrix.

The differences met so far (older Blender → newer Blender):

- A Geometry Nodes modifier's inputs: ID properties on the modifier, `m[identifier]`,
  `m.get()`, `m.keys()` (to 5.1) → RNA structs, `m.properties.inputs.<identifier>.value`,
  where `m[...]`, `m.get()` and `m.keys()` raise TypeError (5.2+). On 5.2.3 writing an
  Object input that way does not make the depsgraph follow that object (5.3.0 does).
- Removing that modifier: releases the data-blocks its inputs held (to 5.1) → leaves each
  a user (5.2.3, 5.3.0), so the inputs are cleared first.
- A Mesh Cache modifier's `flip_axis`: an enum set (to 4.5) → three booleans (5.0+).
- A curves data-block's poly type: no `set_types`, the node group's Set Spline Type does
  it (4.2) → `curves.set_types(type="POLY")` (4.3+).
- A new material's node tree: made by `material.use_nodes = True` (to 4.5) → always
  there, `use_nodes` deprecated (5.0+), to be removed in 6.0.
- `//`-relative paths in a path property: no option (to 4.4) →
  `options={"PATH_SUPPORTS_BLEND_RELATIVE"}` (4.5+).
"""

import bpy

# --- Geometry Nodes modifier inputs --------------------------------------------------------


def _interface_inputs(modifier):
    """The modifier's RNA input structs (`modifier.properties.inputs`), or None where its
    inputs are ID properties."""
    return getattr(getattr(modifier, "properties", None), "inputs", None)


def modifier_inputs_are_rna(modifier):
    """True where a Geometry Nodes modifier's inputs are RNA structs (`properties.inputs`)."""
    return _interface_inputs(modifier) is not None


def modifier_input(modifier, identifier):
    """The value of the Geometry Nodes modifier's input `identifier` (a socket identifier,
    `Socket_1`), or None if the modifier has no such input."""
    inputs = _interface_inputs(modifier)
    if inputs is not None:
        item = getattr(inputs, identifier, None)
        return getattr(item, "value", None) if item is not None else None
    return modifier.get(identifier)


def set_modifier_input(modifier, identifier, value):
    """Sets the Geometry Nodes modifier's input `identifier` to `value`, so that the next
    evaluation uses it (and follows the object or other data-block it names). Raises
    KeyError if the input does not exist."""
    inputs = _interface_inputs(modifier)
    if inputs is not None:
        item = getattr(inputs, identifier, None)
        if item is None or not hasattr(item, "value"):
            raise KeyError(f"modifier '{modifier.name}' has no input {identifier!r}")
        item.value = value
    else:
        if modifier.node_group is None or not any(
                getattr(s, "identifier", None) == identifier for s in modifier.node_group.interface.items_tree):
            raise KeyError(f"modifier '{modifier.name}' has no input {identifier!r}")
        modifier[identifier] = value
    # Neither write is sure to reach the depsgraph: an ID property write runs no update at
    # all, and on 5.2.3 the RNA write of an Object input re-evaluates nothing (5.3.0's
    # does), since the new dependency is not in the depsgraph's relations. Assigning the
    # node group again rebuilds them (the group keeps its inputs' values) and tags the
    # object, on every version.
    modifier.node_group = modifier.node_group


def remove_nodes_modifier(obj, modifier):
    """Removes the Geometry Nodes `modifier` from `obj`, releasing the data-blocks its inputs
    hold. Where inputs are RNA structs, a removed modifier leaves each data-block its inputs
    held with the user it gave it (seen on 5.2.3 and 5.3.0: `users` stays 1 while
    `bpy.data.user_map` finds no user), so a carrier would never count as unused: those
    inputs are cleared first, which releases the user."""
    inputs = _interface_inputs(modifier)
    if inputs is not None:
        for prop in inputs.bl_rna.properties:
            if prop.identifier in ("rna_type", "name"):
                continue
            item = getattr(inputs, prop.identifier, None)
            value = item.bl_rna.properties.get("value") if item is not None else None
            if value is not None and value.type == "POINTER" and item.value is not None:
                item.value = None
    obj.modifiers.remove(modifier)


# --- Mesh Cache ----------------------------------------------------------------------------


def mesh_cache_flip_none(modifier):
    """The value of a Mesh Cache modifier's `flip_axis` that flips no axis: an empty set where
    it is an enum set, all-False booleans where it is a boolean array."""
    current = modifier.flip_axis
    return set() if isinstance(current, set) else (False,) * len(current)


# --- Curves --------------------------------------------------------------------------------


def can_set_curve_types(curves):
    """True where a curves data-block sets its curve types from Python (`set_types`)."""
    return hasattr(curves, "set_types")


def set_poly(curves):
    """Makes every curve of `curves` a poly curve where Python can; returns False where it
    cannot (the caller's node group must then use Set Spline Type: creating the built-in
    `curve_type` attribute by hand corrupts memory in Blender 4.2)."""
    if not can_set_curve_types(curves):
        return False
    curves.set_types(type="POLY")
    return True


# --- Materials -----------------------------------------------------------------------------


def ensure_node_tree(idblock):
    """`idblock`'s (a material's or world's) node tree, made where it is made on request
    (`use_nodes`, deprecated once trees always exist)."""
    if idblock.node_tree is None and hasattr(idblock, "use_nodes"):
        idblock.use_nodes = True
    return idblock.node_tree


# --- Properties ----------------------------------------------------------------------------


def _supports_blend_relative():
    """Whether properties can say they hold `//` paths. `bpy.props` checks its options only
    when the class registers (a Blender without the option then refuses the whole class),
    so this asks RNA, which reports the option on every property where it exists."""
    return "is_path_supports_blend_relative" in bpy.types.Property.bl_rna.properties


# Keyword arguments for a path property that holds `//`-relative paths (Blender 4.5+ warns
# about one that does not say so; older Blenders have no such option)
BLEND_RELATIVE = {"options": {"PATH_SUPPORTS_BLEND_RELATIVE"}} if _supports_blend_relative() else {}


# --- Shading -------------------------------------------------------------------------------


def eevee_engine():
    """The EEVEE render engine's identifier: BLENDER_EEVEE_NEXT (4.2 to 4.5, where
    BLENDER_EEVEE was the legacy engine's, gone) or BLENDER_EEVEE (5.0+, EEVEE Next under
    its old name)."""
    items = {e.identifier for e in bpy.types.RenderSettings.bl_rna.properties["engine"].enum_items}
    return "BLENDER_EEVEE_NEXT" if "BLENDER_EEVEE_NEXT" in items else "BLENDER_EEVEE"


def shader_output(node):
    """A shader node's BSDF output socket: its first output of type SHADER."""
    return next(s for s in node.outputs if s.type == "SHADER")
