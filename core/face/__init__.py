"""From a take to a moving face (Lin 2003, chapter 7). In: a take's 3D trajectories, a
head model (and a scan); out: the head model (:mod:`.head`, :mod:`.headio`), the scan
(:mod:`.scanio`) and the head fitted to it (:mod:`.headfit`), RBF scattering (:mod:`.rbf`),
the take bound to the head (:mod:`.bind`), the face rig (:mod:`.facerig`), shape keys and
PCA (:mod:`.shapes`), and one take -> per-frame vertex displacements pipeline
(:mod:`.animate`) used by the command line, the add-on, batch and the demo."""
