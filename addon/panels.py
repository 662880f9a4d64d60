"""The Madder panel in the Physics properties tab."""

import bpy


class MADDER_PT_stain(bpy.types.Panel):
    bl_label = "Madder Stain"
    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    bl_context = "physics"

    @classmethod
    def poll(cls, context):
        return context.object is not None and context.object.type == "MESH"

    def draw_header(self, context):
        self.layout.prop(context.object.madder, "enabled", text="")

    def draw(self, context):
        obj = context.object
        s = obj.madder
        layout = self.layout
        layout.use_property_split = True
        layout.active = s.enabled
        layout.prop_search(s, "source_group", obj, "vertex_groups")
        layout.prop(s, "amount")
        layout.prop(s, "diffusion_rate")
        layout.prop(s, "substeps")
        layout.prop(s, "stain_color")
        layout.prop(s, "cache_dir")
        row = layout.row(align=True)
        row.operator("madder.bake", icon="FILE_CACHE")
        row.operator("madder.free_bake", icon="TRASH", text="Free")
        if s.cache_file:
            layout.label(text=f"Baked: {s.cache_file}", icon="CHECKMARK")


def register():
    bpy.utils.register_class(MADDER_PT_stain)


def unregister():
    bpy.utils.unregister_class(MADDER_PT_stain)
