"""`make demo`: a glass of red wine thrown on a linen tablecloth as it falls onto a table,
baked and rendered: a filmstrip of the fall and the dried stain, wide and close.

Builds the scene from nothing with `bpy` (so every Blender the CI runs builds it for
itself): a round table (a cylinder with Collision) and a 1.6 m square tablecloth let go
30 cm above it, falling, landing and draping under Blender's cloth for 3 s at 24 fps
(the seed's Fig. 4.5). The cloth is simulated on a coarse grid (37 × 37 vertices, a few
seconds) and smoothed by a Catmull-Clark Subdivision (two levels) to 145 × 145 = 21,025
vertices; the subdivided motion is written to a PC2 file and played back by a Mesh Cache
modifier on the flat subdivided cloth, as a cloth simulated in another program arrives
in Blender, and the stain's simulator sees the cloth's own ≥ 20k vertices. After the
drape the file holds the cloth still while the stain dries. The tablecloth's material is
the Linen Madder fabric preset at 5 threads per centimetre, UV-mapped over the whole
cloth.

Then, as a user would, with the add-on installed from the built zip into a fresh user
repository: red wine thrown from a glass knocked over at frame 1, while the cloth falls
(a soft `stain_source` group of 8 cm near where the table's rim will be, a Throw toward
the rim and a glass's 125 mL), the Liquid preset Red Wine and the Linen fabric preset;
and the stain's clock, since a drying stain takes hours: the Frame Time clock keyed from
1/24 s a frame during the fall to minutes a frame after it. Nothing of the look is set:
the wicking, the fabric's grain, how the wine rings, the Detail (Auto) and the OpenEXR
image sequence (on, Auto size) are the defaults (issue 34). Baked by `madder.bake`, the
"Madder Stain" shader added by `madder.add_stain_shader`; Cycles renders a filmstrip of
four frames of the fall (`<out>-filmstrip`), the whole table at the last frame, dried
(`--out`), and a close-up of the dried stain (`<out>-closeup`)."""

import argparse
import math
import os
import struct
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)

import harness  # noqa: E402

TABLE_RADIUS, TABLE_HEIGHT = 0.45, 0.75
CLOTH_SIZE, CLOTH_QUADS, SUBDIV = 1.6, 36, 2  # 36·4 = 144 quads a side after subdivision
DROP = 0.30  # the cloth is let go this high above the table top
FPS, FALL_FRAMES = 24, 72  # the fall in real time: lands at frame 10, drapes by 72
DRY_FRAMES, DRY_FRAME_TIME = 40, 180.0  # then 40 frames of 3 minutes: 2 hours to dry
FRAMES = FALL_FRAMES + DRY_FRAMES
FILMSTRIP = (4, 11, 24, FALL_FRAMES)  # in the air, landing, draping, settled
SPILL_CENTRE = (0.246, -0.328, TABLE_HEIGHT)  # 4 cm in from the table's rim, toward the camera
SPILL_RADIUS = 0.08


def write_pc2(path, frames, start, rate):
    """A PC2 point cache of `frames` ((F, N, 3) float32), as Blender's Mesh Cache reads it
    (written here, not by `madder.write_pc2`: the scene is built before the add-on that
    carries the madder module is installed)."""
    import numpy as np

    frames = np.ascontiguousarray(frames, dtype="<f4")
    with open(path, "wb") as f:
        f.write(struct.pack("<12siiffi", b"POINTCACHE2\0", 1, frames.shape[1], start, rate, frames.shape[0]))
        f.write(frames.tobytes())


def build_scene(blend):
    """Builds the table, the falling tablecloth (its motion in `<blend folder>/tablecloth.pc2`),
    lights and camera; saves to `blend`."""
    import bpy
    import numpy as np
    import scene_kit as kit

    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.fps, scene.render.fps_base = FPS, 1.0
    scene.frame_start, scene.frame_end = 1, FALL_FRAMES

    bpy.ops.mesh.primitive_cylinder_add(vertices=96, radius=TABLE_RADIUS, depth=TABLE_HEIGHT,
                                        location=(0.0, 0.0, TABLE_HEIGHT / 2))
    table = bpy.context.active_object
    table.name = "Table"
    table.data.materials.append(kit.material("Wood", (0.23, 0.11, 0.05), 0.45))
    table.modifiers.new("Collision", "COLLISION")
    table.collision.thickness_outer = 0.004
    table.collision.cloth_friction = 5.0

    bpy.ops.mesh.primitive_plane_add(size=8.0, location=(0.0, 0.0, 0.0))
    floor = bpy.context.active_object
    floor.name = "Floor"
    floor.data.materials.append(kit.material("Floor", (0.33, 0.31, 0.29), 0.6))

    bpy.ops.mesh.primitive_grid_add(x_subdivisions=CLOTH_QUADS, y_subdivisions=CLOTH_QUADS, size=CLOTH_SIZE,
                                    location=(0.0, 0.0, TABLE_HEIGHT + DROP), calc_uvs=True)
    cloth = bpy.context.active_object
    cloth.name = "ClothSim"
    mod = cloth.modifiers.new("Cloth", "CLOTH")
    mod.settings.quality = 8
    mod.settings.mass = 0.25
    mod.settings.air_damping = 1.0
    mod.settings.bending_stiffness = 1.0
    mod.collision_settings.use_collision = True
    mod.collision_settings.distance_min = 0.006
    mod.point_cache.frame_start, mod.point_cache.frame_end = 1, FALL_FRAMES
    sub = cloth.modifiers.new("Subdivision", "SUBSURF")
    sub.levels = sub.render_levels = SUBDIV
    sub.uv_smooth = "NONE"  # the UVs stay the flat cloth's grid: the weave runs straight
    sub.boundary_smooth = "PRESERVE_CORNERS"
    t0 = time.perf_counter()
    motion, mesh = [], None
    for frame in range(1, FALL_FRAMES + 1):
        scene.frame_set(frame)
        dg = bpy.context.evaluated_depsgraph_get()
        evaluated = cloth.evaluated_get(dg)
        if mesh is None:  # the flat cloth as it is let go: the mesh the Mesh Cache moves
            mesh = bpy.data.meshes.new_from_object(evaluated, preserve_all_data_layers=True, depsgraph=dg)
        co = np.empty(3 * len(evaluated.data.vertices), dtype=np.float32)
        evaluated.data.vertices.foreach_get("co", co)
        motion.append(co.reshape(-1, 3))
    # still while it dries
    motion += [motion[-1]] * DRY_FRAMES
    pc2 = os.path.join(os.path.dirname(blend), "tablecloth.pc2")
    write_pc2(pc2, np.stack(motion), 1.0, 1.0)
    mesh.name = "Tablecloth"
    tablecloth = bpy.data.objects.new("Tablecloth", mesh)
    scene.collection.objects.link(tablecloth)
    tablecloth.matrix_world = cloth.matrix_world
    bpy.data.objects.remove(cloth)
    mesh.shade_smooth()
    cache = tablecloth.modifiers.new("Mesh Cache", "MESH_CACHE")
    cache.cache_format, cache.filepath = "PC2", pc2
    cache.frame_start = 1.0
    print(f"demo: dropped the tablecloth ({FALL_FRAMES} frames of Blender cloth on {(CLOTH_QUADS + 1) ** 2} "
          f"vertices, subdivided to {len(mesh.vertices)}) in {time.perf_counter() - t0:.1f} s -> {pc2}")
    z = motion[-1][:, 2] + tablecloth.location.z
    print(f"demo: draped tablecloth z from {z.min():.3f} to {z.max():.3f} m (table top {TABLE_HEIGHT} m)")

    mesh.materials.append(kit.material("Linen", (0.80, 0.78, 0.72), 0.9))
    kit.soft_group(tablecloth, "stain_source", (*SPILL_CENTRE[:2], TABLE_HEIGHT + DROP), SPILL_RADIUS)

    kit.sun(scene, (38.0, 0.0, 35.0), 3.5)
    kit.world(scene, (0.55, 0.60, 0.68), 0.6)
    kit.camera(scene, (1.55, -2.05, 1.75), (0.0, 0.0, 0.55), lens=40.0)
    scene.frame_start, scene.frame_end = 1, FRAMES
    scene.frame_current = 1
    bpy.ops.wm.save_as_mainfile(filepath=blend, check_existing=False)


def configure(image_size=None, detail=None):
    """Sets up the spill on the open demo scene as a user would, and only that: the fabric
    (the Linen preset at a coarse 5 threads per centimetre), the Spill Group, the amount,
    the Liquid preset, the throw, and the stain's clock (real time while the cloth falls,
    minutes a frame while it dries). The look (wicking, the fabric's grain, how the wine rings),
    the Detail (Auto from the cloth's edge) and the image sequence (on: the cloth has a
    UV map; its size Auto) are the defaults'. `image_size` (px) overrides the size, for
    `tests/bench/bench_image_bake.py`, which bakes the same setting; `detail` sets the
    Detail level by hand (CI's quick runs on the older Blenders); returns the tablecloth."""
    import bpy

    cloth = bpy.data.objects["Tablecloth"]
    fab = bpy.data.materials["Linen"].madder_fabric
    fab.enabled, fab.preset = True, "LINEN_PLAIN"
    fab.thread_count = 5.0  # a coarse linen: the weave shows in the close-up
    bpy.context.view_layer.objects.active = cloth
    s = cloth.madder
    s.enabled = True
    s.source_group = "stain_source"
    s.liquid = "RED_WINE"
    s.amount = 1.2  # kg/m²: the pool's depth (what a spill without a Throw lays)
    # the glass is knocked over toward the table's rim: a Single Arrow empty whose arrow
    # (local Z) points along the throw, and the splash's volume
    throw = bpy.data.objects.get("Throw")
    if throw is None:
        throw = bpy.data.objects.new("Throw", None)
        throw.empty_display_type = "SINGLE_ARROW"
        bpy.context.scene.collection.objects.link(throw)
    throw.location = (*SPILL_CENTRE[:2], TABLE_HEIGHT + DROP)  # where the cloth is at frame 1
    throw.rotation_euler = (0.0, math.pi / 2, math.atan2(SPILL_CENTRE[1], SPILL_CENTRE[0]))
    s.splash.throw, s.splash.volume = throw, 125.0  # a glass of wine
    # the clock: 1/24 s a frame while the cloth falls (the scene's rate), then minutes a
    # frame; keys on two adjacent frames, so every frame's value is one of them
    s.clock = "FRAME_TIME"
    for frame, seconds in ((FALL_FRAMES, 1.0 / FPS), (FALL_FRAMES + 1, DRY_FRAME_TIME)):
        s.frame_time = seconds
        cloth.keyframe_insert("madder.frame_time", frame=frame)
    if image_size is not None:
        s.image_size = str(image_size)
    if detail is not None:
        s.detail_auto, s.detail = False, detail
    return cloth


def filmstrip(scene, path, scale):
    """Renders the frames of `FILMSTRIP` at half the picture's size and lays them out two by
    two in one image at `path` (in the order of reading)."""
    import bpy
    import numpy as np

    scene.render.resolution_percentage = scale // 2
    tiles = []
    t0 = time.perf_counter()
    for frame in FILMSTRIP:
        scene.frame_set(frame)
        scene.render.filepath = os.path.join(os.path.dirname(path), "demo", f"filmstrip-{frame:04d}.png")
        bpy.ops.render.render(write_still=True)
        img = bpy.data.images.load(scene.render.filepath)
        w, h = img.size
        tiles.append(np.array(img.pixels[:], dtype=np.float32).reshape(h, w, 4))
        bpy.data.images.remove(img)
    # pixel rows run bottom to top: the first row of tiles goes on top
    rows = [np.concatenate(tiles[k:k + 2], axis=1) for k in (0, 2)]
    sheet = np.concatenate(rows[::-1], axis=0)
    img = bpy.data.images.new("filmstrip", sheet.shape[1], sheet.shape[0], alpha=True)
    img.pixels.foreach_set(sheet.ravel())
    img.filepath_raw, img.file_format = path, "PNG"
    img.save()
    bpy.data.images.remove(img)
    print(f"demo: rendered the filmstrip (frames {', '.join(map(str, FILMSTRIP))}) in "
          f"{time.perf_counter() - t0:.1f} s -> {path}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--zip", default=os.environ.get("MADDER_ZIP"), help="extension zip (make addon)")
    ap.add_argument("--out", default="out/demo.png")
    ap.add_argument("--frame", type=int, default=FRAMES, help="frame rendered (default: the last)")
    ap.add_argument("--samples", type=int, default=32, help="Cycles samples (denoised; the committed pictures: 32)")
    ap.add_argument("--scale", type=int, default=100, help="render resolution percentage (of 1280x720)")
    ap.add_argument("--image-size", default=None, help="stain image size, px (default: Auto)")
    ap.add_argument("--detail", type=int, default=None, help="Detail level (default: Auto)")
    ap.add_argument("--no-filmstrip", dest="filmstrip", action="store_false",
                    help="skip the filmstrip of the fall (CI's quick runs on the older Blenders)")
    ap.add_argument("--measure", action="store_true",
                    help="then measure the shader's cost and the wide vs close colours (demo_measure.py)")
    args = ap.parse_args()
    out = os.path.abspath(args.out)
    work = os.path.join(os.path.dirname(out), "demo")
    os.makedirs(work, exist_ok=True)
    blend = os.path.join(work, "tablecloth.blend")

    # a fresh Blender user folder: Blender keeps an installed wheel whose file name has not
    # changed, so a reused folder could run a stale build of the same version
    os.environ["BLENDER_USER_RESOURCES"] = tempfile.mkdtemp(prefix="madder-demo-")
    import bpy
    import scene_kit as kit

    build_scene(blend)  # before the add-on: the factory settings would disable it
    harness.install_extension(os.path.abspath(args.zip))
    bpy.ops.wm.open_mainfile(filepath=blend)
    scene = bpy.context.scene
    cloth = configure(args.image_size, args.detail)
    s = cloth.madder

    t0 = time.perf_counter()
    if bpy.ops.madder.bake() != {"FINISHED"}:
        sys.exit("demo: the bake failed (see the message above)")
    print(f"demo: baked {FRAMES} frames ({(FALL_FRAMES - 1) / FPS:.1f} s falling, then "
          f"{DRY_FRAMES * DRY_FRAME_TIME / 3600:.1f} h drying) of '{cloth.name}' ({len(cloth.data.vertices)} vertices, "
          f"Detail {s.bake_detail}, {s.image_baked_size} px images) in {time.perf_counter() - t0:.1f} s -> "
          f"{bpy.path.abspath(s.cache_file)}")

    bpy.ops.madder.add_stain_shader()
    kit.cycles(scene, 1280, 720, args.samples)
    if args.filmstrip:
        filmstrip(scene, os.path.splitext(out)[0] + "-filmstrip.png", args.scale)
    scene.frame_set(args.frame)
    scene.render.resolution_percentage = args.scale
    scene.render.filepath = out
    t0 = time.perf_counter()
    bpy.ops.render.render(write_still=True)
    print(f"demo: rendered frame {args.frame} in {time.perf_counter() - t0:.1f} s -> {out}")

    # the close-up: from 70 cm in front of the table's rim, on the stain's edge on the table
    # top (where its outline shows) and the run over the rim below it
    closeup = os.path.splitext(out)[0] + "-closeup.png"
    wide_pose = (scene.camera.matrix_world.copy(), scene.camera.data.lens)
    cx, cy, cz = SPILL_CENTRE
    kit.aim(scene.camera, (cx + 0.33, cy - 0.44, cz + 0.32), (cx - 0.03, cy + 0.04, cz - 0.05))
    scene.camera.data.lens = 40.0
    scene.render.filepath = closeup
    t0 = time.perf_counter()
    bpy.ops.render.render(write_still=True)
    print(f"demo: rendered the close-up in {time.perf_counter() - t0:.1f} s -> {closeup}")
    if args.measure:
        import demo_measure

        close_pose = (scene.camera.matrix_world.copy(), scene.camera.data.lens)
        demo_measure.run(scene, cloth, wide_pose, close_pose, out, TABLE_HEIGHT, SPILL_CENTRE)


if __name__ == "__main__":
    main()
    harness.exit(0)
