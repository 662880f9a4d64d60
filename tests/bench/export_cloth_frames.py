"""Exports the cloth motion of the flag and tablecloth fixtures (blend_fixtures/) to .npz
(faces (F, 3) uint32, frames (T, N, 3) float64, start, rate) for the codec benchmark
(tests/bench/bench_codec.py). Runs in the venv's bpy; no add-on needed.

    .venv/bin/python tests/bench/export_cloth_frames.py OUT_DIR [--frames N]
"""

import argparse
import pathlib
import sys

import bpy
import numpy as np

ROOT = pathlib.Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "blend_fixtures"))
from harness import frame_mesh  # noqa: E402

FIXTURES = {"flag": ("flag.blend", "Flag"), "tablecloth": ("tablecloth.blend", None)}


def cloth_object(name):
    if name is not None:
        return bpy.data.objects[name]
    for obj in bpy.data.objects:
        if obj.type == "MESH" and any(m.type == "CLOTH" for m in obj.modifiers):
            return obj
    raise SystemExit("no object with a cloth modifier")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("out", type=pathlib.Path)
    ap.add_argument("--frames", type=int, default=0, help="at most this many (0: the scene's)")
    args = ap.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    for key, (blend, obj_name) in FIXTURES.items():
        bpy.ops.wm.open_mainfile(filepath=str(ROOT / "blend_fixtures" / blend))
        scene = bpy.context.scene
        obj = cloth_object(obj_name)
        end = scene.frame_end
        if args.frames:
            end = min(end, scene.frame_start + args.frames - 1)
        faces, frames = None, []
        for f in range(scene.frame_start, end + 1):
            scene.frame_set(f)
            faces, pos = frame_mesh(obj)
            frames.append(pos)
        np.savez(
            args.out / f"{key}.npz",
            faces=faces,
            frames=np.array(frames),
            start=float(scene.frame_start),
            rate=1.0,
        )
        print(f"{key}: {obj.name}, {len(frames[0])} vertices, {len(frames)} frames", file=sys.stderr)


if __name__ == "__main__":
    main()
