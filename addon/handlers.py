"""Playback: after every frame change, each enabled object with a bake gets that frame's
stain written into its attributes (`madder_stain`, `madder_wetness`, `madder_deposit`;
see `bridge.write_stain`), by way of its carrier (`carrier`: never into the cloth's own
mesh, which would throw away the Cloth modifier's cache).

A stale stain is never shown. When the cache cannot give this frame for this mesh
(`problem()`: the file is missing or unreadable, truncated or corrupt at the frame, made
for another vertex count, or the mesh's faces changed since the bake, by the topology
fingerprint the bake recorded), playback writes zeros instead (the shader then shows the
bare cloth), and the panel shows the reason with the path it looked at.

Renders: `render_init` lists every affected frame of the range in the console, and
`render_pre` (which runs for every frame, before its frame change) checks the frame about
to be rendered. Unless the object's *Render Without Stain* is on, an affected frame stops
the render. A handler cannot cancel a render (an exception in it is printed and the
render goes on), but a frame that cannot be saved stops an animation render, and the
operator then raises (`bpy.ops.render.render`). So the output path is pointed under a
regular file for that frame; `render_cancel` restores it. A Blender executable in
background mode (`blender -b file -a`) then exits with status 1.

Cost: a frame that plays reads one block (Rust, GIL released) and writes three
attributes. Everything else is cached: the open reader per file (re-opened when the
file's mtime or size changes), the attributes, the topology check (re-run only when the
mesh's counts or its corner array change)."""

import os
import re
import sys
import tempfile

import bpy
from bpy.app.handlers import persistent

from . import bridge, carrier, frames, images, playback, presets, shading, stored
from .errors import RelocateError

_readers = {}  # absolute path -> (mtime_ns, size, CacheReader)
_corrupt = {}  # (path, mtime_ns, size) -> {frame: message}: blocks that failed to read
_suspended = 0  # > 0 while a bake walks the frames: playback must not touch the meshes
_render = None  # while a render runs: {"filepath": the user's output path, "stopped": reason}
_remapped = []  # (object, its cache path before) while a Save As runs
_told = {}  # object name -> the problem last printed for it (None: it played)


def suspend():
    """No playback until the matching `resume()`: a bake steps through frames and must not
    have the handler rewrite the meshes it is reading (nor spend the time)."""
    global _suspended
    _suspended += 1


def resume():
    global _suspended
    _suspended -= 1


def suspended():
    """Whether a bake is walking the frames (`suspend`)."""
    return _suspended > 0


def _reader(path):
    import madder

    st = os.stat(path)
    key = (st.st_mtime_ns, st.st_size)
    hit = _readers.get(path)
    if hit is None or hit[:2] != key:
        _readers[path] = (*key, madder.CacheReader(path))
    return _readers[path][2]


def forget(path):
    """Drops what is known about the cache at `path` (after a relocation or a new bake)."""
    _readers.pop(path, None)
    for key in [k for k in _corrupt if k[0] == path]:
        del _corrupt[key]


@persistent
def on_depsgraph_update(scene, depsgraph):
    """An edited mesh (Edit Mode, a script's bmesh) has its faces checked again."""
    if stored.remembers_topology():
        for update in depsgraph.updates:
            if update.is_updated_geometry and isinstance(update.id, bpy.types.Mesh):
                stored.forget_topology(update.id.original.as_pointer())


def problem(obj, frame):
    """Why `obj` cannot show its baked stain at `frame`, as a message naming the path that
    was looked at, or None when it can (or has no bake). Reads no frame data. With an
    image sequence in use, a missing image of the frame is a problem too."""
    return _check(obj, frame)[0] or images.frame_problem(obj, frame)


def wants_attributes(obj):
    """Whether playback writes `obj`'s stain attributes: Vertex Colors is on, or the
    shader cannot read images instead (none baked): never a stale stain on screen."""
    return obj.madder.output_vertex_colors or not stored.uses_images(obj)


def _check(obj, frame):
    """(problem, reader, cache frame): the reader and the clamped frame to read when there
    is no problem."""
    settings = obj.madder
    if not settings.cache_file:
        return None, None, None
    path = stored.played_path(obj)
    if not os.path.isfile(path):
        return f"Cache not found: {path}", None, None
    import madder

    try:
        reader = _reader(path)
    except (OSError, madder.MadderError) as e:  # the message names the file
        return f"Cache unreadable: {e}", None, None
    why = playback.mismatch(path, reader, len(obj.data.vertices))
    if why is not None:
        return why, None, None
    if settings.bake_topology and not stored.same_topology(obj.data, settings.bake_topology):
        return f"Stale cache: the mesh's faces changed since the bake ({path}): bake again", None, None
    why, at = playback.frame_to_read(path, reader, frame, _corrupt.get(_file_key(path, reader), {}))
    return why, (reader if why is None else None), at


def damage(obj):
    """A warning when `obj`'s cache is truncated (some frames show no stain), else None."""
    try:
        reader = _reader(stored.played_path(obj)) if obj.madder.cache_file else None
    except Exception:
        return None  # `problem()` says why
    return playback.truncation(reader) if reader is not None else None


def _probe(obj, frame):
    """`problem()`, after reading the frame's block so that a corrupt one is known (renders
    check a frame before its frame change reads it)."""
    why, reader, at = _check(obj, frame)
    if why is None and reader is not None:
        why = _read(obj, reader, at, (1.0, 1.0, 1.0), (1.0, 1.0, 1.0), bridge.stain_buffers(reader.n_vertices))
    return why or images.frame_problem(obj, frame)


def _read(obj, reader, at, refs, color, buffers):
    """Reads frame `at` into `buffers` (one read and checksum for all fields, normalized in
    place, in Rust); a corrupt block is remembered for the panel and returned as the problem."""
    import madder

    try:
        reader.read_stain(at, refs, color, *buffers)
    except madder.CacheError as e:
        _corrupt.setdefault(_file_key(stored.played_path(obj), reader), {})[at] = str(e)
        return f"Damaged cache: {e}: bake again"
    return None


def _file_key(path, reader):
    hit = _readers.get(path)
    return (path, *hit[:2]) if hit is not None and hit[2] is reader else (path,)


def apply_frame(obj, frame):
    """Writes `obj`'s baked stain at `frame` (clamped to the baked range) into its mesh
    (unless it shows images only: `wants_attributes`). Returns None when it did (or there
    is no bake, or the mesh is in Edit Mode), else the problem: the cache's, after
    clearing the stain attributes (no stale stain is ever left shown), or a missing image
    of the frame's sequence."""
    if not obj.madder.cache_file or obj.mode == "EDIT":
        return None
    why, reader, at = _check(obj, frame)
    if why is None and not wants_attributes(obj):  # the shader reads the images
        return images.frame_problem(obj, frame)
    if why is None:
        settings = obj.madder
        refs = tuple(settings.bake_references)
        if not any(refs):  # a cache made outside a bake (a script): the object's own settings
            refs = presets.references(settings)
        buffers = bridge.stain_buffers(reader.n_vertices)
        why = _read(obj, reader, at, refs, tuple(settings.stain_color), buffers)
    if why is not None:
        carrier.clear(obj)
        return why
    # a render never adds data-blocks mid-frame (`carrier`): its carrier was made on load
    mesh = carrier.ensure(obj) if _render is None else carrier.find(obj)
    if mesh is None:
        return f"no '{carrier.MODIFIER}' modifier to show the stain (play a frame in the viewport, then render)"
    bridge.write_stain(mesh, *buffers)
    return images.frame_problem(obj, frame)


def _stained(scene):
    # a Live object's attributes are its preview's (`preview`), not the cache's
    return [o for o in scene.objects
            if o.type == "MESH" and o.madder.enabled and o.madder.cache_file and not o.madder.live]


@persistent
def on_frame_change(scene, depsgraph=None):
    """Runs on every frame change, in the viewport and in renders, before the depsgraph
    evaluates the new frame (`frame_change_pre`): the attributes written here are in that
    one evaluation. Written after it (`frame_change_post`), the mesh's tag made Blender
    evaluate its modifier stack a second time, which cost more than the handler itself.
    It reads no evaluated data (only the cache and the original meshes of `scene`), so it
    is valid with whichever depsgraph Blender evaluates next, the viewport's or the
    render's."""
    if _suspended:
        return
    for obj in _stained(scene):
        try:
            why = apply_frame(obj, scene.frame_current)
        except Exception as e:  # never break playback or a render; say what failed
            why = f"cannot show the stain: {e}"
            try:
                carrier.clear(obj)
            except Exception:
                pass
        # the console hears of each problem once (renders report every frame themselves)
        if why is not None and _render is None and _told.get(obj.name) != why:
            print(f"Madder: '{obj.name}' at frame {scene.frame_current}: {why}", file=sys.stderr)
        _told[obj.name] = why


@persistent
def on_load(*_args):
    """A file just opened shows its current frame from the cache, not the stain saved in
    the .blend (which is stale when the cache moved or is gone)."""
    stored.forget_topology()  # the meshes of the old file are gone; their addresses get reused
    for obj in bpy.data.objects:  # a file saved with Madder switched off (by an older Madder)
        if obj.type == "MESH" and obj.library is None and not obj.madder.enabled:
            carrier.show(obj, False)
    scene = bpy.context.scene
    if scene is not None:
        on_frame_change(scene)


# -- renders


_ranges = frames.ranges


@persistent
def on_render_init(scene, *_args):
    global _render
    _render = {"filepath": scene.render.filepath, "stopped": None}
    for obj in _stained(scene):
        bad = [f for f in range(scene.frame_start, scene.frame_end + 1, max(scene.frame_step, 1))
               if problem(obj, f) is not None]
        if bad:
            anyway = obj.madder.render_without_cache or scene.render.is_movie_format
            what = "renders without its stain" if anyway else "stops the render"
            print(f"Madder: '{obj.name}' has no valid stain at frames {_ranges(bad)} ({what}): "
                  f"{problem(obj, bad[0])}", file=sys.stderr)
            if not obj.madder.render_without_cache and scene.render.is_movie_format:
                # a movie's file is open from the first frame: it cannot be stopped from here
                if bpy.app.background and bpy.app.binary_path:  # `blender -b … -a`: fail now
                    print(f"Madder: render failed: '{obj.name}' has no valid stain at frame {bad[0]}",
                          file=sys.stderr)
                    raise SystemExit(1)
                print("Madder: a movie cannot be stopped at a frame: these frames render without the "
                      "stain (render an image sequence to stop there)", file=sys.stderr)


@persistent
def on_render_pre(scene, *_args):
    """Before each rendered frame (its frame change comes after): report the objects that
    cannot show their stain, and stop the render unless they may render without it (an
    image sequence only: see `on_render_init` for movies)."""
    if _render is None or _render["stopped"]:
        return
    movie = scene.render.is_movie_format
    frame = scene.frame_current
    for obj in _stained(scene):
        why = _probe(obj, frame)
        if why is None:
            continue
        print(f"Madder: render frame {frame}: '{obj.name}': {why}", file=sys.stderr)
        if not obj.madder.render_without_cache and not movie:
            _stop(scene, f"'{obj.name}' has no valid stain at frame {frame}")


def _stop(scene, reason):
    """Makes this frame's image unsavable, which ends an animation render with an error."""
    _render["stopped"] = reason
    blocker = os.path.join(tempfile.gettempdir(), f"madder-render-stopped-{os.getpid()}")
    if not os.path.isfile(blocker):
        with open(blocker, "w") as f:
            f.write("Madder stopped a render: its output path points under this file.\n")
    label = re.sub(r'[\\/:*?"<>|]', "_", f"Madder stopped the render - {reason} (see the console)")
    scene.render.filepath = os.path.join(blocker, label, "####")
    print(f"Madder: stopping the render: {reason} (tick Render Without Stain to render anyway)", file=sys.stderr)


@persistent
def on_render_end(scene, *_args):
    global _render
    state, _render = _render, None
    if state is None:
        return
    if state["stopped"]:
        scene.render.filepath = state["filepath"]
        if bpy.app.background and bpy.app.binary_path:  # `blender -b … -a`: fail the command
            print(f"Madder: render failed: {state['stopped']}", file=sys.stderr)
            raise SystemExit(1)


# -- Save As: a relative cache path keeps pointing at the same file, as Blender remaps images


@persistent
def on_save_pre(filepath, *_args):
    old = bpy.data.filepath
    if not old or not filepath or os.path.dirname(os.path.abspath(filepath)) == os.path.dirname(old):
        return
    start = os.path.dirname(os.path.abspath(filepath))
    for obj in bpy.data.objects:
        rel = obj.madder.cache_file if obj.type == "MESH" else ""
        if rel.startswith("//"):
            target = os.path.normpath(bpy.path.abspath(rel))
            try:
                obj.madder.cache_file = "//" + os.path.relpath(target, start).replace(os.sep, "/")
            except ValueError:  # another drive
                obj.madder.cache_file = target
            _remapped.append((obj.name, rel))


@persistent
def on_save_post(filepath, *_args):
    """A copy (Save Copy) leaves this session on the old file: its paths go back."""
    if os.path.abspath(filepath) != bpy.data.filepath:
        for name, rel in _remapped:
            obj = bpy.data.objects.get(name)
            if obj is not None:
                obj.madder.cache_file = rel
    _remapped.clear()


_HANDLERS = (
    ("frame_change_pre", on_frame_change),
    ("load_post", on_load),
    ("depsgraph_update_post", on_depsgraph_update),
    ("render_init", on_render_init),
    ("render_pre", on_render_pre),
    ("render_complete", on_render_end),
    ("render_cancel", on_render_end),
    ("save_pre", on_save_pre),
    ("save_post", on_save_post),
)


def register():
    for name, fn in _HANDLERS:
        handlers = getattr(bpy.app.handlers, name)
        if fn not in handlers:
            handlers.append(fn)


def unregister():
    for name, fn in _HANDLERS:
        handlers = getattr(bpy.app.handlers, name)
        if fn in handlers:
            handlers.remove(fn)
    _readers.clear()
    _corrupt.clear()
    stored.forget_topology()
    _told.clear()


def relocate(obj, path):
    """Points `obj` at the cache file `path` (a moved cache). Raises RelocateError, naming
    the file (its `filename`, `object`), when it is not a cache for this mesh; the object
    then keeps its path. Returns the problem left at the current frame (e.g. a truncated
    file), or None."""
    import madder

    path = os.path.abspath(bpy.path.abspath(path))
    where = dict(object=obj.name, filename=path)
    try:
        reader = madder.CacheReader(path)
    except (OSError, madder.MadderError) as e:
        raise RelocateError(f"cannot use {path} as the cache of '{obj.name}': {e}", **where) from e
    n = len(obj.data.vertices)
    if reader.n_vertices != n:
        raise RelocateError(f"{path} holds {reader.n_vertices} vertices; '{obj.name}' has {n}: not its cache", **where)
    missing = [f for f in bridge.FIELDS if f not in reader.fields]
    if missing:
        raise RelocateError(f"{path} has no '{missing[0]}' field: not a Madder stain cache", **where)
    forget(path)
    obj.madder.cache_file = stored.stored_path(path)
    if stored.uses_images(obj):  # the images beside the cache: point the shader's at them
        shading.sync_object(obj)
        images.reload(obj)
    frame = bpy.context.scene.frame_current
    return apply_frame(obj, frame)
