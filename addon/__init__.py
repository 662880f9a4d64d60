"""Madder: stains on moving cloth. This file only registers the add-on's parts.

The parts that use bpy are imported when the add-on registers (or when one is asked for,
e.g. `madder.addon.cli`), not on import: the package's bpy-free modules (`presets`,
`placement`, `motion`, `codec`, `pour`, `schedule`, `live`, `textures`, `errors`) can then be
imported, and tested, without Blender."""

import importlib

_PARTS = ("properties", "fabrics", "operators", "shading", "panels", "handlers", "preview", "cli")


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
