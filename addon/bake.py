"""Baking a stain: walks the scene's frames, feeds the evaluated positions to the Rust
simulator and streams the densities into the cache file. Errors are `BakeError`s whose
message names the object and frame (and whose `object` and `frame` attributes hold them);
the previous cache is kept on any failure.

This module is the bpy adapter: what needs no Blender lives in bpy-free modules, tested
from tests/python: `presets` (references, the simulator's keywords), `placement` (Unit
Scale, world placement, the collapsed-transform check), `motion` (motion-file sampling,
the Mesh Cache modifier's timing), `pour` (spills, pours and their fall-off),
`schedule` (the one-frame lookahead) and `errors`."""

import math
import os

import bpy
import numpy as np

from . import (
    bridge,
    carrier,
    codec,
    fabrics,
    handlers,
    images,
    motion,
    placement,
    pour,
    presets,
    schedule,
    shading,
    splash,
    stored,
    textures,
)
from .errors import BakeError, ExportError, FabricSettingsError, MotionCodecError
from .placement import check_transform as _check_transform, placed

FIELDS, COLOR_FIELDS, FLOW_FIELDS = bridge.FIELDS, bridge.COLOR_FIELDS, bridge.FLOW_FIELDS
__all__ = ["BakeError", "BakeJob", "MotionFile", "bake", "free", "placed", "simulator_settings", "unit_scale"]


def core():
    """The native `madder` module shipped in the extension's wheel."""
    try:
        import madder
    except ImportError as e:  # a broken install must say so, not fail obscurely later
        raise BakeError(f"Madder's native module could not be loaded ({e}); reinstall the extension") from e
    return madder


def check_object(obj, sources=()):
    if obj is None:
        raise BakeError("no active object: select the cloth (a mesh object) to bake, or use Bake All Stains")
    if obj.type != "MESH":
        raise BakeError(f"Madder bakes mesh objects; '{obj.name}' is a {obj.type.lower()}", object=obj.name)
    group = obj.madder.source_group
    if not group and not sources:
        raise BakeError(
            f"'{obj.name}': no liquid: choose a Spill Group (vertex group), or mark an object as a Madder Source",
            object=obj.name,
        )
    if group and group not in obj.vertex_groups:
        raise BakeError(f"'{obj.name}' has no vertex group '{group}' (its Spill Group)", object=obj.name)


def source_objects(scene, obj):
    """The scene's liquid sources (brushes and pours) for cloth `obj`."""
    sources = [o for o in scene.objects if o.madder_source.is_source and o != obj]
    for o in sources:
        if o.type != "MESH":
            raise BakeError(f"'{o.name}' is marked as a Madder Source but is a {o.type.lower()}, not a mesh",
                            object=o.name)
    return sources


def unit_scale(scene):
    """Metres per Blender unit of `scene` (`placement.unit_scale`)."""
    units = scene.unit_settings
    return placement.unit_scale(units.system, units.scale_length)


def check_transform(obj, frame, faces, local, matrix):
    """`placement.check_transform` for object `obj`."""
    _check_transform(obj.name, frame, faces, local, matrix)


def frame_positions(obj, depsgraph, n_vertices, frame, faces, unit):
    """World positions of the evaluated `obj` at `frame`, in metres, (N, 3) float32."""
    obj_eval = obj.evaluated_get(depsgraph)
    n = len(obj_eval.data.vertices)
    if n != n_vertices:
        raise BakeError(
            f"'{obj.name}' has {n} vertices at frame {frame} but {n_vertices} in its mesh: "
            "the deformed cloth must keep its topology (move generating modifiers such as "
            "Subdivision below the cloth and disable them for the bake)",
            object=obj.name, frame=frame,
        )
    local = bridge.rest_positions(obj_eval.data).astype(np.float64)
    bad = placement.first_non_finite(local)
    if bad is not None:
        raise BakeError(f"'{obj.name}': vertex {bad} has a non-finite position at frame {frame}",
                        object=obj.name, frame=frame, vertex=bad)
    check_transform(obj, frame, faces, local, obj_eval.matrix_world)
    return placed(local, obj_eval.matrix_world, unit)


class MotionFile(motion.MotionSamples):
    """Cloth positions from the object's Motion File (PC2/MDD, or Madder's compressed
    `.madm`; object space, placed by the object's current transform), sampled at scene
    frames. A PC2/MDD file is read as the object's Mesh Cache modifier that reads the same
    file shows it (`motion.MotionSamples`; Frame Start 0 and Frame Scale 1 without one). A
    `.madm` file, which no modifier reads, plays sample k at scene frame start + k·rate of
    its header, through the Frame Start and Frame Scale that the Mesh Cache modifier of its
    decompressed PC2 gets (`codec.modifier_timing`)."""

    def __init__(self, madder, obj):
        path = bpy.path.abspath(obj.madder.motion_file)
        compressed = codec.is_compressed(path)
        try:
            cache = madder.MotionCodec(path) if compressed else madder.PointCache(path)
        except madder.MadderError as e:
            raise BakeError(f"'{obj.name}': motion file: {motion.sample_message(e)}", object=obj.name) from e
        if cache.n_points != len(obj.data.vertices):
            raise BakeError(
                f"'{obj.name}' has {len(obj.data.vertices)} vertices but its motion file {path} has "
                f"{cache.n_points} points",
                object=obj.name,
            )
        offset, scale = 0.0, 1.0
        if compressed:
            try:
                offset, scale = codec.modifier_timing(cache.start, cache.rate, path)
            except MotionCodecError as e:
                raise BakeError(f"'{obj.name}': motion file: {e}", object=obj.name) from e
        for m in () if compressed else obj.modifiers:
            if m.type != "MESH_CACHE" or not m.filepath:
                continue
            if os.path.normpath(bpy.path.abspath(m.filepath)) != os.path.normpath(path):
                continue
            offset, scale = motion.modifier_timing(obj.name, m)
            break
        super().__init__(cache, obj.name, path, offset, scale)
        self.obj = obj
        self.matrix = np.array(obj.matrix_world, dtype=np.float64)


class Stepper:
    """One object's stain simulation, advanced a frame at a time from the object's
    settings: the one code path that both a bake (`BakeJob`) and Live preview
    (`live_session.LiveSession`) drive, so that a preview's frames are a bake's frames.

    `Stepper(scene, obj)` checks the input and prepares the topology, the fabric and the
    references; `start(pos)` builds the simulator at the first frame and spills the Spill
    Group; `advance(pos, contacts, dt, after, after_dt)` steps `dt` seconds to the next
    frame's positions (`after`: the positions `after_dt` later, `schedule`'s lookahead, or
    None at the last frame) and pours what the sources brought; `frame_fields()` is the
    frame's cache fields (`cache_fields`, in order). The frame's positions come from
    `positions(frame)`, the sources' pours from `contacts(frame, pos)` and its length from
    `seconds(frame)` (all on the scene as it is now, at that frame)."""

    def __init__(self, scene, obj):
        self.madder = core()
        self.sources = source_objects(scene, obj) if obj is not None else []
        check_object(obj, self.sources)
        self.scene, self.obj = scene, obj
        self.scene_dt = scene.render.fps_base / scene.render.fps
        self.clocked = obj.madder.clock == "FRAME_TIME"
        mesh = obj.data
        faces, face_polygon, n_polygons = bridge.topology_arrays(mesh)
        self.face_polygon = face_polygon
        self.n_vertices = len(mesh.vertices)
        if len(faces) == 0:
            raise BakeError(f"'{obj.name}' has no faces", object=obj.name)
        settings = obj.madder
        self.unit = unit_scale(scene)
        # Detail: the user's level, or chosen from the cloth's mean edge (issue 34)
        self.mean_edge = mean_edge_length(obj, self.unit)
        self.auto_detail = presets.use_auto_detail(settings.detail_auto, settings.is_property_set("detail_auto"),
                                                   settings.is_property_set("detail"))
        if self.auto_detail:
            # a cloth collapsed by its scale has no mean edge: Detail 0, and the frame's
            # transform check (placement.check_transform) names the object and frame
            self.detail = presets.auto_detail(self.mean_edge, len(mesh.vertices)) if self.mean_edge > 0.0 else 0
        else:
            self.detail = settings.detail
        self.wet0 = bridge.vertex_group_weights(obj, settings.source_group) if settings.source_group else None
        # with sources, colours can differ: track them (three more fields)
        self.fields = FIELDS + (COLOR_FIELDS if self.sources else [])
        # the flow goes to the cloth's cache only (the fine cache feeds the images)
        self.flow = bool(settings.bake_flow)
        self.cache_fields = self.fields + (FLOW_FIELDS if self.flow else [])
        self._pos = None  # this frame's positions (m), for the flow fields
        self.topology = _topology(self.madder, obj, faces, self.n_vertices, face_polygon, n_polygons)
        self.warnings = []
        n_nonmanifold = len(self.topology.non_manifold_edges())
        if n_nonmanifold:
            self.warnings.append(f"{n_nonmanifold} non-manifold edges (shared by 3+ faces)")
        self.conductivity = _conductivity(self.madder, obj, self.topology, face_polygon, self.warnings)
        self.references = presets.references(
            settings, [o.madder_source for o in self.sources], spill=self.wet0 is not None
        )
        if self.references[0] == 0.0:
            self.warnings.append("its liquid has no solute (concentration 0): it wets the cloth but leaves no stain")
        self.faces = faces.astype(np.int64)
        self.motion = MotionFile(self.madder, obj) if settings.motion_file else None
        self.sim = None
        self.splashed = set()  # sources whose splash is done

    def start(self, pos, depsgraph=None):
        """Builds the simulator at the first frame (rest pose: `_rest()`; first pose: `pos`)
        and spills the Spill Group."""
        self.sim = self.madder.Simulator(self.topology, self._rest(depsgraph), pos,
                                         **simulator_settings(self.scene, self.obj, self.unit),
                                         **self.conductivity, detail=self.detail)
        self.splashed = set()
        self._spill(pos)
        self._pos = pos

    def advance(self, pos, contacts, dt, after, after_dt):
        """Steps `dt` seconds to the next frame (positions `pos`; `after` the frame after it,
        `after_dt` later, or None) and pours the `contacts` of that frame."""
        self.sim.step(pos, dt, after=after, after_dt=after_dt)
        self._pour(contacts, dt)
        self._pos = pos

    def seconds(self, frame):
        """How long the step into `frame` lasts (s): the scene's 1/Frame Rate, or with the
        Frame Time clock the object's Frame Time as the scene evaluates it now (the caller
        has moved the scene to `frame`: keyframes and drivers give that frame's value)."""
        if not self.clocked:
            return self.scene_dt
        t = float(self.obj.madder.frame_time)
        if not (math.isfinite(t) and t > 0.0):
            raise BakeError(f"'{self.obj.name}' at frame {frame}: its Frame Time is {t:g} s; it must be > 0",
                            object=self.obj.name, frame=frame)
        return t

    @property
    def recorded_frame_time(self):
        """The frame time a cache records (what Coherent Structures integrates by): the
        scene's, or a Frame Time that nothing animates; 0 (none) where it may vary."""
        if not self.clocked:
            return self.scene_dt
        return 0.0 if self.obj.animation_data is not None else float(self.obj.madder.frame_time)

    def frame_fields(self):
        """This frame's cache fields, in the order of `cache_fields`."""
        return self._outputs() + self._flow()

    def _outputs(self, fine=False):
        """This frame's cache fields: total solute, liquid and deposit densities (kg/m²),
        and the solute's colour when sources may mix colours; at the refined cloth's
        vertices with `fine`."""
        sim = self.sim
        out = [np.ascontiguousarray(sim.stain(fine=fine)[:, 3]), sim.wetness(fine=fine), sim.deposit(fine=fine)]
        if self.sources:
            out += list(np.ascontiguousarray(sim.solute_color(fine=fine).T))
        return out

    def _flow(self):
        """With Bake Flow: this frame's liquid velocity (m/s, relative to the cloth) and
        cloth positions (m), world space, one field per component; else nothing."""
        if not self.flow:
            return []
        vel = np.asarray(self.sim.velocity, dtype=np.float32)
        pos = np.asarray(self._pos, dtype=np.float32)
        return [np.ascontiguousarray(a[:, k]) for a in (vel, pos) for k in range(3)]

    def _spill(self, pos):
        """The initial wetness: what the Spill Group's weights hold at Amount, as a pool or as
        weights × Amount (Spill Shape, `pour`), of the object's liquid, or with a Throw
        object a directed splash of Volume from the group's centre (`splash`); and its
        Splash Speed (outward from the weighted centroid of the wet area)."""
        s = self.obj.madder
        if self.wet0 is None or not self.wet0.any():
            return
        throw = s.splash.throw
        if throw is not None:
            # a directed splash (`splash`): Volume thrown along the Throw object's Z axis from
            # the Spill Group's centre, instead of the weights × Amount
            axis = np.asarray(throw.matrix_world, dtype=np.float64)[:3, 2]
            try:
                laid = splash.lay_out(pos, self.faces, self.sim.vertex_area, pour.centroid(self.wet0, pos), axis,
                                      s.splash.volume * 1e-6, seed=s.splash_seed,
                                      height=s.splash.height * self.unit)
            except splash.SplashError as e:
                raise BakeError(f"'{self.obj.name}': its splash (Throw '{throw.name}'): {e}",
                                object=self.obj.name) from e
            self.sim.add_liquid(splash.densities(laid.mass, self.sim.vertex_area), s.concentration,
                                tuple(s.stain_color))
        elif s.spill_shape == "POOL":
            # laid on the simulated (refined) cloth, its edge free of the cloth's mesh
            self.sim.add_pool(self.wet0, s.amount, s.concentration, tuple(s.stain_color))
        else:
            self.sim.add_liquid(pour.spilled(self.wet0, s.amount), s.concentration, tuple(s.stain_color))
        if s.splash_speed > 0.0:
            self.sim.splash(pour.centroid(self.wet0, pos), s.splash_speed * self.unit, s.splash_seed, self.wet0)

    def _contacts(self, frame, pos, depsgraph=None):
        """Per active source at `frame`: its pour weights on the cloth (1 at contact, fading
        linearly to 0 at its reach) and its origin (the splash centre)."""
        if not self.sources:
            return []
        depsgraph = depsgraph or bpy.context.evaluated_depsgraph_get()
        out = []
        for src in self.sources:
            s = src.madder_source
            if not pour.pours_at(frame, s.use_frame_range, s.frame_start, s.frame_end):
                continue
            src_eval = src.evaluated_get(depsgraph)
            verts, tris = bridge.world_triangles(src_eval)
            if len(tris) == 0:
                continue
            reach = s.distance * self.unit  # metres, like the positions
            d = self.madder.distances_within(pos, verts * np.float32(self.unit), tris, reach)
            weight = pour.falloff(d, reach)
            if weight.any():
                out.append((src, weight, tuple(np.asarray(src_eval.matrix_world.translation) * self.unit)))
        return out

    def _pour(self, contacts, dt):
        """Adds the liquid each source brought during the frame of `dt` s that just ended:
        `flow × dt` per unit area times its weights. The first time a source pours, its
        splash starts from the source's origin."""
        for src, weight, origin in contacts:
            s = src.madder_source
            self.sim.add_liquid(pour.poured(s.amount, dt, weight), s.concentration, tuple(s.color))
            if s.splash_speed > 0.0 and src.name not in self.splashed:
                self.splashed.add(src.name)
                self.sim.splash(origin, s.splash_speed * self.unit, s.splash_seed, weight)

    def _positions(self, frame, depsgraph=None):
        if self.motion is not None:
            local = self.motion.local(frame)
            check_transform(self.obj, frame, self.faces, local, self.motion.matrix)
            return placed(local, self.motion.matrix, self.unit)
        return frame_positions(self.obj, depsgraph or bpy.context.evaluated_depsgraph_get(), self.n_vertices, frame,
                               self.faces, self.unit)

    def _rest(self, depsgraph=None):
        """The rest pose: the mesh's own (undeformed) vertices, placed in world space (in
        metres) by the object's transform at the first frame (or the motion file's
        placement)."""
        co = bridge.rest_positions(self.obj.data).astype(np.float64)
        if self.motion is not None:
            matrix = self.motion.matrix
        else:
            matrix = self.obj.evaluated_get(depsgraph or bpy.context.evaluated_depsgraph_get()).matrix_world
        rest = placed(co, matrix, self.unit)
        bad = placement.first_non_finite(rest)
        if bad is not None:
            raise BakeError(f"'{self.obj.name}': vertex {bad} has a non-finite rest position",
                            object=self.obj.name, vertex=bad)
        return rest


class BakeJob(Stepper):
    """One object's bake, advanced a frame at a time, so that a modal operator can show
    progress and cancel between frames, and a script can simply run it to the end.

    Lifecycle: `BakeJob(scene, obj)` checks the input and prepares the topology and the
    fabric (nothing is written yet); `step()` bakes the next frame and returns False when
    every frame is done; `finish()` moves the new cache over the old one and records it;
    `cancel()` (or any error) discards the new cache, so the previous bake stays. Both
    restore the frame the user was on. Playback is suspended while the job is open.

    The first frame builds the simulator (`madder.Simulator`: rest pose = the mesh's own
    vertices, placed in world space; first pose = the frame's positions), spills the
    initial wetness of the Spill Group (weight × Amount of the object's liquid) and
    starts its splash. Every later frame steps the simulator to the frame's positions,
    then lets each source pour what it brought during that frame (and splash, the first
    time it pours). Each frame's densities go to the cache (`FIELDS`, kg/m²). With Bake
    Flow on, so do the liquid's velocity and the cloth's positions (`FLOW_FIELDS`, m/s and
    m, world space: what the Coherent Structures operator integrates); the cache records
    the frame time either way.

    The simulator runs at the object's Detail (`madder.Simulator(detail=…)`); the cache
    holds its values at the cloth's vertices either way. With Image Sequence on, each
    frame's values on the refined cloth also go to the fine cache (the same fields,
    `sim.n_fine_vertices` values each), written into the staging folder of the images
    (`textures.Staging`); once the last frame is simulated, `step()` goes on a frame at
    a time writing the images from it (`images.SequenceExport`), and `finish()` puts the
    cache, then the fine cache and the image folder in place. So `total` counts every
    frame twice then."""

    def __init__(self, scene, obj, frames=None):
        super().__init__(scene, obj)
        settings = obj.madder
        self.path = stored.target_path(obj)
        self.first, self.last = frames or (scene.frame_start, scene.frame_end)
        if self.last < self.first:
            raise BakeError(f"'{obj.name}': the frame range {self.first}-{self.last} is empty", object=obj.name)
        self.images = self._check_images(settings)  # before anything is written
        try:
            os.makedirs(os.path.dirname(self.path), exist_ok=True)
        except OSError as e:
            raise BakeError(f"'{obj.name}': cannot create the cache folder {os.path.dirname(self.path)}: {e}",
                            object=obj.name, filename=os.path.dirname(self.path)) from e
        if settings.output_vertex_colors or self.images is None:
            # before the frames are evaluated: adding the modifier is an edit of the cloth,
            # which outdates an unbaked cloth cache that the bake then fills again
            carrier.ensure(obj)
        if self.motion is not None:
            outside = self.motion.outside(self.first, self.last)
            if outside:
                self.warnings.append(outside)
        self.frame = None  # last frame baked
        self.frame_before = scene.frame_current
        self.writer = None
        self.fine_writer = self.staging = self.export = None
        self.image_outline = ""  # how Sharp Outline drew the images (SequenceExport's)
        # (positions, contacts) per frame, evaluated once each, one frame early
        self._walk = schedule.Lookahead(self._visit)
        self._evaluating = self.first  # the frame being read, for error messages
        self._suspended = False

    def _check_images(self, settings):
        """With Image Sequence on: `(size, corner UVs, UV map name)`, after checking what
        the images need (a UV map, frames they can be numbered by, a size); else None."""
        obj = self.obj
        if not settings.output_images:
            if not settings.output_vertex_colors:
                raise BakeError(f"'{obj.name}': no output: tick Vertex Colors and/or Image Sequence",
                                object=obj.name)
            return None
        uv = bridge.corner_uvs(obj.data)
        if uv is None:
            if not settings.is_property_set("output_images") and settings.output_vertex_colors:
                # on by default (issue 34): a cloth without a UV map bakes vertex colours only
                self.warnings.append("has no UV map: baked without the Image Sequence (vertex colors only)")
                return None
            raise BakeError(f"'{obj.name}' has no UV map: its Image Sequence needs one to lay out the images "
                            "(add a UV map, or untick Image Sequence)", object=obj.name)
        why = textures.frames_problem(self.first, self.last)
        if why is not None:
            if not settings.is_property_set("output_images") and settings.output_vertex_colors:
                # on by default (issue 34): frames that cannot number images bake vertex colours only
                self.warnings.append(f"{why}: baked without the Image Sequence (vertex colors only)")
                return None
            raise BakeError(f"'{obj.name}': {why}", object=obj.name)
        if settings.image_size == "AUTO":
            size = auto_image_size(obj, uv, self.unit, self.mean_edge / 2**self.detail)
        else:
            try:
                size = textures.check_size(settings.image_size)
            except ExportError as e:
                raise BakeError(f"'{obj.name}': {e}", object=obj.name) from e
        return size, uv, obj.data.uv_layers.active.name

    @property
    def frames(self):
        return self.last - self.first + 1

    @property
    def total(self):
        return self.frames * (2 if self.images else 1)

    @property
    def done(self):
        simulated = 0 if self.frame is None else self.frame - self.first + 1
        return simulated + (self.export.done if self.export is not None else 0)

    @property
    def status(self):
        """What the job is doing, for the progress line."""
        if self.export is not None:
            return f"writing the images ({self.export.done} of {self.export.total} frames done)"
        return f"baking frame {self.frame}"

    def step(self):
        """Bakes the next frame (or, with Image Sequence, writes the next frame's images
        once every frame is simulated); returns False once everything is written."""
        if self.export is not None:
            return self._step_images()
        madder, obj = self.madder, self.obj
        try:
            if self.frame is None:
                handlers.suspend()
                self._suspended = True
                frame = self.first
                self._evaluating = frame
                self._goto(frame)
                self.start(self._positions(frame))
                self.writer = madder.CacheWriter(self.path, self.n_vertices, self.cache_fields, self.first,
                                                 self.frames, self.recorded_frame_time)
                if self.images:
                    self._begin_images()
            else:
                frame = self.frame + 1
                self._evaluating = frame
                pos, contacts, dt = self._walk.take(frame)
                # one frame ahead, so the cloth's acceleration over [frame − 1, frame] is
                # centred (and right at the first frame); every frame is still evaluated
                # once, in order
                after, _, after_dt = self._walk.peek(frame + 1) if frame < self.last else (None, None, None)
                self._evaluating = frame
                self.advance(pos, contacts, dt, after, after_dt)
            self.writer.push_frame(self.frame_fields())
            if self.fine_writer is not None:
                self.fine_writer.push_frame(self._outputs(fine=True))
            self.frame = frame
            if self.images and frame == self.last:
                self._start_export()
        except madder.MadderError as e:
            self.cancel()
            raise BakeError(f"'{obj.name}' at frame {self._evaluating}: {e}",
                            object=obj.name, frame=self._evaluating, vertex=getattr(e, "vertex", None),
                            filename=getattr(e, "filename", None)) from e
        except ExportError as e:
            self.cancel()
            raise BakeError(str(e), object=obj.name, frame=e.frame, filename=e.filename) from e
        except BaseException:
            self.cancel()
            raise
        return self.images is not None or self.frame < self.last

    # -- the image sequence

    def _begin_images(self):
        """The staging folder of the images, and the fine cache in it."""
        fine, folder, _ = stored.image_paths(self.obj, self.path)
        self.staging = textures.Staging(folder)
        self.staging.begin()
        self.fine_staged = os.path.join(self.staging.path, os.path.basename(fine))
        self.fine_writer = self.madder.CacheWriter(self.fine_staged, self.sim.n_fine_vertices, self.fields,
                                                   self.first, self.frames, self.recorded_frame_time)

    def _start_export(self):
        """Every frame is simulated: the fine cache is complete (in the staging folder);
        the images are written from it, a frame per `step()`."""
        self.fine_writer.finish()
        self.fine_writer = None
        size, uv, _ = self.images
        weave = images.weave_detail(self.madder, self.obj, self.faces, self.face_polygon, uv, self.detail, size,
                                    self.unit)
        self.export = images.SequenceExport(self.madder, self.obj, self.fine_staged, self.topology, self.detail,
                                            uv, self.references, size, self.staging.path,
                                            textures.stem(self.path), weave=weave)
        self.image_outline = self.export.outline

    def _step_images(self):
        try:
            return self.export.step()
        except ExportError as e:
            self.cancel()
            raise BakeError(str(e), object=self.obj.name, frame=e.frame, filename=e.filename) from e
        except BaseException:
            self.cancel()
            raise

    def _visit(self, frame):
        """Positions at `frame`, what the sources bring there and how long the step into it
        lasts (`self._walk` calls it once per frame, in order)."""
        self._evaluating = frame
        self._goto(frame)
        pos = self._positions(frame)
        return pos, self._contacts(frame, pos), self.seconds(frame)

    def _goto(self, frame):
        """Moves the scene to `frame` unless nothing needs the scene (motion from a file, no
        sources and the scene's clock): then the bake never evaluates it."""
        if self.motion is None or self.sources or self.clocked:
            self.scene.frame_set(frame)

    def finish(self):
        """Replaces the previous cache with the new one (and, with Image Sequence, the
        fine cache and the image folder: in that order, the cache first since its sync
        is what can fail; the others are renames in the same folder); returns the
        cache's path. Without Image Sequence, an earlier bake's fine cache and images
        are deleted (they no longer match the cache)."""
        obj = self.obj
        if self.images is not None and self.export is not None:
            self.warnings += self.export.warnings()
            self.export.close()
        try:
            self.writer.finish()
            self.writer = None
            fine, _, _ = stored.image_paths(obj, self.path)
            if self.images is not None:
                try:
                    os.replace(self.fine_staged, fine)
                except OSError as e:
                    raise ExportError(f"'{obj.name}': cannot move the fine cache to {fine}: {e.strerror or e}",
                                      object=obj.name, filename=fine) from e
                self.staging.commit()
                self.staging = None
        except self.madder.MadderError as e:
            self.cancel()
            raise BakeError(f"'{obj.name}': {e}", object=obj.name) from e
        except (ExportError, OSError) as e:
            self.cancel()
            raise BakeError(f"'{obj.name}': {e}" if isinstance(e, OSError) else str(e), object=obj.name,
                            filename=getattr(e, "filename", None)) from e
        self._close()
        handlers.forget(self.path)
        handlers.forget(fine)
        s = obj.madder
        s.cache_file = stored.stored_path(self.path)
        s.bake_references = self.references
        s.bake_topology = stored.topology_fingerprint(obj.data)
        s.bake_detail = self.detail
        if self.images is not None:
            size, _, uv_map = self.images
            images.record(obj, self.first, self.last, size, uv_map, self.image_outline)
        else:
            images.forget(obj)
            try:
                textures.remove_outputs(self.path)
            except OSError as e:
                self.warnings.append(f"could not remove the image sequence of an earlier bake: {e}")
        shading.sync_object(obj)
        images.reload(obj)
        # Playback writes mesh attributes from frame_change_pre; during a render from the
        # UI, Blender evaluates the scene in a render thread, and "Lock Interface" is what
        # keeps the two from touching the same data at once (background renders are safe
        # either way: handlers run between frames on the one thread).
        self.scene.render.use_lock_interface = True
        return self.path

    def cancel(self):
        """Discards the new cache, fine cache and images (the previous ones stay) and
        restores the frame."""
        if self.writer is not None:
            self.writer.abort()
            self.writer = None
        if self.fine_writer is not None:
            self.fine_writer.abort()
            self.fine_writer = None
        if self.export is not None:
            self.export.close()
        if self.staging is not None:
            self.staging.discard()
            self.staging = None
        self._close()

    def _close(self):
        if self._suspended:
            handlers.resume()
            self._suspended = False
            if self.scene.frame_current != self.frame_before:
                self.scene.frame_set(self.frame_before)


def simulator_settings(scene, obj, unit=None):
    """Keyword arguments of `madder.Simulator` from the object's settings and the scene's
    gravity (`presets.simulator_keywords`), scaled by `unit` (metres per unit; default the
    scene's Unit Scale) like the positions. The grain (irregularity) is the fabric's
    covering most of the cloth (`fabrics.cloth_grain`; plain cotton where no fabric is
    assigned) unless Grain From is Object; a file saved before Grain From existed that
    set the object's Irregularity keeps it."""
    unit = unit_scale(scene) if unit is None else unit
    return presets.simulator_keywords(obj.madder, scene.gravity, scene.use_gravity, unit, grain=grain_of(obj))


def grain_of(obj):
    """`(irregularity, length mm, seed)` the bake uses for `obj`, or None for the object's own."""
    s = obj.madder
    legacy = not s.is_property_set("grain_from") and s.is_property_set("irregularity") and s.irregularity > 0.0
    if s.grain_from == "OBJECT" or legacy:
        return None
    return fabrics.cloth_grain(obj)


def mean_edge_length(obj, unit):
    """Mean length (m) of the cloth's edges at rest, in world scale (the object's scale
    and the scene's Unit Scale), what Auto Detail refines."""
    mesh = obj.data
    ev = np.empty(2 * len(mesh.edges), dtype=np.int64)
    mesh.edges.foreach_get("vertices", ev)
    if len(ev) == 0:
        raise BakeError(f"'{obj.name}' has no edges", object=obj.name)
    co = bridge.rest_positions(mesh).astype(np.float64)
    co = co @ np.asarray(obj.matrix_world.to_3x3(), dtype=np.float64).T
    ev = ev.reshape(-1, 2)
    return float(np.linalg.norm(co[ev[:, 0]] - co[ev[:, 1]], axis=1).mean()) * unit


def auto_image_size(obj, uv, unit, refined_edge):
    """Image size (px) of Auto: a texel of half the refined mean edge (`presets.auto_image_size`),
    from the cloth's rest area (m²) and the area its faces cover in the UV square."""
    mesh = obj.data
    mesh.calc_loop_triangles()
    tri = np.empty(3 * len(mesh.loop_triangles), dtype=np.int64)
    mesh.loop_triangles.foreach_get("vertices", tri)
    # the rest area in world scale, triangle by triangle: a scale of 0 across a flat
    # cloth (its own z) leaves its area whole
    co = bridge.rest_positions(mesh).astype(np.float64)
    co = co @ np.asarray(obj.matrix_world.to_3x3(), dtype=np.float64).T
    surface = float(textures.triangle_areas(co[tri.reshape(-1, 3)]).sum()) * unit * unit
    uv_area = float(textures.uv_areas(np.asarray(uv, dtype=np.float64).reshape(-1, 3, 2)).sum())
    if uv_area <= 0.0:
        raise BakeError(f"'{obj.name}': its UV map covers no area: the Image Sequence cannot be laid out",
                        object=obj.name)
    if not (surface > 0.0 and refined_edge > 0.0):
        # collapsed by its scale: the frame's transform check names the object and frame
        return textures.SIZES[0]
    return presets.auto_image_size(surface, uv_area, refined_edge, textures.SIZES)


def bake(scene, obj, progress=None, frames=None):
    """Bakes `obj` over the scene's frame range (or `frames=(first, last)`) to the end.
    Returns `(path, warnings)`. `progress(done, total)` is called after every frame."""
    job = BakeJob(scene, obj, frames)
    more = True
    while more:
        more = job.step()
        if progress:
            progress(job.done, job.total)
    return job.finish(), job.warnings


def _conductivity(madder, obj, topology, face_polygon, warnings):
    """Keyword arguments of the simulator: isotropic `diffusion`, or the woven faces of the
    materials' fabrics (then the rest-pose weft is written as `madder_weft` too)."""
    rate = obj.madder.diffusion_rate
    try:
        woven = fabrics.face_conductivity(obj, rate, face_polygon)
    except FabricSettingsError as e:
        raise BakeError(f"'{obj.name}': {e}", object=obj.name, material=e.material) from e
    if woven is None:
        return {"diffusion": rate}
    uv = bridge.corner_uvs(obj.data)
    if uv is None:
        warnings.append("has no UV map to orient its fabrics: baked isotropic (add a UV map for woven spreading)")
        return {"diffusion": rate}
    tensors, angle = woven
    degenerate = bridge.degenerate_uv_faces(uv)
    if degenerate:
        warnings.append(f"{degenerate} faces have degenerate UVs; their weft follows an edge")
    weft = madder.weft_directions(topology, bridge.rest_positions(obj.data), uv, angle)
    bridge.write_face_weft(obj.data, face_polygon, weft)
    return {"face_tensors": tensors, "face_uv": uv, "face_angle": angle}


def _topology(madder, obj, faces, n_vertices, face_polygon, n_polygons):
    try:
        return madder.Topology(faces, n_vertices, face_polygon, n_polygons)
    except madder.MadderError as e:
        raise BakeError(f"'{obj.name}': {e}", object=obj.name) from e


def free(obj):
    """Deletes `obj`'s cache file, its fine cache and image sequences, and its stain
    attributes; its materials' stain shader goes back to the (now absent, so harmless)
    attributes. Returns the paths removed."""
    settings = obj.madder
    path = bpy.path.abspath(settings.cache_file) if settings.cache_file else None
    removed = []
    if path:
        try:
            if os.path.exists(path):
                os.remove(path)
                removed.append(path)
            removed += textures.remove_outputs(path)
        except OSError as e:
            raise BakeError(f"'{obj.name}': cannot remove {e.filename}: {e.strerror or e}", object=obj.name,
                            filename=e.filename) from e
        handlers.forget(path)
    settings.cache_file = ""
    settings.bake_references = (0.0, 0.0, 0.0)
    settings.bake_topology = ""
    settings.bake_detail = 0
    images.forget(obj)
    if obj.type == "MESH":
        shading.sync_object(obj)
        images.remove_images(obj)
    if obj.type == "MESH":
        carrier.remove(obj)
        present = [a for a in (obj.data.attributes.get(name) for name in bridge.ATTRIBUTES) if a is not None]
        for attr in present:
            obj.data.attributes.remove(attr)
        if present:
            obj.data.update()
    return removed
