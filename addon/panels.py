"""The Madder panel in the Physics properties tab."""

import textwrap

import bpy

from . import fabrics, handlers, preview, stored


class _PhysicsPanel:
    """A panel of mesh objects in the Physics properties tab."""

    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    bl_context = "physics"

    @classmethod
    def poll(cls, context):
        return context.object is not None and context.object.type == "MESH"


class MADDER_PT_stain(_PhysicsPanel, bpy.types.Panel):
    bl_label = "Madder Stain"

    def draw_header(self, context):
        self.layout.prop(context.object.madder, "enabled", text="")

    def draw(self, context):
        s = context.object.madder
        layout = self.layout
        layout.use_property_split = True
        layout.active = s.enabled
        row = layout.row(align=True)
        row.operator("madder.bake", icon="FILE_CACHE")
        row.operator("madder.free_bake", icon="TRASH", text="Free")
        layout.operator("madder.bake", text="Bake All Stains", icon="SCENE_DATA").all_objects = True
        layout.operator("madder.add_stain_shader", icon="NODE_MATERIAL")
        _draw_live(layout, context.object)
        if s.cache_file and not s.live:
            _draw_cache_status(layout, context.object, context.scene.frame_current)


def _draw_live(layout, obj):
    """Live preview: the toggle, its memory, what it holds, Bake from Preview."""
    s = obj.madder
    row = layout.row(align=True)
    row.prop(s, "live", toggle=True, icon="PLAY")
    row.prop(s, "live_memory")
    if s.live:
        layout.label(text=preview.status(obj), icon="INFO")
        layout.operator("madder.bake_from_preview", icon="FILE_CACHE")


def _draw_cache_status(layout, obj, frame):
    """The bake's state at this frame: playing, or why not (with the path looked at), and
    the way out (Relocate Cache, or bake again)."""
    s = obj.madder
    why = handlers.problem(obj, frame)
    if why is None:
        layout.label(text=f"Baked: {s.cache_file}", icon="CHECKMARK")
        warning = handlers.damage(obj)
        if warning:
            layout.label(text=warning, icon="ERROR")
    else:
        col = layout.column(align=True)
        col.alert = True
        for i, line in enumerate(textwrap.wrap(why, 48)):
            col.label(text=line, icon="ERROR" if i == 0 else "BLANK1")
        layout.operator("madder.relocate_cache", icon="FILEBROWSER")
    layout.prop(s, "render_without_cache")


class _StainSubPanel(_PhysicsPanel):
    bl_parent_id = "MADDER_PT_stain"

    def layout_of(self, context):
        layout = self.layout
        layout.use_property_split = True
        layout.active = context.object.madder.enabled
        return layout, context.object.madder


class MADDER_PT_stain_liquid(_StainSubPanel, bpy.types.Panel):
    bl_label = "Liquid"

    def draw(self, context):
        layout, s = self.layout_of(context)
        layout.prop(s, "liquid")
        layout.prop_search(s, "source_group", context.object, "vertex_groups")
        col = layout.column()
        col.active = bool(s.source_group)
        col.prop(s, "amount")
        col.prop(s, "spill_shape")
        layout.prop(s, "stain_color")
        layout.prop(s, "concentration")
        layout.prop(s, "diffusion_rate")
        col = layout.column(heading="Splash", align=True)
        col.active = bool(s.source_group)
        col.prop(s, "splash_speed", text="Speed")
        col.prop(s, "splash_seed", text="Seed")
        col.prop(s.splash, "throw")
        col.prop(s.splash, "volume")
        col.prop(s.splash, "height")


class MADDER_PT_stain_output(_StainSubPanel, bpy.types.Panel):
    bl_label = "Output"

    def draw(self, context):
        layout, s = self.layout_of(context)
        obj = context.object
        row = layout.row(heading="Detail")
        row.prop(s, "detail_auto", text="Auto")
        sub = row.row()
        sub.active = not s.detail_auto
        sub.prop(s, "detail", text="")
        col = layout.column(heading="Output", align=True)
        col.prop(s, "output_vertex_colors")
        col.prop(s, "output_images")
        col = layout.column()
        col.active = s.output_images
        col.prop(s, "image_size")
        col.prop(s, "sharp_outline")
        sub = col.row()
        sub.active = s.sharp_outline
        sub.prop(s, "outline_in_shader")
        if not s.output_images:
            return
        if obj.data.uv_layers.active is None:
            col.label(text="Needs a UV map", icon="ERROR")
        if not s.cache_file:
            return
        if stored.uses_images(obj):
            first, last = s.image_frames
            col.label(text=f"Images: {s.image_baked_size} px, frames {first}–{last}", icon="IMAGE_DATA")
            if s.image_size != "AUTO" and s.image_baked_size != int(s.image_size):
                col.label(text="Size changed: Re-export Textures to apply it", icon="INFO")
            if s.image_baked_outline != s.sharp_outline or (
                    s.sharp_outline and s.image_baked_outline_shader != s.outline_in_shader):
                col.label(text="Sharp Outline changed: Re-export Textures to apply it", icon="INFO")
        else:
            col.label(text="Bake to write the image sequence", icon="INFO")
        col.operator("madder.export_textures", icon="TEXTURE")


class MADDER_PT_stain_forces(_StainSubPanel, bpy.types.Panel):
    bl_label = "Forces"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        layout, s = self.layout_of(context)
        col = layout.column(heading="Forces", align=True)
        row = col.row()
        row.prop(s, "use_gravity")
        if not context.scene.use_gravity:
            row.label(text="Scene gravity is off", icon="INFO")
        col.prop(s, "use_rectilinear")
        col.prop(s, "use_coriolis")
        layout.prop(s, "friction")
        layout.prop(s, "viscosity")
        layout.prop(s, "momentum_advection")


class MADDER_PT_stain_interactions(_StainSubPanel, bpy.types.Panel):
    bl_label = "Interactions"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        layout, s = self.layout_of(context)
        col = layout.column(align=True)
        col.prop(s, "absorption")
        col.prop(s, "saturation")
        col = layout.column(align=True)
        col.prop(s, "adsorption")
        col.prop(s, "capacity")
        col = layout.column(align=True)
        col.prop(s, "evaporation")
        col.prop(s, "evaporation_boundary")


class MADDER_PT_stain_look(_StainSubPanel, bpy.types.Panel):
    bl_label = "Look"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        layout, s = self.layout_of(context)
        col = layout.column(align=True)
        col.prop(s, "wicking")
        sub = col.row()
        sub.active = s.wicking > 0.0
        sub.prop(s, "wicking_iterations")
        sub.prop(s, "front_settles")
        layout.prop(s, "grain_from")
        col = layout.column(align=True)
        col.active = s.grain_from == "OBJECT"
        col.prop(s, "irregularity")
        sub = col.column(align=True)
        sub.active = s.grain_from == "OBJECT" and s.irregularity > 0.0
        sub.prop(s, "irregularity_length")
        sub.prop(s, "irregularity_fine")
        sub.prop(s, "irregularity_seed")
        col = layout.column(align=True)
        col.prop(s, "carry_solute")
        sub = col.column(align=True)
        sub.active = s.carry_solute
        sub.prop(s, "residual_saturation")
        sub.prop(s, "carried_fraction")
        sub.prop(s, "dispersivity")
        sub.prop(s, "capillary_rise")
        col.prop(s, "vapour_limited")
        col = layout.column(align=True)
        col.prop(s, "holdup")
        col.prop(s, "drip_hold")


class MADDER_PT_stain_cache(_StainSubPanel, bpy.types.Panel):
    bl_label = "Cache"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        layout, s = self.layout_of(context)
        layout.prop(s, "clock")
        if s.clock == "FRAME_TIME":
            layout.prop(s, "frame_time")
        layout.prop(s, "substeps")
        layout.prop(s, "first_substep")
        layout.prop(s, "motion_file")
        layout.prop(s, "cache_dir")


class MADDER_PT_stain_motion(_PhysicsPanel, bpy.types.Panel):
    """Compress Motion and Decompress, under the Motion File they feed: the cloth's motion
    as a .madm file, and that file as a PC2 for the Mesh Cache modifier."""

    bl_label = "Compressed Motion"
    bl_parent_id = "MADDER_PT_stain_cache"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        m = context.object.madder.motion
        layout.prop(m, "path")
        layout.prop(m, "bits")
        layout.operator("madder.compress_motion", icon="FILE_CACHE")
        if m.report:
            col = layout.column(align=True)
            for i, line in enumerate(textwrap.wrap(m.report, 48)):
                col.label(text=line, icon="INFO" if i == 0 else "BLANK1")
        layout.prop(m, "pc2_path")
        layout.prop(m, "add_mesh_cache")
        layout.operator("madder.decompress_motion", icon="MOD_MESHDEFORM")


class MADDER_PT_stain_lcs(_StainSubPanel, bpy.types.Panel):
    bl_label = "Coherent Structures"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        layout, s = self.layout_of(context)
        lcs = s.lcs
        layout.prop(s, "bake_flow")
        if not s.bake_flow:
            layout.label(text="Tick Bake Flow and bake to compute them", icon="INFO")
        col = layout.column(align=True)
        col.prop(lcs, "frame")
        col.prop(lcs, "span")
        layout.prop(lcs, "direction", expand=True)
        layout.prop(lcs, "steps_per_frame")
        col = layout.column(heading="Ridges", align=True)
        col.prop(lcs, "smoothing")
        col.prop(lcs, "hessian_smoothing")
        col.prop(lcs, "min_edges")
        col.prop(lcs, "min_branch")
        col.prop(lcs, "join")
        col.prop(lcs, "remove_valleys")
        layout.prop(lcs, "radius")
        layout.operator("madder.coherent_structures", icon="FORCE_VORTEX")
        if lcs.ridge_object is not None:
            layout.label(text=f"Ridges: {lcs.ridge_object.name}", icon="OUTLINER_OB_CURVES")


class MADDER_PT_source(_PhysicsPanel, bpy.types.Panel):
    bl_label = "Madder Source"

    def draw_header(self, context):
        self.layout.prop(context.object.madder_source, "is_source", text="")

    def draw(self, context):
        src = context.object.madder_source
        layout = self.layout
        layout.use_property_split = True
        layout.active = src.is_source
        layout.prop(src, "liquid")
        layout.prop(src, "amount")
        layout.prop(src, "color")
        layout.prop(src, "concentration")
        layout.prop(src, "distance")
        col = layout.column(heading="Splash", align=True)
        col.prop(src, "splash_speed", text="Speed")
        col.prop(src, "splash_seed", text="Seed")
        layout.prop(src, "use_frame_range")
        col = layout.column(align=True)
        col.active = src.use_frame_range
        col.prop(src, "frame_start")
        col.prop(src, "frame_end")


# cell kind → icon for the tile preview (up and down of a thread share its colour)
_CELL_ICONS = {"W": "SEQUENCE_COLOR_01", "w": "SEQUENCE_COLOR_02", "F": "SEQUENCE_COLOR_05",
               "f": "SEQUENCE_COLOR_06", ".": "SEQUENCE_COLOR_09"}
_MAX_PREVIEW = 16


class MADDER_PT_fabric(bpy.types.Panel):
    bl_label = "Madder Fabric"
    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    bl_context = "material"

    @classmethod
    def poll(cls, context):
        return context.material is not None

    def draw_header(self, context):
        self.layout.prop(context.material.madder_fabric, "enabled", text="")

    def draw(self, context):
        fab = context.material.madder_fabric
        layout = self.layout
        layout.use_property_split = True
        layout.active = fab.enabled
        layout.prop(fab, "preset")
        layout.prop(fab, "weave")
        if fab.weave == "CUSTOM":
            layout.prop(fab, "grid")
        else:
            layout.prop(fab, "gaps")
        layout.prop(fab, "speed")
        layout.prop(fab, "angle")
        layout.prop(fab, "thread_count")
        layout.prop(fab, "shader_weave")
        col = layout.column(heading="Grain", align=True)
        col.prop(fab, "irregularity")
        col.prop(fab, "irregularity_length")
        col.prop(fab, "irregularity_seed")
        col = layout.column(heading="Permeability", align=True)
        for pair in fabrics.PAIRS:
            col.prop(fab, pair)
        result, error = fabrics.describe(fab)
        if error:
            layout.label(text=error, icon="ERROR")
            return
        ratio, angle = result
        layout.label(text=f"Spreads {ratio:.2f}× faster along {angle:+.0f}° from the weft", icon="MOD_CLOTH")
        try:
            rows = fabrics.tile_rows(fab)
        except Exception as e:
            layout.label(text=str(e), icon="ERROR")
            return
        box = layout.box()
        box.label(text="Tile (red: warp, blue: weft, grey: gap)")
        grid = box.grid_flow(row_major=True, columns=min(len(rows[0]), _MAX_PREVIEW), even_columns=True, align=True)
        for row in rows[:_MAX_PREVIEW]:
            for cell in row[:_MAX_PREVIEW]:
                grid.label(text="", icon=_CELL_ICONS.get(cell, "QUESTION"))


classes = (
    MADDER_PT_stain,
    MADDER_PT_stain_liquid,
    MADDER_PT_stain_output,
    MADDER_PT_stain_forces,
    MADDER_PT_stain_interactions,
    MADDER_PT_stain_look,
    MADDER_PT_stain_cache,
    MADDER_PT_stain_motion,
    MADDER_PT_stain_lcs,
    MADDER_PT_source,
    MADDER_PT_fabric,
)


def register():
    for c in classes:
        bpy.utils.register_class(c)


def unregister():
    for c in reversed(classes):
        bpy.utils.unregister_class(c)
