"""Designations by hand (SEEDS.csv, Lin 2003 section 4.3 step 1): the user names markers in the
first frame, in the direct view and in a mirror, and the tracker starts from those pairs.

SEEDS.csv, header required::

    id,view,x,y
    chin,direct,640.2,512.8
    chin,mirror1,1101.5,498.0

``id`` is the marker's name (it becomes the take's label), ``view`` one of ``direct``,
``mirror0``, ``mirror1``, ``x, y`` the pixel where the dot is in the first tracked frame. Each id
needs its direct-view point and at least one mirror point. Where the automatic pairing of the
first frames disagrees with a designation, the designation wins; markers nobody named are
paired automatically and labelled ``m000``...
"""

from __future__ import annotations

import csv
from dataclasses import dataclass

import numpy as np

from ..capture.rig import VIEW_NAMES
from ..common.errors import InputError

SEED_COLUMNS = ("id", "view", "x", "y")
SEED_PX = 4.0  # a designation takes the first frame's dot within this many pixels of it


@dataclass
class Seeds:
    names: list            # (S,) marker names
    points: np.ndarray     # (S, 3, 2) pixels per view (direct, mirror0, mirror1); NaN where not given


def read_seeds(path, image_size) -> Seeds:
    """SEEDS.csv as :class:`Seeds`; one clear message for a malformed file, an unknown view, a
    point off the ``image_size`` ``(W, H)`` image, a duplicate, or a name lacking its direct or
    mirror point."""
    W, H = image_size
    try:
        with open(path, newline="", encoding="utf-8") as fh:
            rows = list(csv.reader(fh))
    except OSError as exc:
        raise InputError(f"cannot read {path}: {exc.strerror or exc}") from None
    except UnicodeDecodeError:
        raise InputError(f"{path} is not a SEEDS.csv (text with columns {','.join(SEED_COLUMNS)})") from None
    if not rows or tuple(c.strip() for c in rows[0]) != SEED_COLUMNS:
        raise InputError(f"{path} is not a SEEDS.csv (header {','.join(SEED_COLUMNS)})")
    names, table = [], {}
    for line, row in enumerate(rows[1:], start=2):
        if not any(c.strip() for c in row):
            continue
        if len(row) != 4:
            raise InputError(f"{path}, line {line}: expected {','.join(SEED_COLUMNS)}")
        name, view = row[0].strip(), row[1].strip()
        if not name:
            raise InputError(f"{path}, line {line}: the id is empty")
        if view not in VIEW_NAMES:
            raise InputError(f"{path}, line {line}: unknown view {view!r} (use {', '.join(VIEW_NAMES)})")
        try:
            x, y = float(row[2]), float(row[3])
        except ValueError:
            raise InputError(f"{path}, line {line}: x and y must be numbers") from None
        if not (0 <= x < W and 0 <= y < H):
            raise InputError(f"{path}, line {line}: ({x:g}, {y:g}) lies off the {W}x{H} image")
        if name not in table:
            names.append(name)
            table[name] = np.full((len(VIEW_NAMES), 2), np.nan)
        v = VIEW_NAMES.index(view)
        if np.isfinite(table[name][v]).all():
            raise InputError(f"{path}, line {line}: {name!r} is designated twice in the {view} view")
        table[name][v] = (x, y)
    if not names:
        raise InputError(f"{path} designates no marker")
    for name in names:
        if not np.isfinite(table[name][0]).all():
            raise InputError(f"{path}: {name!r} has no point in the direct view")
        if not np.isfinite(table[name][1:]).all(axis=1).any():
            raise InputError(f"{path}: {name!r} has no point in either mirror")
    return Seeds(names=names, points=np.stack([table[n] for n in names]))


def seeded_tracks(seeds: Seeds, det, dids, mids_all):
    """The 2D tracks of the first frame's dots each designation points at: ``(direct track (S,),
    mirror tracks (K, S): -1 where not designated)``. A designation with no dot within
    :data:`SEED_PX` in its view is an error (the click missed the dot, or the frame is not the
    first tracked one)."""
    from scipy.spatial import cKDTree

    K = len(mids_all)
    direct = np.full(len(seeds.names), -1)
    mirror = np.full((K, len(seeds.names)), -1)
    for v in range(K + 1):
        xy = det.xy[v][det.frame_view(0, v)]
        ids = np.asarray(dids[0] if v == 0 else mids_all[v - 1][0], int)
        want = np.flatnonzero(np.isfinite(seeds.points[:, v, 0]))
        if want.size == 0:
            continue
        if len(xy) == 0:
            d, j = np.full(want.size, np.inf), np.zeros(want.size, int)
        else:
            d, j = cKDTree(xy).query(seeds.points[want, v])
        miss = np.flatnonzero(d > SEED_PX)
        if miss.size:
            s = want[miss[0]]
            x, y = seeds.points[s, v]
            raise InputError(f"seed {seeds.names[s]!r}: no marker within {SEED_PX:g} px of ({x:g}, {y:g}) in the "
                             f"{VIEW_NAMES[v]} view of the first frame")
        if v == 0:
            direct[want] = ids[j]
        else:
            mirror[v - 1, want] = ids[j]
    if np.unique(direct).size < direct.size:
        raise InputError("two seeds point at the same dot in the direct view")
    return direct, mirror
