"""Track (Movie Clip Editor) and the take (3D View): the rigid markers, tracking a rig video or the clip's own tracks to a C3D take, importing a take as empties."""

from .operators import OPERATORS
from .panels import PANELS

__all__ = ["OPERATORS", "PANELS"]
