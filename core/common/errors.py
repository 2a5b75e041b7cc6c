"""Errors the core raises for bad input.

Every user-facing failure of the core is a :class:`MirrorCapError` carrying one
clear sentence. The CLI prints it and exits non-zero; the Blender operators turn
it into ``self.report({'ERROR'}, ...)``.
"""


class MirrorCapError(Exception):
    """Bad input or an impossible request, described in one sentence."""


class InputError(MirrorCapError):
    """A file or argument the user gave is malformed."""


class DegenerateError(MirrorCapError):
    """The data is well-formed but cannot determine the unknowns (e.g. collinear points)."""
