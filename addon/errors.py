"""The add-on's own errors, bpy-free. Each carries where it happened as attributes, as the
core's exceptions do (`madder._errors`): `object` (the object's name), `frame` (the scene
frame), and for some `material` or `filename`; None when it does not apply. The message
names them too, for the user."""


class AddonError(Exception):
    """Base of the add-on's errors: `object`, `frame` and any further fields as attributes."""

    object = None
    frame = None

    def __init__(self, message, **fields):
        super().__init__(message)
        for key, value in fields.items():
            setattr(self, key, value)


class BakeError(AddonError):
    """A bake cannot start or go on: the message names the object and, once frames are
    being read, the frame (`object`, `frame`)."""


class FabricSettingsError(AddonError):
    """A material's fabric cannot be homogenized (`material`; `object` once known)."""


class RelocateError(AddonError):
    """A file picked by Relocate Cache is not this object's cache (`object`, `filename`)."""


class ExportError(AddonError):
    """An image sequence cannot be written (`filename`: the file or folder; `object` once
    known)."""


class LcsError(AddonError):
    """Coherent structures cannot be computed from a bake (`object`, `frame`, `filename`:
    the cache)."""


class MotionCodecError(AddonError):
    """A cloth's motion cannot be compressed into a .madm file or decompressed from one
    (`object`, `frame`, `vertex`, `filename`: the file at fault)."""
