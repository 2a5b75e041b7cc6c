"""Camera calibration from views of a board (``mirrorcap calibrate``).

Boards:

* ``chessboard:COLSxROWS:SQUARE_MM`` -- a chessboard with COLS x ROWS *inner* corners
  (OpenCV's pattern size) and squares of SQUARE_MM millimetres;
* ``charuco:COLSxROWS:SQUARE_MM:MARKER_MM[:DICT]`` -- a ChArUco board of COLS x ROWS
  *squares*, markers of MARKER_MM, ArUco dictionary DICT (default ``DICT_4X4_50``).

Frames are sampled evenly from the source (at most ``max_views``), the board is
found in each (``findChessboardCornersSB`` / ``CharucoDetector``), and
``cv2.calibrateCameraExtended`` fits K and (k1, k2, p1, p2, k3). Too few usable views, an
RMS reprojection error above ``max_rms_px``, a board whose plane turns less than :data:`MIN_BOARD_TURN_DEG`
between views, or a focal length known to worse than ``max_focal_sd_percent`` is an error, never a silently
poor calibration.

Views of the board in parallel planes -- all face-on, say -- cannot tell the focal length from the board's
distance (Zhang's method needs the board's plane to turn): ten views of a chessboard tilted at most 1 deg
from face-on gave a focal length 10 % off with a 0.013 px reprojection error and a standard deviation OpenCV
put at 0.001 %. On the rig, a focal length 1 % off distorts a take by 0.2 mm RMS after one similarity, 2 % by
0.4 mm and 5 % by 0.9-1.0 mm (the dense, tele900 and hd clips tracked with a scaled focal length; stop 40),
and nothing in the take can tell.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from ..common.errors import DegenerateError, InputError
from ..geometry.camera import Camera
from .video import VideoSource


@dataclass
class Board:
    kind: str  # "chessboard" or "charuco"
    cols: int
    rows: int
    square_mm: float
    marker_mm: float = 0.0
    dictionary: str = "DICT_4X4_50"

    @classmethod
    def parse(cls, text: str) -> "Board":
        m = re.fullmatch(r"chessboard:(\d+)x(\d+):([0-9.]+)", text.strip())
        if m:
            board = cls("chessboard", int(m.group(1)), int(m.group(2)), float(m.group(3)))
        else:
            m = re.fullmatch(r"charuco:(\d+)x(\d+):([0-9.]+):([0-9.]+)(?::(DICT_\w+))?", text.strip())
            if not m:
                raise InputError(f"board must be chessboard:COLSxROWS:SQUARE_MM or "
                                 f"charuco:COLSxROWS:SQUARE_MM:MARKER_MM[:DICT], got {text!r}")
            board = cls("charuco", int(m.group(1)), int(m.group(2)), float(m.group(3)), float(m.group(4)),
                        m.group(5) or "DICT_4X4_50")
            if not 0 < board.marker_mm < board.square_mm:
                raise InputError("charuco marker size must be positive and smaller than the square")
            import cv2

            if not hasattr(cv2.aruco, board.dictionary):
                raise InputError(f"unknown ArUco dictionary {board.dictionary}")
        if board.cols < 2 or board.rows < 2 or board.square_mm <= 0:
            raise InputError("board needs at least 2x2 corners and a positive square size")
        return board

    def spec(self) -> str:
        if self.kind == "chessboard":
            return f"chessboard:{self.cols}x{self.rows}:{self.square_mm:g}"
        return f"charuco:{self.cols}x{self.rows}:{self.square_mm:g}:{self.marker_mm:g}:{self.dictionary}"

    def object_points(self) -> np.ndarray:
        """Chessboard inner corners in board millimetres (z = 0), OpenCV's order."""
        g = np.mgrid[0:self.cols, 0:self.rows].T.reshape(-1, 2)
        return np.c_[g * self.square_mm, np.zeros(len(g))].astype(np.float32)

    def charuco_board(self):
        import cv2

        dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, self.dictionary))
        return cv2.aruco.CharucoBoard((self.cols, self.rows), self.square_mm, self.marker_mm, dictionary)


def detect_board(gray: np.ndarray, board: Board):
    """Board corners in one 8-bit grey image: ``(object_points (n, 3), image_points (n, 2))``
    or ``None`` when the board is not found (fewer than 6 corners for ChArUco)."""
    import cv2

    if board.kind == "chessboard":
        found, corners = cv2.findChessboardCornersSB(gray, (board.cols, board.rows),
                                                     flags=cv2.CALIB_CB_EXHAUSTIVE | cv2.CALIB_CB_ACCURACY)
        if not found:
            return None
        return board.object_points(), corners.reshape(-1, 2).astype(np.float32)
    detector = cv2.aruco.CharucoDetector(board.charuco_board())
    corners, ids, _, _ = detector.detectBoard(gray)
    if ids is None or len(ids) < 6:
        return None
    obj, img = board.charuco_board().matchImagePoints(corners, ids)
    return obj.reshape(-1, 3).astype(np.float32), img.reshape(-1, 2).astype(np.float32)


#: a calibration whose views' board planes all lie within this angle of each other is refused (the module text):
#: ten clean renders of views tilted at most 10 deg from face-on in random directions (19 deg apart at most) gave
#: the focal length within 0.06 %; at most 5 deg (9.7 deg apart) and 3 deg (5.8), 0.08 % with standard deviations
#: of 0.11 and 0.30 % -- which grow with the corners' noise, here 0.014 px; at most 1 deg, 10 % off
MIN_BOARD_TURN_DEG = 10.0


@dataclass
class CalibrationResult:
    camera: Camera
    rms_px: float
    views_used: int
    views_tried: int
    board: Board
    board_turn_deg: float = float("nan")    # the largest angle between two views' board planes
    focal_sd_percent: float = float("nan")  # OpenCV's standard deviation of fx and fy (the larger), % of f

    def to_dict(self) -> dict:
        d = self.camera.to_dict()
        d["calibration"] = {"rms_px": self.rms_px, "views_used": self.views_used,
                            "views_tried": self.views_tried, "board": self.board.spec(),
                            "board_turn_deg": self.board_turn_deg, "focal_sd_percent": self.focal_sd_percent}
        return d


def calibrate_camera(source: VideoSource, board: Board, *, max_views: int = 40, min_views: int = 6,
                     max_rms_px: float = 1.0, max_focal_sd_percent: float = 0.5, progress=None) -> CalibrationResult:
    """Calibrate from up to ``max_views`` frames sampled evenly from ``source``. Refused (module text): an RMS
    reprojection error over ``max_rms_px``, board planes that turn less than :data:`MIN_BOARD_TURN_DEG`, and
    a focal length whose standard deviation (OpenCV's, from the fit) exceeds ``max_focal_sd_percent`` of it --
    a focal length 1 % off distorts a take by ~0.2 mm RMS. The standard deviation is the model's figure (it
    put the 10 % error of parallel boards at 0.001 %), hence the test of the boards' turn besides it."""
    import cv2

    if min_views < 3:
        raise InputError("at least 3 views are needed for a calibration")
    step = max(1, source.frame_count // max_views)
    obj_pts, img_pts, tried = [], [], 0
    for _, frame in source.frames(0, None, step):
        tried += 1
        gray = cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)
        found = detect_board(gray, board)
        if found is not None:
            obj_pts.append(found[0])
            img_pts.append(found[1])
        if progress:
            progress(tried, min(max_views, source.frame_count))
        if tried >= max_views:
            break
    if not obj_pts:
        raise DegenerateError(f"the board ({board.spec()}) was not found in any of {tried} frames")
    if len(obj_pts) < min_views:
        raise DegenerateError(f"the board was found in only {len(obj_pts)} of {tried} frames; "
                              f"at least {min_views} views are needed")
    w, h = source.size
    rms, K, dist, rvecs, _, sd_intrinsics, _, _ = cv2.calibrateCameraExtended(obj_pts, img_pts, (w, h), None, None)
    if not np.isfinite(rms) or rms > max_rms_px:
        raise DegenerateError(f"calibration reprojection error {rms:.3f} px exceeds {max_rms_px:g} px; "
                              "use sharper views, more board poses or check the board size")
    normals = np.array([cv2.Rodrigues(r)[0][:, 2] for r in rvecs])   # each view's board normal, camera frame
    turn = float(np.degrees(np.arccos(min(1.0, np.abs(normals @ normals.T).min()))))   # planes: the normals' sign aside
    if turn < MIN_BOARD_TURN_DEG:
        raise DegenerateError(f"the board's plane turns only {turn:.1f} deg between the views: boards in parallel "
                              "planes (all face-on, say) cannot tell the focal length from the board's distance -- "
                              "film the board turned 10-40 deg from face-on, to the left, right, up and down")
    sd = np.asarray(sd_intrinsics, float).ravel()
    focal_sd = float(100.0 * max(sd[0] / K[0, 0], sd[1] / K[1, 1]))
    if not focal_sd <= max_focal_sd_percent:
        raise DegenerateError(f"the focal length is known to +-{focal_sd:.2f} % only (1 sd; at most "
                              f"{max_focal_sd_percent:g} % accepted): 1 % off distorts a take by ~0.2 mm RMS -- film "
                              "the board in more poses, turned 10-40 deg from face-on and filling more of the frame")
    camera = Camera(K=K, dist=dist.ravel()[:5], image_size=(w, h))
    return CalibrationResult(camera=camera, rms_px=float(rms), views_used=len(obj_pts), views_tried=tried,
                             board=board, board_turn_deg=turn, focal_sd_percent=focal_sd)
