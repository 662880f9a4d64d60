"""Madder's exception hierarchy. The native module raises these; catch `MadderError` for all."""

from ._core import MadderError


class MeshError(MadderError, ValueError):
    """Bad mesh input: the message names the face, vertex or frame."""


class ParameterError(MadderError, ValueError):
    """A parameter out of its valid range."""


class SolveError(MadderError):
    """A linear solve failed (the system was not positive definite)."""


class CacheError(MadderError, OSError):
    """A cache file is missing, truncated or corrupt: the message names file and frame."""


class FabricError(MadderError, ValueError):
    """A weave tile or cell tensor is invalid: the message names the cell."""
