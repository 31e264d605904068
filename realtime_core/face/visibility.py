"""What a view sees: the front-most surface under 2-D points, found through a grid of triangle bins.

One search serves the rig checks' "is this lip face covered by a nearer face?"
(:func:`realtime_core.face.checks.lip_backs_seen`) and the head's "how far forward is the surface
here?" (:func:`assets.heads.cavity.front_depth`). Coordinates are a view's: (u, w) across the view,
depth towards the viewer (any unit; the same for points, triangles and ``cell``).
"""

from __future__ import annotations

import numpy as np

from realtime_core.face.compiled import front_most_binned, triangle_boxes


def front_most(
    points: np.ndarray,
    tris: np.ndarray,
    *,
    cell: float | None = None,
    skip: np.ndarray | None = None,
    below: float | np.ndarray | None = None,
    tolerance: float = 0.0,
) -> np.ndarray:
    """(k,) the largest depth of ``tris`` (m, 3, 3) (u, w, depth) under each of ``points`` (k, 2) (u, w);
    NaN where no triangle lies under a point.

    ``skip`` (k,): the index into ``tris`` of a triangle each point leaves out (its own face; -1: none).
    ``below`` (scalar or (k,)): only depths under this count (a ray that starts there, going back).
    ``tolerance``: barycentric slack, how far outside a triangle still counts as under it.
    ``cell``: the grid's cell (None: the median extent of the triangles' 2-D boxes). The triangles are
    binned by their boxes on this grid, so only point-triangle pairs that share a cell are tested."""
    p = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    tr = np.asarray(tris, dtype=np.float64).reshape(-1, 3, 3)
    k = len(p)
    out = np.full(k, np.nan)
    if not k or not len(tr):
        return out
    lo, hi = np.empty((len(tr), 2)), np.empty((len(tr), 2))
    triangle_boxes(tr, lo, hi)
    if cell is None:
        cell = float(np.median((hi - lo).max(axis=1)))
    # The boxes' extremes are every coordinate's: np.ptp of the triangles' (u, w).
    cell = max(cell, 1e-12 * max(float(hi.max() - lo.min()), 1e-300))
    lo_pt, hi_pt = p.min(axis=0), p.max(axis=0)
    use = np.flatnonzero((hi >= lo_pt).all(axis=1) & (lo <= hi_pt).all(axis=1))
    if not len(use):
        return out
    g0 = np.floor((np.maximum(lo[use], lo_pt) - lo_pt) / cell).astype(np.int64)
    g1 = np.floor((np.minimum(hi[use], hi_pt) - lo_pt) / cell).astype(np.int64)
    ncol = int(np.floor((hi_pt[0] - lo_pt[0]) / cell)) + 1
    span = g1 - g0 + 1
    count = span[:, 0] * span[:, 1]
    # Every (cell, triangle) pair: triangle i covers cells g0[i] + (a % span_x, a // span_x), a < count[i].
    owner = np.repeat(np.arange(len(use)), count)
    a = np.arange(int(count.sum())) - np.repeat(np.cumsum(count) - count, count)
    gx = g0[owner, 0] + a % span[owner, 0]
    gy = g0[owner, 1] + a // span[owner, 0]
    key = gy * ncol + gx
    order = np.argsort(key, kind="stable")
    key, owner = key[order], use[owner[order]]
    pg = np.floor((p - lo_pt) / cell).astype(np.int64)
    pk = pg[:, 1] * ncol + pg[:, 0]
    start, stop = np.searchsorted(key, pk, side="left"), np.searchsorted(key, pk, side="right")
    # Each point's candidates tested in one compiled loop (realtime_core.face.compiled), not as (pairs,) arrays.
    skips = np.full(k, -1, dtype=np.int64) if skip is None else np.asarray(skip, dtype=np.int64).reshape(k)
    limit = np.full(k, np.inf) if below is None else np.broadcast_to(np.asarray(below, dtype=np.float64), (k,)).copy()
    front_most_binned(p, tr, lo, hi, owner, start, stop, skips, limit, float(tolerance), out)
    return out
