"""`make bench`: what the Image Sequence output adds to a bake (issue 12: at most 2× the
bake without it, at 1024 px), measured from outside as a user meets it.

In real Blender (bpy) with the extension installed from the zip: the demo's scene (the
21k-vertex tablecloth draped on a table, `blend_fixtures/demo.py`) and its spill of red
wine at Detail 1, all its frames, baked by `bpy.ops.madder.bake()` with vertex colours only,
and with the image sequence at 1024 px as well, in interleaved rounds in one process (so
the machine's drift hits both). Then, on the last bake's cache, Re-export Textures with
Sharp Outline off, within a texel and in the shader (the images lifted and the front's
distance written), in interleaved rounds. Prints the times and their ratios; asserts
nothing.
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
os.environ["BLENDER_USER_RESOURCES"] = tempfile.mkdtemp(prefix="madder-bench-")

import bpy  # noqa: E402
import demo  # noqa: E402
import harness  # noqa: E402


def bake(blend, size, detail, images):
    """One bake of the demo's spill on a fresh load of `blend`; returns its wall time (s)."""
    bpy.ops.wm.open_mainfile(filepath=blend)
    s = demo.configure(size).madder
    s.detail = detail
    s.output_vertex_colors = True
    s.output_images = images
    start = time.perf_counter()
    assert bpy.ops.madder.bake() == {"FINISHED"}
    return time.perf_counter() - start


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", default="1024", help="image size, px")
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--detail", type=int, default=1)
    args = ap.parse_args()
    work = tempfile.mkdtemp(prefix="madder-image-bake-")
    blend = os.path.join(work, "tablecloth.blend")
    demo.build_scene(blend)  # before the add-on: the factory settings would disable it
    harness.install_extension(harness.default_zip())
    times = {False: [], True: []}
    for _ in range(args.rounds):
        for images in (False, True):
            times[images].append(bake(blend, args.size, args.detail, images))
    plain, textured = (statistics.median(times[k]) for k in (False, True))
    n = len(bpy.data.objects["Tablecloth"].data.vertices)
    print(
        f"image sequence in the bake: the demo's spill ({n} vertices, Detail {args.detail}, {demo.FRAMES} frames), "
        f"{os.cpu_count()} cores: vertex colours {plain:.1f} s, with {args.size} px images too {textured:.1f} s "
        f"({1e3 * (textured - plain) / demo.FRAMES:.0f} ms a frame for the images): "
        f"{textured / plain:.2f}x (target <= 2x)"
    )
    modes = {"off": (False, False), "within a texel": (True, False), "in the shader": (True, True)}
    spent = {mode: [] for mode in modes}
    s = bpy.data.objects["Tablecloth"].madder
    for _ in range(args.rounds):
        for mode, (sharp, shader) in modes.items():
            s.sharp_outline, s.outline_in_shader = sharp, shader
            start = time.perf_counter()
            assert bpy.ops.madder.export_textures() == {"FINISHED"}
            spent[mode].append(time.perf_counter() - start)
    print(f"Re-export Textures of the {demo.FRAMES} frames at {args.size} px, Sharp Outline "
          + ", ".join(f"{mode}: {statistics.median(t):.1f} s" for mode, t in spent.items()))


if __name__ == "__main__":
    main()
    harness.exit(0)
