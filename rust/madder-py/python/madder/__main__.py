"""`python -m madder bake scene.blend [...]`: the Madder command line with the `bpy` module
(Blender as a Python module), where there is no `blender --command`. It enables the
Madder extension installed in this Blender's user extensions and runs its command line
(see the add-on's `cli.py` for the options)."""

import importlib
import os
import sys


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    try:
        import bpy
    except ImportError:
        print("madder: error: needs Blender's bpy module (pip install bpy) or `blender --command madder`", file=sys.stderr)
        return 2
    import addon_utils  # on sys.path once bpy is imported

    names = [m.__name__ for m in addon_utils.modules() if m.__name__.startswith("bl_ext.") and m.__name__.endswith(".madder")]
    if not names:
        where = bpy.utils.user_resource("EXTENSIONS")
        print(f"madder: error: the Madder extension is not installed in {where}; install the extension zip first", file=sys.stderr)
        return 2
    addon_utils.enable(names[0], default_set=True)
    return importlib.import_module(names[0] + ".cli").main(argv)


def _exit(code):
    """bpy 4.2 from PyPI crashes (SIGSEGV) when the interpreter exits after an add-on with
    property update callbacks was enabled, as Madder is here; end at once with the real
    status there (4.5 and 5.0 exit normally; a Blender binary never runs this file)."""
    bpy = sys.modules.get("bpy")
    if bpy is not None and bpy.app.version < (4, 5, 0):
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)
    sys.exit(code)


if __name__ == "__main__":
    _exit(main())
