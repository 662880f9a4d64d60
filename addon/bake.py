"""Baking a stain: walks the scene's frames, feeds the evaluated positions to the Rust
simulator and streams the densities into the cache file. Errors are `BakeError`s whose
message names the object and frame; the previous cache is kept on any failure."""

import os
import re

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
    if obj is None:
        raise BakeError("no active object: select the cloth (a mesh object) to bake, or use Bake All Stains")
    if obj.type != "MESH":
        raise BakeError(f"Madder bakes mesh objects; '{obj.name}' is a {obj.type.lower()}")
    group = obj.madder.source_group
    if not group and not sources:
        raise BakeError(
            f"'{obj.name}': no liquid: choose a Spill Group (vertex group), or mark an object as a Madder Source"
        )
    if group and group not in obj.vertex_groups:
        raise BakeError(f"'{obj.name}' has no vertex group '{group}' (its Spill Group)")


def source_objects(scene, obj):
    """The scene's liquid sources (brushes and pours) for cloth `obj`."""
    sources = [o for o in scene.objects if o.madder_source.is_source and o != obj]
    for o in sources:
        if o.type != "MESH":
            raise BakeError(f"'{o.name}' is marked as a Madder Source but is a {o.type.lower()}, not a mesh")
    return sources


def unit_scale(scene):
    """Metres per Blender unit: the scene's Unit Scale, as Blender applies it to every
    length, velocity and acceleration it shows (not at all with the unit system None)."""
    units = scene.unit_settings
    return float(units.scale_length) if units.system != "NONE" else 1.0


def placed(local, matrix, unit):
    """Object-space positions `local` (N, 3) through the 4×4 `matrix`, in metres, float32."""
    m = np.asarray(matrix, dtype=np.float64)
    return ((np.asarray(local, dtype=np.float64) @ m[:3, :3].T + m[:3, 3]) * unit).astype(np.float32)


def check_transform(obj, frame, faces, local, matrix):
    """Refuses an object transform that collapses the cloth at `frame`: a scale of 0 (or
    nearly 0) on the axes the cloth spans leaves it no area, and the simulation nothing
    to work on. Compares the world-space area of the triangles `faces` with their
    object-space area times the transform's largest stretch squared (1 for any rotation
    and uniform scale; 0 when the scale flattens the cloth to a line or a point) and
    refuses a ratio of a millionth or less."""
    full = np.asarray(matrix, dtype=np.float64)
    m = full[:3, :3]
    if not np.isfinite(full).all():
        raise BakeError(f"'{obj.name}' at frame {frame}: its object transform is not finite")
    stretch = np.linalg.svd(m, compute_uv=False)
    if stretch[-1] > 1e-6 * stretch[0]:  # invertible: no area can vanish (the usual case, O(1))
        return
    a, b, c = (local[faces[:, k]] for k in range(3))
    n = np.cross(b - a, c - a)  # twice the object-space area vectors
    area_local = np.linalg.norm(n, axis=1).sum()
    if not area_local > 0.0:  # no area even in object space: not the transform's doing
        return
    # the area vectors map by the cofactor matrix det(M)·M^-T, computed without inverting
    cof = np.cross(m[:, [1, 2, 0]].T, m[:, [2, 0, 1]].T)
    area_world = np.linalg.norm(n @ cof, axis=1).sum()
    if not area_world > 1e-6 * stretch[0] ** 2 * area_local:
        scale = ", ".join(f"{x:g}" for x in np.linalg.norm(m, axis=0))
        raise BakeError(
            f"'{obj.name}' at frame {frame}: its object scale ({scale}) collapses the cloth to no area; "
            "give the object a non-zero scale on every axis the cloth spans (check its scale animation)"
        )


def frame_positions(obj, depsgraph, n_vertices, frame, faces, unit):
    """World positions of the evaluated `obj` at `frame`, in metres, (N, 3) float32."""
    obj_eval = obj.evaluated_get(depsgraph)
    n = len(obj_eval.data.vertices)
    if n != n_vertices:
        raise BakeError(
            f"'{obj.name}' has {n} vertices at frame {frame} but {n_vertices} in its mesh: "
            "the deformed cloth must keep its topology (move generating modifiers such as "
            "Subdivision below the cloth and disable them for the bake)"
        )
    local = bridge.rest_positions(obj_eval.data).astype(np.float64)
    bad = np.flatnonzero(~np.isfinite(local).all(axis=1))
    if bad.size:
        raise BakeError(f"'{obj.name}': vertex {bad[0]} has a non-finite position at frame {frame}")
    check_transform(obj, frame, faces, local, obj_eval.matrix_world)
    return placed(local, obj_eval.matrix_world, unit)


class MotionFile:
    """Cloth positions from a PC2/MDD file (object space, placed by the object's current
    transform), sampled at scene frames exactly as Blender's Mesh Cache modifier shows the
    file in its Time Mode *Frame* and Play Mode *Scene*: scene frame `f` reads sample
    `f · frame_scale − frame_start` (0-based), whatever start, rate or times the file's
    header gives. `frame_start` and `frame_scale` are those of the object's Mesh Cache
    modifier that reads the same file, or 0 and 1 (the modifier's defaults) without one.
    Between samples the positions are interpolated linearly, as the modifier does; before
    the first sample and after the last the cloth holds that sample, as the modifier shows
    it (the bake warns)."""

    def __init__(self, madder, obj):
        path = bpy.path.abspath(obj.madder.motion_file)
        try:
            self.cache = madder.PointCache(path)
        except madder.MadderError as e:
            raise BakeError(f"'{obj.name}': motion file: {_sample_message(e)}") from e
        if self.cache.n_points != len(obj.data.vertices):
            raise BakeError(
                f"'{obj.name}' has {len(obj.data.vertices)} vertices but its motion file {path} has "
                f"{self.cache.n_points} points"
            )
        self.obj, self.path = obj, path
        self.offset, self.scale = 0.0, 1.0
        for m in obj.modifiers:
            if m.type != "MESH_CACHE" or not m.filepath or os.path.normpath(bpy.path.abspath(m.filepath)) != os.path.normpath(path):
                continue
            if m.time_mode != "FRAME" or m.play_mode != "SCENE":
                raise BakeError(
                    f"'{obj.name}': its Mesh Cache modifier '{m.name}' reads the motion file with Time Mode "
                    f"'{m.time_mode.title()}' and Play Mode '{m.play_mode.title()}'; Madder reads motion files "
                    "as the modifier does in Time Mode Frame, Play Mode Scene: set those"
                )
            others = {
                "Forward/Up Axis": (m.forward_axis, m.up_axis) != ("POS_Y", "POS_Z"),
                "Flip Axis": any(m.flip_axis),  # a set of axes before 5.0, three booleans since
                "Influence": m.factor != 1.0 or bool(m.vertex_group),
                "Deform Mode": m.deform_mode != "OVERWRITE",
                "Interpolation": m.interpolation != "LINEAR",
            }
            changed = [k for k, v in others.items() if v]
            if changed:
                raise BakeError(
                    f"'{obj.name}': its Mesh Cache modifier '{m.name}' changes the file's positions "
                    f"({', '.join(changed)}), which Madder's motion file reader does not do: leave those "
                    "at their defaults, or clear Motion File to bake what the modifier stack shows"
                )
            self.offset, self.scale = m.frame_start, m.frame_scale
            break
        self.matrix = np.array(obj.matrix_world, dtype=np.float64)

    def sample(self, frame):
        """The (fractional) sample the Mesh Cache modifier shows at scene `frame`."""
        return frame * self.scale - self.offset

    def outside(self, first, last):
        """A warning when frames `first`–`last` read past the file's samples (or None)."""
        n = self.cache.n_frames
        out = [f for f in range(first, last + 1) if not (-1e-6 <= self.sample(f) <= n - 1 + 1e-6)]
        if not out:
            return None
        return (
            f"{len(out)} frames ({out[0]}…{out[-1]}) read past the {n} samples of its motion file "
            f"{os.path.basename(self.path)}: the cloth holds its first or last sample there, as the "
            "Mesh Cache modifier shows it"
        )

    def local(self, frame):
        """Object-space positions at scene `frame`, (N, 3) float64."""
        t, last = self.sample(frame), self.cache.n_frames - 1
        t = min(max(t, 0.0), float(last))  # the modifier holds the first or last sample
        k = int(min(np.floor(t + 1e-6), last))
        try:
            co = self.cache.read_frame(k).astype(np.float64)
            if k < last and t - k > 1e-6:
                co += (t - k) * (self.cache.read_frame(k + 1) - co)
        except Exception as e:
            raise BakeError(f"'{self.obj.name}' at frame {frame}: {_sample_message(e)}") from e
        return co


def _sample_message(error):
    """A point-cache error read while baking, with its file frame called the *sample*, so
    that the bake's message names one frame: the scene's."""
    return re.sub(r"\bframe (\d+)", r"sample \1", str(error))


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
    initial wetness of the Spill Group (weight × Amount of the object's liquid) and
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
        self.unit = unit_scale(scene)
        self.faces = faces.astype(np.int64)
        self.motion = MotionFile(self.madder, obj) if settings.motion_file else None
        if self.motion is not None:
            outside = self.motion.outside(self.first, self.last)
            if outside:
                self.warnings.append(outside)
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
                self.sim = madder.Simulator(self.topology, self._rest(), pos,
                                            **simulator_settings(self.scene, obj, self.unit),
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
        """The initial wetness: the Spill Group's weights × Amount of the object's liquid,
        and its splash (outward from the weighted centroid of the wet area)."""
        s = self.obj.madder
        if self.wet0 is None or not self.wet0.any():
            return
        self.sim.add_liquid((self.wet0 * s.amount).astype(np.float32), s.concentration, tuple(s.stain_color))
        if s.splash_speed > 0.0:
            w = self.wet0.astype(np.float64)
            centre = tuple((w @ pos.astype(np.float64)) / w.sum())
            self.sim.splash(centre, s.splash_speed * self.unit, s.splash_seed, self.wet0)

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
            reach = s.distance * self.unit  # metres, like the positions
            d = self.madder.distances_within(pos, verts * np.float32(self.unit), tris, reach)
            weight = np.clip(1.0 - d / reach, 0.0, 1.0).astype(np.float32)  # inf → 0
            if weight.any():
                out.append((src, weight, tuple(np.asarray(src_eval.matrix_world.translation) * self.unit)))
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
                self.sim.splash(origin, s.splash_speed * self.unit, s.splash_seed, weight)

    def _goto(self, frame):
        """Moves the scene to `frame` unless nothing needs the scene (motion from a file and
        no sources): then the bake never evaluates it."""
        if self.motion is None or self.sources:
            self.scene.frame_set(frame)

    def _positions(self, frame):
        if self.motion is not None:
            local = self.motion.local(frame)
            check_transform(self.obj, frame, self.faces, local, self.motion.matrix)
            return placed(local, self.motion.matrix, self.unit)
        return frame_positions(self.obj, bpy.context.evaluated_depsgraph_get(), self.n_vertices, frame,
                               self.faces, self.unit)

    def _rest(self):
        """The rest pose: the mesh's own (undeformed) vertices, placed in world space (in
        metres) by the object's transform at the first frame (or the motion file's
        placement)."""
        co = bridge.rest_positions(self.obj.data).astype(np.float64)
        if self.motion is not None:
            matrix = self.motion.matrix
        else:
            matrix = self.obj.evaluated_get(bpy.context.evaluated_depsgraph_get()).matrix_world
        rest = placed(co, matrix, self.unit)
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


def simulator_settings(scene, obj, unit=None):
    """Keyword arguments of `madder.Simulator` from the object's settings (SI units) and
    the scene's gravity (off when either the scene's or the object's Gravity is off),
    which Blender stores in scene units per s², so it is scaled by `unit` (metres per
    unit; default the scene's Unit Scale) like the positions."""
    s = obj.madder
    unit = unit_scale(scene) if unit is None else unit
    return dict(
        color=tuple(s.stain_color),
        gravity=tuple(g * unit for g in scene.gravity),
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
