"""Rendering: the Madder Stain shader and playback during an animation render."""

import os

import bpy
import numpy as np
from conftest import make_active


def test_stain_shader_is_inserted_once_and_keeps_the_inputs(open_fixture):
    open_fixture("flag.blend")
    flag = make_active(bpy.data.objects["Flag"])
    mat = flag.active_material
    bsdf = next(n for n in mat.node_tree.nodes if n.type == "BSDF_PRINCIPLED")
    cloth = tuple(bsdf.inputs["Base Color"].default_value)
    assert bpy.ops.madder.add_stain_shader() == {"FINISHED"}
    group = next(n for n in mat.node_tree.nodes if n.type == "GROUP")
    assert group.node_tree.name == "Madder Stain"
    assert bsdf.inputs["Base Color"].links[0].from_node == group
    assert bsdf.inputs["Roughness"].links[0].from_node == group
    assert tuple(group.inputs["Base Color"].default_value) == cloth
    assert bpy.ops.madder.add_stain_shader() == {"FINISHED"}  # idempotent
    assert sum(n.type == "GROUP" for n in mat.node_tree.nodes) == 1


def render_frames(scene, out, frames):
    scene.render.filepath = os.path.join(out, "f####")
    scene.frame_start, scene.frame_end = frames[0], frames[-1]
    bpy.ops.render.render(animation=True)
    images = {}
    for f in frames:
        img = bpy.data.images.load(os.path.join(out, f"f{f:04d}.png"))
        px = np.empty(len(img.pixels), dtype=np.float32)
        img.pixels.foreach_get(px)
        images[f] = px.reshape(img.size[1], img.size[0], 4)[..., :3]
        bpy.data.images.remove(img)
    return images


def test_animation_render_shows_each_frames_stain(open_fixture, tmp_path):
    """100 frames of a still disk whose stain spreads: rendered in background with the
    bpy module. Only the stain changes, so frames differ exactly where it changed."""
    scene = open_fixture("disk.blend")
    disk = make_active(bpy.data.objects["Disk"])
    disk.animation_data_clear()
    disk.madder.source_group = "stain_source"
    disk.madder.liquid = "RED_WINE"
    disk.madder.amount = 1.0
    disk.madder.diffusion_rate = 0.004
    scene.frame_start, scene.frame_end = 1, 100
    assert bpy.ops.madder.bake() == {"FINISHED"}
    assert scene.render.use_lock_interface
    bpy.ops.madder.add_stain_shader()
    r = scene.render
    r.engine = "CYCLES"
    r.resolution_x, r.resolution_y, r.resolution_percentage = 64, 48, 100
    scene.cycles.samples = 2
    scene.cycles.use_denoising = False
    r.image_settings.file_format = "PNG"
    images = render_frames(scene, str(tmp_path), list(range(1, 101)))
    assert len(images) == 100
    first, last = images[1], images[100]
    changed = np.abs(first - last).max(axis=2) > 0.02
    # the stain spread: some pixels changed, but not the whole picture (no other change)
    assert 0.002 < changed.mean() < 0.5, changed.mean()
    # and it changes progressively: frame 50 is between the two
    mid = np.abs(images[50] - first).max(axis=2)[changed].mean()
    end = np.abs(last - first).max(axis=2)[changed].mean()
    assert 0.1 * end < mid < end
