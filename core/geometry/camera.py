"""The pinhole camera with lens distortion, and the one place where pixels are
undistorted and normalised.

Conventions (used across the core):

* Pixel coordinates are OpenCV's: origin at the centre of the top-left pixel,
  x to the right, y down.
* The camera frame is OpenCV's: x right, y down, z forward (optical axis), in
  millimetres once a scale is known.
* *Normalised* coordinates are undistorted image coordinates with focal length
  1 (``x_n = X/Z``, ``y_n = Y/Z``) -- the "normalised camera" of Lin (2003), ch. 3,
  where ``f = 1``. Every geometric algorithm in :mod:`core.geometry.mirror` works on them.

CAMERA.json format::

    {"K": [[fx, 0, cx], [0, fy, cy], [0, 0, 1]],
     "dist": [k1, k2, p1, p2, k3]   (or [], or OpenCV's 4/8/12/14 coefficients),
     "image_size": [width, height]}
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..common.errors import InputError
from ..common.files import read_json

_DIST_LENGTHS = (0, 4, 5, 8, 12, 14)


@dataclass(frozen=True)
class Camera:
    """An OpenCV camera: intrinsic matrix ``K`` (3, 3), distortion ``dist`` (n,),
    and the image size ``(width, height)`` in pixels."""

    K: np.ndarray
    dist: np.ndarray = field(default_factory=lambda: np.zeros(0))
    image_size: tuple[int, int] = (0, 0)

    def __post_init__(self):
        K = np.asarray(self.K, dtype=float)
        dist = np.asarray(self.dist, dtype=float).ravel()
        if K.shape != (3, 3) or not np.all(np.isfinite(K)):
            raise InputError("camera K must be a finite 3x3 matrix")
        if K[0, 0] <= 0 or K[1, 1] <= 0 or K[2, 2] != 1 or np.any(K[1:, 0] != 0) or np.any(K[2, :2] != 0):
            raise InputError("camera K must look like [[fx,s,cx],[0,fy,cy],[0,0,1]] with fx, fy > 0")
        if dist.size not in _DIST_LENGTHS or not np.all(np.isfinite(dist)):
            raise InputError(
                f"camera dist must hold 0, 4, 5, 8, 12 or 14 finite coefficients, got {dist.size}"
            )
        w, h = (int(v) for v in self.image_size)
        if w < 0 or h < 0:
            raise InputError("camera image_size must be two non-negative integers [width, height]")
        object.__setattr__(self, "K", K)
        object.__setattr__(self, "dist", dist)
        object.__setattr__(self, "image_size", (w, h))

    # ------------------------------------------------------------------ basics
    @property
    def focal_px(self) -> float:
        """Mean focal length in pixels; converts normalised lengths to pixels."""
        return 0.5 * (self.K[0, 0] + self.K[1, 1])

    @property
    def has_distortion(self) -> bool:
        return bool(self.dist.size and np.any(self.dist != 0))

    @classmethod
    def ideal(cls, focal_px: float, image_size: tuple[int, int]) -> "Camera":
        """A distortion-free camera with square pixels and the principal point at the
        image centre (the simulated CCD of Lin 2003, section 6.2)."""
        w, h = image_size
        K = np.array([[focal_px, 0.0, (w - 1) / 2.0], [0.0, focal_px, (h - 1) / 2.0], [0.0, 0.0, 1.0]])
        return cls(K=K, dist=np.zeros(0), image_size=(w, h))

    # --------------------------------------------------------------- conversions
    def normalize(self, pixels) -> np.ndarray:
        """Pixels ``(..., 2)`` -> undistorted normalised coordinates ``(..., 2)``.

        This is the one documented place where lens distortion is removed. Without
        distortion it is the exact inverse of ``K``; with distortion it uses
        OpenCV's iterative ``undistortPoints``.
        """
        pts = np.asarray(pixels, dtype=float)
        if pts.shape[-1] != 2:
            raise InputError("pixel coordinates must have shape (..., 2)")
        if self.has_distortion:
            import cv2

            flat = np.ascontiguousarray(pts.reshape(-1, 1, 2))
            # A tight stopping rule: the default 5 iterations leave ~0.01 px error
            # for strong distortion, too much for the sub-pixel claims of the core.
            crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-12)
            out = cv2.undistortPointsIter(flat, self.K, self.dist, None, None, crit)
            return out.reshape(pts.shape)
        fx, s, cx = self.K[0]
        fy, cy = self.K[1, 1], self.K[1, 2]
        yn = (pts[..., 1] - cy) / fy
        xn = (pts[..., 0] - cx - s * yn) / fx
        return np.stack([xn, yn], axis=-1)

    def denormalize(self, normalized) -> np.ndarray:
        """Normalised coordinates ``(..., 2)`` -> pixels ``(..., 2)``, applying distortion."""
        pts = np.asarray(normalized, dtype=float)
        if self.has_distortion:
            import cv2

            flat = np.concatenate([pts.reshape(-1, 2), np.ones((pts.size // 2, 1))], axis=1)
            out, _ = cv2.projectPoints(flat, np.zeros(3), np.zeros(3), self.K, self.dist)
            return out.reshape(pts.shape)
        x, y = pts[..., 0], pts[..., 1]
        u = self.K[0, 0] * x + self.K[0, 1] * y + self.K[0, 2]
        v = self.K[1, 1] * y + self.K[1, 2]
        return np.stack([u, v], axis=-1)

    def project(self, points) -> np.ndarray:
        """3D points ``(..., 3)`` in the camera frame -> pixels ``(..., 2)``."""
        pts = np.asarray(points, dtype=float)
        return self.denormalize(pts[..., :2] / pts[..., 2:3])

    def ideal_pixels(self, normalized) -> np.ndarray:
        """Normalised coordinates -> *undistorted* pixels (``K`` only, no distortion).

        Distances measured here are in pixels but along straight lines, which is
        what the mirrored epipolar band of eq. 5.2-5.3 needs."""
        pts = np.asarray(normalized, dtype=float)
        x, y = pts[..., 0], pts[..., 1]
        return np.stack(
            [self.K[0, 0] * x + self.K[0, 1] * y + self.K[0, 2], self.K[1, 1] * y + self.K[1, 2]], axis=-1
        )

    # ------------------------------------------------------------------- files
    def to_dict(self) -> dict:
        return {"K": self.K.tolist(), "dist": self.dist.tolist(), "image_size": list(self.image_size)}

    @classmethod
    def from_dict(cls, data: dict, source: str = "camera") -> "Camera":
        if not isinstance(data, dict):
            raise InputError(f"{source}: expected a JSON object with K, dist and image_size")
        missing = [k for k in ("K", "image_size") if k not in data]
        if missing:
            raise InputError(f"{source}: missing key(s) {', '.join(missing)}")
        try:
            K = np.array(data["K"], dtype=float)
            dist = np.array(data.get("dist", []), dtype=float)
            size = data["image_size"]
            if len(size) != 2 or any(not float(v).is_integer() or v <= 0 for v in size):
                raise ValueError
            size = (int(size[0]), int(size[1]))
        except (TypeError, ValueError):
            raise InputError(f"{source}: K must be 3x3 numbers, dist a list of numbers, "
                             "image_size two positive integers") from None
        try:
            return cls(K=K, dist=dist, image_size=size)
        except InputError as exc:
            raise InputError(f"{source}: {exc}") from None

    @classmethod
    def load(cls, path) -> "Camera":
        return cls.from_dict(read_json(path, "camera file"), source=f"camera file {path}")

    def contains(self, pixels, margin: float = 0.5) -> np.ndarray:
        """Boolean mask ``(...)``: pixel lies inside the image (with a margin in px)."""
        w, h = self.image_size
        p = np.asarray(pixels, dtype=float)
        return (
            (p[..., 0] >= -margin) & (p[..., 0] <= w - 1 + margin)
            & (p[..., 1] >= -margin) & (p[..., 1] <= h - 1 + margin)
        )


def angle_deg(u, v) -> np.ndarray:
    """Angle in degrees between vectors ``(..., 3)`` (orientation matters: pass
    consistently oriented normals)."""
    u = np.asarray(u, dtype=float)
    v = np.asarray(v, dtype=float)
    # atan2 of |u x v| and u.v is accurate for tiny angles (acos is not).
    cross = np.linalg.norm(np.cross(u, v), axis=-1)
    dot = np.sum(u * v, axis=-1)
    return np.degrees(np.arctan2(cross, dot))


__all__ = ["Camera", "angle_deg"]
