"""Madder: stains on moving cloth. This file only registers the add-on's parts."""

from . import cli, fabrics, handlers, operators, panels, properties, shading

_modules = (properties, fabrics, operators, shading, panels, handlers, cli)


def register():
    for m in _modules:
        m.register()


def unregister():
    for m in reversed(_modules):
        m.unregister()
