"""`make bench`: what the look a preset carries (issue 34) costs a bake, before and after,
in one process, measured from outside as a user meets it (`bpy.ops.madder.bake()`).

"After" is what a user gets today. "Before" is the same scene with the issue's mechanisms
switched off, each by its own setting, as the issue found a new user's bake: no wicking
(and so no settled front), no grain, no carried solute and so no rim (no residual
saturation, no vapour-limited drying, no dispersion), no run holdup and no drip at the
hem, the Spill Group's weights laid as they are (not a pool), Detail 0 and no images (and
so no Sharp Outline), and no directed splash.

Two scenes:
- the flag fixture (`blend_fixtures/flag.blend`: a 2 × 1.2 m flag in wind, 41 × 25
  vertices, 48 frames, its Spill Group) with only the Red Wine preset chosen: the
  out-of-box bake;
- the demo (`blend_fixtures/demo.py`: the tablecloth falling onto the table with a glass
  of wine thrown on it, 112 frames), configured as `demo.configure` does; with `--demo-detail`
  its after-bake's Detail is set by hand (CI's demo bakes at 1; Auto gives 2 and about a
  quarter of an hour on 2 cores). `--no-demo` leaves it out.

Rounds interleave before and after, so the machine's drift hits both. Prints each bake's
median wall time, its Detail and image size, and the ratio; asserts nothing.
"""

import argparse
import os
import shutil
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


def switch_off(s):
    """The issue's mechanisms off on the object settings `s` (the Liquid turns Custom,
    keeping the preset's other values)."""
    s.wicking = 0.0
    s.front_settles = False
    s.grain_from, s.irregularity = "OBJECT", 0.0
    s.carry_solute = False
    s.residual_saturation, s.vapour_limited, s.dispersivity = 0.0, False, 0.0
    s.holdup, s.drip_hold = 0.0, 0.0
    s.spill_shape = "WEIGHTS"
    s.detail_auto, s.detail = False, 0
    s.output_images = False
    s.splash.throw = None


def flag_scene(blend, before):
    bpy.ops.wm.open_mainfile(filepath=blend)
    flag = bpy.data.objects["Flag"]
    bpy.context.view_layer.objects.active = flag
    s = flag.madder
    s.enabled, s.source_group, s.liquid = True, "stain_source", "RED_WINE"
    if before:
        switch_off(s)
    return flag


def demo_scene(blend, before, detail=None):
    bpy.ops.wm.open_mainfile(filepath=blend)
    cloth = demo.configure(detail=None if before else detail)
    if before:
        switch_off(cloth.madder)
    return cloth


def bake(scene, blend, before):
    """One bake of `scene(blend, before)` (a fresh load of `blend`, set up); returns
    (seconds, Detail, image size or 0)."""
    obj = scene(blend, before)
    start = time.perf_counter()
    assert bpy.ops.madder.bake() == {"FINISHED"}
    spent = time.perf_counter() - start
    s = obj.madder
    return spent, s.bake_detail, s.image_baked_size if s.image_baked else 0


def compare(label, scene, blend, rounds):
    runs = {False: [], True: []}
    for _ in range(rounds):
        for before in (True, False):
            runs[before].append(bake(scene, blend, before))
    line = []
    for before in (True, False):
        t = statistics.median(r[0] for r in runs[before])
        _, level, size = runs[before][-1]
        line.append((t, f"{'before' if before else 'after'} {t:.1f} s (Detail {level}, "
                        f"{f'{size} px images' if size else 'no images'})"))
    print(f"{label}, {os.cpu_count()} cores, median of {rounds}: {line[0][1]}, {line[1][1]}: "
          f"{line[1][0] / line[0][0]:.1f}x", flush=True)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=3, help="interleaved rounds of the flag")
    ap.add_argument("--demo-rounds", type=int, default=1)
    ap.add_argument("--demo-detail", type=int, default=None,
                    help="the demo's Detail after (default: Auto, as a user gets it)")
    ap.add_argument("--no-demo", action="store_true")
    args = ap.parse_args()
    work = tempfile.mkdtemp(prefix="madder-look-bench-")
    flag = os.path.join(work, "flag.blend")
    shutil.copyfile(os.path.join(ROOT, "blend_fixtures", "flag.blend"), flag)
    table = os.path.join(work, "tablecloth.blend")
    if not args.no_demo:
        demo.build_scene(table)  # before the add-on: the factory settings would disable it
    harness.install_extension(harness.default_zip())
    compare("out-of-box flag (Red Wine preset only)", flag_scene, flag, args.rounds)
    if not args.no_demo:
        compare(f"demo ({demo.FRAMES} frames)", lambda blend, before: demo_scene(blend, before, args.demo_detail),
                table, args.demo_rounds)
    shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
    harness.exit(0)
