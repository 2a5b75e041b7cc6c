"""Take files. In/out: labelled 3D trajectories as C3D (:mod:`.c3d`), one frame of
correspondences as PAIRS.csv and 3D points as POINTS.csv (:mod:`.pairs`)."""
