"""Detections over time -> a labelled 3D take with head motion separated (Lin 2003,
chapter 5). In: per-frame detections and the camera (and mirror planes, or none);
out: mirror planes self-calibrated from the markers (:mod:`.selfcal`), direct/mirror
pairs (:mod:`.pairing`), per-frame 3D candidates (:mod:`.candidates`), motion filters and
conjectures (:mod:`.motion`), the tracker (:mod:`.tracker`, late markers in :mod:`.late`),
and video -> TAKE.c3d + REPORT.json (:mod:`.pipeline`, ``mirrorcap track``)."""
