"""Baking a stain: walks the scene's frames, feeds the evaluated positions to the Rust
simulator and streams the densities into the cache file. Errors are `BakeError`s whose
message names the object and frame; the previous cache is kept on any failure."""

import os

import bpy
import numpy as np

from . import bridge, fabrics, handlers

CACHE_EXT = ".madder"
FIELDS = ["density"]


class BakeError(Exception):
    pass


def core():
    """The native `madder` module shipped in the extension's wheel."""
    try:
        import madder
    except ImportError as e:  # a broken install must say so, not fail obscurely later
        raise BakeError(f"Madder's native module could not be loaded ({e}); reinstall the extension") from e
    return madder


def cache_path(obj):
    """Absolute path of the cache file `obj` bakes to."""
    settings = obj.madder
    folder = settings.cache_dir or "//madder_cache/"
    if folder.startswith("//") and not bpy.data.filepath:
        raise BakeError(f"'{obj.name}': save the .blend first, or set an absolute cache folder")
    folder = bpy.path.abspath(folder)
    return os.path.join(folder, bpy.path.clean_name(obj.name) + CACHE_EXT)


def stored_path(path):
    """Path to store in the .blend: relative to it when it is saved (a moved project keeps working)."""
    if bpy.data.filepath:
        try:
            return bpy.path.relpath(path)
        except ValueError:  # another drive
            return path
    return path


def check_object(obj):
    if obj is None or obj.type != "MESH":
        kind = "nothing" if obj is None else f"a {obj.type.lower()}"
        name = "" if obj is None else f"'{obj.name}' "
        raise BakeError(f"Madder bakes mesh objects; {name}is {kind}")
    group = obj.madder.source_group
    if not group:
        raise BakeError(f"'{obj.name}': choose a Source vertex group to start the stain from")
    if group not in obj.vertex_groups:
        raise BakeError(f"'{obj.name}' has no vertex group '{group}' (the Source)")


def frame_positions(obj, depsgraph, n_vertices, frame):
    obj_eval = obj.evaluated_get(depsgraph)
    n = len(obj_eval.data.vertices)
    if n != n_vertices:
        raise BakeError(
            f"'{obj.name}' has {n} vertices at frame {frame} but {n_vertices} in its mesh: "
            "the deformed cloth must keep its topology (move generating modifiers such as "
            "Subdivision below the cloth and disable them for the bake)"
        )
    pos = bridge.world_positions(obj_eval)
    bad = np.flatnonzero(~np.isfinite(pos).all(axis=1))
    if bad.size:
        raise BakeError(f"'{obj.name}': vertex {bad[0]} has a non-finite position at frame {frame}")
    return pos


def bake(scene, obj, progress=None):
    """Bakes `obj` over the scene's frame range. Returns `(path, warnings)`.

    `progress(done, total)` is called after every frame. On any error the cache writer is
    aborted, so the previous cache file (if any) is left as it was."""
    madder = core()
    check_object(obj)
    settings = obj.madder
    path = cache_path(obj)
    try:
        os.makedirs(os.path.dirname(path), exist_ok=True)
    except OSError as e:
        raise BakeError(f"'{obj.name}': cannot create the cache folder {os.path.dirname(path)}: {e}") from e

    first, last = scene.frame_start, scene.frame_end
    fps = scene.render.fps / scene.render.fps_base
    mesh = obj.data
    faces, face_polygon, n_polygons = bridge.topology_arrays(mesh)
    n_vertices = len(mesh.vertices)
    if len(faces) == 0:
        raise BakeError(f"'{obj.name}' has no faces")
    density0 = bridge.vertex_group_weights(obj, settings.source_group) * np.float32(settings.amount)

    topology = _topology(madder, obj, faces, n_vertices, face_polygon, n_polygons)
    warnings = []
    n_nonmanifold = len(topology.non_manifold_edges())
    if n_nonmanifold:
        warnings.append(f"{n_nonmanifold} non-manifold edges (shared by 3+ faces)")
    conductivity = _conductivity(madder, obj, topology, face_polygon, warnings)

    frame_before = scene.frame_current
    writer = None
    try:
        with handlers.suspended():
            scene.frame_set(first)
            depsgraph = bpy.context.evaluated_depsgraph_get()
            pos = frame_positions(obj, depsgraph, n_vertices, first)
            stepper = madder.DiffusionStepper(topology, pos, density0, **conductivity)
            if stepper.degenerate_uv_faces:
                warnings.append(f"{stepper.degenerate_uv_faces} faces have degenerate UVs; their weft follows an edge")
            writer = madder.CacheWriter(path, n_vertices, FIELDS, first, last - first + 1)
            writer.push_frame([stepper.density])
            for frame in range(first + 1, last + 1):
                scene.frame_set(frame)
                pos = frame_positions(obj, depsgraph, n_vertices, frame)
                try:
                    stepper.step(pos, 1.0 / fps, settings.substeps)
                except madder.MadderError as e:
                    raise BakeError(f"'{obj.name}' at frame {frame}: {e}") from e
                writer.push_frame([stepper.density])
                if progress:
                    progress(frame - first, last - first)
            writer.finish()
            writer = None
    except madder.MadderError as e:
        raise BakeError(f"'{obj.name}': {e}") from e
    finally:
        if writer is not None:
            writer.abort()
        scene.frame_set(frame_before)
    settings.cache_file = stored_path(path)
    return path, warnings


def _conductivity(madder, obj, topology, face_polygon, warnings):
    """Keyword arguments of the stepper: isotropic `rate`, or the woven faces of the
    materials' fabrics (then the rest-pose weft is written as `madder_weft` too)."""
    rate = obj.madder.diffusion_rate
    try:
        woven = fabrics.face_conductivity(obj, rate, face_polygon)
    except ValueError as e:
        raise BakeError(f"'{obj.name}': {e}") from e
    if woven is None:
        return {"rate": rate}
    uv = bridge.corner_uvs(obj.data)
    if uv is None:
        warnings.append("has no UV map to orient its fabrics: baked isotropic (add a UV map for woven spreading)")
        return {"rate": rate}
    tensors, angle = woven
    weft = madder.weft_directions(topology, bridge.rest_positions(obj.data), uv, angle)
    bridge.write_face_weft(obj.data, face_polygon, weft)
    return {"face_tensors": tensors, "face_uv": uv, "face_angle": angle}


def _topology(madder, obj, faces, n_vertices, face_polygon, n_polygons):
    try:
        return madder.Topology(faces, n_vertices, face_polygon, n_polygons)
    except madder.MadderError as e:
        raise BakeError(f"'{obj.name}': {e}") from e


def free(obj):
    """Deletes `obj`'s cache file and its stain attributes. Returns the path removed (or None)."""
    settings = obj.madder
    path = bpy.path.abspath(settings.cache_file) if settings.cache_file else None
    if path and os.path.exists(path):
        os.remove(path)
    settings.cache_file = ""
    if obj.type == "MESH":
        for name in (bridge.STAIN_ATTR, bridge.DENSITY_ATTR, bridge.WEFT_ATTR):
            attr = obj.data.attributes.get(name)
            if attr is not None:
                obj.data.attributes.remove(attr)
        obj.data.update()
    return path
