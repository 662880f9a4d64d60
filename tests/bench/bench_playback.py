"""`make bench`: cost of playing back one frame of a bake on a 100k-vertex mesh, in real
Blender (bpy), through the installed extension: read the frame from the cache (Rust),
write the POINT attributes with foreach_set, tag the mesh. Prints figures; asserts nothing."""

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


def main():
    module = harness.install_extension(os.environ.get("MADDER_ZIP") or os.path.join(ROOT, "dist", "madder-0.1.0.zip"))
    import madder

    handlers = sys.modules[module + ".handlers"]
    bpy.ops.wm.read_homefile(use_empty=True)
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=316, y_subdivisions=316, size=2)
    obj = bpy.context.object
    n = len(obj.data.vertices)
    frames = 30
    path = os.path.join(tempfile.mkdtemp(), "bench.madder")
    fields = ["solute", "wetness", "deposit"]  # what a bake writes (addon/bridge.py FIELDS)
    w = madder.CacheWriter(path, n, fields, 1, frames)
    rng = np.random.default_rng(1)
    for _ in range(frames):
        w.push_frame([rng.random(n, dtype=np.float32) * 0.01 for _ in fields])
    w.finish()
    obj.madder.enabled = True
    obj.madder.cache_file = path
    handlers.apply_frame(obj, 1)  # warm: reader opened, attributes created

    def median_ms(fn, reps=3):
        times = []
        for _ in range(reps):
            for f in range(1, frames + 1):
                t = time.perf_counter()
                fn(f)
                times.append(1e3 * (time.perf_counter() - t))
        return statistics.median(times)

    reader = madder.CacheReader(path)
    t_read = median_ms(lambda f: reader.read_frame(f))
    t_apply = median_ms(lambda f: handlers.apply_frame(obj, f))
    t_handler = median_ms(lambda f: bpy.context.scene.frame_set(f))
    print(f"playback of one frame on a {n}-vertex mesh ({os.cpu_count()} cores), median over {3 * frames} frames:")
    print(f"  read from cache     {t_read:6.2f} ms")
    print(f"  apply_frame (read + 3 attributes + tag)  {t_apply:6.2f} ms   (target ≤ 5 ms)")
    print(f"  scene.frame_set incl. depsgraph update   {t_handler:6.2f} ms")


if __name__ == "__main__":
    main()
