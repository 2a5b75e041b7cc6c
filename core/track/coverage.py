"""How much of what the camera shows a take measures (REPORT.json ``coverage``), and a warning when it is
a small part of it.

A marker is measured in a frame when its dot in the direct view is paired with its image in a mirror. On
every rig the project has rendered and tracked -- 35 clips, UV and normal light, 480 to 1080 lines, mirrors
at 35-65 degrees -- a typical frame measures 53-99 % of the dots its direct view shows (the rest: dots no
mirror sees, and the tracker's gaps). A take far below that tracks few of its dots and says little of the
face, though every stage ran: the held-out small540 (normal light, 960x540, 2.2 mm dots 3.2 px across in
the direct view and 2.5-2.8 px in the mirrors) measured 1 %, 5 markers of 240, and the command ended as if it
had worked. The dots' sizes go into the warning: under normal light, mirror images 3 px across or less lost most
of their dots on the clips measured (the video's halved colour resolution blends a dot that small into the
skin), where 3.6 px kept them."""

from __future__ import annotations

import numpy as np

#: a typical frame measuring less than this share of the dots its direct view shows is warned about
#: (:func:`take_coverage`): 0.53-0.99 on the 35 clips the project tracks, 0.01 on the held-out small540
MIN_MEASURED_SHARE = 0.3
MEASURED_SHARE_SEEN = "53-99 %"


def dot_sizes(px) -> str:
    """``"the dots measure 3.2 px across in the direct view, 2.8 and 2.5 px in the mirrors"`` from each view's
    typical dot ``px`` (the median blob's, :meth:`..capture.views.ClipDetections.typical_dot_px`); ``""`` where
    the detections carry no areas."""
    if px[0] is None:
        return ""
    mirrors = " and ".join("-" if p is None else f"{p:.1f}" for p in px[1:])
    return f"the dots measure {px[0]:.1f} px across in the direct view, {mirrors} px in the mirrors"


def take_coverage(det, measured) -> dict:
    """REPORT.json ``coverage`` of a take: its detections ``det`` (:class:`..capture.views.ClipDetections`) and
    ``measured`` ``(F, N)`` (a marker measured in a frame). Per frame, the median over the frames whose direct
    view shows a dot: ``direct_dots``, ``mirror_dots`` (per mirror), ``measured`` markers and
    ``measured_share`` (measured markers / direct-view dots); ``dot_px`` the median blob's diameter per view
    (None without areas); ``enough``: the share reaches :data:`MIN_MEASURED_SHARE`."""
    direct = det.counts(0)
    shown = direct > 0 if (direct > 0).any() else np.ones(len(direct), bool)
    n_measured = np.asarray(measured, bool).sum(axis=1)
    share = float(np.median(n_measured[shown] / np.maximum(direct[shown], 1)))
    return {"direct_dots": float(np.median(direct[shown])),
            "mirror_dots": [float(np.median(det.counts(v)[shown])) for v in range(1, len(det.xy))],
            "measured": float(np.median(n_measured[shown])), "measured_share": share,
            "dot_px": det.typical_dot_px(),
            "enough": share >= MIN_MEASURED_SHARE}


def coverage_warning(coverage: dict) -> str | None:
    """The warning for a take whose :func:`take_coverage` is not ``enough``; None when it is."""
    if coverage["enough"]:
        return None
    sizes = dot_sizes(coverage["dot_px"])
    mirrors = " and ".join(f"{n:.0f}" for n in coverage["mirror_dots"])
    return (f"in a typical frame the take measures {coverage['measured']:.0f} of the {coverage['direct_dots']:.0f} "
            f"dots its direct view shows ({100 * coverage['measured_share']:.0f} %, where the rigs measured give "
            f"{MEASURED_SHARE_SEEN}): most dots found no image in a mirror. The mirrors show {mirrors} dots a frame"
            + (f", and {sizes}" if sizes else "") + " -- dots too small or too faint in the mirrors are missed "
            "(larger dots, a closer camera or a higher resolution: under normal light, mirror images 3 px across or "
            "less lost most of their dots on the rigs measured), as are dots of a colour COLORS.json does not hold "
            "and dots outside the rig file's views")
