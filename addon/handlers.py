"""Playback: after every frame change, each enabled object with a bake gets that frame's
stain written into its mesh attributes (`madder_stain`, `madder_wetness`,
`madder_deposit`; see `bridge.write_stain`)."""

import os

import bpy
import numpy as np
from bpy.app.handlers import persistent

from . import bridge, properties

_readers = {}  # absolute path -> (mtime_ns, size, CacheReader)
_suspended = 0  # > 0 while a bake walks the frames: playback must not touch the meshes


def suspend():
    """No playback until the matching `resume()`: a bake steps through frames and must not
    have the handler rewrite the meshes it is reading (nor spend the time)."""
    global _suspended
    _suspended += 1


def resume():
    global _suspended
    _suspended -= 1


def _reader(path):
    import madder

    st = os.stat(path)
    key = (st.st_mtime_ns, st.st_size)
    hit = _readers.get(path)
    if hit is None or hit[:2] != key:
        _readers[path] = (*key, madder.CacheReader(path))
    return _readers[path][2]


def apply_frame(obj, frame):
    """Writes `obj`'s baked stain at `frame` (clamped to the baked range) into its mesh.
    Returns False when there is nothing to show (no bake, or the file is gone)."""
    settings = obj.madder
    if not settings.cache_file or obj.mode == "EDIT":
        return False
    path = bpy.path.abspath(settings.cache_file)
    if not os.path.exists(path):
        return False
    reader = _reader(path)
    if reader.n_vertices != len(obj.data.vertices):
        return False
    missing = [f for f in bridge.FIELDS if f not in reader.fields]
    if missing:
        raise ValueError(f"{path} has no '{missing[0]}' field (baked by an older Madder?): bake again")
    frame = min(max(frame, reader.first_frame), reader.last_frame)
    block = dict(zip(reader.fields, reader.read_frame(frame)))  # one read for all fields
    colors = np.stack([block[f] for f in bridge.COLOR_FIELDS], axis=1) if "color_r" in block else None
    refs = tuple(settings.bake_references)
    if not any(refs):  # a cache made outside a bake (a script): the object's own settings
        refs = properties.references(settings)
    bridge.write_stain(obj.data, block["solute"], block["wetness"], block["deposit"], refs, settings.stain_color, colors)
    return True


@persistent
def on_frame_change(scene, depsgraph=None):
    """Runs after every frame change, in the viewport and in renders. It reads no evaluated
    data (only the cache and the original meshes of `scene`), so it is valid with whichever
    depsgraph Blender passes, the viewport's or the render's."""
    if _suspended:
        return
    for obj in scene.objects:
        if obj.type != "MESH" or not obj.madder.enabled:
            continue
        try:
            apply_frame(obj, scene.frame_current)
        except Exception as e:  # never break playback or a render; say what failed
            print(f"Madder: cannot show the stain of '{obj.name}' at frame {scene.frame_current}: {e}")


def register():
    if on_frame_change not in bpy.app.handlers.frame_change_post:
        bpy.app.handlers.frame_change_post.append(on_frame_change)


def unregister():
    if on_frame_change in bpy.app.handlers.frame_change_post:
        bpy.app.handlers.frame_change_post.remove(on_frame_change)
    _readers.clear()
