"""One frame of correspondences -> mirror planes and 3D points (``mirrorcap reconstruct``).

The steps follow "the proposed algorithm" of Lin (2003), section 3.2, per mirror,
with three additions a real rig needs: wrong correspondences are rejected
(RANSAC), the two mirrors' independent scales are tied together through markers
seen in both, and an optional maximum-likelihood refinement runs before the
known-length scale (step 3) is applied.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from ..common.errors import DegenerateError, InputError
from .camera import Camera
from .mirror import (
    MirrorPlane,
    estimate_mirror_plane,
    link_mirror_scales,
    points_from_planes,
    scale_to_length,
)
from .refine import refine_reconstruction

MIN_PAIRS_PER_MIRROR = 6


@dataclass
class PairTable:
    """Correspondences grouped by marker: ``ids`` (n,), ``direct_px`` (n, 2),
    ``mirror_px`` (K, n, 2) and ``visible`` (K, n) for mirrors ``0..K-1``."""

    ids: list
    direct_px: np.ndarray
    mirror_px: np.ndarray
    visible: np.ndarray

    @property
    def n_mirrors(self) -> int:
        return self.visible.shape[0]


@dataclass
class KnownLength:
    id_a: str
    id_b: str
    millimetres: float


@dataclass
class PairReconstruction:
    ids: list
    points: np.ndarray  # (n, 3)
    mirrors_label: list  # "0", "1", "0+1" per point
    planes: list  # MirrorPlane per mirror, d in output units
    units: str
    scale: float
    rejected: list  # [(id, mirror)] correspondences RANSAC rejected
    unreconstructed: list  # ids with no accepted correspondence
    shared_points: int  # markers tying the two mirrors' scales (0 for one mirror)
    refinement: dict | None = None
    warnings: list = field(default_factory=list)
    timings_ms: dict = field(default_factory=dict)

    def report(self) -> dict:
        """The JSON written beside POINTS.csv."""
        return {
            "units": self.units,
            "scale": self.scale,
            "frame": "OpenCV camera frame: x right, y down, z forward",
            "mirrors": [dict(mirror=k, **pl.to_dict()) for k, pl in enumerate(self.planes)],
            "points": len(self.ids),
            "fused_points": sum(1 for m in self.mirrors_label if "+" in m),
            "scale_link_shared_points": self.shared_points,
            "rejected_pairs": [{"id": i, "mirror": k} for i, k in self.rejected],
            "unreconstructed_ids": self.unreconstructed,
            "refinement": self.refinement,
            "warnings": self.warnings,
            "timings_ms": self.timings_ms,
        }


def reconstruct_pairs(
    table: PairTable,
    camera: Camera,
    *,
    known_length: KnownLength | None = None,
    refine: bool = False,
    robust: bool = True,
    threshold_px: float = 2.0,
    seed: int = 0,
) -> PairReconstruction:
    """Estimate every mirror plane from the table and reconstruct its markers."""
    t0 = time.perf_counter()
    timings = {}
    inside = camera.contains(table.direct_px)
    inside_m = camera.contains(table.mirror_px) | ~table.visible
    if camera.image_size != (0, 0) and (not inside.all() or not inside_m.all()):
        k, i = np.argwhere(~np.vstack([inside[None], inside_m]))[0]
        w, h = camera.image_size
        raise InputError(
            f"marker {table.ids[i]!r}: a point lies outside the {w}x{h} image of the camera file "
            "(wrong camera file, or coordinates not in pixels?)"
        )
    K = table.n_mirrors
    for k in range(K):
        n_k = int(table.visible[k].sum())
        if n_k < MIN_PAIRS_PER_MIRROR:
            raise DegenerateError(
                f"mirror {k} has only {n_k} pair(s); at least {MIN_PAIRS_PER_MIRROR} are needed"
            )
    if known_length is not None:
        for marker in (known_length.id_a, known_length.id_b):
            if marker not in table.ids:
                raise InputError(f"--known-length names unknown id {marker!r}")
        if known_length.id_a == known_length.id_b:
            raise InputError("--known-length needs two different ids")
        if not (np.isfinite(known_length.millimetres) and known_length.millimetres > 0):
            raise InputError("--known-length must be a positive number of millimetres")

    visible = table.visible.copy()
    planes = []
    rejected = []
    for k in range(K):
        idx = np.flatnonzero(visible[k])
        plane = estimate_mirror_plane(
            table.direct_px[idx], table.mirror_px[k, idx], camera, robust=robust,
            threshold_px=threshold_px, seed=seed + k, label=f"mirror {k}",
        )
        rejected += [(table.ids[i], k) for i in idx[~plane.inliers]]
        visible[k, idx[~plane.inliers]] = False
        planes.append(plane)
    timings["planes"] = (time.perf_counter() - t0) * 1e3

    p = camera.normalize(table.direct_px)
    pm = camera.normalize(np.where(table.visible[..., None], table.mirror_px, table.direct_px[None]))
    normals = np.stack([pl.normal for pl in planes])
    ds = np.array([pl.d for pl in planes])
    shared = 0
    warnings = []
    if K > 1:
        ds, shared = link_mirror_scales(p, pm, visible, normals, ds)
        if shared == 0:
            raise DegenerateError(
                "no marker is seen in both mirrors, so the two mirrors' scales cannot be related; "
                "add pairs for markers visible in both mirrors, or reconstruct each mirror separately"
            )
        if shared < 3:
            warnings.append(f"only {shared} marker(s) tie the two mirrors' scales together")
    for k, pl in enumerate(planes):
        if np.isfinite(pl.noise_px) and 3.0 * pl.noise_px > threshold_px and robust:
            warnings.append(
                f"mirror {k}: the measured image noise ({pl.noise_px:.2f} px) suggests a RANSAC "
                f"threshold of at least {3 * pl.noise_px:.1f} px (now {threshold_px:g})"
            )

    keep = visible.any(axis=0)
    pts = points_from_planes(p[keep], pm[:, keep], normals, ds, visible[:, keep])
    t1 = time.perf_counter()
    timings["points"] = (t1 - t0) * 1e3 - timings["planes"]

    refinement = None
    if refine:
        res = refine_reconstruction(p[keep], pm[:, keep], visible[:, keep], normals, ds, pts,
                                    focal_px=camera.focal_px)
        refinement = {"rms_px_before": res.rms_px_before, "rms_px_after": res.rms_px_after,
                      "evaluations": res.evaluations,
                      "linear_normals": [[float(v) for v in n] for n in normals]}
        normals, ds, pts = res.normals, res.ds, res.points
        timings["refine"] = (time.perf_counter() - t1) * 1e3

    kept_ids = [m for m, k in zip(table.ids, keep) if k]
    unreconstructed = [m for m, k in zip(table.ids, keep) if not k]
    scale, units = 1.0, "relative"
    if known_length is not None:
        for marker in (known_length.id_a, known_length.id_b):
            if marker not in kept_ids:
                raise DegenerateError(
                    f"--known-length id {marker!r} could not be reconstructed (all its pairs were rejected)"
                )
        scale = scale_to_length(pts, kept_ids.index(known_length.id_a), kept_ids.index(known_length.id_b),
                                known_length.millimetres)
        pts = pts * scale
        ds = ds * scale
        units = "mm"
    for k, pl in enumerate(planes):
        pl.normal, pl.d = normals[k], float(ds[k])
    labels = ["+".join(str(k) for k in range(K) if visible[k, i]) for i in np.flatnonzero(keep)]
    timings["total"] = (time.perf_counter() - t0) * 1e3
    return PairReconstruction(
        ids=kept_ids, points=pts, mirrors_label=labels, planes=planes, units=units, scale=scale,
        rejected=rejected, unreconstructed=unreconstructed, shared_points=shared, refinement=refinement,
        warnings=warnings, timings_ms=timings,
    )


__all__ = ["KnownLength", "PairReconstruction", "reconstruct_pairs", "MIN_PAIRS_PER_MIRROR", "MirrorPlane"]
