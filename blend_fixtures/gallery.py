"""`make gallery`: the contact sheet of the four liquid presets on three weaves, at three
moments, written to docs/gallery.png.

One scene, built from nothing with `bpy`: twelve flat squares of white cotton (16 cm,
49 × 49 vertices, UV-mapped), one per liquid preset (rows: Water, Red Wine, Coffee, Ink)
and weave (columns: Plain, Twill 2/1, Satin 5), each with its own material carrying the
Madder fabric at 3 threads per centimetre (a coarse weave, so that it shows at the
sheet's scale), and a spill at its centre: a soft Spill Group of 3 cm radius at 0.8 kg/m²,
eight times what the fibres hold, which lands as a pool (the default Spill Shape) of 1.6 cm
radius. Labels are Blender text objects.

The add-on is used as a user would: installed from the built zip, each square's Liquid
preset, weave and thread count set in its properties and nothing of the look (the
wicking, the grain, the rings, the Detail and the images are the defaults, issue 34),
all baked by `madder.bake` (All Objects), the "Madder Stain" shader added by
`madder.add_stain_shader`. Drying takes real time (a saturated cotton cloth dries in
about half an hour), so the scene's clock runs at one minute per frame (fps 1, fps base
60) over an hour, each frame in the default simulation steps (`--check-steps` measures
their error against 30 steps). Three frames are rendered from above with Cycles and
stitched side by side (numpy, saved by Blender's image API): wet (1 min after the
spill), drying (15 min) and dry (60 min). Under them, a row of calibrated swatches (issue
35) at the same scale: the plain cotton dry, full of water, full of red wine, and dried
red wine at the same dye, its values written into the shader's attributes rather than
baked, so the row shows what the stain shader makes of a known wetness and dye.

`--check-steps` bakes one square (Coffee, plain) twice, with `SUBSTEPS` (4) and with 30 steps per
frame, and prints how far the two stains differ: the long steps' error."""

import argparse
import os
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)

import harness  # noqa: E402

PRESETS = [("WATER", "Water"), ("RED_WINE", "Red Wine"), ("COFFEE", "Coffee"), ("INK", "Ink")]
WEAVES = [("PLAIN", "Plain"), ("TWILL21", "Twill 2/1"), ("SATIN5", "Satin 5")]
SIZE, QUADS, PITCH = 0.16, 48, 0.2  # square side (m), quads a side, centre spacing (m)
SPILL_RADIUS, AMOUNT = 0.03, 0.8
THREADS_PER_CM = 3.0
SECONDS_PER_FRAME, FRAMES, SUBSTEPS = 60, 61, 4  # frame 1 is the spill, frame 61 one hour on
MOMENTS = [(2, "wet: 1 min"), (16, "drying: 15 min"), (61, "dry: 60 min")]
PANEL = (900, 1100)
# the swatch row under the sheet (issue 35): uniform cloth at known wetness and dye, read by
# the stain shader from attributes set here (not baked): (label, dye amount, wetness, bound dye)
SWATCHES = [("dry cloth", 0.0, 0.0, 0.0), ("wet: water", 0.0, 1.0, 0.0),
            ("wet: red wine", 1.0, 1.0, 0.0), ("dry: red wine", 1.0, 0.0, 1.0)]
SWATCH_Y, SWATCH_PITCH, STRIP_HEIGHT = -1.0, 0.6, 300  # row centre and spacing (m), strip height (px)


def square_name(preset, weave):
    return f"{preset}_{weave}"


def build_scene(blend, only=None):
    """The squares, labels, camera and light (no add-on settings yet); saved to `blend`."""
    import bpy
    import scene_kit as kit

    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.fps, scene.render.fps_base = 1, float(SECONDS_PER_FRAME)
    scene.frame_start, scene.frame_end, scene.frame_current = 1, FRAMES, 1

    ink = kit.material("Label", (0.9, 0.9, 0.9), 0.9)
    for r, (preset, plabel) in enumerate(PRESETS):
        y = (1.5 - r) * PITCH
        for c, (weave, wlabel) in enumerate(WEAVES):
            if only is not None and (preset, weave) != only:
                continue
            x = (c - 1) * PITCH
            bpy.ops.mesh.primitive_grid_add(x_subdivisions=QUADS, y_subdivisions=QUADS, size=SIZE,
                                            location=(x, y, 0.0), calc_uvs=True)
            sq = bpy.context.active_object
            sq.name = sq.data.name = square_name(preset, weave)
            sq.data.materials.append(kit.material(f"Cotton {plabel} {wlabel}", (0.86, 0.85, 0.82), 0.9))
            kit.soft_group(sq, "stain_source", (x, y, 0.0), SPILL_RADIUS)
            if r == 0:
                text(scene, wlabel, (x, 2.0 * PITCH + 0.005, 0.001), 0.032, "CENTER", ink)
        text(scene, plabel, (-1.5 * PITCH - 0.01, y - 0.012, 0.001), 0.032, "RIGHT", ink)
    title = text(scene, "", (-0.09, 2.0 * PITCH + 0.065, 0.001), 0.042, "CENTER", ink)
    title.name = "Title"

    bpy.ops.mesh.primitive_plane_add(size=3.0, location=(0.0, 0.0, -0.002))
    bpy.context.active_object.data.materials.append(kit.material("Backdrop", (0.06, 0.06, 0.065), 1.0))

    cam = kit.camera(scene, (-0.09, 0.055, 2.0), (-0.09, 0.055, 0.0))
    cam.data.type = "ORTHO"
    cam.data.ortho_scale = 1.0
    kit.sun(scene, (12.0, 0.0, 30.0), 4.0, angle_deg=8.0)
    kit.world(scene, (0.7, 0.72, 0.75), 0.5)
    kit.cycles(scene, *PANEL, 24)
    bpy.ops.wm.save_as_mainfile(filepath=blend, check_existing=False)


def add_swatches(scene, wine_color):
    """The swatch row at `SWATCH_Y` (outside the sheet's view): four squares of the sheet's
    cotton, plain weave at the sheet's thread count, each uniformly at one of `SWATCHES`,
    written into the attributes the stain shader reads (the wine's colour as its preset
    set it on the baked square), with the stain shader added by `madder.add_stain_shader`
    as on the baked squares."""
    import bpy
    import numpy as np
    import scene_kit as kit

    ink = bpy.data.materials["Label"]
    for i, (label, dye, wetness, bound) in enumerate(SWATCHES):
        x = (i - (len(SWATCHES) - 1) / 2) * SWATCH_PITCH
        bpy.ops.mesh.primitive_grid_add(x_subdivisions=8, y_subdivisions=8, size=SIZE,
                                        location=(x, SWATCH_Y + 0.02, 0.0), calc_uvs=True)
        sq = bpy.context.active_object
        sq.name = sq.data.name = f"Swatch {label}"
        mat = kit.material(f"Cotton swatch {i}", (0.86, 0.85, 0.82), 0.9)
        fab = mat.madder_fabric
        fab.enabled, fab.weave, fab.thread_count = True, "PLAIN", THREADS_PER_CM
        sq.data.materials.append(mat)
        mesh = sq.data
        n = len(mesh.vertices)
        mesh.color_attributes.new("madder_stain", "FLOAT_COLOR", "POINT")
        mesh.attributes.new("madder_wetness", "FLOAT", "POINT")
        mesh.attributes.new("madder_deposit", "FLOAT", "POINT")
        rgba = np.tile([*(dye * c for c in wine_color), dye], n)
        mesh.attributes["madder_stain"].data.foreach_set("color", rgba)
        mesh.attributes["madder_wetness"].data.foreach_set("value", np.full(n, wetness))
        mesh.attributes["madder_deposit"].data.foreach_set("value", np.full(n, bound))
        bpy.context.view_layer.objects.active = sq
        bpy.ops.madder.add_stain_shader()
        text(scene, label, (x, SWATCH_Y - 0.095, 0.001), 0.026, "CENTER", ink)


def text(scene, body, location, size, align, material):
    import bpy

    curve = bpy.data.curves.new(f"Label {body}", "FONT")
    curve.body = body
    curve.size = size
    curve.align_x = align
    curve.materials.append(material)
    obj = bpy.data.objects.new(f"Label {body}", curve)
    obj.location = location
    scene.collection.objects.link(obj)
    return obj


def configure(obj, preset, weave, substeps=None, image_size=None):
    """The Madder settings a user would set on a square, and only those: its fabric (on its
    material: the weave and the thread count), the Spill Group, the amount and the Liquid
    preset. The look, the Detail and the images are the defaults' (issue 34). `substeps`
    and `image_size` override the defaults (for `--check-steps` and `--image-size`)."""
    fab = obj.material_slots[0].material.madder_fabric
    fab.enabled, fab.weave, fab.thread_count = True, weave, THREADS_PER_CM
    s = obj.madder
    s.enabled = True
    s.source_group = "stain_source"
    s.liquid = preset
    s.amount = AMOUNT
    if substeps is not None:
        s.substeps = substeps
    if image_size is not None:
        s.image_size = str(image_size)


def bake_all(blend, zip_path, substeps, image_size, only=None):
    import bpy

    build_scene(blend, only)  # before the add-on: the factory settings would disable it
    harness.install_extension(os.path.abspath(zip_path))
    bpy.ops.wm.open_mainfile(filepath=blend)
    squares = []
    for preset, _ in PRESETS:
        for weave, _ in WEAVES:
            obj = bpy.data.objects.get(square_name(preset, weave))
            if obj is not None:
                configure(obj, preset, weave, substeps, image_size)
                squares.append(obj)
    bpy.ops.wm.save_mainfile()
    t0 = time.perf_counter()
    if bpy.ops.madder.bake(all_objects=True) != {"FINISHED"}:
        sys.exit("gallery: the bake failed (see the message above)")
    print(f"gallery: baked {len(squares)} squares ({len(squares[0].data.vertices)} vertices each, Detail "
          f"{squares[0].madder.bake_detail}, {squares[0].madder.image_baked_size} px images, {FRAMES} frames of "
          f"{SECONDS_PER_FRAME} s in {squares[0].madder.substeps} steps each, the first ones after the spill from "
          f"{squares[0].madder.first_substep} s up) in {time.perf_counter() - t0:.1f} s")
    return squares


def check_steps(work, zip_path):
    """The long steps' error: Coffee on plain baked with `SUBSTEPS` and 30 steps per frame."""
    import bpy
    import numpy as np

    results = {}
    for steps in (SUBSTEPS, 30):
        folder = os.path.join(work, f"steps{steps}")
        os.makedirs(folder, exist_ok=True)
        (obj,) = bake_all(os.path.join(folder, "check.blend"), zip_path, steps, "512", only=("COFFEE", "PLAIN"))
        images = os.path.join(os.path.dirname(bpy.path.abspath(obj.madder.cache_file)), f"{obj.name}_images")
        for frame, _label in MOMENTS:
            for kind in ("stain", "wet"):
                img = bpy.data.images.load(os.path.join(images, f"{obj.name}_{kind}.{frame:04d}.exr"))
                results[steps, frame, kind] = np.array(img.pixels[:]).reshape(512, 512, 4)
                bpy.data.images.remove(img)
    for frame, label in MOMENTS:
        for kind, ch in (("stain", 3), ("wet", 0), ("wet", 1)):
            a, b = results[SUBSTEPS, frame, kind][..., ch], results[30, frame, kind][..., ch]
            print(f"gallery: {label:15s} {kind}[{'RGBA'[ch]}]: {SUBSTEPS} vs 30 steps per frame differ by max "
                  f"{np.abs(a - b).max():.4f}, mean {np.abs(a - b).mean():.5f} (mean value {b.mean():.4f})")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--zip", default=os.environ.get("MADDER_ZIP"), help="extension zip (make addon)")
    ap.add_argument("--out", default="docs/gallery.png")
    ap.add_argument("--samples", type=int, default=24)
    ap.add_argument("--scale", type=int, default=100, help="render resolution percentage")
    ap.add_argument("--image-size", default=None, help="stain image size, px (default: Auto)")
    ap.add_argument("--check-steps", action="store_true", help="measure the long steps' error instead")
    ap.add_argument("--only", default=None, metavar="LIQUID:WEAVE",
                    help="bake and render one square (e.g. RED_WINE:PLAIN), for a quick look at the layout")
    args = ap.parse_args()
    out = os.path.abspath(args.out)
    work = os.path.abspath(os.path.join("out", "gallery"))
    os.makedirs(work, exist_ok=True)
    os.environ["BLENDER_USER_RESOURCES"] = tempfile.mkdtemp(prefix="madder-gallery-")
    if args.check_steps:
        check_steps(work, args.zip)
        return

    import bpy
    import numpy as np

    only = tuple(args.only.split(":")) if args.only else None
    squares = bake_all(os.path.join(work, "gallery.blend"), args.zip, None, args.image_size, only)
    scene = bpy.context.scene
    for obj in scene.objects:
        if obj.type == "MESH" and obj.madder.enabled:
            bpy.context.view_layer.objects.active = obj
            bpy.ops.madder.add_stain_shader()
    scene.cycles.samples = args.samples
    scene.render.resolution_percentage = args.scale
    panels = []
    for frame, label in MOMENTS:
        scene.frame_set(frame)
        bpy.data.objects["Title"].data.body = label
        path = os.path.join(work, f"panel-{frame:03d}.png")
        scene.render.filepath = path
        t0 = time.perf_counter()
        bpy.ops.render.render(write_still=True)
        print(f"gallery: rendered frame {frame} ({label}) in {time.perf_counter() - t0:.1f} s")
        img = bpy.data.images.load(path)
        w, h = img.size
        panels.append(np.array(img.pixels[:], dtype=np.float32).reshape(h, w, 4))
        bpy.data.images.remove(img)
    gutter = np.full((panels[0].shape[0], 8, 4), 0.4, dtype=np.float32)
    gutter[..., 3] = 1.0
    sheet = np.concatenate([p for panel in panels for p in (panel, gutter)][:-1], axis=1)
    # the swatch row: rendered at the panels' scale (pixels per metre) across the sheet's width
    # (the wine's colour; with --only, the one square's)
    wine = bpy.data.objects.get(square_name("RED_WINE", "PLAIN")) or squares[0]
    add_swatches(scene, tuple(wine.madder.stain_color))
    cam, r = scene.camera, scene.render
    per_metre = max(r.resolution_x, r.resolution_y) * r.resolution_percentage / 100 / cam.data.ortho_scale
    r.resolution_x, r.resolution_y, r.resolution_percentage = sheet.shape[1], STRIP_HEIGHT * args.scale // 100, 100
    cam.data.ortho_scale = r.resolution_x / per_metre
    cam.location = (0.0, SWATCH_Y, cam.location.z)
    path = os.path.join(work, "swatches.png")
    scene.render.filepath = path
    bpy.data.objects["Title"].hide_render = True
    bpy.ops.render.render(write_still=True)
    img = bpy.data.images.load(path)
    strip = np.array(img.pixels[:], dtype=np.float32).reshape(r.resolution_y, r.resolution_x, 4)
    bpy.data.images.remove(img)
    rule = np.full((8, sheet.shape[1], 4), 0.4, dtype=np.float32)
    rule[..., 3] = 1.0
    sheet = np.concatenate([strip, rule, sheet], axis=0)  # rows from the bottom: the strip under
    h, w = sheet.shape[:2]
    img = bpy.data.images.new("gallery", w, h, alpha=False)
    img.pixels.foreach_set(sheet.ravel())
    img.filepath_raw = out
    img.file_format = "PNG"
    img.save()
    print(f"gallery: contact sheet {w}x{h} written to {out}")


if __name__ == "__main__":
    main()
    harness.exit(0)
