"""`make bench`: Madder vs Blender's Dynamic Paint, per frame, on the same cloth.

One bpy process builds a vertical flag (a `--size` x `--size` quad grid, 1 m x 0.6 m in
the XZ plane, ~100k vertices at the default 316) with a Cloth modifier pinned along its
pole edge (vertex group ``pin``) under gravity and a light wind, and bakes the cloth for
frames 1..`--frames` (``ptcache.bake_all``) *before anything is timed*, so the cloth
solver is excluded from both figures: every later frame change only reads the cloth cache.

Dynamic Paint: a canvas on the flag after the Cloth modifier, one VERTEX / PAINT surface
with the spread and drip effects, memory cache; a small ico sphere brush (PAINT, volume +
proximity) touching the flag. Its time per frame is measured in two ways, over the frames
2..F played in order with ``scene.frame_set`` (frame 1 only resets and initialises the
surface, so it is left out; going back to frame 1 resets the surface's non-baked cache, so
every repetition recomputes):
  * ``execution_time`` of the evaluated canvas modifier (Blender's own timer around the
    modifier's evaluation: surface step, effects, writing the output layers), read after
    each frame change. This is the headline figure.
  * cross-check: wall time of ``frame_set`` with the canvas enabled minus the same with it
    disabled (``show_viewport``), cloth read from the bake either way; this also counts
    the depsgraph overhead Dynamic Paint causes (brush evaluation, cache writes).
It also checks that the surface really painted: it counts the vertices with a non-zero
alpha in the ``dp_paintmap`` color layer of the evaluated mesh.

Madder: the evaluated world positions of every frame are read once with ``foreach_get``
into float32 arrays (untimed). A Simulator starts at frame 1 with a Gaussian patch of
solvent around the brush; the time per frame is ``sim.step(positions, 1/fps)`` plus
reading back ``wetness()``, ``stain()`` and ``deposit()``, i.e. Python <-> Rust transfer
included, cloth excluded, for the same frames 2..F.

Prints figures; never asserts timings. Usage:
    PYTHONPATH=.venv/madder-wheel .venv/bin/python tests/bench/bench_dynamic_paint.py \\
        [--size 316] [--frames 12] [--reps 2]
"""

import argparse
import os
import statistics
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))
sys.path.insert(0, os.path.join(ROOT, "blend_fixtures"))
os.environ.setdefault("BLENDER_USER_RESOURCES", tempfile.mkdtemp(prefix="madder-bench-"))

import bpy  # noqa: E402
import numpy as np  # noqa: E402
from build_fixtures import add_cloth, bake_all, grid_arrays, mesh_from_arrays  # noqa: E402
from mathutils import Vector  # noqa: E402

FPS = 24
FLAG_SIZE = (1.0, 0.6)  # along x (away from the pole) and z (up), metres
BRUSH_AT = (0.25, 0.0, 0.3)  # brush centre, near the pole where the flag moves least
BRUSH_RADIUS = 0.06
TARGET = 20.0  # the target: Madder at most 1/20 of Dynamic Paint's time


def build_scene(size, frames):
    """The flag with its baked cloth, and the Dynamic Paint canvas + brush (enabled)."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.frame_start, scene.frame_end = 1, frames
    scene.render.fps, scene.render.fps_base = FPS, 1.0
    scene.frame_set(1)

    u, v, faces, uv = grid_arrays(size, size, *FLAG_SIZE)
    rest = np.stack([u, np.zeros_like(u), v], axis=1)
    flag = bpy.data.objects.new("Flag", mesh_from_arrays("Flag", rest, faces, uv))
    scene.collection.objects.link(flag)
    for name in ("dp_paintmap", "dp_wetmap"):  # Dynamic Paint writes its output only into
        flag.data.color_attributes.new(name, "BYTE_COLOR", "CORNER")  # existing layers
    flag.vertex_groups.new(name="pin").add(np.flatnonzero(u == 0.0).tolist(), 1.0, "REPLACE")
    add_cloth(flag, scene, quality=5, mass=0.05, air_damping=1.0, vertex_group_mass="pin")

    bpy.ops.object.effector_add(type="WIND", location=(-0.5, -0.5, 0.3))
    wind = bpy.context.active_object
    # The wind axis is the empty's local +Z: along +X and across the flag (+Y), since
    # cloth only feels the wind normal to its faces.
    wind.rotation_euler = Vector((1.0, 1.0, 0.0)).to_track_quat("Z", "Y").to_euler()
    wind.field.strength = 500.0
    wind.field.noise = 1.0
    wind.field.flow = 0.0

    t = time.perf_counter()
    bake_all(scene)  # before the canvas exists, so only the cloth cache is baked
    t_bake = time.perf_counter() - t

    canvas = flag.modifiers.new("Dynamic Paint", "DYNAMIC_PAINT")
    canvas.ui_type = "CANVAS"
    with bpy.context.temp_override(object=flag, active_object=flag):
        if bpy.ops.dpaint.type_toggle(type="CANVAS") != {"FINISHED"}:
            raise RuntimeError("could not make the flag a Dynamic Paint canvas")
    surface = canvas.canvas_settings.canvas_surfaces[0]
    surface.surface_format = "VERTEX"
    surface.surface_type = "PAINT"
    surface.frame_start, surface.frame_end = 1, frames
    surface.use_spread = True
    surface.use_drip = True
    surface.output_name_a, surface.output_name_b = "dp_paintmap", "dp_wetmap"
    surface.point_cache.use_disk_cache = False

    bpy.ops.mesh.primitive_ico_sphere_add(subdivisions=2, radius=BRUSH_RADIUS, location=BRUSH_AT)
    brush = bpy.context.active_object
    brush.name = "Brush"
    bmod = brush.modifiers.new("Dynamic Paint", "DYNAMIC_PAINT")
    bmod.ui_type = "BRUSH"  # the type the canvas looks for (type_toggle alone keeps CANVAS)
    with bpy.context.temp_override(object=brush, active_object=brush):
        if bpy.ops.dpaint.type_toggle(type="BRUSH") != {"FINISHED"}:
            raise RuntimeError("could not make the sphere a Dynamic Paint brush")
    bs = bmod.brush_settings
    bs.paint_source = "VOLUME_DISTANCE"
    bs.paint_distance = 0.03
    bs.paint_color = (0.5, 0.05, 0.1)
    bs.paint_alpha = 1.0
    bs.paint_wetness = 1.0
    return scene, flag, canvas, t_bake


def world_positions(scene, flag, frames):
    """Evaluated world positions of frames 1..F, (F, N, 3) float32 (cloth from the bake)."""
    out = []
    for f in range(1, frames + 1):
        scene.frame_set(f)
        ev = flag.evaluated_get(bpy.context.evaluated_depsgraph_get())
        mesh = ev.data
        co = np.empty(3 * len(mesh.vertices), dtype=np.float32)
        mesh.vertices.foreach_get("co", co)
        m = np.array(ev.matrix_world, dtype=np.float32)
        out.append(co.reshape(-1, 3) @ m[:3, :3].T + m[:3, 3])
    return np.stack(out)


def play_dynamic_paint(scene, flag, canvas, frames):
    """Plays 1..F in order; returns per-frame (wall ms, modifier ms) for frames 2..F."""
    wall, modtime = [], []
    scene.frame_set(1)  # start frame: the surface and its non-baked cache are reset
    for f in range(2, frames + 1):
        t = time.perf_counter()
        scene.frame_set(f)
        wall.append(1e3 * (time.perf_counter() - t))
        if canvas.show_viewport:
            ev = flag.evaluated_get(bpy.context.evaluated_depsgraph_get())
            modtime.append(1e3 * ev.modifiers[canvas.name].execution_time)
    return wall, modtime


def painted_vertices(flag, n):
    """Vertices with a non-zero alpha in the evaluated dp_paintmap layer (-1: no layer)."""
    mesh = flag.evaluated_get(bpy.context.evaluated_depsgraph_get()).data
    layer = mesh.attributes.get("dp_paintmap")
    if layer is None:
        return -1
    color = np.empty(4 * len(layer.data), dtype=np.float32)
    layer.data.foreach_get("color", color)
    alpha = color[3::4]
    if layer.domain == "CORNER":
        vert = np.empty(len(mesh.loops), dtype=np.int32)
        mesh.loops.foreach_get("vertex_index", vert)
        hit = np.zeros(n, dtype=bool)
        hit[vert[alpha > 0.0]] = True
        return int(hit.sum())
    return int((alpha > 0.0).sum())


def triangles(flag):
    mesh = flag.data
    mesh.calc_loop_triangles()
    tris = np.empty(3 * len(mesh.loop_triangles), dtype=np.uint32)
    mesh.loop_triangles.foreach_get("vertices", tris)
    return tris.reshape(-1, 3)


def bench_madder(flag, positions, reps):
    """Per-frame ms of step + reading the outputs back (frames 2..F), construction ms and
    the number of wet vertices at the end; None if madder.Simulator is unavailable."""
    try:
        import madder

        madder.Simulator  # noqa: B018
    except (ImportError, AttributeError) as e:
        print(f"madder.Simulator not available ({e}); skipping the Madder part")
        return None
    faces = triangles(flag)
    n = positions.shape[1]
    co = np.empty(3 * n, dtype=np.float32)
    flag.data.vertices.foreach_get("co", co)
    m = np.array(flag.matrix_world, dtype=np.float32)
    rest = np.ascontiguousarray(co.reshape(-1, 3) @ m[:3, :3].T + m[:3, 3])
    r2 = ((rest - np.asarray(BRUSH_AT, dtype=np.float32)) ** 2).sum(axis=1)
    sigma = 0.05  # Gaussian patch, 1 kg/m² peak, cut at 3 sigma
    solvent = np.where(r2 < (3.0 * sigma) ** 2, np.exp(-r2 / (2.0 * sigma**2)), 0.0).astype(np.float32)
    dt = 1.0 / FPS
    times, t_new, wet = [], [], None
    for _ in range(reps):
        t = time.perf_counter()
        sim = madder.Simulator(faces, rest, positions[0], gravity=(0.0, 0.0, -9.81))  # default physics
        sim.add_liquid(solvent, concentration=0.05, color=(0.5, 0.05, 0.1))
        t_new.append(1e3 * (time.perf_counter() - t))
        for k in range(1, len(positions)):
            frame_pos = positions[k]
            after_pos = positions[k + 1] if k + 1 < len(positions) else None
            t = time.perf_counter()
            sim.step(frame_pos, dt, after=after_pos)
            wet, _stain, _deposit = sim.wetness(), sim.stain(), sim.deposit()
            times.append(1e3 * (time.perf_counter() - t))
    return times, statistics.median(t_new), int((np.asarray(wet) > 1e-3).sum()), sim.profile()


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--size", type=int, default=316, help="quads per side (316: ~100k vertices)")
    ap.add_argument("--frames", type=int, default=12, help="cloth/stain frames 1..F")
    ap.add_argument("--reps", type=int, default=2, help="repetitions of each timed playback")
    args = ap.parse_args()
    if args.frames < 3:
        ap.error("--frames must be at least 3")

    scene, flag, canvas, t_bake = build_scene(args.size, args.frames)
    n = len(flag.data.vertices)
    steps = args.frames - 1

    # Positions once, canvas off (the cloth cache is what we read); then warm both states.
    canvas.show_viewport = False
    positions = world_positions(scene, flag, args.frames)
    play_dynamic_paint(scene, flag, canvas, args.frames)
    canvas.show_viewport = True
    play_dynamic_paint(scene, flag, canvas, args.frames)
    painted = painted_vertices(flag, n)

    wall_on, mod_on, wall_off = [], [], []
    for _ in range(args.reps):  # interleaved, so drifts hit both states alike
        canvas.show_viewport = True
        w, m = play_dynamic_paint(scene, flag, canvas, args.frames)
        wall_on += w
        mod_on += m
        canvas.show_viewport = False
        w, _ = play_dynamic_paint(scene, flag, canvas, args.frames)
        wall_off += w
    t_dp = statistics.median(mod_on)
    t_dp_diff = statistics.median(wall_on) - statistics.median(wall_off)

    result = bench_madder(flag, positions, args.reps)

    def row(label, value, note=""):
        print(f"  {label:<46}{value}{note}")

    print(
        f"Dynamic Paint vs Madder on a {n}-vertex cloth flag, {steps} frames ({args.frames} baked), "
        f"{os.cpu_count()} cores, medians over {args.reps} x {steps} frames, cloth excluded:"
    )
    moved = float(np.linalg.norm(positions[-1] - positions[0], axis=1).max())
    row(f"cloth bake of {args.frames} frames (not in any figure)", f"{t_bake:8.2f} s")
    row("cloth motion, largest vertex displacement", f"{moved:8.3f} m")
    row("frame_set, canvas off (cloth cache read)", f"{statistics.median(wall_off):8.2f} ms")
    row("frame_set, canvas on", f"{statistics.median(wall_on):8.2f} ms")
    row("Dynamic Paint, on - off (wall)", f"{t_dp_diff:8.2f} ms")
    row("Dynamic Paint, modifier execution_time", f"{t_dp:8.2f} ms", f"   ({painted} vertices painted)")
    if painted <= 0:
        print("  WARNING: Dynamic Paint painted nothing; the comparison is against a no-op")
    if result is None:
        return
    times, t_new, wet, prof = result
    t_m = statistics.median(times)
    ratio = t_m / t_dp
    row("Madder Simulator() + add_liquid (once)", f"{t_new:8.2f} ms")
    row("Madder step + wetness/stain/deposit", f"{t_m:8.2f} ms", f"   ({wet} vertices wetter than 1 g/m²)")
    k = max(prof["substeps"], 1)  # the last repetition's sub-steps
    parts = ("window", "geometry", "forces", "advection", "diffusion", "interaction")
    phases = ", ".join(f"{p} {1e3 * prof[p] / k:.1f}" for p in parts if p in prof)
    row("  of which, per frame (ms, last repetition)", "", f" {phases}")
    row(
        "  CG iterations / transport cycles per frame",
        "",
        f" density {prof['density_iterations'] / k:.1f}, velocity {prof['velocity_iterations'] / k:.1f}; "
        f"{prof['transport_cycles'] / k:.1f}",
    )
    if "window_vertices" in prof:
        row(
            "  window per frame (vertices)",
            "",
            f" {prof['window_vertices'] / k:.0f}, of which active {prof['active_vertices'] / k:.0f}; "
            f"{prof['window_rebuilds']} rebuilds in {k} frames",
        )
    verdict = "holds" if ratio <= 1.0 / TARGET else "NOT met"
    row("ratio Madder / Dynamic Paint", f"{ratio:8.3f}", f"   (target ≤ 1/{TARGET:g} = {1 / TARGET:.3f}: {verdict})")


if __name__ == "__main__":
    main()
