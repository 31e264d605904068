"""A cheek's lining kept behind the cheek: the inside that comes through the skin moved with the skin in front of it.

A head whose mouth bag lies close behind a thin cheek (the anny thin old woman: its side walls 0.07-0.08 IOD behind
the skin, 0.2 IOD above the mouth line) gets the bag's motion from the field by its frontal position, not with the
cheek in front of it: at a wide /a/ the walls moved 0.22-0.26 IOD down and 0.10-0.12 back, and came through the cheek,
a dark fleck beside the mouth (:func:`realtime_core.face.checks.inside_shown`). :func:`with_lining_behind_skin` gives
the inside vertices that come through (and those within LINING_REACH of them along the inside) the motion of the skin
in front of them at rest, blended by their distance, so the lining keeps its place behind the cheek as the cheek
moves. Only for a rig that fails that check (``assets.heads.head.rig_checked``): others are left to the bit.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import dijkstra
from scipy.spatial import cKDTree

from realtime_core.face.checks import (
    EXTREME_POSES,
    INSIDE_SHOWN_LIMIT,
    inside_poses,
    inside_split,
    lips_band,
)
from realtime_core.face.model import MouthLandmarks
from realtime_core.face.projection import edge_length_graph
from realtime_core.face.rig import Rig
from realtime_core.face.visibility import front_most

LINING_REACH = 0.2
"""IOD along the inside's surface: how far from a vertex that comes through the skin the skin's motion is blended in
(all of it at the vertex, none this far away, smoothly between), so the lining bends rather than tears."""
LINING_SKIN_POINTS = 3
"""How many skin vertices in front of an inside vertex (nearest across the front view) give it their motion,
weighted by inverse distance."""


def shown_vertices(rig: Rig, landmarks: MouthLandmarks, poses: tuple[tuple[float, ...], ...]) -> np.ndarray:
    """Rig vertex indices of the inside (:func:`realtime_core.face.checks.inside_split`) lying more than
    INSIDE_SHOWN_LIMIT IOD in front of the front-most skin at any of ``poses``, in any of the split's views."""
    v0 = np.asarray(rig.neutral, dtype=np.float64)
    t = np.asarray(rig.triangles, dtype=np.int64)
    split = inside_split(v0, t, landmarks)
    if split is None:
        return np.zeros(0, dtype=np.int64)
    tn = t[split.faces]
    found: set[int] = set()
    for pose in poses:
        v = np.asarray(rig.deformed(np.asarray(pose, dtype=np.float64)), dtype=np.float64) - split.origin
        for tv, inside, skin in zip(split.to_views, split.inside, split.skin, strict=True):
            if not len(inside) or not len(skin):
                continue
            own = np.setdiff1d(np.unique(tn[inside]), tn[skin])
            q = v[own] @ tv
            front = front_most(q[:, :2], v[tn[skin]] @ tv)
            found.update(own[q[:, 2] > front + INSIDE_SHOWN_LIMIT * split.iod].tolist())
    return np.array(sorted(found), dtype=np.int64)


def with_lining_behind_skin(
    rig: Rig, landmarks: MouthLandmarks, *, poses: tuple[tuple[float, ...], ...] | None = None
) -> Rig | None:
    """``rig`` with the inside that comes through the skin at ``poses`` (None: the checks' sample of
    :data:`realtime_core.face.checks.EXTREME_POSES`, :func:`realtime_core.face.checks.inside_poses`) moved with the
    skin in front of it: each inside vertex of the front view within LINING_REACH IOD (along the inside) of one that
    comes through takes w of the motion of the LINING_SKIN_POINTS skin vertices nearest in front of it at rest (by
    inverse distance across the view) and (1 - w) of its own, w a smoothstep from 1 there to 0 at LINING_REACH. The
    lips (:func:`realtime_core.face.checks.lips_band`) and what lies behind the mouth between its corners keep their
    rows, as the check leaves them out. None: nothing comes through, or nothing can be moved. Meta "inside_lined": how
    many vertices were."""
    sample = inside_poses(EXTREME_POSES) if poses is None else poses
    shown = shown_vertices(rig, landmarks, sample)
    if not len(shown):
        return None
    v0 = np.asarray(rig.neutral, dtype=np.float64)
    t = np.asarray(rig.triangles, dtype=np.int64)
    split = inside_split(v0, t, landmarks, views=(0.0,))
    if split is None or not len(split.inside[0]) or not len(split.skin[0]):
        return None
    iod, tv = split.iod, split.to_views[0]
    tn = t[split.faces]
    skin_v = np.unique(tn[split.skin[0]])
    inside_v = np.setdiff1d(np.unique(tn[split.inside[0]]), skin_v)
    local = (v0 - split.origin) @ tv / iod  # (n, 3): across, up, forward (IOD), the front view
    # Neither the lips nor what lies behind the mouth between its corners (the check leaves both out: the lips roll,
    # and the inside shows through the opening).
    half = 0.5 * abs(float(local[landmarks.corner_left, 0] - local[landmarks.corner_right, 0]))
    mouth = (local[:, 2] < 0) & (np.abs(local[:, 0]) < half)
    movable = inside_v[~lips_band(v0, landmarks)[inside_v] & ~mouth[inside_v]]
    sources = np.intersect1d(shown, movable)
    if not len(sources):
        return None
    # Distance along the inside's own edges (both ends movable) from the vertices that come through.
    on = sp.diags(np.isin(np.arange(len(v0)), movable).astype(np.float64))
    graph = (on @ edge_length_graph(v0 / iod, t) @ on).tocsr()
    graph.eliminate_zeros()
    dist = dijkstra(graph, directed=False, indices=sources, min_only=True, limit=LINING_REACH)
    near = np.flatnonzero(np.isfinite(dist))
    s = np.clip(dist[near] / LINING_REACH, 0.0, 1.0)
    w = 1.0 - s * s * (3.0 - 2.0 * s)
    keep = w > 1e-6
    near, w = near[keep], w[keep]
    # The skin in front of each: its nearest skin vertices across the front view lying in front of it.
    tree = cKDTree(local[skin_v, :2])
    k = min(4 * LINING_SKIN_POINTS, len(skin_v))
    d2, j = tree.query(local[near, :2], k=k)
    d2, j = d2.reshape(len(near), k), j.reshape(len(near), k)
    ahead = local[skin_v[j], 2] > local[near, 2][:, None]
    rank = np.cumsum(ahead, axis=1)
    use = ahead & (rank <= LINING_SKIN_POINTS)
    has = use.any(axis=1)
    near, w, d2, j, use = near[has], w[has], d2[has], j[has], use[has]
    if not len(near):
        return None
    c = np.where(use, 1.0 / np.maximum(d2, 1e-6), 0.0)
    c /= c.sum(axis=1, keepdims=True)
    row = -np.ones(len(v0), dtype=np.int64)
    row[rig.moving] = np.arange(len(rig.moving))
    moving = np.union1d(rig.moving, near).astype(np.int64)
    n_m, n_old = len(moving), rig.matrix.shape[0]
    at = np.searchsorted(moving, near)
    weight = np.zeros(n_m)
    weight[at] = w
    # New rows: (1 - w) x own rows + w x sum_j c_j x skin rows, per coordinate.
    own = row[moving]
    rr, cc, vv = [], [], []
    for axis in range(3):
        has_own = own >= 0
        rr.append(3 * np.flatnonzero(has_own) + axis)
        cc.append(3 * own[has_own] + axis)
        vv.append(1.0 - weight[has_own])
        skin_rows = row[skin_v[j]]  # (h, k)
        ok = use & (skin_rows >= 0)
        hh, kk = np.nonzero(ok)
        rr.append(3 * at[hh] + axis)
        cc.append(3 * skin_rows[hh, kk] + axis)
        vv.append(w[hh] * c[hh, kk])
    pick = sp.csr_matrix((np.concatenate(vv), (np.concatenate(rr), np.concatenate(cc))), shape=(3 * n_m, n_old))
    matrix = (pick @ rig.matrix).tocsr()
    matrix.eliminate_zeros()
    spread = rig.contact_spread
    if spread is not None:
        kept = np.flatnonzero(own >= 0)
        spread = (sp.csr_matrix((np.ones(len(kept)), (kept, own[kept])), shape=(n_m, spread.shape[0])) @ spread).tocsr()
    meta = {**rig.meta, "inside_lined": len(near)}
    return replace(rig, moving=moving, matrix=matrix, meta=meta, contact_spread=spread)
