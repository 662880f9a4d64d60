"""`make bench`: what playing back a bake costs, measured from outside as a user sees it.

A 100k-vertex grid deformed by a Wave modifier (so every frame change re-evaluates it
anyway), in real Blender (bpy), with the extension installed from the zip. The figures
are median wall times of `scene.frame_set(f)` in the same process, over interleaved
rounds (so the machine's drift hits every case alike), in three states: Madder on (its
handlers and its "Madder Stain" modifier, which copies the carrier's fields onto the
cloth), Madder switched off (the object's panel unticked: handlers registered, modifier
hidden), and no Madder (handlers removed, modifier hidden). Playback's cost is "on"
minus "no Madder": the handler and the modifier's evaluation together. Also printed: the
handler's parts (reading a frame from the cache, apply_frame). Prints figures; asserts
nothing."""

import os
import statistics
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))
sys.path.insert(0, os.path.join(ROOT, "blend_fixtures"))
os.environ["BLENDER_USER_RESOURCES"] = tempfile.mkdtemp(prefix="madder-bench-")

import bpy  # noqa: E402
import harness  # noqa: E402
import numpy as np  # noqa: E402

FRAMES = 30
ROUNDS = 5


def main():
    module = harness.install_extension(harness.default_zip())
    import madder

    handlers = sys.modules[module + ".handlers"]
    stored = sys.modules[module + ".stored"]
    bpy.ops.wm.read_homefile(use_empty=True)
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=316, y_subdivisions=316, size=2)
    obj = bpy.context.object
    obj.modifiers.new("Wave", "WAVE")
    n = len(obj.data.vertices)
    path = os.path.join(tempfile.mkdtemp(), "bench.madder")
    fields = ["solute", "wetness", "deposit"]  # what a bake writes (addon/bridge.py FIELDS)
    w = madder.CacheWriter(path, n, fields, 1, FRAMES)
    rng = np.random.default_rng(1)
    for _ in range(FRAMES):
        w.push_frame([rng.random(n, dtype=np.float32) * 0.01 for _ in fields])
    w.finish()
    s = obj.madder
    s.enabled = True
    s.cache_file = path
    s.bake_references = (0.01, 0.1, 0.01)  # as a bake records them
    s.bake_topology = stored.topology_fingerprint(obj.data)
    scene = bpy.context.scene
    scene.frame_start, scene.frame_end = 1, FRAMES
    assert handlers.apply_frame(obj, 1) is None  # warm: reader opened, attributes created
    ours = [(getattr(bpy.app.handlers, name), fn) for name, fn in handlers._HANDLERS]

    def frame_set_ms():
        out = []
        for f in range(1, FRAMES + 1):
            t = time.perf_counter()
            scene.frame_set(f)
            out.append(1e3 * (time.perf_counter() - t))
        return out

    with_, off, without = [], [], []
    for _ in range(ROUNDS):
        with_ += frame_set_ms()
        s.enabled = False  # hides the modifier
        off += frame_set_ms()
        for lst, fn in ours:
            lst.remove(fn)
        without += frame_set_ms()
        for lst, fn in ours:
            lst.append(fn)
        s.enabled = True
    assert handlers.problem(obj, 5) is None
    scene.frame_set(5)  # the handler did show the cache's frame
    wet = np.empty(n, dtype=np.float32)
    shown = obj.evaluated_get(bpy.context.evaluated_depsgraph_get()).data  # through the carrier
    shown.attributes["madder_wetness"].data.foreach_get("value", wet)
    np.testing.assert_allclose(wet, np.clip(madder.CacheReader(path).read(5, "wetness") / 0.1, 0, 1), atol=1e-6)

    def median_ms(fn):
        times = []
        for _ in range(ROUNDS):
            for f in range(1, FRAMES + 1):
                t = time.perf_counter()
                fn(f)
                times.append(1e3 * (time.perf_counter() - t))
        return statistics.median(times)

    reader = madder.CacheReader(path)
    t_read = median_ms(lambda f: reader.read_frame(f))
    t_apply = median_ms(lambda f: handlers.apply_frame(obj, f))
    t_with, t_off, t_without = statistics.median(with_), statistics.median(off), statistics.median(without)
    print(f"playback on a Wave-deformed {n}-vertex grid ({os.cpu_count()} cores, bpy {bpy.app.version_string}), "
          f"medians over {ROUNDS * FRAMES} frames:")
    print(f"  scene.frame_set without Madder   {t_without:6.2f} ms")
    print(f"  scene.frame_set with Madder      {t_with:6.2f} ms")
    print(f"  scene.frame_set, Madder off      {t_off:6.2f} ms")
    print(f"  Madder's cost from outside       {t_with - t_without:6.2f} ms   (handler + modifier; target ≤ 3 ms)")
    print(f"  switched off, its cost           {t_off - t_without:6.2f} ms   (target 0)")
    print(f"    of which apply_frame           {t_apply:6.2f} ms   (read + 3 attributes of the carrier + tag)")
    print(f"    of which reading the cache     {t_read:6.2f} ms")


if __name__ == "__main__":
    main()
