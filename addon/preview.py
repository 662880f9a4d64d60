"""Live preview: with an object's **Live** on, playing the timeline forward from the start
frame simulates each frame as it is shown, without a bake; Bake from Preview writes what
was previewed to the cache.

The simulation is `bake.Stepper`, the code path a bake drives, fed the same inputs in the
same order (`live.decide`: one-frame lookahead, so frame `f` is finished, and shown, when
`f + 1` is): the previewed frames are a bake's frames, bit for bit
(tests/blender/test_live.py). A frame's positions are read in `frame_change_post`, from
the depsgraph Blender just evaluated for the frame (the cloth simulated or read from its
point cache, the sources moved); the stain attributes written there make Blender evaluate
the object's modifier stack once more for that frame (playback of a bake writes them in
`frame_change_pre` and avoids that second evaluation, see `handlers`): the price of
simulating from evaluated positions.

A session is dropped (and its stain cleared) on a jump that is not the next frame
forward, scrubbing back excepted, and restarts at the start frame unless every frame of
the range is finished and held (then it plays like a bake; `live.decide`), when any setting of the object, its
sources or the scene that the simulation reads changed (a key of every such value,
compared at each frame change: edits by the UI, a script or undo alike), when Live is
turned off, and when a file is loaded. The finished frames' cache fields are held
(`live.FrameStore`) up to the object's Live Memory, oldest dropped first."""

import os
import sys

import bpy
from bpy.app.handlers import persistent

from . import bake, bridge, carrier, handlers, images, live, shading, stored, textures
from .errors import BakeError

_sessions = {}  # object name -> Session
_errors = {}  # object name -> why its live preview stopped

# settings that do not change what is simulated (playback, output, bookkeeping)
_NOT_SIMULATED = {
    "live", "live_memory", "enabled", "cache_dir", "cache_file", "bake_references", "bake_topology",
    "bake_detail", "lcs", "render_without_cache", "output_vertex_colors", "output_images", "image_size",
    "image_baked", "image_frames", "image_baked_size", "image_uv_map", "rna_type", "name",
    "sharp_outline", "image_baked_outline", "outline_in_shader", "image_baked_outline_shader",
}


def _values(group, skip=()):
    out = []
    for prop in group.bl_rna.properties:
        if prop.identifier in skip or prop.type in {"POINTER", "COLLECTION"}:
            continue
        value = getattr(group, prop.identifier)
        out.append((prop.identifier, tuple(value) if hasattr(value, "__len__") and not isinstance(value, str)
                    else value))
    return tuple(out)


def settings_key(scene, obj):
    """Every value the simulation of `obj` reads from settings: its Madder settings, its
    sources' (and which objects they are), the scene's frame range, rate, gravity and units."""
    sources = tuple((o.name, _values(o.madder_source)) for o in scene.objects
                    if o.madder_source.is_source and o != obj)
    units = scene.unit_settings
    # an animated Frame Time changes from frame to frame: the clock's keys are not a setting
    skip = _NOT_SIMULATED | ({"frame_time"} if obj.animation_data is not None else set())
    return (_values(obj.madder, skip), sources, scene.frame_start, scene.frame_end, scene.render.fps,
            scene.render.fps_base, tuple(scene.gravity), scene.use_gravity, units.system, units.scale_length,
            len(obj.data.vertices), len(obj.data.polygons))


class Session:
    """One object's live simulation: the stepper, the frame taken next, the frame shown
    but not yet finished (its positions and pours: its step needs the next frame's
    positions) and the finished frames held."""

    def __init__(self, scene, obj):
        self.stepper = bake.Stepper(scene, obj)
        self.first, self.last = scene.frame_start, scene.frame_end
        self.key = settings_key(scene, obj)
        self.store = live.FrameStore(obj.madder.live_memory * 2**20)
        self.expected = None
        self.pending = None  # (frame, positions, contacts, seconds)

    @property
    def complete(self):
        """Every frame of the range finished and held."""
        return self.expected is not None and self.expected > self.last and not self.store.dropped

    def restart(self, depsgraph):
        st = self.stepper
        st.start(st._positions(self.first, depsgraph), depsgraph)
        self.store.put(self.first, st.frame_fields())
        self.expected = self.first + 1

    def step(self, frame, depsgraph):
        st = self.stepper
        pos = st._positions(frame, depsgraph)
        contacts = st._contacts(frame, pos, depsgraph)
        dt = st.seconds(frame)
        if self.pending is not None:
            f0, pos0, contacts0, dt0 = self.pending
            st.advance(pos0, contacts0, dt0, pos, dt)
            self.store.put(f0, st.frame_fields())
        self.pending = (frame, pos, contacts, dt)
        if frame == self.last:  # a bake's last frame has no lookahead either
            st.advance(pos, contacts, dt, None, None)
            self.store.put(frame, st.frame_fields())
            self.pending = None
        self.expected = frame + 1


def session(obj):
    return _sessions.get(obj.name)


def drop(obj, clear=True):
    """Ends `obj`'s live session (its held frames are freed) and clears its stain."""
    _sessions.pop(obj.name, None)
    if clear and obj.type == "MESH" and obj.mode != "EDIT":
        carrier.clear(obj)


def status(obj):
    """The panel's line: frames held and their memory, or why the preview stopped."""
    why = _errors.get(obj.name)
    if why:
        return why
    s = session(obj)
    if s is None or not len(s.store):
        return f"Play from frame {bpy.context.scene.frame_start} to simulate"
    frames = s.store.frames()
    dropped = f", {s.store.dropped} dropped" if s.store.dropped else ""
    return f"{len(frames)} frames held ({frames[0]}–{frames[-1]}), {s.store.nbytes / 2**20:.1f} MB{dropped}"


def _show(obj, frame, fields, st):
    settings = obj.madder
    color = fields[3:6] if st.sources else tuple(settings.stain_color)
    attributes = live.stain_attributes(fields[0], fields[1], fields[2], st.references, color)
    bridge.write_stain(carrier.ensure(obj), *attributes)


def frame_change(scene, obj, depsgraph):
    """What the frame change to the scene's current frame does to `obj`'s preview."""
    frame = scene.frame_current
    s = session(obj)
    if s is not None and s.key != settings_key(scene, obj):
        drop(obj)
        s = None
    action = live.decide(frame, scene.frame_start, scene.frame_end, s.expected if s is not None else None,
                         s is not None and s.complete)
    if action == live.RESET:
        if s is not None or obj.name in _errors:
            drop(obj)
        return
    try:
        if action == live.RESTART:
            _errors.pop(obj.name, None)
            s = _sessions[obj.name] = Session(scene, obj)
            s.restart(depsgraph)
        elif action == live.STEP:
            s.step(frame, depsgraph)
    except Exception as e:
        drop(obj)
        _errors[obj.name] = f"Live stopped at frame {frame}: {e}"
        raise
    held = s.store.newest_at_or_before(frame)
    if held is not None and obj.mode != "EDIT":
        _show(obj, held[0], held[1], s.stepper)


def _live_objects(scene):
    return [o for o in scene.objects if o.type == "MESH" and o.madder.enabled and o.madder.live]


@persistent
def on_frame_change_post(scene, depsgraph=None):
    """Steps every live object of `scene` to the frame just evaluated (see the module doc)."""
    if handlers.suspended():
        return
    objs = _live_objects(scene)
    if not objs:
        return
    depsgraph = depsgraph or bpy.context.evaluated_depsgraph_get()
    for obj in objs:
        try:
            frame_change(scene, obj, depsgraph)
        except Exception as e:  # never break playback; the panel and the console say why
            print(f"Madder: '{obj.name}' Live at frame {scene.frame_current}: {e}", file=sys.stderr)


@persistent
def on_load(*_args):
    _sessions.clear()
    _errors.clear()


def live_update(settings, context):
    """Live toggled: off ends the session and shows the bake again (if any)."""
    obj = settings.id_data
    if not settings.live:
        _errors.pop(obj.name, None)
        if obj.name in _sessions:
            drop(obj)
        if obj.madder.cache_file and context.scene is not None:
            handlers.apply_frame(obj, context.scene.frame_current)


def memory_update(settings, _context):
    s = _sessions.get(settings.id_data.name)
    if s is not None:
        s.store.trim(settings.live_memory * 2**20)


def bake_from_preview(scene, obj):
    """Writes the previewed frames (start frame to the newest finished one) to `obj`'s cache
    as a bake writes it (same fields and format; a temporary file renamed over the old one,
    which stays on failure), records it like a bake, and turns Live off so the cache plays.
    Returns the path. Refuses, naming the frames, when the memory limit dropped frames
    from the start of the preview."""
    s = session(obj)
    if s is None or not len(s.store):
        raise BakeError(f"'{obj.name}': nothing previewed: turn Live on and play from frame {scene.frame_start}",
                        object=obj.name)
    if s.key != settings_key(scene, obj):
        raise BakeError(f"'{obj.name}': settings changed since the preview: play it again", object=obj.name)
    # on by default (issue 34): kept without images unless the user ticked it
    if obj.madder.output_images and obj.madder.is_property_set("output_images"):
        raise BakeError(f"'{obj.name}': Image Sequence needs the refined cloth's fields, which Live does not keep: "
                        "untick Image Sequence, or Bake", object=obj.name)
    held = s.store.frames()
    if held[0] != s.first:
        raise BakeError(
            f"'{obj.name}': frames {s.first}–{held[0] - 1} of the preview were dropped by the Live Memory limit "
            f"({obj.madder.live_memory:g} MB; {len(held)} frames held): raise it and play again from frame {s.first}",
            object=obj.name)
    st = s.stepper
    path = stored.target_path(obj)
    try:
        os.makedirs(os.path.dirname(path), exist_ok=True)
    except OSError as e:
        raise BakeError(f"'{obj.name}': cannot create the cache folder {os.path.dirname(path)}: {e}",
                        object=obj.name, filename=os.path.dirname(path)) from e
    madder = st.madder
    try:
        writer = madder.CacheWriter(path, st.n_vertices, st.cache_fields, s.first, len(held), st.recorded_frame_time)
        try:
            for f in held:
                writer.push_frame(s.store.get(f))
        except BaseException:
            writer.abort()
            raise
        writer.finish()
    except madder.MadderError as e:
        raise BakeError(f"'{obj.name}': {e}", object=obj.name, filename=getattr(e, "filename", None)) from e
    handlers.forget(path)
    settings = obj.madder
    settings.cache_file = stored.stored_path(path)
    settings.bake_references = st.references
    settings.bake_topology = stored.topology_fingerprint(obj.data)
    settings.bake_detail = st.detail
    images.forget(obj)
    try:
        textures.remove_outputs(path)
    except OSError:
        pass  # an earlier bake's images stay; they are not used (no Image Sequence recorded)
    shading.sync_object(obj)
    settings.live = False  # the cache plays now (live_update shows it)
    scene.render.use_lock_interface = True
    return path


_HANDLERS = (("frame_change_post", on_frame_change_post), ("load_post", on_load))


def register():
    for name, fn in _HANDLERS:
        lst = getattr(bpy.app.handlers, name)
        if fn not in lst:
            lst.append(fn)


def unregister():
    for name, fn in _HANDLERS:
        lst = getattr(bpy.app.handlers, name)
        if fn in lst:
            lst.remove(fn)
    _sessions.clear()
    _errors.clear()
