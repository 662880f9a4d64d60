"""The `madder` command line, for render farms and pipelines:

    blender -b scene.blend --command madder bake [--object NAME ... | --all] [--frames A-B | A] [--no-save]
    blender -b --command madder bake scene.blend [...]
    python -m madder bake scene.blend [...]          (the bpy module, no Blender binary)

It blocks until every bake is done, prints progress, saves the .blend (so the objects
remember their caches; `--no-save` skips that) and exits 0, or exits 1 with the reason on
stderr (2 for a usage error). Without `--object`, every object with Madder Stain enabled
is baked."""

import argparse
import sys
import time

import bpy

from . import bake, frames, textures

_handle = None


# the frame arguments' parsing is bpy-free, in `frames`
_frame_range, _join_frames = frames.parse_range, frames.join_frames


def _parser():
    ap = argparse.ArgumentParser(prog="madder", description="Madder: bake stains on moving cloth.")
    sub = ap.add_subparsers(dest="command", required=True)
    b = sub.add_parser("bake", help="bake the stains of a .blend file")
    b.add_argument("blend", nargs="?", help=".blend file to open (default: the file already loaded)")
    who = b.add_mutually_exclusive_group()
    who.add_argument("--object", action="append", dest="objects", metavar="NAME", help="object to bake (repeatable)")
    who.add_argument("--all", action="store_true", help="every object with Madder Stain enabled (the default)")
    b.add_argument("--frames", type=_frame_range, metavar="A-B",
                   help="frame range, or one frame; negative frames are fine (-5-3) (default: the scene's)")
    b.add_argument("--no-save", action="store_true", help="do not save the .blend after baking")
    return ap


def _say(msg):
    print(f"madder: {msg}", flush=True)


def _fail(msg, code=1):
    print(f"madder: error: {msg}", file=sys.stderr, flush=True)
    return code


def main(argv):
    """Runs the command line `argv` (without the program name); returns the exit code."""
    try:
        args = _parser().parse_args(_join_frames(argv))
    except SystemExit as e:  # argparse printed the usage or the help
        return 0 if e.code in (0, None) else 2
    if args.blend:
        try:
            bpy.ops.wm.open_mainfile(filepath=args.blend)
        except RuntimeError as e:
            return _fail(f"cannot open {args.blend}: {e}")
    if not bpy.data.filepath:
        return _fail("no .blend file is loaded: pass one, e.g. `madder bake scene.blend`", 2)
    scene = bpy.context.scene
    if args.objects:
        missing = [n for n in args.objects if n not in bpy.data.objects]
        if missing:
            return _fail(f"{bpy.data.filepath} has no object named {', '.join(repr(n) for n in missing)}")
        objs = [bpy.data.objects[n] for n in args.objects]
    else:
        objs = [o for o in scene.objects if o.type == "MESH" and o.madder.enabled]
        if not objs:
            return _fail(f"no object in {bpy.data.filepath} has Madder Stain enabled (use --object NAME)")

    for obj in objs:
        t0 = time.perf_counter()
        step = [0]

        def progress(done, total, obj=obj, step=step):
            tenth = 10 * done // total
            if tenth > step[0]:
                step[0] = tenth
                _say(f"'{obj.name}' {done}/{total} frames")

        try:
            path, warnings = bake.bake(scene, obj, progress, frames=args.frames)
        except bake.BakeError as e:
            return _fail(str(e))
        obj.madder.enabled = True
        for w in warnings:
            _say(f"warning: '{obj.name}': {w}")
        also = f" and {textures.image_folder(path)}" if obj.madder.image_baked else ""
        _say(f"baked '{obj.name}' in {time.perf_counter() - t0:.2f} s -> {path}{also}")
    if not args.no_save:
        bpy.ops.wm.save_mainfile()
        _say(f"saved {bpy.data.filepath}")
    return 0


def register():
    global _handle
    # `blender --command` needs a Blender binary; in the bpy module the command is registered
    # all the same (harmless, and what the farm tests' stand-in for the binary runs). bpy
    # 4.2 crashes at the interpreter's exit while a command is registered: every entry point
    # of ours ends such a process with `os._exit` there (harness.exit, `python -m madder`).
    if hasattr(bpy.utils, "register_cli_command"):  # Blender 4.2+
        _handle = bpy.utils.register_cli_command("madder", main)


def unregister():
    global _handle
    if _handle is not None:
        bpy.utils.unregister_cli_command(_handle)
        _handle = None
