"""Capture (Movie Clip Editor): open the rig video, calibrate the camera, detect markers, solve the mirrors from a board."""

from .operators import OPERATORS
from .panels import PANELS

__all__ = ["OPERATORS", "PANELS"]
