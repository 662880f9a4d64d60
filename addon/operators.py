"""Madder's operators. Thin: they check the context, call `bake`, and report."""

import bpy

from . import bake, handlers


class MADDER_OT_bake(bpy.types.Operator):
    """Simulate the stain over the scene's frame range and write it to the cache"""

    bl_idname = "madder.bake"
    bl_label = "Bake Stain"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        return context.object is not None

    def execute(self, context):
        obj = context.object
        wm = context.window_manager
        total = max(context.scene.frame_end - context.scene.frame_start, 1)
        wm.progress_begin(0, total)
        try:
            path, warnings = bake.bake(context.scene, obj, progress=lambda done, _: wm.progress_update(done))
        except bake.BakeError as e:
            self.report({"ERROR"}, str(e))
            return {"CANCELLED"}
        finally:
            wm.progress_end()
        obj.madder.enabled = True
        handlers.apply_frame(obj, context.scene.frame_current)
        for w in warnings:
            self.report({"WARNING"}, f"Madder: '{obj.name}': {w}")
        self.report({"INFO"}, f"Madder: baked '{obj.name}' to {path}")
        return {"FINISHED"}


class MADDER_OT_free_bake(bpy.types.Operator):
    """Delete the baked stain of the active object"""

    bl_idname = "madder.free_bake"
    bl_label = "Free Bake"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        return context.object is not None and bool(context.object.madder.cache_file)

    def execute(self, context):
        path = bake.free(context.object)
        self.report({"INFO"}, f"Madder: removed {path}" if path else "Madder: nothing to remove")
        return {"FINISHED"}


classes = (MADDER_OT_bake, MADDER_OT_free_bake)


def register():
    for c in classes:
        bpy.utils.register_class(c)


def unregister():
    for c in reversed(classes):
        bpy.utils.unregister_class(c)
