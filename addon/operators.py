"""Madder's operators. Thin: they pick the objects, drive `bake.BakeJob`s, and report.

Baking runs modal when invoked from the UI (a timer advances one frame per tick, the
progress bar and status text show how far it is, Esc cancels and keeps the previous
bake) and blocking when executed from a script or in background mode."""

import bpy
from bpy.props import BoolProperty, StringProperty

from . import bake, bridge, codec, codec_jobs, handlers, preview, reexport, stored, structures
from .errors import ExportError, LcsError, MotionCodecError, RelocateError


def _undo_during_job(op, event):
    """True (and a warning) for an undo or redo shortcut while a modal job runs: undo
    reloads the file's data under the job, whose objects then raise ReferenceError
    mid-write (other add-ons' modal operators block it the same way). The job's own
    changes are one undo step once it ends."""
    if event.type == "Z" and event.value == "PRESS" and (event.ctrl or event.oskey):
        op.report({"WARNING"}, "Madder: undo waits until the job ends (Esc cancels it)")
        return True
    return False


def _targets(context, all_objects):
    if all_objects:
        objs = [o for o in context.scene.objects if o.type == "MESH" and o.madder.enabled]
        if not objs:
            raise bake.BakeError("no object in the scene has Madder Stain enabled")
        return objs
    return [context.object]


class MADDER_OT_bake(bpy.types.Operator):
    """Simulate the stain over the scene's frame range and write it to the cache (Esc cancels)"""

    bl_idname = "madder.bake"
    bl_label = "Bake Stain"
    bl_options = {"REGISTER", "UNDO"}

    all_objects: BoolProperty(
        name="All Objects",
        description="Bake every object of the scene that has Madder Stain enabled",
        default=False,
    )

    @classmethod
    def poll(cls, context):
        return context.scene is not None

    # -- blocking: scripts, background mode, the command line
    def execute(self, context):
        try:
            for obj in _targets(context, self.all_objects):
                path, warnings = bake.bake(context.scene, obj)
                self._done(context, obj, path, warnings)
        except bake.BakeError as e:
            self.report({"ERROR"}, str(e))
            return {"CANCELLED"}
        return {"FINISHED"}

    # -- modal: the UI
    def invoke(self, context, event):
        if context.window_manager is None or not context.window:
            return self.execute(context)
        try:
            self._queue = _targets(context, self.all_objects)
        except bake.BakeError as e:
            self.report({"ERROR"}, str(e))
            return {"CANCELLED"}
        self._job = None
        self._total = len(self._queue)
        wm = context.window_manager
        wm.progress_begin(0, 100)
        self._timer = wm.event_timer_add(0.0, window=context.window)
        wm.modal_handler_add(self)
        return {"RUNNING_MODAL"}

    def modal(self, context, event):
        if event.type == "ESC":
            return self._stop(context, cancelled=True)
        if _undo_during_job(self, event):
            return {"RUNNING_MODAL"}
        if event.type != "TIMER":
            return {"PASS_THROUGH"}
        try:
            if self._job is None:
                self._job = bake.BakeJob(context.scene, self._queue[0])
            if not self._job.step():
                job, self._job = self._job, None
                self._queue.pop(0)
                self._done(context, job.obj, job.finish(), job.warnings)
                if not self._queue:
                    return self._stop(context)
        except bake.BakeError as e:
            self.report({"ERROR"}, str(e))
            self._job = None
            return self._stop(context, cancelled=True)
        job = self._job
        if job is not None:
            finished = self._total - len(self._queue)
            pct = 100 * (finished + job.done / job.total) / self._total
            context.window_manager.progress_update(int(pct))
            context.workspace.status_text_set(
                f"Madder: '{job.obj.name}': {job.status} ({job.done}/{job.total}) — Esc to cancel"
            )
        return {"RUNNING_MODAL"}

    def _stop(self, context, cancelled=False):
        if self._job is not None:
            self._job.cancel()
            self.report({"WARNING"}, f"Madder: bake of '{self._job.obj.name}' cancelled; the previous bake is kept")
        wm = context.window_manager
        wm.event_timer_remove(self._timer)
        wm.progress_end()
        context.workspace.status_text_set(None)
        return {"CANCELLED"} if cancelled else {"FINISHED"}

    def _done(self, context, obj, path, warnings):
        obj.madder.enabled = True
        handlers.apply_frame(obj, context.scene.frame_current)
        for w in warnings:
            self.report({"WARNING"}, f"Madder: '{obj.name}': {w}")
        also = ""
        if obj.madder.image_baked:
            also = f", its images to {stored.image_paths(obj, path)[1]}"
        self.report({"INFO"}, f"Madder: baked '{obj.name}' to {path}{also}")


class MADDER_OT_free_bake(bpy.types.Operator):
    """Delete the baked stain of the active object: its cache, fine cache and image sequences"""

    bl_idname = "madder.free_bake"
    bl_label = "Free Bake"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        return context.object is not None and bool(context.object.madder.cache_file)

    def execute(self, context):
        try:
            removed = bake.free(context.object)
        except bake.BakeError as e:
            self.report({"ERROR"}, f"Madder: {e}")
            return {"CANCELLED"}
        self.report({"INFO"}, f"Madder: removed {', '.join(removed)}" if removed else "Madder: nothing to remove")
        return {"FINISHED"}


class MADDER_OT_export_textures(bpy.types.Operator):
    bl_idname = "madder.export_textures"
    bl_label = "Re-export Textures"
    bl_description = (
        "Write the active object's image sequence again from its fine cache, at the current Size, "
        "without baking (Esc cancels and keeps the previous images)"
    )
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        obj = context.object
        return obj is not None and obj.type == "MESH" and bool(obj.madder.cache_file) and obj.madder.output_images

    def execute(self, context):
        try:
            job = reexport.ReexportJob(context.scene, context.object)
            while job.step():
                pass
            self._done(job, job.finish())
        except ExportError as e:
            self.report({"ERROR"}, f"Madder: {e}")
            return {"CANCELLED"}
        return {"FINISHED"}

    def invoke(self, context, event):
        if context.window_manager is None or not context.window:
            return self.execute(context)
        try:
            self._job = reexport.ReexportJob(context.scene, context.object)
        except ExportError as e:
            self.report({"ERROR"}, f"Madder: {e}")
            return {"CANCELLED"}
        wm = context.window_manager
        wm.progress_begin(0, 100)
        self._timer = wm.event_timer_add(0.0, window=context.window)
        wm.modal_handler_add(self)
        return {"RUNNING_MODAL"}

    def modal(self, context, event):
        if event.type == "ESC":
            self._job.cancel()
            self.report({"WARNING"}, f"Madder: re-export of '{self._job.obj.name}' cancelled; the previous "
                        "images are kept")
            return self._stop(context, {"CANCELLED"})
        if _undo_during_job(self, event):
            return {"RUNNING_MODAL"}
        if event.type != "TIMER":
            return {"PASS_THROUGH"}
        job = self._job
        try:
            if not job.step():
                self._done(job, job.finish())
                return self._stop(context, {"FINISHED"})
        except ExportError as e:
            self.report({"ERROR"}, f"Madder: {e}")
            return self._stop(context, {"CANCELLED"})
        context.window_manager.progress_update(int(100 * job.done / job.total))
        context.workspace.status_text_set(
            f"Madder: '{job.obj.name}': writing the images ({job.done}/{job.total} frames) — Esc to cancel")
        return {"RUNNING_MODAL"}

    def _stop(self, context, result):
        wm = context.window_manager
        wm.event_timer_remove(self._timer)
        wm.progress_end()
        context.workspace.status_text_set(None)
        return result

    def _done(self, job, folder):
        for w in job.warnings:
            self.report({"WARNING"}, f"Madder: '{job.obj.name}': {w}")
        self.report({"INFO"}, f"Madder: wrote the images of '{job.obj.name}' at {job.size} px to {folder}")


class MADDER_OT_relocate_cache(bpy.types.Operator):
    """Point the active object at its stain cache after the cache or the .blend moved"""

    bl_idname = "madder.relocate_cache"
    bl_label = "Relocate Cache"
    bl_options = {"REGISTER", "UNDO"}

    filepath: StringProperty(
        name="Cache File",
        description="The .madder cache file this object's stain was baked to, where it is now",
        subtype="FILE_PATH",
    )
    filter_glob: StringProperty(
        default="*" + stored.CACHE_EXT,
        description="Which files the file browser lists: Madder caches",
        options={"HIDDEN"},
    )

    @classmethod
    def poll(cls, context):
        return context.object is not None and context.object.type == "MESH"

    def invoke(self, context, event):
        if not self.filepath:
            self.filepath = stored.played_path(context.object) or bpy.path.abspath(context.object.madder.cache_dir)
        context.window_manager.fileselect_add(self)
        return {"RUNNING_MODAL"}

    def execute(self, context):
        obj = context.object
        try:
            left = handlers.relocate(obj, self.filepath)
        except RelocateError as e:
            self.report({"ERROR"}, f"Madder: {e}")
            return {"CANCELLED"}
        if left:
            self.report({"WARNING"}, f"Madder: '{obj.name}': {left}")
        self.report({"INFO"}, f"Madder: '{obj.name}' plays {obj.madder.cache_file}")
        return {"FINISHED"}


class MADDER_OT_coherent_structures(bpy.types.Operator):
    """FTLE of the baked liquid flow from the chosen frame over the span (the madder_ftle attribute)
    and its ridges as curves that follow the cloth (needs a bake with Bake Flow)"""

    bl_idname = "madder.coherent_structures"
    bl_label = "Compute Coherent Structures"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        return context.object is not None

    def execute(self, context):
        obj = context.object
        wm = context.window_manager
        shown = []

        def progress(done, total):
            if not shown:
                wm.progress_begin(0, total)
                shown.append(True)
            wm.progress_update(done)

        # everything is computed before the scene changes: an error leaves it as it was
        try:
            result = structures.compute(bake.core(), obj, progress)
        except (LcsError, bake.BakeError) as e:
            self.report({"ERROR"}, f"Madder: {e}")
            return {"CANCELLED"}
        finally:
            if shown:
                wm.progress_end()
        structures.write_ftle(obj, result.sigma)
        ridge = structures.add_ridges(context.scene, obj, result.ridges, bake.unit_scale(context.scene))
        s = obj.madder.lcs
        found = f"{len(result.ridges['edges'])} ridge edges in '{ridge.name}'" if ridge else "no ridges"
        self.report({"INFO"}, f"Madder: '{obj.name}' FTLE at frame {s.frame} over {s.span} frames "
                              f"{s.direction.lower()}: {result.sigma.min():.3g}–{result.sigma.max():.3g} 1/s "
                              f"(attribute {bridge.FTLE_ATTR}), {found}")
        return {"FINISHED"}


class MADDER_OT_bake_from_preview(bpy.types.Operator):
    """Write the frames Live simulated (from the start frame) to the cache, as Bake would"""

    bl_idname = "madder.bake_from_preview"
    bl_label = "Bake from Preview"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        return context.object is not None and context.object.type == "MESH"

    def execute(self, context):
        try:
            path = preview.bake_from_preview(context.scene, context.object)
        except bake.BakeError as e:
            self.report({"ERROR"}, f"Madder: {e}")
            return {"CANCELLED"}
        self.report({"INFO"}, f"Madder: baked the preview to {path}")
        return {"FINISHED"}


class _StepwiseOperator:
    """An operator driving a stepwise job (`step()` → more to do, `finish()`, `cancel()`,
    `done`/`total`/`status`, `obj`): blocking from a script or in background mode; modal
    from the UI, one step per timer tick with the progress bar and status text, Esc
    cancelling. Subclasses give `_job(context)`, `_done(job, result)` and `_what`."""

    _what = ""

    def execute(self, context):
        try:
            job = self._job(context)
            try:
                while job.step():
                    pass
                result = job.finish()
            except BaseException:
                job.cancel()
                raise
        except MotionCodecError as e:
            self.report({"ERROR"}, f"Madder: {e}")
            return {"CANCELLED"}
        self._done(job, result)
        return {"FINISHED"}

    def invoke(self, context, event):
        if context.window_manager is None or not context.window:
            return self.execute(context)
        try:
            self._running = self._job(context)
        except MotionCodecError as e:
            self.report({"ERROR"}, f"Madder: {e}")
            return {"CANCELLED"}
        wm = context.window_manager
        wm.progress_begin(0, 100)
        self._timer = wm.event_timer_add(0.0, window=context.window)
        wm.modal_handler_add(self)
        return {"RUNNING_MODAL"}

    def modal(self, context, event):
        job = self._running
        if event.type == "ESC":
            job.cancel()
            self.report({"WARNING"}, f"Madder: {self._what} of '{job.obj.name}' cancelled; nothing was written")
            return self._stop(context, {"CANCELLED"})
        if _undo_during_job(self, event):
            return {"RUNNING_MODAL"}
        if event.type != "TIMER":
            return {"PASS_THROUGH"}
        try:
            if not job.step():
                result = job.finish()
                self._done(job, result)
                return self._stop(context, {"FINISHED"})
        except Exception as e:  # any failure ends the modal run, with nothing written
            job.cancel()
            self.report({"ERROR"}, f"Madder: {e}")
            return self._stop(context, {"CANCELLED"})
        context.window_manager.progress_update(int(100 * job.done / max(job.total, 1)))
        context.workspace.status_text_set(
            f"Madder: '{job.obj.name}': {job.status} ({job.done}/{job.total}) — Esc to cancel")
        return {"RUNNING_MODAL"}

    def _stop(self, context, result):
        wm = context.window_manager
        wm.event_timer_remove(self._timer)
        wm.progress_end()
        context.workspace.status_text_set(None)
        return result


class MADDER_OT_compress_motion(_StepwiseOperator, bpy.types.Operator):
    """Compress the active object's evaluated motion over the scene's frame range into a .madm file
    (Compressed Motion), which Motion File bakes from and Decompress turns into a PC2 (Esc cancels)"""

    bl_idname = "madder.compress_motion"
    bl_label = "Compress Motion"
    bl_options = {"REGISTER", "UNDO"}
    _what = "compression"

    @classmethod
    def poll(cls, context):
        return context.object is not None and context.object.type == "MESH"

    def _job(self, context):
        return codec_jobs.CompressJob(context.scene, context.object)

    def _done(self, job, stats):
        self.report({"INFO"}, f"Madder: compressed the motion of '{job.obj.name}' to {job.path}: "
                              f"{job.obj.madder.motion.report}")
        if stats["max_error"] > codec.ERROR_WARNING:
            self.report({"WARNING"}, f"Madder: '{job.obj.name}': the compressed motion is off by up to "
                                     f"{100 * stats['max_error']:.3g} % of its size: compress with more Bits")


class MADDER_OT_decompress_motion(_StepwiseOperator, bpy.types.Operator):
    """Decompress the active object's Compressed Motion (.madm) to a PC2 file (PC2 File) and, with
    Mesh Cache Modifier on, point a Mesh Cache modifier at it (Esc cancels)"""

    bl_idname = "madder.decompress_motion"
    bl_label = "Decompress to PC2"
    bl_options = {"REGISTER", "UNDO"}
    _what = "decompression"

    @classmethod
    def poll(cls, context):
        return context.object is not None

    def _job(self, context):
        return codec_jobs.DecompressJob(context.scene, context.object)

    def _done(self, job, path):
        m = job.modifier
        shown = f"; its Mesh Cache modifier '{m.name}' plays it" if m is not None else ""
        self.report({"INFO"}, f"Madder: decompressed {job.source} to {path} ({job.total} samples){shown}")
        if m is not None:
            stack = list(job.obj.modifiers)
            above = [x.name for x in stack[:stack.index(m)]
                     if x.type in {"CLOTH", "SOFT_BODY"} and x.show_viewport]
            if above:
                them = "it" if len(above) == 1 else "them"
                self.report({"INFO"}, f"Madder: '{job.obj.name}': '{', '.join(above)}' above '{m.name}' still "
                                      f"computed (the file overwrites the result): disable {them} to play the "
                                      "file alone")


classes = (MADDER_OT_bake, MADDER_OT_free_bake, MADDER_OT_bake_from_preview, MADDER_OT_export_textures,
           MADDER_OT_relocate_cache, MADDER_OT_coherent_structures, MADDER_OT_compress_motion,
           MADDER_OT_decompress_motion)


def register():
    for c in classes:
        bpy.utils.register_class(c)


def unregister():
    for c in reversed(classes):
        bpy.utils.unregister_class(c)
