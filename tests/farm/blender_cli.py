"""Runs a Blender command line with the `bpy` module, for the Flamenco tests: there is no
Blender binary here. It handles, in order as Blender does, only the arguments Madder's job
type passes (anything else is refused, so the test cannot pass by ignoring one):

    -b, -y, --factory-startup, FILE.blend, --scene NAME, --python-exit-code N,
    --python-expr CODE, --command ID ARGS..., --render-output PATH, --render-format FMT,
    --render-frame A..B,C

`--command` runs the callback an add-on registered with `bpy.utils.register_cli_command`
(recorded here as it registers) and exits with its code, like Blender."""

import os
import sys
import traceback

import bpy

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "blend_fixtures"))
import harness  # noqa: E402  (ends the process as bpy 4.2 needs: harness.exit)

_commands = {}
_register = bpy.utils.register_cli_command


def _record(cli_id, execute):
    _commands[cli_id] = execute
    return _register(cli_id, execute)


bpy.utils.register_cli_command = _record


def frames(spec):
    out = []
    for part in spec.split(","):
        a, _, b = part.partition("..")
        out.extend(range(int(a), int(b or a) + 1))
    return out


def run(argv):
    exit_code = 0
    i = 0
    while i < len(argv):
        arg = argv[i]
        i += 1
        scene = bpy.context.scene
        if arg in ("-b", "--background", "-y", "--enable-autoexec"):
            continue
        if arg == "--factory-startup":
            bpy.ops.wm.read_factory_settings(use_empty=True)
        elif arg.endswith(".blend"):
            bpy.ops.wm.open_mainfile(filepath=arg)
        elif arg == "--scene":
            if argv[i] != scene.name:  # the bpy module has no window to switch scenes in
                raise SystemExit(f"blender_cli: cannot switch to scene {argv[i]!r}")
            i += 1
        elif arg == "--python-exit-code":
            exit_code = int(argv[i])
            i += 1
        elif arg == "--python-expr":
            try:
                exec(compile(argv[i], "<string>", "exec"), {"__name__": "__main__"})
            except Exception:
                traceback.print_exc()
                if exit_code:
                    return exit_code
            i += 1
        elif arg in ("-c", "--command"):
            cli_id, rest = argv[i], argv[i + 1 :]
            if cli_id not in _commands:
                print(f"Unrecognized command: {cli_id!r}", file=sys.stderr)
                return 1
            return _commands[cli_id](rest)
        elif arg in ("-o", "--render-output"):
            scene.render.filepath = argv[i]
            i += 1
        elif arg in ("-F", "--render-format"):
            scene.render.image_settings.file_format = argv[i]
            i += 1
        elif arg in ("-f", "--render-frame"):
            for f in frames(argv[i]):
                scene.frame_start = scene.frame_end = f
                bpy.ops.render.render(animation=True)
            i += 1
        else:
            raise SystemExit(f"blender_cli: argument {arg!r} is not handled here")
    return 0


if __name__ == "__main__":
    harness.exit(run(sys.argv[1:]))
