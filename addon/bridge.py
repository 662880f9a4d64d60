"""bpy ↔ numpy adapters. Every per-vertex transfer goes through `foreach_get`/`foreach_set`
on flat numpy buffers; nothing here loops over vertices in Python per frame."""

import numpy as np

STAIN_ATTR = "madder_stain"
WETNESS_ATTR = "madder_wetness"
DEPOSIT_ATTR = "madder_deposit"
WEFT_ATTR = "madder_weft"
LEGACY_DENSITY_ATTR = "madder_density"  # written by Madder before the full simulator
# cache fields, per vertex and frame (float32): total solute (dissolved + absorbed +
# adsorbed), liquid (free + absorbed solvent) and adsorbed solute (the deposit), in kg/m²;
# with sources, also the solute's colour (the mass-weighted mix of the liquids)
FIELDS = ["solute", "wetness", "deposit"]
COLOR_FIELDS = ["color_r", "color_g", "color_b"]
# with Bake Flow on (what the LCS tools integrate): the liquid's velocity relative to the
# cloth (m/s, world space, tangent) and the cloth's positions (m, world space) per vertex
VELOCITY_FIELDS = ["velocity_x", "velocity_y", "velocity_z"]
POSITION_FIELDS = ["position_x", "position_y", "position_z"]
FLOW_FIELDS = VELOCITY_FIELDS + POSITION_FIELDS
FTLE_ATTR = "madder_ftle"
# every attribute a bake or playback may have written (Free Bake removes them)
ATTRIBUTES = (STAIN_ATTR, WETNESS_ATTR, DEPOSIT_ATTR, WEFT_ATTR, FTLE_ATTR, LEGACY_DENSITY_ATTR)


def topology_arrays(mesh):
    """Triangles of `mesh` as (F, 3) uint32, the polygon of each triangle, and the polygon count."""
    mesh.calc_loop_triangles()
    n = len(mesh.loop_triangles)
    faces = np.empty(3 * n, dtype=np.uint32)
    mesh.loop_triangles.foreach_get("vertices", faces)
    poly = np.empty(n, dtype=np.uint32)
    mesh.loop_triangles.foreach_get("polygon_index", poly)
    return faces.reshape(n, 3), poly, len(mesh.polygons)


def corner_uvs(mesh):
    """UVs of each triangle's corners from the active UV map, (F, 3, 2) float32, or None
    when the mesh has no UV map. Call after `topology_arrays` (it needs loop_triangles)."""
    layer = mesh.uv_layers.active
    if layer is None:
        return None
    uv = np.empty(2 * len(mesh.loops), dtype=np.float32)
    layer.data.foreach_get("uv", uv)
    loops = np.empty(3 * len(mesh.loop_triangles), dtype=np.int64)
    mesh.loop_triangles.foreach_get("loops", loops)
    return np.ascontiguousarray(uv.reshape(-1, 2)[loops].reshape(-1, 3, 2))


def rest_positions(mesh):
    """Object-space positions of the original mesh, (N, 3) float32."""
    co = np.empty(3 * len(mesh.vertices), dtype=np.float32)
    mesh.vertices.foreach_get("co", co)
    return co.reshape(-1, 3)


def write_face_weft(mesh, face_polygon, weft):
    """Writes the per-triangle weft `weft` (F, 3) as the FACE-domain vector attribute
    `madder_weft` (one unit vector per polygon: the normalized sum over its triangles)."""
    per_poly = np.zeros((len(mesh.polygons), 3))
    np.add.at(per_poly, face_polygon, weft)
    norm = np.linalg.norm(per_poly, axis=1, keepdims=True)
    per_poly = np.divide(per_poly, norm, out=np.zeros_like(per_poly), where=norm > 0).astype(np.float32)
    attr = _attribute(mesh, WEFT_ATTR, "FLOAT_VECTOR", "FACE")
    now = np.empty(per_poly.size, dtype=np.float32)
    attr.data.foreach_get("vector", now)
    if np.array_equal(now, per_poly.ravel()):
        return  # unchanged (a re-bake): an edit of the mesh would outdate an unbaked cloth cache
    attr.data.foreach_set("vector", per_poly.ravel())
    mesh.update()


def world_triangles(obj_eval):
    """World-space vertices (M, 3) float32 and triangles (K, 3) uint32 of an evaluated mesh."""
    mesh = obj_eval.data
    mesh.calc_loop_triangles()
    tris = np.empty(3 * len(mesh.loop_triangles), dtype=np.uint32)
    mesh.loop_triangles.foreach_get("vertices", tris)
    return world_positions(obj_eval), tris.reshape(-1, 3)


def world_positions(obj_eval):
    """World-space vertex positions of an evaluated mesh object, (N, 3) float32."""
    mesh = obj_eval.data
    co = np.empty(3 * len(mesh.vertices), dtype=np.float32)
    mesh.vertices.foreach_get("co", co)
    co = co.reshape(-1, 3)
    m = np.array(obj_eval.matrix_world, dtype=np.float64)
    return (co @ m[:3, :3].T + m[:3, 3]).astype(np.float32)


def vertex_group_weights(obj, name):
    """Weights of vertex group `name` per vertex (0 where unassigned), (N,) float32.

    bpy exposes vertex-group membership only per vertex, so this walks the vertices once;
    it runs once per bake, never per frame."""
    group = obj.vertex_groups[name]
    gi = group.index
    weights = np.zeros(len(obj.data.vertices), dtype=np.float32)
    for v in obj.data.vertices:
        for g in v.groups:
            if g.group == gi:
                weights[v.index] = g.weight
    return weights


def _attribute(mesh, name, data_type, domain="POINT"):
    """The attribute `name`, (re)created if it is missing or of another type or domain."""
    attr = mesh.attributes.get(name)
    if attr is not None and (attr.data_type != data_type or attr.domain != domain):
        mesh.attributes.remove(attr)
        attr = None
    if attr is None:
        owner = mesh.color_attributes if data_type == "FLOAT_COLOR" else mesh.attributes
        attr = owner.new(name, data_type, domain)
    return attr


_scratch = {}  # vertex count -> the playback buffers, reused every frame


def stain_buffers(n):
    """Buffers for one frame of playback attributes on `n` vertices: RGBA (4n), wetness
    (n) and deposit (n), float32, kept between frames (allocating them per frame cost
    more than filling them)."""
    hit = _scratch.get(n)
    if hit is None:
        _scratch.clear()
        hit = _scratch[n] = tuple(np.zeros(k * n, dtype=np.float32) for k in (4, 1, 1))
    return hit


def write_stain(mesh, rgba, wetness, deposit):
    """Writes one frame's playback attributes on the POINT domain (computed from the
    cache's densities by `CacheReader.read_stain`, core `io::attributes`):

    - `madder_stain` (FLOAT_COLOR): alpha = the dye amount a = solute / (concentration ×
      saturation), in [0, 1 + madder.DYE_EXCESS_RANGE]: a tide line holds several times
      the dye of a saturated spot (1), and the shader darkens by all of it; RGB = solute
      colour × min(a, 1), the coverage (premultiplied, for an "over" mix, and never
      brighter than the liquid's colour where the Solid view shows the attribute).
    - `madder_wetness` (FLOAT): liquid / saturation (1: the fibres are full; free liquid
      pooled on top reads 1 as well).
    - `madder_deposit` (FLOAT): adsorbed solute / capacity.

    `mesh` is the object's carrier (`carrier`), never the cloth's own mesh. Then tags it so
    the depsgraph re-evaluates the cloth (foreach_set alone does not)."""
    _attribute(mesh, STAIN_ATTR, "FLOAT_COLOR").data.foreach_set("color", rgba)
    _attribute(mesh, WETNESS_ATTR, "FLOAT").data.foreach_set("value", wetness)
    _attribute(mesh, DEPOSIT_ATTR, "FLOAT").data.foreach_set("value", deposit)
    mesh.update()


def degenerate_uv_faces(uv):
    """How many triangles of `uv` (F, 3, 2) have degenerate UVs (no weft direction; the
    simulator then takes an edge), by the core's test |det| ≤ ε·|a|·|b| with the core's
    ε (`madder._core.DEGENERATE_UV_REL`)."""
    from madder._core import DEGENERATE_UV_REL

    uv = np.asarray(uv, dtype=np.float64)
    a, b = uv[:, 1] - uv[:, 0], uv[:, 2] - uv[:, 0]
    det = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
    bound = DEGENERATE_UV_REL * np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1)
    return int(np.count_nonzero(~(np.abs(det) > bound)))
