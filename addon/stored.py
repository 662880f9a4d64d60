"""The files a bake leaves and how an object finds them again: where `obj` bakes to
(`target_path`) and what it plays (`played_path`), the path stored in the .blend
(`stored_path`), the fingerprint that ties a bake to its mesh's faces
(`topology_fingerprint`, `same_topology`) and the image sequence beside a cache
(`uses_images`, `image_paths`).

The bottom of the add-on's bpy side: `bake`, `handlers`, `images` and `shading` all
import it and it imports none of them (nothing above `errors` and the bpy-free
`textures`), so those four form no import circle."""

import os
import zlib

import bpy
import numpy as np

from . import textures
from .errors import BakeError

CACHE_EXT = ".madder"

_topology = {}  # mesh pointer -> ((counts, corner layer pointer, fingerprint), matches)


def target_path(obj):
    """Absolute path of the cache file `obj` bakes to (from its Cache Folder). Raises
    BakeError when the folder is relative and the .blend was never saved."""
    settings = obj.madder
    folder = settings.cache_dir or "//madder_cache/"
    if folder.startswith("//") and not bpy.data.filepath:
        raise BakeError(f"'{obj.name}': save the .blend first, or set an absolute cache folder", object=obj.name)
    folder = bpy.path.abspath(folder)
    return os.path.join(folder, bpy.path.clean_name(obj.name) + CACHE_EXT)


def played_path(obj):
    """Absolute path of the cache `obj` plays back, the one its last bake recorded ("" when
    it has none). It differs from `target_path` after a relocation, or when the Cache
    Folder changed since the bake."""
    return bpy.path.abspath(obj.madder.cache_file) if obj.madder.cache_file else ""


def stored_path(path):
    """Path to store in the .blend: relative to it when it is saved (a moved project keeps working)."""
    if bpy.data.filepath:
        try:
            return bpy.path.relpath(path)
        except ValueError:  # another drive
            return path
    return path


def topology_fingerprint(mesh):
    """A cheap fingerprint of `mesh`'s faces: the counts of vertices, edges, faces and
    corners, then a CRC of every corner's vertex. The bake records it; playback compares
    it, so a stain baked for other faces is not shown on these."""
    corners = np.empty(len(mesh.loops), dtype=np.int32)
    layer = mesh.attributes.get(".corner_vert")
    if layer is not None:  # the fast path (mesh.loops' "vertex_index" is 100× slower)
        layer.data.foreach_get("value", corners)
    else:
        mesh.loops.foreach_get("vertex_index", corners)
    return f"{_counts(mesh)}{zlib.crc32(corners.tobytes()):08x}"


def _counts(mesh):
    return f"{len(mesh.vertices)}:{len(mesh.edges)}:{len(mesh.polygons)}:{len(mesh.loops)}:"


def same_topology(mesh, recorded):
    """Whether `mesh`'s faces match the fingerprint `recorded`. The counts are compared
    every call; the CRC again only when the mesh's corner layer moved (Edit Mode rebuilds
    it), the counts changed, or `forget_topology` dropped the mesh (a geometry edit, a file
    opened)."""
    counts = _counts(mesh)
    if not recorded.startswith(counts):
        return False
    layer = mesh.attributes.get(".corner_vert")
    key = (counts, layer.as_pointer() if layer is not None else 0, recorded)
    hit = _topology.get(mesh.as_pointer())
    if hit is None or hit[0] != key:
        hit = _topology[mesh.as_pointer()] = (key, topology_fingerprint(mesh) == recorded)
    return hit[1]


def forget_topology(mesh_pointer=None):
    """Drops the remembered check of one mesh (by `as_pointer()`), or of every mesh."""
    if mesh_pointer is None:
        _topology.clear()
    else:
        _topology.pop(mesh_pointer, None)


def remembers_topology():
    """Whether any mesh's check is remembered (the depsgraph handler skips its walk if not)."""
    return bool(_topology)


def uses_images(obj):
    """Whether `obj`'s stain shader reads images: it wants them (Image Sequence) and a
    bake or re-export wrote them."""
    s = obj.madder
    return bool(s.output_images and s.image_baked and s.cache_file)


def image_paths(obj, cache=None):
    """(fine cache, image folder, file prefix) of `obj`, derived from its cache path
    (`cache`, default the one it plays)."""
    cache = cache or played_path(obj)
    return textures.fine_cache_path(cache), textures.image_folder(cache), textures.stem(cache)
