"""Bind and bake (3D View): register a take to the head and bake the face rig as shape keys."""

from .operators import OPERATORS
from .panels import PANELS

__all__ = ["OPERATORS", "PANELS"]
