"""`make bench`: Madder vs Blender's Dynamic Paint, per frame, on the same cloth, with
matched work (issue 16, target 1: Madder at most 1/5 of Dynamic Paint's time in every cell).

One bpy process builds a vertical flag (a `--size` x `--size` quad grid, 1 m x 0.6 m in
the XZ plane, ~100k vertices at 316) with a Cloth modifier pinned along its pole edge
(vertex group ``pin``) under gravity and a light wind, and bakes the cloth for frames
1..`--frames` (``ptcache.bake_all``) *before anything is timed*, so the cloth solver is
excluded from both figures: every later frame change only reads the cloth cache.

Matched work: each tool wets the same share of the cloth, 10 %, 40 % and 100 %, and
20 % for target 2 (`--shares`), counted at the last frame (Dynamic Paint's painted vertices, Madder's
vertices wetter than 1 g/m²). Both spread, and the cloth moves through Dynamic Paint's
brush, so a footprint is not a share: each tool's radius is found by bisection on untimed
runs until its count is within ±`MATCH` of the share (a brush sphere at the flag's centre
for Dynamic Paint, a pour on the vertices within the radius of it at frame 1 for
Madder; for 100 % a brush past the corners and the pour everywhere). Both counts are
printed beside the times.

Dynamic Paint: a canvas on the flag after the Cloth modifier, one VERTEX / PAINT surface
with the spread and drip effects, memory cache; the brush paints by VOLUME_DISTANCE. Its
time per frame is measured over frames 2..F played in order with ``scene.frame_set``
(frame 1 only resets and initialises the surface; going back to it resets the surface's
non-baked cache, so every repetition recomputes):
  * ``execution_time`` of the evaluated canvas modifier (Blender's own timer around the
    modifier's evaluation: surface step, effects, writing the output layers), read after
    each frame change. This is the headline figure.
  * cross-check: wall time of ``frame_set`` with the canvas enabled minus the same with it
    disabled (``show_viewport``); this also counts the depsgraph overhead Dynamic Paint
    causes (brush evaluation, cache writes).

Madder: the evaluated world positions of every frame are read once with ``foreach_get``
into float32 arrays (untimed). A Simulator with the default physics starts at frame 1 with
the pour; the time per frame is ``sim.step(positions, 1/fps)`` plus reading back
``wetness()``, ``stain()`` and ``deposit()``, i.e. Python <-> Rust transfer included,
cloth excluded, for the same frames 2..F, in the same process as Dynamic Paint.

Prints figures; never asserts timings. Usage:
    PYTHONPATH=.venv/madder-wheel .venv/bin/python tests/bench/bench_dynamic_paint.py \\
        [--size 316] [--frames 12] [--reps 2] [--shares 0.1,0.4,1]
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
CENTRE = (0.5, 0.0, 0.3)  # the brush's and the pour's centre: the flag's, at rest
BRUSH_RADIUS = 0.06  # the ico sphere as made; scaled to each share's radius
POUR = 0.15  # kg/m² of solvent where the pour lands (about what cotton holds)
MATCH = 0.1  # the wet counts' tolerance, as a share of the cloth
TARGET = 5.0  # issue 16, target 1: Madder at most 1/5 of Dynamic Paint's time
INTERACTIVE = 16.0  # issue 16, target 2: ms per frame with ~20 % of the cloth wet (60 fps)


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

    bpy.ops.mesh.primitive_ico_sphere_add(subdivisions=2, radius=BRUSH_RADIUS, location=CENTRE)
    brush = bpy.context.active_object
    brush.name = "Brush"
    bmod = brush.modifiers.new("Dynamic Paint", "DYNAMIC_PAINT")
    bmod.ui_type = "BRUSH"  # the type the canvas looks for (type_toggle alone keeps CANVAS)
    with bpy.context.temp_override(object=brush, active_object=brush):
        if bpy.ops.dpaint.type_toggle(type="BRUSH") != {"FINISHED"}:
            raise RuntimeError("could not make the sphere a Dynamic Paint brush")
    bs = bmod.brush_settings
    bs.paint_source = "VOLUME_DISTANCE"
    bs.paint_distance = 0.005  # the volume paints; a 5 mm margin (the bisection sets the radius)
    bs.paint_color = (0.5, 0.05, 0.1)
    bs.paint_alpha = 1.0
    bs.paint_wetness = 1.0
    return scene, flag, canvas, brush, t_bake


def footprint(share):
    """The radius of the disc covering `share` of the flag at rest (None: the whole flag)."""
    if share >= 1.0:
        return None
    return float(np.sqrt(share * FLAG_SIZE[0] * FLAG_SIZE[1] / np.pi))


def place_brush(brush, radius):
    """Scales the brush sphere to `radius` at the flag's centre (None: a sphere reaching
    past its corners)."""
    if radius is None:
        radius = 1.5 * float(np.hypot(FLAG_SIZE[0] / 2, FLAG_SIZE[1] / 2))
    brush.location = CENTRE
    brush.scale = (radius / BRUSH_RADIUS,) * 3


def calibrate(share, n, count):
    """The radius at which `count(radius)` (wet vertices after an untimed run) is within
    `MATCH` of `share` of `n` (bisection from the disc of that share; None for the whole
    cloth), and that count."""
    r = footprint(share)
    got = count(r)
    if r is None:
        return r, got
    lo, hi = 0.0, 2.0 * r
    for _ in range(8):
        if abs(got / n - share) <= MATCH * share:
            break
        if got / n > share:
            hi = r
        else:
            lo = r
        r = 0.5 * (lo + hi)
        got = count(r)
    return r, got


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


def bench_madder(flag, positions, reps, radius):
    """Per-frame ms of step + reading the outputs back (frames 2..F), construction ms, the
    number of wet vertices at the end and the last run's profile, for a pour within
    `radius` of the centre (None: everywhere); None if madder.Simulator is unavailable."""
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
    d = np.linalg.norm(positions[0] - np.asarray(CENTRE, dtype=np.float32), axis=1)
    inside = d < radius if radius is not None else np.ones(n, dtype=bool)
    solvent = np.where(inside, POUR, 0.0).astype(np.float32)
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


def row(label, value, note=""):
    print(f"  {label:<46}{value}{note}")


def madder_rows(result):
    """The Madder figures of one share; returns its median ms per frame."""
    times, t_new, wet, prof = result
    t_m = statistics.median(times)
    row("Madder Simulator() + add_liquid (once)", f"{t_new:8.2f} ms")
    row("Madder step + wetness/stain/deposit", f"{t_m:8.2f} ms", f"   ({wet} vertices wetter than 1 g/m²)")
    k = max(prof["substeps"], 1)  # the last repetition's sub-steps
    parts = ("window", "geometry", "forces", "advection", "diffusion", "interaction")
    phases = ", ".join(f"{p} {1e3 * prof[p] / k:.1f}" for p in parts if p in prof)
    row("  of which, per sub-step (ms, last repetition)", "", f" {phases}")
    split = ("advection_trace", "advection_plan", "advection_apply")
    if all(p in prof for p in split):
        trace, plan, apply = (1e3 * prof[p] / k for p in split)
        row(
            "  advection: back-traces / fluxes + plan / sub-cycles (ms)",
            "",
            f" {trace:.1f} / {plan:.1f} / {apply:.1f}",
        )
    row(
        "  CG iterations / transport cycles per sub-step",
        "",
        f" density {prof['density_iterations'] / k:.1f}, velocity {prof['velocity_iterations'] / k:.1f}; "
        f"{prof['transport_cycles'] / k:.1f}",
    )
    if "window_vertices" in prof:
        row(
            "  window per sub-step (vertices)",
            "",
            f" {prof['window_vertices'] / k:.0f}, of which active {prof['active_vertices'] / k:.0f}; "
            f"{prof['window_rebuilds']} rebuilds in {k} sub-steps",
        )
    if "least_work" in prof:
        # issue 16, target 4: what each phase must move and do at least (stain/work.rs)
        # and the rates that makes; the machine's limits are printed by `cargo bench
        # --bench simulate` in the same `make bench`
        cells = []
        for p in parts:
            w, sec = prof["least_work"][p], max(prof[p], 1e-12)
            cells.append(f"{p} {1e-6 * w['bytes'] / k:.1f} MB {1e-6 * w['flops'] / k:.1f} Mflop "
                         f"({1e-9 * w['bytes'] / sec:.1f} GB/s, {1e-9 * w['flops'] / sec:.2f} GFLOP/s)")
        row("  least work per sub-step (achieved rate)", "", " " + "; ".join(cells))
    return t_m, wet


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--size", type=int, default=316, help="quads per side (316: ~100k vertices)")
    ap.add_argument("--frames", type=int, default=12, help="cloth/stain frames 1..F")
    ap.add_argument("--reps", type=int, default=2, help="repetitions of each timed playback")
    ap.add_argument("--shares", default="0.1,0.2,0.4,1", help="shares of the cloth wetted, comma-separated")
    args = ap.parse_args()
    if args.frames < 3:
        ap.error("--frames must be at least 3")
    shares = [float(x) for x in args.shares.split(",")]
    if not shares or any(not 0.0 < x <= 1.0 for x in shares):
        ap.error("--shares must be in (0, 1]")

    scene, flag, canvas, brush, t_bake = build_scene(args.size, args.frames)
    n = len(flag.data.vertices)
    steps = args.frames - 1

    # positions once, canvas off (the cloth cache is what we read)
    canvas.show_viewport = False
    positions = world_positions(scene, flag, args.frames)
    moved = float(np.linalg.norm(positions[-1] - positions[0], axis=1).max())
    print(
        f"Dynamic Paint vs Madder on a {n}-vertex cloth flag, {steps} frames ({args.frames} baked), "
        f"{os.cpu_count()} cores, medians over {args.reps} x {steps} frames, cloth excluded:"
    )
    row(f"cloth bake of {args.frames} frames (not in any figure)", f"{t_bake:8.2f} s")
    row("cloth motion, largest vertex displacement", f"{moved:8.3f} m")

    table = []
    for share in shares:

        def dp_count(radius):
            place_brush(brush, radius)
            play_dynamic_paint(scene, flag, canvas, args.frames)
            return painted_vertices(flag, n)

        def madder_count(radius):
            result = bench_madder(flag, positions, 1, radius)
            return -1 if result is None else result[2]

        canvas.show_viewport = False
        play_dynamic_paint(scene, flag, canvas, args.frames)  # warm both states
        canvas.show_viewport = True
        r_dp, painted = calibrate(share, n, dp_count)
        r_m, _ = calibrate(share, n, madder_count)
        wall_on, mod_on, wall_off = [], [], []
        for _ in range(args.reps):  # interleaved, so drifts hit both states alike
            canvas.show_viewport = True
            w, m = play_dynamic_paint(scene, flag, canvas, args.frames)
            wall_on += w
            mod_on += m
            canvas.show_viewport = False
            w, _ = play_dynamic_paint(scene, flag, canvas, args.frames)
            wall_off += w
        canvas.show_viewport = False
        t_dp = statistics.median(mod_on)
        t_dp_diff = statistics.median(wall_on) - statistics.median(wall_off)
        def cm(r):
            return "the whole flag" if r is None else f"{100 * r:.1f} cm"

        print(f"\n share {share:.0%} of the cloth (brush radius {cm(r_dp)}, pour radius {cm(r_m)}):")
        row("frame_set, canvas off (cloth cache read)", f"{statistics.median(wall_off):8.2f} ms")
        row("Dynamic Paint, on - off (wall)", f"{t_dp_diff:8.2f} ms")
        row("Dynamic Paint, modifier execution_time", f"{t_dp:8.2f} ms", f"   ({painted} vertices painted)")
        if painted <= 0:
            print("  WARNING: Dynamic Paint painted nothing; the comparison is against a no-op")
        result = bench_madder(flag, positions, args.reps, r_m)
        if result is None:
            return
        t_m, wet = madder_rows(result)
        table.append((share, painted, wet, t_dp, t_m))

    print(f"\n matched work, {n} vertices, {os.cpu_count()} cores (target: Madder / Dynamic Paint ≤ 1/{TARGET:g}):")
    print(f"  {'share':>6} {'DP wet':>8} {'Madder wet':>11} {'DP ms':>8} {'Madder ms':>10} {'ratio':>7}")
    for share, painted, wet, t_dp, t_m in table:
        ratio = t_m / t_dp
        verdict = "met" if ratio <= 1.0 / TARGET else "NOT met"
        print(f"  {share:>6.0%} {100 * painted / n:>7.1f}% {100 * wet / n:>10.1f}% {t_dp:>8.2f} {t_m:>10.2f} "
              f"{ratio:>7.3f}  {verdict}")
    for share, _, wet, _, t_m in table:
        if share == 0.2 and n >= 90_000:  # target 2 is the 100k flag
            verdict = "met" if t_m <= INTERACTIVE else "NOT met"
            print(f" interactive: {100 * wet / n:.0f} % wet, Madder {t_m:.2f} ms a frame "
                  f"(target ≤ {INTERACTIVE:g} ms: {verdict})")


if __name__ == "__main__":
    main()
