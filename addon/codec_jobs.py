"""Compress Motion and Decompress, the bpy side: the stepwise jobs behind the operators
(a modal operator runs one step per timer tick, a script runs them to the end). What
needs no Blender (the checks, the encoder and decoder calls, the timing) is in `codec`.

`CompressJob` walks the scene's frame range in order (as a bake does, so a cloth
simulation that is not baked is computed on the way) and hands each frame's evaluated
object-space positions to `codec.Compression`; `DecompressJob` decodes a `.madm` file to
a PC2 and, optionally, points a Mesh Cache modifier at it. Both restore the frame the
user was on, write nothing until they finish, and keep any earlier file on failure."""

import os

import bpy

from . import bake, bridge, codec, compat, handlers, stored
from .errors import MotionCodecError

# the Mesh Cache modifier Decompress adds when none reads the PC2 already
MODIFIER_NAME = "Madder Motion"


def compressed_path(obj):
    """Absolute path of the `.madm` file of `obj`: its Compressed Motion setting, or the
    object's name in its Cache Folder."""
    s = obj.madder
    path = s.motion.path
    if not path:
        folder = s.cache_dir or "//madder_cache/"
        path = os.path.join(folder, bpy.path.clean_name(obj.name) + codec.EXT)
    if path.startswith("//") and not bpy.data.filepath:
        raise MotionCodecError(f"'{obj.name}': save the .blend first, or give Compressed Motion an absolute path",
                               object=obj.name)
    return bpy.path.abspath(path)


def decompressed_path(obj):
    """Absolute path of the PC2 file Decompress writes for `obj`."""
    pc2 = obj.madder.motion.pc2_path
    if not pc2:
        return codec.pc2_path(compressed_path(obj))
    if pc2.startswith("//") and not bpy.data.filepath:
        raise MotionCodecError(f"'{obj.name}': save the .blend first, or give PC2 File an absolute path",
                               object=obj.name)
    return bpy.path.abspath(pc2)


def _check_object(obj):
    if obj is None:
        raise MotionCodecError("no active object: select the cloth (a mesh object) whose motion to compress")
    if obj.type != "MESH":
        raise MotionCodecError(f"Madder compresses the motion of mesh objects; '{obj.name}' is a "
                               f"{obj.type.lower()}", object=obj.name)


class CompressJob:
    """The evaluated motion of `obj` over the scene's frame range into its `.madm` file
    (`compressed_path`). `step()` evaluates and adds the next frame (False once the last
    is in), `finish()` puts the file in place and records the figures, `cancel()` (or any
    error) discards it."""

    def __init__(self, scene, obj):
        _check_object(obj)
        self.scene, self.obj = scene, obj
        self.path = compressed_path(obj)
        self.n_vertices = len(obj.data.vertices)
        self.compression = codec.Compression(bake.core(), obj.name, self.path, scene.frame_start, scene.frame_end,
                                             obj.madder.motion.bits)
        self.frame_before = scene.frame_current
        self._suspended = False

    @property
    def total(self):
        return self.compression.total

    @property
    def done(self):
        return self.compression.done

    @property
    def status(self):
        return f"compressing the motion of frame {self.compression.next_frame()}"

    def step(self):
        if not self._suspended:
            handlers.suspend()  # playback must not rewrite the meshes being read
            self._suspended = True
        frame = self.compression.next_frame()
        obj = self.obj
        try:
            self.scene.frame_set(frame)
            obj_eval = obj.evaluated_get(bpy.context.evaluated_depsgraph_get())
            mesh = obj_eval.data
            if len(mesh.vertices) != self.n_vertices:
                raise MotionCodecError(
                    f"'{obj.name}' has {len(mesh.vertices)} vertices at frame {frame} but {self.n_vertices} in its "
                    "mesh: the compressed motion must fit the mesh, as a Motion File or a Mesh Cache does (move "
                    "generating modifiers such as Subdivision below the cloth and disable them)",
                    object=obj.name, frame=frame)
            faces = bridge.topology_arrays(mesh)[0]
            more = self.compression.add(frame, bridge.rest_positions(mesh), faces)
        except BaseException:
            self.cancel()
            raise
        return more

    def finish(self):
        """Puts the file in place; returns the encoder's stats (a dict)."""
        try:
            stats = self.compression.finish()
        finally:
            self._close()
        m = self.obj.madder.motion
        m.figures = (stats["bits_per_vertex_frame"], stats["max_error"], stats["rms_error"])
        m.report = codec.summary(stats)
        return stats

    def cancel(self):
        """Discards the partial file (an earlier file at the path stays) and restores the frame."""
        self.compression.abort()
        self._close()

    def _close(self):
        if self._suspended:
            handlers.resume()
            self._suspended = False
        if self.scene.frame_current != self.frame_before:
            self.scene.frame_set(self.frame_before)


class DecompressJob:
    """The object's `.madm` file decoded into its PC2 file (`decompressed_path`), then,
    with Mesh Cache Modifier on, a Mesh Cache modifier pointed at it."""

    def __init__(self, scene, obj):
        if obj is None:
            raise MotionCodecError("no active object: select the object whose compressed motion to decompress")
        self.scene, self.obj = scene, obj
        self.source, self.target = compressed_path(obj), decompressed_path(obj)
        self.decompression = codec.Decompression(bake.core(), self.source, self.target, obj.name)
        n = self.decompression.codec.n_points
        if obj.madder.motion.add_mesh_cache and (obj.type != "MESH" or len(obj.data.vertices) != n):
            have = f"has {len(obj.data.vertices)} vertices" if obj.type == "MESH" else f"is a {obj.type.lower()}"
            raise MotionCodecError(f"'{obj.name}' {have} but {self.source} holds {n} points: a Mesh Cache "
                                   "modifier could not play it (untick Mesh Cache Modifier to write the PC2 only)",
                                   object=obj.name, filename=self.source)
        self.modifier = None

    @property
    def total(self):
        return self.decompression.total

    @property
    def done(self):
        return self.decompression.done

    @property
    def status(self):
        return f"decompressing sample {self.done}"

    def step(self):
        return self.decompression.step()

    def finish(self):
        """Writes the PC2 (and points the modifier at it); returns its path."""
        path = self.decompression.finish()
        if self.obj.madder.motion.add_mesh_cache:
            self.modifier = point_mesh_cache(self.obj, path, *self.decompression.timing)
        return path

    def cancel(self):
        """Removes the partial file: the earlier PC2, if any, is kept."""
        self.decompression.abort()


def point_mesh_cache(obj, path, frame_start, frame_scale):
    """Points a Mesh Cache modifier of `obj` at the PC2 file `path` (the one that reads it
    already, else the one named `MODIFIER_NAME`, else a new one at the bottom of the stack,
    where it overwrites what the modifiers above compute), in Time Mode Frame, Play Mode
    Scene, with `frame_start` and `frame_scale` (`codec.modifier_timing`) and no change
    to the positions, as the bake's motion file reader expects (`motion.modifier_timing`)."""
    target = os.path.normpath(path)
    m = next((m for m in obj.modifiers if m.type == "MESH_CACHE" and m.filepath
              and os.path.normpath(bpy.path.abspath(m.filepath)) == target), None)
    if m is None:
        m = obj.modifiers.get(MODIFIER_NAME)
        if m is not None and m.type != "MESH_CACHE":
            m = None
    if m is None:
        m = obj.modifiers.new(MODIFIER_NAME, "MESH_CACHE")
    m.cache_format = "PC2"
    m.filepath = stored.stored_path(path)
    m.time_mode, m.play_mode = "FRAME", "SCENE"
    m.frame_start, m.frame_scale = frame_start, frame_scale
    m.deform_mode, m.interpolation = "OVERWRITE", "LINEAR"
    m.forward_axis, m.up_axis = "POS_Y", "POS_Z"
    m.factor, m.vertex_group = 1.0, ""
    m.flip_axis = compat.mesh_cache_flip_none(m)
    return m
