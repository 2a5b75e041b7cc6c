"""MirrorCap's numerical core: pure numpy / scipy / OpenCV, never ``bpy``.

One subpackage per pipeline stage; data flows one way, and a stage imports only the
stages below it (``make test`` checks this with import-linter, contracts in
``pyproject.toml``):

* :mod:`.common`   -- errors, atomic files, the message log and progress.
* :mod:`.geometry` -- the camera, rigid fits, mirror planes, triangulation, the
  mirrored epipolar band; one frame of correspondences -> planes + 3D points.
* :mod:`.capture`  -- rig video, camera calibration, the rig file, marker extraction
  (UV), detections, mirror planes from a board.
* :mod:`.take`     -- take files: C3D, PAIRS.csv and POINTS.csv.
* :mod:`.track`    -- detections over time -> a labelled 3D take with head motion
  separated (self-calibration, pairing, candidates, motion filters, the tracker);
  video -> TAKE.c3d + REPORT.json.
* :mod:`.face`     -- the head model, the scan fit, RBF, the face rig, binding a take,
  PCA; one take -> per-frame vertex displacements pipeline.

``docs/architecture.md`` draws the data flow and says where a new stage goes.
"""

if __name__ == "core":  # pragma: no cover - a guard against a second import name
    raise ImportError("import the core as mirrorcap.core (python -m mirrorcap, or the installed package), "
                      "not as a top-level 'core'")

__version__ = "0.1.0"
