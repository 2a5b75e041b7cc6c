"""MirrorCap's numerical core: pure numpy / scipy / OpenCV, never ``bpy``.

One module per pipeline stage (data flows one way):

* :mod:`core.video` -- rig video / image sequences, streamed frame by frame.
* :mod:`core.calibrate` -- camera calibration from a chessboard or ChArUco board.
* :mod:`core.markers` -- marker extraction (Lin 2003, section 5.2) and the view split.
* :mod:`core.detect` -- video -> DETECTIONS.csv; learning colour classes.
* :mod:`core.camera` -- the OpenCV camera; pixels -> normalised coordinates.
* :mod:`core.mirror` -- mirror planes and 3D points (Lin 2003, ch. 3; eq. 5.1-5.3).
* :mod:`core.pairs` -- PAIRS.csv / POINTS.csv.
* :mod:`core.reconstruct` -- one frame of pairs -> planes + points (``mirrorcap reconstruct``).
* :mod:`core.simulate` -- synthetic rigs with exact truth (a test tool).
* :mod:`core.render` -- synthetic rig frames and calibration boards with truth (a test tool).
* :mod:`core.cli` -- the ``mirrorcap`` command line.
"""

__version__ = "0.1.0"
