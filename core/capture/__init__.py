"""From the rig to detections. In: video files or image sequences, board views, RIG.json,
COLORS.json; out: the camera's calibration (:mod:`.calibrate`), mirror planes from a
board (:mod:`.boardcal`), the rig file (:mod:`.rig`), per-frame marker detections in the
direct view and both mirrors (:mod:`.markers`, the UV detector of section 5.2;
:mod:`.detect`, DETECTIONS.csv)."""
