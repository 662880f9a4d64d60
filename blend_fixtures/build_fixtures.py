"""Build (and check) the small .blend fixtures used by Madder's tests and demos.

Every fixture is generated from scratch with the ``bpy`` module (Blender as a
Python module), starting from an empty factory scene, so the files can be
regenerated at any time and reviewed as code rather than as binary blobs.

Fixtures
--------
``flag.blend``
    A 2.0 m x 1.2 m flag (object ``Flag``, 41 x 25 vertices) standing in the
    XZ plane, pinned along its pole edge (x = 0, vertex group ``pin``) and
    fluttering in a wind + turbulence field for frames 1-48 at 24 fps.  This is
    the main demo scene and the input for the bake tests.

``tablecloth.blend``
    A 2 m x 2 m cloth (object ``Tablecloth``, 41 x 41 vertices) that falls
    under gravity onto a sphere (object ``Table``, r = 0.6 m, Collision
    modifier) and drapes over it, frames 1-60 at 24 fps.  Used for long-run
    stability and conservation tests.

``disk.blend``
    A flat disk of radius 1 m (object ``Disk``, concentric-ring triangulation)
    in the XY plane that rotates rigidly about +Z at a constant angular
    velocity: one full turn over frames 1-97 at 24 fps, i.e. omega = pi/2 rad/s
    (linear keyframes, linear extrapolation).  No cloth; the motion lives in
    ``matrix_world``.  Used for rigid-rotation / Coriolis validation.

All fixtures have a UV map, a soft vertex group ``stain_source`` (weight 1 at
the patch centre falling smoothly to 0 at the patch radius, absent elsewhere),
a camera, a sun light, a plain world colour and Cycles set up for fast CPU
renders (16 samples, 480 x 320, no denoising).

The cloth caches are baked **into the .blend file** (memory cache, no
``blendcache_*`` directory).  After baking, the evaluated positions of a fixed
sample of vertices and the object's ``matrix_world`` are recorded for every
frame in the scene custom property ``madder_fixture_ref``; ``--check`` reopens
each file in a fresh session and compares the playback against that record.

Usage::

    BLENDER_USER_RESOURCES=/tmp/fixture-userres \\
        python blend_fixtures/build_fixtures.py [--out DIR] [--only NAME ...]
    python blend_fixtures/build_fixtures.py --check [--out DIR]

``--out`` defaults to the directory containing this script.  ``--check`` exits
with status 1 if any fixture is missing or wrong.  If BLENDER_USER_RESOURCES is
not set, a directory under the system temp dir is used so that Blender never
touches the user's configuration.
"""

from __future__ import annotations

import argparse
import contextlib
import math
import os
import sys
import tempfile
import time

import numpy as np

# Keep Blender away from the user's ~/.config when the caller did not isolate
# it (must happen before bpy is imported).
os.environ.setdefault(
    "BLENDER_USER_RESOURCES", os.path.join(tempfile.gettempdir(), "madder-fixture-userres")
)

import bpy  # noqa: E402
from bpy_extras import anim_utils  # noqa: E402
from mathutils import Vector  # noqa: E402

FPS = 24
REF_KEY = "madder_fixture_ref"
STAIN_GROUP = "stain_source"
N_SAMPLE_VERTS = 40  # vertices recorded per frame in the reference

RENDER_RESOLUTION = (480, 320)
RENDER_SAMPLES = 16
WORLD_COLOUR = (0.42, 0.48, 0.58, 1.0)  # grey-blue


# --------------------------------------------------------------------------
# Scene helpers
# --------------------------------------------------------------------------


def reset_scene(frame_end: int) -> bpy.types.Scene:
    """Start from an empty factory scene with frames 1..frame_end at 24 fps."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.frame_start = 1
    scene.frame_end = frame_end
    scene.frame_current = 1
    scene.render.fps = FPS
    scene.render.fps_base = 1.0
    return scene


def setup_render(scene: bpy.types.Scene) -> None:
    """Cycles on the CPU with settings that make a test render fast."""
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = RENDER_SAMPLES
    scene.cycles.preview_samples = RENDER_SAMPLES
    scene.cycles.use_denoising = False
    scene.cycles.use_preview_denoising = False
    scene.render.resolution_x, scene.render.resolution_y = RENDER_RESOLUTION
    scene.render.resolution_percentage = 100


def setup_world(scene: bpy.types.Scene) -> None:
    """A plain grey-blue background (node trees exist by default in 5.0)."""
    world = bpy.data.worlds.new("World")
    world.color = WORLD_COLOUR[:3]
    if world.node_tree is None:  # made on request (use_nodes) before 5.0
        world.use_nodes = True
    background = world.node_tree.nodes["Background"]
    background.inputs["Color"].default_value = WORLD_COLOUR
    background.inputs["Strength"].default_value = 1.0
    scene.world = world


def link(scene: bpy.types.Scene, obj: bpy.types.Object) -> bpy.types.Object:
    scene.collection.objects.link(obj)
    return obj


def add_camera(scene, location, target, lens=50.0) -> bpy.types.Object:
    """Add the scene camera at ``location`` looking at ``target``."""
    cam = link(scene, bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera")))
    cam.data.lens = lens
    cam.location = location
    direction = Vector(target) - Vector(location)
    cam.rotation_euler = direction.to_track_quat("-Z", "Y").to_euler()
    scene.camera = cam
    return cam


def add_sun(scene, rotation_deg=(40.0, 10.0, 30.0), energy=3.0) -> bpy.types.Object:
    light = bpy.data.lights.new("Sun", type="SUN")
    light.energy = energy
    sun = link(scene, bpy.data.objects.new("Sun", light))
    sun.location = (0.0, 0.0, 5.0)
    sun.rotation_euler = [math.radians(a) for a in rotation_deg]
    return sun


def make_material(name: str, base_colour, roughness=0.8, checker=None) -> bpy.types.Material:
    """A Principled BSDF material (node trees exist by default in 5.0).

    ``checker=(colour, scale)`` adds a UV checker texture alternating between
    ``base_colour`` and ``colour``, which makes rotation visible in renders.
    """
    mat = bpy.data.materials.new(name)
    mat.diffuse_color = base_colour
    if mat.node_tree is None:  # made on request (use_nodes) before 5.0
        mat.use_nodes = True
    nodes = mat.node_tree.nodes
    bsdf = nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = base_colour
    bsdf.inputs["Roughness"].default_value = roughness
    if checker is not None:
        colour, scale = checker
        uv = nodes.new("ShaderNodeTexCoord")
        tex = nodes.new("ShaderNodeTexChecker")
        tex.inputs["Color1"].default_value = base_colour
        tex.inputs["Color2"].default_value = colour
        tex.inputs["Scale"].default_value = scale
        mat.node_tree.links.new(uv.outputs["UV"], tex.inputs["Vector"])
        mat.node_tree.links.new(tex.outputs["Color"], bsdf.inputs["Base Color"])
    return mat


def save_blend(path: str) -> None:
    """Save compressed; remove any old file first so no ``.blend1`` appears."""
    bpy.context.scene.frame_set(bpy.context.scene.frame_start)
    if os.path.exists(path):
        os.remove(path)
    bpy.ops.wm.save_as_mainfile(filepath=path, compress=True, check_existing=False)


# --------------------------------------------------------------------------
# Mesh helpers
# --------------------------------------------------------------------------


def mesh_from_arrays(name: str, co: np.ndarray, faces: np.ndarray, uv: np.ndarray):
    """Create a mesh from (V,3) positions, (F,k) face indices and (V,2) UVs.

    All faces have the same number of corners; the UVs are per vertex and get
    expanded to the face corners of a UV map called ``UVMap``.
    """
    co = np.ascontiguousarray(co, dtype=np.float32)
    faces = np.ascontiguousarray(faces, dtype=np.int32)
    n_faces, corners = faces.shape

    mesh = bpy.data.meshes.new(name)
    mesh.vertices.add(len(co))
    mesh.vertices.foreach_set("co", co.ravel())
    mesh.loops.add(faces.size)
    mesh.loops.foreach_set("vertex_index", faces.ravel())
    mesh.polygons.add(n_faces)
    mesh.polygons.foreach_set("loop_start", np.arange(0, faces.size, corners, dtype=np.int32))
    mesh.update(calc_edges=True)
    if mesh.validate(verbose=True):
        raise RuntimeError(f"mesh {name!r} was invalid")

    uv_layer = mesh.uv_layers.new(name="UVMap")
    loop_uv = np.asarray(uv, dtype=np.float32)[faces.ravel()]
    uv_layer.data.foreach_set("uv", loop_uv.ravel())
    return mesh


def grid_arrays(nu: int, nv: int, size_u: float, size_v: float):
    """A regular grid of nu x nv quads on [0,size_u] x [0,size_v].

    Returns (u, v, faces, uv): per-vertex plane coordinates (vertex index =
    j * (nu+1) + i), counter-clockwise quads in the (u, v) plane and UVs.
    """
    i, j = np.meshgrid(np.arange(nu + 1), np.arange(nv + 1))
    u = (i.ravel() / nu) * size_u
    v = (j.ravel() / nv) * size_v

    row = nu + 1
    qi, qj = np.meshgrid(np.arange(nu), np.arange(nv))
    v00 = (qj * row + qi).ravel()
    faces = np.stack([v00, v00 + 1, v00 + row + 1, v00 + row], axis=1)

    uv = np.stack([u / size_u, v / size_v], axis=1)
    return u, v, faces, uv


def disk_arrays(radius: float, n_rings: int):
    """A disk triangulated as concentric rings; ring i holds 6*i vertices.

    Returns (co, faces, uv) with a planar XY projection as UVs.  Adjacent rings
    are zipped together by merging their vertices in order of angle, which
    gives near-equilateral triangles everywhere (6 * n_rings**2 triangles).
    """
    co = [np.zeros((1, 3))]
    ring_start = [0]
    for i in range(1, n_rings + 1):
        ang = 2.0 * np.pi * np.arange(6 * i) / (6 * i)
        r = radius * i / n_rings
        co.append(np.stack([r * np.cos(ang), r * np.sin(ang), np.zeros_like(ang)], axis=1))
        ring_start.append(ring_start[-1] + (1 if i == 1 else 6 * (i - 1)))
    co = np.concatenate(co)

    # Centre fan.
    k = np.arange(6)
    tris = [np.stack([np.zeros(6, int), 1 + k, 1 + (k + 1) % 6], axis=1)]

    # Zip ring i (inner, n_in vertices) to ring i+1 (outer, n_out vertices).
    # Each "advance" along either ring emits one triangle; advances are taken
    # in order of the angle of the vertex being advanced to.
    for i in range(1, n_rings):
        n_in, n_out = 6 * i, 6 * (i + 1)
        s_in, s_out = ring_start[i], ring_start[i + 1]
        t = np.concatenate([np.arange(1, n_in + 1) / n_in, np.arange(1, n_out + 1) / n_out])
        is_out = np.concatenate([np.zeros(n_in, bool), np.ones(n_out, bool)])
        is_out = is_out[np.argsort(t, kind="stable")]
        j = np.cumsum(~is_out) - (~is_out)  # inner advances before this event
        m = np.cumsum(is_out) - is_out  # outer advances before this event
        inner = s_in + j % n_in
        inner_next = s_in + (j + 1) % n_in
        outer = s_out + m % n_out
        outer_next = s_out + (m + 1) % n_out
        tris.append(
            np.where(
                is_out[:, None],
                np.stack([outer, outer_next, inner], axis=1),
                np.stack([inner, outer, inner_next], axis=1),
            )
        )
    faces = np.concatenate(tris)
    uv = (co[:, :2] / radius + 1.0) * 0.5
    return co, faces, uv


def add_soft_group(obj, name, rest_co, centre, radius) -> int:
    """Vertex group with a smooth cosine bump of ``radius`` around ``centre``.

    Weight is 1 at the centre and falls smoothly (zero slope at both ends) to 0
    at ``radius``; vertices outside the patch are not in the group.  Returns
    the number of member vertices.
    """
    dist = np.linalg.norm(np.asarray(rest_co) - np.asarray(centre), axis=1)
    inside = np.flatnonzero(dist < radius)
    weights = 0.5 * (1.0 + np.cos(np.pi * dist[inside] / radius))
    group = obj.vertex_groups.new(name=name)
    for index, weight in zip(inside.tolist(), weights.tolist(), strict=True):
        group.add([index], weight, "REPLACE")
    return len(inside)


# --------------------------------------------------------------------------
# Simulation, baking and reference recording
# --------------------------------------------------------------------------


def add_cloth(obj, scene, **settings) -> bpy.types.ClothModifier:
    """Add a cloth modifier with an in-file (memory) cache covering the scene."""
    mod = obj.modifiers.new("Cloth", "CLOTH")
    for key, value in settings.items():
        setattr(mod.settings, key, value)
    cache = mod.point_cache
    cache.use_disk_cache = False
    cache.frame_start = scene.frame_start
    cache.frame_end = scene.frame_end
    return mod


@contextlib.contextmanager
def quiet_stdout():
    """Silence C-level stdout (the baker prints one line per frame)."""
    sys.stdout.flush()
    saved = os.dup(1)
    try:
        with open(os.devnull, "w") as devnull:
            os.dup2(devnull.fileno(), 1)
        yield
    finally:
        os.dup2(saved, 1)
        os.close(saved)


def bake_all(scene) -> None:
    """Bake every point cache of the scene (from the first frame)."""
    scene.frame_set(scene.frame_start)
    with bpy.context.temp_override(scene=scene), quiet_stdout():
        result = bpy.ops.ptcache.bake_all(bake=True)
    if result != {"FINISHED"}:
        raise RuntimeError(f"ptcache.bake_all returned {result}")


def evaluated_positions(obj) -> np.ndarray:
    """Evaluated (modifier-applied) vertex positions in object space, (V,3)."""
    depsgraph = bpy.context.evaluated_depsgraph_get()
    mesh = obj.evaluated_get(depsgraph).data
    co = np.empty(len(mesh.vertices) * 3, dtype=np.float32)
    mesh.vertices.foreach_get("co", co)
    return co.reshape(-1, 3)


def evaluated_world_matrix(obj) -> np.ndarray:
    depsgraph = bpy.context.evaluated_depsgraph_get()
    return np.array(obj.evaluated_get(depsgraph).matrix_world, dtype=np.float64)


def sample_indices(n_verts: int) -> np.ndarray:
    """A deterministic, evenly spread sample of vertex indices."""
    return np.unique(np.linspace(0, n_verts - 1, N_SAMPLE_VERTS).round().astype(int))


def play(scene, obj):
    """Step through every frame; return frames, positions (F,V,3), matrices (F,4,4)."""
    frames = list(range(scene.frame_start, scene.frame_end + 1))
    positions, matrices = [], []
    for frame in frames:
        scene.frame_set(frame)
        positions.append(evaluated_positions(obj))
        matrices.append(evaluated_world_matrix(obj))
    scene.frame_set(scene.frame_start)
    return frames, np.stack(positions), np.stack(matrices)


def record_reference(scene, obj) -> dict:
    """Play the scene back and store a compact reference in the scene."""
    frames, positions, matrices = play(scene, obj)
    index = sample_indices(positions.shape[1])
    scene[REF_KEY] = {
        "object": obj.name,
        "frames": frames,
        "sample_index": index.tolist(),
        "sample_co": positions[:, index].astype(np.float64).ravel().tolist(),
        "matrix_world": matrices.ravel().tolist(),
    }
    return {"frames": frames, "positions": positions, "matrices": matrices}


# --------------------------------------------------------------------------
# Fixtures
# --------------------------------------------------------------------------

FLAG_SIZE = (2.0, 1.2)  # along x (away from the pole) and z (up)
FLAG_QUADS = (40, 24)


def build_flag(path: str) -> dict:
    """Flag pinned on its pole edge, fluttering in wind + turbulence."""
    scene = reset_scene(frame_end=48)

    u, v, faces, uv = grid_arrays(*FLAG_QUADS, *FLAG_SIZE)
    rest = np.stack([u, np.zeros_like(u), v], axis=1)  # XZ plane, normal -Y
    flag = link(scene, bpy.data.objects.new("Flag", mesh_from_arrays("Flag", rest, faces, uv)))
    flag.data.materials.append(make_material("FlagCloth", (0.90, 0.85, 0.70, 1.0)))
    flag.data.shade_smooth()

    pin = flag.vertex_groups.new(name="pin")
    pin.add(np.flatnonzero(u == 0.0).tolist(), 1.0, "REPLACE")
    add_soft_group(flag, STAIN_GROUP, rest, centre=(1.0, 0.0, 0.6), radius=0.25)

    add_cloth(
        flag,
        scene,
        quality=8,
        mass=0.05,
        air_damping=1.0,
        bending_stiffness=0.5,
        vertex_group_mass="pin",
    )

    # Wind along +X (the empty's local +Z is the wind axis).  Blender's cloth
    # only feels the wind component normal to each face, so it takes a strong
    # wind plus turbulence (which wrinkles the flag and breaks the symmetry) to
    # lift the flag out against gravity and keep it fluttering.
    bpy.ops.object.effector_add(type="WIND", location=(-1.0, -0.5, 0.6))
    wind = bpy.context.active_object
    wind.name = "Wind"
    wind.rotation_euler = (0.0, math.radians(90.0), 0.0)
    wind.field.strength = 2000.0
    wind.field.noise = 2.0
    wind.field.seed = 1
    wind.field.flow = 0.0

    bpy.ops.object.effector_add(type="TURBULENCE", location=(1.0, 0.0, 0.6))
    turbulence = bpy.context.active_object
    turbulence.name = "Turbulence"
    turbulence.field.strength = 20.0
    turbulence.field.size = 0.6
    turbulence.field.seed = 2
    turbulence.field.flow = 0.0

    add_camera(scene, location=(1.6, -4.6, 0.9), target=(1.0, 0.0, 0.3))
    add_sun(scene)
    setup_world(scene)
    setup_render(scene)

    bake_all(scene)
    ref = record_reference(scene, flag)
    save_blend(path)
    return ref


def build_tablecloth(path: str) -> dict:
    """Square cloth dropped onto a sphere, draping under gravity."""
    scene = reset_scene(frame_end=60)

    table_radius, table_centre = 0.6, (0.0, 0.0, 0.6)
    bpy.ops.mesh.primitive_uv_sphere_add(
        segments=48, ring_count=24, radius=table_radius, location=table_centre
    )
    table = bpy.context.active_object
    table.name = table.data.name = "Table"
    table.data.shade_smooth()
    table.data.materials.append(make_material("TableWood", (0.35, 0.20, 0.10, 1.0), 0.5))
    table.modifiers.new("Collision", "COLLISION")
    table.collision.thickness_outer = 0.01
    table.collision.cloth_friction = 10.0

    u, v, faces, uv = grid_arrays(40, 40, 2.0, 2.0)
    rest = np.stack([u - 1.0, v - 1.0, np.zeros_like(u)], axis=1)  # XY plane, normal +Z
    cloth = link(
        scene,
        bpy.data.objects.new("Tablecloth", mesh_from_arrays("Tablecloth", rest, faces, uv)),
    )
    cloth.location = (0.0, 0.0, 1.35)  # 0.15 m above the top of the sphere
    cloth.data.materials.append(make_material("TableclothCloth", (0.85, 0.88, 0.92, 1.0)))
    cloth.data.shade_smooth()
    add_soft_group(cloth, STAIN_GROUP, rest, centre=(0.25, 0.15, 0.0), radius=0.3)

    # A stiffer bend than the default keeps the folds at the corners smooth
    # (no grid-scale crumpling) without the cost of self-collision.
    mod = add_cloth(cloth, scene, quality=8, mass=0.3, air_damping=1.0, bending_stiffness=5.0)
    mod.collision_settings.use_collision = True
    mod.collision_settings.distance_min = 0.01
    mod.collision_settings.use_self_collision = False

    add_camera(scene, location=(2.3, -4.0, 2.4), target=(0.0, 0.0, 0.75))
    add_sun(scene)
    setup_world(scene)
    setup_render(scene)

    bake_all(scene)
    ref = record_reference(scene, cloth)
    save_blend(path)
    return ref


DISK_TURN_FRAMES = (1, 97)  # one full counter-clockwise turn


def build_disk(path: str) -> dict:
    """Rigid disk rotating about +Z at a constant angular velocity."""
    scene = reset_scene(frame_end=DISK_TURN_FRAMES[1])

    co, faces, uv = disk_arrays(radius=1.0, n_rings=20)
    disk = link(scene, bpy.data.objects.new("Disk", mesh_from_arrays("Disk", co, faces, uv)))
    disk_material = make_material("DiskMaterial", (0.80, 0.80, 0.78, 1.0), checker=((0.55, 0.57, 0.60, 1.0), 8.0))
    disk.data.materials.append(disk_material)
    add_soft_group(disk, STAIN_GROUP, co, centre=(0.5, 0.0, 0.0), radius=0.25)

    first, last = DISK_TURN_FRAMES
    disk.rotation_euler = (0.0, 0.0, 0.0)
    disk.keyframe_insert("rotation_euler", index=2, frame=first)
    disk.rotation_euler = (0.0, 0.0, 2.0 * math.pi)
    disk.keyframe_insert("rotation_euler", index=2, frame=last)

    # Blender 5.0 uses layered actions: the F-curves live in the channelbag of
    # the slot assigned to the object (Action.fcurves no longer exists).
    # (4.2 has the action's own F-curves; layered actions came in 4.4.)
    anim = disk.animation_data
    if hasattr(anim, "action_slot"):
        fcurves = anim_utils.action_get_channelbag_for_slot(anim.action, anim.action_slot).fcurves
    else:
        fcurves = anim.action.fcurves
    for fcurve in fcurves:
        fcurve.extrapolation = "LINEAR"
        for key in fcurve.keyframe_points:
            key.interpolation = "LINEAR"

    add_camera(scene, location=(0.0, 0.0, 5.2), target=(0.0, 0.0, 0.0))
    add_sun(scene, rotation_deg=(20.0, 10.0, 0.0))
    setup_world(scene)
    setup_render(scene)

    ref = record_reference(scene, disk)
    save_blend(path)
    return ref


FIXTURES = {
    "flag": build_flag,
    "tablecloth": build_tablecloth,
    "disk": build_disk,
}


# --------------------------------------------------------------------------
# Checking
# --------------------------------------------------------------------------


class CheckError(Exception):
    pass


def require(condition: bool, message: str) -> None:
    if not condition:
        raise CheckError(message)


def check_common(scene, obj, frame_end: int) -> None:
    require(scene.frame_start == 1 and scene.frame_end == frame_end,
            f"frame range {scene.frame_start}-{scene.frame_end}, expected 1-{frame_end}")
    require(scene.render.fps == FPS and scene.render.fps_base == 1.0, "fps is not 24")
    require(scene.render.engine == "CYCLES" and scene.cycles.device == "CPU", "not Cycles/CPU")
    require(scene.camera is not None, "no camera")
    require(obj.data.uv_layers.active is not None, "no UV map")
    group = obj.vertex_groups.get(STAIN_GROUP)
    require(group is not None, f"no {STAIN_GROUP!r} vertex group")
    weights = [g.weight for vert in obj.data.vertices for g in vert.groups if g.group == group.index]
    require(len(weights) > 0 and max(weights) > 0.9, f"{STAIN_GROUP!r} has no strong weights")


def check_cloth_cache(obj, frame_end: int) -> str:
    mod = next((m for m in obj.modifiers if m.type == "CLOTH"), None)
    require(mod is not None, "no cloth modifier")
    cache = mod.point_cache
    require(not cache.use_disk_cache, "cloth cache uses the disk")
    require(cache.is_baked, "cloth cache is not baked")
    require(cache.frame_start == 1 and cache.frame_end == frame_end, "cache frame range wrong")
    return cache.info


def check_reference(scene, frames, positions, matrices) -> float:
    """Compare playback with the reference recorded at build time."""
    ref = scene.get(REF_KEY)
    require(ref is not None, f"scene has no {REF_KEY!r} property")
    require(list(ref["frames"]) == frames, "reference frames differ")
    index = np.array(ref["sample_index"])
    want_co = np.array(ref["sample_co"]).reshape(len(frames), len(index), 3)
    want_mw = np.array(ref["matrix_world"]).reshape(len(frames), 4, 4)
    err = max(np.abs(positions[:, index] - want_co).max(), np.abs(matrices - want_mw).max())
    require(err < 1e-5, f"playback differs from the build-time reference by {err:.3g}")
    return float(err)


def check_random_access(scene, obj) -> float:
    """Jump straight to the last frame of a freshly opened file.

    A cloth cache that only lived on disk or in the building session could not
    produce the last frame without simulating every frame before it.
    """
    ref = scene[REF_KEY]
    index = np.array(ref["sample_index"])
    want = np.array(ref["sample_co"]).reshape(len(ref["frames"]), len(index), 3)[-1]
    scene.frame_set(ref["frames"][-1])
    err = float(np.abs(evaluated_positions(obj)[index] - want).max())
    require(err < 1e-5, f"jumping to the last frame gives other positions (error {err:.3g})")
    return err


def check_flag(scene, frames, positions, matrices) -> list[str]:
    obj = bpy.data.objects["Flag"]
    check_common(scene, obj, 48)
    info = check_cloth_cache(obj, 48)
    pin = obj.vertex_groups.get("pin")
    require(pin is not None and obj.modifiers["Cloth"].settings.vertex_group_mass == "pin",
            "pin group missing or not used by the cloth")
    rest = positions[0]
    pinned = np.flatnonzero(np.isclose(rest[:, 0], 0.0))
    free = np.flatnonzero(np.isclose(rest[:, 0], FLAG_SIZE[0]))
    pin_drift = np.abs(positions[:, pinned] - rest[pinned]).max()
    require(pin_drift < 1e-4, f"pinned edge moved by {pin_drift:.3g} m")
    step = np.linalg.norm(np.diff(positions[:, free], axis=0), axis=2).max(axis=1)
    late = step[len(step) // 2:]  # second half of the clip: still fluttering?
    require(late.min() > 0.005, f"free edge nearly stops moving (min step {late.min():.3g} m)")
    y = positions[:, free, 1]
    require(np.ptp(y) > 0.2, "free edge barely leaves the flag plane")
    return [
        f"cache: {info}",
        f"pinned edge drift {pin_drift:.2g} m",
        f"free edge per-frame displacement: max {step.max():.3f} m, "
        f"min over frames 24-48 {late.min():.3f} m",
        f"free edge y range {y.min():+.3f}..{y.max():+.3f} m, "
        "centroid at f48 ({:.3f}, {:.3f}, {:.3f})".format(*positions[-1].mean(axis=0)),
    ]


def check_tablecloth(scene, frames, positions, matrices) -> list[str]:
    obj = bpy.data.objects["Tablecloth"]
    table = bpy.data.objects["Table"]
    check_common(scene, obj, 60)
    info = check_cloth_cache(obj, 60)
    require(any(m.type == "COLLISION" for m in table.modifiers), "Table has no Collision modifier")
    world = positions + np.array(obj.matrix_world.translation)  # identity rotation/scale
    centre = np.array(table.matrix_world.translation)
    radius = 0.6
    dist = np.linalg.norm(world[-1] - centre, axis=1)
    z = world[-1, :, 2]
    edge_len = np.diff(np.sort(positions[0][:, 0]))
    edge_len = edge_len[edge_len > 1e-6].min()
    # Draped: the cloth rests on top of the sphere and the rim hangs well below it.
    mid = np.argmin(np.linalg.norm(positions[0][:, :2], axis=1))
    require(abs(z[mid] - (centre[2] + radius)) < 0.05, f"cloth centre at z={z[mid]:.3f}, not on top")
    require(np.median(z) < centre[2] + 0.5 * radius, "cloth does not hang down around the sphere")
    require(dist.min() > radius - 0.5 * edge_len, f"cloth penetrates the sphere ({dist.min():.3f})")
    step = np.linalg.norm(positions[-1] - positions[-2], axis=1).max()
    return [
        f"cache: {info}",
        f"last frame: centre vertex z {z[mid]:.3f} (sphere top {centre[2] + radius:.3f}), "
        f"median z {np.median(z):.3f}, lowest z {z.min():.3f}",
        f"min distance to sphere centre {dist.min():.3f} m (r = {radius})",
        f"max vertex motion between frames 59 and 60: {step:.4f} m",
    ]


def check_disk(scene, frames, positions, matrices) -> list[str]:
    obj = bpy.data.objects["Disk"]
    check_common(scene, obj, DISK_TURN_FRAMES[1])
    drift = np.abs(positions - positions[0]).max()
    require(drift < 1e-6, "disk deforms in object space")
    angle = np.unwrap(np.arctan2(matrices[:, 1, 0], matrices[:, 0, 0]))
    t = (np.array(frames) - frames[0]) / FPS
    omega = np.polyfit(t, angle, 1)[0]
    expected = 2.0 * math.pi / ((DISK_TURN_FRAMES[1] - DISK_TURN_FRAMES[0]) / FPS)
    residual = np.abs(angle - omega * t).max()
    require(abs(omega - expected) < 1e-4 and residual < 1e-4,
            f"rotation not uniform (omega {omega:.5f}, residual {residual:.3g})")
    return [
        f"object-space positions constant (max drift {drift:.2g})",
        f"matrix_world rotation: {math.degrees(angle[-1]):.2f} deg over frames "
        f"{frames[0]}-{frames[-1]}, omega {omega:.5f} rad/s (expected pi/2 = {expected:.5f}), "
        f"max deviation from uniform {residual:.2g} rad",
    ]


CHECKS = {"flag": check_flag, "tablecloth": check_tablecloth, "disk": check_disk}


def check_fixture(name: str, path: str) -> bool:
    print(f"{name}.blend ({os.path.getsize(path) / 1e6:.2f} MB)" if os.path.exists(path)
          else f"{name}.blend: MISSING")
    if not os.path.exists(path):
        return False
    try:
        bpy.ops.wm.open_mainfile(filepath=path)
        scene = bpy.context.scene
        obj = bpy.data.objects[scene[REF_KEY]["object"]]
        jump_err = check_random_access(scene, obj)
        frames, positions, matrices = play(scene, obj)
        err = check_reference(scene, frames, positions, matrices)
        lines = CHECKS[name](scene, frames, positions, matrices)
        require(not any(n.startswith("blendcache_") for n in os.listdir(os.path.dirname(path))),
                "a blendcache_* directory exists next to the fixtures")
    except (CheckError, KeyError) as exc:
        print(f"  FAIL: {exc}")
        return False
    print(f"  {obj.name}: {len(positions[0])} vertices, frames {frames[0]}-{frames[-1]}, "
          f"playback matches build-time reference (max error {err:.2g}; "
          f"jump straight to last frame: {jump_err:.2g})")
    for line in lines:
        print(f"  {line}")
    print("  OK")
    return True


# --------------------------------------------------------------------------
# Entry point
# --------------------------------------------------------------------------


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", default=os.path.dirname(os.path.abspath(__file__)),
                        help="directory for the .blend files (default: next to this script)")
    parser.add_argument("--only", nargs="+", choices=sorted(FIXTURES), default=list(FIXTURES),
                        help="restrict to these fixtures")
    parser.add_argument("--check", action="store_true",
                        help="check existing fixtures instead of building them")
    args = parser.parse_args(argv)
    out = os.path.abspath(args.out)

    if args.check:
        ok = [check_fixture(name, os.path.join(out, f"{name}.blend")) for name in args.only]
        print("all fixtures OK" if all(ok) else "FIXTURE CHECK FAILED")
        return 0 if all(ok) else 1

    os.makedirs(out, exist_ok=True)
    for name in args.only:
        path = os.path.join(out, f"{name}.blend")
        start = time.perf_counter()
        FIXTURES[name](path)
        print(f"built {path} ({os.path.getsize(path) / 1e6:.2f} MB) "
              f"in {time.perf_counter() - start:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
