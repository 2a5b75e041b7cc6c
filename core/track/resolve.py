"""Re-solve: a take recomputed from its 2D tracks after the user fixed them (Lin 2003, section 4.3,
steps 7-8: "manual fine tuning", then the mirrors re-estimated and the trajectories recomputed).

The tracks are per marker and view, ``(F, M, 3, 2)`` pixels (direct, mirror 0, mirror 1; NaN where
the marker is not tracked in that view) -- in Blender, the clip tracks the take was written to and
the user corrected with Blender's own tracking tools. Every (frame, marker) with its direct point and
at least one mirror point is a correspondence of the user's; all of them together re-estimate both
mirror planes (eq. 3.8 with RANSAC, :func:`..geometry.reconstruct.reconstruct_pairs`: a wrong
correspondence left in the tracks is rejected and reported, not reconstructed) and give every
marker's 3D position (eq. 3.10-3.12), fused over the mirrors that see it. A wrong dot that happens to
lie on its epipolar line passes that test; where both mirrors see the marker, their one-mirror
positions then disagree (by more than :data:`DISAGREE_MM`), and the one nearer the marker's position
at its nearest consistent frame is kept. The scale is the earlier take's: mirror 0's distance is kept
as the take's report had it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..common.errors import InputError
from ..geometry.camera import Camera
from ..geometry.mirror import points_from_planes
from ..geometry.reconstruct import PairTable, reconstruct_pairs

VIEWS = 3
DISAGREE_MM = 2.0     # a marker's two one-mirror positions further apart (take units): one dot is wrong


@dataclass
class Resolved:
    points: np.ndarray            # (F, M, 3) take units (the earlier take's), NaN where not reconstructed
    planes: list                  # MirrorPlane per mirror, d in take units
    rejected: np.ndarray          # (F, M) the user's correspondence rejected as not one dot (RANSAC)
    report: dict = field(default_factory=dict)


def resolve_tracks(labels, tracks, camera: Camera, previous_mirrors: list | None = None,
                   threshold_px: float = 2.0) -> Resolved:
    """The take from ``tracks (F, M, 3, 2)`` (see the module text). ``previous_mirrors``: the earlier
    take report's ``mirrors`` (``[{"normal": [...], "d": ...}, ...]``), which fixes the scale (and
    without which the result is in the relative units of eq. 3.8)."""
    T = np.asarray(tracks, float)
    if T.ndim != 4 or T.shape[2:] != (VIEWS, 2):
        raise InputError(f"tracks must have shape (frames, markers, {VIEWS}, 2), not {T.shape}")
    F, M = T.shape[:2]
    if len(labels) != M:
        raise InputError(f"{len(labels)} labels for {M} markers")
    seen = np.all(np.isfinite(T), axis=3)                                  # (F, M, 3)
    rows = seen[:, :, 0] & seen[:, :, 1:].any(axis=2)
    f_idx, m_idx = np.nonzero(rows)
    if f_idx.size == 0:
        raise InputError("no marker has a direct-view point and a mirror point in the same frame: nothing to solve")
    visible = seen[f_idx, m_idx, 1:].T                                     # (2, n)
    mirror_px = np.where(visible[..., None], T[f_idx, m_idx, 1:].transpose(1, 0, 2), 0.0)
    ids = [f"{i}" for i in range(f_idx.size)]
    rec = reconstruct_pairs(PairTable(ids=ids, direct_px=T[f_idx, m_idx, 0], mirror_px=mirror_px, visible=visible),
                            camera, robust=True, threshold_px=threshold_px)
    scale = 1.0
    if previous_mirrors:                  # the earlier take's units: mirror 0 as far from the camera as it was
        scale = abs(float(previous_mirrors[0]["d"]) / rec.planes[0].d)
    points = np.full((F, M, 3), np.nan)
    kept = np.asarray([int(i) for i in rec.ids], int)
    points[f_idx[kept], m_idx[kept]] = rec.points * scale
    rejected = np.zeros((F, M), bool)
    accepted = visible.copy()
    for i, k in rec.rejected:
        rejected[f_idx[int(i)], m_idx[int(i)]] = True
        accepted[int(k), int(i)] = False
    # a wrong dot on the epipolar line passes the test above; seen in both mirrors, its two one-mirror
    # positions disagree: the one nearer the marker's position at its nearest consistent frame is kept
    p = camera.normalize(T[f_idx, m_idx, 0])
    single = np.stack([points_from_planes(p, camera.normalize(mirror_px[k]), pl.normal, pl.d)
                       for k, pl in enumerate(rec.planes)]) * scale                       # (K, n, 3)
    disagree = np.zeros(f_idx.size, bool)
    if len(rec.planes) == 2:
        both = accepted[0] & accepted[1]
        disagree = both & (np.linalg.norm(single[0] - single[1], axis=1) > DISAGREE_MM)
        points[f_idx[disagree], m_idx[disagree]] = np.nan
        for m in np.unique(m_idx[disagree]):
            good = np.flatnonzero(np.isfinite(points[:, m, 0]))
            for i in np.flatnonzero(disagree & (m_idx == m)):
                if good.size == 0:
                    continue
                ref = points[good[np.argmin(np.abs(good - f_idx[i]))], m]
                k = int(np.argmin(np.linalg.norm(single[:, i] - ref, axis=1)))
                points[f_idx[i], m] = single[k, i]
                rejected[f_idx[i], m] = True
    for pl in rec.planes:
        pl.d = float(pl.d * scale)
    report = {"units": "take units (the earlier take's scale)" if previous_mirrors else "relative",
              "scale_from_previous": scale,
              "mirrors": [dict(mirror=k, **pl.to_dict()) for k, pl in enumerate(rec.planes)],
              "correspondences": int(f_idx.size),
              "rejected_correspondences": int(len(rec.rejected)),
              "mirrors_disagree": int(disagree.sum()),
              "reconstructed": int(kept.size),
              "shared_points": rec.shared_points, "warnings": rec.warnings,
              "per_marker": {str(labels[m]): {"frames": int(rows[:, m].sum()),
                                              "reconstructed": int(np.isfinite(points[:, m, 0]).sum())}
                             for m in range(M)}}
    if previous_mirrors:
        report["mirror_change_deg"] = [
            float(np.degrees(np.arccos(min(1.0, abs(float(np.dot(pl.normal, np.asarray(pm["normal"], float))))))))
            for pl, pm in zip(rec.planes, previous_mirrors)]
    return Resolved(points=points, planes=rec.planes, rejected=rejected, report=report)
