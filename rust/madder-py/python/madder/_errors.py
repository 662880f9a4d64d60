"""Madder's exception hierarchy. The native module raises these; catch `MadderError` for all.

Each exception carries the fields of the core's error as attributes, None when its variant
has no such field: `vertex`, `face`, `frame`, `cell` ((row, column) of a weave tile),
`name` (of a parameter), and others named in `_errors.rs`'s mapping (`expected`, `got`,
`value`, `line`...). A cache or point-cache error names its file in `filename`; one that
an I/O failure caused is also the built-in kind (`FileNotFoundError`, `PermissionError`,
`IsADirectoryError`, `NotADirectoryError`) with its `errno`."""

import errno as _errno

from ._core import MadderError


class _Located:
    """Where an error is: the attributes every Madder exception has (None when unknown)."""

    vertex = None
    face = None
    frame = None
    cell = None
    name = None


class MeshError(_Located, MadderError, ValueError):
    """Bad mesh input: the message (and `face`, `vertex`) names the face or vertex."""


class ParameterError(_Located, MadderError, ValueError):
    """A parameter out of its valid range: `name` is the parameter, `value` its value."""


class SolveError(_Located, MadderError):
    """A linear solve failed (the system was not positive definite)."""


class CacheError(_Located, MadderError, OSError):
    """A cache, point-cache or image file is missing, truncated, corrupt or cannot be
    written: `filename` (and `frame`) say where."""

    def __str__(self):
        # the core's message, which names the file already (OSError's own form would be
        # "[Errno n] strerror: 'filename'" once `filename` is set)
        return str(self.args[0]) if len(self.args) == 1 else OSError.__str__(self)


class FabricError(_Located, MadderError, ValueError):
    """A weave tile or cell tensor is invalid: `cell` is its (row, column)."""


class CacheNotFoundError(CacheError, FileNotFoundError):
    """A cache or point-cache file that does not exist."""


class CachePermissionError(CacheError, PermissionError):
    """A cache or point-cache file that may not be read or written."""


class CacheIsADirectoryError(CacheError, IsADirectoryError):
    """A cache path that is a folder."""


class CacheNotADirectoryError(CacheError, NotADirectoryError):
    """A cache path under something that is not a folder."""


_IO_KINDS = {
    _errno.ENOENT: CacheNotFoundError,
    _errno.EACCES: CachePermissionError,
    _errno.EPERM: CachePermissionError,
    _errno.EISDIR: CacheIsADirectoryError,
    _errno.ENOTDIR: CacheNotADirectoryError,
}


def _from_core(cls, message, fields):
    """The exception of class `cls` with `message` and the core variant's `fields` as
    attributes (called by the binding, `errors.rs`). A CacheError with an `errno` becomes
    the matching built-in I/O kind."""
    if cls is CacheError and fields.get("errno") is not None:
        cls = _IO_KINDS.get(fields["errno"], CacheError)
    err = cls(message)
    for key, value in fields.items():
        setattr(err, key, value)
    return err
