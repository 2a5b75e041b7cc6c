"""Retargeting (3D View and ``mirrorcap retarget``): a take's expressions as ARKit-52 weights keyed on
any character's shape keys of the same names (and the Live Link Face CSV), or the motion itself
transferred onto a character with landmarks (placed by clicking or guessed); MPEG-4 FAPs."""

from .operators import OPERATORS
from .panels import PANELS

__all__ = ["OPERATORS", "PANELS"]
