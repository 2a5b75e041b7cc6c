"""A video that jumps (stop 44): a recording paused and resumed in one file, two clips joined, a frame of another
moment. After such a jump the face is not where the head pose says, and every marker would take a neighbour's dot;
the tracker (:func:`.tracker._track_pass`) looks for the head again where a frame's markers clash or vanish."""

from __future__ import annotations

import numpy as np

from ..geometry.rigid import rigid_fit
from .result import COLOUR_SPACING_MM

#: a frame whose markers clash over blobs (:func:`.tracker._resolve_conflicts`) this much -- at least
#: RELOCATE_CONFLICTS, and RELOCATE_CONFLICT_SHARE of those measured -- or measures under RELOCATE_DROP as many as the
#: frame before, is one where the face may not be where the head pose says: a jump in the video (a recording paused
#: and resumed, two clips joined), after which every marker would take a neighbour's dot. There the head is looked
#: for (:func:`relocate_head`). On the 66 tracked stress, normal-light and held-out clips a 10-frame median of at most 7
#: conflicts; after a jump of 100 frames of the bench take (6.6 mm) 22-26, of 200 frames 11 with a drop of 16 %
RELOCATE_CONFLICTS = 8
RELOCATE_CONFLICT_SHARE = 0.04
RELOCATE_DROP = 0.85
RELOCATE_MIN_MARKERS = 12
#: ... the pose found is taken when it puts this many times as many markers (and RELOCATE_GAIN more) on a candidate of
#: their colour within RELOCATE_INLIER_MM as the predicted pose does: where the prediction was right, no change. After
#: jumps of 60-200 frames of the bench take: 1-9 markers -> 96-167 (the face 3.9-10 mm away); on the 66 clips, where
#: nothing jumps, at most 5 -> 21 (small540, whose dots are too small to track) and 3 -> 20 (rose720 at CRF 32)
RELOCATE_GAIN_FACTOR = 2.0
RELOCATE_GAIN = 30
RELOCATE_INLIER_MM = 1.5
#: the nearest-candidate radii (mm) of the search's rounds, from a jump's size down to the tracker's gates
RELOCATE_RADII_MM = (20.0, 16.0, 12.0, 9.0, 7.0, 5.0, 4.0, 3.0, 2.5, 2.0, 2.0, 2.0)


def relocate_head(model, colour, frame_tree, R, T):
    """The head pose that puts the markers' predicted head-frame positions ``model`` ``(n, 3)`` (colour classes
    ``colour``) on the frame's 3D candidates (``frame_tree``: their KD-tree in :data:`COLOUR_SPACING_MM`-spaced colour
    keys), searched from the predicted pose ``R``, ``T`` by iterated closest points: each round pairs every marker
    with the nearest candidate of its colour within the round's radius (:data:`RELOCATE_RADII_MM`) and fits the
    rigid motion of those pairs (:func:`..geometry.rigid.rigid_fit`). Returns ``(R, T)`` when it puts clearly more
    markers on a candidate than the prediction does (:data:`RELOCATE_GAIN_FACTOR`, :data:`RELOCATE_GAIN`), else
    None."""
    if frame_tree is None:
        return None
    before = on_candidates(model, colour, frame_tree, R, T)
    R1, T1 = R, T
    for radius in RELOCATE_RADII_MM:
        d, j = nearest_candidates(model, colour, frame_tree, R1, T1, radius)
        ok = np.isfinite(d)
        if ok.sum() < RELOCATE_MIN_MARKERS:
            return None
        R1, T1 = rigid_fit(model[ok], frame_tree.data[j[ok], :3])
    after = on_candidates(model, colour, frame_tree, R1, T1)
    if after >= max(RELOCATE_GAIN_FACTOR * before, before + RELOCATE_GAIN):
        return R1, T1
    return None


def nearest_candidates(model, colour, frame_tree, R, T, radius):
    """Each of the head-frame points ``model`` moved by ``R``, ``T``: the distance to the nearest 3D candidate of its
    colour in ``frame_tree`` (inf beyond ``radius``) and its row."""
    return frame_tree.query(np.c_[model @ R.T + T, colour * COLOUR_SPACING_MM], distance_upper_bound=radius)


def on_candidates(model, colour, frame_tree, R, T) -> int:
    """How many of ``model`` moved by ``R``, ``T`` lie within :data:`RELOCATE_INLIER_MM` of a candidate of their
    colour (0 for a frame without candidates)."""
    if frame_tree is None:
        return 0
    return int(np.isfinite(nearest_candidates(model, colour, frame_tree, R, T, RELOCATE_INLIER_MM)[0]).sum())
