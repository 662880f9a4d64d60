"""`python -m madder bake scene.blend [...]`: the Madder command line with the `bpy` module
(Blender as a Python module), where there is no `blender --command`.

It needs nothing but `pip install bpy madder-<version>.whl`: the wheel carries the
add-on's Python code as `madder.addon` (copied in at build time from the repository's
`addon/`, so there is one source). Which add-on runs:

- a Madder extension installed in this Blender's extension repositories (the user's own
  version, the one their UI uses) when there is one;
- otherwise the add-on packaged in this wheel, registered directly with `bpy`.

The first line of output says which one ran. The options are the add-on's (`cli.py`)."""

import importlib
import os
import sys


def _say(msg):
    print(f"madder: {msg}", flush=True)


def _installed_extension(addon_utils):
    """The module name (`bl_ext.<repo>.madder`) of an installed Madder extension, or None."""
    names = sorted(
        m.__name__ for m in addon_utils.modules() if m.__name__.startswith("bl_ext.") and m.__name__.endswith(".madder")
    )
    return names[0] if names else None


def load_addon():
    """Registers the Madder add-on with `bpy` (the installed extension if any, else the
    packaged one) and returns its `cli` module. Raises RuntimeError when it cannot."""
    import addon_utils  # on sys.path once bpy is imported
    import bpy

    name = _installed_extension(addon_utils)
    if name is not None:
        if name not in bpy.context.preferences.addons and addon_utils.enable(name, default_set=True) is None:
            raise RuntimeError(f"the installed Madder extension {name} failed to enable (see the traceback above)")
        module = importlib.import_module(name)
        _say(f"using the Madder extension {name} installed in {os.path.dirname(module.__file__)}")
        return importlib.import_module(name + ".cli")
    try:
        from . import addon
    except ImportError as e:
        raise RuntimeError(
            f"this madder wheel carries no add-on ({e}); build it with `make wheel`, or install the extension zip"
        ) from e
    from . import __version__

    if not hasattr(bpy.types.Object, "madder"):
        addon.register()
    _say(f"using the add-on packaged in the madder {__version__} wheel ({os.path.dirname(addon.__file__)})")
    return addon.cli


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    try:
        import bpy  # noqa: F401
    except ImportError:
        print(
            "madder: error: needs Blender's bpy module (pip install bpy: 5.1 and later on CPython 3.13, "
            "4.2-5.0 on CPython 3.11) "
            "or `blender --command madder`",
            file=sys.stderr,
        )
        return 2
    try:
        cli = load_addon()
    except RuntimeError as e:
        print(f"madder: error: {e}", file=sys.stderr)
        return 2
    return cli.main(argv)


def _exit(code):
    """The bpy modules from PyPI before 5.0 crash (SIGSEGV) when the interpreter exits after
    this command ran: 4.2 once an add-on with property update callbacks was enabled, 4.5
    after the add-on packaged in the wheel was registered (every time, on 4.5.15). End at
    once with the real status there (5.0 exits normally; a Blender binary never runs this
    file)."""
    bpy = sys.modules.get("bpy")
    if bpy is not None and bpy.app.version < (5, 0, 0):
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)
    sys.exit(code)


if __name__ == "__main__":
    _exit(main())
