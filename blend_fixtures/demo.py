"""`make demo`: bake a stain on the bundled flag and render one frame, full view and close-up.

Installs the built extension into a fresh user repository (as a user would), opens a copy
of `flag.blend`, bakes a splash of red wine from its `stain_source` vertex group through
the add-on's operator (the full simulator at Detail 3, each cloth triangle split into 64, with wicking and an
irregular fabric:
it runs down the waving flag, soaks in and binds) to an image sequence in UV space, adds
the add-on's "Madder Stain" shader to the flag's material (it reads the images), and
renders a frame with Cycles on the CPU, then a close-up of the stain (`<out>-closeup`)."""

import argparse
import os
import shutil
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)

import harness  # noqa: E402


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--zip", default=os.environ.get("MADDER_ZIP"), help="extension zip (make addon)")
    ap.add_argument("--out", default="out/demo.png")
    ap.add_argument("--frame", type=int, default=40)
    args = ap.parse_args()
    out = os.path.abspath(args.out)
    work = os.path.join(os.path.dirname(out), "demo")
    os.makedirs(work, exist_ok=True)
    blend = os.path.join(work, "flag.blend")
    # MADDER_FIXTURES: the fixtures rebuilt by an older Blender (`make demo BPY=4.2.23`)
    shutil.copyfile(os.path.join(os.environ.get("MADDER_FIXTURES") or HERE, "flag.blend"), blend)

    # a fresh Blender user folder: Blender keeps an installed wheel whose file name has not
    # changed, so a reused folder could run a stale build of the same version
    os.environ["BLENDER_USER_RESOURCES"] = tempfile.mkdtemp(prefix="madder-demo-")
    import bpy

    harness.install_extension(os.path.abspath(args.zip))
    bpy.ops.wm.open_mainfile(filepath=blend)
    scene = bpy.context.scene
    flag = bpy.data.objects["Flag"]
    bpy.context.view_layer.objects.active = flag
    flag.madder.enabled = True
    flag.madder.source_group = "stain_source"
    s = flag.madder
    s.liquid = "RED_WINE"
    s.amount = 1.5  # kg/m²: a generous spill, 15× what the fibres hold, so it runs
    s.diffusion_rate = 0.004
    s.splash_speed, s.splash_seed = 1.0, 3  # thrown on the flag: it splashes outward
    s.detail = 3  # the stain on the cloth's triangles split 64 ways
    s.wicking = 2.0  # a sharp front that slows as the spill thins
    s.irregularity, s.irregularity_length, s.irregularity_seed = 0.6, 40.0, 3  # a ragged outline
    s.output_images = True  # and written as EXR images in UV space, read by the shader
    s.output_vertex_colors = False
    s.image_size = "2048"

    t0 = time.perf_counter()
    result = bpy.ops.madder.bake()
    if result != {"FINISHED"}:
        sys.exit("demo: the bake failed (see the message above)")
    frames = scene.frame_end - scene.frame_start + 1
    print(f"demo: baked {frames} frames of '{flag.name}' ({len(flag.data.vertices)} vertices) "
          f"in {time.perf_counter() - t0:.2f} s -> {bpy.path.abspath(flag.madder.cache_file)}")

    bpy.ops.madder.add_stain_shader()
    scene.frame_set(args.frame)
    scene.cycles.samples = 64
    scene.render.resolution_x, scene.render.resolution_y = 960, 640
    scene.render.filepath = out
    t0 = time.perf_counter()
    bpy.ops.render.render(write_still=True)
    print(f"demo: rendered frame {args.frame} in {time.perf_counter() - t0:.1f} s")
    print(f"demo: picture written to {out}")

    # the close-up: the camera moved toward the stain's source area, a longer lens
    closeup = os.path.splitext(out)[0] + "-closeup.png"
    cam = scene.camera
    target = stain_centre(flag, "stain_source")
    direction = (target - cam.location).normalized()
    cam.location = target - direction * 1.8
    cam.data.lens = 85.0
    scene.render.filepath = closeup
    t0 = time.perf_counter()
    bpy.ops.render.render(write_still=True)
    print(f"demo: rendered the close-up in {time.perf_counter() - t0:.1f} s -> {closeup}")


def stain_centre(obj, group):
    """World centroid of the evaluated mesh's vertices in vertex group `group`."""
    import bpy
    from mathutils import Vector

    index = obj.vertex_groups[group].index
    weights = {v.index: g.weight for v in obj.data.vertices for g in v.groups if g.group == index}
    ev = obj.evaluated_get(bpy.context.evaluated_depsgraph_get())
    mesh = ev.to_mesh()
    total, acc = 0.0, Vector((0.0, 0.0, 0.0))
    for i, w in weights.items():
        acc += w * (ev.matrix_world @ mesh.vertices[i].co)
        total += w
    ev.to_mesh_clear()
    return acc / total


if __name__ == "__main__":
    main()
    harness.exit(0)
