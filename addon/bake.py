"""Baking a stain: walks the scene's frames, feeds the evaluated positions to the Rust
simulator and streams the densities into the cache file. Errors are `BakeError`s whose
message names the object and frame; the previous cache is kept on any failure."""

import os

import bpy
import numpy as np

from . import bridge, fabrics, handlers, properties

CACHE_EXT = ".madder"
FIELDS, COLOR_FIELDS = bridge.FIELDS, bridge.COLOR_FIELDS


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


def check_object(obj, sources=()):
    if obj is None or obj.type != "MESH":
        kind = "nothing" if obj is None else f"a {obj.type.lower()}"
        name = "" if obj is None else f"'{obj.name}' "
        raise BakeError(f"Madder bakes mesh objects; {name}is {kind}")
    group = obj.madder.source_group
    if not group and not sources:
        raise BakeError(
            f"'{obj.name}': no liquid: choose a Source vertex group, or mark an object as a Madder Source"
        )
    if group and group not in obj.vertex_groups:
        raise BakeError(f"'{obj.name}' has no vertex group '{group}' (the Source)")


def source_objects(scene, obj):
    """The scene's liquid sources (brushes and pours) for cloth `obj`."""
    sources = [o for o in scene.objects if o.madder_source.is_source and o != obj]
    for o in sources:
        if o.type != "MESH":
            raise BakeError(f"'{o.name}' is marked as a Madder Source but is a {o.type.lower()}, not a mesh")
    return sources


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


class MotionFile:
    """Cloth positions from a PC2/MDD file (object space, placed by the object's current
    transform), sampled at scene frames: PC2 sample `k` is at scene frame `start + k·rate`,
    MDD sample `k` at `times[k]` seconds, counted from the bake's first frame. Between
    samples the positions are interpolated linearly; outside the file is an error."""

    def __init__(self, madder, obj, scene, first):
        path = bpy.path.abspath(obj.madder.motion_file)
        try:
            self.cache = madder.PointCache(path)
            self.cache.check_times()
        except madder.MadderError as e:
            raise BakeError(f"'{obj.name}': motion file: {e}") from e
        if self.cache.n_points != len(obj.data.vertices):
            raise BakeError(
                f"'{obj.name}' has {len(obj.data.vertices)} vertices but its motion file {path} has "
                f"{self.cache.n_points} points"
            )
        self.obj, self.path = obj, path
        times = np.asarray(self.cache.frame_times, dtype=np.float64)
        if self.cache.time_unit == "second":  # MDD: seconds from the first frame
            fps = scene.render.fps / scene.render.fps_base
            times = first + (times - times[0]) * fps
        self.frames = times  # scene frame of every sample
        m = np.array(obj.matrix_world, dtype=np.float64)
        self.rotation, self.offset = m[:3, :3].T, m[:3, 3]

    def positions(self, frame):
        f = self.frames
        if not (f[0] - 1e-6 <= frame <= f[-1] + 1e-6):
            raise BakeError(
                f"'{self.obj.name}': frame {frame} is outside its motion file {self.path} "
                f"(frames {f[0]:g}–{f[-1]:g})"
            )
        k = int(np.clip(np.searchsorted(f, frame, side="right") - 1, 0, len(f) - 1))
        try:
            co = self.cache.read_frame(k).astype(np.float64)
            if k + 1 < len(f) and frame > f[k]:
                t = (frame - f[k]) / (f[k + 1] - f[k])
                co = (1 - t) * co + t * self.cache.read_frame(k + 1)
        except Exception as e:
            raise BakeError(f"'{self.obj.name}' at frame {frame}: {e}") from e
        return (co @ self.rotation + self.offset).astype(np.float32)


class BakeJob:
    """One object's bake, advanced a frame at a time, so that a modal operator can show
    progress and cancel between frames, and a script can simply run it to the end.

    Lifecycle: `BakeJob(scene, obj)` checks the input and prepares the topology and the
    fabric (nothing is written yet); `step()` bakes the next frame and returns False when
    every frame is done; `finish()` moves the new cache over the old one and records it;
    `cancel()` (or any error) discards the new cache, so the previous bake stays. Both
    restore the frame the user was on. Playback is suspended while the job is open.

    The first frame builds the simulator (`madder.Simulator`: rest pose = the mesh's own
    vertices, placed in world space; first pose = the frame's positions), spills the
    initial wetness of the Source group (weight × Amount of the object's liquid) and
    starts its splash. Every later frame steps the simulator to the frame's positions,
    then lets each source pour what it brought during that frame (and splash, the first
    time it pours). Each frame's densities go to the cache (`FIELDS`, kg/m²)."""

    def __init__(self, scene, obj, frames=None):
        self.madder = core()
        self.sources = source_objects(scene, obj) if obj is not None else []
        check_object(obj, self.sources)
        self.scene, self.obj = scene, obj
        self.path = cache_path(obj)
        try:
            os.makedirs(os.path.dirname(self.path), exist_ok=True)
        except OSError as e:
            raise BakeError(f"'{obj.name}': cannot create the cache folder {os.path.dirname(self.path)}: {e}") from e
        self.first, self.last = frames or (scene.frame_start, scene.frame_end)
        if self.last < self.first:
            raise BakeError(f"'{obj.name}': the frame range {self.first}-{self.last} is empty")
        self.dt = scene.render.fps_base / scene.render.fps
        mesh = obj.data
        faces, face_polygon, n_polygons = bridge.topology_arrays(mesh)
        self.n_vertices = len(mesh.vertices)
        if len(faces) == 0:
            raise BakeError(f"'{obj.name}' has no faces")
        settings = obj.madder
        self.wet0 = bridge.vertex_group_weights(obj, settings.source_group) if settings.source_group else None
        # with sources, colours can differ: track them (three more fields)
        self.fields = FIELDS + (COLOR_FIELDS if self.sources else [])
        self.topology = _topology(self.madder, obj, faces, self.n_vertices, face_polygon, n_polygons)
        self.warnings = []
        n_nonmanifold = len(self.topology.non_manifold_edges())
        if n_nonmanifold:
            self.warnings.append(f"{n_nonmanifold} non-manifold edges (shared by 3+ faces)")
        self.conductivity = _conductivity(self.madder, obj, self.topology, face_polygon, self.warnings)
        self.references = properties.references(settings, [o.madder_source for o in self.sources], spill=self.wet0 is not None)
        if self.references[0] == 0.0:
            self.warnings.append("its liquid has no solute (concentration 0): it wets the cloth but leaves no stain")
        self.motion = MotionFile(self.madder, obj, scene, self.first) if settings.motion_file else None
        self.frame = None  # last frame baked
        self.frame_before = scene.frame_current
        self.writer = self.sim = None
        self.splashed = set()  # sources whose splash is done
        self._ahead = None  # (frame, positions, contacts) evaluated one frame early
        self._evaluating = self.first  # the frame being read, for error messages
        self._suspended = False

    @property
    def total(self):
        return self.last - self.first + 1

    @property
    def done(self):
        return 0 if self.frame is None else self.frame - self.first + 1

    def step(self):
        """Bakes the next frame; returns False once the last frame is in."""
        madder, obj = self.madder, self.obj
        try:
            if self.frame is None:
                handlers.suspend()
                self._suspended = True
                frame = self.first
                self._evaluating = frame
                self._goto(frame)
                pos = self._positions(frame)
                self.sim = madder.Simulator(self.topology, self._rest(), pos, **simulator_settings(self.scene, obj),
                                            **self.conductivity)
                self._spill(pos)
                self.writer = madder.CacheWriter(self.path, self.n_vertices, self.fields, self.first, self.total)
            else:
                frame = self.frame + 1
                pos, contacts = self._visit(frame)
                # one frame ahead, so the cloth's acceleration over [frame − 1, frame] is
                # centred (and right at the first frame); every frame is still evaluated
                # once, in order
                after = None
                if frame < self.last:
                    self._ahead = (frame + 1, *self._visit(frame + 1))
                    after = self._ahead[1]
                self._evaluating = frame
                self.sim.step(pos, self.dt, after=after)
                self._pour(contacts)
            self.writer.push_frame(self._outputs())
            self.frame = frame
        except madder.MadderError as e:
            self.cancel()
            raise BakeError(f"'{obj.name}' at frame {self._evaluating}: {e}") from e
        except BaseException:
            self.cancel()
            raise
        return self.frame < self.last

    def _outputs(self):
        """This frame's cache fields: total solute, liquid and deposit densities (kg/m²),
        and the solute's colour when sources may mix colours."""
        sim = self.sim
        out = [np.ascontiguousarray(sim.stain()[:, 3]), sim.wetness(), sim.deposit()]
        if self.sources:
            out += list(np.ascontiguousarray(sim.solute_color().T))
        return out

    def _spill(self, pos):
        """The initial wetness: the Source group's weights × Amount of the object's liquid,
        and its splash (outward from the weighted centroid of the wet area)."""
        s = self.obj.madder
        if self.wet0 is None or not self.wet0.any():
            return
        self.sim.add_liquid((self.wet0 * s.amount).astype(np.float32), s.concentration, tuple(s.stain_color))
        if s.splash_speed > 0.0:
            w = self.wet0.astype(np.float64)
            centre = tuple((w @ pos.astype(np.float64)) / w.sum())
            self.sim.splash(centre, s.splash_speed, s.splash_seed, self.wet0)

    def _visit(self, frame):
        """Positions at `frame` and what the sources bring there (from the lookahead when
        the previous step already visited it)."""
        self._evaluating = frame
        if self._ahead is not None and self._ahead[0] == frame:
            _, pos, contacts = self._ahead
            self._ahead = None
            return pos, contacts
        self._goto(frame)
        pos = self._positions(frame)
        return pos, self._contacts(frame, pos)

    def _contacts(self, frame, pos):
        """Per active source at `frame`: its pour weights on the cloth (1 at contact, fading
        linearly to 0 at its reach) and its origin (the splash centre)."""
        if not self.sources:
            return []
        depsgraph = bpy.context.evaluated_depsgraph_get()
        out = []
        for src in self.sources:
            s = src.madder_source
            if s.use_frame_range and not (s.frame_start <= frame <= s.frame_end):
                continue
            src_eval = src.evaluated_get(depsgraph)
            verts, tris = bridge.world_triangles(src_eval)
            if len(tris) == 0:
                continue
            d = self.madder.distances_within(pos, verts, tris, s.distance)
            weight = np.clip(1.0 - d / s.distance, 0.0, 1.0).astype(np.float32)  # inf → 0
            if weight.any():
                out.append((src, weight, tuple(src_eval.matrix_world.translation)))
        return out

    def _pour(self, contacts):
        """Adds the liquid each source brought during the frame that just ended: `flow × dt`
        per unit area times its weights. The first time a source pours, its splash starts
        from the source's origin."""
        for src, weight, origin in contacts:
            s = src.madder_source
            self.sim.add_liquid((s.amount * self.dt * weight).astype(np.float32), s.concentration, tuple(s.color))
            if s.splash_speed > 0.0 and src.name not in self.splashed:
                self.splashed.add(src.name)
                self.sim.splash(origin, s.splash_speed, s.splash_seed, weight)

    def _goto(self, frame):
        """Moves the scene to `frame` unless nothing needs the scene (motion from a file and
        no sources): then the bake never evaluates it."""
        if self.motion is None or self.sources:
            self.scene.frame_set(frame)

    def _positions(self, frame):
        if self.motion is not None:
            return self.motion.positions(frame)
        return frame_positions(self.obj, bpy.context.evaluated_depsgraph_get(), self.n_vertices, frame)

    def _rest(self):
        """The rest pose: the mesh's own (undeformed) vertices, placed in world space by the
        object's transform at the first frame (or the motion file's placement)."""
        co = bridge.rest_positions(self.obj.data).astype(np.float64)
        if self.motion is not None:
            rotation, offset = self.motion.rotation, self.motion.offset
        else:
            m = np.array(self.obj.evaluated_get(bpy.context.evaluated_depsgraph_get()).matrix_world, dtype=np.float64)
            rotation, offset = m[:3, :3].T, m[:3, 3]
        rest = (co @ rotation + offset).astype(np.float32)
        bad = np.flatnonzero(~np.isfinite(rest).all(axis=1))
        if bad.size:
            raise BakeError(f"'{self.obj.name}': vertex {bad[0]} has a non-finite rest position")
        return rest

    def finish(self):
        """Replaces the previous cache with the new one; returns its path."""
        try:
            self.writer.finish()
        except self.madder.MadderError as e:
            self.cancel()
            raise BakeError(f"'{self.obj.name}': {e}") from e
        self.writer = None
        self._close()
        self.obj.madder.cache_file = stored_path(self.path)
        self.obj.madder.bake_references = self.references
        self.obj.madder.bake_topology = handlers.topology_fingerprint(self.obj.data)
        # Playback writes mesh attributes from frame_change_pre; during a render from the
        # UI, Blender evaluates the scene in a render thread, and "Lock Interface" is what
        # keeps the two from touching the same data at once (background renders are safe
        # either way: handlers run between frames on the one thread).
        self.scene.render.use_lock_interface = True
        return self.path

    def cancel(self):
        """Discards the new cache (the previous one stays) and restores the frame."""
        if self.writer is not None:
            self.writer.abort()
            self.writer = None
        self._close()

    def _close(self):
        if self._suspended:
            handlers.resume()
            self._suspended = False
            if self.scene.frame_current != self.frame_before:
                self.scene.frame_set(self.frame_before)


def simulator_settings(scene, obj):
    """Keyword arguments of `madder.Simulator` from the object's settings (SI units) and
    the scene's gravity (off when either the scene's or the object's Gravity is off)."""
    s = obj.madder
    return dict(
        color=tuple(s.stain_color),
        gravity=tuple(scene.gravity),
        viscosity=s.viscosity,
        friction=s.friction,
        absorption=s.absorption,
        saturation=s.saturation,
        adsorption=s.adsorption,
        capacity=s.capacity,
        evaporation=s.evaporation,
        evaporation_boundary=s.evaporation_boundary,
        substeps=s.substeps,
        use_gravity=bool(s.use_gravity and scene.use_gravity),
        use_rectilinear=s.use_rectilinear,
        use_coriolis=s.use_coriolis,
        momentum_advection=s.momentum_advection,
    )


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
    except ValueError as e:
        raise BakeError(f"'{obj.name}': {e}") from e
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
        raise BakeError(f"'{obj.name}': {e}") from e


def free(obj):
    """Deletes `obj`'s cache file and its stain attributes. Returns the path removed (or None)."""
    settings = obj.madder
    path = bpy.path.abspath(settings.cache_file) if settings.cache_file else None
    if path and os.path.exists(path):
        os.remove(path)
    settings.cache_file = ""
    settings.bake_references = (0.0, 0.0, 0.0)
    settings.bake_topology = ""
    if obj.type == "MESH":
        for name in bridge.ATTRIBUTES:
            attr = obj.data.attributes.get(name)
            if attr is not None:
                obj.data.attributes.remove(attr)
        obj.data.update()
    return path
