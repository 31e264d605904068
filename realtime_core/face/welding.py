"""Welding coincident vertices (texture seams split them in most files) and the mesh pieces it joins."""

from __future__ import annotations

import numpy as np
from scipy.sparse.csgraph import connected_components

from realtime_core.face.projection import vertex_adjacency


def weld(
    vertices: np.ndarray, *, tolerance: float = 1e-9, keep_apart: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Merge coincident vertices (texture seams split them in most files).

    vertices (n, 3) -> canon (n,) index of each vertex's welded copy, welded (n_w, 3). Positions
    are compared after rounding to ``tolerance`` times the mesh extent.
    """
    v = np.asarray(vertices, dtype=np.float64)
    scale = max(float(np.ptp(v, axis=0).max()), 1e-300) * tolerance
    key = np.round(v / scale).astype(np.int64)
    if keep_apart is not None and len(keep_apart):
        # A fourth key column that is unique for the listed vertices and 0 for all others.
        tag = np.zeros((len(v), 1), dtype=np.int64)
        tag[np.asarray(keep_apart, dtype=np.int64), 0] = np.arange(1, len(keep_apart) + 1)
        key = np.hstack([key, tag])
    _, first, canon = np.unique(key, axis=0, return_index=True, return_inverse=True)
    # Keep the file's vertex order (np.unique sorts by position, which a rotation would change).
    order = np.argsort(first)
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    return rank[canon.reshape(-1)], v[first[order]]


def mesh_pieces(n_vertices: int, triangles: np.ndarray) -> np.ndarray:
    """(n_vertices,) int: each vertex's connected piece of the mesh ``triangles`` (m, 3) as they are (no weld: for a
    caller whose vertices were welded with cut copies kept apart and must not be merged again)."""
    _, piece = connected_components(vertex_adjacency(n_vertices, np.asarray(triangles, dtype=np.int64)), directed=False)
    return np.asarray(piece)


def welded_pieces(
    vertices: np.ndarray,
    triangles: np.ndarray,
    *,
    keep_apart: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The connected pieces of a mesh (vertices (n, 3), triangles (m, 3)) once texture seams are welded
    (:func:`weld`, ``keep_apart`` as there): canon (n,) each vertex's welded index, welded (n_w, 3) and
    piece (n_w,) int each welded vertex's piece label (a vertex's own piece: ``piece[canon]``)."""
    canon, welded = weld(np.asarray(vertices, dtype=np.float64), keep_apart=keep_apart)
    return canon, welded, mesh_pieces(len(welded), canon[np.asarray(triangles, dtype=np.int64)])
