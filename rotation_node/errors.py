"""
Exception types of rotation_node.

Every error the package raises on bad input is a ``ValueError`` (or a subclass
of it) whose message names the argument, key or file that was wrong.
"""


class RotationNodeError(Exception):
    """Base class of the package's own errors."""


class BagError(RotationNodeError, ValueError):
    """An MCAP bag could not be read or written (corrupt, truncated, unknown type...)."""


class DiskFullError(BagError):
    """The disk filled while a bag was written: ``kept`` messages are in it, ``dropped`` not."""

    def __init__(self, message: str, *, kept: int, dropped: int) -> None:
        super().__init__(message)
        self.kept = kept
        self.dropped = dropped


class SceneError(RotationNodeError, ValueError):
    """A scene file is invalid: an unknown key, a missing field or a bad value."""


class ParameterError(RotationNodeError, ValueError):
    """A node parameter (or parameters file entry) has an invalid value."""


class ComparisonError(RotationNodeError, ValueError):
    """Two orientation streams cannot be compared as asked (no overlap, too few samples)."""


class DegenerateMotionError(ComparisonError):
    """The motion does not determine what was asked (one rotation axis only, too little motion)."""
