"""A smooth deformation field: harmonic interpolation of the control-point motion over the head mesh.

Paper 000's interpolation (Sec. 5.2) gives every head vertex the motion of the three control
points of the simple-model triangle it projects into, or eq. 10's distance-weighted fallback.
Neighbouring vertices can take different triangles (upper and lower lip, inner and outer lip
surface) and the field then tears or folds. Here the *region* that Sec. 5.2 moves keeps its
boundary (control points: their own simple vertex; vertices Sec. 5.2 leaves still: zero), and
every other vertex of that region takes the harmonic extension: the solution of the graph
Laplace equation L u = 0 with positive edge weights 1 / edge length. By the maximum principle
each vertex's weights are a convex combination of its neighbours', so the field is as smooth as
the mesh allows and never overshoots the controls. Because the weights follow mesh edges, a lip
cut open along its seam is two separate surfaces and the upper lip never follows the jaw.

Parts not connected to any control point (teeth, tongue, eyes as separate pieces) keep their
Sec. 5.2 rows, which move each such part rigidly with the control points nearest its centroid.
The weights are one sparse (n_head, n_simple) matrix, so frames cost what Sec. 5.2 frames cost.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components
from scipy.sparse.linalg import splu

from realtime_core.face.projection import vertex_adjacency


def harmonic_weights(
    vertices: np.ndarray,
    triangles: np.ndarray,
    control: np.ndarray,
    sec5: sp.csr_matrix,
    *,
    margin: float = 0.0,
    use: np.ndarray | None = None,
    pinned: np.ndarray | None = None,
    pinned_rows: sp.csr_matrix | None = None,
    pinned_reach: float = 0.0,
) -> sp.csr_matrix:
    """(n_head, n_simple) CSR weights. vertices (n, 3), triangles (m, 3), control (n_s,) head vertex of
    each simple vertex, sec5 (n, n_s) the Sec. 5.2 weights (they define the moving region and the
    rows of parts without control points); margin (head units): the region grows by this much so
    the motion fades out smoothly instead of stopping at the edge of the Sec. 5.2 region.
    use: (n_s,) bool the control points kept as constraints (default all).
    pinned (k,) head vertices with given rows ``pinned_rows`` (k, n_s) (the two sides of a cut lip
    seam, each following its own lip's inner contour): further boundary values of the field; the
    region also takes every vertex within ``pinned_reach`` (head units, along the mesh) of them, so
    surfaces that curl in behind the lips (a scan's inner lip sheets, which Sec. 5.2's depth limit
    leaves still) roll with their lip and fade out over that distance instead of tearing."""
    v = np.asarray(vertices, dtype=np.float64)
    n, n_s = len(v), len(control)
    ctrl_all = np.asarray(control, dtype=np.int64)
    cols = np.arange(n_s) if use is None else np.flatnonzero(np.asarray(use, dtype=bool))
    ctrl = ctrl_all[cols]
    adj = vertex_adjacency(n, triangles).tocoo()
    length = np.linalg.norm(v[adj.row] - v[adj.col], axis=1)
    w = 1.0 / np.maximum(length, 1e-12 * max(float(np.ptp(v, axis=0).max()), 1e-300))
    wm = sp.csr_matrix((w, (adj.row, adj.col)), shape=(n, n))
    _, comp = connected_components(wm, directed=False)
    has_ctrl = np.zeros(comp.max() + 1, dtype=bool)
    has_ctrl[comp[ctrl]] = True
    moving = np.diff(sec5.indptr) > 0
    if margin > 0 and moving.any():
        from scipy.spatial import cKDTree

        d, _ = cKDTree(v[moving]).query(v, distance_upper_bound=margin)
        grown = np.isfinite(d)
        rigid_part = ~has_ctrl[comp]
        moving = moving | (grown & ~rigid_part)
    is_ctrl = np.zeros(n, dtype=bool)
    is_ctrl[ctrl] = True
    pin = np.zeros(0, dtype=np.int64) if pinned is None else np.asarray(pinned, dtype=np.int64)
    if len(pin):
        if pinned_rows is None or pinned_rows.shape != (len(pin), n_s):
            raise ValueError("pinned_rows must be (len(pinned), n_simple)")
        if pinned_reach > 0:
            from scipy.sparse.csgraph import dijkstra

            glen = sp.csr_matrix((length + 1e-12 * float(length.max()), (adj.row, adj.col)), shape=(n, n))
            d = dijkstra(glen, indices=pin, min_only=True, limit=pinned_reach)
            moving = moving | (np.isfinite(d) & has_ctrl[comp])
        moving = moving.copy()
        moving[pin] = True
        keep_c = ~np.isin(ctrl, pin)  # a pinned vertex's row is the given one, not a control's
        cols, ctrl = cols[keep_c], ctrl[keep_c]
        is_ctrl = is_ctrl.copy()
        is_ctrl[pin] = True
    free = moving & has_ctrl[comp] & ~is_ctrl
    idx_free = np.flatnonzero(free)
    if len(idx_free) == 0:
        return sec5.tocsr()
    lap = sp.diags(np.asarray(wm.sum(axis=1)).ravel()) - wm
    l_ff = lap[idx_free][:, idx_free].tocsc()
    # Boundary: control points carry e_i; every other non-free vertex (still under Sec. 5.2) is 0.
    b = -lap[idx_free][:, ctrl] @ sp.csr_matrix(
        (np.ones(len(cols)), (np.arange(len(cols)), cols)), shape=(len(cols), n_s)
    )
    if len(pin):
        b = b - lap[idx_free][:, pin] @ sp.csr_matrix(pinned_rows)
    # Free vertices cut off from every boundary vertex would make L_ff singular: pin them weakly.
    l_ff = l_ff + sp.identity(len(idx_free), format="csc") * (1e-9 * float(w.mean()))
    solved = splu(l_ff).solve(np.asarray(b.todense()))
    solved[np.abs(solved) < 1e-5] = 0.0  # negligible weights: fewer moving vertices, cheaper frames
    rows = sp.csr_matrix(solved)
    keep = sec5.tolil(copy=True)
    out = sp.lil_matrix((n, n_s))
    rigid = moving & ~has_ctrl[comp]
    out[np.flatnonzero(rigid)] = keep[np.flatnonzero(rigid)]
    out[ctrl, cols] = 1.0
    if len(pin):
        out[pin] = sp.csr_matrix(pinned_rows).tolil()
    out = out.tocsr()
    place = sp.csr_matrix((np.ones(len(idx_free)), (idx_free, np.arange(len(idx_free)))), shape=(n, len(idx_free)))
    return (out + place @ rows).tocsr()
