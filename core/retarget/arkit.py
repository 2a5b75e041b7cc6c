"""ARKit-52 blendshape weights from a take's head-motion-free marker displacements.

The actor's head (the generic head, or the head fitted to the performer through the same
fit) carries the 52 ARKit expressions as shape keys. At the markers' bound vertices they form
a basis ``B (K, M, 3)``; per frame the weights ``w_f`` in [0, 1] explain the markers'
displacements ``d_f (M, 3)`` from the neutral frame. All frames are solved at once as one
bounded least-squares problem over the clip::

    min_W  sum_f |B w_f - d_f|^2 + lambda sum_f |w_f - w_{f-1}|^2 + mu |W|^2 + gamma sum W,   0 <= W <= 1

(``gamma sum W`` is an L1 penalty, as ``W >= 0``: marker noise alone does not activate a shape).

(:func:`solve_weights`: ADMM, each step a set of tridiagonal solves over the frames, so
1,000 frames take well under a second). Shapes that move no marker
(the eyes' look directions, the tongue) are not observable: they stay 0 and are reported.
After the solve the mutually exclusive pairs (jaw and mouth left/right, each eye's look
in/out and up/down) keep only their difference, and ``mouthClose <= jawOpen``.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field, replace

import numpy as np

from ..common.errors import InputError

#: the 52 ARKit blendshapes, in the order the Live Link Face app writes them
ARKIT_SHAPES = [
    "eyeBlinkLeft", "eyeLookDownLeft", "eyeLookInLeft", "eyeLookOutLeft", "eyeLookUpLeft", "eyeSquintLeft",
    "eyeWideLeft", "eyeBlinkRight", "eyeLookDownRight", "eyeLookInRight", "eyeLookOutRight", "eyeLookUpRight",
    "eyeSquintRight", "eyeWideRight", "jawForward", "jawRight", "jawLeft", "jawOpen", "mouthClose", "mouthFunnel",
    "mouthPucker", "mouthRight", "mouthLeft", "mouthSmileLeft", "mouthSmileRight", "mouthFrownLeft",
    "mouthFrownRight", "mouthDimpleLeft", "mouthDimpleRight", "mouthStretchLeft", "mouthStretchRight",
    "mouthRollLower", "mouthRollUpper", "mouthShrugLower", "mouthShrugUpper", "mouthPressLeft", "mouthPressRight",
    "mouthLowerDownLeft", "mouthLowerDownRight", "mouthUpperUpLeft", "mouthUpperUpRight", "browDownLeft",
    "browDownRight", "browInnerUp", "browOuterUpLeft", "browOuterUpRight", "cheekPuff", "cheekSquintLeft",
    "cheekSquintRight", "noseSneerLeft", "noseSneerRight", "tongueOut"]
EXCLUSIVE_PAIRS = [("jawLeft", "jawRight"), ("mouthLeft", "mouthRight"),
                   ("eyeLookInLeft", "eyeLookOutLeft"), ("eyeLookInRight", "eyeLookOutRight"),
                   ("eyeLookUpLeft", "eyeLookDownLeft"), ("eyeLookUpRight", "eyeLookDownRight")]
SMOOTHNESS = 8.0        # lambda, mm^2 per unit weight change between frames
RIDGE = 1e-3            # mu: keeps the solve defined where two shapes look alike at the markers
SPARSITY = 4.0          # gamma, mm^2: the L1 term gamma sum W (W >= 0) that keeps noise from waking idle shapes
OBSERVABLE_MM = 2.0     # a shape moving the markers by less than this in all (root sum of squares, at weight 1): not observable


@dataclass
class ArkitSolve:
    names: list                   # the shapes solved (the basis' order)
    weights: np.ndarray           # (F, K) in [0, 1]
    residual_mm: np.ndarray       # (F,) RMS marker residual of the fit
    unobservable: list = field(default_factory=list)
    iterations: int = 0

    def frames(self, start: int, end: int) -> "ArkitSolve":
        """The solve of the take frames ``start:end`` only (a stretch keyed; the whole take was solved): its
        weights, residuals and report."""
        return replace(self, weights=self.weights[start:end], residual_mm=self.residual_mm[start:end])

    def report(self) -> dict:
        active = self.weights > 0.05
        return {"shapes": len(self.names), "unobservable": self.unobservable,
                "residual_mm": {"rms": float(np.sqrt(np.mean(self.residual_mm ** 2))),
                                "max": float(self.residual_mm.max()),
                                "per_frame": np.round(self.residual_mm, 4).tolist()},
                "activity": {n: {"frames_active": int(active[:, k].sum()), "max": float(self.weights[:, k].max())}
                             for k, n in enumerate(self.names)}}


def arkit_basis(shape_keys: dict, vertices) -> tuple[list, np.ndarray]:
    """The ARKit shapes among ``shape_keys`` (``{name: (V, 3) offsets}``, names matched
    case-insensitively) at ``vertices``: ``(names, B (K, M, 3))`` in the app's order."""
    by_lower = {k.lower(): k for k in shape_keys}
    names = [n for n in ARKIT_SHAPES if n.lower() in by_lower]
    if not names:
        raise InputError("the actor's head has none of the 52 ARKit shape keys (eyeBlinkLeft, jawOpen, ...)")
    vertices = np.asarray(vertices, np.int64)
    return names, np.stack([np.asarray(shape_keys[by_lower[n.lower()]], float)[vertices] for n in names])


def solve_weights(basis, displacements, names, smoothness: float = SMOOTHNESS, ridge: float = RIDGE,
                  sparsity: float = None, tol: float = 1e-5, max_iterations: int = 2000) -> ArkitSolve:
    """Weights ``(F, K)`` in [0, 1] for ``displacements (F, M, 3)`` (head mm, from the neutral
    frame) over ``basis (K, M, 3)``: the bounded problem of the module text, solved by ADMM
    (alternating an unbounded smooth solve with a projection onto [0, 1]). The unbounded step
    ``X G + lambda T X + rho X = R`` (``G = B^T B + mu I``, ``T`` the frames' path Laplacian)
    is diagonal in ``G``'s eigenvectors times the frames' DCT-II basis (where ``T`` is
    diagonal), so each step is two matrix products and a DCT."""
    from scipy.fft import dct, idct

    B = np.asarray(basis, float).reshape(len(names), -1).T          # (3M, K)
    D = np.asarray(displacements, float)
    F = D.shape[0]
    d = D.reshape(F, -1)                                             # (F, 3M)
    if not np.isfinite(d).all():
        raise InputError("the take has gaps left after binding: the ARKit solve needs every marker every frame")
    seen = np.linalg.norm(B, axis=0) > OBSERVABLE_MM
    Bs = B[:, seen]
    K = Bs.shape[1]
    G = Bs.T @ Bs + ridge * np.eye(K)
    s, U = np.linalg.eigh(G)
    rho = float(np.median(s))
    sparsity = SPARSITY if sparsity is None else sparsity
    BtD = d @ Bs - 0.5 * sparsity                                    # (F, K); the L1 term's gradient
    lam = smoothness if F > 1 else 0.0
    # the frames' path Laplacian T is diagonal in the orthonormal DCT-II basis: T = Q diag(t) Q^T
    t_eig = 2.0 - 2.0 * np.cos(np.pi * np.arange(F) / F)
    denom = lam * t_eig[:, None] + s[None, :] + rho                 # (F, K)
    X = np.clip(np.linalg.solve(G, BtD.T).T, 0.0, 1.0)
    Z, Uu = X.copy(), np.zeros_like(X)
    it = 0
    for it in range(1, max_iterations + 1):
        R = (BtD + rho * (Z - Uu)) @ U                               # (F, K) in G's eigenbasis
        X = idct(dct(R, type=2, norm="ortho", axis=0) / denom, type=2, norm="ortho", axis=0) @ U.T
        Z_old = Z
        Z = np.clip(X + Uu, 0.0, 1.0)
        Uu += X - Z
        if np.abs(X - Z).max() < tol and np.abs(Z - Z_old).max() < tol:
            break
    W = np.zeros((F, len(names)))
    W[:, seen] = Z
    W = apply_exclusions(W, names)
    res = np.sqrt(np.mean((W @ B.T - d).reshape(F, -1, 3) ** 2, axis=(1, 2)) * 3)
    return ArkitSolve(list(names), W, res, [n for n, k in zip(names, seen) if not k], iterations=it)


def apply_exclusions(weights, names) -> np.ndarray:
    """Mutually exclusive pairs keep their difference (the larger minus the smaller, the other
    0); ``mouthClose`` never exceeds ``jawOpen`` (the lips cannot close more than the jaw opens)."""
    W = np.array(weights, float)
    idx = {n: k for k, n in enumerate(names)}
    for a, b in EXCLUSIVE_PAIRS:
        if a in idx and b in idx:
            low = np.minimum(W[:, idx[a]], W[:, idx[b]])
            W[:, idx[a]] -= low
            W[:, idx[b]] -= low
    if "mouthClose" in idx and "jawOpen" in idx:
        W[:, idx["mouthClose"]] = np.minimum(W[:, idx["mouthClose"]], W[:, idx["jawOpen"]])
    return W


def retarget_take(head, shape_keys: dict, labels, points, *, neutral_frame: int = 0, head_pose=None,
                  marker_map: dict | None = None, unseen: str = "error", smoothness: float | None = None):
    """A take to ARKit weights: bind it to the actor's ``head`` (:func:`..face.bind.bind_take`),
    take the ARKit ``shape_keys`` at the bound vertices, solve (:func:`solve_weights`) and the
    head's yaw, pitch and roll (:func:`head_angles`). Returns ``(binding, solve, angles)``."""
    from ..face.bind import bind_take

    binding = bind_take(head, labels, points, neutral_frame=neutral_frame, head_pose=head_pose,
                        marker_map=marker_map, unseen=unseen)
    names, basis = arkit_basis(shape_keys, binding.vertices)
    solve = solve_weights(basis, binding.displacements, names,
                          **({} if smoothness is None else {"smoothness": smoothness}))
    return binding, solve, head_angles(binding.head_motion[0], head.face_axes())


def shape_name_key(name: str) -> str:
    """An ARKit shape name as characters exported from other tools spell it, reduced to one form: a side written
    ``_L`` / ``_R`` (or ``.l``, ``-R``, ``_left``) at its end read as ``Left`` / ``Right``, the part after the last
    namespace separator (``blendShape1.jawOpen``, ``Face:jawOpen``, ``mesh|jawOpen``), then lower case without
    ``_``, ``-`` or spaces: ``eyeBlink_L``, ``EyeBlinkLeft`` and ``eye_blink_left`` are all ``eyeblinkleft``."""
    base, side = name.strip(), ""
    written = re.search(r"(?i)[_.\s-](l|r|left|right)$", base)
    if written:
        side = "left" if written.group(1).lower().startswith("l") else "right"
        base = base[:written.start()]
    base = re.split(r"[.:|]", base)[-1]
    return re.sub(r"[_\s-]", "", base).lower() + side


def match_shape_names(target_names, names) -> tuple[dict, list]:
    """``{solved name: target key name}`` and the solved names the target lacks. A target key matches when its
    name is the solved name in any case, else when both reduce to one :func:`shape_name_key` (another tool's
    spelling: ``blendShape1.jawOpen``, ``eyeBlink_L``, ``mouth_smile_right``); the first such key wins."""
    by_lower, by_key = {}, {}
    for t in target_names:
        by_lower.setdefault(t.lower(), t)
        by_key.setdefault(shape_name_key(t), t)
    found = {}
    for n in names:
        hit = by_lower.get(n.lower()) or by_key.get(shape_name_key(n))
        if hit is not None and hit not in found.values():
            found[n] = hit
    return found, [n for n in names if n not in found]


def head_angles(R, axes: dict) -> np.ndarray:
    """Head yaw, pitch and roll in radians ``(F, 3)`` of rotations ``R (F, 3, 3)`` given in the
    head's frame, with the head's ``axes`` (:meth:`..face.head.HeadModel.face_axes`): yaw about
    its up axis (positive: turning to the subject's left), pitch about its lateral axis
    (positive: looking down), roll about its forward axis."""
    up = -np.asarray(axes["down"], float)
    C = np.stack([np.asarray(axes["lateral"], float), up, np.asarray(axes["forward"], float)])   # rows: x, y, z
    Rl = C @ np.asarray(R, float) @ C.T                      # the rotation in (lateral, up, forward) coordinates
    yaw = np.arctan2(Rl[:, 0, 2], Rl[:, 2, 2])
    pitch = np.arcsin(np.clip(-Rl[:, 1, 2], -1.0, 1.0))
    roll = np.arctan2(Rl[:, 1, 0], Rl[:, 1, 1])
    return np.stack([yaw, pitch, roll], axis=1)


def rotations_from_angles(yaw_pitch_roll, axes: dict) -> np.ndarray:
    """The inverse of :func:`head_angles`: rotations ``(F, 3, 3)`` in the head's frame from yaw, pitch
    and roll ``(F, 3)`` in radians (``R = C^T R_y(yaw) R_x(pitch) R_z(roll) C``, ``C`` the head's
    lateral, up and forward axes as rows)."""
    a = np.asarray(yaw_pitch_roll, float).reshape(-1, 3)
    up = -np.asarray(axes["down"], float)
    C = np.stack([np.asarray(axes["lateral"], float), up, np.asarray(axes["forward"], float)])
    cy, sy = np.cos(a[:, 0]), np.sin(a[:, 0])
    cp, sp = np.cos(a[:, 1]), np.sin(a[:, 1])
    cr, sr = np.cos(a[:, 2]), np.sin(a[:, 2])
    z, o = np.zeros(len(a)), np.ones(len(a))
    Ry = np.stack([np.stack([cy, z, sy], -1), np.stack([z, o, z], -1), np.stack([-sy, z, cy], -1)], 1)
    Rx = np.stack([np.stack([o, z, z], -1), np.stack([z, cp, -sp], -1), np.stack([z, sp, cp], -1)], 1)
    Rz = np.stack([np.stack([cr, -sr, z], -1), np.stack([sr, cr, z], -1), np.stack([z, z, o], -1)], 1)
    return C.T @ (Ry @ Rx @ Rz) @ C
