"""Madder: stains on moving cloth. This file only registers the add-on's parts.

The parts that use bpy are imported when the add-on registers (or when one is asked for,
e.g. `madder.addon.cli`), not on import: the package's bpy-free modules (those that import
bpy neither themselves nor through another; tests/python/test_addon_logic.py finds them from
the source and imports each with bpy blocked) can then be imported, and tested, without
Blender."""

import importlib

_PARTS = ("splash_props", "properties", "fabrics", "operators", "shading", "panels", "handlers", "preview", "cli")


def __getattr__(name):
    if name in _PARTS:
        return importlib.import_module(f"{__name__}.{name}")
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def register():
    for name in _PARTS:
        importlib.import_module(f"{__name__}.{name}").register()


def unregister():
    for name in reversed(_PARTS):
        importlib.import_module(f"{__name__}.{name}").unregister()
