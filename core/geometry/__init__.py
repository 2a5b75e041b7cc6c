"""Geometry of the rig (Lin 2003, chapter 3). In: pixels, normalised views, point sets;
out: the camera (:mod:`.camera`), rigid and similarity fits (:mod:`.rigid`), mirror planes
and 3D points (:mod:`.mirror`, eq. 3.1-3.12), the mirrored epipolar band (eq. 5.1-5.3), and
one frame of correspondences -> planes + points (:mod:`.reconstruct`)."""
