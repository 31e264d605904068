"""Triangle normals: the one cross product the rig checks, the fold repair and the heads' shading read.

Unnormalised on purpose: the length is twice the triangle's area, which the callers use too (a degenerate
triangle's zero normal is told apart from a turned one; vertex normals are area-weighted by summing them).
trimesh's ``triangles.normals`` is not the same thing (unit length, degenerate triangles dropped from its
rows). Here rather than in :mod:`realtime_core.face`: importing that package loads the whole rig stack
(0.44 s), which the viewers' renderer, drawing with these normals, never needs.
"""

from __future__ import annotations

import numpy as np


def triangle_normals(vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """(m, 3) unnormalised normals (v1 - v0) x (v2 - v0) of ``triangles`` (m, 3) vertex indices into
    ``vertices`` (n, 3): length twice the triangle's area, along the side from which the corners run
    counter-clockwise."""
    v, t = vertices, triangles
    return np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]])
