"""Head (3D View): add the generic head, fit it to the performer's scan."""

from .operators import OPERATORS
from .panels import PANELS

__all__ = ["OPERATORS", "PANELS"]
