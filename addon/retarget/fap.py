"""``mirrorcap fap`` and ``mirrorcap bake --fap``: MPEG-4 facial animation parameters out of a
take, and a .fap file back onto a head (:mod:`core.retarget.mpeg4`).

Out: TAKE.c3d -> :func:`core.face.animate.animate_take` on HEAD.blend (as ``bake`` binds it; no
synthetic blinks: the eyelid FAPs are not measured) -> the head's per-frame displacements ->
:func:`core.retarget.mpeg4.faps_from_motion` (head rotation FAPs from the take's head motion)
-> TAKE.fap (and FAP.json: the feature points, FAPU and which FAPs were written).

In (``bake --fap``, :mod:`addon.bake.bake`): TAKE.fap -> each feature point's displacement -> a
sparse take of one marker per feature point (:func:`core.retarget.mpeg4.replay_take`), which
the face rig animates on the head like any take.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from ...core.common.errors import InputError
from ...core.common.files import write_files_atomically
from ...core.face.animate import head_pose_from_report
from ...core.face.bind import load_marker_map
from ...core.retarget import mpeg4
from ...core.take.c3d import read_c3d
from ..common.headio import find_head_object, head_feature_points, open_blend, read_head

def run_fap(take, head_blend, output, *, head_object=None, head_pose_report=None, marker_map=None,
            neutral_frame: int = 0, unseen: str = "conjecture",
            high_level: bool = True, report=None, name: str | None = None) -> dict:
    """The whole ``mirrorcap fap``: read, bind, rig, measure the FAPs, write TAKE.fap atomically.
    Returns the report (also written to ``report`` as JSON when given)."""
    t0 = time.perf_counter()
    output = Path(output)
    if not output.parent.is_dir():
        raise InputError(f"output folder {output.parent} does not exist")
    data = read_c3d(take)
    mapping = load_marker_map(marker_map) if marker_map else None
    F = data["points"].shape[0]
    pose = None if head_pose_report is None else head_pose_from_report(head_pose_report, F)
    open_blend(head_blend)
    obj = find_head_object(head_object)
    head = read_head(obj)
    head.validate()
    points = head_feature_points(obj, head)
    units = mpeg4.fap_units(head, points)
    anim, track = mpeg4.take_faps(head, data["labels"], data["points"], data["rate"], feature=points,
                                  neutral_frame=neutral_frame, head_pose=pose,
                                  unseen=unseen, marker_map=mapping,
                                  high_level=high_level, name=name or Path(take).stem)
    write_files_atomically({output: mpeg4.fap_text(track)})
    written = [int(n) for n in np.flatnonzero(track.mask) + 1]
    result = {
        "take": str(take), "head": str(head_blend), "object": obj.name, "output": str(output),
        "frames": int(track.frames), "fps": track.fps, "faps_written": written,
        "fapu_mm": {k: round(float(v), 3) for k, v in units.items()},
        "feature_points": {k: int(v) for k, v in sorted(points.items())},
        "open_jaw_max": int(np.rint(track.values[:, 2].max())),
        "visemes": {int(v): int(c) for v, c in zip(*np.unique(track.viseme[:, 0], return_counts=True))},
        "expressions": {int(v): int(c) for v, c in zip(*np.unique(track.expression[:, 0], return_counts=True))},
        **anim.summary(), "timings_s": {"total_s": time.perf_counter() - t0},
    }
    if report is not None:
        write_files_atomically({Path(report): json.dumps(result, indent=1) + "\n"})
    return result
